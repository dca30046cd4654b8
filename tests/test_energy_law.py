"""The pair law's energy: with `contact.normal_direction: gradient` the elastic forces are the
gradient of the pairs' Hertz potential, so a passive slab squeezed between two sphere layers
keeps its mechanical energy; the paper's law (forces along n_c) pumps it.

The harness is a rigid slab moving in the x-z plane (x, z and a rocking angle about y) between
two fixed, opposed sphere rows, its forces chained from the production kernels as `pair_forces`
chains them, integrated by velocity Verlet (kick-drift-kick; the contact forces evaluated once
a step, at the step's end position and half-step velocity, and each pair's memory committed).
In planar motion the variant is exactly conservative: a pair's gradient has, besides the force
F_n d/(d.n_c), a couple from phi's dependence on the turning n_c, and the common contact point's
lever arm supplies it exactly when d, n_c and the tilt lie in one plane.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from spotsim.assemble.model import contact_law
from spotsim.contact.detection import contact_point, force_direction, penetration
from spotsim.contact.friction import bristle
from spotsim.contact.normal import hertz_potential, indentation, normal_force, onset_rate
from spotsim.jit import njit
from spotsim.scenario import Contact, Friction

R1, R2 = 0.7e-3, 0.8e-3  # fixed rows (masters, like the fingers) and slab (slaves, like the groove), m
HALF_THICKNESS = 2e-3  # the slab's, m
SQUEEZE = 10e-6  # a coaxial pair's penetration with the slab centred, m
MASS, INERTIA = 1.0, 3.5e-5  # kg, kg m^2 about y (a 20 x 4 mm section)
#: Slid at 10 mm/s, bounced at 2 mm/s and rocked at 0.5 rad/s: the slab stays between the rows.
START_V = np.array([0.01, 0.002, 0.5])  # m/s, m/s, rad/s
DURATION = 1.0  # s
#: The contact's fastest mode is ~5e3 rad/s (18 pairs of ~1.6e6 N/m on 1 kg): omega h = 0.05.
#: Verlet's energy error goes as h^2; the tests check it does, at STEP and STEP / 2.
STEP = 1e-5  # s


def law(normal_direction, restitution=1.0, friction=False):
    """The law's constants (`assemble.model.contact_law`) for Table 1's aluminium and radii, c_r,
    and Table 2's friction, or none (mu = 0: the bristle lies saturated at zero)."""
    mu = {} if friction else {"mu_k": 0.0, "mu_s": 0.0}
    contact = Contact(restitution=restitution, normal_direction=normal_direction, sphere_radius_finger_mm=R1 * 1e3,
                      sphere_radius_groove_mm=R2 * 1e3)
    return contact_law(SimpleNamespace(contact=contact, friction=Friction(**mu)))


def layers():
    """Slab spheres (body frame) and the fixed rows (world): centres and face normals."""
    xs = np.arange(-12, 13) * R2  # the slab's faces span +-9.6 mm
    top = np.stack([xs, 0 * xs, 0 * xs + HALF_THICKNESS + R2], axis=1)
    slab_c = np.concatenate([top, top * [1, 1, -1]])
    slab_n = np.concatenate([np.tile([0.0, 0.0, 1.0], (len(xs), 1)), np.tile([0.0, 0.0, -1.0], (len(xs), 1))])
    X = np.arange(-45, 46) * R1  # the rows span +-31.5 mm
    face = HALF_THICKNESS + 2 * (R1 + R2) - SQUEEZE  # coaxial centres are r1 + r2 - SQUEEZE apart
    upper = np.stack([X, 0 * X, 0 * X + face - R1], axis=1)
    plate_c = np.stack([upper, upper * [1, 1, -1]])  # (2, n, 3): the upper row, the lower row
    plate_n = np.stack([np.tile([0.0, 0.0, -1.0], (len(X), 1)), np.tile([0.0, 0.0, 1.0], (len(X), 1))])
    return slab_c, slab_n, plate_c, plate_n


@njit
def slab_forces(q, v, h, slab_c, slab_n, plate_c, plate_n, law, s_mem, v_minus_mem, touching):
    """Force (x, z) and torque (about y) on the slab at pose q = (x, z, theta), velocity v, and
    the energy its contacts store, J; bristles bent over h (s) and the pairs' memory updated.

    For each slab sphere, the rows' spheres within r1 + r2 along x: the pair's kernels in the
    order `pair_forces` calls them. s_mem (n_slab, n_row, 3), v_minus_mem, touching (n_slab, n_row).
    """
    ct, st = np.cos(q[2]), np.sin(q[2])
    fx = fz = tau = stored = 0.0
    for i in range(slab_c.shape[0]):
        b, nb = slab_c[i], slab_n[i]
        c2 = (q[0] + ct * b[0] + st * b[2], b[1], q[1] - st * b[0] + ct * b[2])
        n2 = (ct * nb[0] + st * nb[2], nb[1], -st * nb[0] + ct * nb[2])
        row = 0 if nb[2] > 0.0 else 1
        X0, pitch = plate_c[row, 0, 0], plate_c[row, 1, 0] - plate_c[row, 0, 0]
        lo = max(int(np.floor((c2[0] - R1 - R2 - X0) / pitch)), 0)
        hi = min(int(np.ceil((c2[0] + R1 + R2 - X0) / pitch)), plate_c.shape[1] - 1)
        for j in range(plate_c.shape[1]):
            if j < lo or j > hi:
                touching[i, j] = False
                continue
            c1, n1 = plate_c[row, j], plate_n[row, j]
            n_c, phi, hit, side = penetration(c1, n1, R1, c2, n2, R2)
            if not hit:
                touching[i, j] = False
                continue
            p = contact_point(c1, c2, R1, R2, n_c, phi)
            g = force_direction(c1, c2, n_c, phi, law.gradient, side)
            rx, rz = p[0] - q[0], p[2] - q[1]
            v_rel = (-(v[0] + v[2] * rz), 0.0, -(v[1] - v[2] * rx))  # the row is fixed: 0 - v_slab(p)
            delta_dot = indentation(-(v_rel[0] * g[0] + v_rel[1] * g[1] + v_rel[2] * g[2]))
            if touching[i, j]:
                v_minus, s_prev = v_minus_mem[i, j], (s_mem[i, j, 0], s_mem[i, j, 1], s_mem[i, j, 2])
            else:
                v_minus, s_prev = onset_rate(delta_dot, law.floor), (0.0, 0.0, 0.0)
            F_n = normal_force(indentation(phi), delta_dot, v_minus, law.K, law.damping)
            s, F_f, _, _, _ = bristle(s_prev, v_rel, n_c, F_n, h, law.bristle, False)
            touching[i, j], v_minus_mem[i, j] = True, v_minus
            s_mem[i, j, 0], s_mem[i, j, 1], s_mem[i, j, 2] = s[0], s[1], s[2]
            f_x, f_z = -(F_n * g[0] + F_f[0]), -(F_n * g[2] + F_f[2])  # on the slab: minus the master's
            fx += f_x
            fz += f_z
            tau += rz * f_x - rx * f_z
            stored += hertz_potential(phi, law.K) + 0.5 * law.bristle.k_b * (s[0] ** 2 + s[1] ** 2 + s[2] ** 2)
    return np.array([fx, fz, tau]), stored


@njit
def verlet(q, v, h, n_steps, every, slab_c, slab_n, plate_c, plate_n, law, mass):
    """Velocity Verlet over n_steps of h: the mechanical energy (J) every `every` steps, and the
    final q, v. mass: (m, m, I_y)."""
    n_slab, n_row = slab_c.shape[0], plate_c.shape[1]
    s_mem, v_minus_mem = np.zeros((n_slab, n_row, 3)), np.zeros((n_slab, n_row))
    touching = np.zeros((n_slab, n_row), dtype=np.bool_)
    F, stored = slab_forces(q, v, h, slab_c, slab_n, plate_c, plate_n, law, s_mem, v_minus_mem, touching)
    energy = np.empty(n_steps // every + 1)
    energy[0] = 0.5 * np.sum(mass * v * v) + stored
    for k in range(1, n_steps + 1):
        v = v + 0.5 * h * F / mass
        q = q + h * v
        F, stored = slab_forces(q, v, h, slab_c, slab_n, plate_c, plate_n, law, s_mem, v_minus_mem, touching)
        v = v + 0.5 * h * F / mass
        if k % every == 0:
            energy[k // every] = 0.5 * np.sum(mass * v * v) + stored
    return energy, q, v


def run(pair_law, step=STEP, duration=DURATION, start_v=START_V):
    """The slab's mechanical energy (J) after each step over `duration`, and its final pose."""
    energy, q, _ = verlet(np.zeros(3), start_v.copy(), step, round(duration / step), 1, *layers(), pair_law,
                          np.array([MASS, MASS, INERTIA]))
    return energy, q


#: The energy the variant must keep over 1 s (the issue's bound); it keeps it to ~1e-5, Verlet's error.
ENERGY_RTOL = 1e-3
#: Halving a second-order scheme's step divides its energy error by ~4.
SECOND_ORDER = (3.0, 5.0)
#: The paper's law gains ~24% over the second in this test; "clearly more" than the variant's 1e-3.
PUMPED = 1.1
#: Its gain is the law's, not the step's: it changes by less than this when the step is halved.
GAIN_CONVERGED = 1e-3


def test_gradient_law_keeps_a_squeezed_slabs_energy():
    """With the force along d / (d . n_c), c_r = 1 and no friction, a slab squeezed between two
    opposed sphere rows, slid, bounced and rocked, keeps its kinetic plus Hertz energy
    (sum of 0.8 K (phi/2)^2.5) to 1e-3 over 1 s; the error is Verlet's, falling as h^2."""
    errors = []
    for h in (STEP, STEP / 2):
        energy, _ = run(law("gradient"), step=h)
        errors.append(np.abs(energy / energy[0] - 1).max())
    assert errors[0] < ENERGY_RTOL
    assert SECOND_ORDER[0] < errors[0] / errors[1] < SECOND_ORDER[1]


def test_paper_law_pumps_a_squeezed_slabs_energy():
    """The same slab under the paper's law (force along n_c, though phi also depends on the
    pair's lateral offset) gains more than 10% in 1 s, the same gain at STEP and STEP / 2."""
    gains = [run(law("common_normal"), step=h)[0] for h in (STEP, STEP / 2)]
    gains = [energy[-1] / energy[0] for energy in gains]
    assert gains[0] > PUMPED
    assert gains[0] == pytest.approx(gains[1], rel=GAIN_CONVERGED)


#: Slid at 0.3 m/s, bounced at 20 mm/s, rocked at 5 rad/s: it slides, rocks, knocks and sticks.
FAST_V = np.array([0.3, 0.02, 5.0])
#: A rise in energy smaller than Verlet's error at STEP (~1e-5 of the energy) is not a rise.
ENERGY_RISE_RTOL = 1e-5


def test_gradient_law_with_damping_and_friction_never_gains_energy():
    """With c_r = 0.8 and Table 2's friction, the slab's kinetic plus stored energy (Hertz and
    1/2 k_b |s|^2 per bristle) never rises above any earlier value, and most of it goes."""
    energy, _ = run(law("gradient", restitution=0.8, friction=True), duration=0.2, start_v=FAST_V)
    rise = np.max(energy - np.minimum.accumulate(energy))
    assert rise < ENERGY_RISE_RTOL * energy[0]
    assert energy[-1] < 0.1 * energy[0]

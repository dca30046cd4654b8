"""Stable-step prediction for the stiff contact, before a run.

An explicit integrator is stable for an undamped mode of angular frequency omega only while
omega h stays inside its stability interval on the imaginary axis, and for a damped mode of
rate c/m only while h c/m stays inside it on the negative real axis. The contact sets both:

- Hertz: with F = K (phi/2)^1.5 (phi the bodies' approach), one pair carrying f has
  stiffness dF/dphi = 0.75 K^(2/3) f^(1/3), and n pairs sharing a load F have
  k = 0.75 K^(2/3) F^(1/3) n^(2/3);
- the bristles: n sticking pairs add n k_b, and damp with n c_b;
- Zhang damping: lambda delta^1.5 delta_dot is a damper of n * factor F_pair / v_minus, its
  largest with the onset speed at the floor.

The mass is the lightest free module's effective mass at its groove, 1 / (1/m + r^2 / I_min),
with r the distance from its centroid to the groove frame: a rotation about the weak axis
moves the contact as a lighter mass would. The load is the larger of the grasp load and the
peak of a single-pair Hertz impact at the closing speed (closed form); the pair count is
`EXPECTED_PAIRS`. The estimate is an order of magnitude, not a bound: the study of the
stability checks it against runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..contact.normal import hertz_potential
from ..jit import njit_inline
from ..tables import ADAPTIVE
from .actuation import rotor_energy
from .tether import tether_energy
from .tree import gravity_energy, kinetic_energy, spring_energy

#: Pairs sharing the load in the estimate: the shipped runs peak at 20-100 pairs in contact
#: (Case I ~ 20 at its impacts, the dual-arm second grasp 62).
EXPECTED_PAIRS = 32

#: The stability intervals of the integrators: (imaginary axis, negative real axis), in units
#: of h times the eigenvalue's magnitude. Symplectic Euler: |omega h| < 2 for an undamped
#: oscillator and h c/m < 2 for a damper (its velocity update is explicit Euler). RK4:
#: 2 sqrt(2) and 2.785. Dormand-Prince 5: ~3.3 on both (its region reaches -3.3 and 3.3 i).
STABILITY_INTERVAL = {"symplectic_euler": (2.0, 2.0), "adaptive_euler": (2.0, 2.0),
                      "rk4": (2.0 * math.sqrt(2.0), 2.785), "dopri5": (3.3, 3.3)}


@dataclass(frozen=True)
class StepPrediction:
    """The stiffest contact mode of a scene and the largest stable step of its integrator."""

    mass_kg: float  # the effective mass used
    load_N: float  # the load shared by the pairs
    pairs: int
    omega_rad_s: float  # stiffest undamped mode (Hertz + bristles)
    damping_rate_1_s: float  # fastest damped mode, c / m
    stable_step_s: float  # the integrator's largest stable step for both
    step_s: float  # the dynamics step the scenario takes
    integrator: str

    @property
    def omega_h(self) -> float:
        return self.omega_rad_s * self.step_s

    @property
    def stable(self) -> bool:
        return self.step_s <= self.stable_step_s


def impact_peak_force(K_phi: float, mass: float, speed: float) -> float:
    """Peak force of an undamped Hertz impact, F = K_phi phi^1.5, of a mass at a speed, N:
    K_phi d_max^1.5 with d_max = (5 m v^2 / (4 K_phi))^(2/5)."""
    with np.errstate(over="ignore", invalid="ignore"):  # past the float range: an inf force, a 0 step
        d_max = (5.0 * mass * speed * speed / (4.0 * K_phi)) ** 0.4
        return K_phi * d_max**1.5


def effective_mass(model) -> float:
    """The lightest free module's effective mass at its groove, kg: 1/(1/m + r^2/I_min)."""
    masses = []
    for mod in model.modules:
        j = mod.joint
        if not j:
            continue
        inertia = model.pin_model.inertias[j]
        r = np.linalg.norm(mod.placement.translation - inertia.lever)
        I_min = float(np.linalg.eigvalsh(inertia.inertia).min())
        masses.append(1.0 / (1.0 / inertia.mass + r * r / I_min))
    return min(masses) if masses else math.inf


def predict_step(model, pairs: int = EXPECTED_PAIRS) -> StepPrediction:
    """The stiffest contact mode of `model`'s scene and its integrator's largest stable step."""
    s, p = model.scenario, model.law
    method = s.simulation.integrator.method
    h = model.sim.h
    m = effective_mass(model)
    K_phi = p.K / 2.0**1.5  # F = K (phi/2)^1.5 = K_phi phi^1.5
    load = max(s.end_effector.grasp_load_N, impact_peak_force(K_phi, m, s.end_effector.closing_speed_m_s))
    k_hertz = 0.75 * p.K ** (2.0 / 3.0) * load ** (1.0 / 3.0) * pairs ** (2.0 / 3.0)
    k_bristle = pairs * p.bristle.k_b
    omega = math.sqrt((k_hertz + k_bristle) / m)
    # Zhang: each pair's damper is factor * F_pair / v_minus (per unit of delta_dot = phi_dot/2)
    c = pairs * p.bristle.c_b + 0.5 * p.damping * load / p.floor
    rate = c / m
    imag, real = STABILITY_INTERVAL[method]
    stable = min(imag / omega, real / rate if rate > 0 else math.inf)
    if method in ADAPTIVE:  # the step it takes is its own; judge its largest
        h = s.simulation.integrator.h_max_s
    return StepPrediction(m, load, pairs, omega, rate, stable, h, method)


def stability_warnings(model) -> list[str]:
    """A warning when the scenario's dynamics step lies outside its integrator's predicted
    stability region."""
    pred = predict_step(model)
    if pred.stable or pred.integrator in ADAPTIVE:  # an adaptive step shrinks by itself
        return []
    return [f"the dynamics step {pred.step_s * 1e3:.3g} ms (simulation.dt_s / substeps) exceeds the "
            f"predicted stable step {pred.stable_step_s * 1e3:.3g} ms of {pred.integrator} for the "
            f"contact (omega h = {pred.omega_h:.2f}; {pred.pairs} pairs sharing {pred.load_N:.3g} N "
            f"on {pred.mass_kg:.3g} kg): expect divergence; raise simulation.substeps"]


#: A passive phase (the drive holding, no work done on the bodies) gains no energy physically;
#: the run is diverged once its mechanical energy exceeds this factor of its value when the
#: phase began, plus ENERGY_FLOOR_J (so that a phase starting at rest is not judged on
#: round-off). Not 1: the paper's pair law directs each pair's force along the common normal,
#: while its penetration also depends on the pair's lateral offset, so it is not exactly
#: conservative when faces slide or rock against each other (`contact.normal_direction:
#: gradient` is). Converged Case I runs gain up to 2.1x in passive phases (12.5 and 6.25 us steps, RK4
#: alike), where a step past the stability limit gains hundreds of times (0.5 ms: 0.0026 J ->
#: 1.9 J); 10x lies between.
ENERGY_GROWTH = 10.0
ENERGY_FLOOR_J = 1e-6


@njit_inline
def mechanical_energy(m, d, phi, s):
    """The kinetic energy of every moving body and rotor (from the kinematics of the state,
    d.now; the motor drives' rotors, `actuation.rotor_energy`), plus the energy stored in the
    joints' springs and in the contacts, J: Hertz 0.8 K (phi/2)^2.5 per pair (`hertz_potential`)
    and 1/2 k_b |s|^2 per bristle (phi: the pairs' penetrations, m; s: their bristle
    deflections, m); with gravity, the bodies' potential in it since the start (d.gravity_datum),
    and the tethers' stretch."""
    E = (kinetic_energy(m, d.now, d.v) + spring_energy(m, d.q) + rotor_energy(m, d) + tether_energy(m, d.now)
         + gravity_energy(m, d.now) - d.gravity_datum)
    K, k_b = m.law.K, m.law.bristle.k_b
    for i in range(phi.shape[0]):
        E += hertz_potential(phi[i], K)
    for i in range(s.shape[0]):
        E += 0.5 * k_b * (s[i, 0] ** 2 + s[i, 1] ** 2 + s[i, 2] ** 2)
    return E

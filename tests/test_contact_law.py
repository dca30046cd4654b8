"""The contact law on named cases with hand-computed answers (paper Eq. 6-17)."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from spotsim.assemble.model import contact_law
from spotsim.contact.detection import SIDE_CAP, contact_point, cutoff_distance, force_direction, penetration
from spotsim.contact.friction import SLIPPING, STICKING, BristleParams, bristle
from spotsim.contact.normal import damping_factor, hertz_stiffness, indentation, normal_force, onset_rate
from spotsim.scenario import Contact, Friction

#: Closed forms here are evaluated in double precision on O(1e-3) numbers.
TOL = 1e-15
#: Eq. (8)'s phi of O(1e-4) m from O(1e-6) m^2 terms: its round-off is O(1e-19) m.
PHI_ROUND_OFF_M = 1e-18
R1, R2 = 0.7e-3, 0.8e-3
UP, DOWN = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])


def pair(c1, c2, n1=DOWN, n2=UP):
    """Master A at c1 facing n1 against slave B at c2 facing n2: (n_c, phi, in contact)."""
    n_c, phi, hit, _ = penetration(np.asarray(c1, float), n1, R1, np.asarray(c2, float), n2, R2)
    return np.array(n_c), phi, hit


def test_overlapping_coaxial_spheres_penetrate_by_the_overlap():
    """Coaxial spheres 1.2 mm apart with radii summing to 1.5 mm overlap by 0.3 mm."""
    n_c, phi, hit = pair([0, 0, 1.2e-3], [0, 0, 0])
    assert hit and phi == pytest.approx(0.3e-3, abs=TOL)
    assert np.allclose(n_c, UP)  # opposed faces: the common normal is the slave's normal


def test_touching_spheres_do_not_penetrate():
    """Spheres exactly r1 + r2 apart touch: phi = 0, no contact."""
    _, phi, hit = pair([0, 0, 1.5e-3], [0, 0, 0])
    assert phi == pytest.approx(0.0, abs=TOL) and not hit


def test_separated_spheres_have_negative_penetration():
    """Spheres 2 mm apart along the normal are 0.5 mm short of touching."""
    _, phi, hit = pair([0, 0, 2.0e-3], [0, 0, 0])
    assert phi == pytest.approx(-0.5e-3, abs=TOL) and not hit


def test_laterally_offset_pair_penetrates_along_the_common_normal():
    """Offset 0.9 mm sideways, 1 mm along n: A moves sqrt(1.5^2 - 0.9^2) - 1 = 0.2 mm to touch."""
    _, phi, hit = pair([0.9e-3, 0, 1.0e-3], [0, 0, 0])
    assert hit and phi == pytest.approx(0.2e-3, abs=TOL)


def test_pair_beyond_lateral_reach_never_touches():
    """Offset 1.6 mm sideways exceeds r1 + r2: no real root, whatever the normal distance."""
    _, _, hit = pair([1.6e-3, 0, 0.0], [0, 0, 0])
    assert not hit


def test_same_facing_spheres_never_pair():
    """Two spheres on faces facing the same way have no common normal (Eq. 6) and never pair."""
    _, _, hit = pair([0, 0, 0.5e-3], [0, 0, 0], n1=UP, n2=UP)
    assert not hit


def test_gradient_direction_is_minus_the_gradient_of_the_penetration():
    """For a pair offset sideways on tilted faces, force_direction's variant is -dphi/dc1 and has
    n_c component 1; the paper's direction is n_c. Central differences at a 10 nm step agree to
    2e-11 (round-off of phi ~ 1e-19 m over 1e-8 m, truncation ~ step^2 / r^2); 1e-9 allowed."""
    c1, c2 = np.array([0.3e-3, -0.2e-3, 1.2e-3]), np.zeros(3)
    n1, n2 = np.array([0.1, 0.0, -1.0]) / np.hypot(0.1, 1.0), UP
    n_c, phi, hit, side = penetration(c1, n1, R1, c2, n2, R2)
    assert hit and not side
    g = np.array(force_direction(c1, c2, n_c, phi, True, side))
    eps = 1e-8
    grad = [(penetration(c1 + eps * e, n1, R1, c2, n2, R2)[1] - penetration(c1 - eps * e, n1, R1, c2, n2, R2)[1])
            / (2 * eps) for e in np.eye(3)]
    assert np.allclose(g, -np.array(grad), rtol=0, atol=1e-9)
    assert np.dot(g, n_c) == pytest.approx(1.0, abs=1e-15) and np.linalg.norm(g - n_c) > 0.1
    assert force_direction(c1, c2, n_c, phi, False, side) == n_c


def test_a_sphere_behind_entering_sideways_touches_only_when_the_spheres_overlap():
    """A master sphere 0.1 mm behind the slave's centre along the common normal (chi < 0), slid
    sideways towards it. Eq. (8) alone puts it in contact at phi = 0.1 mm the moment its lateral
    offset drops below r1 + r2 = 1.5 mm, with the spheres still apart: a jump from no force to
    a deep pair. Capped (SIDE_CAP), it touches when the spheres first overlap, at an offset of
    sqrt(1.5^2 - 0.1^2) = 1.4967 mm, and then penetrates by twice their overlap."""
    _, phi, hit = pair([1.499e-3, 0, -0.1e-3], [0, 0, 0])
    assert not hit and phi < 0.0
    _, phi, hit = pair([1.4966e-3, 0, -0.1e-3], [0, 0, 0])
    assert hit and 0.0 < phi < 2 * 1e-7  # twice the 63 nm overlap there, rounded up: not 0.1 mm
    n_c, phi, hit, side = penetration(np.array([1.4e-3, 0, -0.1e-3]), DOWN, R1, np.zeros(3), UP, R2)
    assert hit and side and phi == pytest.approx(SIDE_CAP * (1.5e-3 - np.hypot(1.4e-3, 0.1e-3)), abs=TOL)


def tilted_faces(rng, spread):
    """A random slave face normal about UP and a master face normal about its opposite, each
    tilted by normal deviates of `spread` per component (unit 3-vectors)."""
    n2 = UP + rng.normal(0, spread, 3)
    n2 /= np.linalg.norm(n2)
    n1 = -n2 + rng.normal(0, spread, 3)
    return n1 / np.linalg.norm(n1), n2


def test_the_side_cap_leaves_face_on_pairs_to_eq_8():
    """Pairs in contact whose centres lie at least (r1 + r2) / 2 apart along the common normal,
    on faces tilted up to ~30 degrees, have Eq. (8)'s penetration (to its round-off). At least
    200 of 5000 random starts must be such pairs for the check to mean anything."""
    rng = np.random.default_rng(2)
    checked = 0
    for _ in range(5000):
        n1, n2 = tilted_faces(rng, 0.3)
        c1 = rng.uniform(-1.5e-3, 1.5e-3, 3)
        n_c, phi, hit, side = penetration(c1, n1, R1, np.zeros(3), n2, R2)
        chi = float(np.dot(n_c, c1))
        if not hit or chi < (R1 + R2) / SIDE_CAP:
            continue
        checked += 1
        eq_8 = -chi + np.sqrt(chi * chi - (c1 @ c1 - (R1 + R2) ** 2))
        assert not side and phi == pytest.approx(eq_8, abs=PHI_ROUND_OFF_M)
    assert checked > 200


def test_the_penetration_is_continuous_with_slope_at_most_the_side_cap():
    """Moving the master by dc changes its penetration (0 out of contact) by at most
    SIDE_CAP |dc|, for random pairs on faces tilted up to ~60 degrees, over the whole sphere of
    reach: no jump where a pair comes into contact sideways or from behind, and no unbounded
    slope side-on (Eq. (8) alone has both: its phi grows as sqrt(2 (r1 + r2) s) with a side-on
    pair's overlap s)."""
    rng = np.random.default_rng(1)
    step, touched, steepest = 1e-7, 0, 0.0

    def phi_of(c1, n1, n2):
        _, phi, hit, _ = penetration(c1, n1, R1, np.zeros(3), n2, R2)
        return phi if hit else 0.0

    for _ in range(40_000):
        n1, n2 = tilted_faces(rng, 0.5)
        c1 = rng.uniform(-1.8e-3, 1.8e-3, 3)
        dc = rng.normal(size=3)
        dc *= step / np.linalg.norm(dc)
        a, b = phi_of(c1, n1, n2), phi_of(c1 + dc, n1, n2)
        if a or b:
            touched += 1
            steepest = max(steepest, abs(b - a) / step)
    assert touched > 5000  # enough pairs in contact to have met every kind of entry
    # a difference of two phi ~ 1e-4 m over 1e-7 m: round-off ~ 1e-19 / 1e-7 = 1e-12 of the slope
    assert steepest <= SIDE_CAP * (1 + 1e-6)


def test_side_capped_gradient_direction_is_minus_the_gradient_of_the_penetration():
    """A side-on pair (its centres 0.2 mm apart along n_c, 1.45 mm across) is capped; the
    variant's direction is then SIDE_CAP along the line of the centres, -dphi/dc1. Central
    differences at a 1 nm step: round-off ~ 1e-19 m / 1e-9 m = 1e-10, truncation ~ step^2 /
    |c1 - c2|^2 ~ 1e-12; 1e-6 allowed. The closed form agrees to round-off (TOL)."""
    c1, c2 = np.array([1.45e-3, 0.0, 0.2e-3]), np.zeros(3)
    n_c, phi, hit, side = penetration(c1, DOWN, R1, c2, UP, R2)
    assert hit and side
    g = np.array(force_direction(c1, c2, n_c, phi, True, side))
    eps = 1e-9
    grad = [(penetration(c1 + eps * e, DOWN, R1, c2, UP, R2)[1] - penetration(c1 - eps * e, DOWN, R1, c2, UP, R2)[1])
            / (2 * eps) for e in np.eye(3)]
    assert np.allclose(g, -np.array(grad), rtol=0, atol=1e-6)
    assert np.allclose(g, SIDE_CAP * c1 / np.linalg.norm(c1), rtol=0, atol=TOL)


def test_contact_point_is_mid_overlap_for_coaxial_spheres():
    """For coaxial spheres the shared contact point lies halfway through the overlap."""
    c1, c2 = np.array([0, 0, 1.2e-3]), np.array([0, 0, 0.0])
    n_c, phi, _, _ = penetration(c1, DOWN, R1, c2, UP, R2)
    p = contact_point(c1, c2, R1, R2, n_c, phi)
    # overlap spans z in [c1 - r1, c2 + r2] = [0.5, 0.8] mm
    assert p[2] == pytest.approx(0.65e-3, abs=TOL)


def test_cutoff_covers_every_pair_up_to_the_divergence_limit():
    """Random pairs in contact with phi <= r_min all lie within the search cutoff."""
    rng = np.random.default_rng(0)
    c1 = rng.uniform(-2e-3, 2e-3, size=(20_000, 3))
    found = [pair(c, [0, 0, 0]) for c in c1]
    phi, hit = np.array([phi for _, phi, _ in found]), np.array([hit for _, _, hit in found])
    ok = hit & (phi <= min(R1, R2))
    assert ok.sum() > 100
    assert np.linalg.norm(c1[ok], axis=1).max() <= cutoff_distance(R1, R2, min(R1, R2))


def test_hertz_stiffness_from_table_1():
    """K = 4/3 E/(2(1-nu^2)) sqrt(r1 r2/(r1+r2)) for equal aluminium parts: 9.61798e8 N/m^1.5."""
    K = hertz_stiffness(7e10, 0.25, 7e10, 0.25, R1, R2)
    by_hand = 4 / 3 * 7e10 / (2 * (1 - 0.25**2)) * np.sqrt(0.7e-3 * 0.8e-3 / 1.5e-3)
    assert K == pytest.approx(by_hand, rel=1e-14)
    assert K == pytest.approx(9.61798e8, rel=1e-6)


def test_damping_factor_limits():
    """Zhang's factor is 0 for a perfectly elastic impact (c_r = 1) and 1 at c_r = 0.5."""
    assert damping_factor(1.0) == 0.0
    assert damping_factor(0.5) == pytest.approx(1.0, abs=1e-15)


def test_normal_force_is_zero_at_zero_indentation_and_never_pulls():
    """F_n(0) = 0; a fast separation cannot make the force negative (clamped)."""
    K, f = 1e9, damping_factor(0.8)
    assert normal_force(0.0, 0.01, 0.01, K, f) == 0.0
    assert normal_force(1e-6, -10.0, 0.01, K, f) == 0.0


def test_normal_force_is_hertz_when_still():
    """At zero indentation rate the force is K delta^1.5 with delta = phi / 2."""
    K = 1e9
    F = normal_force(indentation(4e-6), 0.0, 1.0, K, 0.3)
    assert F == pytest.approx(K * (2e-6) ** 1.5, rel=1e-14)


def law_of(**contact):
    """The compiled law's constants (`assemble.model.contact_law`) of a `contact:` block with these keys."""
    return contact_law(SimpleNamespace(contact=Contact(**contact), friction=Friction()))


def restitution(v0, law, mass=0.1):
    """Exit over entry normal speed of a head-on impact: master sphere A falling at v0 (m/s) onto
    a fixed slave B, integrated tightly (DOP853) with the production kernels, the onset rate
    taken as `pair_forces` takes it."""
    origin, r1, r2 = np.zeros(3), law.r1, law.r2

    def contact(z, v_z, v_minus):
        """phi, the force direction's z and the force magnitude at height z, speed v_z."""
        c1 = np.array([0.0, 0.0, z])
        n_c, phi, hit, side = penetration(c1, DOWN, r1, origin, UP, r2)
        g = force_direction(c1, origin, n_c, phi, law.gradient, side)
        delta_dot = indentation(-(v_z * g[2]))
        F = normal_force(indentation(phi), delta_dot, v_minus, law.K, law.damping) if hit else 0.0
        return phi, g[2], F, delta_dot

    z0 = r1 + r2 + 1e-7  # just above contact: nothing acts before the touch, so the rate at onset is this one
    v_minus = onset_rate(contact(z0, -v0, 0.0)[3], law.floor)

    def rhs(t, y):
        _, g_z, F, _ = contact(y[0], y[1], v_minus)
        return [y[1], F * g_z / mass]

    def leave(t, y):  # phi falling through zero: the spheres part
        return contact(y[0], y[1], v_minus)[0]

    leave.terminal, leave.direction = True, -1
    out = solve_ivp(rhs, (0.0, 1.0), [z0, -v0], method="DOP853", rtol=1e-12, atol=1e-16, events=leave,
                    max_step=1e-5)
    return out.y_events[0][0][1] / v0


def hunt_crossley_restitution(chi):
    """The restitution e of m x'' = -K x^n (1 + chi x'/x'_0), entering at x = 0 with x'_0 > 0:
    the root of chi (1 + e) = ln((1 + chi) / (1 - chi e)).

    With u = x'/x'_0, u du / (1 + chi u) = -(K / (m x'_0^2)) x^n dx; integrated from entry
    (x = 0, u = 1) to exit (x = 0, u = -e) its right side vanishes, leaving
    [u / chi - ln(1 + chi u) / chi^2] from 1 to -e = 0. K, n, m and x'_0 drop out (the impact
    is self-similar), and 1 - chi e > 0 at the root, so the force never reaches the clamp.
    """
    if chi == 0.0:
        return 1.0
    return brentq(lambda e: chi * (1 + e) - np.log((1 + chi) / (1 - chi * e)), 0.0, min(1.0, 1 / chi) - 1e-15,
                  xtol=1e-15, rtol=1e-15)


#: The measured restitution against its closed form: DOP853 at rtol 1e-12 and the exit event
#: located to round-off agree with the closed form to ~1e-10; 1e-8 leaves room.
RESTITUTION_RTOL = 1e-8
#: Zhang et al.'s factor gives c_r only up to the truncation it is built on (see the test
#: below): the model's true restitution exceeds c_r by 0.0070 at c_r = 0.8, by O((1 - c_r)^3).
ZHANG_TRUNCATION = 0.01
APPROACH_FLOOR = Contact().approach_speed_floor_m_s  # 10 mm/s, the key's default


def test_zhang_factor_solves_the_restitution_relation_to_third_order():
    """Zhang et al. (2020)'s factor 6 (1 - c_r) / ((2 c_r - 1)^2 + 3) is exactly the root chi of
    the Hunt-Crossley relation chi (1 + e) = ln((1 + chi)/(1 - chi e)) with its logarithms
    expanded to third order in chi, -chi^2 (1 - e^2)/2 + chi^3 (1 + e^3)/3 = 0, at e = c_r:
    it is exact to that order, not exactly."""
    for c_r in (0.3, 0.5, 0.8, 0.95):
        chi = damping_factor(c_r)
        assert chi == pytest.approx(1.5 * (1 - c_r**2) / (1 + c_r**3), rel=1e-14)
        assert hunt_crossley_restitution(chi) != pytest.approx(c_r, abs=1e-7)
    assert hunt_crossley_restitution(damping_factor(0.8)) - 0.8 == pytest.approx(0.0070, abs=5e-5)


@pytest.mark.parametrize("c_r", [0.8, 0.5])
def test_restitution_above_the_floor_is_the_damping_laws(c_r):
    """Above the onset floor (approach 14 mm/s, Case I's closing speed, and 50 mm/s) one sphere
    pair restitutes at the same e at both speeds, the Hunt-Crossley closed form at Zhang's
    factor: c_r to within the factor's third-order truncation."""
    law = law_of(restitution=c_r)
    e_slow, e_fast = restitution(0.014, law), restitution(0.05, law)
    assert e_slow == pytest.approx(e_fast, rel=RESTITUTION_RTOL)
    assert e_slow == pytest.approx(hunt_crossley_restitution(damping_factor(c_r)), rel=RESTITUTION_RTOL)
    if c_r == 0.8:
        assert 0.0 < e_slow - c_r < ZHANG_TRUNCATION


def test_restitution_below_the_floor_is_higher_by_the_floors_ratio():
    """Below the floor (approach 6 mm/s < 10 mm/s) the onset rate is raised, so the damping is
    weaker by (true onset rate / floored rate) = approach speed / the key's floor, and the pair
    restitutes as an unfloored one whose factor is scaled by that ratio."""
    law, v0 = law_of(restitution=0.8), 0.006
    e_below, e_above = restitution(v0, law), restitution(0.014, law)
    chi = damping_factor(0.8) * v0 / APPROACH_FLOOR
    assert e_below == pytest.approx(hunt_crossley_restitution(chi), rel=RESTITUTION_RTOL)
    assert e_below > e_above + 0.02


def test_onset_floor_takes_the_key_as_an_approach_speed():
    """The key bounds the normal approach speed: the law's floor on delta_dot_minus, the rate of
    delta = phi / 2, is half of it."""
    assert law_of(approach_speed_floor_m_s=0.01).floor == pytest.approx(0.005, rel=1e-15)


BRISTLE = BristleParams(mu_k=0.26, mu_s=0.30, k_b=3e4, c_b=80.0, v_d=1e-3)
NORMAL = np.array([0.0, 0.0, 1.0])


def settle_bristle(load, F_n=10.0, dt=1e-5, t_end=0.3, mass=0.01):
    """A small block pressed with F_n and pulled sideways by `load`, driven by the bristle.

    Returns the final deflection, velocity and state. The block's mass is small so that
    the bristle's response settles well within t_end.
    """
    s, x_dot, state = (0.0, 0.0, 0.0), 0.0, None
    for _ in range(int(t_end / dt)):
        s, F_f, state, _, _ = bristle(s, (x_dot, 0.0, 0.0), NORMAL, F_n, dt, BRISTLE, False)
        x_dot += dt * (load + F_f[0]) / mass
    return np.array(s), x_dot, state


def test_bristle_holds_a_load_below_static_friction():
    """A tangential load of 2.5 N < mu_s F_n = 3 N is held with deflection load / k_b."""
    s, x_dot, state = settle_bristle(2.5)
    assert s[0] == pytest.approx(2.5 / BRISTLE.k_b, rel=1e-6)
    assert abs(x_dot) < 1e-9 and state == STICKING


def test_bristle_slides_at_kinetic_friction_above_static():
    """A load of 3.5 N > mu_s F_n slides; the bristle then resists with mu_k F_n = 2.6 N."""
    s, x_dot, state = settle_bristle(3.5, t_end=0.05)
    assert state == SLIPPING and x_dot > BRISTLE.v_d
    assert BRISTLE.k_b * np.linalg.norm(s) == pytest.approx(BRISTLE.mu_k * 10.0, rel=1e-12)


def test_carried_deflection_turns_with_the_normal():
    """A deflection carried to a tilted contact stays in the new tangent plane, length kept."""
    tilted = np.array([np.sin(0.1), 0.0, np.cos(0.1)])
    s, _, _, _, _ = bristle((1e-5, 0.0, 0.0), (0.0, 0.0, 0.0), tilted, 100.0, 1e-4, BRISTLE, False)
    assert abs(np.dot(s, tilted)) < 1e-18 and np.linalg.norm(s) == pytest.approx(1e-5, rel=1e-12)


#: The share held, the root of |s + v tau| = s_max, differs from s_max's growth over v by
#: round-off amplified by the cancellation in it: ~eps s_max / (mu dF / k_b) = 1e-13 for a 1 %
#: jump of the normal force.
SHARE_RTOL = 1e-9


def jump_impulse(dF, dt, v=0.005, F_n=10.0, t_end=1e-4):
    """The bristle's damping impulse (N s) over t_end after the normal force of a pair sliding
    at v (m/s, saturated at mu_k F_n) jumps by dF, in steps of dt: the jump flagged in the
    first step alone, as a controller tick flags it."""
    s = (BRISTLE.mu_k * F_n / BRISTLE.k_b, 0.0, 0.0)  # saturated along the sliding
    impulse = 0.0
    for k in range(round(t_end / dt)):
        s, F_f, _, _, _ = bristle(s, (v, 0.0, 0.0), NORMAL, F_n + dF, dt, BRISTLE, k == 0)
        impulse += dt * (F_f[0] + BRISTLE.k_b * s[0])  # the damping's share of the force
    return impulse


def test_a_jump_of_the_normal_force_damps_by_its_closed_form_at_any_step():
    """A jump dF of the normal force raises s_max by mu_k dF / k_b: the bristle holds while it
    slides that far, damping -c_b v for tau = mu_k dF / (k_b v), an impulse of
    -(c_b mu_k / k_b) dF whatever the speed. Steps longer than tau take it as the share of the
    step held; steps far shorter resolve it (to within one step's c_b v dt)."""
    dF, v = 0.01, 0.005
    tau = BRISTLE.mu_k * dF / (BRISTLE.k_b * v)  # 17.3 us
    closed = -BRISTLE.c_b * BRISTLE.mu_k * dF / BRISTLE.k_b
    for dt in (1e-4, 5e-5, 2.5e-5):  # longer than tau: held for a share of the first step
        assert dt > tau
        assert jump_impulse(dF, dt, v) == pytest.approx(closed, rel=SHARE_RTOL)
    for dt in (1e-7, 1e-8):
        assert abs(jump_impulse(dF, dt, v) - closed) <= BRISTLE.c_b * v * dt
    assert jump_impulse(dF, 2e-5, v=2 * v) == pytest.approx(closed, rel=SHARE_RTOL)


def test_without_a_jump_a_saturated_bristle_does_not_damp():
    """A normal force growing smoothly keeps a sliding bristle saturated as dt -> 0: no damping
    (the reading of Eq. (14) for a saturated bristle), however the step is cut."""
    v, rate = 0.005, 10.0  # N/s: mu_k rate / k_b = 8.7e-5 m/s, far below v
    for dt in (1e-4, 1e-6):
        s = (BRISTLE.mu_k * 10.0 / BRISTLE.k_b, 0.0, 0.0)
        for k in range(round(1e-3 / dt)):
            s, F_f, _, slack, held = bristle(s, (v, 0.0, 0.0), NORMAL, 10.0 + rate * (k + 1) * dt, dt, BRISTLE,
                                             False)
            assert slack <= 0.0 and held == 0.0 and F_f[0] == -BRISTLE.k_b * s[0]


# Friction between mu_k F_n and mu_s F_n, where Eq. (16)'s switch of the cap decides.
PRESS = 10.0  # N
STATIC, KINETIC = BRISTLE.mu_s * PRESS, BRISTLE.mu_k * PRESS  # 3.0 N, 2.6 N
BLOCK_MASS = 0.01  # kg: m x'' + c_b x' + k_b x is overdamped (c_b^2 > 4 m k_b), its slow pole at -394.5 /s
BLOCK_DT = 1e-5  # s
#: A held bristle settles to load / k_b to round-off: the slow pole has decayed by e^-40 in 0.1 s.
HELD_RTOL = 1e-9


def pulled_block(load, t_end, F_n=lambda t: PRESS, normal=lambda t: NORMAL, dt=BLOCK_DT, mass=BLOCK_MASS):
    """A block held on a plane by the normal force F_n(t) (N) and pulled by load(t) (N, 3-vector
    in the tangent plane of normal(t)), its friction the bristle law; the plane may turn about
    the contact point, and the block's velocity stays in it. Symplectic Euler steps of dt.

    Returns t (n,), deflection s (n, 3), velocity v (n, 3), friction F_f (n, 3), state (n,).
    """
    n_steps = round(t_end / dt)
    t = np.arange(1, n_steps + 1) * dt
    S, V, F, state = np.zeros((n_steps, 3)), np.zeros((n_steps, 3)), np.zeros((n_steps, 3)), np.zeros(n_steps, int)
    s, v = (0.0, 0.0, 0.0), np.zeros(3)
    for k in range(n_steps):
        n = normal(t[k])
        s, F_f, state[k], _, _ = bristle(s, v, n, F_n(t[k]), dt, BRISTLE, False)
        v = v + dt * (load(t[k]) + np.array(F_f)) / mass
        v -= np.dot(v, normal(t[k] + dt)) * normal(t[k] + dt)  # the plane holds the block in it
        S[k], V[k], F[k] = s, v, F_f
    return t, S, V, F, state


def along_x(magnitude):
    """A load of `magnitude(t)` N along x."""
    return lambda t: np.array([magnitude(t), 0.0, 0.0])


def sticking_block_response(load, t):
    """x(t), x'(t) of the block while its bristle holds (s = x) under a step `load` from rest:
    m x'' + c_b x' + k_b x = load, overdamped, poles p1 (slow) and p2."""
    m, c, k = BLOCK_MASS, BRISTLE.c_b, BRISTLE.k_b
    root = np.sqrt(c * c - 4 * m * k)
    p1, p2 = (-c + root) / (2 * m), (-c - root) / (2 * m)
    x = load / k * (1 - (p2 * np.exp(p1 * t) - p1 * np.exp(p2 * t)) / (p2 - p1))
    v = load / k * p1 * p2 * (np.exp(p2 * t) - np.exp(p1 * t)) / (p2 - p1)
    return x, v


@pytest.mark.parametrize("load", [2.7, 2.95])
def test_slowly_ramped_load_between_kinetic_and_static_friction_is_held(load):
    """A load between mu_k F_n and mu_s F_n, ramped up over 0.5 s, is held: the block creeps at
    load rate / k_b < v_d, so the cap stays mu_s F_n, and it settles with deflection load / k_b."""
    t, s, v, F, state = pulled_block(along_x(lambda t: load * min(t / 0.5, 1.0)), 0.7)
    assert KINETIC < load < STATIC
    assert np.abs(v[:, 0]).max() < BRISTLE.v_d and (state == STICKING).all()
    assert BRISTLE.k_b * np.linalg.norm(s, axis=1).max() < STATIC  # never saturated
    assert s[-1, 0] == pytest.approx(load / BRISTLE.k_b, rel=HELD_RTOL) and abs(v[-1, 0]) < 1e-12


@pytest.mark.parametrize("load", [2.65, 2.8])
def test_step_load_between_kinetic_and_static_friction_slides_if_it_reaches_the_kinetic_cap_fast(load):
    """A step load between mu_k F_n and mu_s F_n, from rest. While the bristle holds, the block
    follows m x'' + c_b x' + k_b x = load (s = x) whatever the cap; Eq. (16) makes the cap
    mu_k F_n / k_b whenever |v| > v_d, which the first microseconds of the step exceed. If x
    reaches mu_k F_n / k_b while x' > v_d, the bristle saturates at the kinetic cap, friction is
    mu_k F_n < load, and the block slides for ever (a saturated bristle's speed only grows).
    Otherwise x' falls below v_d first, the cap is mu_s F_n / k_b > load / k_b, and it sticks.
    Here x' ~ 394.5/s (load - mu_k F_n) / k_b at the kinetic cap: 2.8 N slides, 2.65 N sticks
    (the divide is near 2.676 N), where a slow ramp holds both."""
    x_cap = KINETIC / BRISTLE.k_b
    t_cap = brentq(lambda t: sticking_block_response(load, t)[0] - x_cap, 1e-9, 1.0)
    slides = sticking_block_response(load, t_cap)[1] > BRISTLE.v_d
    assert slides == (load == 2.8)  # both outcomes are exercised
    t, s, v, F, state = pulled_block(along_x(lambda t: load), 0.1)
    if not slides:
        assert s[-1, 0] == pytest.approx(load / BRISTLE.k_b, rel=HELD_RTOL) and state[-1] == STICKING
        return
    saturated = np.flatnonzero(np.isclose(BRISTLE.k_b * s[:, 0], KINETIC, rtol=1e-12))
    assert saturated[0] * BLOCK_DT == pytest.approx(t_cap, abs=2 * BLOCK_DT)  # the closed form's crossing
    after = saturated[0]
    assert (state[after:] == SLIPPING).all() and np.allclose(F[after:, 0], -KINETIC, rtol=1e-12, atol=0)
    accel = (v[-1, 0] - v[after, 0]) / (t[-1] - t[after])
    assert accel == pytest.approx((load - KINETIC) / BLOCK_MASS, rel=1e-9)


def test_falling_normal_force_lets_a_held_block_slip_when_the_load_exceeds_static_friction():
    """Under a held 2.5 N, a normal force falling at 10 N/s from 12 N holds the block while
    2.5 N < mu_s F_n(t); the bristle saturates at t* = (12 - 2.5 / mu_s) / 10 = 0.3667 s,
    within two steps (the cap falls by mu_s 10 N/s dt a step), and the block then slides."""
    load, t_star = 2.5, (12.0 - 2.5 / BRISTLE.mu_s) / 10.0
    t, s, v, F, state = pulled_block(along_x(lambda t: load), 0.5, F_n=lambda t: 12.0 - 10.0 * t)
    held = BRISTLE.k_b * s[:, 0] > load * (1 - HELD_RTOL)
    onset = t[np.flatnonzero(~held & (t > 0.1))[0]]  # after the step's transient
    assert onset == pytest.approx(t_star, abs=2 * BLOCK_DT)
    before = (t > 0.1) & (t < t_star - 2 * BLOCK_DT)
    assert held[before].all() and (state[before] == STICKING).all() and np.abs(v[before, 0]).max() < 1e-9
    assert state[-1] == SLIPPING and v[-1, 0] > BRISTLE.v_d
    assert -F[-1, 0] == pytest.approx(BRISTLE.mu_k * (12.0 - 10.0 * t[-1]), rel=1e-12)


#: A plane turning at 1 rad/s under a held load: each step rescales the carried deflection to
#: its length in the new plane, which turns it by ~(Omega dt)^2 towards the turning axis, and
#: the block creeps (~1e-10 m/s) to re-bend it. The force out of balance is the block's
#: inertia in that creep, far below c_b |s| Omega^2 dt = 7e-8 N; measured 5e-10 N.
TURNING_FORCE_TOL = 1e-8  # N


def test_held_deflection_turns_with_a_turning_normal():
    """The contact plane turns at 1 rad/s about y by 0.5 rad while a 2.5 N load (in the plane,
    partly along the turning axis) is held under 10 N: the deflection stays in the plane and
    the friction stays equal and opposite to the load."""
    omega, load, beta = 1.0, 2.5, 0.6  # rad/s, N, rad: the load's angle from the turning direction
    angle = lambda t: omega * max(t - 0.1, 0.0)  # held still for 0.1 s first
    normal = lambda t: np.array([np.sin(angle(t)), 0.0, np.cos(angle(t))])
    pull = lambda t: load * (np.cos(beta) * np.array([np.cos(angle(t)), 0.0, -np.sin(angle(t))])
                             + np.sin(beta) * np.array([0.0, 1.0, 0.0]))
    t, s, v, F, state = pulled_block(pull, 0.6, normal=normal)
    turning = t > 0.1
    normals, loads = np.array([normal(x) for x in t[turning]]), np.array([pull(x) for x in t[turning]])
    assert angle(t[-1]) == pytest.approx(0.5)
    assert np.abs(np.einsum("ij,ij->i", s[turning], normals)).max() < 1e-12 * np.linalg.norm(s[turning], axis=1).min()
    assert np.abs(F[turning] + loads).max() < TURNING_FORCE_TOL
    assert (state[turning] == STICKING).all()

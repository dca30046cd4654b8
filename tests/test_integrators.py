"""The integrators advance the floating branches' centroids in the world frame, at their orders."""

import numpy as np
import pinocchio as pin
import pytest
from conftest import CASE_I
from scipy.integrate import solve_ivp

import spotsim
from spotsim.contact.detection import penetration
from spotsim.contact.forces import Memory, no_contacts
from spotsim.contact.friction import BristleParams, bristle
from spotsim.contact.normal import hertz_stiffness, indentation, normal_force
from spotsim.contact.search import LIST_SKIN, world_spheres
from spotsim.run import Stepper
from spotsim.sim.actuation import current_speed, next_event
from spotsim.sim.dynamics import accelerations, velocity_jump
from spotsim.sim.forces import forces
from spotsim.sim.integrators import (
    SWITCH_WINDOW,
    approach_rate,
    error_rates,
    euler_error,
    onset_step,
    switch_fraction,
    tableau,
)
from spotsim.sim.loop import set_near
from spotsim.sim.model import sim_model
from spotsim.sim.tree import kinematics, travel_rate

#: Round-off on O(1) numbers over a few thousand steps.
ROUND_OFF = 1e-12
#: One formula's value computed by the compiled kernels and again here, or a bound compared with
#: what it bounds where the triangle inequality can be tight: relative, a few ulps' worth.
SAME_FORMULA_RTOL = 1e-12
#: A tumbling module far from the fingers: smooth, contact-free, gyroscopic.
TUMBLE_S = 0.02
TUMBLE_V = (0.004, -0.003, 0.002, 3.0, -2.0, 4.0)  # the module's twist (v_O, omega), body frame


def tumbling(case_I, method, **integrator):
    """Case I with the module spinning, integrated by `method`: a Stepper."""
    s = spotsim.replace(case_I, simulation={"integrator": {"method": method, **integrator}})
    model = spotsim.build_model(s)
    stepper = Stepper(model)
    iv = model.pin_model.idx_vs[model.module_joint]
    v = stepper.data.v
    v[iv:iv + 6] = TUMBLE_V
    return model, stepper


def tumble(case_I, method, h, **integrator):
    """The module's (q, v) after TUMBLE_S of free tumbling, integrated with steps of h."""
    _, stepper = tumbling(case_I, method, **integrator)
    for _ in range(round(TUMBLE_S / h)):
        stepper.step(h)
        assert len(stepper.data.contacts.key) == 0  # no contact: a smooth motion
    return np.concatenate([stepper.data.q, stepper.data.v])


def module_centroid(model, q, v):
    """The module's centroid (world) and its velocity, by Pinocchio."""
    pm, j = model.pin_model, model.module_joint
    pd = pm.createData()
    pin.forwardKinematics(pm, pd, q, v)
    c = pm.inertias[j].lever
    M, twist = pd.oMi[j], pd.v[j]
    return M.act(c), M.rotation @ (twist.linear + np.cross(twist.angular, c))


def test_force_free_tumbling_body_keeps_its_momentum_and_straight_path(case_I):
    """With no force, a tumbling body's centroid moves on a straight line at constant velocity
    (symplectic Euler, 2000 steps)."""
    model, stepper = tumbling(case_I, "symplectic_euler")
    p0, vG0 = module_centroid(model, stepper.data.q, stepper.data.v)
    h = 1e-5
    for _ in range(2000):
        stepper.step(h)
    p, vG = module_centroid(model, stepper.data.q, stepper.data.v)
    assert np.linalg.norm(vG - vG0) <= ROUND_OFF
    assert np.linalg.norm(p - (p0 + 2000 * h * vG0)) <= ROUND_OFF


def test_centroid_acceleration_is_force_over_mass(model_I):
    """The compiled accelerations, turned into the centroid's world acceleration (Pinocchio's
    classical acceleration of the centroid), are F / m: what the integrators move it by."""
    from spotsim.sim.data import make_data

    data = make_data(model_I)
    m, j = model_I.pin_model, model_I.module_joint
    pd = m.createData()
    rng = np.random.default_rng(5)
    mass, c = m.inertias[j].mass, m.inertias[j].lever
    for _ in range(20):
        q = pin.randomConfiguration(m, -np.ones(m.nq), np.ones(m.nq))
        v = rng.normal(size=m.nv)
        f_local = np.zeros((m.njoints, 6))
        f_local[j] = rng.normal(size=6)  # force and moment about the joint origin, joint axes
        data.assign(q=q, v=v, loads=data.loads._replace(f_local=f_local))
        kinematics(model_I.sim, data)
        accelerations(model_I.sim, data)
        pin.forwardKinematics(m, pd, q, v, data.a)
        a, twist = pd.a[j], pd.v[j]
        a_G = pd.oMi[j].rotation @ (a.linear + np.cross(a.angular, c) + np.cross(twist.angular, twist.linear +
                                                                                 np.cross(twist.angular, c)))
        assert np.allclose(a_G, pd.oMi[j].rotation @ f_local[j, :3] / mass, rtol=0, atol=ROUND_OFF)


def test_an_unknown_integrator_lists_the_valid_ones():
    with pytest.raises(ValueError, match="symplectic_euler, rk4, dopri5"):
        tableau("leapfrog")


#: Sums of at most seven double-precision fractions of order one.
TABLEAU_ROUND_OFF = 1e-15


def test_tableaus_are_consistent():
    """Each Runge-Kutta tableau's rows sum to its nodes, its weights to one; the embedded
    estimate's weights (a difference of two weight sets) to zero."""
    for method in ("rk4", "dopri5"):
        A, b, c, e = tableau(method)
        assert np.allclose(A.sum(axis=1), c, atol=TABLEAU_ROUND_OFF)
        assert b.sum() == pytest.approx(1.0, abs=TABLEAU_ROUND_OFF)
        assert np.all(np.triu(A) == 0.0)  # explicit
        if len(e):
            assert e.sum() == pytest.approx(0.0, abs=TABLEAU_ROUND_OFF)


def test_momenta_match_pinocchio(model_I):
    """The compiled momenta of the floating branches (a free-flying robot with its fingers and
    two modules: the dual arm) equal Pinocchio's, summed over their bodies, at random states."""
    from conftest import ROOT

    from spotsim.sim.data import make_data
    from spotsim.sim.tree import current_frames, momenta

    model = spotsim.build_model(spotsim.load_scenario(ROOT / "config" / "dual_arm_sequential.yaml"))
    pm, pd = model.pin_model, model.pin_model.createData()
    data = make_data(model)
    rng = np.random.default_rng(7)
    for _ in range(5):
        q = pin.randomConfiguration(pm, -np.ones(pm.nq), np.ones(pm.nq))
        v = rng.normal(size=pm.nv)
        data.assign(q=q, v=v)
        current_frames(model.sim, data)
        P, L, p_max, l_max, c = momenta(model.sim, data.now, model.sim.record.all_branches)
        pin.forwardKinematics(pm, pd, q, v)
        h = [pd.oMi[j].act(pm.inertias[j] * pd.v[j]) for j in range(1, pm.njoints)]
        assert np.allclose(P, sum(x.linear for x in h), rtol=0, atol=ROUND_OFF * max(1.0, np.abs(P).max()))
        assert np.allclose(L, sum(x.angular for x in h), rtol=0, atol=ROUND_OFF * max(1.0, np.abs(L).max()))
        assert p_max == pytest.approx(max(np.linalg.norm(x.linear) for x in h), rel=ROUND_OFF)
        masses = [pm.inertias[j].mass for j in range(1, pm.njoints)]
        centroids = [pd.oMi[j].act(pm.inertias[j].lever) for j in range(1, pm.njoints)]
        assert np.allclose(c, np.average(centroids, axis=0, weights=masses), rtol=0, atol=ROUND_OFF)


def test_each_integrator_converges_at_its_order_on_a_smooth_free_motion(case_I):
    """Halving the step cuts the error by ~2 (symplectic Euler), >= 10 (RK4), >= 20 (DP5)."""
    reference = tumble(case_I, "rk4", TUMBLE_S / 160)
    # (least ratio, the coarser step): dopri5 needs the largest steps to stay above round-off
    expected = {"symplectic_euler": (1.8, TUMBLE_S / 5), "rk4": (10.0, TUMBLE_S / 5), "dopri5": (20.0, TUMBLE_S)}
    for method, (least, h) in expected.items():
        # dopri5 as a fixed-step method: tolerances it always meets, its step capped at h
        errors = [np.abs(tumble(case_I, method, step, **({"rtol": 1e3, "atol": 1.0, "h_max_s": step}
                                                         if method == "dopri5" else {})) - reference).max()
                  for step in (h, h / 2)]
        assert errors[0] / errors[1] >= least, (method, errors)


#: dopri5 at rtol 1e-10 over the 20 ms tumble: its error per step is held to ~1e-11 of the
#: state's O(0.1-1) components, and the RK4 reference's own error is ~1e-12; 1e-8 leaves room
#: for their accumulation over ~100 steps, and is far below what an uncontrolled 20 ms step
#: gives (~0.04).
DOPRI5_AGREEMENT = 1e-8


def test_dopri5_controls_its_error_by_rejecting_steps(case_I):
    """Asked for a step far longer than its tolerance allows on a tumbling body, dopri5 rejects
    it, takes shorter steps, and lands on a state within its tolerance of RK4's converged one."""
    reference = tumble(case_I, "rk4", TUMBLE_S / 160)
    _, stepper = tumbling(case_I, "dopri5", rtol=1e-10, atol=1e-12, h_max_s=TUMBLE_S)
    while stepper.data.t < TUMBLE_S - 1e-12:
        assert stepper.step(TUMBLE_S - stepper.data.t) > 0.0
    v = stepper.data.view()
    assert v.rejected > 0 and v.accepted > 1
    state = np.concatenate([v.q, v.v])
    assert np.abs(state - reference).max() < DOPRI5_AGREEMENT


def adaptive_tumble(case_I, velocity_tol):
    """The tumbling module's (q, v) after TUMBLE_S by adaptive_euler asked for one step of
    TUMBLE_S at a time, and its Data. No pair starts in the tumble, so its onset guard is
    lifted (a 1 m onset depth): the error control alone sets the steps."""
    _, stepper = tumbling(case_I, "adaptive_euler", velocity_tol_m_s=velocity_tol, onset_depth_m=1.0, h_max_s=TUMBLE_S)
    while stepper.data.t < TUMBLE_S - 1e-12:
        assert stepper.step(TUMBLE_S - stepper.data.t) > 0.0
    return np.concatenate([stepper.data.q, stepper.data.v]), stepper.data.view()


#: adaptive_euler is first order: a step's error ~ h^2 is held to the tolerance, so h ~
#: tol^(1/2) and the error over a fixed time ~ h ~ tol^(1/2): a hundredth of the tolerance
#: gives a tenth of the error. 5 leaves room for the step sequence's own jitter.
ADAPTIVE_ERROR_RATIO_PER_100X_TOL = 5.0


def test_adaptive_euler_rejects_steps_and_converges_as_its_tolerance_falls(case_I):
    """Asked for one 20 ms step of a tumbling module, adaptive_euler rejects it, takes shorter
    ones, and its error against RK4's converged state falls ~10x for a 100x tighter tolerance."""
    reference = tumble(case_I, "rk4", TUMBLE_S / 160)
    errors = []
    for tol in (1e-6, 1e-8):
        state, v = adaptive_tumble(case_I, tol)
        assert v.rejected > 0 and v.accepted > 1
        errors.append(np.abs(state - reference).max())
    assert errors[0] / errors[1] >= ADAPTIVE_ERROR_RATIO_PER_100X_TOL, errors


def assert_same_end(first, again):
    """Two Steppers' steps ended bit-identical: state (the fingers' included) and every pair
    memory field."""
    a, b = first.data.view(), again.data.view()
    for name in ("q", "v"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for name in a.memory._fields:
        assert np.array_equal(getattr(a.memory, name), getattr(b.memory, name)), name


def test_adaptive_euler_rejected_try_leaves_no_trace(recorded_states, model_I):
    """A step whose first try is rejected ends bit-identical (state, pair memory) to
    the same step asked for at the length it was accepted at: a rejection restores everything."""
    s = spotsim.replace(model_I.scenario, simulation={"integrator": {"method": "adaptive_euler",
                                                                     "velocity_tol_m_s": 1e-6}})
    model = spotsim.build_model(s)
    checked = 0
    for state in recorded_states:
        first = Stepper(model, state.copy())
        h = first.step(1e-3)
        if first.data.rejected == state.rejected:
            continue  # accepted at once: nothing to check here
        again = Stepper(model, state.copy())
        assert again.step(h) == h and again.data.rejected == state.rejected
        assert_same_end(first, again)
        checked += 1
    assert checked >= 3


def test_switch_fraction_interpolates_each_bristles_slack(model_I):
    """A try's earliest bristle switch lies where its slack, linear between the memory and the
    try's end, crosses zero: a holding bristle (slack 3 um) that ends saturated (-1 um) at 3/4
    of the step, a saturated one (-1 um) that lets go (+1 um) at 1/2; one that holds
    throughout, or a pair in one list alone, has none. A switch too slow to matter (its
    misplaced damping impulse under the tolerance's share) is not located."""
    m, um = model_I.sim, 1e-6
    memory = Memory(np.array([1, 2, 3, 5]), np.zeros((4, 3)), np.zeros(4), np.array([3.0, -1.0, 2.0, 1.0]) * um)

    def end(slack, speed):
        return no_contacts()._replace(key=np.array([1, 2, 3, 4]), slack=np.array(slack) * um, speed=np.array(speed))

    fast, still = 0.02, 1e-12  # m/s: a sliding pair's speed, and one whose switch cannot matter
    assert switch_fraction(m, memory, end([-1.0, 1.0, 1.0, -5.0], [fast] * 4), 1e-5) == 0.5
    assert switch_fraction(m, memory, end([-1.0, 1.0, 1.0, -5.0], [fast, still, fast, fast]), 1e-5) == 0.75
    assert switch_fraction(m, memory, end([-1.0, 1.0, 1.0, -5.0], [still] * 4), 1e-5) == 1.0
    assert switch_fraction(m, memory, end([1.0, -1.0, 1.0, -5.0], [fast] * 4), 1e-5) == 1.0


def test_adaptive_euler_located_switch_leaves_no_trace_and_ends_the_step(recorded_states, model_I):
    """With its bristle switches located, a step whose first try is cut at a switch ends
    bit-identical (state, pair memory) to the same step asked for at the length it
    was accepted at, and no switch that matters lies earlier in it than SWITCH_WINDOW from its
    end."""
    s = spotsim.replace(model_I.scenario, simulation={"integrator": {"method": "adaptive_euler",
                                                                     "bristle_switches": "located"}})
    model = spotsim.build_model(s)
    checked = 0
    for state in recorded_states:
        first = Stepper(model, state.copy())
        start_memory = state.view().memory
        h = first.step(1e-3)
        if first.data.cut == state.cut:
            continue  # no switch cut this step
        assert switch_fraction(model.sim, start_memory, first.data.view().contacts, h) >= 1.0 - SWITCH_WINDOW
        again = Stepper(model, state.copy())
        assert again.step(h) == h
        assert_same_end(first, again)
        checked += 1
    assert checked >= 3


#: The agreement asked of the closed-form Hertz impact; the crossings are resolved to 1e-6.
ORACLE_RTOL = 1e-3


#: Gravity for the falling module, m/s^2, and the steps it is stepped with, s: they change from
#: step to step, as an adaptive step does.
FALL_G = (0.0, 0.0, -9.81)
FALL_STEPS = [1e-4, 2e-4, 3e-4, 1.5e-4, 5e-5, 2.5e-4] * 4


def falling_centroid(case_I, kick):
    """Case I in gravity, its module clear of the fingers, stepped by adaptive Euler with
    FALL_STEPS and the given kick: the steps taken, the module's centroid and its velocity at
    the start and at the end (Pinocchio's), and the velocity of its centroid in the kinematics
    the last force evaluation read and in d.now."""
    s = spotsim.replace(case_I, simulation={"gravity_m_s2": FALL_G, "integrator": {"kick": kick}})
    model = spotsim.build_model(s)
    stepper = Stepper(model)
    start = module_centroid(model, stepper.data.q, stepper.data.v)
    taken = []
    for h in FALL_STEPS:
        taken.append(stepper.step(h))
        assert len(stepper.data.contacts.key) == 0
    d, j = stepper.data, model.module_joint
    lever = model.pin_model.inertias[j].lever
    read = [f.vo_W[j] + np.cross(f.w_W[j], f.R_W[j] @ lever) for f in (d, d.now)]
    return np.array(taken), start, module_centroid(model, stepper.data.q, stepper.data.v), read


@pytest.mark.parametrize("kick", ["step", "staggered"])
def test_a_falling_module_follows_its_closed_form_whatever_the_steps(case_I, kick):
    """Symplectic Euler is the leapfrog scheme: its velocities lie half a step behind its
    positions. Under constant gravity g, with steps h_0 ... h_{N-1} that change, kicks that
    span the mean of the last step and the next (staggered) leave the velocity at half the last
    step behind the end and the position off by g t h_0 / 2 (the first step's half, as at a
    fixed step): exactly, and the last step's normal damping read the velocity of that motion,
    v0 + g (t + h_0/2), half the last step ahead of the state's, which the rest of its forces
    read (`end_forces`). Kicks that span their own steps leave the velocity at the end, where
    the forces read it, and the position off by g sum(h_k^2) / 2: an error of every change of
    step."""
    h, (x0, v0), (x, v), (read, read_normal) = falling_centroid(case_I, kick)
    g, t = np.array(FALL_G), h.sum()
    assert len(set(h)) > 1  # the steps did change
    if kick == "staggered":
        v_expected, drift = v0 + g * (t - (h[-1] - h[0]) / 2), g * t * h[0] / 2
        assert read_normal == pytest.approx(v0 + g * (t + h[0] / 2), rel=ROUND_OFF, abs=ROUND_OFF)
    else:
        v_expected, drift = v0 + g * t, g * (h ** 2).sum() / 2
    assert v == pytest.approx(v_expected, rel=ROUND_OFF, abs=ROUND_OFF)
    assert read == pytest.approx(v, rel=ROUND_OFF, abs=ROUND_OFF)
    assert x == pytest.approx(x0 + v0 * t + g * t ** 2 / 2 + drift, rel=ROUND_OFF, abs=ROUND_OFF)


#: Linear momentum's drift relative to the largest body's: one unit in the last place per step.
MOMENTUM_ROUND_OFF_PER_STEP = np.finfo(float).eps


@pytest.mark.parametrize("case", ["single_arm_case_I", "dual_arm_sequential"])
def test_staggered_kicks_keep_momentum_and_its_balance_with_the_contact_impulse(case):
    """With staggered kicks each velocity update still moves every body by the same span of
    the same internal forces, and the impulse from outside (the fixed arm's fingers on the
    module) is counted over that span: the balance holds to round-off per step, the free-
    floating robot's momentum to round-off."""
    path = CASE_I.with_name(f"{case}.yaml")
    r = spotsim.simulate(spotsim.load_scenario(path, ["simulation.integrator.kick=staggered"]))
    assert r.status == "completed"
    assert r.summary["momentum"]["linear_drift_rel"] <= MOMENTUM_ROUND_OFF_PER_STEP * r.summary["steps"]


def test_undamped_hertz_impact_matches_its_closed_form():
    """One sphere pair, c_r = 1, integrated tightly (scipy's DOP853 with the contact's crossing
    as events): peak approach, peak force and contact time to 1e-3, and it leaves as fast as
    it came. With delta = phi/2 (spotsim's reading), F = K (phi/2)^1.5 = K_phi phi^1.5 in the
    bodies' approach phi, and the closed forms hold for phi with K_phi = K / 2^1.5."""
    r1, r2, m, v0 = 0.7e-3, 0.8e-3, 1.0, 0.01
    K = hertz_stiffness(7e10, 0.25, 7e10, 0.25, r1, r2)
    K_phi = K / 2**1.5
    d_max = (5 * m * v0**2 / (4 * K_phi)) ** 0.4
    F_max, T_c = K_phi * d_max**1.5, 2.9433 * d_max / v0
    down, up, origin = np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, 1.0]), np.zeros(3)

    def contact(z, v_z):
        """phi and the force on the falling sphere A (along +z) at height z, speed v_z."""
        _, phi, hit, _ = penetration(np.array([0.0, 0.0, z]), down, r1, origin, up, r2)
        return phi, normal_force(indentation(phi), -0.5 * v_z, 1.0, K, 0.0) if hit else 0.0  # c_r = 1

    def rhs(t, y):
        return [y[1], contact(y[0], y[1])[1] / m]

    def leave(t, y):  # phi falling through zero: the spheres part
        return contact(y[0], y[1])[0]

    leave.terminal, leave.direction = True, -1
    touch = 1e-6 / v0  # it starts 1 um above contact
    out = solve_ivp(rhs, (0.0, touch + 2 * T_c), [r1 + r2 + 1e-6, -v0], method="DOP853", rtol=1e-11, atol=1e-15,
                    max_step=T_c / 2000, events=leave, dense_output=True)
    t_out = out.t_events[0][0]
    t = np.linspace(touch, t_out, 20001)
    z, v = out.sol(t)
    phis = np.array([contact(a, b)[0] for a, b in zip(z, v)])
    forces = np.array([contact(a, b)[1] for a, b in zip(z, v)])
    assert phis.max() == pytest.approx(d_max, rel=ORACLE_RTOL)
    assert forces.max() == pytest.approx(F_max, rel=ORACLE_RTOL)
    assert t_out - touch == pytest.approx(T_c, rel=ORACLE_RTOL)
    assert out.y_events[0][0][1] == pytest.approx(v0, rel=ORACLE_RTOL)  # c_r = 1: it leaves as fast as it came


BLOCK_LOAD_HELD, BLOCK_LOAD_SLIDING = 2.5, 3.5  # N, either side of mu_s F_n = 3 N
#: The bound on a held block's drift over 10 s, m.
HOLD_DRIFT_M = 1e-6
#: A sliding bristle lies at s_max, so the friction is exactly mu_k F_n: the acceleration is
#: constant up to round-off in differencing the velocity.
SLIDE_ACCEL_RTOL = 1e-9


def pressed_block(load, seconds, dt=1e-4, mass=0.1, F_n=10.0):
    """A block pressed on a plane with F_n and pulled along it by `load`, its friction the
    bristle law: positions (m) and velocities each step."""
    params = BristleParams(mu_k=0.26, mu_s=0.30, k_b=3e4, c_b=80.0, v_d=1e-3)
    normal, s, x, v = np.array([0.0, 0.0, 1.0]), (0.0, 0.0, 0.0), 0.0, 0.0
    xs, vs = [], []
    for _ in range(round(seconds / dt)):
        s, F_f, _, _, _ = bristle(s, (v, 0.0, 0.0), normal, F_n, dt, params, False)
        v += dt * (load + F_f[0]) / mass
        x += dt * v
        xs.append(x)
        vs.append(v)
    return np.array(xs), np.array(vs)


def test_pressed_block_holds_still_below_static_friction_for_10_s():
    """Pulled with 2.5 N < mu_s F_n, the block settles and then moves less than 1 um in 10 s."""
    x, _ = pressed_block(BLOCK_LOAD_HELD, 11.0)
    settled = x[round(1.0 / 1e-4)]  # after the bristle's transient (~10 ms)
    assert np.abs(x[round(1.0 / 1e-4):] - settled).max() < HOLD_DRIFT_M


def test_pressed_block_slides_with_kinetic_friction_above_static():
    """Pulled with 3.5 N > mu_s F_n, it accelerates at (load - mu_k F_n) / m."""
    dt, mass = 1e-4, 0.1
    _, v = pressed_block(BLOCK_LOAD_SLIDING, 1.0, dt=dt, mass=mass)
    a = np.diff(v[-1000:]) / dt
    assert np.allclose(a, (BLOCK_LOAD_SLIDING - 0.26 * 10.0) / mass, rtol=SLIDE_ACCEL_RTOL)


#: A step short enough to end before the drive's next reading in every recorded state.
FIRST_STEP_S = 2e-6
#: adaptive_euler's error control off: a velocity tolerance no try reaches (m/s) and an onset
#: guard no step reaches (m), so that its first try is the step.
NO_ERROR_CONTROL = {"velocity_tol_m_s": 1e3, "onset_depth_m": 1.0}
#: The new speeds: the recorded one scaled, and closing this much faster (m/s) where it held.
RATE_SCALES, EXTRA_CLOSING_M_S = (0.9, 0.5), 1e-3


def with_new_rate(model, state, scale):
    """A copy of the recorded state with a new finger speed (RATE_SCALES, EXTRA_CLOSING_M_S),
    as the drive's reading would set it (an impulse, `dynamics.velocity_jump`)."""
    data = state.copy()
    m = model.sim
    speed = -(scale * current_speed(m, data) + (1.0 - scale) * EXTRA_CLOSING_M_S)
    joints = m.actuators.joint
    velocity_jump(m, data, joints, np.full(len(joints), speed))
    data.assign(jumped=True)
    return data


def test_adaptive_euler_start_after_a_new_finger_rate_is_symplectic_eulers(recorded_states, model_I):
    """When the drive sets a new finger speed, adaptive_euler re-evaluates its start with the
    bristles bent over the coming step, as symplectic Euler evaluates every start: from a
    state in contact, with a new finger rate (so that adaptive_euler cannot reuse its last
    evaluation), one step of each (error control off) ends bit-identical. Unbent, a sliding
    pair whose limit the new rate raised would hold and add c_b v_t to its friction for the
    whole step. With step kicks: a staggered kick spans another interval than symplectic
    Euler's first step, by design."""
    models = {method: spotsim.build_model(spotsim.replace(model_I.scenario, simulation={"integrator": {
        "method": method, "kick": "step", **NO_ERROR_CONTROL}})) for method in ("symplectic_euler", "adaptive_euler")}
    checked = 0
    for state in recorded_states:
        if state.view().sample_t - state.view().t <= FIRST_STEP_S:
            continue
        for scale in RATE_SCALES:
            ends = []
            for model in models.values():
                stepper = Stepper(model, with_new_rate(model, state, scale))
                assert stepper.step(FIRST_STEP_S) == FIRST_STEP_S
                v = stepper.data.view()
                ends.append((v.q.copy(), v.v.copy()))
            for a, b in zip(*ends):
                assert np.array_equal(a, b)
            checked += 1
    assert checked >= 10


#: A step far longer than a bristle's hold after a new rate (microseconds): it holds for a
#: share of the step alone.
SHARE_STEP_S = 2e-5
#: The tolerances either side of the try's estimated error without the share, relative: far
#: tighter than the share's part in the estimate.
ESTIMATE_BRACKET = 1e-6
#: A state is checked only where the share moves the estimate by this much, relative: a
#: thousand brackets, so that tolerances a bracket either side of the estimate without the
#: share tell it from the estimate with it.
SHARE_PART_MIN = 1e3 * ESTIMATE_BRACKET


def test_adaptive_euler_judges_a_try_after_a_new_finger_rate_without_its_held_share(recorded_states, model_I):
    """The damping that a new finger speed's jump of the normal force lets a saturated bristle
    hold is a closed-form impulse over the try (`friction.bristle`), not a force the try
    samples: its error estimate leaves it out. From a state in contact, with a new finger rate
    that lets some bristle hold, adaptive_euler accepts the try at once at a velocity tolerance
    just above the try's estimated error without the share, and rejects it just below, where
    the share moves the estimate by far more than that. The step itself is symplectic Euler's
    with the share (error control off, it is that step)."""
    free = spotsim.build_model(spotsim.replace(model_I.scenario, simulation={"integrator": {
        "method": "adaptive_euler", **NO_ERROR_CONTROL}}))
    m, h = free.sim, SHARE_STEP_S
    n = m.integrator.lever.shape[0]

    def start(data, jump):
        """The error rates at data's state (`integrators.error_rates`), evaluated for a try of
        h, and how many saturated bristles held a share of it."""
        shared = forces(m, data, h, jump)
        accelerations(m, data)
        out = np.empty((n, 6))
        error_rates(m, data, out)
        return out, shared

    def first_try_accepted(state, scale, tol):
        loose = m.integrator
        m.assign(integrator=loose._replace(velocity_tol=tol))  # this test's own model
        try:
            data = with_new_rate(free, state, scale)
            taken = Stepper(free, data).step(h)
        finally:
            m.assign(integrator=loose)
        return taken == h and data.rejected == state.rejected

    checked = 0
    for state in recorded_states:
        if state.view().sample_t - state.view().t <= h:
            continue
        for scale in RATE_SCALES:
            stepper = Stepper(free, with_new_rate(free, state, scale))
            assert stepper.step(h) == h
            end = np.empty((n, 6))
            error_rates(m, stepper.data, end)
            probe = with_new_rate(free, state, scale)
            if stepper.broad is not None:
                stepper.broad.refresh(probe)  # the pairs the step found
            held, shared = start(probe, True)
            plain, _ = start(probe, False)
            # error ratios against the model's tolerance, which scales them
            with_share, without = euler_error(m, held, end, h), euler_error(m, plain, end, h)
            if shared == 0 or abs(with_share / without - 1.0) < SHARE_PART_MIN:
                continue  # nothing held, or too little to tell the two estimates apart
            estimate = m.integrator.velocity_tol * without
            assert first_try_accepted(state, scale, estimate * (1.0 + ESTIMATE_BRACKET))
            assert not first_try_accepted(state, scale, estimate * (1.0 - ESTIMATE_BRACKET))
            checked += 1
    assert checked >= 3


def test_onset_guard_takes_the_clearance_only_where_asked_and_known(model_I, recorded_states):
    """`onset_guard: clearance`: at a state its last search was made at, the guard allows a
    step that closes the clearance as well as the onset depth at the face pairs' own approach
    rate (where it is below the bound on any two spheres'), longer than the travel guard's
    wherever the search found a clearance; once the broad phase's face pairs are set anew, that
    clearance no longer holds and the step's closing is the onset depth alone."""
    fields = model_I.sim.fields
    by_travel, clear = (sim_model(fields._replace(integrator=fields.integrator._replace(onset_clearance=c)))
                        for c in (False, True))
    depth = fields.integrator.onset_depth
    longer = 0
    for state in recorded_states:
        d = state.copy()
        travel = onset_step(by_travel, d)
        rate = min(travel_rate(model_I.sim, d), approach_rate(clear, d))
        assert onset_step(clear, d) == pytest.approx((d.candidates.clearance + depth) / rate, rel=SAME_FORMULA_RTOL)
        assert onset_step(clear, d) >= travel
        longer += onset_step(clear, d) > travel
        set_near(d, d.near.copy())
        assert onset_step(clear, d) == pytest.approx(depth / rate, rel=SAME_FORMULA_RTOL)
    assert longer > len(recorded_states) // 2


def test_approach_rate_bounds_how_fast_the_spheres_of_near_face_pairs_close(model_I, recorded_states):
    """At contact states given random body velocities (up to 50 mm/s and 1 rad/s on the module
    and 50 mm/s on each finger), no master and slave sphere of a face pair in d.near that lie
    within reach of touching (their gap at most LIST_SKIN plus the onset depth) close faster
    than `approach_rate`, every pair's closing speed computed from the bodies' motion."""
    rng = np.random.default_rng(9)
    m = model_I.sim
    iv = model_I.pin_model.idx_vs[model_I.module_joint]
    R = m.law.r1 + m.law.r2
    reach = R + LIST_SKIN + m.integrator.onset_depth
    checked = 0
    for k in range(20):
        d = recorded_states[k % len(recorded_states)].copy()
        d.v[iv:iv + 3] = rng.uniform(-0.05, 0.05, 3)
        d.v[iv + 3:iv + 6] = rng.uniform(-1.0, 1.0, 3)
        for f in model_I.fingers:
            d.v[model_I.pin_model.idx_vs[f.joint]] = rng.uniform(-0.05, 0.05)
        kinematics(m, d)
        C1, _, C2, _ = world_spheres(m, d)
        bound = approach_rate(m, d)
        for f in d.near:
            jm, js = m.faces.master_joint[f], m.faces.slave_joint[f]
            rows = np.arange(m.faces.master_start[f], m.faces.master_stop[f])
            cols = np.flatnonzero(m.slave.face == m.faces.slave_face[f])
            e = C1[rows, None, :] - C2[None, cols, :]
            dist = np.linalg.norm(e, axis=2)
            near = dist <= reach
            if not near.any():
                continue
            v1 = d.vo_W[jm] + np.cross(d.w_W[jm], C1[rows] - d.p_W[jm])
            v2 = d.vo_W[js] + np.cross(d.w_W[js], C2[cols] - d.p_W[js])
            closing = -np.einsum("ijk,ijk->ij", e, v1[:, None, :] - v2[None, :, :]) / dist
            assert closing[near].max() <= bound * (1 + SAME_FORMULA_RTOL)
            checked += int(near.sum())
    assert checked > 1000


def test_clearance_guard_keeps_a_new_pairs_first_penetration_within_the_onset_depth(case_I):
    """Along Case I's approach and self-centring with `onset_guard: clearance`, every pair that
    starts is no deeper than the onset depth at the first evaluation that finds it: the
    travel guard's promise, kept with steps that also close the clearance."""
    s = spotsim.replace(case_I, simulation={"integrator": {"onset_guard": "clearance"}})
    model = spotsim.build_model(s)
    stepper, m = Stepper(model), model.sim
    d = stepper.data
    before, new = set(), []
    while d.t < 0.8:
        stepper.step(min(d.h_next if d.h_next > 0 else m.h, next_event(m, d) - d.t))
        keys = d.contacts.key
        new += [float(d.contacts.phi[i]) for i, k in enumerate(keys) if k not in before]
        before = set(keys.tolist())
    assert len(new) > 300
    assert max(new) <= s.simulation.integrator.onset_depth_m

"""The broad phase's Verlet skin and the search's pair list never lose a contact."""

import numpy as np
import pinocchio as pin

from spotsim.contact.search import (
    GAP_SLACK,
    _moved,
    by_key,
    empty_pair_list,
    face_frame,
    grid_search,
    listed_search,
    world_spheres,
)
from spotsim.run import Stepper
from spotsim.sim.broadphase import BroadPhase
from spotsim.sim.step import travel_rate
from spotsim.sim.tree import kinematics

H = 1e-4


def test_reused_face_pairs_find_every_contact(model_I):
    """Along Case I, the skin-reused face pairs give the same sphere pairs as a fresh broad phase."""
    stepper = Stepper(model_I)
    fresh_phase = BroadPhase(model_I)
    checked = reused = 0
    while stepper.data.t < 0.75:
        stepper.step(H)
        data = stepper.data
        if data.t > 0.42 and round(data.t / H) % 25 == 0:
            snap = data.copy()
            kinematics(model_I.sim, snap)
            fresh = grid_search(model_I.sim, snap, fresh_phase.near(snap.q))
            kept = grid_search(model_I.sim, snap, snap.near)
            assert np.array_equal(fresh.key, kept.key)
            checked += 1
            reused += snap.travel > 0
    assert checked > 10 and reused > 0


def test_travel_rate_bounds_the_fingers_and_the_module(model_I):
    """The travel bound counts at least the closing fingers' speed once they move."""
    stepper = Stepper(model_I)
    stepper.step(H)
    assert travel_rate(model_I.sim, stepper.data) >= model_I.scenario.end_effector.closing_speed_m_s


def both_searches(model, data, near, pair_list):
    """(grid search's pairs, the listed search's pairs, the list after it, whether it was
    rebuilt) at data's state (a copy; data is left as it is)."""
    x = data.copy()
    x.assign(near=np.asarray(near, dtype=np.int64), pair_list=pair_list)
    listed = listed_search(model.sim, x)
    kept = x.pair_list
    return grid_search(model.sim, x, x.near), listed, kept, not np.shares_memory(kept.gap, pair_list.gap)


#: The pair-list check compares the searches at every CHECK_EVERY-th step of the run (the list
#: lives across steps either way; along Case I's contact 3 gives about 38,000 pairs compared,
#: 1,500 rebuilt lists and 3,000 reused ones): every step took 50 s of the suite.
CHECK_EVERY = 3
#: Distances of ~1 mm computed two ways (the search's face coordinates, world coordinates here)
#: agree to ~1e-18 m; this slack lies far above that and far below the 1 um onset depth.
CLEARANCE_ROUND_OFF_M = 1e-12


def test_pair_list_finds_exactly_the_grid_search_pairs(model_I):
    """Along Case I's self-centring, the pairs tested from the kept pair list are exactly the
    grid search's at every third step, and the list is reused between its rebuilds."""
    stepper = Stepper(model_I)
    reused = rebuilt = found = steps = 0
    while stepper.data.t < 0.75:
        v = stepper.data.view()
        steps += 1
        if v.t > 0.42 and len(v.near) and steps % CHECK_EVERY == 0:
            snap = stepper.data.copy()
            kinematics(model_I.sim, snap)
            grid, listed, _, fresh = both_searches(model_I, snap, v.near, v.pair_list)
            assert np.array_equal(grid.key, listed.key) and np.array_equal(grid.master, listed.master)
            found += len(grid.key)
            rebuilt += fresh
            reused += not fresh
        stepper.step(H)
    assert found > 1000 and rebuilt > 10 and reused > rebuilt


def test_kept_pair_list_finds_the_grid_search_pairs_after_any_small_motion(model_I, recorded_states):
    """A list built at a contact state and kept while the module is then moved at random (up
    to 40 um and 1 mrad, in any direction) and the fingers slide: wherever the list is kept,
    its pairs, tested only among the candidates whose gap the motion could have closed, are
    exactly the grid search's. The motion is checked against the two poses, not integrated."""
    rng = np.random.default_rng(3)
    m = model_I.sim
    iq = model_I.pin_model.idx_qs[model_I.module_joint]
    near = np.arange(len(m.faces.master_start))
    kept = skipped = found = 0
    for k in range(200):
        data = recorded_states[k % len(recorded_states)].copy()
        kinematics(m, data)
        _, _, built, _ = both_searches(model_I, data, near, empty_pair_list(len(near)))
        axis = rng.normal(size=3)
        turn = pin.Quaternion(pin.AngleAxis(rng.uniform(0.0, 1e-3), axis / np.linalg.norm(axis)))
        q = data.q
        quat = pin.Quaternion(q[iq + 6], *q[iq + 3:iq + 6]) * turn
        q[iq + 3:iq + 7] = quat.coeffs()
        q[iq:iq + 3] += rng.uniform(-40e-6, 40e-6) * rng.normal(size=3) / np.sqrt(3)
        for f in model_I.fingers:  # the fingers slide on their joints
            data.q[model_I.pin_model.idx_qs[f.joint]] += rng.uniform(-20e-6, 20e-6)
        kinematics(m, data)
        grid, listed, _, fresh = both_searches(model_I, data, near, built)
        assert np.array_equal(grid.key, listed.key)
        found += len(grid.key)
        if not fresh:
            kept += 1
            for f in near:  # candidates left untested: their gap exceeds the motion's bound
                if built.scan[f] or built.stop[f] == built.start[f]:
                    continue
                A = np.empty((3, 3))
                frame = face_frame(m, data, f, A)
                moved = _moved(A, frame.off, built.A[f], built.off[f], m.faces.master_centre_J[f],
                               m.faces.master_radius[f])
                skipped += int(np.sum(built.gap[built.start[f]:built.stop[f]] > moved + GAP_SLACK))
    assert found > 100 and kept > 20 and skipped > 0


def test_pair_list_falls_back_to_the_grid_search_off_the_ball_regime(model_I, recorded_states):
    """On poses of the module tilted and shifted at random about contact states (up to 60
    degrees, where some face pairs leave the ball regime and are searched anew), a freshly
    built list gives exactly the grid search's pairs."""
    rng = np.random.default_rng(7)
    m = model_I.sim
    iq = model_I.pin_model.idx_qs[model_I.module_joint]
    near = np.arange(len(m.faces.master_start))
    scanned = found = 0
    for k in range(300):
        data = recorded_states[k % len(recorded_states)].copy()
        axis = rng.normal(size=3)
        angle = np.radians(rng.uniform(0.0, 60.0 if k % 2 else 3.0))
        turn = pin.Quaternion(pin.AngleAxis(angle, axis / np.linalg.norm(axis)))
        q = data.q
        quat = pin.Quaternion(q[iq + 6], *q[iq + 3:iq + 6]) * turn
        q[iq + 3:iq + 7] = quat.coeffs()
        q[iq:iq + 3] += rng.normal(scale=0.3e-3, size=3)
        kinematics(m, data)
        grid, listed, pair_list, _ = both_searches(model_I, data, near, empty_pair_list(len(near)))
        assert np.array_equal(grid.key, listed.key)
        found += len(grid.key)
        # face pairs that face each other yet are searched anew: the fallback at work
        scanned += any(pair_list.scan[f] and face_frame(m, data, f, np.empty((3, 3))).facing for f in near)
    assert found > 100 and scanned > 0


def test_found_pairs_are_put_in_key_order_at_any_count():
    """The listed search's ordering (insertion up to 64 pairs, argsort past them) gives the
    pairs sorted by key, as np.argsort does, with master and slave kept together."""
    rng = np.random.default_rng(11)
    n_slave = 5000
    for n in (0, 1, 7, 64, 65, 300):
        keys = rng.choice(400 * n_slave, size=n, replace=False)  # unique, as a step's pairs are
        master, slave = keys // n_slave, keys % n_slave
        order = np.argsort(keys)
        found = by_key(master.copy(), slave.copy(), n_slave, 0.0)
        assert np.array_equal(found.key, keys[order])
        assert np.array_equal(found.master, master[order]) and np.array_equal(found.slave, slave[order])


def brute_clearance(m, data, near, candidates) -> float:
    """The least |c1 - c2| - (r1 + r2) over the sphere pairs of the face pairs `near` that are
    not among `candidates`, every distance computed."""
    C1, _, C2, _ = world_spheres(m, data)
    faces, n_slave, R = m.faces, C2.shape[0], m.law.r1 + m.law.r2
    slave = np.arange(n_slave)
    listed = set(candidates.key.tolist())
    least = np.inf
    for f in near:
        rows = np.arange(faces.master_start[f], faces.master_stop[f])
        cols = slave[m.slave.face == faces.slave_face[f]]
        gap = np.linalg.norm(C1[rows, None, :] - C2[None, cols, :], axis=2) - R
        keys = rows[:, None] * n_slave + cols[None, :]
        other = ~np.isin(keys, list(listed)) if listed else np.ones(keys.shape, dtype=bool)
        least = min(least, gap[other].min(initial=np.inf))
    return least


def test_listed_search_bounds_the_clearance_of_every_other_pair(model_I, recorded_states):
    """The onset guard's clearance (`Candidates.clearance`): on contact states moved at random
    after the list was built (up to 40 um and 1 mrad, or turned up to 0.5 rad), it never exceeds
    the least distance between the spheres of any pair of the state's face pairs that the
    search did not return (all of them computed), it is 0 when a face pair is searched anew
    (off the ball regime), and it is not 0 everywhere."""
    rng = np.random.default_rng(5)
    m = model_I.sim
    iq = model_I.pin_model.idx_qs[model_I.module_joint]
    positive = scanned = 0
    for k in range(40):
        data = recorded_states[k % len(recorded_states)].copy()
        near = data.view().near.copy()  # the broad phase's face pairs at that state
        kinematics(m, data)
        _, _, built, _ = both_searches(model_I, data, near, empty_pair_list(len(near)))
        axis = rng.normal(size=3)
        turn = pin.Quaternion(pin.AngleAxis(rng.uniform(0.0, 1e-3 if k % 4 else 0.5), axis / np.linalg.norm(axis)))
        q = data.q
        q[iq + 3:iq + 7] = (pin.Quaternion(q[iq + 6], *q[iq + 3:iq + 6]) * turn).coeffs()
        q[iq:iq + 3] += rng.uniform(-40e-6, 40e-6) * rng.normal(size=3) / np.sqrt(3)
        kinematics(m, data)
        _, listed, kept, _ = both_searches(model_I, data, near, built)
        assert 0.0 <= listed.clearance <= max(brute_clearance(m, data, near, listed), 0.0) + CLEARANCE_ROUND_OFF_M
        if any(kept.scan[f] for f in near):
            scanned += 1
            assert listed.clearance == 0.0
        positive += listed.clearance > 0.0
    assert positive > 10 and scanned > 0

"""The broad phase's Verlet skin: reusing coal's face pairs never loses a contact."""

import numpy as np
import pinocchio as pin

from conftest import restore
from spotsim.step import broad_phase, candidate_pairs, kinematics, make_data, step, travel_rate
from spotsim.contact.search import empty_pair_list
from spotsim.integrators import make_integrator


def test_reused_face_pairs_find_every_contact(model_I):
    """Along Case I, the skin-reused face pairs give the same sphere pairs as a fresh broad phase."""
    data = make_data(model_I)
    integrator = make_integrator("symplectic_euler", model_I.pin_model)
    h = 1e-4
    checked = reused = 0
    while data.t < 0.75:
        step(model_I, data, h, integrator)
        if data.t > 0.42 and round(data.t / h) % 25 == 0:
            snap = restore(data)
            kinematics(model_I, snap)
            fresh = candidate_pairs(model_I, snap, broad_phase(model_I, snap))
            kept = candidate_pairs(model_I, snap, data.near_pairs)
            assert np.array_equal(fresh[2], kept[2])  # keys, sorted
            checked += 1
            reused += data.travel > 0
    assert checked > 10 and reused > 0


def test_travel_rate_bounds_the_fingers_and_the_module(model_I):
    """The travel bound counts at least the closing fingers' speed once they move."""
    data = make_data(model_I)
    integrator = make_integrator("symplectic_euler", model_I.pin_model)
    step(model_I, data, 1e-4, integrator)
    assert travel_rate(model_I, data) >= model_I.scenario.end_effector.closing_speed_m_s


def _both_searches(model, data, near, pair_list):
    """(grid search's pairs, the pair list's pairs, the list after the search, whether it was
    rebuilt) at data's state."""
    from spotsim.contact.search import listed_search

    M, p = model.master, model.params
    args = (np.asarray(near, dtype=np.int64), model.face_table, M.centres_J, M.normals_J, model.master_finger,
            model.master_axis_J, data.opening, model.slave_maps, len(model.slave.centres_J), data.R_W, data.p_W,
            p.r1, p.r2, p.cutoff)
    listed, kept = listed_search(*args, pair_list)
    return candidate_pairs(model, data, near), listed, kept, kept.gap is not pair_list.gap


def test_pair_list_finds_exactly_the_grid_search_pairs(model_I):
    """Along Case I's self-centring, the pairs tested from the kept pair list are exactly the
    grid search's, step by step, and the list is reused between its rebuilds."""
    data = make_data(model_I)
    integrator = make_integrator("symplectic_euler", model_I.pin_model)
    h = 1e-4
    reused = rebuilt = found = 0
    while data.t < 0.75:
        if data.t > 0.42 and len(data.near_pairs):
            snap = restore(data)
            kinematics(model_I, snap)
            grid, listed, _, fresh = _both_searches(model_I, snap, data.near_pairs, data.pair_list)
            for a, b in zip(grid, listed):
                assert np.array_equal(a, b)
            found += len(grid[2])
            rebuilt += fresh
            reused += not fresh
        step(model_I, data, h, integrator)
    assert found > 1000 and rebuilt > 10 and reused > rebuilt


def test_kept_pair_list_finds_the_grid_search_pairs_after_any_small_motion(model_I, recorded_states):
    """A list built at a contact state and kept while the module is then moved at random (up
    to 40 um and 1 mrad, in any direction) and the fingers slide: wherever the list is kept,
    its pairs, tested only among the candidates whose gap the motion could have closed, are
    exactly the grid search's. The motion is checked against the two poses, not integrated."""
    from spotsim.contact.search import GAP_SLACK, _face_frame, _moved

    rng = np.random.default_rng(3)
    j = model_I.module_joint
    iq = model_I.pin_model.idx_qs[j]
    M = model_I.master
    kept = skipped = found = 0
    for k in range(200):
        data = restore(recorded_states[k % len(recorded_states)])
        kinematics(model_I, data)
        near = np.arange(len(model_I.face_pairs))
        _, _, built, _ = _both_searches(model_I, data, near, empty_pair_list(len(model_I.face_pairs)))
        axis = rng.normal(size=3)
        turn = pin.Quaternion(pin.AngleAxis(rng.uniform(0.0, 1e-3), axis / np.linalg.norm(axis)))
        quat = pin.Quaternion(data.q[iq + 6], *data.q[iq + 3:iq + 6]) * turn
        data.q[iq + 3:iq + 7] = quat.coeffs()
        data.q[iq:iq + 3] += rng.uniform(-40e-6, 40e-6) * rng.normal(size=3) / np.sqrt(3)
        data.opening = data.opening + rng.uniform(-20e-6, 20e-6, size=data.opening.shape)
        kinematics(model_I, data)
        grid, listed, after, fresh = _both_searches(model_I, data, near, built)
        for a, b in zip(grid, listed):
            assert np.array_equal(a, b)
        found += len(grid[2])
        if not fresh:
            kept += 1
            for f in near:  # candidates left untested: their gap exceeds the motion's bound
                if built.scan[f] or built.stop[f] == built.start[f]:
                    continue
                A = np.empty((3, 3))
                frame = _face_frame(f, model_I.face_table, M.normals_J, model_I.master_finger, model_I.master_axis_J,
                                    data.opening, data.R_W, data.p_W, A)
                table = model_I.face_table
                moved = _moved(A, frame[4], built.A[f], built.off[f], table.master_centre_J[f],
                               table.master_radius[f])
                skipped += int(np.sum(built.gap[built.start[f]:built.stop[f]] > moved + GAP_SLACK))
    assert found > 100 and kept > 20 and skipped > 0


def test_pair_list_falls_back_to_the_grid_search_off_the_ball_regime(model_I, recorded_states):
    """On poses of the module tilted and shifted at random about contact states (up to 60
    degrees, where some face pairs leave the ball regime and are searched anew), a freshly
    built list gives exactly the grid search's pairs."""
    from spotsim.contact.search import _face_frame

    rng = np.random.default_rng(7)
    j = model_I.module_joint
    iq = model_I.pin_model.idx_qs[j]
    scanned = found = 0
    for k in range(300):
        data = restore(recorded_states[k % len(recorded_states)])
        axis = rng.normal(size=3)
        angle = np.radians(rng.uniform(0.0, 60.0 if k % 2 else 3.0))
        turn = pin.Quaternion(pin.AngleAxis(angle, axis / np.linalg.norm(axis)))
        quat = pin.Quaternion(data.q[iq + 6], *data.q[iq + 3:iq + 6]) * turn
        data.q[iq + 3:iq + 7] = quat.coeffs()
        data.q[iq:iq + 3] += rng.normal(scale=0.3e-3, size=3)
        kinematics(model_I, data)
        near = np.arange(len(model_I.face_pairs))
        grid, listed, pair_list, _ = _both_searches(model_I, data, near, empty_pair_list(len(near)))
        for a, b in zip(grid, listed):
            assert np.array_equal(a, b)
        found += len(grid[2])
        # face pairs that face each other yet are searched anew: the fallback at work
        M = model_I.master
        scanned += any(pair_list.scan[f] and _face_frame(f, model_I.face_table, M.normals_J, model_I.master_finger,
                                                      model_I.master_axis_J, data.opening, data.R_W, data.p_W,
                                                      np.empty((3, 3)))[0]
                       for f in near)
    assert found > 100 and scanned > 0


def test_found_pairs_are_put_in_key_order_at_any_count():
    """The listed search's ordering (insertion up to 64 pairs, argsort past them) gives the
    pairs sorted by key, as np.argsort does, with master and slave kept together."""
    from spotsim.contact.search import _by_key

    rng = np.random.default_rng(11)
    n_slave = 5000
    for n in (0, 1, 7, 64, 65, 300):
        keys = rng.choice(400 * n_slave, size=n, replace=False)  # unique, as a step's pairs are
        master, slave = keys // n_slave, keys % n_slave
        order = np.argsort(keys)
        m, s, k = _by_key(master.copy(), slave.copy(), n_slave)
        assert np.array_equal(k, keys[order])
        assert np.array_equal(m, master[order]) and np.array_equal(s, slave[order])

"""The study runner: one `execute` on three backends, the same records on each; a worker's
death, a task's failure and Ctrl-C handled alike; a worker's models."""

import functools
import os

import numpy as np
import pytest
from conftest import CASE_I

import spotsim
from spotsim import SpotsimError, load_scenario
from spotsim.status import EXCEPTION, WORKER_DIED
from spotsim.studies import runner as rn

TWICE = functools.partial(pow, 2)  # a picklable run function every backend can import: 2**task


def _run_all(runner, tasks, more=None):
    """execute's records by task, with `more(task)` giving each finished task's followers."""
    records, order = {}, []

    def finished(task, record):
        records[task] = record
        order.append(task)
        return more(task) if more else None

    ran = rn.execute(TWICE, tasks, runner, finished, lambda task, e: (EXCEPTION, repr(e)))
    return ran, records, order


@pytest.mark.parametrize("backend", [rn.SERIAL, rn.PROCESSES, rn.DASK])
def test_every_backend_gives_every_record_and_follows_each_tasks_followers(backend):
    """Tasks 0..3, each bringing task + 10 once: eight records, 2**task each, on every backend."""
    ran, records, _ = _run_all(rn.Runner(backend, workers=2), range(4), lambda t: [t + 10] if t < 10 else [])
    assert ran == 8 and records == {t: 2**t for t in (0, 1, 2, 3, 10, 11, 12, 13)}


def test_no_tasks_start_no_workers(monkeypatch):
    """A study with nothing left to run (every record found) starts no pool and no cluster."""
    monkeypatch.setattr(rn, "dask_client", None)  # would raise if called
    monkeypatch.setattr(rn, "_on_processes", None)
    for backend in rn.BACKENDS:
        assert rn.execute(TWICE, [], rn.Runner(backend), lambda t, r: None, lambda t, e: None) == 0


def _dies_on_three(task):
    if task == 3:
        os._exit(9)  # the worker process dies, as a crash in compiled code would end it
    return 2**task


def test_a_task_whose_worker_dies_is_tried_again_then_failed_and_the_others_run():
    """On the process pool, the task that kills its worker is tried once more, then recorded by
    `failed` as its worker's death; every other task gets its own record."""
    records = {}

    def failed(task, e):
        return WORKER_DIED if rn.worker_died(e) else EXCEPTION

    ran = rn.execute(_dies_on_three, range(6), rn.Runner(rn.PROCESSES, workers=2),
                     lambda t, r: records.__setitem__(t, r), failed)
    assert ran == 6 and records[3] == WORKER_DIED
    assert {t: r for t, r in records.items() if t != 3} == {t: 2**t for t in (0, 1, 2, 4, 5)}


@pytest.mark.parametrize("backend", [rn.SERIAL, rn.PROCESSES])
def test_ctrl_c_stops_the_runs_after_the_records_handed_back(backend):
    """KeyboardInterrupt out of the study's own hand (here its third record) ends execute with
    KeyboardInterrupt; the records handed back before stay the study's, the workers stop."""
    seen = []

    def finished(task, record):
        seen.append(record)
        if len(seen) == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        rn.execute(TWICE, range(50), rn.Runner(backend, workers=2), finished, lambda t, e: None)
    assert len(seen) == 3 and set(seen) <= {2**t for t in range(50)}


def test_a_runner_refuses_what_it_cannot_do():
    with pytest.raises(SpotsimError, match="backend 'threads'"):
        rn.Runner("threads")
    with pytest.raises(SpotsimError, match="runs on the dask backend, not processes"):
        rn.Runner(rn.PROCESSES, scheduler="tcp://127.0.0.1:8786")
    with pytest.raises(SpotsimError, match="workers = 0"):
        rn.Runner(workers=0)


def test_an_ensemble_gives_the_same_members_here_in_a_pool_and_on_dask(case_I):
    """Three members of a shortened Case I: the same summaries in this process, in a pool of
    two and on a local Dask cluster of two."""
    short = spotsim.replace(case_I, simulation={"duration_s": 0.45})
    model = spotsim.build_model(short)

    def members(runner):
        e = spotsim.ensemble(short, 3, seed=4, model=model, runner=runner)
        return [(m.status, m.summary["grasps"][0]["peak_force_norm_N"], m.summary["steps"]) for m in e.members]

    here = members(rn.Runner(rn.SERIAL))
    assert here == members(rn.Runner(rn.PROCESSES, workers=2)) == members(rn.Runner(rn.DASK, workers=2))
    assert len({peak for _, peak, _ in here}) == 3  # three starts, three runs


def test_a_worker_reuses_a_model_across_starts_and_a_compiled_scene_across_contact_parameters():
    """Models from the worker's caches are those built from scratch."""
    from spotsim.assemble.model import build_model

    rn._MODELS.clear()
    rn._SCENES.clear()
    a = load_scenario(CASE_I)
    b = load_scenario(CASE_I, ["module.initial_offset_mm.1=-2.0"])
    c = load_scenario(CASE_I, ["friction.mu_k=0.3", "contact.restitution=0.6"])
    ma, mb, mc = rn.model_for(a), rn.model_for(b), rn.model_for(c)
    assert mb.pin_model is ma.pin_model  # with_start: the Pinocchio model shared
    assert mc.urdf is ma.urdf and len(rn._SCENES) == 1 and len(rn._MODELS) == 2
    for cached, scenario in ((mb, b), (mc, c)):
        fresh = build_model(scenario)
        assert np.array_equal(cached.q0, fresh.q0) and cached.law == fresh.law

"""The record intervals of a run, compiled: steps, records, and why the loop stops.

A record interval of dt is one free-flight step when nothing can touch within it
(`step.free_flight`), else `substeps` steps of dt / substeps (an adaptive integrator: its own
steps until dt is covered). Each ends with a record (`record.close_interval`). The loop returns
to Python when coal's face pairs must be refreshed (the Verlet skin is used up), when its row
buffer is full, when the grasp phase completes or times out, or when the run diverges.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..contact.search import Candidates
from ..jit import njit
from ..tables import COMPLETE
from .actuation import current_speed, next_event
from .events import RAN, REFRESH, STOPPED, TOO_DEEP, UNDERFLOW
from .phase import HOLD_ROUND_OFF_S
from .record import close_interval
from .step import free_flight, step

#: An adaptive integrator's interval is covered once less than this share of dt is left.
INTERVAL_COVERED = 1e-9


class Progress(NamedTuple):
    """What a call of the loop tells Python: why it returned, where the run is, and what it
    recorded (the first n_rows of rows, the first n_snapshots snapshots)."""

    event: int  # `events`
    t: float  # s
    travel: float  # the broad phase's travel since its last run, m
    active: int  # the grasp under way
    complete: bool  # it is complete
    elapsed: float  # s since its drive started
    rows: np.ndarray
    n_rows: int
    snapshots: object  # data.Snapshots
    n_snapshots: int
    n_snapshot_pairs: int


@njit
def progress_of(d, event):
    """The Progress of d after the loop returned `event`."""
    g = d.active
    return Progress(event, d.t, d.travel, g, d.phase[g] == COMPLETE, d.t - d.t_start[g], d.rows, d.n_rows,
                    d.snapshots, d.n_snapshots, d.n_snapshot_pairs)


@njit
def skin_used(m, d):
    """Whether coal's face pairs must be refreshed before the next step (culled search only)."""
    return not m.literal and d.travel > m.limits.skin


@njit
def phase_ended(m, d):
    """Whether the active grasp's phase ended: it timed out, or it completed (the last grasp
    `record_after` before, the run recording what rings after it)."""
    g = d.active
    if d.phase[g] == COMPLETE:
        return g + 1 < m.grasps.ee.shape[0] or d.t - d.t_complete[g] >= m.completion.record_after - HOLD_ROUND_OFF_S
    return d.t - d.t_start[g] > m.completion.phase_timeout


@njit
def set_near(d, near):
    """The broad phase's face pairs `near`, fresh: the travel since starts at zero, and the
    last search's clearance no longer holds (it knew only the face pairs before) until the
    next search."""
    d.near = near
    d.travel = 0.0
    c = d.candidates
    d.candidates = Candidates(c.master, c.slave, c.key, 0.0)


@njit
def begin_interval(m, d):
    """Set up the next record interval: one free-flight step of dt, or steps of dt / substeps
    (an adaptive integrator's own, up to dt)."""
    d.flight = free_flight(m, d)
    d.flights += d.flight
    d.t_end = d.t + m.dt
    if d.flight:
        d.left, d.h = 1, m.dt
    elif m.integrator.adaptive:
        d.left, d.h = 1, m.h
    else:
        d.left, d.h = m.substeps, m.h
    d.held = current_speed(m, d) == 0.0  # the drive holds through the interval so far


@njit
def interval_steps(m, d):
    """The steps left in the interval under way (fewer if the loop must return): RAN, or why
    it stopped early (REFRESH, STOPPED, TOO_DEEP, UNDERFLOW)."""
    adaptive = m.integrator.adaptive and not d.flight
    while d.left > 0:
        # an adaptive step: its last estimate (before any, the interval's step), up to the
        # interval's end and the Model's next event (a controller's reading)
        h = step(m, d, min(d.h_next if d.h_next > 0.0 else d.h, d.t_end - d.t, next_event(m, d) - d.t)
                 if adaptive else d.h)
        if h == 0.0:
            return UNDERFLOW
        if adaptive:
            d.left = 1 if d.t_end - d.t > INTERVAL_COVERED * m.dt else 0
        else:
            d.left -= 1
        if d.contacts.key.shape[0] and d.summary.max_penetration > m.limits.max_penetration:
            return TOO_DEEP
        if phase_ended(m, d) or (d.phase[d.active] == COMPLETE and d.t == d.t_complete[d.active]):
            return STOPPED  # (a completion ends its interval: a row at it, the window's rows after)
        if skin_used(m, d) and d.left > 0:
            return REFRESH
    return RAN


@njit
def run_intervals(m, d, n_records):
    """Up to n_records record intervals of the active grasp (at most d.rows' length), their
    rows and snapshots into d.rows and d.snapshots: their Progress (event RAN when all
    n_records rows are written).

    Enter with coal's face pairs fresh (d.travel within the skin) or within an interval: it
    then takes at least one step.
    """
    d.n_rows = d.n_snapshots = d.n_snapshot_pairs = 0
    return progress_of(d, _intervals(m, d, n_records))


@njit
def _intervals(m, d, n_records):
    while True:
        if d.left == 0:
            if skin_used(m, d):
                return REFRESH
            begin_interval(m, d)
        event = interval_steps(m, d)
        if event == REFRESH or event == TOO_DEEP or event == UNDERFLOW:
            return event
        d.left = 0  # the interval ends here (early if its phase ended)
        event = close_interval(m, d)
        if event != RAN:  # a divergence
            return event
        if phase_ended(m, d):
            return STOPPED
        if d.n_rows == n_records:
            return RAN

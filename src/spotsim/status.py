"""What a run ended as: its status, said once for `simulate` and every study that runs it.

The simulator's own: `completed` (every grasp closed within its grooves), `not captured`
(every grasp closed, one with a finger outside its groove: on a land or a mouth's edge beside
it, `scenario.in_grooves`), `incomplete` (a grasp not closed by its time-out), `diverged`,
`interrupted` (Ctrl-C) and `wall limit` (its wall-time budget spent: no verdict). A study's
run can also end `rejected` (an invalid scenario, or a start whose fingers and groove
interpenetrate), `exception` (something raised out of the run: a bug to report) or, on Dask,
`worker died` (its worker died twice under it).

What a grasp came to, its **outcome**, is said here too, for runs, ensembles, sweeps, envelopes
and the stability study alike: `seated` (closed within its grooves, its residual tilt and
offset within WEDGED_TILT_DEG and WEDGED_OFFSET_MM), `wedged` (closed within its grooves,
beyond them), `not captured` (closed with a finger outside its groove), `incomplete` (not
closed by the time-out) or `diverged`. A run's outcome is its grasps' worst.
"""

COMPLETED, NOT_CAPTURED, INCOMPLETE = "completed", "not captured", "incomplete"
DIVERGED, INTERRUPTED, WALL_LIMIT = "diverged", "interrupted", "wall limit"
REJECTED, EXCEPTION, WORKER_DIED = "rejected", "exception", "worker died"
#: Runs that ended on their physics, to their end: their records compare with a reference's.
COMPARABLE = (COMPLETED, NOT_CAPTURED, INCOMPLETE)

SEATED, WEDGED = "seated", "wedged"
#: A closed grasp is `wedged` when its residual tilt max(|roll|, |pitch|) exceeds WEDGED_TILT_DEG
#: or its residual offset exceeds WEDGED_OFFSET_MM; else `seated`. Measured at a converged step
#: (12.5 us; 287 completed members of Cases I-III with the earlier kinematic drive), completed
#: grasps fell in two groups with nothing between: seated, 0.09-0.30 mm off and rolled
#: 0.27-0.99 deg, and wedged, 0.46-0.51 mm off and rolled 1.57-1.71 deg. The module rolls about
#: x_a as it is left off along y_a (3.0-3.4 deg per mm in both groups, pitch under 0.03 deg), so
#: each threshold sits in the middle of the same empty gap. With the motor drive every measured
#: grasp lies far inside (micrometres, 0.01 deg).
WEDGED_TILT_DEG = 1.25
WEDGED_OFFSET_MM = 0.38
#: The outcomes, worst first: a run's is its grasps' first in this order.
OUTCOMES = (DIVERGED, NOT_CAPTURED, INCOMPLETE, WEDGED, SEATED)


def grasp_outcome(status: str, grasp: dict | None, offset_mm: float = WEDGED_OFFSET_MM,
                  tilt_deg: float = WEDGED_TILT_DEG) -> str:
    """A grasp's outcome from its run's status and its summary entry: `seated` or `wedged` when
    it closed within its grooves (`offset_mm`, `tilt_deg`), `not captured` when it closed with
    a finger outside them; a grasp that did not close takes its run's status (`incomplete` for
    a run that closed its other grasps)."""
    if grasp is None or grasp.get("completed_s") is None:
        return INCOMPLETE if status in (COMPLETED, NOT_CAPTURED) else status
    if grasp.get("in_grooves") is False:
        return NOT_CAPTURED
    roll, pitch, _ = grasp["residual_rpy_deg"]
    wedged = max(abs(roll), abs(pitch)) > tilt_deg or grasp["residual_offset_norm_mm"] > offset_mm
    return WEDGED if wedged else SEATED


def run_outcome(status: str, summary: dict | None, offset_mm: float = WEDGED_OFFSET_MM) -> str:
    """A run's outcome: its grasps' worst (OUTCOMES), `diverged` for a diverged run; '' for a run
    that did not end on its physics (interrupted, wall limit, rejected, exception, worker died)."""
    if status == DIVERGED:
        return DIVERGED
    if summary is None or status not in COMPARABLE:
        return ""
    found = {grasp_outcome(status, g, offset_mm) for g in summary["grasps"]}
    return next(o for o in OUTCOMES if o in found)

"""What a run ended as: its status, said once for `simulate` and every study that runs it.

The simulator's own: `completed` (every grasp closed within its grooves), `not captured`
(every grasp closed, one with a finger outside its groove: on a land or a mouth's edge beside
it, `scenario.in_grooves`), `incomplete` (a grasp not closed by its time-out), `diverged`,
`interrupted` (Ctrl-C) and `wall limit` (its wall-time budget spent: no verdict). A study's
run can also end `rejected` (an invalid scenario, or a start whose fingers and groove
interpenetrate), `exception` (something raised out of the run: a bug to report) or, on Dask,
`worker died` (its worker died twice under it).
"""

COMPLETED, NOT_CAPTURED, INCOMPLETE = "completed", "not captured", "incomplete"
DIVERGED, INTERRUPTED, WALL_LIMIT = "diverged", "interrupted", "wall limit"
REJECTED, EXCEPTION, WORKER_DIED = "rejected", "exception", "worker died"
#: Runs that ended on their physics, to their end: their records compare with a reference's.
COMPARABLE = (COMPLETED, NOT_CAPTURED, INCOMPLETE)

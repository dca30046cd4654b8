"""What the benchmarks that compare ensembles with a reference share: the cases, and one
ensemble's comparison with its reference's members."""

from __future__ import annotations

import numpy as np
from speed import pct

import spotsim
from spotsim.studies.accuracy_ensemble import compare
from spotsim.studies.ensemble import ALL_AXES, grasp_prefix, member_row

#: (title, shipped config) of the cases each benchmark runs.
CASES = (("Case I", "single_arm_case_I"), ("Case II", "single_arm_case_II"), ("Case III", "single_arm_case_III"),
         ("dual arm", "dual_arm_sequential"))


def member_rows(e) -> list[dict]:
    """An ensemble's members table (`member_row`)."""
    n_grasps = len(e.members[0].grasps())
    return [member_row(m, n_grasps, n_grasps > 1) for m in e.members]


def against(scenario, ref_rows: list[dict], members: int, family: str = ALL_AXES):
    """An ensemble of `members` starts of `scenario` (seed 0, `family`, 2 workers) compared, by the
    ensemble accuracy study's `compare`, with the reference's members from the same starts:
    (the summaries of its members that ran, its grasps' column prefixes, the comparison)."""
    e = spotsim.ensemble(scenario, members, family=family, workers=2)
    n_grasps = len(e.members[0].grasps())
    c = compare(member_rows(e), ref_rows, n_grasps, n_grasps > 1)
    return [m.summary for m in e.members if m.summary], [grasp_prefix(g, n_grasps) for g in range(n_grasps)], c


def ensemble_rows(scenario, members: int, family: str = ALL_AXES) -> tuple[list[dict], float, int]:
    """An ensemble of `members` starts of `scenario` (seed 0, `family`, 2 workers): its member rows,
    its median wall time per member (s) and its grasp count."""
    e = spotsim.ensemble(scenario, members, family=family, workers=2)
    wall = float(np.median([m.summary["wall_time_s"] for m in e.members if m.summary]))
    return member_rows(e), wall, len(e.members[0].grasps())


def medians(rows: list[dict], p: str) -> tuple[float, float]:
    """The median peak force (N) and residual offset (mm) of the grasp with column prefix p over
    member rows."""
    force = np.median([r[p + "peak_force_norm_N"] for r in rows if r.get(p + "peak_force_norm_N")])
    residual = np.nanmedian([r[p + "residual_norm_mm"] for r in rows if r.get(p + "residual_norm_mm") is not None])
    return float(force), float(residual)


def rel(c: dict, key: str) -> str:
    """A comparison's relative difference `key` (`compare`'s `*_rel`) with its sampling error, in per cent."""
    return pct(c[key], c[key + "_error"])

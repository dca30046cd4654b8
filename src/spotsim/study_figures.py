"""Figures of a study's directory (`spotsim plot DIR`): what its files hold, drawn, for an
ensemble, a sweep, an envelope and an accuracy study. The studies write tables only; the
command line draws their figures from them. A run's own figures are `results.plot_figures`."""

from __future__ import annotations

import json
import math
from pathlib import Path

from .errors import SpotsimError
from .files import save_figure

#: The quantities drawn per grasp: members-table column (`ensemble.member_row`), label.
QUANTITIES = (("residual_norm_mm", "residual offset e (mm)"), ("peak_force_norm_N", "peak contact force |F| (N)"),
              ("completed_s", "completion time (s)"))


def _saved(fig, path: Path, rect=(0, 0, 1, 1)) -> Path:
    """`fig`, laid out within `rect` of it, saved as `path` (whole or not at all), and closed."""
    import matplotlib.pyplot as plt

    fig.tight_layout(rect=rect)
    path.parent.mkdir(exist_ok=True)
    save_figure(fig, path)
    plt.close(fig)
    return path


def plot_ensemble(d: Path) -> list[Path]:
    """figures/ensemble.png: per grasp (a row), a histogram of each of QUANTITIES over the
    members whose grasp completed, titled with its classes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .studies.ensemble import ENSEMBLE_JSON, grasp_prefix
    from .studies.estimate import read_members

    e = json.loads((d / ENSEMBLE_JSON).read_text())
    rows = read_members(d / "members.csv")
    grasps = list(e["classes"])
    fig, axes = plt.subplots(len(grasps), len(QUANTITIES), figsize=(4 * len(QUANTITIES), 3 * len(grasps)),
                             squeeze=False)
    for g, key in enumerate(grasps):
        p = grasp_prefix(g, len(grasps))
        classes = ", ".join(f"{c} {v['count']}" for c, v in e["classes"][key].items())
        for ax, (column, label) in zip(axes[g], QUANTITIES, strict=True):
            values = [v for v in (r.get(f"{p}{column}") for r in rows) if isinstance(v, float) and math.isfinite(v)]
            ax.hist(values, bins=max(5, min(30, len(values) // 2)), color="tab:blue", alpha=0.8)
            ax.set_xlabel(label)
            ax.set_ylabel("members")
            ax.grid(alpha=0.3)
        axes[g][0].set_title(f"{key}: {classes}", loc="left", fontsize=9)
    fig.suptitle(f"{e['scenario']}: ensemble of {e['members']} (seed {e['seed']}), members whose grasp completed",
                 fontsize=10)
    return [_saved(fig, d / "figures" / "ensemble.png")]


def plot_sweep(d: Path) -> list[Path]:
    """figures/sweep.png: each point's verdict, residual offset and peak force against the first
    varied key (one key), or its verdict over the first two varied keys (a map)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd
    import yaml

    from .studies.sweep import SPEC_FILE, TABLE

    keys = (yaml.safe_load((d / SPEC_FILE).read_text()) or {}).get("keys") or []
    t = pd.read_parquet(d / f"{TABLE}.parquet")
    if not keys or not len(t):
        raise SpotsimError(f"{d}: the sweep has no points to plot")
    # a joined axis (`--vary a+b=...`) sets its keys alike: draw it once, by its first key
    keys = [k for i, k in enumerate(keys) if not any(t[k].equals(t[j]) for j in keys[:i])]
    verdict = t["verdict"].where(t["verdict"] != "", t["status"])
    kinds = sorted(verdict.unique())
    colours = {k: plt.cm.tab10(i % 10) for i, k in enumerate(kinds)}
    prefix = "g1_" if "g1_residual_norm_mm" in t else ""
    if len(keys) == 1:
        fig, axes = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
        for ax, (column, label) in zip(axes, QUANTITIES[:2], strict=True):
            for k in kinds:
                rows = t[verdict == k]
                ax.scatter(rows[keys[0]], rows[f"{prefix}{column}"], color=colours[k], label=k, s=18)
            ax.set_ylabel(label + (" (grasp 1)" if prefix else ""))
            ax.grid(alpha=0.3)
        e = t[f"{prefix}residual_norm_mm"]
        if (e[e.notna()] > 0).all() and e.notna().any():
            axes[0].set_yscale("log")
        axes[0].legend(fontsize=8)
        axes[1].set_xlabel(keys[0])
    else:
        fig, ax = plt.subplots(figsize=(7, 6))
        for k in kinds:
            rows = t[verdict == k]
            ax.scatter(rows[keys[0]], rows[keys[1]], color=colours[k], label=k, s=24)
        ax.set_xlabel(keys[0])
        ax.set_ylabel(keys[1])
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        if len(keys) > 2:
            ax.set_title(f"over the first two of {len(keys)} varied keys", fontsize=9)
    fig.suptitle(f"sweep of {len(t)} points: {d}", fontsize=10)
    return [_saved(fig, d / "figures" / "sweep.png")]


# ----------------------------------------------------------------------------- work-precision


def _study(d: Path, table: str) -> tuple[list[dict], str, str]:
    """A study's rows (`table`, read back as `estimate.read_members` reads a members table), its
    scenario's name and its first finding (its markdown's title and first bullet)."""
    from .studies.estimate import read_members

    rows = read_members(d / table)
    if not rows:
        raise SpotsimError(f"{d}: the study has no rows to plot")
    md = (d / table).with_suffix(".md").read_text().splitlines()
    finding = next((line[2:] for line in md if line.startswith("- ")), "")
    return rows, md[0].split(": ", 1)[-1], finding


def _work_precision(panels: list, lines: dict, x: str, short, title: str, path: Path) -> list[Path]:
    """Error measures against wall time (column `x`), log-log, a line per group of `lines`
    (label -> rows), each point annotated `short(row)`, a row without a value a cross on the top
    edge. `panels`: (axis label, the row's value, the target line (value, label) or None,
    `marks(ax, at, floor)` drawing what the panel marks besides; `at(row)` places a row)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 5.2), squeeze=False)
    for ax, (label, value, target, marks) in zip(axes[0], panels, strict=True):
        good = [value(r) for group in lines.values() for r in group if not math.isnan(value(r))]
        # p-values run down to ~1e-18 (two disjoint samples of 32): the floor follows the data
        floor = max(min([e for e in good if e > 0], default=1e-6) / 3, 1e-30)
        top = max(good, default=1.0) * 3

        def at(r, value=value, floor=floor, top=top):
            return top if math.isnan(value(r)) else max(value(r), floor)

        for name, group in lines.items():
            done = [r for r in group if not math.isnan(value(r))]
            (line,) = ax.plot([r[x] for r in done], [at(r) for r in done], "o-", lw=1.2, ms=4, label=name)
            for r in group:
                if math.isnan(value(r)):
                    ax.plot(r[x], top, "x", color=line.get_color(), ms=8, mew=2)
                    ax.annotate(f"{short(r)}: {r['status']}", (r[x], top), fontsize=7, rotation=90, va="top",
                                ha="right", color=line.get_color())
                else:
                    ax.annotate(short(r), (r[x], at(r)), fontsize=6, xytext=(3, 3), textcoords="offset points",
                                color=line.get_color())
        marks(ax, at, floor)
        if target is not None:
            ax.axhline(target[0], ls="--", color="tab:green", lw=1, label=target[1])
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(f"wall time{' per member' if 'member' in x else ''} (s)")
        ax.set_ylabel(label)
        ax.xaxis.set_minor_formatter(NullFormatter())  # the decades alone: minor labels collide
        ax.grid(alpha=0.3, which="both")
    handles, labels = axes[0][0].get_legend_handles_labels()
    seen = dict(zip(labels, handles))
    fig.legend(seen.values(), seen.keys(), loc="lower center", ncol=3, fontsize=7, frameon=False)
    fig.suptitle(title, fontsize=9)
    return [_saved(fig, path, rect=(0, 0.14, 1, 1))]


def _short(r: dict) -> str:
    """A setting's label beside its point: its tolerance, or its step."""
    return (f"rtol {r['rtol']:g}" if r["method"] == "dopri5" else f"tol {r['tol']:g}"
            if r["method"] == "adaptive_euler" else f"{r['step_ms'] * 1e3:g} us")


def _title(name: str, what: str, finding: str) -> str:
    import textwrap

    return f"{name}: {what}\n{textwrap.shorten(finding, 150)}"


def plot_accuracy(d: Path) -> list[Path]:
    """work_precision.png of an accuracy study's directory: the residual offset's error (mm),
    the peak force's relative error and, on a free-floating robot, the centroid displacement's,
    each grasp's worst, against wall time, a line per integrator (and sphere scale); the
    paper's setting circled, the scenario's own a square, the reference's wall time dotted and
    the reference started a nanometre off dash-dotted."""
    from .studies.accuracy import PERTURBATION_MM, WITHIN_REL

    rows, name, finding = _study(d, "accuracy.csv")
    prefixes = sorted({k[: -len("offset_err_mm")] for k in rows[0] if k.endswith("offset_err_mm")})
    ref = next((r for r in rows if r["role"] == "reference"), None)
    moved = next((r for r in rows if r["role"] == "perturbed"), None)
    swept = [r for r in rows if r["role"] not in ("reference", "perturbed") and not math.isnan(r["wall_time_s"])]
    lines: dict = {}
    for r in sorted(swept, key=lambda r: (r["rtol"] if r["method"] == "dopri5" else r["tol"]
                                          if r["method"] == "adaptive_euler" else -r["substeps"]), reverse=True):
        scale = r.get("sphere_scale", 1.0)
        lines.setdefault(r["method"] + (f", spheres x{scale:g}" if scale != 1.0 else ""), []).append(r)

    def panel(key, label):
        def value(r):
            return max((r[f"{p}{key}"] for p in prefixes), default=math.nan)

        def marks(ax, at, floor):
            for r in swept:
                if r["role"] == "paper":
                    ax.plot(r["wall_time_s"], at(r), "o", ms=14, mfc="none", mec="black", mew=1.5,
                            label=f"paper's setting (symplectic Euler, 1 ms): {r['status']}")
                if r["role"] == "default":
                    ax.plot(r["wall_time_s"], at(r), "s", ms=11, mfc="none", mec="tab:gray", mew=1.5,
                            label="the scenario's setting")
            if ref is not None and not math.isnan(ref["wall_time_s"]):
                ax.axvline(ref["wall_time_s"], ls=":", color="black", lw=1, label=f"reference: {ref['setting']}")
            if moved is not None and value(moved) > 0:  # False on nan
                ax.axhline(value(moved), ls="-.", color="tab:purple", lw=1,
                           label=f"the reference started {PERTURBATION_MM * 1e6:g} nm off")

        one = max((WITHIN_REL * ref[f"{p}offset_norm_mm"] for p in prefixes), default=math.nan) if ref else math.nan
        target = ((WITHIN_REL, "1 %") if key.endswith("_rel") else
                  None if math.isnan(one) else (one, "1 % of the reference's offset"))
        return label, value, target, marks

    panels = [panel("offset_err_mm", "residual offset error (mm)"),
              panel("peak_force_err_rel", "peak force error (relative)")]
    if f"{prefixes[0]}centroid_err_rel" in rows[0]:
        panels.append(panel("centroid_err_rel", "centroid displacement error (relative)"))

    return _work_precision(panels, lines, "wall_time_s", _short, _title(name, "error against wall time", finding),
                           d / "work_precision.png")


def plot_accuracy_ensemble(d: Path) -> list[Path]:
    """work_precision_ensemble.png of an ensemble accuracy study's directory: against wall time
    per member, a line per integrator, the worst member-by-member difference of the
    deterministic quantities, the residual median's difference and the residual's least KS
    p-value; the targets dashed, the scenario's setting a square, the confirmation a star."""
    from .studies.accuracy_ensemble import DETERMINISTIC_REL, KS_ALPHA, RESIDUAL_MEDIAN_REL

    rows, name, finding = _study(d, "accuracy_ensemble.csv")
    ref = next((r for r in rows if r["role"] == "reference"), None)
    confirmation = next((r for r in rows if r["role"] == "confirmation"), None)
    swept = sorted((r for r in rows if r["role"] not in ("reference", "confirmation")
                    and not math.isnan(r["wall_per_member_s"])), key=lambda r: r["wall_per_member_s"])
    lines: dict = {}
    for r in swept:
        lines.setdefault(r["method"], []).append(r)

    def panel(key, label, target):
        def marks(ax, at, floor):
            for r in swept:
                if r["role"] == "default":
                    ax.plot(r["wall_per_member_s"], at(r), "s", ms=11, mfc="none", mec="tab:gray", mew=1.5,
                            label="the scenario's setting")
            if confirmation is not None and not math.isnan(confirmation[key]):
                ax.plot(confirmation["wall_per_member_s"], at(confirmation), "*", ms=12, color="black",
                        label=f"confirmation: {confirmation['setting']}")
            if ref is not None:
                ax.axvline(ref["wall_per_member_s"], ls=":", color="black", lw=1, label=f"reference: {ref['setting']}")
            if key.endswith("_p"):
                ax.set_ylim(floor, 1.5)
        return label, lambda r: r[key], (target, "target"), marks

    panels = [panel("max_deterministic_rel", "deterministic, member by member: worst relative difference",
                    DETERMINISTIC_REL),
              panel("max_residual_median_rel", "residual offset median: relative difference", RESIDUAL_MEDIAN_REL),
              panel("min_residual_ks_p", "residual offset: KS p-value vs the reference", KS_ALPHA)]
    members = f"ensembles of {int(ref['members'])} (seed {int(ref['seed'])})" if ref else "ensembles"
    return _work_precision(panels, lines, "wall_per_member_s", _short,
                           _title(name, f"{members}, error against wall time", finding),
                           d / "work_precision_ensemble.png")


def plot_envelope(d: Path) -> list[Path]:
    """envelope.png of an envelope's directory, its planes in the paper's Fig. 16 style: every
    run of its points file (the rays' probes and the runs at their brackets' ends) at its start,
    coloured by its residual offset where seated, a cross where not; the boundary joined around
    the rays (envelope.csv) and the claimed tolerance's rectangle."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import yaml

    from .status import SEATED, run_outcome
    from .studies.envelope import AXES, CLAIMED, PLANES
    from .studies.estimate import read_members
    from .studies.runner import read_records
    from .studies.sweep import POINTS_FILE

    rays = read_members(d / "envelope.csv")
    precision = yaml.safe_load((d / "envelope.yaml").read_text())["precision_mm"]
    runs = list(read_records(d / POINTS_FILE).values())
    if not runs:
        raise SpotsimError(f"{d}: no {POINTS_FILE}: the envelope's runs are not there to plot")

    def within(direction: dict, plane) -> bool:  # no component off the plane
        return all(direction[a] == 0.0 for a in AXES if a not in plane)

    directions = [{a: r[f"dir_{a}"] for a in AXES} for r in rays]
    planes = [p for p in PLANES if any(within(v, p) and v[p[0]] and v[p[1]] for v in directions)]
    fig, axes = plt.subplots(1, max(len(planes), 1), figsize=(6.2 * max(len(planes), 1), 5.6), squeeze=False)
    for ax, (a, b) in zip(axes[0], planes):
        xs, ys, res = [], [], []
        for rec in runs:
            start = {axis: rec.about["values"].get(AXES[axis][0], 0.0) for axis in AXES}
            if not within(start, (a, b)):
                continue
            seated = run_outcome(rec.status, rec.summary, precision) == SEATED
            g = (rec.summary or {}).get("grasps") or [{}]
            xs.append(start[a])
            ys.append(start[b])
            res.append(g[0].get("residual_offset_norm_mm") if seated else math.nan)
            if not seated:
                ax.plot(start[a], start[b], "x", color="0.3", ms=5)
        sc = ax.scatter(xs, ys, c=res, cmap="viridis", s=18, zorder=3)
        edges = sorted((math.atan2(v[b], v[a]), min(r["boundary"], r["limit"]) * v[a],
                        min(r["boundary"], r["limit"]) * v[b]) for r, v in zip(rays, directions) if within(v, (a, b)))
        if edges:
            ax.plot([p[1] for p in edges] + [edges[0][1]], [p[2] for p in edges] + [edges[0][2]], "-", color="C3",
                    label="capture boundary")
        ca, cb = CLAIMED[a], CLAIMED[b]
        ax.plot([-ca, ca, ca, -ca, -ca], [-cb, -cb, cb, cb, -cb], "--", color="k", label="claimed tolerance")
        ax.set_xlabel(f"{a} ({AXES[a][1]})")
        ax.set_ylabel(f"{b} ({AXES[b][1]})")
        ax.set_title(f"capture envelope, {a}-{b} (x: not seated)")
        ax.legend(loc="upper right", fontsize=8)
        fig.colorbar(sc, ax=ax, label="residual offset (mm)")
    return [_saved(fig, d / "envelope.png")]

"""Figures of an ensemble's and a sweep's directories (`spotsim plot DIR`): what their tables
hold, drawn. A run's own figures are `results.plot_figures`."""

from __future__ import annotations

import json
import math
from pathlib import Path

from .errors import SpotsimError
from .files import save_figure

#: The quantities drawn per grasp: members-table column (`ensemble.member_row`), label.
QUANTITIES = (("residual_norm_mm", "residual offset e (mm)"), ("peak_force_norm_N", "peak contact force |F| (N)"),
              ("completed_s", "completion time (s)"))


def _saved(fig, d: Path, name: str) -> Path:
    """`fig`, laid out, as d/figures/`name` (whole or not at all), and closed."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    path = d / "figures" / name
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
    return [_saved(fig, d, "ensemble.png")]


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
    return [_saved(fig, d, "sweep.png")]

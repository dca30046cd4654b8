"""Writing a run's results: summary.json last and atomically, so a half-written run never
looks complete."""

from __future__ import annotations

import csv
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from .scenario import to_yaml
from .sim.run import Result

SUMMARY = "summary.json"
REPLAY = "replay.npz"  # what `spotsim replay` draws besides the timeseries


def _atomic_write(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _atomic_npz(path: Path, arrays: dict) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)
    os.replace(tmp, path)


def clear_summary(out_dir: Path) -> None:
    """Remove a previous run's summary before a new run writes into the same directory."""
    (Path(out_dir) / SUMMARY).unlink(missing_ok=True)


def write_results(result: Result, out_dir: str | Path, figures: bool = True) -> Path:
    """Write summary.json, timeseries.npz/.csv, replay.npz, scenario.yaml and figures/ into
    `out_dir`."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    clear_summary(out)
    ts = result.timeseries
    _atomic_npz(out / "timeseries.npz", ts)
    if result.replay:
        _atomic_npz(out / REPLAY, result.replay)
    _atomic_write(out / "timeseries.csv", _csv(ts, result.summary.get("fingers", [])))
    _atomic_write(out / "scenario.yaml", to_yaml(result.scenario))
    if figures and len(ts["t"]) > 1:
        plot_figures(ts, out / "figures", result.scenario.name)
    _atomic_write(out / SUMMARY, json.dumps(result.summary, indent=2) + "\n")
    return out


def _csv(ts: dict, fingers: list[str]) -> str:
    import io

    columns, header = [], []
    axes = {3: "xyz", 4: ("qx", "qy", "qz", "qw"), 2: ("upper", "lower")}
    for name, arr in ts.items():
        arr = np.asarray(arr)
        if arr.ndim == 1:
            columns.append(arr)
            header.append(name)
        else:
            labels = axes.get(arr.shape[1], [str(i) for i in range(arr.shape[1])])
            if name.startswith("finger"):
                labels = fingers
            for i in range(arr.shape[1]):
                columns.append(arr[:, i])
                header.append(f"{name}_{labels[i]}")
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(header)
    for row in zip(*columns):
        w.writerow([f"{x:.9g}" if isinstance(x, (float, np.floating)) else int(x) for x in row])
    return buf.getvalue()


def plot_figures(ts: dict, fig_dir: Path, title: str) -> None:
    """The paper's Fig. 11 (offset of O_b from O_a per axis) and Fig. 12 (combined force); for
    a dual-arm run also Fig. 20 (robot centroid displacement per grasp) and Fig. 21 (contact
    forces and torques per grasp)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig_dir.mkdir(parents=True, exist_ok=True)
    if "robot_centroid_m" in ts:
        _dual_arm_figures(ts, fig_dir, title, plt)
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(ts["t"], ts["pairs_slipping"], lw=1, color="tab:red", label="slipping")
    ax.plot(ts["t"], ts["pairs_sticking"], lw=1, color="tab:cyan", label="sticking")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("sphere pairs in contact (count)")
    ax.set_title(f"{title}: active pairs by state (Fig. 9)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(fig_dir / "active_pairs.png", dpi=110)
    plt.close(fig)
    for name, key, unit, label in (("offset", "offset_mm", "mm", "offset of $O_b$ from $O_a$ (Fig. 11)"),
                                   ("contact_force", "force_N", "N", "combined contact force (Fig. 12)"),
                                   ("contact_torque", "torque_Nm", "N m",
                                    "combined contact torque about the module centroid")):
        fig, axes = plt.subplots(3, 1, sharex=True, figsize=(7, 6))
        for i, ax in enumerate(axes):
            ax.plot(ts["t"], ts[key][:, i], lw=1)
            ax.set_ylabel(f"{'xyz'[i]} ({unit})")
            ax.grid(alpha=0.3)
        axes[0].set_title(f"{title}: {label}")
        axes[-1].set_xlabel("time (s)")
        fig.tight_layout()
        fig.savefig(fig_dir / f"{name}.png", dpi=110)
        plt.close(fig)


def _dual_arm_figures(ts: dict, fig_dir: Path, title: str, plt) -> None:
    grasps = [g for g in np.unique(ts["grasp"])]
    fig, axes = plt.subplots(1, len(grasps), figsize=(6 * len(grasps), 4), squeeze=False)
    for ax, g in zip(axes[0], grasps, strict=True):
        rows = ts["grasp"] == g
        d = (ts["robot_centroid_m"][rows] - ts["robot_centroid_m"][rows][0]) * 1e3
        for i, axis in enumerate("xyz"):
            ax.plot(ts["t"][rows], d[:, i], lw=1, label=axis)
        ax.set_title(f"grasp {g + 1}: robot centroid displacement")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("displacement (mm)")
        ax.grid(alpha=0.3)
        ax.legend()
    fig.suptitle(f"{title}: robot centroid displacement per grasp (Fig. 20)")
    fig.tight_layout()
    fig.savefig(fig_dir / "robot_centroid_displacement.png", dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(2, len(grasps), figsize=(6 * len(grasps), 6), squeeze=False, sharex="col")
    for col, g in enumerate(grasps):
        rows = ts["grasp"] == g
        for row, (key, unit) in enumerate((("force_N", "N"), ("torque_Nm", "N m"))):
            ax = axes[row, col]
            for i, axis in enumerate("xyz"):
                ax.plot(ts["t"][rows], ts[key][rows][:, i], lw=1, label=axis)
            ax.set_ylabel(f"contact {'force' if row == 0 else 'torque'} ({unit})")
            ax.grid(alpha=0.3)
            ax.legend()
        axes[0, col].set_title(f"grasp {g + 1}")
        axes[1, col].set_xlabel("time (s)")
    fig.suptitle(f"{title}: contact forces and torques per grasp (Fig. 21)")
    fig.tight_layout()
    fig.savefig(fig_dir / "contact_forces_torques.png", dpi=110)
    plt.close(fig)


FIGURES_SINGLE = ("offset.png", "contact_force.png", "contact_torque.png", "active_pairs.png")
FIGURES_DUAL = FIGURES_SINGLE + ("robot_centroid_displacement.png", "contact_forces_torques.png")


def read_arrays(path: Path) -> dict:
    """The arrays of an .npz file; OSError or ValueError for a file that is missing, cut short
    or not an .npz (numpy's and zipfile's own errors, made one)."""
    import zipfile

    try:
        with np.load(path) as f:
            return {k: f[k] for k in f.files}
    except (zipfile.BadZipFile, EOFError, KeyError) as e:
        raise ValueError(f"{path.name}: not a readable .npz ({type(e).__name__}: {e})") from e


def read_results(result_dir: str | Path) -> tuple[dict, dict]:
    """A results directory's summary.json and time series, or SpotsimError naming what is
    missing or unreadable."""
    from .errors import SpotsimError

    d = Path(result_dir)
    try:
        summary = json.loads((d / SUMMARY).read_text())
        ts = read_arrays(d / "timeseries.npz")
    except (OSError, ValueError) as e:
        raise SpotsimError(f"{d}: not a spotsim results directory (needs {SUMMARY} and "
                           f"timeseries.npz): {e}") from e
    if not isinstance(summary, dict):
        raise SpotsimError(f"{d}: {SUMMARY} is not a run's summary (a JSON object)")
    return summary, ts


def replot(result_dir: str | Path) -> list[Path]:
    """Regenerate a results directory's figures from its timeseries.npz and summary.json."""
    from .errors import SpotsimError

    d = Path(result_dir)
    summary, ts = read_results(d)
    if len(ts.get("t", ())) < 2:
        raise SpotsimError(f"{d}: the run recorded fewer than two samples; nothing to plot")
    plot_figures(ts, d / "figures", summary.get("scenario", d.name))
    names = FIGURES_DUAL if "robot_centroid_m" in ts else FIGURES_SINGLE
    return [d / "figures" / n for n in names]

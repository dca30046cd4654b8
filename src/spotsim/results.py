"""Writing a run's results (summary.json last, every file atomically, so that a half-written
run never looks complete) and reading them back."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import NamedTuple

import numpy as np

from . import instrument, measures
from .errors import SpotsimError
from .files import atomic, atomic_write, prepare, save_figure
from .run import RESULTS_FORMAT, Result
from .scenario import to_yaml

SUMMARY = "summary.json"
MARKERS = "markers.csv"  # a dual-arm run's bodies' displacements at a camera's rate (`measures`)
REPLAY = "replay.npz"  # what `spotsim replay` draws besides the timeseries
#: What a recorded interval takes on disk at most (timeseries.npz and .csv; Case I writes
#: 222 B, the dual arm ...), and the figures and the rest.
DISK_PER_RECORD_B = 1000
DISK_FIXED_B = 2e6


def disk_need(scenario) -> float:
    """Bytes a run's results may take on disk (`DISK_PER_RECORD_B` a recorded interval)."""
    return scenario.simulation.duration_s / scenario.simulation.dt_s * DISK_PER_RECORD_B + DISK_FIXED_B


def run_scenario(scenario, out_dir: str | Path, *, model=None, source: str = "<scenario>", error_estimate: bool = True,
                 spread_members: int | None = None, figures: bool = True, sample_hz: float = measures.CAMERA_HZ,
                 progress: bool = False) -> Result:
    """What `spotsim run` does, from Python: check that `out_dir` can take the results (before
    anything runs; SpotsimError), run the scenario (`simulate`), estimate its error unless told
    not to (`studies.estimate.estimate`: the companion run, and, where no study or ensemble gives
    one, the spread over `spread_members` starts around the run's own, default 16; 0: none) and
    write the results directory (`write_results`). Returns the Result, its summary with its
    `error_estimate`. `simulate` and `write_results` alone give none."""
    from .assemble.model import build_model
    from .run import INTERRUPTED, simulate
    from .studies.estimate import SPREAD_MEMBERS, estimate

    prepare(Path(out_dir), SUMMARY, disk_need(scenario))
    model = build_model(scenario, source) if model is None else model  # the start's: the spread's runs share it
    result = simulate(scenario, model=model, progress=progress, source=source)
    if error_estimate and result.status != INTERRUPTED:
        try:
            result.summary["error_estimate"] = estimate(
                scenario, result.summary, source=source, model=model,
                spread_members=SPREAD_MEMBERS if spread_members is None else spread_members, progress=progress)
        except KeyboardInterrupt:
            result.summary["error_estimate"] = {"note": "interrupted by the user"}
    write_results(result, out_dir, figures=figures, sample_hz=sample_hz)
    return result


def write_results(result: Result, out_dir: str | Path, figures: bool = True,
                  sample_hz: float = measures.CAMERA_HZ) -> Path:
    """Write timeseries.npz/.csv, replay.npz, scenario.yaml, a dual-arm run's markers.csv (its
    bodies' displacements sampled at `sample_hz`, a motion camera's record), figures/ and,
    last, summary.json into `out_dir`, each file whole or not at all. SpotsimError if a file
    cannot be written (a full disk): it names the files kept, and no summary.json is written."""
    out = prepare(out_dir, SUMMARY)
    ts = result.timeseries
    kept: list[str] = []
    writes = [("timeseries.npz", lambda: atomic(out / "timeseries.npz", lambda f: np.savez_compressed(f, **ts)))]
    if result.replay:
        writes.append((REPLAY, lambda: atomic(out / REPLAY, lambda f: np.savez_compressed(f, **result.replay))))
    writes += [("timeseries.csv", lambda: atomic_write(out / "timeseries.csv",
                                                       _csv(ts, result.summary.get("fingers", [])))),
               ("scenario.yaml", lambda: atomic_write(out / "scenario.yaml", to_yaml(result.scenario)))]
    normal = _table_normal(result.summary)
    if normal is not None and len(ts["t"]) > 1:
        camera = measures.sample(ts["t"], measures.displacements(ts, normal), sample_hz)
        result.summary["markers"] = {"file": MARKERS, "sample_hz": sample_hz, "table_axes": _axes_note(normal)}
        writes.append((MARKERS, lambda: atomic_write(out / MARKERS, measures.markers_csv(*camera))))
    if figures and len(ts["t"]) > 1:
        writes.append(("figures/", lambda: plot_figures(ts, out / "figures", result.scenario.name, result.summary,
                                                        sample_hz)))
    writes.append((SUMMARY, lambda: atomic_write(out / SUMMARY, json.dumps(result.summary, indent=2) + "\n")))
    for name, write in writes:
        try:
            write()
        except OSError as e:
            raise SpotsimError(f"{out}: cannot write results: {e.strerror} (writing {name}); kept: "
                               f"{', '.join(kept) or 'nothing'}; no {SUMMARY}: the run's results are not "
                               "complete") from e
        kept.append(name)
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


def _table_normal(summary: dict):
    """The table's normal a dual-arm run is measured in (`measures`), or None (single arm)."""
    testbed = summary.get("testbed")
    return testbed.get("table_normal") if isinstance(testbed, dict) else None


def _axes_note(normal) -> str:
    x, y, z = measures.table_axes(normal).round(6).tolist()
    return f"x_T {x}, y_T {y}, normal {z} (world)"


def time_label(ts: dict) -> str:
    """A figure's time axis, with its sampling: the record's interval, and that summary.json's
    peaks are taken over every dynamics step, between the records too."""
    dt = float(np.median(np.diff(ts["t"]))) if len(ts["t"]) > 1 else float("nan")
    return f"time (s): a record every {dt * 1e3:.3g} ms; summary.json's peaks are over every step"


def plot_figures(ts: dict, fig_dir: Path, title: str, summary: dict | None = None,
                 sample_hz: float = measures.CAMERA_HZ, markers=None) -> None:
    """The paper's Fig. 11 (offset of O_b from O_a per axis) and Fig. 12 (combined force); for
    a dual-arm run also Fig. 20 (robot centroid displacement per grasp), Fig. 21 (contact
    forces and torques per grasp) and the SPOT experiment's displacements (Figs. 23-29; with a
    measured marker record (times, columns), against it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig_dir.mkdir(parents=True, exist_ok=True)
    if "robot_centroid_m" in ts:
        _dual_arm_figures(ts, fig_dir, title, plt)
        normal = _table_normal(summary or {})
        if normal is not None:
            _displacement_figure(ts, summary, normal, sample_hz, markers, fig_dir, title, plt)
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(ts["t"], ts["pairs_slipping"], lw=1, color="tab:red", label="slipping")
    ax.plot(ts["t"], ts["pairs_sticking"], lw=1, color="tab:cyan", label="sticking")
    ax.set_xlabel(time_label(ts))
    ax.set_ylabel("sphere pairs in contact (count)")
    ax.set_title(f"{title}: active pairs by state (Fig. 9)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    save_figure(fig, fig_dir / "active_pairs.png")
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
        axes[-1].set_xlabel(time_label(ts))
        fig.tight_layout()
        save_figure(fig, fig_dir / f"{name}.png")
        plt.close(fig)
    if "finger_opening_mm" in ts:
        _finger_figure(ts, (summary or {}).get("fingers", []), fig_dir, title, plt)
    if "dynamometer_force_N" in ts and "dynamometer" in (summary or {}):
        _dynamometer_figure(ts, summary["dynamometer"], fig_dir, title, plt)


def _finger_figure(ts: dict, fingers: list[str], fig_dir: Path, title: str, plt) -> None:
    """Each finger's opening and contact load, and the active drive's closing speed."""
    names = fingers if len(fingers) == ts["finger_opening_mm"].shape[1] else \
        [f"finger {i + 1}" for i in range(ts["finger_opening_mm"].shape[1])]
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(7, 6.5))
    for key, ax, label in (("finger_opening_mm", axes[0], "opening (mm)"), ("finger_load_N", axes[1], "load (N)")):
        for i, name in enumerate(names):
            ax.plot(ts["t"], ts[key][:, i], lw=1, label=name)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    axes[2].plot(ts["t"], ts["drive_speed_mm_s"], lw=1, color="k")
    axes[2].set_ylabel("closing speed (mm/s)")
    axes[2].grid(alpha=0.3)
    axes[0].set_title(f"{title}: the fingers' opening and load, the drive's closing speed")
    axes[-1].set_xlabel(time_label(ts))
    fig.tight_layout()
    save_figure(fig, fig_dir / "fingers.png")
    plt.close(fig)


def _dynamometer_figure(ts: dict, setting: dict, fig_dir: Path, title: str, plt) -> None:
    """The contact force on the fingers (the reverse of the module's) against what the
    dynamometer under the arm reads (`instrument`), per axis of O_a (the paper's Fig. 18)."""
    samples = instrument.reading(ts, setting)
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(7, 6))
    for i, ax in enumerate(axes):
        ax.plot(ts["t"], -ts["force_N"][:, i], lw=0.8, color="tab:red", label="contact force on the fingers")
        ax.plot(samples["t"], samples["force_N"][:, i], lw=1, color="tab:blue",
                label=f"dynamometer ({setting['filter_cutoff_Hz']:g} Hz low-pass, {setting['sampling_Hz']:g} Hz)")
        ax.set_ylabel(f"{'xyz'[i]}_a (N)")
        ax.grid(alpha=0.3)
    axes[0].set_title(f"{title}: contact force and the dynamometer's reading (Fig. 18)")
    axes[0].legend(fontsize=7)
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    save_figure(fig, fig_dir / "dynamometer.png")
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
        ax.set_xlabel(time_label(ts))
        ax.set_ylabel("displacement (mm)")
        ax.grid(alpha=0.3)
        ax.legend()
    fig.suptitle(f"{title}: robot centroid displacement per grasp (Fig. 20)")
    fig.tight_layout()
    save_figure(fig, fig_dir / "robot_centroid_displacement.png")
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
        axes[1, col].set_xlabel(time_label(ts))
    fig.suptitle(f"{title}: contact forces and torques per grasp (Fig. 21)")
    fig.tight_layout()
    save_figure(fig, fig_dir / "contact_forces_torques.png")
    plt.close(fig)


def _displacement_figure(ts, summary, normal, sample_hz, markers, fig_dir, title, plt) -> None:
    """Each body's displacement in the table's plane and its yaw: the record (lines), its
    camera samples (dots), a measured marker record if given (crosses); grasps shaded."""
    moved = measures.displacements(ts, normal)
    t_cam, cam = measures.sample(ts["t"], moved, sample_hz)
    bodies = [b for b in measures.BODIES if f"{b}_x_mm" in moved]
    fig, axes = plt.subplots(len(bodies), 3, figsize=(13, 2.1 * len(bodies)), sharex=True, squeeze=False)
    windows = measures.grasp_windows(summary, float(ts["t"][-1]))
    for r, body in enumerate(bodies):
        for c, (q, unit) in enumerate(measures.QUANTITIES):
            ax, col = axes[r, c], f"{body}_{q}_{unit}"
            for k, (a, b) in enumerate(windows):
                ax.axvspan(a, b, color=("tab:blue", "tab:orange")[k % 2], alpha=0.08)
            ax.plot(ts["t"], moved[col], lw=1, color="k", label="simulated")
            ax.plot(t_cam, cam[col], ".", ms=2, color="tab:green", label=f"at {sample_hz:g} Hz")
            if markers is not None and col in markers[1]:
                ax.plot(markers[0], markers[1][col], "x", ms=3, color="tab:red", label="measured")
            ax.set_ylabel(f"{body} {q} ({unit})")
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    for c in range(3):
        axes[-1, c].set_xlabel("time (s)")
    fig.suptitle(f"{title}: displacements in the table's plane from the start (shaded: grasps; Figs. 23-29)")
    fig.tight_layout()
    save_figure(fig, fig_dir / ("markers_comparison.png" if markers is not None else "displacements.png"))
    plt.close(fig)


FIGURES_SINGLE = ("offset.png", "contact_force.png", "contact_torque.png", "active_pairs.png", "fingers.png")
FIGURES_DUAL = FIGURES_SINGLE + ("robot_centroid_displacement.png", "contact_forces_torques.png", "displacements.png")


def read_arrays(path: Path) -> dict:
    """The arrays of an .npz file; OSError for a file that cannot be read, ValueError for one
    cut short, corrupt or not an .npz (whatever numpy, zipfile or zlib raise on it)."""
    def bad(e):
        return ValueError(f"{path.name}: not a readable .npz ({type(e).__name__}: {e})")

    try:
        f = np.load(path, allow_pickle=False)
    except OSError:
        raise
    except Exception as e:  # a corrupt file makes the zip and npy readers raise many kinds
        raise bad(e) from e
    if not isinstance(f, np.lib.npyio.NpzFile):
        raise ValueError(f"{path.name}: a single array, not an .npz archive of them")
    with f:
        try:
            return {k: f[k] for k in f.files}
        except OSError:
            raise
        except Exception as e:
            raise bad(e) from e


class Loaded(NamedTuple):
    """A results directory as read: its summary.json and its time series (arrays by name)."""

    summary: dict
    timeseries: dict


#: The series every run records (the figures draw them).
SERIES = ("t", "offset_mm", "force_N", "torque_Nm", "pairs_slipping", "pairs_sticking")


def read_results(result_dir: str | Path) -> Loaded:
    """A results directory's summary.json and time series, or SpotsimError naming what is
    missing, unreadable, foreign or of another results format."""
    d = Path(result_dir)
    if not d.is_dir():
        raise SpotsimError(f"{d}: no such results directory")
    if not (d / SUMMARY).is_file():
        raise SpotsimError(f"{d}: no {SUMMARY}: not a spotsim results directory, or its run has not finished "
                           "writing it")
    try:
        summary = json.loads((d / SUMMARY).read_text())
    except UnicodeDecodeError:
        raise SpotsimError(f"{d}: {SUMMARY} is not text") from None
    except json.JSONDecodeError as e:
        raise SpotsimError(f"{d}: {SUMMARY} is not valid JSON ({e.msg} at line {e.lineno} column {e.colno})") from None
    except OSError as e:
        raise SpotsimError(f"{d}: cannot read {SUMMARY}: {e.strerror}") from None
    if not isinstance(summary, dict):
        raise SpotsimError(f"{d}: {SUMMARY} is not a run's summary (a JSON object)")
    found = summary.get("results_format")
    if found != RESULTS_FORMAT:
        written = f"spotsim {summary['spotsim_version']}" if "spotsim_version" in summary else "another program"
        layout = "no results_format" if found is None else f"results format {found!r}"
        raise SpotsimError(f"{d}: {SUMMARY} has {layout} (written by {written}); this spotsim reads format "
                           f"{RESULTS_FORMAT}: run the scenario again")
    try:
        ts = read_arrays(d / "timeseries.npz")
    except OSError as e:
        raise SpotsimError(f"{d}: cannot read timeseries.npz: {e.strerror}") from None
    except ValueError as e:
        raise SpotsimError(f"{d}: {e}") from None
    missing = [k for k in SERIES if k not in ts]
    if missing:
        raise SpotsimError(f"{d}: timeseries.npz lacks {', '.join(missing)}: not a run's time series")
    return Loaded(summary, ts)


def replot(result_dir: str | Path, sample_hz: float = measures.CAMERA_HZ, markers: str | Path | None = None
           ) -> tuple[list[Path], list[dict]]:
    """Regenerate a results directory's figures from its timeseries.npz and summary.json: the
    figures' paths and, with a measured marker record (`measures.read_markers`), the error of
    the simulation against it per grasp and column (`measures.compare`), also written to
    markers_comparison.csv beside figures/. A study's directory (an ensemble's, a sweep's, an
    envelope's, an accuracy study's) gets its own figures (`study_figures`)."""
    from . import study_figures

    d = Path(result_dir)
    for marker, plot in (("ensemble.json", study_figures.plot_ensemble), ("sweep.parquet", study_figures.plot_sweep),
                         ("envelope.csv", study_figures.plot_envelope), ("accuracy.csv", study_figures.plot_accuracy),
                         ("accuracy_ensemble.csv", study_figures.plot_accuracy_ensemble)):
        if (d / marker).is_file():
            if markers is not None:
                raise SpotsimError(f"{d}: --markers compares a run's record; this is a study's directory "
                                   f"({marker})")
            return plot(d), []
    summary, ts = read_results(d)
    if len(ts.get("t", ())) < 2:
        raise SpotsimError(f"{d}: the run recorded fewer than two samples; nothing to plot")
    normal = _table_normal(summary)
    measured = None
    if markers is not None:
        if normal is None:
            raise SpotsimError(f"{d}: a single-arm run has no marker measures to compare with {markers}")
        measured = measures.read_markers(markers)
    plot_figures(ts, d / "figures", summary.get("scenario", d.name), summary, sample_hz, measured)
    names = list(FIGURES_DUAL if normal is not None else FIGURES_SINGLE)
    errors = []
    if measured is not None:
        errors = measures.compare(ts["t"], measures.displacements(ts, normal), *measured,
                                  measures.grasp_windows(summary, float(ts["t"][-1])))
        names.append("markers_comparison.png")
        lines = ["grasp,column,samples,rms,max"] + [
            f"{e['grasp']},{e['column']},{e['samples']},{e['rms']},{e['max']}" for e in errors]
        atomic_write(d / "markers_comparison.csv", "\n".join(lines) + "\n")
    return [d / "figures" / n for n in names], errors

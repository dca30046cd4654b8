"""The SPOT experiment's measures (paper Sec. 5.2, Figs. 23-29) of a dual-arm run.

On the testbed, motion cameras record markers on the floating base, the modules and the
end-effectors at 90 Hz. The measures here are what such a record gives: each body's
displacement from its start in the table's plane (x, y, mm) and its turn about the table's
normal (yaw, deg), over time; per grasp, each one's peak-to-peak amplitude within the grasp
and its largest excursion from the grasp's start. They are taken from the run's record and
from its samples at a camera rate, and compared with a measured marker record (`read_markers`,
`compare`) in the same columns as `markers.csv`.

The table's axes: z_T its normal (`testbed.table_normal`; a free-floating run uses the same
axes, so that both scenes are measured alike), x_T world x in the table's plane (world y
where world x is the normal), y_T = z_T x x_T. The bodies: the base (its joint frame),
TM-1 and TM-2 (their groove frames O_b) and EE-1 and EE-2 (their grasp frames O_a; an
end-effector turns with the base, whose arms are locked).
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np

from .errors import SpotsimError

#: The testbed's motion cameras' rate, Hz (paper Sec. 5.2).
CAMERA_HZ = 90.0
#: The bodies measured, and the recorded series of their positions and rotations.
BODIES = {"base": ("base_pos_m", "base_quat_xyzw"), "TM-1": ("TM-1_pos_m", "TM-1_quat_xyzw"),
          "TM-2": ("TM-2_pos_m", "TM-2_quat_xyzw"), "EE-1": ("EE-1_pos_m", "base_quat_xyzw"),
          "EE-2": ("EE-2_pos_m", "base_quat_xyzw")}
#: A body's measured quantities and their units, as columns `<body>_<quantity>_<unit>`.
QUANTITIES = (("x", "mm"), ("y", "mm"), ("yaw", "deg"))
#: The most rows a marker file may have (a 90 Hz record of 30 hours).
MAX_MARKER_ROWS = 10_000_000


def table_axes(normal) -> np.ndarray:
    """The table's axes as rows (x_T, y_T, z_T) in world."""
    z = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    x = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = x - (x @ z) * z
    x /= np.linalg.norm(x)
    return np.array([x, np.cross(z, x), z])


def _yaw(quat_xyzw: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The turn about `normal` of each rotation relative to the first, rad, unwrapped: the
    twist of R(t) R(0)^T about the normal (all of it on the testbed)."""
    q = np.asarray(quat_xyzw, dtype=float)
    v0, w0 = -q[0, :3], q[0, 3]  # the first rotation's inverse, (x, y, z), w
    v, w = q[:, :3], q[:, 3]
    # the product q(t) q(0)^-1
    rel_w = w * w0 - v @ v0
    rel_v = w[:, None] * v0 + w0 * v + np.cross(v, v0)
    return np.unwrap(2.0 * np.arctan2(rel_v @ normal, rel_w))


def displacements(ts: dict, normal) -> dict[str, np.ndarray]:
    """Each recorded body's displacement from its first record: {"<body>_x_mm", "_y_mm",
    "_yaw_deg": (n,)}, in the table's axes; empty for a single-arm run."""
    axes = table_axes(normal)
    out = {}
    for body, (pos, quat) in BODIES.items():
        if pos not in ts:
            continue
        d = (np.asarray(ts[pos]) - ts[pos][0]) @ axes.T * 1e3
        out[f"{body}_x_mm"], out[f"{body}_y_mm"] = d[:, 0], d[:, 1]
        out[f"{body}_yaw_deg"] = np.degrees(_yaw(ts[quat], axes[2]))
    return out


def sample(t: np.ndarray, series: dict[str, np.ndarray], hz: float) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """`series` over times t sampled at `hz` from t[0] (linear interpolation): a camera's
    record of the run."""
    if not (math.isfinite(hz) and hz > 0):
        raise SpotsimError(f"the sample rate must be a positive number of Hz, not {hz}")
    # the record's times carry round-off: a sample within a millionth of a period of its end
    # is taken at the end
    times = t[0] + np.arange(int(math.floor((t[-1] - t[0]) * hz + 1e-6)) + 1) / hz
    times[-1] = min(times[-1], t[-1])
    return times, {k: np.interp(times, t, v) for k, v in series.items()}


def amplitudes(t: np.ndarray, series: dict[str, np.ndarray], start: float, end: float) -> dict[str, dict]:
    """Each series' peak-to-peak amplitude over [start, end] and its largest excursion from
    its value at `start` (signed): {column: {"peak_to_peak": .., "max_excursion": ..}}."""
    rows = (t >= start - 1e-12) & (t <= end + 1e-12)
    out = {}
    for k, v in series.items():
        if not rows.any():
            out[k] = {"peak_to_peak": None, "max_excursion": None}
            continue
        w = v[rows]
        dev = w - w[0]
        out[k] = {"peak_to_peak": float(w.max() - w.min()), "max_excursion": float(dev[np.abs(dev).argmax()])}
    return out


def grasp_windows(summary: dict, t_end: float) -> list[tuple[float, float]]:
    """Each started grasp's window: from its drive's start to its completion (or t_end)."""
    out = []
    for g in summary.get("grasps", []):
        if g.get("started_s") is None:
            continue
        out.append((g["started_s"], g["completed_s"] if g.get("completed_s") is not None else t_end))
    return out


def markers_csv(times: np.ndarray, series: dict[str, np.ndarray]) -> str:
    """The rows of a marker record: time_s, then every column of `series`."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["time_s", *series])
    for i, t in enumerate(times):
        w.writerow([f"{t:.6f}", *(f"{series[k][i]:.6g}" for k in series)])
    return buf.getvalue()


def read_markers(path: str | Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A measured marker record: a CSV with a header `time_s` then columns
    `<body>_<x_mm|y_mm|yaw_deg>` for any of the bodies (`BODIES`), each a displacement from the
    body's start in the table's axes, times increasing. SpotsimError, in one line, otherwise."""
    p = Path(path)
    try:
        text = p.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise SpotsimError(f"{p}: cannot read the marker record: {getattr(e, 'strerror', None) or e}") from None
    rows = list(csv.reader(io.StringIO(text)))
    if not rows or rows[0][:1] != ["time_s"]:
        raise SpotsimError(f"{p}: a marker record starts with a header whose first column is time_s")
    known = {f"{b}_{q}_{u}" for b in BODIES for q, u in QUANTITIES}
    header = [h.strip() for h in rows[0]]
    unknown = [h for h in header[1:] if h not in known]
    if unknown or len(header) < 2 or len(set(header)) != len(header):
        raise SpotsimError(f"{p}: header columns {unknown or header[1:]} are not distinct columns "
                           f"<body>_x_mm, _y_mm or _yaw_deg of the bodies {', '.join(BODIES)}")
    if len(rows) - 1 > MAX_MARKER_ROWS:
        raise SpotsimError(f"{p}: more than {MAX_MARKER_ROWS} rows")
    values = np.empty((len(rows) - 1, len(header)))
    for i, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise SpotsimError(f"{p}: line {i} has {len(row)} values, the header {len(header)}")
        try:
            values[i - 2] = [float(x) for x in row]
        except ValueError:
            raise SpotsimError(f"{p}: line {i} has a value that is not a number") from None
    if len(values) < 2 or not np.isfinite(values).all() or (np.diff(values[:, 0]) <= 0).any():
        raise SpotsimError(f"{p}: a marker record needs two or more rows of finite numbers, times increasing")
    return values[:, 0], {h: values[:, i] for i, h in enumerate(header) if i}


def compare(t: np.ndarray, simulated: dict[str, np.ndarray], t_m: np.ndarray, measured: dict[str, np.ndarray],
            windows: list[tuple[float, float]]) -> list[dict]:
    """Per grasp window and measured column: the simulation at the marker times minus the
    measurement, its RMS and its largest magnitude, over the markers within the window (and
    within the run). [{"grasp": g, "column": c, "samples": n, "rms": .., "max": ..}]."""
    out = []
    for g, (a, b) in enumerate(windows):
        inside = (t_m >= max(a, t[0])) & (t_m <= min(b, t[-1]))
        for col, m in measured.items():
            if col not in simulated:
                continue
            err = np.interp(t_m[inside], t, simulated[col]) - m[inside]
            n = int(inside.sum())
            out.append({"grasp": g + 1, "column": col, "samples": n,
                        "rms": float(np.sqrt(np.mean(err ** 2))) if n else None,
                        "max": float(np.abs(err).max()) if n else None})
    return out

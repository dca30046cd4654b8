"""A design sweep: the groove's bevel angle and depth against the capture envelope, the residual
offset and the peak force.

    python examples/design_sweep.py [--quick] [--out DIR] [--workers W]

For each geometry (both grooves' bevel angle to their mid-plane, and both grooves' depth), the
capture envelope of Case I's scenario along x_a, y_a and pitch, both ways
(`spotsim.studies.envelope.envelope`, bisection to 0.5 mm and 2 deg), and Case I's own run
from its (0, -3, 0) mm start: its residual offset and peak contact force. Prints a table of
them and writes design_sweep.png. The envelope's probes run on a local Dask cluster, and an
interrupted sweep started again over the same --out runs only what it lacks.

--quick: two bevel angles at the default depth, along y_a only, to 1 mm (a minute or so).
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

import spotsim
from spotsim.studies.envelope import CLAIMED, Search, envelope
from spotsim.studies.runner import Runner

CONFIG = Path(__file__).resolve().parents[1] / "config" / "single_arm_case_I.yaml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default="results/design_sweep")
    ap.add_argument("--workers", type=int)
    args = ap.parse_args()
    if args.quick:
        bevels, depths, axes, res = (40.0, 50.0), (13.0,), ("y",), {"mm": 1.0, "deg": 2.0}
    else:
        bevels, depths, axes = (35.0, 45.0, 55.0), (10.0, 13.0, 16.0), ("x", "y", "pitch")
        res = {"mm": 0.5, "deg": 2.0}
    rows = []
    for bevel, depth in itertools.product(bevels, depths):
        sets = [f"geometry.upper_bevel_deg={bevel}", f"geometry.lower_bevel_deg={bevel}",
                f"geometry.upper_depth_mm={depth}", f"geometry.lower_depth_mm={depth}"]
        out = Path(args.out) / f"bevel_{bevel:g}_depth_{depth:g}"
        report = envelope(CONFIG, out, Search(axes=axes, planes=(), resolution=res),
                          runner=Runner(workers=args.workers), sets=sets)
        run = spotsim.simulate(spotsim.load_scenario(CONFIG, sets))
        grasp = run.grasp
        bounds = {r.name: (r.lo, r.hi) for r in report.rays}
        rows.append({"bevel": bevel, "depth": depth, "bounds": bounds, "status": run.status,
                     "residual": grasp["residual_offset_norm_mm"], "force": grasp["peak_force_norm_N"]})
        print(f"bevel {bevel:g} deg, depth {depth:g} mm: " +
              ", ".join(f"{name} captured to {lo:g} (not at {'-' if hi is None else f'{hi:g}'})"
                        for name, (lo, hi) in bounds.items()) +
              f"; Case I start: {run.status}, residual {_num(grasp['residual_offset_norm_mm'], 4)} mm, "
              f"peak force {_num(grasp['peak_force_norm_N'], 2)} N", flush=True)
    plot(rows, axes, Path(args.out) / "design_sweep.png")
    print(f"figure: {Path(args.out) / 'design_sweep.png'}")


def _num(x, digits):
    return "-" if x is None else f"{x:.{digits}f}"


def plot(rows, axes, path: Path) -> None:
    """Per axis, the captured half-width (the smaller of the two ways) against the bevel angle,
    a line per depth, the claimed tolerance dashed; then the residual offset and peak force."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, panels = plt.subplots(1, len(axes) + 2, figsize=(4.2 * (len(axes) + 2), 3.8), squeeze=False)
    depths = sorted({r["depth"] for r in rows})
    for ax, axis in zip(panels[0], axes):
        for depth in depths:
            mine = [r for r in rows if r["depth"] == depth]
            width = [min(r["bounds"][f"{axis}+"][0], r["bounds"][f"{axis}-"][0]) for r in mine]
            ax.plot([r["bevel"] for r in mine], width, "o-", label=f"depth {depth:g} mm")
        ax.axhline(CLAIMED[axis], ls="--", color="k", label="claimed")
        ax.set_xlabel("bevel angle (deg)")
        ax.set_ylabel(f"captured ±{axis} ({'mm' if axis in ('x', 'y') else 'deg'})")
        ax.legend(fontsize=7)
    for ax, key, label in ((panels[0][-2], "residual", "residual offset (mm)"),
                           (panels[0][-1], "force", "peak contact force (N)")):
        for depth in depths:
            mine = [r for r in rows if r["depth"] == depth]
            ax.plot([r["bevel"] for r in mine], [r[key] for r in mine], "o-", label=f"depth {depth:g} mm")
        ax.set_xlabel("bevel angle (deg)")
        ax.set_ylabel(label)
        ax.legend(fontsize=7)
    fig.suptitle("Case I: groove bevel and depth against the capture envelope")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()

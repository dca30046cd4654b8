"""What moves when the robot is laid out to match Table 5's body 4 (`robot.layout`).

    python benchmarks/table5_layout.py [--members 8]

The default layout (`compact`) fits the base to Table 5 body 3 alone, with TM-1's centroid
150 mm behind its groove; `table5_body4` moves the arm mounts, the base's centroid and TM-1's
centroid (`scenario.LAYOUT_TM1_COM_MM`) so that the FDR + TM-1 composite is body 4 too. Printed,
for both layouts: the composite's moments against Table 5; the dual-arm grasp
(config/dual_arm_sequential.yaml) as MEMBERS-member ensembles (seed 0), each grasp's peak force
and robot centroid displacement against the paper's; and the SPOT runs
(config/spot_testbed_*.yaml, config/spot_offset_*.yaml), one run each, with the experiment's
per-grasp amplitudes and EE-2's offset to TM-2 when the second grasp starts.
"""

from __future__ import annotations

import argparse

import numpy as np
from speed import measured_at

import spotsim
from spotsim.assemble import assets
from spotsim.assemble.robot import LAYOUTS, TABLE5, TABLE6
from spotsim.assemble.scene import fdr_inertia
from spotsim.scenario import LAYOUT_TM1_COM_MM
from spotsim.studies.ensemble import ensemble

#: The paper's dual-arm figures (Sec. 5.1): the FDR centroid's displacement per grasp, mm.
PAPER_D = {1: (-0.637, -0.582, 0.146), 2: (-0.173, 0.306, -0.05)}
SPOT = [f"spot_{scene}_{offset}mm" for scene in ("testbed", "offset") for offset in ("2p5", "3", "3p5")]


def tm1_com(layout: str, scenario) -> tuple[float, float, float]:
    """TM-1's centroid (groove frame, mm) in a layout: its own, or the scenario's."""
    return LAYOUT_TM1_COM_MM[layout] or tuple(scenario.tm1.com_mm)


def laid_out(scenario, layout: str):
    """The scenario with the robot in `layout` (and TM-1's centroid where the layout needs it)."""
    com = LAYOUT_TM1_COM_MM[layout]
    return spotsim.replace(scenario, robot={"layout": layout}, **({"tm1": {"com_mm": list(com)}} if com else {}))


def spread(st: dict, digits: int = 3) -> str:
    return f"{st['median']:.{digits}g} [{st['p10']:.{digits}g}, {st['p90']:.{digits}g}]"


def p2p(grasp: dict, body: str, axis: str) -> str:
    return f"{grasp['displacements'][f'{body}_{axis}_mm']['peak_to_peak']:.3g}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--members", type=int, default=8)
    args = parser.parse_args()
    for prefix in TABLE6:
        assets.prefixed_arm("ur3", prefix)
    dual = spotsim.load_scenario(assets.CONFIG_DIR / "dual_arm_sequential.yaml")
    print(f"Measured by `python benchmarks/table5_layout.py --members {args.members}` at {measured_at()}\n")
    print("| layout | TM-1 centroid in its groove frame (mm) | composite moments (kg m²) | vs Table 5 body 4 (%) |")
    print("| --- | --- | --- | --- |")
    for layout in LAYOUTS:
        com = tm1_com(layout, dual)
        I = np.diag(fdr_inertia(laid_out(dual, layout), with_tm1=True).inertia)
        print(f"| {layout} | {list(com)} | {np.round(I, 3)} | {np.round(100 * (I / TABLE5[4].inertia - 1), 1) + 0.0} |")

    print(f"\nDual-arm grasp, ensembles of {args.members} (seed 0): median [p10, p90]; member 0's displacement; "
          f"paper grasp 1 {list(PAPER_D[1])} mm (|d| {np.linalg.norm(PAPER_D[1]):.3g}), grasp 2 {list(PAPER_D[2])} mm "
          f"(|d| {np.linalg.norm(PAPER_D[2]):.3g})\n")
    print("| layout | grasp | peak force (N) | robot centroid displacement |d| (mm) | member 0's d (mm) |")
    print("| --- | --- | --- | --- | --- |")
    for layout in LAYOUTS:
        e = ensemble(laid_out(dual, layout), args.members, seed=0, workers=2)
        first = e.members[0].summary["grasps"]
        for g in (1, 2):
            st = e.statistics[f"grasp_{g}"]
            d = first[g - 1]["robot_centroid_displacement_mm"]
            print(f"| {layout} | {g} | {spread(st['peak_force_norm_N'])} | "
                  f"{spread(st['centroid_displacement_norm_mm'])} | {np.round(d, 3) + 0.0} |")

    print("\nSPOT runs, one each: peak-to-peak amplitudes per grasp (mm), EE-2's offset to TM-2 when grasp 2 starts\n")
    print("| run | layout | base x, grasp 1 / 2 | base y, grasp 1 / 2 | TM-1 x / y, grasp 1 | TM-2 x / y, grasp 2 "
          "| EE-2 to TM-2 at grasp 2 (mm) | status |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for name in SPOT:
        scenario = spotsim.load_scenario(assets.CONFIG_DIR / f"{name}.yaml")
        for layout in LAYOUTS:
            s = spotsim.simulate(laid_out(scenario, layout)).summary
            g1, g2 = s["grasps"]
            cells = [f"{p2p(g, body, 'x')} / {p2p(g, body, 'y')}" for g, body in ((g1, "TM-1"), (g2, "TM-2"))]
            print(f"| {name} | {layout} | {p2p(g1, 'base', 'x')} / {p2p(g2, 'base', 'x')} | {p2p(g1, 'base', 'y')} / "
                  f"{p2p(g2, 'base', 'y')} | {cells[0]} | {cells[1]} | {np.round(g2['start_offset_mm'], 3) + 0.0} "
                  f"| {s['status']} |")


if __name__ == "__main__":
    main()

"""Compare the culled search with the paper's all-pairs search along a real run.

    python examples/compare_searches.py [--until SECONDS] [--every N]

Steps Case I with the culled search (coal broad phase + grid-local search) and, every N
dynamics steps once the fingers touch, evaluates the literal all-pairs search on the same
state. Prints whether both found the same sphere pairs and forces, and the time each took.
"""

import argparse
import time
from pathlib import Path

import numpy as np

import spotsim
from spotsim.contact.forces import pair_forces
from spotsim.contact.search import grid_search, literal_search
from spotsim.run import Stepper
from spotsim.sim.tree import kinematics

ROOT = Path(__file__).resolve().parents[1]


def evaluate(model, state, search):
    """The contacts and forces on a copy of `state` (its pair memory kept), and the time taken."""
    data = state.copy()
    kinematics(model.sim, data)
    t0 = time.perf_counter()
    if search == "literal":
        candidates = literal_search(model.sim, data)
    else:
        candidates = grid_search(model.sim, data, data.near)
    data.assign(candidates=candidates)
    pair_forces(model.sim, data, 1e-4, False)
    return data.contacts, time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--until", type=float, default=0.6, help="simulated seconds to cover")
    parser.add_argument("--every", type=int, default=20, help="compare every N dynamics steps")
    args = parser.parse_args()

    model = spotsim.build_model(spotsim.load_scenario(ROOT / "config" / "single_arm_case_I.yaml"))
    stepper = Stepper(model)
    h = model.scenario.simulation.dt_s / model.scenario.simulation.substeps
    checked = same = pairs = k = 0
    worst, t_culled, t_all = 0.0, 0.0, 0.0
    while stepper.data.t < args.until:
        stepper.step(h)
        k += 1
        if k % args.every or not len(stepper.data.contacts.key):
            continue
        if not checked:  # compile both searches before timing them
            evaluate(model, stepper.data, "culled"), evaluate(model, stepper.data, "literal")
        culled, tc = evaluate(model, stepper.data, "culled")
        literal, ta = evaluate(model, stepper.data, "literal")
        checked += 1
        t_culled, t_all = t_culled + tc, t_all + ta
        pairs += len(literal.key)
        if np.array_equal(culled.key, literal.key):
            same += 1
            if len(literal.key):  # the last step's pairs may all have parted at this state
                scale = max(np.abs(literal.force_W).max(), 1e-300)
                worst = max(worst, float(np.abs(culled.force_W - literal.force_W).max() / scale))
    print(f"states compared: {checked} (t up to {stepper.data.t:.3f} s), {pairs} pairs in contact in all")
    print(f"same pairs in {same} of {checked}; largest force difference {worst:.2e} (relative)")
    if checked:
        print(f"pairs + forces per step: culled {t_culled / checked * 1e3:.3f} ms, "
              f"all-pairs {t_all / checked * 1e3:.1f} ms ({t_all / t_culled:.0f}x)")


if __name__ == "__main__":
    main()

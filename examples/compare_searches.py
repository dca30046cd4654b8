"""Compare the culled search with the paper's all-pairs search along a real run.

    python examples/compare_searches.py [--until SECONDS] [--every N]

Runs Case I with the culled search (coal broad phase + grid-local search) and, every N
dynamics steps once the fingers touch, evaluates the literal all-pairs search on the same
state. Prints whether both found the same sphere pairs and forces, and the time each took.
"""

import argparse
import time
from pathlib import Path

import numpy as np

import spotsim
from spotsim.integrators import make_integrator
from spotsim.step import Contacts, contact_forces, kinematics, literal_pairs, make_data, sphere_pairs, step

ROOT = Path(__file__).resolve().parents[1]


def evaluate(model, data, search):
    """Contacts and forces on a copy of the pair memory, so both searches see the same state."""
    memory = (data.mem_key, data.mem_s, data.mem_vminus)
    t0 = time.perf_counter()
    if search == "all":
        m, s = literal_pairs(model, data)
        key = m * len(model.slave.centres_J) + s
        order = np.argsort(key)
        c = Contacts(m[order], s[order], key[order])
    else:
        c = sphere_pairs(model, data)
    c = contact_forces(model, data, c, 1e-4)
    elapsed = time.perf_counter() - t0
    data.mem_key, data.mem_s, data.mem_vminus = memory
    return c, elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--until", type=float, default=0.6, help="simulated seconds to cover")
    parser.add_argument("--every", type=int, default=20, help="compare every N dynamics steps")
    args = parser.parse_args()

    model = spotsim.build_model(spotsim.load_scenario(ROOT / "config" / "single_arm_case_I.yaml"))
    data = make_data(model)
    integrator = make_integrator("symplectic_euler", model.pin_model)
    h = model.scenario.simulation.dt_s / model.scenario.simulation.substeps
    checked = same = pairs = 0
    worst, t_culled, t_all, k = 0.0, 0.0, 0.0, 0
    while data.t < args.until:
        c = step(model, data, h, integrator)
        k += 1
        if len(c.key) == 0 or k % args.every:
            continue
        kinematics(model, data)
        culled, tc = evaluate(model, data, "culled")
        literal, ta = evaluate(model, data, "all")
        checked += 1
        t_culled, t_all = t_culled + tc, t_all + ta
        pairs += len(literal.key)
        if np.array_equal(culled.key, literal.key):
            same += 1
            scale = max(np.abs(literal.force_W).max(), 1e-300)
            worst = max(worst, float(np.abs(culled.force_W - literal.force_W).max() / scale))
    print(f"states compared: {checked} (t up to {data.t:.3f} s), {pairs} pairs in contact in all")
    print(f"same pairs in {same} of {checked}; largest force difference {worst:.2e} (relative)")
    if checked:
        print(f"pairs + forces per step: culled {t_culled / checked * 1e3:.3f} ms, "
              f"all-pairs {t_all / checked * 1e3:.1f} ms ({t_all / t_culled:.0f}x)")


if __name__ == "__main__":
    main()

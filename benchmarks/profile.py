"""Where a run's time goes (a shipped case, changed by --set if given): its steps over time and one step at a clamp.

    python benchmarks/profile.py [--case dual] [--set KEY=VALUE ...] [--chunk 0.25] [--repeat 5]

1. The run's wall time, the fastest of REPEAT runs, and the run in chunks of CHUNK
   simulated seconds: for each, the accepted steps and force evaluations (from runs of the
   same scenario ended at the chunk's end: a run is deterministic, so these are exact), the
   mean number of pairs in contact, and the drive controller's ticks in it (its simulated
   time over the controller's period: the motor's speed loop, or the prescribing drives'
   controller). While the fingers touch, an adaptive step ends at every tick (the drive may
   set a new current or speed there), so the ticks are the fewest steps a chunk in contact
   can take.
2. One step at a clamp (the first grasp, CLAMP_BEFORE before it completes; reached by steps
   of one controller period, `Stepper`): the whole step, with its force
   evaluations, and the stages of one evaluation, each timed in a compiled loop on a copy of
   that state.
3. The bound these set: at one step per tick, a chunk in which the fingers clamp runs at most
   (controller period) / (step at the clamp) times faster than real time.
4. The bound stiffness sets: at the same state, the accelerations' linearisation in the
   velocities, da/dv (central differences, the pairs and their memory held): symplectic
   Euler's velocity update v + h a(v) is stable only while |1 + h lambda| <= 1 for each of
   its eigenvalues lambda (the contacts' and joints' damping on the inertia they move), so
   for h <= -2 Re(lambda) / |lambda|^2 over the decaying ones, whatever the error tolerance;
   beside it, the mean step the run's own integrator takes there, and the coordinates that
   share the mode that sets the bound.
"""

from __future__ import annotations

import argparse
import time
from typing import NamedTuple

import numpy as np
from numba import njit
from speed import CASES, ROOT, measured_at, repeat_forces

import spotsim
from spotsim.contact.forces import pair_forces
from spotsim.contact.search import find_pairs
from spotsim.contact.wrenches import body_wrenches, contact_summary
from spotsim.run import Stepper
from spotsim.sim.dynamics import accelerations
from spotsim.sim.step import step

#: The clamp whose step is timed: this long before the first grasp completes, s.
CLAMP_BEFORE = 0.1
#: The velocity perturbation of the linearisation da/dv, m/s or rad/s: far below the relative
#: speeds at a clamp and the friction's deadband (1 mm/s), so that no pair's law switches
#: branch within it, and far above the accelerations' round-off.
DV = 1e-7
#: Calls of each stage per timing, and timings (the fastest is kept). Whole steps move the
#: state on: STEP_CALLS of one controller period stay well within CLAMP_BEFORE.
CALLS, STEP_CALLS, TIMINGS = 2000, 200, 5


@njit
def repeat_search(m, d, n):
    for _ in range(n):
        find_pairs(m, d)


@njit
def repeat_pair_forces(m, d, h, n):
    for _ in range(n):
        pair_forces(m, d, h, False)


@njit
def repeat_wrenches(m, d, n):
    for _ in range(n):
        body_wrenches(m, d)
        contact_summary(m, d)


@njit
def repeat_accelerations(m, d, n):
    for _ in range(n):
        accelerations(m, d)


@njit
def repeat_steps(m, d, h, n):
    """n whole steps of at most h (s) from d's state (d moves on)."""
    for _ in range(n):
        step(m, d, h)


class Steps(NamedTuple):
    """What STEP_CALLS whole steps of at most h from a state take, on average."""

    evaluations: float  # force evaluations per step
    step_s: float  # the step taken, s


def steps_from(m, data, h) -> Steps:
    """STEP_CALLS whole steps of at most h (s) from a copy of data's state: their force
    evaluations and their length, on average."""
    d = data.copy()
    t, evaluations = d.t, d.evaluations
    repeat_steps(m, d, h, STEP_CALLS)
    return Steps((d.evaluations - evaluations) / STEP_CALLS, (d.t - t) / STEP_CALLS)


def fastest_us(call, data, calls: int = CALLS) -> float:
    """The fastest of TIMINGS timings of `call(copy of data, calls)`, µs per call."""
    best = np.inf
    for _ in range(TIMINGS):
        d = data.copy()
        call(d, 1)  # compiled, and the copy warm
        t0 = time.perf_counter()
        call(d, calls)
        best = min(best, (time.perf_counter() - t0) / calls)
    return best * 1e6


def chunks(scenario, end: float, chunk: float) -> list[dict]:
    """The run's accepted steps and force evaluations up to each chunk's end (cumulative)."""
    out = []
    for t in list(np.arange(chunk, end, chunk)) + [end]:
        summary = spotsim.simulate(spotsim.replace(scenario, simulation={"duration_s": float(t)})).summary
        out.append({"t": float(t), "steps": summary["integrator"]["accepted_steps"],
                    "evaluations": summary["integrator"]["force_evaluations"]})
    return out


def chunk_row(label: str, grasp, mean_pairs: str, a: dict, b: dict, period: float) -> str:
    """The table row of the run between the cumulative counts a and b."""
    steps, evaluations = b["steps"] - a["steps"], b["evaluations"] - a["evaluations"]
    ticks = (b["t"] - a["t"]) / period
    return (f"| {label} | {grasp} | {mean_pairs} | {steps} | {evaluations} | {ticks:.0f} | {steps / ticks:.2f} | "
            f"{evaluations / max(steps, 1):.2f} |")


def controller_period(model) -> float:
    """The active drive's reading period, s, as the model compiled it (`assemble.model.drives`:
    the motor's speed loop, else the controller that prescribes the fingers' speed)."""
    return float(model.sim.drives.period[0])


def velocity_names(model) -> list[str]:
    """Each velocity coordinate's name: its joint's, a floating joint's six components
    suffixed."""
    pm, names = model.pin_model, []
    for j in range(1, pm.njoints):
        n = pm.nvs[j]
        names += [pm.names[j]] if n == 1 else [f"{pm.names[j]}.{c}" for c in ("vx", "vy", "vz", "wx", "wy", "wz")[:n]]
    return names


def damping_rates(m, data, h) -> tuple[np.ndarray, np.ndarray]:
    """The eigenvalues and eigenvectors of da/dv at data's state (1/s), its pairs and their
    memory held, the bristles bent over h."""
    def acc(v):
        d = data.copy()
        d.v[:] = v
        repeat_forces(m, d, h, 1)
        accelerations(m, d)
        return d.a.copy()

    nv = data.v.shape[0]
    A = np.empty((nv, nv))
    for i in range(nv):
        e = np.zeros(nv)
        e[i] = DV
        A[:, i] = (acc(data.v + e) - acc(data.v - e)) / (2 * DV)
    return np.linalg.eig(A)


def clamp_state(scenario, t: float):
    """The model and data of the scenario stepped to t (s) by steps of one controller period."""
    model = spotsim.build_model(scenario)
    stepper = Stepper(model)
    h = controller_period(model)
    while stepper.data.t < t:
        stepper.step(h)
    return model, stepper.data


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="dual", choices=list(CASES))
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override a scenario key (repeatable), as `spotsim run --set`")
    ap.add_argument("--chunk", type=float, default=0.25, help="simulated seconds per chunk")
    ap.add_argument("--repeat", type=int, default=5, help="whole runs timed (the fastest is kept)")
    args = ap.parse_args()
    scenario = spotsim.load_scenario(ROOT / "config" / CASES[args.case], args.set)
    model = spotsim.build_model(scenario)
    period = controller_period(model)
    full = spotsim.simulate(scenario, model=model)  # every kernel loaded from numba's cache
    wall = min(spotsim.simulate(scenario, model=model).summary["wall_time_s"] for _ in range(args.repeat))
    end = full.summary["sim_time_s"]
    series = full.timeseries
    t, pairs = series["t"], series["pairs_slipping"] + series["pairs_sticking"]
    sets = "".join(f" --set {k}" for k in args.set)
    print(f"Measured by `python benchmarks/profile.py --case {args.case}{sets}` at {measured_at()}: the run in "
          f"chunks of {args.chunk:g} s simulated, and one step at a clamp")
    print(f"\nThe run: {end:.3f} s simulated in {wall:.3f} s (the fastest of {args.repeat}), {end / wall:.2f} times "
          f"faster than real time; the controller's period {period * 1e3:g} ms:\n")
    print("| chunk (s) | grasp | mean pairs in contact | accepted steps | force evaluations | controller ticks | "
          "steps per tick | evaluations per step |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    rows = chunks(scenario, end, args.chunk)
    start = {"t": 0.0, "steps": 0, "evaluations": 0}
    for a, b in zip([start] + rows[:-1], rows, strict=True):
        inside = (t > a["t"]) & (t <= b["t"] + 1e-12)
        print(chunk_row(f"{a['t']:.2f}-{b['t']:.2f}", int(series["grasp"][inside][-1]) + 1,
                        f"{pairs[inside].mean():.1f}", a, b, period))
    print(chunk_row("all", "", "", start, rows[-1], period))

    grasp = full.summary["grasps"][0]
    at = grasp["completed_s"] - CLAMP_BEFORE
    model, data = clamp_state(scenario, at)
    m, h = model.sim, period
    n_pairs = len(data.contacts.key)
    steps = steps_from(m, data, h)
    timed = {
        f"whole step ({steps.evaluations:.2f} force evaluations, the drive, grasp phase, bookkeeping)": fastest_us(
            lambda d, n: repeat_steps(m, d, h, n), data, STEP_CALLS),
        "force evaluation (kinematics, pairs, pair forces, wrenches)": fastest_us(
            lambda d, n: repeat_forces(m, d, h, n), data),
        "  sphere pairs (culled search)": fastest_us(lambda d, n: repeat_search(m, d, n), data),
        "  pair forces": fastest_us(lambda d, n: repeat_pair_forces(m, d, h, n), data),
        "  wrenches and summary": fastest_us(lambda d, n: repeat_wrenches(m, d, n), data),
        "accelerations (the articulated-body algorithm)": fastest_us(lambda d, n: repeat_accelerations(m, d, n), data),
    }
    whole = next(iter(timed.values()))
    print(f"\nOne step at the clamp (grasp 1, {at:.3f} s, {n_pairs} pairs in contact), each stage timed "
          f"{CALLS} times ({STEP_CALLS} whole steps) on a copy of the state, the fastest of {TIMINGS}:\n")
    print("| stage | µs per call | share of the step |")
    print("| --- | --- | --- |")
    for name, us in timed.items():
        print(f"| {name} | {us:.2f} | {100 * us / whole:.0f} % |")
    print(f"\nAt one step per controller tick, a clamp runs at most {period * 1e6 / whole:.1f} times faster than real "
          f"time ({period * 1e6:g} µs simulated per {whole:.2f} µs step).")

    rates, modes = damping_rates(m, data, h)
    bounds = np.where(rates.real < 0.0, -2.0 * rates.real / np.maximum(np.abs(rates) ** 2, 1e-300), np.inf)
    k = int(np.argmin(bounds))
    share = np.abs(modes[:, k]) / np.abs(modes[:, k]).max()
    names = velocity_names(model)
    sharing = ", ".join(f"{names[i]} {share[i]:.2f}" for i in np.argsort(-share)[:4])
    rate = f"{rates[k].real:.0f} {rates[k].imag:+.0f}i"
    print(f"\nThe stiffest damping at the clamp: da/dv's eigenvalue {rate} 1/s bounds an explicit velocity "
          f"update's stable steps to {bounds[k] * 1e6:.0f} µs; the run's integrator takes "
          f"{steps.step_s * 1e6:.0f} µs there on average (mean of {STEP_CALLS}). The mode's largest "
          f"coordinates (share of the largest): {sharing}.")


if __name__ == "__main__":
    main()

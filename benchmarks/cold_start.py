"""The cold start: a scenario's first run on a machine, its kernels compiled (numba's cache empty).

    python benchmarks/cold_start.py [--case I] [--against REV]

Simulates the scenario in a fresh process whose NUMBA_CACHE_DIR is an empty directory, then in
another that finds the cache the first one filled: each process's wall time (import, model,
the kernels' compilation or their loading, the run). With --against REV, revision REV's
src/spotsim and urdf/ (from `git archive`) go first, then this checkout's, each with its own empty
cache, one after the other: the ratio of their cold starts, REV / this (above 1: this one
starts faster). Last, the kernels this checkout compiled more than once for the scenario: a
kernel compiles once per distinct type of its arguments, and a literal constant or an omitted
default is a type of its own.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

from speed import CASES, ROOT, measured_at

#: The child's part: simulate, then name the kernels compiled for several argument types.
CHILD = """
import json, sys
import spotsim
from numba.core.registry import CPUDispatcher
result = spotsim.simulate(spotsim.load_scenario(sys.argv[1]))
several = {}
for name, module in list(sys.modules.items()):
    if name.startswith("spotsim"):
        for k, v in vars(module).items():
            if isinstance(v, CPUDispatcher) and v.py_func.__module__ == name and len(v.signatures) > 1:
                several[f"{name}.{k}"] = len(v.signatures)
print(json.dumps({"status": result.status, "several": several}))
"""


def started(src: Path, config: Path, cache: Path) -> tuple[float, dict]:
    """One process simulating `config` with spotsim from `src` and numba's cache in `cache`:
    its wall time, s, and what it printed."""
    env = {**os.environ, "PYTHONPATH": str(src), "NUMBA_CACHE_DIR": str(cache)}
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", CHILD, str(config)], env=env, capture_output=True, text=True,
                         check=True, cwd=ROOT)
    return time.perf_counter() - t0, json.loads(out.stdout.strip().splitlines()[-1])


def revision_src(rev: str, where: Path) -> Path:
    """Revision `rev`'s src directory, unpacked under `where` beside its urdf/ (which a
    checkout's spotsim reads)."""
    where.mkdir(parents=True, exist_ok=True)
    archive = where / "src.tar"
    subprocess.run(["git", "-C", str(ROOT), "archive", "-o", str(archive), rev, "src", "urdf"], check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(where, filter="data")
    return where / "src"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default="I", choices=sorted(CASES))
    parser.add_argument("--against", metavar="REV", help="a revision to compare with, run first")
    args = parser.parse_args()
    config = ROOT / "config" / CASES[args.case]
    against = f" --against {args.against}" if args.against else ""
    print(f"Measured by `python benchmarks/cold_start.py --case {args.case}{against}` at {measured_at()}: "
          f"{config.name}, each process with its own numba cache")
    with tempfile.TemporaryDirectory(prefix="spotsim_cold_") as tmp:
        tmp = Path(tmp)
        sources = [("this checkout", ROOT / "src")]
        if args.against:
            sources.insert(0, (args.against, revision_src(args.against, tmp / "base")))
        cold = {}
        for name, src in sources:
            cache = tmp / f"cache_{len(cold)}"
            cold[name], first = started(src, config, cache)
            warm, _ = started(src, config, cache)
            print(f"\n{name}: first run {cold[name]:.1f} s (kernels compiled), second {warm:.1f} s (loaded); "
                  f"the run {first['status']}")
        if args.against:
            print(f"\ncold start {args.against} / this checkout: {cold[args.against] / cold['this checkout']:.2f}")
        several = ", ".join(f"{k} ({n})" for k, n in sorted(first["several"].items())) or "none"
        print(f"\nkernels this checkout compiled for several argument types (how many): {several}")


if __name__ == "__main__":
    main()

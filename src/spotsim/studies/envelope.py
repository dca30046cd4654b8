"""The capture envelope of a single-arm scenario's mechanism, by bisection along rays.

From the centred start, a ray is a direction in the module's misalignment (x_a, y_a in mm;
roll, pitch, yaw in degrees): along each axis both ways, and fanned over the (x_a, y_a) plane
and the roll-yaw plane. Along a ray the start is moved by a magnitude r; a probe at r runs the
scenario from there (`runs.run_task`, the start gap grown where the misaligned start would
interpenetrate) and is captured when its verdict is `seated` (closed within its grooves, its
residual offset and tilt within the precision, `status.grasp_outcome`). Each ray probes its
search limit first (a ray captured there has its boundary beyond it), then bisects between its
largest captured and smallest uncaptured magnitudes until they are `resolution` apart: about
log2(limit / resolution) + 1 runs a ray, where a grid of the same resolution along the ray
takes limit / resolution, and a plane's grid the square.

Bisection takes the captured set along a ray to be an interval from the centre. Near the
boundary the outcome is also a matter of chance (model.md Sec. 9): with `members` > 1, each
ray's last captured and first uncaptured probes are run again as ensembles of `members` starts
perturbed as `spotsim run --ensemble` perturbs them, and the capture fraction at each is
reported (`Ray.chance`).

Probes are sweep points (the same keys, files and resumption: `points.jsonl` in the output
directory), run on the same runner (`runner.execute`, Dask by default).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import ScenarioError
from ..files import atomic_write, prepare
from ..scenario import TOLERANCE_DEG, TOLERANCE_OFFSET_MM, from_dict, set_value
from ..status import SEATED, run_outcome
from .runner import Runner, SchedulerLost, Task, append_record, check_budget, read_records, scenario_key
from .sweep import POINTS_FILE, PRECISION_MM, point_task, run_on

#: The misalignment axes: key path of the module's start, unit.
AXES = {"x": ("module.initial_offset_mm.0", "mm"), "y": ("module.initial_offset_mm.1", "mm"),
        "roll": ("module.initial_rpy_deg.0", "deg"), "pitch": ("module.initial_rpy_deg.1", "deg"),
        "yaw": ("module.initial_rpy_deg.2", "deg")}
#: The paper's claimed tolerance per axis (Sec. 2.3).
CLAIMED = {"x": TOLERANCE_OFFSET_MM, "y": TOLERANCE_OFFSET_MM, **TOLERANCE_DEG}
#: Default resolution and search limit per unit.
RESOLUTION = {"mm": 0.25, "deg": 1.0}
LIMIT = {"mm": 16.0, "deg": 90.0}
#: The planes fanned with rays, and how many rays each (evenly spaced around the full circle).
PLANES = (("x", "y"), ("roll", "yaw"))
PLANE_RAYS = 12


@dataclass
class Ray:
    """A ray from the centred start: unit components per axis (in the axes' own units), its
    resolution and search limit, and what its probes found: the largest captured magnitude
    `lo` and the smallest not captured `hi` (None: none yet), each probe as (magnitude,
    verdict, key)."""

    name: str
    direction: dict
    resolution: float
    limit: float
    lo: float = 0.0
    hi: float | None = None
    probes: list = field(default_factory=list)
    beyond: str = ""  # the verdict of the first probe not captured
    chance: dict = field(default_factory=dict)  # magnitude -> (captured, members) near the boundary

    def next_probe(self) -> float | None:
        """The next magnitude to probe, or None when the boundary is found (or lies beyond the
        limit)."""
        if not self.probes:
            return self.limit
        if self.hi is None or self.hi - self.lo <= self.resolution:
            return None
        return 0.5 * (self.lo + self.hi)

    def record(self, magnitude: float, verdict_: str, key: str) -> None:
        self.probes.append((magnitude, verdict_, key))
        if verdict_ == SEATED:
            self.lo = max(self.lo, magnitude)
        elif self.hi is None or magnitude < self.hi:
            self.hi, self.beyond = magnitude, verdict_

    @property
    def boundary(self) -> float:
        """The capture boundary's magnitude: the midpoint of its bracket (inf beyond the limit)."""
        return math.inf if self.hi is None else 0.5 * (self.lo + self.hi)


def rays(axes=tuple(AXES), planes=PLANES, plane_rays: int = PLANE_RAYS, resolution=None, limit=None) -> list[Ray]:
    """Both ways along each axis, and `plane_rays` evenly around each plane (the axes' own
    rays among them are not repeated). In a plane of two units (none here) the magnitude is
    in the first's."""
    res, lim = {**RESOLUTION, **(resolution or {})}, {**LIMIT, **(limit or {})}
    out = []
    for a in axes:
        unit = AXES[a][1]
        for sign, tag in ((1.0, "+"), (-1.0, "-")):
            out.append(Ray(f"{a}{tag}", {a: sign}, res[unit], lim[unit]))
    for a, b in planes:
        unit = AXES[a][1]
        for k in range(plane_rays):
            angle = 2 * math.pi * k / plane_rays
            c, s = math.cos(angle), math.sin(angle)
            if abs(c) < 1e-12 or abs(s) < 1e-12:
                continue  # on an axis: that axis' own ray
            out.append(Ray(f"{a}-{b} {math.degrees(angle):.0f} deg", {a: c, b: s}, res[unit], lim[unit]))
    return out


def probe_point(raw0: dict, ray: Ray, magnitude: float, index: int, where: str) -> Task:
    """The sweep point of a probe: the module started `magnitude` along `ray` from centred."""
    values = {AXES[axis][0]: round(magnitude * ray.direction.get(axis, 0.0), 9) + 0.0 for axis in AXES}
    return point_task(raw0, values, index, where)


@dataclass
class EnvelopeReport:
    rays: list
    records: dict
    runs: int
    interrupted: bool
    out: Path

    def axis_table(self) -> list[dict]:
        """Claimed against measured per axis: each way's boundary and its bracket."""
        rows = []
        for axis, (_, unit) in AXES.items():
            ways = {r.name[-1]: r for r in self.rays if r.name in (f"{axis}+", f"{axis}-")}
            if not ways:
                continue
            rows.append({"axis": axis, "unit": unit, "claimed": CLAIMED[axis],
                         **{f"boundary{s}": ways[s].boundary for s in ways},
                         **{f"bracket{s}": (ways[s].lo, ways[s].hi) for s in ways},
                         **{f"beyond{s}": ways[s].beyond for s in ways},
                         "runs": sum(len(r.probes) for r in ways.values())})
        return rows


@dataclass(frozen=True)
class Search:
    """What an envelope searches: both ways along `axes`, `plane_rays` rays around each of
    `planes`, to `resolution` and out to `limit` (per unit, over RESOLUTION and LIMIT), a
    probe captured when it ends seated within `precision_mm`; with `members` > 1, each bracket's
    ends again from that many starts perturbed with `seed`."""

    axes: tuple = tuple(AXES)
    planes: tuple = PLANES
    plane_rays: int = PLANE_RAYS
    resolution: dict | None = None
    limit: dict | None = None
    precision_mm: float = PRECISION_MM
    members: int = 1
    seed: int = 0

    def rays(self) -> list[Ray]:
        return rays(self.axes, self.planes, self.plane_rays, self.resolution, self.limit)

    def most_runs(self) -> int:
        """The most runs the search can make, counted without making its rays: each ray's
        bisection (the limit, then halvings until the bracket is within the resolution) and,
        with members, its bracket's two ends that many times."""
        res, lim = {**RESOLUTION, **(self.resolution or {})}, {**LIMIT, **(self.limit or {})}
        total = 0
        for axes, n_rays in [((a,), 2) for a in self.axes] + [(p, self.plane_rays) for p in self.planes]:
            unit = AXES[axes[0]][1]
            halvings = max(0, math.ceil(math.log2(lim[unit] / res[unit])))
            total += n_rays * (1 + halvings + (2 * self.members if self.members > 1 else 0))
        return total


def envelope(config, out_dir, search: Search = Search(), *, runner: Runner = Runner(), sets=(),
             run=None) -> EnvelopeReport:
    """Find the capture boundary along every ray of `search` for a single-arm scenario (with
    the overrides `sets`, as `--set`), its probes run on `runner` (by `runs.run_task`, or by
    `run(point) -> record` if given: tests). Probes found in `out_dir`'s points file are not
    run again."""
    import yaml

    from .sweep import base_raw

    config, out = Path(config), Path(out_dir)
    raw0 = base_raw(config, list(sets))
    scenario = from_dict(raw0, str(config))
    if scenario.kind != "single_arm":
        raise ScenarioError([f"{config}: kind = {scenario.kind}: the envelope is of a single-arm scenario's module"])
    for axis in AXES:  # the centred start: the rays' origin
        set_value(raw0, AXES[axis][0], 0.0)
    check_budget(search.most_runs(), runner.max_points, f"{config}: the envelope (at most)")
    todo = search.rays()
    done = read_records(out / POINTS_FILE)  # before anything is written: a foreign file stays as it is
    prepare(out, "envelope.md")
    atomic_write(out / "envelope.yaml", yaml.safe_dump({"scenario": str(config), "set": list(sets),
                                                       "precision_mm": search.precision_mm,
                                                       "rays": [{"name": r.name, "direction": r.direction,
                                                                 "resolution": r.resolution, "limit": r.limit}
                                                                for r in todo]}, sort_keys=False))
    state = {"runs": 0, "index": 0}

    def store(record):
        """Keep a new record: appended to the points file and in `done`."""
        append_record(out / POINTS_FILE, record)
        done[record.key] = record
        state["runs"] += 1

    def settle(ray, magnitude, record):
        if record.key not in done:
            store(record)
        ray.record(magnitude, run_outcome(record.status, record.summary, search.precision_mm), record.key)

    def probe(ray):
        """The ray's next probe as a point, settling those already done; None when finished."""
        while (m := ray.next_probe()) is not None:
            state["index"] += 1
            point = probe_point(raw0, ray, m, state["index"], f"{config} [{ray.name} {m:g}]")
            if point.key in done:
                settle(ray, m, done[point.key])
                continue
            return m, point
        return None

    interrupted = False
    try:
        _bisect(todo, probe, settle, runner, str(config), run)
        if search.members > 1:
            _chances(todo, raw0, search, done, runner, str(config), store, run)
    except KeyboardInterrupt:
        interrupted = True
    except SchedulerLost as e:
        write_envelope(EnvelopeReport(todo, done, state["runs"], True, out))
        raise SchedulerLost(f"{e}: {state['runs']} probes finished now, kept in {out / POINTS_FILE}: run the "
                            "envelope again to resume") from e
    report = EnvelopeReport(todo, done, state["runs"], interrupted, out)
    write_envelope(report)
    return report


def _chances(todo, raw0, search: Search, done: dict, runner: Runner, source: str, store, run) -> None:
    """Each ray's bracket run as ensembles: `search.members` perturbed starts (seeded; member
    0 the probe itself) at its last captured and first uncaptured magnitudes, their capture
    fractions into `Ray.chance`. New records go through `store`."""
    from .ensemble import member_scenario, perturbed_starts

    plan = []  # (ray, magnitude, point)
    for ray in todo:
        for m in (ray.lo, ray.hi):
            if m is None or m == 0.0:
                continue
            base = probe_point(raw0, ray, m, 0, source)
            if base.scenario is None:
                continue
            for i, start in enumerate(perturbed_starts(base.scenario, search.members, search.seed)):
                s = member_scenario(base.scenario, start)
                plan.append((ray, m, Task(s, i, scenario_key(s), base.about)))
    missing = list({p.key: p for _, _, p in plan if p.key not in done}.values())
    if missing:
        run_on(runner, missing, source, lambda p, record: store(record), error_estimate=False, grow_gap=True,
               what="envelope", total=len(missing), run=run)
    for ray, m, p in plan:
        rec = done.get(p.key)
        if rec is None:
            continue
        captured, n = ray.chance.get(m, (0, 0))
        seated = run_outcome(rec.status, rec.summary, search.precision_mm) == SEATED
        ray.chance[m] = (captured + seated, n + 1)


def _bisect(todo, probe, settle, runner: Runner, source: str, run) -> None:
    """Bisect every ray at once on `runner`: each ray's next probe submitted as its last ends."""
    where = {}

    def next_of(ray) -> list:
        nxt = probe(ray)
        if nxt is None:
            return []
        where[nxt[1].key] = (ray, nxt[0])
        return [nxt[1]]

    def finished(point, record):
        ray, m = where.pop(point.key)
        settle(ray, m, record)
        return next_of(ray)

    run_on(runner, [p for ray in todo for p in next_of(ray)], source, finished, error_estimate=False,
           grow_gap=True, what="envelope", run=run)


# ----------------------------------------------------------------------------- output


def write_envelope(report: EnvelopeReport) -> None:
    """envelope.csv (a row per ray: its direction, bracket, boundary and runs) and envelope.md
    (claimed against measured per axis); its figure: `study_figures.plot_envelope`."""
    import csv
    import io

    out = report.out
    f = io.StringIO()
    w = csv.writer(f)
    w.writerow(["ray", *(f"dir_{a}" for a in AXES), "resolution", "limit", "captured_up_to", "not_captured_from",
                "boundary", "beyond", "runs", "capture_fraction_at_captured", "capture_fraction_at_not_captured"])
    for r in report.rays:
        w.writerow([r.name, *(r.direction.get(a, 0.0) for a in AXES), r.resolution, r.limit, r.lo,
                    "" if r.hi is None else r.hi, r.boundary, r.beyond, len(r.probes),
                    *(_fraction(r.chance.get(m)) for m in (r.lo, r.hi))])
    atomic_write(out / "envelope.csv", f.getvalue())
    lines = ["| axis | claimed | measured + | measured − | beyond + / − | runs |",
             "| --- | --- | --- | --- | --- | --- |"]
    for row in report.axis_table():
        def fmt(s):
            lo, hi = row[f"bracket{s}"]
            return f"≥ {lo:.3g}" if hi is None else f"{lo:.3g}–{hi:.3g}"
        lines.append(f"| {row['axis']} ({row['unit']}) | ±{row['claimed']:g} | {fmt('+')} | {fmt('-')} | "
                     f"{row['beyond+'] or '–'} / {row['beyond-'] or '–'} | {row['runs']} |")
    atomic_write(out / "envelope.md", "\n".join(lines) + "\n")


def _fraction(chance) -> str:
    return "" if not chance else f"{chance[0] / chance[1]:.3g}"

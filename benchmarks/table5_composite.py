"""Can the dual-arm robot's geometry give Table 5's body 4 (the FDR + TM-1 composite)?

    python benchmarks/table5_composite.py [--starts 60] [--tm1-move 0.2] [--arm ur3]

Table 5 lists body 4's moments of inertia along its axes, not its products, so they are read
here as moments along the FDR base's axes (as principal moments no placement can give them:
`tests/test_robot.py`). The FDR (body 3) stays fitted to Table 5 with its base's inertia
physical: positive, and at least as thick as a uniform box BASE_MIN_SIDE_M thick. Free: each
UR3's mount point on the base (the arms keep Table 6's angles and their mounting
orientation), the base's centroid, and, in the second
search, TM-1's centroid within TM-1MOVE (m) per base axis of its shipped place (150 mm behind its
groove frame). Printed: the composite's moments at the shipped geometry, then for each search
the closest it gets (SLSQP from STARTS starts, least squared relative residual) and the
geometry that gets there; where it meets body 4, the geometry that meets it with the least
change (the smallest sum of squared moves). A third search lets TM-1's centroid go anywhere
and finds the geometry that meets body 4 with TM-1's centroid nearest its groove, to compare
with how far a uniform box with TM-1's mass and inertia reaches from its centroid.

The parts' mass properties come from the shipped XACRO at Table 6's angles (base massless):
arm 1 and its end-effector, arm 2 and its end-effector, TM-1 welded to EE-1. The UR3 base links,
which Pinocchio merges into the base's body, are taken from the UR3 URDF and placed at their
mounts; the parts reproduce the shipped composite's moments (the first line).

--arm puts another Universal Robots model from example-robot-data (ur5, ur10) in place of
the UR3 (the XACRO's arm_model), the base refitted to Table 5 body 3 with what mass is left;
where none is left the searches are not run, and where no start finds a physical base the row
says so.
"""

from __future__ import annotations

import argparse

import numpy as np
import pinocchio as pin
from scipy.optimize import minimize
from speed import measured_at

from spotsim.assemble import assets
from spotsim.assemble.robot import (
    ARM,
    DUAL_ARM_XACRO,
    MASSLESS_BASE,
    TABLE5,
    TABLE6,
    arms_at,
    fit_base,
    locked_robot,
    parallel_axis,
)

#: the arm models the XACRO can take here (Table 6's six UR joint names)
ARMS = ("ur3", "ur5", "ur10")

WELDED = {"tm1_joint_type": "fixed", "tm1_parent": "ee1_grasp"}
#: The base's thinnest side, as a uniform box, m: its inertia must be at least that thick.
BASE_MIN_SIDE_M = 0.2


def base_link(arm: str = ARM) -> tuple[float, np.ndarray]:
    """The arm's base link, fixed to its mount: mass (kg) and inertia about its centroid, which
    is its frame's origin (kg m^2), from the arm's URDF (Pinocchio puts it on the universe)."""
    Y = pin.buildModelFromUrdf(str(assets.example_robot_data_dir() / assets.ARM_URDFS[arm])).inertias[0]
    assert np.allclose(Y.lever, 0.0)
    return Y.mass, Y.inertia.copy()


def mounts() -> dict[str, np.ndarray]:
    """The shipped arm mounts (the XACRO's defaults), m, by arm prefix."""
    defaults = assets.xacro_arg_defaults(DUAL_ARM_XACRO)
    return {p: 1e-3 * np.array([float(x) for x in defaults[f"{p}mount_mm"].split()]) for p in TABLE6}


def arm_parts(args: dict) -> dict[str, tuple[float, np.ndarray, np.ndarray]]:
    """Mass, centroid and inertia about it (base frame) of each arm with its end-effector
    (without its base link), at Table 6's angles."""
    model = pin.buildModelFromXML(assets.compile_xacro(DUAL_ARM_XACRO, {**MASSLESS_BASE, **args}))
    data = model.createData()
    pin.forwardKinematics(model, data, arms_at(model))
    to_base = data.oMi[model.getJointId("fdr_free_flyer")].inverse()
    parts = {}
    for k, side in ((1, "arm1_"), (2, "arm2_")):
        Y = pin.Inertia.Zero()
        for i in range(1, model.njoints):
            if model.names[i].startswith((side, f"ee{k}_")):
                Y = Y + (to_base * data.oMi[i]).act(model.inertias[i])
        parts[side] = (Y.mass, Y.lever.copy(), Y.inertia.copy())
    return parts


def groove(args: dict) -> pin.SE3:
    """Where EE-1 holds TM-1's groove (the ee1_grasp frame), in the base frame."""
    model = pin.buildModelFromXML(assets.compile_xacro(DUAL_ARM_XACRO, {**MASSLESS_BASE, **args}))
    data = model.createData()
    pin.framesForwardKinematics(model, data, arms_at(model))
    to_base = data.oMi[model.getJointId("fdr_free_flyer")].inverse()
    return to_base * data.oMf[model.getFrameId("ee1_grasp")]


def uniform_reach(m: float, inertia: np.ndarray) -> float:
    """How far the farthest point of a uniform box with mass m and this inertia lies from its
    centroid, m: half its diagonal, sqrt(1.5 trace / m) (sides^2 = 6 (I_j + I_k - I_i) / m)."""
    return float(np.sqrt(1.5 * np.trace(inertia) / m))


def tm1_part(args: dict) -> tuple[float, np.ndarray, np.ndarray]:
    """TM-1 welded to EE-1: arm 1's part with it less arm 1's part without it."""
    mw, cw, Iw = arm_parts({**WELDED, **args})["arm1_"]
    mf, cf, If = arm_parts(args)["arm1_"]
    m = mw - mf
    c = (mw * cw - mf * cf) / m
    return m, c, Iw + parallel_axis(mw, cw - c) - If - parallel_axis(mf, cf - c)


class Geometry:
    """The composite for mount shifts d1, d2, a base centroid c_b and a TM-1 centroid move."""

    def __init__(self, arm: str = ARM):
        args = {"arm_model": arm}
        self.arms = arm_parts(args)
        self.tm1 = tm1_part(args)
        self.mounts = mounts()
        self.base_link = base_link(arm)
        self.groove = groove(args)
        self.T3 = np.diag(TABLE5[3].inertia)
        self.T4 = np.array(TABLE5[4].inertia)
        #: what Table 5 body 3 leaves for the base, kg
        self.base_mass = TABLE5[3].mass - sum(m + self.base_link[0] for m, _, _ in self.arms.values())

    def evaluate(self, x):
        """Body 4's moments relative to Table 5's, the base's inertia eigenvalues and TM-1's
        distance from the FDR's centroid for the geometry x. The base is fitted to body 3 as
        `robot.fit_base` fits it, in closed form over the parts, so that the searches need not
        recompile the XACRO at every evaluation."""
        d = {"arm1_": x[0:3], "arm2_": x[3:6]}
        c_b, move = x[6:9], x[9:12]
        parts = []
        for side, (m, c, I) in self.arms.items():
            parts.append((m, c + d[side], I))
            parts.append((self.base_link[0], self.mounts[side] + d[side], self.base_link[1]))
        M3, m_b = TABLE5[3].mass, self.base_mass
        c3 = (m_b * c_b + sum(p[0] * p[1] for p in parts)) / M3
        I_b = self.T3 - sum(p[2] + parallel_axis(p[0], p[1] - c3) for p in parts) - parallel_axis(m_b, c_b - c3)
        m1, c1, I1 = self.tm1
        c1 = c1 + d["arm1_"] + move
        c4 = (M3 * c3 + m1 * c1) / (M3 + m1)
        I4 = self.T3 + parallel_axis(M3, c3 - c4) + I1 + parallel_axis(m1, c1 - c4)
        return np.diag(I4) / self.T4 - 1, np.linalg.eigvalsh(I_b), float(np.linalg.norm(c1 - c3))

    def base_margins(self, x) -> np.ndarray:
        """The base's inertia eigenvalues and its triangle-inequality slack less that of a uniform
        box whose thinnest side is BASE_MIN_SIDE_M (m_b t^2 / 6): all >= 0 for a base at least
        that thick (a slack of 0 is a flat plate)."""
        e = self.evaluate(x)[1]
        return np.r_[e, e.sum() - 2 * e.max() - self.base_mass * BASE_MIN_SIDE_M ** 2 / 6]

    def tm1_from_groove(self, x) -> float:
        """TM-1's centroid's distance from its groove (which moves with arm 1's mount), m."""
        return float(np.linalg.norm(self.tm1[1] + x[9:12] - self.groove.translation))

    def as_values(self, x) -> str:
        """The geometry x as the XACRO's and the scenario's values, mm: the arm mounts, the base's
        centroid and TM-1's centroid in its groove frame (`tm1.com_mm`)."""
        mm = lambda v: "[" + ", ".join(f"{round(1e3 * c):g}" for c in v) + "]"  # noqa: E731
        tm1 = self.groove.rotation.T @ (self.tm1[1] + x[9:12] - self.groove.translation)
        mounts = {side: mm(self.mounts[side] + x[k:k + 3]) for side, k in (("arm1_", 0), ("arm2_", 3))}
        return (f"arm1_mount_mm {mounts['arm1_']}, arm2_mount_mm {mounts['arm2_']}, base_com_mm {mm(x[6:9])}, "
                f"tm1.com_mm {mm(tm1)}")


def arms_own(g: Geometry) -> np.ndarray:
    """The eigenvalues of Table 5 body 3's inertia less each arm's own (with its end-effector and
    base link, about its centroid): the base's inertia is at most this for any mounts and base
    centroid (the parallel-axis terms are positive semidefinite), so a negative one rules out a
    physical base."""
    rest = g.T3.copy()
    for side, (m, c, I) in g.arms.items():
        mb, Ib = g.base_link
        cb = g.mounts[side]
        C = (m * c + mb * cb) / (m + mb)
        rest -= I + parallel_axis(m, c - C) + Ib + parallel_axis(mb, cb - C)
    return np.linalg.eigvalsh(rest)


def closest(g: Geometry, starts: int, tm1_move: float, seed: int = 0):
    """The least squared residual of body 4's moments with a physical base, over `starts`
    SLSQP starts (None if none finds one); TM-1's centroid moves at most tm1_move (m) per
    axis."""
    physical = g.base_margins

    cons = [{"type": "ineq", "fun": physical}]
    bounds = [(None, None)] * 9 + [(-tm1_move, tm1_move)] * 3
    rng = np.random.default_rng(seed)
    found = []
    for k in range(starts):
        x0 = np.zeros(12) if k == 0 else np.r_[rng.normal(0, 0.5, 9), rng.uniform(-tm1_move, tm1_move, 3)]
        res = minimize(lambda x: (lambda r: r @ r)(g.evaluate(x)[0]), x0, constraints=cons, bounds=bounds,
                       method="SLSQP", options={"maxiter": 1000, "ftol": 1e-12})
        if np.all(physical(res.x) >= -1e-9):
            found.append(res)
    if not found:
        return None
    best = min(found, key=lambda r: r.fun)
    # where body 4 is met: the least change of the shipped geometry that meets it, from every
    # start that met it
    meet = cons + [{"type": "eq", "fun": lambda x: g.evaluate(x)[0]}]
    least = [minimize(lambda x: x @ x, r.x, bounds=bounds, constraints=meet, method="SLSQP",
                      options={"maxiter": 1000}) for r in found if r.fun < 1e-10]
    least = [r for r in least if r.success and np.all(physical(r.x) >= -1e-6)
             and np.abs(g.evaluate(r.x)[0]).max() < 1e-6]
    return min(least, key=lambda r: r.fun) if least else best


def nearest_groove(g: Geometry, starts: int, seed: int = 0):
    """The geometry that meets body 4 with a physical base and TM-1's centroid as near its
    groove as any of `starts` SLSQP starts finds (mounts, base centroid and TM-1's centroid
    free), or None."""
    physical = g.base_margins

    meet = [{"type": "ineq", "fun": physical}, {"type": "eq", "fun": lambda x: g.evaluate(x)[0]}]
    rng = np.random.default_rng(seed)
    found = []
    for _ in range(starts):
        x0 = np.r_[rng.normal(0, 0.3, 9), rng.uniform(-0.3, 0.3, 3)]
        r = minimize(lambda x: g.tm1_from_groove(x) ** 2, x0, constraints=meet, method="SLSQP",
                     options={"maxiter": 2000})
        if r.success and np.abs(g.evaluate(r.x)[0]).max() < 1e-6 and physical(r.x).min() >= -1e-6:
            found.append(r)
    return min(found, key=lambda r: r.fun) if found else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=60)
    parser.add_argument("--tm1-move", type=float, default=0.2)
    parser.add_argument("--arm", choices=ARMS, default=ARM, help="the arms' model (default %(default)s)")
    args = parser.parse_args()
    for prefix in TABLE6:
        assets.prefixed_arm(args.arm, prefix)
    g = Geometry(args.arm)
    print(f"Measured by `python benchmarks/table5_composite.py{'' if args.arm == ARM else ' --arm ' + args.arm}` "
          f"at {measured_at()}: {args.starts} SLSQP starts per search\n")
    m_b = g.base_mass
    shipped = "(the XACRO robot not built: no base mass)"
    if m_b > 0:  # the shipped XACRO's base is fitted to the UR3; other arms get theirs (physical or not)
        base = {} if args.arm == ARM else fit_base(arm=args.arm, physical=False)
        model, j = locked_robot(assets.compile_xacro(DUAL_ARM_XACRO, {**WELDED, "arm_model": args.arm, **base}))
        shipped = f"{np.round(100 * (np.diag(model.inertias[j].inertia) / g.T4 - 1), 1)} % from Table 5"
    if args.arm != ARM:
        print(f"{args.arm}: {g.base_link[0] + g.arms['arm1_'][0]:.3f} kg per arm with its end-effector, "
              f"base mass left {m_b:.3f} kg of Table 5 body 3's {TABLE5[3].mass} kg\n")
    r, e, D = g.evaluate(np.zeros(12))
    print(f"shipped geometry: body 4 moments {shipped} (the parts: "
          f"{np.round(100 * r, 1)} %), TM-1 {D:.3f} m from the FDR's centroid"
          + ("" if args.arm == ARM else f"; base inertia eigenvalues {np.round(e, 2)} kg m²") + "\n")
    if args.arm != ARM:
        print(f"Table 5 body 3's inertia less the arms' own: eigenvalues {np.round(arms_own(g), 3)} kg m² "
              "(a bound on the base's for any mounts and base centroid)\n")
    if m_b <= 0:
        print("no mass left for the base: no search")
        return
    print(f"TM-1's centroid lies {g.tm1_from_groove(np.zeros(12)):.3f} m from its groove; a uniform box with "
          f"TM-1's mass and inertia reaches {uniform_reach(g.tm1[0], g.tm1[2]):.3f} m from its centroid at most\n")
    print("| search | body 4 moments vs Table 5 (%) | arm 1 mount moved (m) | arm 2 mount moved (m) "
          "| base centroid (m) | TM-1 centroid moved (m) | base inertia eigenvalues (kg m²) | TM-1 to FDR (m) "
          "| TM-1 centroid to groove (m) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    searches = (("mounts and base centroid", 0.0), (f"and TM-1's centroid within ±{args.tm1_move} m", args.tm1_move))
    layouts = []
    for name, move in (*searches, ("and TM-1's centroid free: nearest its groove", None)):
        best = closest(g, args.starts, move) if move is not None else nearest_groove(g, args.starts)
        if best is None:
            print(f"| {name} | no start finds a physical base{'' if move is not None else ' that meets body 4'} "
                  "| | | | | | | |")
            continue
        r, e, D = g.evaluate(best.x)
        x = np.round(best.x, 3) + 0.0
        print(f"| {name} | {np.round(100 * r, 1) + 0.0} | {x[0:3]} | {x[3:6]} | {x[6:9]} | {x[9:12]} "
              f"| {np.round(e, 2)} | {D:.3f} | {g.tm1_from_groove(best.x):.3f} |")
        layouts.append(f"{name}: {g.as_values(best.x)}")
    if layouts:
        print("\nAs the geometry's values:\n\n" + "\n".join(f"- {line}" for line in layouts))


if __name__ == "__main__":
    main()

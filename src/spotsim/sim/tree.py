"""The kinematic tree of a scene as arrays: its joints by kind, their kinematics, and the
centroids, momenta and energy of its bodies.

The tree is the reduced Pinocchio model's (locked joints reduced away): one row per joint,
row 0 the universe, each joint after its parent. A joint is one of `tables.JOINT_KINDS`:

- a free-flyer, q = (x, y, z, qx, qy, qz, qw) (Pinocchio's XYZQUAT), v = (v_O, omega) in its
  own frame;
- a planar joint, q = (x, y, cos theta, sin theta), v = (v_O,x, v_O,y, omega_z) in its own
  frame: it slides in its xy-plane and turns about its z;
- a revolute joint, q = theta, v = theta dot, about its axis;
- a prismatic joint, q = x, v = x dot, along its axis.

Free-flyers and planar joints are children of the universe: floating roots, each carrying its
branch of the tree (a free-flying robot and its fingers, a module). Each child of the universe
starts a branch (`Branches`), and how the dynamics solves a branch is fixed with the Model
(`sim.dynamics`). A joint whose motion its actuator prescribes (a finger behind a kinematic
drive) is `prescribed`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import pinocchio as pin
from numba.experimental import structref

from ..errors import ModelError
from ..jit import njit, njit_inline
from ..linalg import add3, cross3, mm9, mm33, mtv3, mv3, mv9, put3, put9, quat_rotation9, sub3
from ..structs import StructProxy, StructType, new_struct, register
from ..tables import FIXED, FREE_FLYER, JOINT_KINDS, PINOCCHIO_JOINTS, PLANAR, PRISMATIC, REVOLUTE

#: How the dynamics solves a branch (`sim.dynamics.accelerations`): one free body, whose
#: articulated inertia is its own (Newton-Euler); joints whose motion is all prescribed, on the
#: fixed world (nothing to solve); any other branch by the articulated-body algorithm.
NEWTON_EULER, PRESCRIBED, ARTICULATED = range(3)


class Tree(NamedTuple):
    """The joints of a scene, one row each (row 0: the universe), each after its parent."""

    parent: np.ndarray  # (nj,)
    kind: np.ndarray  # (nj,) index in tables.JOINT_KINDS
    idx_q: np.ndarray  # (nj,) first index of its configuration in q
    idx_v: np.ndarray  # (nj,) first index of its velocity in v
    nv: np.ndarray  # (nj,) its degrees of freedom
    R_P: np.ndarray  # (nj, 3, 3) its placement in its parent's frame: rotation
    p_P: np.ndarray  # (nj, 3) and translation, m
    axis: np.ndarray  # (nj, 3) a revolute or prismatic joint's unit axis, its own frame
    mass: np.ndarray  # (nj,) its body's mass, kg
    lever: np.ndarray  # (nj, 3) its body's centroid, its frame, m
    inertia_G: np.ndarray  # (nj, 3, 3) its body's rotational inertia about the centroid, its axes, kg m^2
    prescribed: np.ndarray  # (nj,) bool: its actuator prescribes its motion
    leaf: np.ndarray  # (nj,) bool: no joint hangs from it
    branch: np.ndarray  # (nj,) the branch it belongs to (-1: the universe)
    # (nj,) bool: its body moves with a floating branch: its momentum is the balance's, and what
    # a body that does not float exerts on it is external
    free: np.ndarray
    # per degree of freedom (nv,): the rotor inertia on the mass matrix's diagonal (Pinocchio's
    # `armature`), kg or kg m^2; the passive spring and damper (`passive_force`),
    # -T(|q - rest|) sign(q - rest) - damping v clamped to +-torque_limit (a servo's within its
    # motor's torque), T a gear's torsion curve: stiffness up to the torque knee_1, stiffness_2
    # up to knee_2, stiffness_3 beyond (a linear spring: infinite knees)
    armature: np.ndarray
    stiffness: np.ndarray  # N/m or N m/rad
    damping: np.ndarray  # N s/m or N m s/rad
    rest: np.ndarray  # m or rad
    torque_limit: np.ndarray  # N or N m (inf: none)
    knee_1: np.ndarray  # N or N m
    stiffness_2: np.ndarray
    knee_2: np.ndarray
    stiffness_3: np.ndarray
    # the revolute and prismatic joints, in tree order, and how far a contact sphere of their
    # subtree moves per unit of their coordinate (prismatic: 1; revolute: its farthest sphere
    # from the axis, m); 0 where their subtree carries no sphere
    internal: np.ndarray  # (n_i,)
    reach: np.ndarray  # (nj,)


class Spring(NamedTuple):
    """A joint's passive spring and damper (or, each field an array by velocity index, every
    joint's: `kinematic_tree`): -T(|q - rest|) sign(q - rest) - damping q', clamped
    to +-torque_limit (N m, or N; inf: not clamped). T is a strain-wave gear's torsion curve, three
    lines through its catalogue's limit torques (stiffness up to knee_1, stiffness_2 up to
    knee_2, stiffness_3 beyond; a linear spring: infinite knees)."""

    stiffness: float
    damping: float
    rest: float
    torque_limit: float = math.inf
    knee_1: float = math.inf
    stiffness_2: float = 0.0
    knee_2: float = math.inf
    stiffness_3: float = 0.0


class Branches(NamedTuple):
    """The subtrees hanging from the universe, one row each."""

    joint: np.ndarray  # (nb,) its first joint, a child of the universe
    mode: np.ndarray  # (nb,) NEWTON_EULER, PRESCRIBED or ARTICULATED
    floating: np.ndarray  # (nb,) bool: its first joint is a free-flyer or a planar joint (a floating root)
    planar: np.ndarray  # (nb,) bool: ... a planar joint
    # (nb,) bool: a floating branch whose other joints are all prescribed and whose root has no
    # armature: it moves as one rigid body, its articulated inertia a rigid body's
    rigid: np.ndarray
    first: np.ndarray  # (nb,) its joints: members[first:stop], in tree order
    stop: np.ndarray
    members: np.ndarray  # (nj - 1,)
    mass: np.ndarray  # (nb,) the mass of its bodies, kg
    gravity_W: np.ndarray  # (nb, 3) the gravity its bodies fall in (on the air-bearing table: in its plane), m/s^2
    # a floating branch's farthest contact sphere from its centroid (the adaptive integrator's
    # lever, m) and from its root's origin (the motion bound's, m), its joints anywhere in
    # their travel; 0 without spheres
    lever: np.ndarray  # (nb,)
    reach: np.ndarray  # (nb,)


class Frames(NamedTuple):
    """Each joint's frame in the world and its motion (row 0, the universe: at rest at the origin)."""

    R_W: np.ndarray  # (nj, 3, 3)
    p_W: np.ndarray  # (nj, 3) m
    w_W: np.ndarray  # (nj, 3) angular velocity, rad/s
    vo_W: np.ndarray  # (nj, 3) velocity of the joint's origin, m/s


# Each is a structure of `structs` (a numba structref): the stages bind it to a local (`t =
# m.tree`) or pass it on as one pointer, where a named tuple would have each of its arrays'
# reference counts raised.
@structref.register
class TreeType(StructType):
    pass


@structref.register
class BranchesType(StructType):
    pass


@structref.register
class FramesType(StructType):
    pass


class TreeStruct(StructProxy):
    """A compiled Tree (see `Tree` for its fields)."""


class BranchesStruct(StructProxy):
    """Compiled Branches (see `Branches` for their fields)."""


class FramesStruct(StructProxy):
    """Compiled Frames (see `Frames` for their fields)."""


register(TreeType, Tree, TreeStruct)
register(BranchesType, Branches, BranchesStruct)
register(FramesType, Frames, FramesStruct)


def new_frames(nj: int) -> FramesStruct:
    return new_struct(Frames(R_W=np.tile(np.eye(3), (nj, 1, 1)), p_W=np.zeros((nj, 3)), w_W=np.zeros((nj, 3)),
                             vo_W=np.zeros((nj, 3))))


# ------------------------------------------------------------------------------- the build


def joint_kind(model: pin.Model, j: int) -> int:
    """The kind (tables.JOINT_KINDS) of joint j of `model` (raises ModelError for another
    joint model, or a free-flyer or planar joint that is not a child of the universe)."""
    name = model.joints[j].shortname()
    kind = PINOCCHIO_JOINTS.get(name)
    if kind is None:
        raise ModelError(f"joint {model.names[j]} is a {name}: the compiled core moves "
                         f"{', '.join(JOINT_KINDS[1:])} joints; lock it or change its type")
    if kind in (FREE_FLYER, PLANAR) and model.parents[j] != 0:
        raise ModelError(f"joint {model.names[j]} is a {JOINT_KINDS[kind]} joint on "
                         f"{model.names[model.parents[j]]}: free-flyers and planar joints float on the universe only")
    return kind


def joint_axis(model: pin.Model, j: int) -> np.ndarray:
    """A revolute or prismatic joint's unit axis in its own frame (zeros for other kinds)."""
    kind = joint_kind(model, j)
    if kind not in (REVOLUTE, PRISMATIC):
        return np.zeros(3)
    jdata = model.joints[j].createData()  # its motion subspace S, one column
    model.joints[j].calc(jdata, pin.neutral(model))
    column = np.asarray(jdata.S).reshape(6)
    axis = column[:3] if kind == PRISMATIC else column[3:]
    if abs(np.linalg.norm(axis) - 1.0) > 1e-9:
        raise ModelError(f"joint {model.names[j]}: its axis {axis.tolist()} is not a unit vector")
    return axis


def no_springs(model: pin.Model) -> Spring:
    """No passive springs (each field an array by velocity index), the model's own dampers."""
    arrays = Spring(*(np.full(model.nv, default) for default in (0.0, 0.0, 0.0, *Spring._field_defaults.values())))
    arrays.damping[:] = model.damping
    return arrays


def kinematic_tree(model: pin.Model, prescribed=(), gravity_W=(0.0, 0.0, 0.0), table_normal=None, springs=None,
                   spheres=()) -> tuple[TreeStruct, BranchesStruct]:
    """The compiled tree and branches of a reduced Pinocchio model.

    prescribed: joints whose actuator prescribes their motion. gravity_W: (3,), m/s^2.
    table_normal: the air-bearing table's normal (world), whose component of gravity the
    bearings carry on planar branches. springs: the passive springs and dampers, a Spring of
    (nv,) arrays (default none, and the model's `damping`).
    spheres: (joint, (n, 3) centres in its frame, travel (m) of the prismatic joints above
    them) of each contact layer, for the integrators' levers and the motion bound.
    """
    nj, nv = model.njoints, model.nv
    springs = no_springs(model) if springs is None else springs
    kinds = [FIXED] + [joint_kind(model, j) for j in range(1, nj)]
    ints = lambda values: np.array(values, dtype=np.int64).reshape(-1)
    prescribed = set(prescribed)
    g = np.asarray(gravity_W, dtype=float)
    g_table = g.copy()
    if table_normal is not None and np.any(table_normal):
        n = np.asarray(table_normal, dtype=float) / np.linalg.norm(table_normal)
        g_table = g - (g @ n) * n
    children = [[] for _ in range(nj)]
    for j in range(1, nj):
        children[model.parents[j]].append(j)

    def subtree(j):
        out = [j]
        for c in children[j]:
            out += subtree(c)
        return sorted(out)

    frames = _sphere_frames(model, spheres)
    tree_reach = np.zeros(nj)
    for j in range(1, nj):
        if kinds[j] == PRISMATIC:
            tree_reach[j] = 1.0 if any(k in frames for k in subtree(j)) else 0.0
        elif kinds[j] == REVOLUTE:
            tree_reach[j] = _axis_reach(model, j, subtree(j), frames)
    tree = Tree(
        parent=ints(model.parents), kind=ints(kinds), idx_q=ints([model.idx_qs[j] for j in range(nj)]),
        idx_v=ints([model.idx_vs[j] for j in range(nj)]), nv=ints([model.nvs[j] for j in range(nj)]),
        R_P=np.array([model.jointPlacements[j].rotation for j in range(nj)]).reshape(nj, 3, 3),
        p_P=np.array([model.jointPlacements[j].translation for j in range(nj)]).reshape(nj, 3),
        axis=np.array([joint_axis(model, j) if j else np.zeros(3) for j in range(nj)]).reshape(nj, 3),
        mass=np.array([model.inertias[j].mass for j in range(nj)], dtype=float),
        lever=np.array([model.inertias[j].lever for j in range(nj)]).reshape(nj, 3),
        inertia_G=np.array([model.inertias[j].inertia for j in range(nj)]).reshape(nj, 3, 3),
        prescribed=np.array([j in prescribed for j in range(nj)], dtype=np.bool_),
        leaf=np.array([not children[j] for j in range(nj)], dtype=np.bool_),
        branch=np.full(nj, -1, dtype=np.int64), free=np.zeros(nj, dtype=np.bool_),
        armature=np.array(model.armature, dtype=float).reshape(nv),
        **{name: np.array(values, dtype=float).reshape(nv) for name, values in springs._asdict().items()},
        internal=ints([j for j in range(1, nj) if kinds[j] in (REVOLUTE, PRISMATIC)]),
        reach=tree_reach)
    rows = []
    for j in children[0]:
        members = subtree(j)
        tree.branch[members] = len(rows)
        floating = kinds[j] in (FREE_FLYER, PLANAR)
        tree.free[members] = floating
        if floating and len(members) == 1 and not np.any(tree.armature[model.idx_vs[j]:model.idx_vs[j] + model.nvs[j]]):
            mode = NEWTON_EULER
        elif not floating and all(k in prescribed for k in members):
            mode = PRESCRIBED
        else:
            mode = ARTICULATED
        lever, reach = _branch_levers(model, j, members, frames) if floating else (0.0, 0.0)
        rigid = floating and all(k in prescribed for k in members[1:]) and \
            not np.any(tree.armature[model.idx_vs[j]:model.idx_vs[j] + model.nvs[j]])
        rows.append((j, mode, floating, kinds[j] == PLANAR, members, sum(model.inertias[k].mass for k in members),
                     g_table if kinds[j] == PLANAR else g, lever, reach, rigid))
    stops = np.cumsum([len(r[4]) for r in rows], dtype=np.int64)
    branches = Branches(
        joint=ints([r[0] for r in rows]), mode=ints([r[1] for r in rows]),
        floating=np.array([r[2] for r in rows], dtype=np.bool_), planar=np.array([r[3] for r in rows], dtype=np.bool_),
        rigid=np.array([r[9] for r in rows], dtype=np.bool_),
        first=ints(np.r_[0, stops[:-1]] if rows else []), stop=ints(stops),
        members=ints([k for r in rows for k in r[4]]), mass=np.array([r[5] for r in rows], dtype=float),
        gravity_W=np.array([r[6] for r in rows], dtype=float).reshape(-1, 3),
        lever=np.array([r[7] for r in rows], dtype=float), reach=np.array([r[8] for r in rows], dtype=float))
    return new_struct(tree), new_struct(branches)


def _sphere_frames(model: pin.Model, spheres) -> dict[int, list]:
    """Each joint carrying contact spheres -> [(centres in its frame, travel)]."""
    frames: dict[int, list] = {}
    for j, centres, travel in spheres:
        if len(centres):
            frames.setdefault(int(j), []).append((np.asarray(centres, dtype=float).reshape(-1, 3), float(travel)))
    return frames


def _in_frame(model: pin.Model, data: pin.Data, j: int, k: int, centres: np.ndarray) -> np.ndarray:
    """Points given in joint k's frame, in joint j's frame (a descendant k of j), at data's kinematics."""
    M = data.oMi[j].actInv(data.oMi[k])
    return centres @ M.rotation.T + M.translation


def _axis_reach(model: pin.Model, j: int, members, frames) -> float:
    """The farthest contact sphere of joint j's subtree from its axis, at the neutral
    configuration plus each layer's travel, m."""
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    axis = joint_axis(model, j)
    far = 0.0
    for k in members:
        for centres, travel in frames.get(k, ()):
            x = _in_frame(model, data, j, k, centres)
            radial = x - np.outer(x @ axis, axis)
            far = max(far, float(np.linalg.norm(radial, axis=1).max()) + travel)
    return far


def _branch_levers(model: pin.Model, j: int, members, frames) -> tuple[float, float]:
    """A floating branch's farthest contact sphere from its centroid and from its root's origin,
    at the neutral configuration (its internal joints at 0) plus each layer's travel, m;
    without spheres its radius of gyration about the centroid and 0."""
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    total = pin.Inertia.Zero()
    for k in members:
        total += data.oMi[j].actInv(data.oMi[k]).act(model.inertias[k])
    centroid = total.lever
    lever = reach = 0.0
    for k in members:
        for centres, travel in frames.get(k, ()):
            x = _in_frame(model, data, j, k, centres)
            lever = max(lever, float(np.linalg.norm(x - centroid, axis=1).max()) + travel)
            reach = max(reach, float(np.linalg.norm(x, axis=1).max()) + travel)
    if lever == 0.0:
        lever = float(np.sqrt(np.trace(total.inertia) / (2 * total.mass)))
    return lever, reach


# ------------------------------------------------------------------------------- one joint


@njit_inline
def axis_rotation9(a, c, s):
    """The rotation by an angle (cos c, sin s) about the unit axis a, row by row (Rodrigues)."""
    t = 1.0 - c
    return (c + t * a[0] * a[0], t * a[0] * a[1] - s * a[2], t * a[0] * a[2] + s * a[1],
            t * a[0] * a[1] + s * a[2], c + t * a[1] * a[1], t * a[1] * a[2] - s * a[0],
            t * a[0] * a[2] - s * a[1], t * a[1] * a[2] + s * a[0], c + t * a[2] * a[2])


@njit_inline
def joint_motion(t, j, q):
    """Joint j's motion at q: its rotation (9-tuple, row by row) and translation (3-tuple) in
    the frame of its placement."""
    k, iq = t.kind[j], t.idx_q[j]
    if k == FREE_FLYER:
        return quat_rotation9(q[iq + 3], q[iq + 4], q[iq + 5], q[iq + 6]), (q[iq], q[iq + 1], q[iq + 2])
    if k == PLANAR:
        c, s = q[iq + 2], q[iq + 3]
        return (c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0), (q[iq], q[iq + 1], 0.0)
    if k == REVOLUTE:
        return axis_rotation9(t.axis[j], math.cos(q[iq]), math.sin(q[iq])), (0.0, 0.0, 0.0)
    x = q[iq]
    return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0), (x * t.axis[j, 0], x * t.axis[j, 1], x * t.axis[j, 2])


@njit_inline
def joint_twist(t, j, v):
    """Joint j's velocity S v_j in its own frame: (linear, angular) 3-tuples."""
    k, iv = t.kind[j], t.idx_v[j]
    if k == FREE_FLYER:
        return (v[iv], v[iv + 1], v[iv + 2]), (v[iv + 3], v[iv + 4], v[iv + 5])
    if k == PLANAR:
        return (v[iv], v[iv + 1], 0.0), (0.0, 0.0, v[iv + 2])
    x = v[iv]
    a = (x * t.axis[j, 0], x * t.axis[j, 1], x * t.axis[j, 2])
    if k == REVOLUTE:
        return (0.0, 0.0, 0.0), a
    return a, (0.0, 0.0, 0.0)


@njit_inline
def joint_quat(t, j, q):
    """A floating root's rotation in its placement frame as a unit quaternion (x, y, z, w)."""
    iq = t.idx_q[j]
    if t.kind[j] == PLANAR:
        half = 0.5 * math.atan2(q[iq + 3], q[iq + 2])
        return 0.0, 0.0, math.sin(half), math.cos(half)
    return q[iq + 3], q[iq + 4], q[iq + 5], q[iq + 6]


@njit_inline
def root_rotation9(t, j, quat):
    """A floating root's rotation in the world (a 9-tuple, row by row) at the unit quaternion
    quat (x, y, z, w) of its joint (a planar joint's: about its z)."""
    return mm9(t.R_P[j], quat_rotation9(quat[0], quat[1], quat[2], quat[3]))


@njit_inline
def put_root(t, j, q, v, R, origin_W, quat, vo_W, w):
    """Write a floating root's configuration and velocity: its rotation R in the world
    (9-tuple, `root_rotation9` of the unit quaternion quat (x, y, z, w) of its joint), its
    origin and the origin's velocity in the world, and its angular velocity w (its own frame).
    A planar joint keeps their components in its plane."""
    iq, iv = t.idx_q[j], t.idx_v[j]
    x = mtv3(t.R_P[j], sub3(origin_W, t.p_P[j]))
    v_O = (R[0] * vo_W[0] + R[3] * vo_W[1] + R[6] * vo_W[2], R[1] * vo_W[0] + R[4] * vo_W[1] + R[7] * vo_W[2],
           R[2] * vo_W[0] + R[5] * vo_W[1] + R[8] * vo_W[2])
    if t.kind[j] == PLANAR:
        Rq = quat_rotation9(quat[0], quat[1], quat[2], quat[3])
        turn = math.sqrt(Rq[0] * Rq[0] + Rq[3] * Rq[3])
        q[iq], q[iq + 1], q[iq + 2], q[iq + 3] = x[0], x[1], Rq[0] / turn, Rq[3] / turn
        v[iv], v[iv + 1], v[iv + 2] = v_O[0], v_O[1], w[2]
        return
    put3(q, iq, x)
    q[iq + 3], q[iq + 4], q[iq + 5], q[iq + 6] = quat[0], quat[1], quat[2], quat[3]
    put3(v, iv, v_O)
    put3(v, iv + 3, w)


# ------------------------------------------------------------------------------- kinematics

_EYE = np.eye(3)



@njit_inline
def frame_of(t, j, q, v, R_W, p_W, w_W, vo_W):
    """Joint j's frame and motion in the world into row j of R_W, p_W, w_W, vo_W, from its
    parent's row (already computed) and its own q, v."""
    i = t.parent[j]
    if t.kind[j] == PRISMATIC:  # no turn: its frame is its placement's
        x, xd = q[t.idx_q[j]], v[t.idx_v[j]]
        R = mm33(R_W[i], t.R_P[j]) if i else mm33(_EYE, t.R_P[j])
        a = t.axis[j]
        shift = add3(mv3(t.R_P[j], (x * a[0], x * a[1], x * a[2])), t.p_P[j])
        w = (0.0, 0.0, 0.0)
        u = mv9(R, (xd * a[0], xd * a[1], xd * a[2]))
    else:
        RJ, pJ = joint_motion(t, j, q)
        vJ, wJ = joint_twist(t, j, v)
        R = mm9(R_W[i], mm9(t.R_P[j], RJ)) if i else mm9(t.R_P[j], RJ)
        shift = add3(mv3(t.R_P[j], pJ), t.p_P[j])
        w = mv9(R, wJ)
        u = mv9(R, vJ)
    origin = add3(mv3(R_W[i], shift), p_W[i]) if i else shift
    put9(R_W[j], R)
    put3(p_W[j], 0, origin)
    if i:
        r = sub3(origin, (p_W[i, 0], p_W[i, 1], p_W[i, 2]))
        wi = (w_W[i, 0], w_W[i, 1], w_W[i, 2])
        w = add3(w, wi)
        u = add3(add3(u, (vo_W[i, 0], vo_W[i, 1], vo_W[i, 2])), cross3(wi, r))
    put3(w_W[j], 0, w)
    put3(vo_W[j], 0, u)


@njit
def kinematics(m, d):
    """Stage 1: every joint's frame and motion in the world at (d.q, d.v), into d.R_W, d.p_W,
    d.w_W, d.vo_W (the universe stays at rest at the origin)."""
    # the arrays bound once: read through the structures in the loop, each read of one would
    # cost its reference counts at every joint
    t, q, v, R_W, p_W, w_W, vo_W = m.tree, d.q, d.v, d.R_W, d.p_W, d.w_W, d.vo_W
    for j in range(1, t.parent.shape[0]):
        frame_of(t, j, q, v, R_W, p_W, w_W, vo_W)


@njit
def current_frames(m, d):
    """Every joint's frame and motion at d's state (q, v) into d.now: the kinematics of the
    state as it is, where d.R_W ... hold those of the last force evaluation."""
    frames_at(m, d, d.v)


@njit
def frames_at(m, d, v):
    """Every joint's frame and motion at d's positions q and the velocities v into d.now."""
    for j in range(1, m.tree.parent.shape[0]):
        frame_of(m.tree, j, d.q, v, d.now.R_W, d.now.p_W, d.now.w_W, d.now.vo_W)


# ------------------------------------------------------------------------------- centroids


@njit_inline
def body_centroid(t, f, j):
    """Joint j's body's centroid (world) and its velocity, 3-tuples, from the Frames f."""
    c = mv3(f.R_W[j], t.lever[j])
    w = (f.w_W[j, 0], f.w_W[j, 1], f.w_W[j, 2])
    return (add3((f.p_W[j, 0], f.p_W[j, 1], f.p_W[j, 2]), c),
            add3((f.vo_W[j, 0], f.vo_W[j, 1], f.vo_W[j, 2]), cross3(w, c)))


@njit_inline
def branch_centroid(m, f, b):
    """Branch b's centroid (world) and the velocity of it (its momentum over its mass),
    3-tuples, from the Frames f of its joints."""
    t, br = m.tree, m.branches
    c0 = c1 = c2 = u0 = u1 = u2 = 0.0
    for i in range(br.first[b], br.stop[b]):
        j = br.members[i]
        p_G, v_G = body_centroid(t, f, j)
        mass = t.mass[j]
        c0 += mass * p_G[0]
        c1 += mass * p_G[1]
        c2 += mass * p_G[2]
        u0 += mass * v_G[0]
        u1 += mass * v_G[1]
        u2 += mass * v_G[2]
    M = br.mass[b]
    return (c0 / M, c1 / M, c2 / M), (u0 / M, u1 / M, u2 / M)


@njit
def momenta(m, f, branches):
    """The linear and angular momentum (about the world origin) of the bodies of `branches`,
    summed, (3,) each; the largest single body's linear and angular momentum magnitudes; and
    their centroid (3,), from the Frames f."""
    t = m.tree
    P, L, c = np.zeros(3), np.zeros(3), np.zeros(3)
    p_max = l_max = m_sum = 0.0
    for b in branches:
        for i in range(m.branches.first[b], m.branches.stop[b]):
            j = m.branches.members[i]
            mass = t.mass[j]
            if mass == 0.0:
                continue
            p_G, v_G = body_centroid(t, f, j)
            p_b = (mass * v_G[0], mass * v_G[1], mass * v_G[2])
            R = f.R_W[j]
            w = (f.w_W[j, 0], f.w_W[j, 1], f.w_W[j, 2])
            l_b = add3(cross3(p_G, p_b), mv3(R, mv3(t.inertia_G[j], mtv3(R, w))))
            for a in range(3):
                P[a] += p_b[a]
                L[a] += l_b[a]
                c[a] += mass * p_G[a]
            m_sum += mass
            p_max = max(p_max, math.sqrt(p_b[0] ** 2 + p_b[1] ** 2 + p_b[2] ** 2))
            l_max = max(l_max, math.sqrt(l_b[0] ** 2 + l_b[1] ** 2 + l_b[2] ** 2))
    return P, L, p_max, l_max, c / m_sum if m_sum > 0.0 else c


@njit
def centroid3(m, f, branches):
    """The centroid (world, m) of the bodies of `branches` as a 3-tuple, from the Frames f."""
    c0 = c1 = c2 = m_sum = 0.0
    for b in branches:
        c, _ = branch_centroid(m, f, b)
        M = m.branches.mass[b]
        c0 += M * c[0]
        c1 += M * c[1]
        c2 += M * c[2]
        m_sum += M
    return c0 / m_sum, c1 / m_sum, c2 / m_sum


@njit
def kinetic_energy(m, f, v):
    """The kinetic energy of every moving body, 1/2 m |v_G|^2 + 1/2 omega . I_G omega, and of
    the rotors (1/2 armature v^2), J, from the Frames f at velocity v."""
    t = m.tree
    total = 0.0
    for j in range(1, t.parent.shape[0]):
        _, v_G = body_centroid(t, f, j)
        w = mtv3(f.R_W[j], (f.w_W[j, 0], f.w_W[j, 1], f.w_W[j, 2]))  # body axes
        Iw = mv3(t.inertia_G[j], w)
        total += 0.5 * t.mass[j] * (v_G[0] * v_G[0] + v_G[1] * v_G[1] + v_G[2] * v_G[2]) + \
            0.5 * (w[0] * Iw[0] + w[1] * Iw[1] + w[2] * Iw[2])
    for i in range(v.shape[0]):
        total += 0.5 * t.armature[i] * v[i] * v[i]
    return total


@njit
def gravity_energy(m, f):
    """The moving bodies' potential in the gravity their branches fall in, -m g . r_G summed,
    J, from the Frames f (zero in zero gravity)."""
    t, total = m.tree, 0.0
    for j in range(1, t.parent.shape[0]):
        g = m.branches.gravity_W[t.branch[j]]
        if g[0] != 0.0 or g[1] != 0.0 or g[2] != 0.0:
            r, _ = body_centroid(t, f, j)
            total -= t.mass[j] * (g[0] * r[0] + g[1] * r[1] + g[2] * r[2])
    return total


@njit_inline
def _knees(t, iv):
    """Degree of freedom iv's spring's twists at its knees (`Tree`), rad or m (inf: none)."""
    if t.knee_1[iv] == math.inf or t.stiffness[iv] == 0.0:
        return math.inf, math.inf
    a1 = t.knee_1[iv] / t.stiffness[iv]
    return a1, a1 + (t.knee_2[iv] - t.knee_1[iv]) / t.stiffness_2[iv] if t.knee_2[iv] < math.inf else math.inf


@njit_inline
def spring_torque(t, iv, a):
    """The torque (or force) of degree of freedom iv's spring twisted by a >= 0: its torsion
    curve, stiffness up to knee_1, stiffness_2 up to knee_2, stiffness_3 beyond."""
    a1, a2 = _knees(t, iv)
    if a <= a1:
        return t.stiffness[iv] * a
    if a <= a2:
        return t.knee_1[iv] + t.stiffness_2[iv] * (a - a1)
    return t.knee_2[iv] + t.stiffness_3[iv] * (a - a2)


@njit_inline
def passive_force(t, iv, x, u):
    """The passive spring's and damper's force on degree of freedom iv at coordinate x and
    speed u: -T(|x - rest|) sign(x - rest) - damping u (`spring_torque`), clamped to
    +-torque_limit."""
    d = x - t.rest[iv]
    T = spring_torque(t, iv, abs(d))
    f = (-T if d > 0.0 else T) - t.damping[iv] * u
    limit = t.torque_limit[iv]
    return limit if f > limit else -limit if f < -limit else f


@njit
def spring_energy(m, q):
    """The energy stored in the joints' passive springs, J: the torsion curve's integral
    (`spring_torque`) to each twist, and past a clamped spring's limit L, where it pushes with L
    alone, L |x| - L^2 / 2k (a clamped spring is linear)."""
    t = m.tree
    total = 0.0
    for j in t.internal:
        i, k = t.idx_v[j], t.stiffness[t.idx_v[j]]
        if k == 0.0:
            continue
        a, L = abs(q[t.idx_q[j]] - t.rest[i]), t.torque_limit[i]
        a1, a2 = _knees(t, i)
        if k * a > L:
            total += L * a - 0.5 * L * L / k
        elif a <= a1:
            total += 0.5 * k * a * a
        elif a <= a2:
            b = a - a1
            total += 0.5 * t.knee_1[i] * a1 + t.knee_1[i] * b + 0.5 * t.stiffness_2[i] * b * b
        else:
            b = a - a2
            total += (0.5 * t.knee_1[i] * a1 + 0.5 * (t.knee_1[i] + t.knee_2[i]) * (a2 - a1) + t.knee_2[i] * b
                      + 0.5 * t.stiffness_3[i] * b * b)
    return total


# ------------------------------------------------------------------------------- motion bound


@njit
def travel_rate(m, d):
    """A bound on how fast any two contact spheres approach each other, m/s: over the floating
    branches with spheres, |v_O| + |omega| reach of their roots, plus the fastest motion the
    joints inside one branch add to a sphere: along each chain of revolute and prismatic
    joints, the sum of |v| times each one's reach."""
    t, br = m.tree, m.branches
    rate = inner = 0.0
    for j in t.internal:
        if t.reach[j] == 0.0:
            continue
        chain = 0.0  # the joints from j up its branch (the floating root's motion is counted above)
        k = j
        while k and (t.kind[k] == REVOLUTE or t.kind[k] == PRISMATIC):
            chain += abs(d.v[t.idx_v[k]]) * t.reach[k]
            k = t.parent[k]
        inner = max(inner, chain)
    for b in range(br.joint.shape[0]):
        if br.reach[b] > 0.0:
            vJ, wJ = joint_twist(t, br.joint[b], d.v)  # norms are frame-free
            rate += math.sqrt(vJ[0] ** 2 + vJ[1] ** 2 + vJ[2] ** 2) + \
                math.sqrt(wJ[0] ** 2 + wJ[1] ** 2 + wJ[2] ** 2) * br.reach[b]
    return rate + inner

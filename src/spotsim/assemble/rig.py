"""The lab rig of the paper's single-arm experiment (Sec. 4.2): the six-axis dynamometer under
the arm's base (`arm.base: dynamometer`) and the bungee the module hangs on (`suspension`).

The dynamometer is a stiff spring-mass-damper: its top plate and the adapter plate (one body,
`dyn_top`) on six joints to the world, three prismatic along the plate's x, y, z and three
revolute about them, all through the centre of its top surface, where a six-axis plate's
moments are referred; the arm's base sits on the adapter. Each joint is a spring and a damper
(`Model.springs`), their stiffnesses those of four three-component sensors at (+-a, +-b) in
the plate: k_x, k_y, k_z along the axes, k_z b^2 and k_z a^2 tilting, k_x (a^2 + b^2)
twisting. The springs' rests are set so that the start is at rest under gravity: the plate
carries the arm's weight from the start, and its reading, like a piezoelectric plate's after
the charge amplifier's reset, is what changes from there.

The bungee is a tether (`sim.tether`) from a fixed point straight above the module's
centroid, as long as the suspended module hangs (`loaded_length_m`), stretched by the
module's weight at the start: a pendulum of that length along the horizontal, a spring-mass
along the vertical.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pinocchio as pin

from ..errors import ModelError
from ..sim.tether import Tethers, no_tethers
from .compliance import Spring, twist

#: The dynamometer's joints, base to top: along x, y, z, then about x, y, z.
DYNAMOMETER_JOINTS = ("dyn_x", "dyn_y", "dyn_z", "dyn_rx", "dyn_ry", "dyn_rz")
#: The adapter plate between the dynamometer and the arm's base: 200 x 200 mm of aluminium,
#: as thick as its mass makes it (2700 kg/m^3).
ADAPTER_SIDE_M = 0.2
ALUMINIUM_KG_M3 = 2700.0


def adapter_thickness(dyn) -> float:
    """The adapter plate's thickness, m."""
    return dyn.adapter_mass_kg / (ALUMINIUM_KG_M3 * ADAPTER_SIDE_M ** 2)


def _box_inertia(mass: float, size) -> np.ndarray:
    a, b, c = size
    return mass / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def top_inertia(dyn) -> pin.Inertia:
    """The dynamometer's top plate and the adapter as one body, in the frame of its joints
    (the top surface's centre, the plate's axes)."""
    t = adapter_thickness(dyn)
    L, W, H = (x * 1e-3 for x in dyn.top_size_mm)
    top = pin.Inertia(dyn.top_mass_kg, np.array([0.0, 0.0, -H / 2]), _box_inertia(dyn.top_mass_kg, (L, W, H)))
    if dyn.adapter_mass_kg == 0.0:
        return top
    adapter = pin.Inertia(dyn.adapter_mass_kg, np.array([0.0, 0.0, t / 2]),
                          _box_inertia(dyn.adapter_mass_kg, (ADAPTER_SIDE_M, ADAPTER_SIDE_M, t)))
    return top + adapter


def stiffnesses(dyn) -> np.ndarray:
    """The six joints' stiffnesses (N/m, N m/rad), `DYNAMOMETER_JOINTS` order."""
    kx, ky, kz = (k * 1e9 for k in dyn.stiffness_N_um)
    a, b = (x * 1e-3 for x in dyn.sensor_half_spacing_mm)
    return np.array([kx, ky, kz, kz * b * b, kz * a * a, 0.5 * (kx + ky) * (a * a + b * b)])


def mount_on_dynamometer(urdf: str, dyn) -> str:
    """The single-arm scene's compiled URDF with the arm's base on the dynamometer: the fixed
    joint that holds the base to the world (`base_static_joint`) holds it to the adapter on
    the dynamometer's top plate instead, the plate's top surface the adapter's thickness
    below the base."""
    found = re.search(r'<joint\s[^>]*name="base_static_joint".*?</joint>', urdf, re.DOTALL)
    if found is None or '<link name="world"' not in urdf:
        raise ModelError("the scene has no joint base_static_joint holding the arm's base to the world")
    I = top_inertia(dyn)
    c, J, mass = [float(x) for x in I.lever], [[float(x) for x in r] for r in I.inertia], float(I.mass)
    links = "".join(f'<link name="{name}_link"/>' for name in DYNAMOMETER_JOINTS[:-1])
    links += (f'<link name="dyn_top"><inertial><origin xyz="{c[0]!r} {c[1]!r} {c[2]!r}" rpy="0 0 0"/>'
              f'<mass value="{mass!r}"/><inertia ixx="{J[0][0]!r}" ixy="{J[0][1]!r}" ixz="{J[0][2]!r}" '
              f'iyy="{J[1][1]!r}" iyz="{J[1][2]!r}" izz="{J[2][2]!r}"/></inertial></link>')
    joints, parent = "", "world"
    for i, name in enumerate(DYNAMOMETER_JOINTS):
        child = "dyn_top" if i == 5 else f"{name}_link"
        kind, axis = ("prismatic", "revolute")[i // 3], ("1 0 0", "0 1 0", "0 0 1")[i % 3]
        origin = f"0 0 {-float(adapter_thickness(dyn))!r}" if i == 0 else "0 0 0"
        joints += (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
                   f'<origin xyz="{origin}" rpy="0 0 0"/><axis xyz="{axis}"/>'
                   '<limit lower="-0.01" upper="0.01" effort="1e6" velocity="1"/></joint>')
        parent = child
    base = found.group(0).replace('<parent link="world"/>', '<parent link="dyn_top"/>')
    on_adapter = f'<origin xyz="0 0 {float(adapter_thickness(dyn))!r}" rpy="0 0 0"/>'
    base = re.sub(r'<origin[^>]*/>', on_adapter, base, count=1)
    return urdf[:found.start()] + links + joints + base + urdf[found.end():]


def gravity_loads(model: pin.Model, q: np.ndarray, names) -> np.ndarray:
    """The joint forces that hold joints `names` still against gravity at q (N or N m)."""
    G = pin.computeGeneralizedGravity(model, model.createData(), q)
    return np.array([G[model.idx_vs[model.getJointId(name)]] for name in names])


def dynamometer_springs(model: pin.Model, q0: np.ndarray, dyn) -> dict[str, Spring]:
    """The dynamometer's six springs (by joint name, as `compliance.joint_springs`): each rest
    where its spring holds the start still against gravity (its joint at zero), each damping
    `dyn.damping_ratio` of critical on the inertia its joint carries at the start (the mass
    matrix's diagonal)."""
    M = pin.crba(model, model.createData(), q0)
    G = gravity_loads(model, q0, DYNAMOMETER_JOINTS)
    springs = {}
    for name, k, g in zip(DYNAMOMETER_JOINTS, stiffnesses(dyn), G, strict=True):
        iv = model.idx_vs[model.getJointId(name)]
        springs[name] = Spring(float(k), 2.0 * dyn.damping_ratio * math.sqrt(k * M[iv, iv]), float(g / k))
    return springs


def settle(model: pin.Model, q: np.ndarray, springs: dict, names, iterations: int = 20) -> np.ndarray:
    """q with joints `names` (springs about their rests) where their springs hold them still
    against gravity: q_i = rest_i - sign(G_i) twist_i(|G_i(q)|) (the spring's torsion curve
    inverted, `Spring.twist`), iterated from q (G changes little over the few milliradians a
    gearbox gives)."""
    q = q.copy()
    if not np.any(model.gravity.linear) or not names:
        return q
    for _ in range(iterations):
        G = gravity_loads(model, q, names)
        for name, g in zip(names, G, strict=True):
            spring = springs[name]
            q[model.idx_qs[model.getJointId(name)]] = spring.rest - math.copysign(twist(spring, abs(g)), g)
    return q


def bungee(model: pin.Model, q0: np.ndarray, joint: int, suspension, mass: float) -> Tethers:
    """The bungee holding module `joint` (its body's centroid) from the point `loaded_length_m`
    straight above it (against gravity) at q0, stretched there by the module's weight."""
    if suspension.kind != "bungee":
        return no_tethers()
    g = np.array(model.gravity.linear)
    data = model.createData()
    pin.forwardKinematics(model, data, q0)
    lever = model.inertias[joint].lever
    centroid = data.oMi[joint].act(lever)
    k = suspension.stiffness_N_m
    up = -g / np.linalg.norm(g)
    return Tethers(joint=np.array([joint], dtype=np.int64), point=lever.reshape(1, 3).copy(),
                   anchor_W=(centroid + suspension.loaded_length_m * up).reshape(1, 3),
                   stiffness=np.array([k]), damping=np.array([2.0 * suspension.damping_ratio * math.sqrt(k * mass)]),
                   rest_length=np.array([suspension.loaded_length_m - mass * np.linalg.norm(g) / k]))

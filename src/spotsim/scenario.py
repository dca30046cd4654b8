"""Strict YAML scenarios: frozen dataclasses, every problem reported in one pass.

Keys carry their units (`dt_s`, `offset_mm`, `roll_deg`). A key with a default may be left
out; the resolved scenario (`spotsim validate`) shows every value used. Problems read
`file: key.path = value: rule`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .errors import ScenarioError
from .paths import scenario_file
from .tables import DRIVES, KICKS, METHODS

# ----------------------------------------------------------------------------- rules


def _positive(x):
    return None if x > 0 else "must be > 0"


def _non_negative(x):
    return None if x >= 0 else "must be >= 0"


def _open_unit(x):
    return None if 0 < x <= 1 else "must be in (0, 1]"


def _fraction(x):
    return None if 0 < x < 1 else "must be in (0, 1)"


def _poisson(x):
    return None if 0 <= x < 0.5 else "must be in [0, 0.5)"


def _bevel(x):
    return None if 0 < x < 90 else "must be in (0, 90) deg"


def _flank(x):
    return None if 0 <= x < 90 else "must be in [0, 90) deg"


def _crossing(x):
    return None if 0 <= x <= 180 else "must be in [0, 180] deg"


#: The longest scenario name: it names the results directory (results/<name>).
MAX_NAME = 100
#: The longest free text (`description`).
MAX_TEXT = 10_000


def _name(x):
    if re.fullmatch(rf"[A-Za-z0-9][A-Za-z0-9._-]{{0,{MAX_NAME - 1}}}", x):
        return None
    return (f"must be 1-{MAX_NAME} letters, digits, '.', '_' or '-', the first a letter or digit "
            "(it names the results directory)")


def _text(x):
    return None if len(x) <= MAX_TEXT else f"must be at most {MAX_TEXT} characters, not {len(x)}"


#: The most dynamics steps per recorded step (the accuracy study's finest reference takes 2,560).
MAX_SUBSTEPS = 1_000_000


def _substeps(x):
    return None if 1 <= x <= MAX_SUBSTEPS else f"must be in [1, {MAX_SUBSTEPS}]"


def _choice(*options, renamed=None):
    """A rule: one of `options`; `renamed` maps an earlier name to its new one, for the message."""
    renamed = renamed or {}

    def rule(x):
        if x in options:
            return None
        hint = f" ({x} is now {renamed[x]})" if x in renamed else ""
        return f"must be one of {', '.join(options)}{hint}"
    return rule


def key(default=dataclasses.MISSING, rule=None, doc=""):
    """A scenario key: its default (none: required), a rule returning an error or None, a doc."""
    meta = {"rule": rule, "doc": doc}
    if isinstance(default, (list, tuple)):
        return field(default_factory=lambda d=tuple(default): d, metadata=meta)
    return field(default=default, metadata=meta)


# ----------------------------------------------------------------------------- schema


@dataclass(frozen=True, kw_only=True)
class Integrator:
    method: str = key("adaptive_euler", _choice(*sorted(METHODS, key=lambda m: m != "adaptive_euler")),
                      "symplectic_euler (the paper's fixed step), adaptive_euler (symplectic Euler, its "
                      "error controlled), rk4 (fixed step), dopri5 (adaptive)")
    rtol: float = key(1e-6, _positive, "dopri5: relative tolerance per state component")
    atol: float = key(1e-9, _positive, "dopri5: absolute tolerance (m, rad, m/s, rad/s)")
    velocity_tol_m_s: float = key(3e-6, _positive, "adaptive_euler: a step's error in any contact sphere's velocity")
    onset_depth_m: float = key(1e-6, _positive, "adaptive_euler: while pairs may start, the most a step moves two "
                               "spheres closer (a new pair's first penetration)")
    onset_guard: str = key("clearance", _choice("clearance", "travel"),
                           "adaptive_euler: how far a step may move two spheres closer while pairs may start: the "
                           "onset depth at the bound on any two spheres' approach (travel), or the least clearance "
                           "of the sphere pairs not in contact plus the onset depth at the approach rate of its face "
                           "pairs' spheres (clearance: about half the steps)")
    bristle_switches: str = key("within_step", _choice("within_step", "located"),
                                "adaptive_euler: where a bristle that saturates or lets go in a step switches its "
                                "damping c_b v_t: at the step's end (within_step), or at its own time, the step cut "
                                "to end just past it (located)")
    kick: str = key("staggered", _choice(*KICKS),
                    "adaptive_euler: how long a step's velocity update applies the forces at its start: its own "
                    "step (step), or the mean of the last step and its own (staggered: symplectic Euler's velocities "
                    "lie half a step behind its positions, so a change of step leaves no velocity error; the normal "
                    "damping at a step's end reads the indentation rate level with the positions)")
    drive_readings: str = key("pass_quiet", _choice("pass_quiet", "each"),
                              "adaptive methods: whether each reading of a motor drive's speed loop ends a step "
                              "(each), or a step may pass the readings that leave its current as it is: its "
                              "transmission stuck, the loop pressing at its clamp and kept there (pass_quiet)")
    h_min_s: float = key(1e-9, _positive, "adaptive methods: smallest step; below it the run is diverged")
    h_max_s: float = key(4e-4, _positive, "adaptive methods: largest step")


@dataclass(frozen=True, kw_only=True)
class Simulation:
    dt_s: float = key(rule=_positive, doc="recorded step; the paper's is 1 ms")
    substeps: int = key(10, _substeps, "dynamics steps per recorded step (dynamics at dt_s/substeps)")
    duration_s: float = key(rule=_positive, doc="time-out: a grasp not complete by then is incomplete")
    integrator: Integrator = key(Integrator(), doc="time integrator")
    gravity_m_s2: tuple[float, float, float] = key((0.0, 0.0, 0.0), doc="gravity in world, m/s^2")


@dataclass(frozen=True, kw_only=True)
class Compliance:
    joints: str = key("rigid", _choice("rigid", "compliant", "servo"),
                      "rigid (the joints locked and reduced away), compliant (each joint's gearbox a torsional "
                      "spring and damper to its brake, held at its angle) or servo (the gearbox's spring to a "
                      "motor side that turns, its rotor's reflected inertia held by a PD position servo within "
                      "the joint's torque limit): docs/model.md")
    stiffness_scale: float = key(1.0, _positive, "a factor on every joint's catalogue stiffness (compliant joints)")
    damping_ratio: float = key(0.05, _non_negative, "each compliant joint's damping as a share of critical, on the "
                               "link-side inertia it turns at the start (the mass matrix's diagonal)")
    servo_bandwidth_Hz: float = key(20.0, _positive, "servo: the position loop's natural frequency on the joint's "
                                    "inertia (its rotor's reflected inertia and the link side's): its gains")
    servo_damping_ratio: float = key(0.7, _non_negative, "servo: the position loop's damping ratio")


@dataclass(frozen=True, kw_only=True)
class Arm:
    model: str = key("z1", _choice("z1"), "6-DOF arm from example-robot-data")
    joint_angles_rad: tuple[float, float, float, float, float, float] = key(
        doc="the arm's self-locked joint angles during the grasp")
    compliance: Compliance = key(Compliance(), doc="how its joints hold: rigid or compliant")
    base: str = key("fixed", _choice("fixed", "dynamometer"),
                    "fixed (the arm's base on the world) or dynamometer (on the dynamometer block's six-axis "
                    "force plate, which records what it reads: docs/model.md)")


def _all_positive(x):
    return None if all(v > 0 for v in x) else "every value must be > 0"


@dataclass(frozen=True, kw_only=True)
class Dynamometer:
    """A six-axis piezoelectric force plate under the arm's base (paper Sec. 4.2), and the
    charge amplifier and recorder that read it (arm.base: dynamometer)."""

    stiffness_N_um: tuple[float, float, float] = key(
        (1.0, 1.0, 2.0), _all_positive, "the plate's rigidity along its x, y, z, kN/um (= 1e9 N/m per unit)")
    sensor_half_spacing_mm: tuple[float, float] = key(
        (65.0, 30.0), _all_positive, "its four three-component sensors sit at (+-a, +-b) mm in its top plate: "
        "its tilting stiffnesses are k_z b^2 and k_z a^2, its twisting stiffness k_x (a^2 + b^2)")
    top_mass_kg: float = key(4.1, _positive, "the mass above its sensors (its top plate), kg: the bare plate's "
                             "natural frequency along z, f_z = sqrt(k_z / m) / 2 pi")
    top_size_mm: tuple[float, float, float] = key((170.0, 100.0, 25.0), _all_positive,
                                                  "its top plate's length, width and height, mm (its inertia)")
    adapter_mass_kg: float = key(1.6, _non_negative, "the adapter plate between it and the arm's base, kg")
    damping_ratio: float = key(0.03, _non_negative, "each of its six axes' damping as a share of critical, on "
                               "the inertia that axis carries at the start")
    filter_cutoff_Hz: float = key(300.0, _positive, "the charge amplifier's low-pass (anti-alias) filter, Hz")
    filter_order: int = key(2, _substeps, "... its order (a Butterworth)")
    sampling_Hz: float = key(1000.0, _positive, "the recorder's sampling rate, Hz")


@dataclass(frozen=True, kw_only=True)
class Suspension:
    """The module hung on a bungee from a fixed point (paper Sec. 4.2), or free."""

    kind: str = key("none", _choice("none", "bungee"),
                    "none (the module floats free) or bungee (hung from a fixed point straight above its "
                    "centroid, against gravity: simulation.gravity_m_s2 must not be zero)")
    loaded_length_m: float = key(0.636, _positive, "the bungee's length with the module hanging at rest, m: a "
                                 "pendulum of this length swings with a period of 2 pi sqrt(L / g)")
    stiffness_N_m: float = key(90.5, _positive, "its axial stiffness, N/m: the module bounces on it at "
                               "sqrt(k / m) / 2 pi")
    damping_ratio: float = key(0.03, _non_negative, "its axial damping as a share of critical on the module's mass")


@dataclass(frozen=True, kw_only=True)
class Motor:
    rotor_inertia_g_cm2: float = key(0.56, _positive, "the motor's rotor inertia, g cm^2")
    torque_constant_mNm_A: float = key(11.5, _positive, "the motor's torque constant (and back-EMF constant), mN m/A")
    terminal_resistance_ohm: float = key(19.8, _positive, "the motor's terminal resistance, ohm: with the supply "
                                         "voltage and the back-EMF, the current it can draw at a speed")
    supply_voltage_V: float = key(12.0, _positive, "the drive's supply voltage, V")
    current_limit_A: float = key(0.335, _non_negative, "the current loop's clamp, A: the grasp load follows from it "
                                 "through the transmission (forward efficiency x ratio x torque constant)")
    gear_ratio: float = key(4.4, _positive, "the planetary gearhead's reduction (motor turns per screw turn)")
    gear_efficiency: float = key(0.9, _open_unit, "the gearhead's efficiency (both ways)")
    screw_lead_mm: float = key(0.7, _positive, "the lead screw's lead: nut travel per screw turn, mm")
    screw_diameter_mm: float = key(3.545, _positive, "the lead screw's pitch diameter, mm (with the lead, its lead "
                                   "angle)")
    thread_half_angle_deg: float = key(30.0, _flank, "the thread's flank (half) angle, deg: 30 for ISO metric, "
                                       "15 for trapezoidal")
    screw_friction: float = key(0.13, _non_negative, "the friction coefficient of the screw's thread in its nut")
    speed_loop_period_s: float = key(1e-4, _positive, "the digital speed loop (PI, anti-windup) reads the fingers' "
                                     "speed (an encoder's: the travel since its last reading over the period) and "
                                     "sets the current this often; the current loop is ideal")
    speed_loop_bandwidth_Hz: float = key(50.0, _positive, "the speed loop's design bandwidth, Hz: its gains follow "
                                         "from it and the drive's inertia")
    anti_windup: str = key("back_calculation", _choice("back_calculation", "conditional"),
                           "how the speed loop's integral keeps from winding up while the current is clamped: it "
                           "stops (conditional), or it tracks the clamp with the integral time (back_calculation: "
                           "continuous in the speed read, where a stop jumps by a whole reading's increment)")


@dataclass(frozen=True, kw_only=True)
class EndEffector:
    closing_speed_m_s: float = key(rule=_positive, doc="finger closing speed (Table 3), the drive's speed limit")
    grasp_load_N: float = key(20.0, _positive, "mean finger load at which the drive stalls (not in the paper)")
    start_gap_mm: float = key(9.0, _positive, "finger travel from start to touching a centred groove")
    drive: str = key("motor", _choice(*DRIVES, renamed={"actuator": "kinematic"}),
                     "kinematic and relay prescribe the fingers' speed at each controller reading: kinematic (a "
                     "current-limited, self-locking motor's law: slows down along its torque-speed line and presses "
                     "at the grasp load) or relay (stops dead at the grasp load, resumes at full speed below "
                     "resume_fraction of it); motor pushes them by a motor's torque through a gearhead and a "
                     "lead screw (the motor block; the grasp load follows from its current limit)")
    slowdown_fraction: float = key(0.5, _fraction, "kinematic: the share of the grasp load above which the fingers "
                                   "slow down (its no-load speed is the closing speed / (1 - this))")
    resume_fraction: float = key(0.5, _fraction, "relay: a stalled drive resumes closing below this share of the "
                                 "grasp load")
    control_period_s: float = key(1e-4, _positive, "the drive's controller reads the load and sets the speed this "
                                  "often (a digital servo), holding it in between")
    motor: Motor = key(Motor(), doc="motor: the motor, gearhead, lead screw and speed loop behind the fingers")


@dataclass(frozen=True, kw_only=True)
class Inertia:
    ixx: float = key(rule=_positive, doc="moment of inertia about x_b through the centroid, kg m^2")
    iyy: float = key(rule=_positive, doc="moment of inertia about y_b through the centroid, kg m^2")
    izz: float = key(rule=_positive, doc="moment of inertia about z_b through the centroid, kg m^2")
    ixy: float = key(0.0, doc="product of inertia xy, kg m^2: the tensor's entry, as in URDF")
    ixz: float = key(0.0, doc="product of inertia xz, kg m^2: the tensor's entry, as in URDF")
    iyz: float = key(0.0, doc="product of inertia yz, kg m^2: the tensor's entry, as in URDF")


@dataclass(frozen=True, kw_only=True)
class Module:
    mass_kg: float = key(rule=_positive, doc="target module mass (Table 1)")
    inertia_kg_m2: Inertia = key(doc="inertia tensor about the centroid, in O_b axes (Table 1)")
    com_mm: tuple[float, float, float] = key((50.0, 0.0, 0.0), doc="centroid in the groove frame O_b")
    initial_offset_mm: tuple[float, float, float] = key(doc="O_b relative to O_a, in O_a, at start")
    initial_rpy_deg: tuple[float, float, float] = key((0.0, 0.0, 0.0), doc="roll, pitch, yaw of O_b in O_a")


@dataclass(frozen=True, kw_only=True)
class Geometry:
    """The double V-groove and finger dimensions; the XACRO arguments of the same names."""

    upper_bevel_deg: float = key(45.0, _bevel, "upper groove flank angle to its mid-plane")
    lower_bevel_deg: float = key(45.0, _bevel, "lower groove flank angle to its mid-plane")
    groove_angle_deg: float = key(90.0, _crossing, "angle between the two groove axes")
    bevel_edge_length_mm: float = key(44.0, _positive, "length of each flank along its groove axis")
    upper_depth_mm: float = key(13.0, _positive, "upper V depth, mouth to root")
    lower_depth_mm: float = key(13.0, _positive, "lower V depth, mouth to root")
    adapter_half_thickness_mm: float = key(16.0, _positive, "O_b to each groove mouth along z_b")
    finger_length_mm: float = key(20.0, _positive, "finger flank length along the ridge")
    finger_slant_mm: float = key(8.0, _positive, "finger flank width up the slope")
    finger_tip_half_width_mm: float = key(2.0, _positive, "truncated ridge half-width")
    finger_mass_kg: float = key(0.05, _positive, "mass of each finger")
    ee_mount_offset_mm: float = key(120.0, _positive, "flange to gripper body, clearing the Z1 stock gripper")
    grasp_offset_mm: float = key(80.0, _positive, "gripper body to the grasp frame O_a")
    ee_body_mass_kg: float = key(0.3, _positive, "gripper body mass")
    face_thickness_mm: float = key(1.0, _positive, "thickness of the box behind each contact face")
    module_body_size_mm: float = key(80.0, _positive, "module body edge (visual only)")


@dataclass(frozen=True, kw_only=True)
class Contact:
    broad_phase: str = key("coal", _choice("coal", "none"), "coal culling, or the paper's all-pairs search")
    skin_mm: float = key(1.0, _non_negative, "extra coal security margin beyond the contact reach")
    restitution: float = key(0.8, _open_unit, "coefficient of restitution c_r (not in the paper)")
    approach_speed_floor_m_s: float = key(1e-2, _positive,
                                          "floor on each pair's onset normal approach speed (the rate of phi); "
                                          "the damping's delta_dot_minus is floored at half of it")
    normal_direction: str = key("common_normal", _choice("common_normal", "gradient"),
                                "direction of a pair's normal force: the common normal n_c (Eq. 11, the paper), "
                                "or d / (d . n_c) with d of Eq. 7, the gradient of the pair's Hertz potential "
                                "(energy-consistent; friction keeps n_c's tangent plane)")
    force_point: str = key("common", _choice("common", "sphere_centres"),
                           "where a pair's force acts: one common point (Eq. 19-21), or each "
                           "body's own sphere centre (a negative control that breaks angular momentum)")
    youngs_modulus_finger_Pa: float = key(7e10, _positive, "E1 (Table 1)")
    youngs_modulus_groove_Pa: float = key(7e10, _positive, "E2 (Table 1)")
    poisson_finger: float = key(0.25, _poisson, "nu1 (Table 1)")
    poisson_groove: float = key(0.25, _poisson, "nu2 (Table 1)")
    sphere_radius_finger_mm: float = key(0.7, _positive, "master sphere radius (Sec. 3.2)")
    sphere_radius_groove_mm: float = key(0.8, _positive, "slave sphere radius (Sec. 3.2)")


@dataclass(frozen=True, kw_only=True)
class Friction:
    mu_k: float = key(0.26, _positive, "kinetic friction coefficient (Table 2)")
    mu_s: float = key(0.30, _positive, "static friction coefficient (Table 2)")
    bristle_stiffness_N_m: float = key(3e4, _positive, "k_b (Table 2)")
    bristle_damping_N_s_m: float = key(80.0, _non_negative, "c_b (Table 2)")
    velocity_deadband_m_s: float = key(1e-3, _positive, "v_d (Table 2)")


@dataclass(frozen=True, kw_only=True)
class Completion:
    hold_s: float = key(0.02, _positive, "how long every criterion must hold")
    phase_timeout_s: float = key(2.0, _positive, "a grasp not complete this long after its drive starts is incomplete")
    max_contact_speed_m_s: float = key(1e-4, _positive, "relative speed at every active contact below this")
    max_net_force_N: float = key(0.5, _positive, "net contact force on the module below this (equilibrium)")
    record_after_s: float = key(0.0, _non_negative, "the last grasp complete, the run goes on recording this "
                                "long with the drive holding (what rings after the grasp); its peaks and "
                                "residual offset stay the grasp's, at its completion")


@dataclass(frozen=True, kw_only=True)
class Scenario:
    """A single arm on a fixed base grasping one module (paper Sec. 4)."""

    name: str = key(rule=_name, doc="scenario name, used in results")
    kind: str = key("single_arm", _choice("single_arm"), "single_arm or dual_arm")
    simulation: Simulation = key(doc="time step, duration and integrator")
    arm: Arm = key(doc="the arm on its fixed base")
    end_effector: EndEffector = key(doc="the finger drive")
    module: Module = key(doc="the target module")
    description: str = key("", _text, "free text")
    geometry: Geometry = key(Geometry(), doc="the double V-groove and the fingers")
    contact: Contact = key(Contact(), doc="sphere layers, search and the normal contact law (Table 1)")
    friction: Friction = key(Friction(), doc="bristle friction (Table 2)")
    completion: Completion = key(Completion(), doc="when a grasp is complete, and its time-out")
    dynamometer: Dynamometer = key(Dynamometer(), doc="the force plate under the arm (arm.base: dynamometer)")
    suspension: Suspension = key(Suspension(), doc="how the module hangs: free, or on a bungee")


#: Table 6: the arms' joint states during the grasps, rad.
TABLE6_ARM1 = (0.556, 0.481, 1.41, 2.40e-7, 1.25, 0.555)
TABLE6_ARM2 = (-0.511, 0.998, 0.479, 4.00e-6, 1.66, -0.511)


#: The robot's layouts (`spotsim.assemble.robot.LAYOUTS`): `compact`, the arms' mounts on a 400 mm
#: base whose centroid is its centre, fitted to Table 5 body 3 alone; `table5_body4`, the mounts,
#: the base's centroid and TM-1's centroid fitted so that the FDR and the FDR + TM-1 composite
#: both match Table 5 (bodies 3 and 4, the latter read as moments along the base's axes). The
#: latter needs TM-1's centroid here, in its groove frame, mm: 0.341 m from its groove, which
#: a uniform box with TM-1's mass and inertia cannot reach (benchmarks/table5_composite.py).
LAYOUT_TM1_COM_MM = {"compact": None, "table5_body4": (124.0, -198.0, 249.0)}


@dataclass(frozen=True, kw_only=True)
class Robot:
    arm_model: str = key("ur3", _choice("ur3"), "6-DOF arms from example-robot-data")
    layout: str = key("compact", _choice(*LAYOUT_TM1_COM_MM),
                      "compact (the base fitted to Table 5 body 3; TM-1 compact) or table5_body4 (the mounts and "
                      "the base's centroid fitted so that, at Table 6's angles, the FDR + TM-1 composite is Table 5 "
                      "body 4 too; needs tm1.com_mm = "
                      f"{list(LAYOUT_TM1_COM_MM['table5_body4'])}, TM-1's groove on a standoff: docs/validation.md)")
    arm1_joint_angles_rad: tuple[float, float, float, float, float, float] = key(
        TABLE6_ARM1, doc="arm 1 locked at Table 6's joint states")
    arm2_joint_angles_rad: tuple[float, float, float, float, float, float] = key(
        TABLE6_ARM2, doc="arm 2 locked at Table 6's joint states")
    compliance: Compliance = key(Compliance(), doc="how both arms' joints hold: rigid or compliant")


def _direction(x):
    return None if math.sqrt(sum(c * c for c in x)) > 1e-6 else "must be a direction (not the zero vector)"


#: How the dual-arm scene's bodies move: in space, or on the paper's air-bearing testbed.
MOUNTS = ("free_floating", "air_bearing")


@dataclass(frozen=True, kw_only=True)
class Testbed:
    mount: str = key("free_floating", _choice(*MOUNTS),
                     "free_floating (in orbit: the base, TM-1 and TM-2 move in 3-D) or air_bearing (the "
                     "SPOT testbed, paper Sec. 5.2: each floats on a planar joint, moving in the table's "
                     "plane through its start and turning about the table's normal)")
    table_normal: tuple[float, float, float] = key(
        (0.0, 1.0, 0.0), _direction, "the table's normal in world (normalised); a dual-arm run's displacements are "
        "measured in its plane. World y is both grasp frames' y_a at config/spot_testbed_*.yaml's arm angles: their "
        "x_a and closing axes z_a lie in the plane")


@dataclass(frozen=True, kw_only=True)
class DualArmScenario:
    """The free-flying dual-arm robot grasping TM-1 with EE-1, then TM-2 with EE-2 (Sec. 5)."""

    name: str = key(rule=_name, doc="scenario name, used in results")
    kind: str = key(rule=_choice("dual_arm"), doc="single_arm or dual_arm")
    simulation: Simulation = key(doc="time step, duration and integrator")
    end_effector: EndEffector = key(doc="both end-effectors")
    tm1: Module = key(doc="target module 1 (Table 5 body 1), offset from EE-1")
    tm2: Module = key(doc="target module 2 (Table 5 body 2), offset from EE-2")
    description: str = key("", _text, "free text")
    robot: Robot = key(Robot(), doc="the free-flying dual-arm robot")
    geometry: Geometry = key(Geometry(), doc="the double V-groove and the fingers")
    contact: Contact = key(Contact(), doc="sphere layers, search and the normal contact law (Table 1)")
    friction: Friction = key(Friction(), doc="bristle friction (Table 2)")
    completion: Completion = key(Completion(), doc="when a grasp is complete, and its time-out")
    testbed: Testbed = key(Testbed(), doc="in orbit, or on the air-bearing testbed")


SCENARIO_KINDS = {"single_arm": Scenario, "dual_arm": DualArmScenario}


# ------------------------------------------------------------------------ mechanics

#: Mechanism tolerance claimed by the paper (Sec. 2.3): outside it a run warns, not fails.
TOLERANCE_OFFSET_MM = 10.0
TOLERANCE_DEG = {"roll": 30.0, "pitch": 62.0, "yaw": 30.0}


#: The most characters of a value an error message shows.
MAX_SHOWN = 80


def _fmt(value) -> str:
    """A value as YAML on one line, cut to MAX_SHOWN characters."""
    text = yaml.safe_dump(value, default_flow_style=True, width=math.inf).strip().removesuffix("...").strip()
    text = " ".join(text.split())  # a multi-line scalar on one line
    return text if len(text) <= MAX_SHOWN else f"{text[:MAX_SHOWN - 20]}... ({len(text)} characters)"


def _convert(tp, value, path, problems, where):
    """Convert one YAML value to type `tp`, appending problems; returns the value or None."""
    def bad(rule):
        problems.append(f"{where}: {path} = {_fmt(value)}: {rule}")
        return None

    if dataclasses.is_dataclass(tp):
        return _build(tp, value, path, problems, where)
    origin = typing.get_origin(tp)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)) or len(value) != len(args):
            return bad(f"must be a list of {len(args)} numbers")
        items = [_convert(a, v, f"{path}[{i}]", problems, where) for i, (a, v) in enumerate(zip(args, value))]
        return None if any(x is None for x in items) else tuple(items)
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return bad("must be a number")
        try:
            number = float(value)
        except OverflowError:  # an integer beyond any float
            return bad("must be finite")
        if not math.isfinite(number):
            return bad("must be finite")
        return number
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            return bad("must be an integer")
        return value
    if tp is str:
        if not isinstance(value, str):
            return bad("must be a string")
        return value
    raise TypeError(tp)


def _build(cls, data, path, problems, where):
    prefix = f"{path}." if path else ""
    if not isinstance(data, dict):
        problems.append(f"{where}: {path or '<top>'} = {_fmt(data)}: must be a mapping")
        return None
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    for k in data:
        if k not in names:
            problems.append(f"{where}: {prefix}{k} = {_fmt(data[k])}: unknown key "
                            f"(valid: {', '.join(names)})")
    values, ok = {}, True
    for f in dataclasses.fields(cls):
        p = f"{prefix}{f.name}"
        if f.name not in data:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                problems.append(f"{where}: {p} = (missing): required key")
                ok = False
            continue
        v = _convert(hints[f.name], data[f.name], p, problems, where)
        if v is None:
            ok = False
            continue
        rule = f.metadata.get("rule")
        msg = rule(v) if rule else None
        if msg:
            problems.append(f"{where}: {p} = {_fmt(data[f.name])}: {msg}")
            ok = False
        values[f.name] = v
    return cls(**values) if ok else None


#: What a run may allocate: spheres in its layers (77 B each in the compiled model, measured on
#: Case I, and as much again while it is built: 2e6 is about 300 MB) and recorded intervals
#: (304 B of time series each: 5e6 is about 1.5 GB).
MAX_SPHERES = 2_000_000
MAX_RECORDS = 5_000_000
#: Dynamics steps a fixed-step run may take (duration_s / dt_s x substeps): at the 1-10 us a
#: contact step costs, 1e8 is several minutes to hours.
MAX_STEPS = 100_000_000


def _budget(s, where: str) -> list[str]:
    """A run's size against MAX_SPHERES and MAX_RECORDS, estimated from its keys: each face's
    layer holds about (length / r + 1)(width / r + 1) spheres at a spacing of its radius."""
    problems = []
    g, c = s.geometry, s.contact
    grooves = sum((g.bevel_edge_length_mm / c.sphere_radius_groove_mm + 1)
                  * (getattr(g, f"{side}_depth_mm") / math.cos(math.radians(getattr(g, f"{side}_bevel_deg")))
                     / c.sphere_radius_groove_mm + 1) * 2 for side in ("upper", "lower"))
    for side in ("upper", "lower"):  # the lands beside each mouth
        land = 0.5 * g.bevel_edge_length_mm - half_mouth_mm(g, side)
        if land > 0:
            r2 = c.sphere_radius_groove_mm
            grooves += 2 * (g.bevel_edge_length_mm / r2 + 1) * (land / r2 + 1)
    r1 = c.sphere_radius_finger_mm
    fingers = 2 * (g.finger_length_mm / r1 + 1) * (2 * g.finger_slant_mm / r1 + 2 * g.finger_tip_half_width_mm / r1 + 3)
    spheres = len(modules_of(s)) * (grooves + fingers)  # a module and an end-effector per grasp
    if spheres > MAX_SPHERES:
        key = "sphere_radius_groove_mm" if grooves >= fingers else "sphere_radius_finger_mm"
        problems.append(f"{where}: contact.{key} = {_fmt(getattr(c, key))}: the sphere layers would hold about "
                        f"{spheres:.2g} spheres, more than the {MAX_SPHERES:.0e} a run may allocate: use larger "
                        "spheres")
    records = s.simulation.duration_s / s.simulation.dt_s
    if records > MAX_RECORDS:
        problems.append(f"{where}: simulation.duration_s = {_fmt(s.simulation.duration_s)}: {records:.2g} recorded "
                        f"intervals of dt_s = {_fmt(s.simulation.dt_s)}, more than the {MAX_RECORDS:.0e} a run may "
                        f"record: shorten the run or lengthen dt_s")
    sim = s.simulation
    if sim.integrator.method in FIXED_STEP and records * sim.substeps > MAX_STEPS:
        problems.append(f"{where}: simulation.substeps = {sim.substeps}: {records * sim.substeps:.2g} dynamics steps "
                        f"(duration_s / dt_s x substeps) of {sim.integrator.method}, more than the "
                        f"{MAX_STEPS:.0e} a run may take: lower substeps or use adaptive_euler")
    return problems


#: The integrators that take substeps fixed steps per recorded step.
FIXED_STEP = ("symplectic_euler", "rk4")


def _inertia_problems(section: str, m: Module, where: str) -> list[str]:
    """A module's inertia tensor must be one a rigid body can have: positive definite, its
    principal moments each at most the sum of the other two."""
    i = m.inertia_kg_m2
    tensor = [[i.ixx, i.ixy, i.ixz], [i.ixy, i.iyy, i.iyz], [i.ixz, i.iyz, i.izz]]
    moments = sorted(float(x) for x in np.linalg.eigvalsh(tensor))
    shown = ", ".join(f"{x:.4g}" for x in moments)
    if moments[0] <= 0:
        return [f"{where}: {section}.inertia_kg_m2 = {_fmt(to_dict(i))}: must be positive definite "
                f"(its principal moments are {shown} kg m^2)"]
    if moments[2] > (moments[0] + moments[1]) * (1 + 1e-9):
        return [f"{where}: {section}.inertia_kg_m2 = {_fmt(to_dict(i))}: no rigid body has principal moments "
                f"{shown} kg m^2 (the largest must not exceed the sum of the other two)"]
    return []


def _cross_checks(s: Scenario, where: str) -> list[str]:
    problems = _budget(s, where)
    if isinstance(s, DualArmScenario):
        com = LAYOUT_TM1_COM_MM[s.robot.layout]
        if com is not None and tuple(s.tm1.com_mm) != com:
            problems.append(f"{where}: tm1.com_mm = {_fmt(list(s.tm1.com_mm))}: robot.layout = {s.robot.layout} "
                            f"is fitted with TM-1's centroid at {_fmt(list(com))} mm in its groove frame")
    for section, module in modules_of(s).items():
        problems += _inertia_problems(section, module, where)
    if isinstance(s, Scenario) and s.arm.base == "dynamometer":
        dyn, rate = s.dynamometer, 1.0 / s.simulation.dt_s
        if rate < 10.0 * dyn.filter_cutoff_Hz:
            problems.append(f"{where}: simulation.dt_s = {_fmt(s.simulation.dt_s)}: the dynamometer's filter "
                            f"(dynamometer.filter_cutoff_Hz = {_fmt(dyn.filter_cutoff_Hz)}) reads the recorded "
                            f"series, which must be at least ten times faster: dt_s <= {0.1 / dyn.filter_cutoff_Hz:g}")
        ratio = rate / dyn.sampling_Hz
        if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-6 * ratio:
            problems.append(f"{where}: dynamometer.sampling_Hz = {_fmt(dyn.sampling_Hz)}: the recorder keeps every "
                            f"n-th recorded sample: 1 / simulation.dt_s = {rate:g} Hz must be a whole multiple of it")
        if dyn.filter_cutoff_Hz >= 0.5 * dyn.sampling_Hz:
            problems.append(f"{where}: dynamometer.filter_cutoff_Hz = {_fmt(dyn.filter_cutoff_Hz)}: an anti-alias "
                            f"filter cuts off below half the sampling rate ({0.5 * dyn.sampling_Hz:g} Hz)")
    if isinstance(s, Scenario) and s.suspension.kind == "bungee":
        g = math.sqrt(sum(c * c for c in s.simulation.gravity_m_s2))
        b = s.suspension
        if g == 0.0:
            problems.append(f"{where}: suspension.kind = bungee: the module hangs against gravity: "
                            "simulation.gravity_m_s2 must not be zero")
        elif b.loaded_length_m - s.module.mass_kg * g / b.stiffness_N_m <= 0.0:
            problems.append(f"{where}: suspension.stiffness_N_m = {_fmt(b.stiffness_N_m)}: the module's weight would "
                            f"stretch the bungee by {s.module.mass_kg * g / b.stiffness_N_m:.3g} m, more than its "
                            f"loaded length {_fmt(b.loaded_length_m)} m")
    integrator = s.simulation.integrator
    if integrator.h_min_s > integrator.h_max_s:
        problems.append(f"{where}: simulation.integrator.h_min_s = {_fmt(integrator.h_min_s)}: must not exceed "
                        f"simulation.integrator.h_max_s = {_fmt(integrator.h_max_s)}")
    if s.friction.mu_k > s.friction.mu_s:
        problems.append(f"{where}: friction.mu_k = {_fmt(s.friction.mu_k)}: must not exceed "
                        f"friction.mu_s = {_fmt(s.friction.mu_s)}")
    g, c = s.geometry, s.contact
    wide, coarse = [], []  # the grooves whose finger is wider than their mouth; whose flank is narrower than a sphere
    for side in ("upper", "lower"):
        depth = getattr(g, f"{side}_depth_mm")
        if depth > g.adapter_half_thickness_mm:
            problems.append(f"{where}: geometry.{side}_depth_mm = {_fmt(depth)}: must not exceed "
                            f"geometry.adapter_half_thickness_mm = {_fmt(g.adapter_half_thickness_mm)}")
        # the finger seats in its groove: its flanks, up from the truncated tip, fit the mouth
        bevel = math.radians(getattr(g, f"{side}_bevel_deg"))
        mouth = half_mouth_mm(g, side)
        finger = g.finger_tip_half_width_mm + g.finger_slant_mm * math.sin(bevel)
        if finger > mouth:
            wide.append(f"the {side} finger is {finger:.3g} mm wide each side of its ridge, its groove's mouth "
                        f"{mouth:.3g} mm")
        flank = min(g.bevel_edge_length_mm, depth / math.cos(bevel))
        if 2 * c.sphere_radius_groove_mm > flank:
            coarse.append(f"the {side} groove's flank is {flank:.3g} mm on its shorter side")
    if wide:
        problems.append(f"{where}: geometry.finger_slant_mm = {_fmt(g.finger_slant_mm)}: a finger must fit its "
                        f"groove's mouth (finger_tip_half_width_mm + finger_slant_mm sin bevel <= depth tan bevel): "
                        f"{'; '.join(wide)}")
    if coarse:
        problems.append(f"{where}: contact.sphere_radius_groove_mm = {_fmt(c.sphere_radius_groove_mm)}: a sphere "
                        f"must fit a groove's flank: {'; '.join(coarse)}")
    if 2 * c.sphere_radius_finger_mm > min(g.finger_length_mm, g.finger_slant_mm):
        problems.append(f"{where}: contact.sphere_radius_finger_mm = {_fmt(c.sphere_radius_finger_mm)}: a sphere "
                        f"must fit a finger's flank: it is {min(g.finger_length_mm, g.finger_slant_mm):.3g} mm on its "
                        f"shorter side")
    return problems


def half_mouth_mm(g: Geometry, side: str) -> float:
    """Half the width of a groove's mouth, mm: its depth times the tangent of its bevel."""
    return getattr(g, f"{side}_depth_mm") * math.tan(math.radians(getattr(g, f"{side}_bevel_deg")))


def in_grooves(g: Geometry, offset_mm) -> bool:
    """Whether both fingers' flat tips lie wholly within their grooves' mouths at an offset of
    O_b from O_a (mm, in O_a): the upper groove centres y, the lower one the direction its
    frame's y takes (turned by groove_angle about z). Otherwise a finger rests on the land or
    the mouth's edge beside its groove: the module is not captured, however still it lies."""
    gamma = math.radians(g.groove_angle_deg)
    upper = abs(offset_mm[1]) + g.finger_tip_half_width_mm
    lower = abs(offset_mm[0] * math.sin(gamma) - offset_mm[1] * math.cos(gamma)) + g.finger_tip_half_width_mm
    return bool(upper <= half_mouth_mm(g, "upper") and lower <= half_mouth_mm(g, "lower"))


def modules_of(s) -> dict[str, Module]:
    """A scenario's modules by section name."""
    return {"module": s.module} if isinstance(s, Scenario) else {"tm1": s.tm1, "tm2": s.tm2}


def tolerance_warnings(s) -> list[str]:
    """Initial misalignments outside the mechanism's claimed tolerance (Sec. 2.3)."""
    warnings = []
    for section, module in modules_of(s).items():
        x, y, _ = module.initial_offset_mm
        for axis, val in (("x", x), ("y", y)):
            if abs(val) > TOLERANCE_OFFSET_MM:
                warnings.append(f"{section}.initial_offset_mm {axis} = {val} mm is outside the claimed "
                                f"+-{TOLERANCE_OFFSET_MM} mm tolerance")
        for (name, limit), val in zip(TOLERANCE_DEG.items(), module.initial_rpy_deg, strict=True):
            if abs(val) > limit:
                warnings.append(f"{section}.initial_rpy_deg {name} = {val} deg is outside the claimed "
                                f"+-{limit} deg tolerance")
    return warnings


def set_override(raw: dict, assignment: str) -> None:
    """Apply one `key.path=value` override to a raw scenario mapping (value parsed as YAML)."""
    if "=" not in assignment:
        raise ScenarioError([f"--set: {assignment}: must read key.path=value"])
    path, text = assignment.split("=", 1)
    value = parse_yaml(text, f"--set: {path} = {text}")
    set_value(raw, path.strip(), value)


def set_value(raw: dict, path: str, value) -> None:
    """Set `key.path` of a raw scenario mapping to `value`, making the mappings on the way; a
    whole-number part after a sequence picks one of its items (`module.initial_offset_mm.1`,
    the second component; the sequence is taken from the scenario's defaults when the
    mapping does not have it)."""
    parts = path.split(".")
    node = raw
    for i, part in enumerate(parts[:-1]):
        nxt = parts[i + 1]
        if isinstance(node, list):
            node = node[_index(node, part, parts[:i + 1], path)]
            continue
        if nxt.isdigit() and not isinstance(node.get(part), list):
            node[part] = _default_sequence(raw, parts[:i + 1], path)
        elif not nxt.isdigit() and not isinstance(node.get(part), dict):
            node[part] = {}
        node = node[part]
    if isinstance(node, list):
        node[_index(node, parts[-1], parts, path)] = value
    else:
        node[parts[-1]] = value


def _index(sequence: list, part: str, parts: list[str], path: str) -> int:
    if not part.isdigit() or int(part) >= len(sequence):
        raise ScenarioError([f"--set: {path}: {'.'.join(parts[:-1])} has {len(sequence)} items: "
                             f"{part} is not one of 0..{len(sequence) - 1}"])
    return int(part)


def _default_sequence(raw: dict, parts: list[str], path: str) -> list:
    """The default of the sequence at key path `parts` for a scenario of raw's kind, as a list."""
    kind = raw.get("kind", "single_arm") if isinstance(raw, dict) else "single_arm"
    cls, value = SCENARIO_KINDS.get(kind, Scenario), None
    for part in parts:
        fields = {f.name: f for f in dataclasses.fields(cls)} if cls is not None else {}
        if part not in fields:
            raise ScenarioError([f"--set: {path}: {'.'.join(parts)} is not a sequence of the scenario"])
        f = fields[part]
        value = (f.default if f.default is not dataclasses.MISSING else
                 f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
        hint = typing.get_type_hints(cls).get(part)
        cls = hint if isinstance(hint, type) and dataclasses.is_dataclass(hint) else None
    if not isinstance(value, (tuple, list)):
        raise ScenarioError([f"--set: {path}: {'.'.join(parts)} is not a sequence of the scenario"])
    return list(value)


def from_dict(raw: Any, where: str = "<scenario>"):
    """Validate a raw mapping into a Scenario (or DualArmScenario, by `kind`), or raise
    ScenarioError with every problem."""
    problems: list[str] = []
    kind = raw.get("kind", "single_arm") if isinstance(raw, dict) else "single_arm"
    if not isinstance(kind, str) or kind not in SCENARIO_KINDS:
        raise ScenarioError([f"{where}: kind = {_fmt(kind)}: must be one of {', '.join(SCENARIO_KINDS)}"])
    sim = raw.get("simulation") if isinstance(raw, dict) else None
    if isinstance(sim, dict) and isinstance(sim.get("integrator"), str):  # `integrator: rk4` names the method
        raw = {**raw, "simulation": {**sim, "integrator": {"method": sim["integrator"]}}}
    scenario = _build(SCENARIO_KINDS[kind], raw, "", problems, where)
    if scenario is not None:
        problems += _cross_checks(scenario, where)
    if problems:
        raise ScenarioError(problems)
    return scenario


#: The most bytes a scenario file may hold (the shipped ones hold 2-3 kB).
MAX_FILE_BYTES = 1_000_000
#: The most values (YAML nodes) a scenario may hold with its aliases expanded: an alias
#: (*name) stands for a whole tree, and a few nested ones for more nodes than memory holds
#: once anything walks them. The shipped scenarios hold about 150.
MAX_NODES = 100_000


class TooLarge(yaml.composer.ComposerError):
    """Valid YAML, larger than a scenario may be."""


class Loader(yaml.SafeLoader):
    """PyYAML's safe loader, strict where a scenario needs it: a number in exponent form
    without a dot (1e-6, 2E3) is a number, as YAML 1.2 and every scientist read it (YAML 1.1
    reads it as a string); a key given twice in one mapping is an error naming both lines;
    more than MAX_NODES values, aliases expanded, are an error where the count passes it."""

    def compose_node(self, parent, index):
        mark = self.peek_event().start_mark
        node = super().compose_node(parent, index)
        sizes = self.__dict__.setdefault("_sizes", {})  # id(node) -> values in its expanded tree
        if id(node) not in sizes:
            children = node.value if isinstance(node, yaml.SequenceNode) else \
                [n for pair in node.value for n in pair] if isinstance(node, yaml.MappingNode) else ()
            sizes[id(node)] = 1 + sum(sizes.get(id(c), 1) for c in children)
        if sizes[id(node)] > MAX_NODES:
            raise TooLarge(None, None, f"more than {MAX_NODES:.0e} values, aliases expanded", mark)
        return node


# YAML 1.2's float, exponent forms included, in place of YAML 1.1's (which needs a dot)
Loader.yaml_implicit_resolvers = {k: [(tag, rx) for tag, rx in v if tag != "tag:yaml.org,2002:float"]
                                  for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()}
Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?[0-9][0-9_]*\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                   |[-+]?\.[0-9][0-9_]*(?:[eE][-+]?[0-9]+)?
                   |[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+
                   |[-+]?\.(?:inf|Inf|INF)
                   |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+0123456789."))


def _mapping(loader: Loader, node: yaml.MappingNode, deep: bool = False) -> dict:
    seen: dict = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        try:
            first = seen.setdefault(key, key_node.start_mark.line + 1)
        except TypeError:  # an unhashable key: SafeLoader's own error names it
            break
        if first != key_node.start_mark.line + 1:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r} (first at line {first})", key_node.start_mark)
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)


def parse_yaml(text: str, where: str) -> Any:
    """YAML text's data (`Loader`), or ScenarioError: `where: line N: problem`."""
    try:
        return yaml.load(text, Loader=Loader)  # noqa: S506 - a SafeLoader
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        line = f"line {mark.line + 1}: " if mark is not None else ""
        kind = "" if isinstance(e, (yaml.constructor.ConstructorError, TooLarge)) else "not valid YAML: "
        raise ScenarioError([f"{where}: {line}{kind}{e.problem or e.context}"]) from None
    except yaml.YAMLError as e:
        raise ScenarioError([f"{where}: not valid YAML: {e}"]) from None
    except RecursionError:
        raise ScenarioError([f"{where}: nested too deeply to read"]) from None


def read_yaml(path: str | Path) -> Any:
    """A YAML file's data (`parse_yaml`), or ScenarioError naming the file when it cannot be
    read, is not UTF-8 text, or not valid YAML."""
    path = Path(path)
    try:
        with path.open("rb") as f:  # at most one byte too many: a device or a pipe may not end
            data = f.read(MAX_FILE_BYTES + 1)
    except OSError as e:
        raise ScenarioError([f"{path}: cannot read: {e.strerror}"]) from e
    if len(data) > MAX_FILE_BYTES:
        raise ScenarioError([f"{path}: more than the {MAX_FILE_BYTES:.0e} bytes a scenario file may hold"])
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ScenarioError([f"{path}: not UTF-8 text (byte {e.start}: {e.object[e.start:e.start + 1]!r})"]) from None
    return parse_yaml(text, str(path))


def load_scenario(path: str | Path, overrides: list[str] = ()) -> Scenario:
    """Read, override (`key.path=value`) and validate a YAML scenario file, or a shipped
    scenario by name (`paths.scenario_file`: `load_scenario("case_III")`)."""
    path = scenario_file(path)
    raw = read_yaml(path)
    if raw is None:
        raw = {}
    if isinstance(raw, dict):  # anything else is reported by from_dict as not a mapping
        for assignment in overrides:
            set_override(raw, assignment)
    return from_dict(raw, str(path))


def to_dict(s) -> dict:
    """A Scenario (or part of one) as plain YAML-ready data."""
    out = {}
    for f in dataclasses.fields(s):
        v = getattr(s, f.name)
        out[f.name] = to_dict(v) if dataclasses.is_dataclass(v) else (list(v) if isinstance(v, tuple) else v)
    return out


def to_yaml(s: Scenario) -> str:
    return yaml.safe_dump(to_dict(s), sort_keys=False)


#: Keys added to a block after scenarios were first fingerprinted, by the block's path, at the
#: value that runs the scene as before the key: there they stay out of the fingerprint.
AS_BEFORE = {("completion",): {"record_after_s": 0.0},  # the grasp ends the run
             ("simulation", "integrator"): {"kick": "step", "drive_readings": "each"},
             ("end_effector", "motor"): {"anti_windup": "conditional"}}


def fingerprint(s) -> str:
    """The scene a scenario runs, as a short hash of every value but its name and description,
    of the motor block unless its drive is the motor (no other drive reads it), and of the arms'
    compliance block unless their joints are compliant (rigid joints read nothing of it), of the
    dynamometer and the suspension unless they are there, and of the keys of AS_BEFORE at their
    values there: equal for two scenarios that run the same physics at the same settings."""
    raw = {k: v for k, v in to_dict(s).items() if k not in ("name", "description")}
    if s.end_effector.drive != "motor":
        raw["end_effector"] = {k: v for k, v in raw["end_effector"].items() if k != "motor"}
    arms = "arm" if "arm" in raw else "robot"
    if raw[arms]["compliance"]["joints"] == "rigid":
        raw[arms] = {k: v for k, v in raw[arms].items() if k != "compliance"}
    if raw.get("arm", {}).get("base") == "fixed":  # the lab rig's blocks, unless it is there
        raw["arm"] = {k: v for k, v in raw["arm"].items() if k != "base"}
        raw.pop("dynamometer")
    if raw.get("suspension", {}).get("kind") == "none":
        raw.pop("suspension")
    for path, before in AS_BEFORE.items():
        parent = raw
        for k in path[:-1]:
            parent = parent[k]
        if path[-1] in parent:
            parent[path[-1]] = {k: v for k, v in parent[path[-1]].items() if k not in before or before[k] != v}
    return hashlib.sha256(json.dumps(raw, sort_keys=True).encode()).hexdigest()[:16]


def replace(s: Scenario, **changes) -> Scenario:
    """A copy of `s` with `section={'key': value}` or `key=value` changes, validated again. A
    change to a section changes only the keys it names, at any depth: `simulation={'integrator':
    {'kick': 'staggered'}}` keeps the scenario's other integrator keys."""
    return from_dict(_merged(to_dict(s), changes), f"<{s.name}>")


def _merged(raw: dict, changes: dict) -> dict:
    """raw (a scenario's dict) with changes merged in, section by section."""
    for name, value in changes.items():
        if isinstance(value, dict) and isinstance(raw.get(name), dict):
            _merged(raw[name], value)
        else:
            raw[name] = value
    return raw

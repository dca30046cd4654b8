"""The built scene: reduced degrees of freedom, checked inertias, and the groove's geometry."""

import numpy as np
import pinocchio as pin
import pytest

from spotsim.assemble.scene import check_inertias
from spotsim.errors import ModelError


def test_locked_arm_is_reduced_away_and_the_fingers_stay_on_their_joints(model_I):
    """The module's free-flyer and the fingers' prismatic joints remain: the arm is locked."""
    m = model_I.pin_model
    assert (m.nq, m.nv) == (9, 8)
    assert sorted(m.names[1:]) == ["ee_finger_lower", "ee_finger_upper", "tm_free_flyer"]
    assert [m.joints[j].shortname() for j in range(1, m.njoints)] == ["JointModelPZ", "JointModelPZ",
                                                                       "JointModelFreeFlyer"]


def test_fingers_open_along_the_closing_axis(model_I):
    """The upper finger opens along +z_a and the lower one along -z_a (in the world: O_a is fixed)."""
    ee = model_I.end_effectors[0]
    assert ee.joint == 0  # the grasp frame hangs on the fixed base: its placement is in world
    R = ee.placement.rotation
    m = model_I.pin_model
    axes = {f.name: m.jointPlacements[f.joint].rotation @ [0, 0, 1] for f in model_I.fingers}  # their joints' z
    assert np.allclose(axes["ee_finger_upper"], R @ [0, 0, 1], atol=1e-12)
    assert np.allclose(axes["ee_finger_lower"], R @ [0, 0, -1], atol=1e-12)


def test_module_carries_table_1_mass_and_inertia(model_I):
    """The module body has Table 1's mass and inertia about its centroid."""
    I = model_I.pin_model.inertias[model_I.module_joint]
    assert I.mass == pytest.approx(2.768)
    expected = np.array([[4.739e-3, 5.349e-5, 3.760e-5], [5.349e-5, 4.668e-3, 7.25e-5],
                         [3.760e-5, 7.25e-5, 4.707e-3]])
    assert np.allclose(I.inertia, expected, rtol=1e-12, atol=0)


def test_groove_admits_the_claimed_parallel_offset(case_I):
    """A finger tip lands inside the groove mouth for offsets up to the claimed +-10 mm."""
    g = case_I.geometry
    for side in ("upper", "lower"):
        mouth = getattr(g, f"{side}_depth_mm") * np.tan(np.radians(getattr(g, f"{side}_bevel_deg")))
        assert mouth - g.finger_tip_half_width_mm >= 10.0
    # along each groove's axis the finger must stay on the flanks over +-10 mm
    assert (g.bevel_edge_length_mm - g.finger_length_mm) / 2 >= 10.0


def test_opening_at_touch_is_the_layer_thickness_over_the_flank_slope(model_I, case_I):
    """Sphere layers of a centred groove touch when the flanks are 2 (r1 + r2) apart: along the
    finger's closing axis that is 2 (r1 + r2) / sin(bevel) of opening."""
    r = (case_I.contact.sphere_radius_finger_mm + case_I.contact.sphere_radius_groove_mm) * 1e-3
    for f in model_I.fingers:
        assert f.opening_touch == pytest.approx(2 * r / np.sin(np.radians(45.0)), rel=1e-12)


def urdf_model(mass="1", ixx="1e-3", ixy="0", xyz="0 0 0"):
    """A one-body URDF with the given inertial values, as Pinocchio parses it (unchecked)."""
    urdf = f"""<robot name="r"><link name="a"/>
      <joint name="j" type="floating"><parent link="a"/><child link="b"/></joint>
      <link name="b"><inertial><origin xyz="{xyz}"/><mass value="{mass}"/>
        <inertia ixx="{ixx}" iyy="1e-3" izz="1e-3" ixy="{ixy}" ixz="0" iyz="0"/></inertial></link>
    </robot>"""
    m = pin.buildModelFromXML(urdf)
    return m, {1}


@pytest.mark.parametrize("kwargs, words", [
    (dict(mass="-1"), "mass -1.0 kg must be > 0"),
    (dict(mass="0"), "mass 0.0 kg must be > 0"),
    (dict(ixx="-1e-3"), "not positive definite"),
    (dict(ixy="2e-3"), "not positive definite"),
    # urdfdom drops an inertial it cannot parse, with only a log line: a massless body
    (dict(xyz="1e400 0 0"), "mass 0.0 kg must be > 0"),
])
def test_bad_inertias_are_rejected(kwargs, words):
    """Pinocchio's URDF parser accepts these silently; the model check does not."""
    model, joints = urdf_model(**kwargs)
    with pytest.raises(ModelError, match=words):
        check_inertias(model, joints)


def test_non_finite_inertia_is_rejected():
    """A NaN centroid set on a built model is caught."""
    model, joints = urdf_model()
    model.inertias[1] = pin.Inertia(1.0, np.array([np.nan, 0.0, 0.0]), np.eye(3) * 1e-3)
    with pytest.raises(ModelError, match="non-finite"):
        check_inertias(model, joints)


def test_shipped_scene_passes_the_inertia_check(model_I):
    """Every body of the reduced scene has positive mass and a positive-definite inertia."""
    check_inertias(model_I.pin_model, set(range(1, model_I.pin_model.njoints)))


def test_dual_arm_modules_take_their_products_of_inertia():
    """Every inertia key of a dual-arm module reaches its body, products included (the XACRO
    once fixed them at zero, silently)."""
    from conftest import ROOT

    import spotsim

    s = spotsim.load_scenario(ROOT / "config" / "dual_arm_sequential.yaml")
    products = {"ixy": 0.01, "ixz": -0.02, "iyz": 0.005}
    for k, section in enumerate(("tm1", "tm2")):
        inertia = {**spotsim.scenario.to_dict(getattr(s, section).inertia_kg_m2), **products}
        model = spotsim.build_model(spotsim.replace(s, **{section: {"inertia_kg_m2": inertia}}))
        I = model.pin_model.inertias[model.modules[k].joint].inertia
        assert (I[0, 1], I[0, 2], I[1, 2]) == pytest.approx((0.01, -0.02, 0.005), abs=1e-15)


def test_a_field_set_from_python_is_what_compiled_code_and_copies_read(model_I):
    """Data is a compiled structure: a field set from Python writes it (not an attribute of the
    proxy alone), so a step, `view` and `copy` see the new value."""
    from spotsim.run import Stepper
    from spotsim.sim.data import make_data

    d = make_data(model_I)
    d.t = 0.25
    d.sample_t += 0.125
    assert d.view().t == 0.25 and d.copy().t == 0.25
    assert d.copy().sample_t == d.view().sample_t == make_data(model_I).sample_t + 0.125
    Stepper(model_I, d).step(1e-5)
    assert d.t > 0.25  # the step went on from the time set, not from the start

"""write_urdf of locked and bare-model robots: the file reloads to the same dynamics."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import pinobs
from pinobs.model.identification import MomentumRegressor
from pinobs.model.urdf_writer import generated_root_joint, write_urdf

FINGERS = ["panda_finger_joint1", "panda_finger_joint2"]


def _assert_same_dynamics(a: pinobs.Robot, b: pinobs.Robot, rng: np.random.Generator) -> None:
    """M(q), c(q, v) + g(q) and the forward dynamics (friction included) at random q, to 1e-12."""
    assert a.joint_names == b.joint_names and (a.nq, a.nv) == (b.nq, b.nv)
    for _ in range(10):
        q = a.random_configuration(rng)
        v = rng.normal(size=a.nv)
        tau = rng.normal(size=a.nv)
        np.testing.assert_allclose(b.mass_matrix(q), a.mass_matrix(q), rtol=0, atol=1e-12)
        nle = a.nonlinear_effects(q, v)  # [N·m], tens: 1e-12 of its size
        np.testing.assert_allclose(
            b.nonlinear_effects(q, v), nle, rtol=0, atol=1e-12 * max(1.0, np.abs(nle).max())
        )
        np.testing.assert_allclose(
            b.forward_dynamics(q, v, tau), a.forward_dynamics(q, v, tau), rtol=0, atol=1e-10
        )


def _joint_types(path: str) -> dict[str | None, str | None]:
    return {j.get("name"): j.get("type") for j in ET.parse(path).getroot().findall("joint")}


def test_a_perturbed_locked_panda_reloads_without_lock_to_the_same_dynamics(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    robot = pinobs.load("panda", lock={FINGERS[0]: 0.03, FINGERS[1]: 0.01})
    truth = robot.perturbed(
        inertia_scale=np.linspace(0.8, 1.2, 7),
        payload=(0.5, [0.0, 0.02, 0.1]),
        damping=np.linspace(0.05, 0.2, 7),
        coulomb=np.linspace(0.02, 0.1, 7),
    )
    path = write_urdf(truth, tmp_path / "calibrated.urdf")
    types = _joint_types(path)
    assert types[FINGERS[0]] == types[FINGERS[1]] == "fixed"
    assert all(types[n] == "revolute" for n in truth.joint_names)
    # a file now: its (fixed) finger joints no longer mimic, so it loads with mimic='error'
    back = pinobs.load(path, friction=True)  # (and no warning: pytest makes them errors)
    assert back.locked == {}
    _assert_same_dynamics(truth, back, rng)


@pytest.mark.parametrize(
    ("name", "lock"),
    [
        ("ur5", {"elbow_joint": 0.7, "wrist_3_joint": -1.1}),  # a middle and the last joint
        ("cartpole_continuous", {"pole_theta": 2.5}),  # continuous: a rotation by its angle
        ("cartpole_continuous", {"cart_x": 0.3}),  # prismatic: a translation along its axis
        ("go1", {"FL_calf_joint": -1.5, "RR_thigh_joint": 0.9}),  # under a free-flyer
    ],
)
def test_locked_joints_are_written_as_fixed_joints_at_their_values(
    name: str, lock: dict[str, float], tmp_path: Path, rng: np.random.Generator
) -> None:
    robot = pinobs.load(name, lock=lock)
    path = write_urdf(robot, tmp_path / "locked.urdf")
    assert all(_joint_types(path)[n] == "fixed" for n in lock)
    back = pinobs.load(path, root_joint=robot.root_joint)
    _assert_same_dynamics(robot, back, rng)


def test_an_identified_locked_robot_saves_a_urdf_with_the_same_dynamics(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    robot = pinobs.load("panda", lock=FINGERS)
    reg = MomentumRegressor(robot)
    nominal = reg.nominal()
    theta = nominal.copy()  # each body's 10 parameters scaled together (still physical),
    theta[: 10 * 7] *= np.repeat(rng.uniform(0.8, 1.2, size=7), 10)
    theta[10 * 7 :] = rng.uniform(0.01, 0.1, size=nominal.size - 70)  # friction, offset
    identified = reg.with_parameters(theta, name="panda+id")
    assert identified.locked == robot.locked
    assert identified.friction  # (identified: switched on)
    back = pinobs.load(write_urdf(identified, tmp_path / "id.urdf"), friction=True)
    _assert_same_dynamics(identified, back, rng)


def test_a_reduced_pin_model_is_written_as_a_generated_urdf(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    full = pinobs.load("panda").model
    ids = [full.getJointId(n) for n in FINGERS]
    robot = pinobs.load(pin.buildReducedModel(full, ids, pin.neutral(full)))
    path = write_urdf(robot, tmp_path / "reduced.urdf")  # was: cannot find the URDF
    back = pinobs.load(path)
    assert back.visual_model.ngeoms == 0  # the model alone: no geometry
    _assert_same_dynamics(robot, back, rng)


@pytest.mark.parametrize("name", ["rigid_body", "top", "cartpole_continuous", "go1", "ur5"])
def test_a_generated_urdf_reloads_every_joint_type_and_root(
    name: str, tmp_path: Path, rng: np.random.Generator
) -> None:
    source = pinobs.load(name)
    robot = pinobs.load(source.model.copy(), friction=False)
    path = write_urdf(robot, tmp_path / f"{name}.urdf")
    root = generated_root_joint(robot.model)
    assert root == source.root_joint
    _assert_same_dynamics(robot, pinobs.load(path, root_joint=root), rng)


def test_a_generated_urdf_keeps_limits_friction_and_unaligned_axes(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    model = pin.Model()
    axis = np.array([0.0, 0.6, 0.8])
    j1 = model.addJoint(
        0,
        pin.JointModelRevoluteUnaligned(*axis),
        pin.SE3(pin.utils.rotate("x", 0.3), np.ones(3)),
        "a",
    )
    model.appendBodyToJoint(j1, pin.Inertia.FromBox(1.2, 0.1, 0.2, 0.3), pin.SE3.Identity())
    j2 = model.addJoint(
        j1,
        pin.JointModelPrismaticUnaligned(0.0, 0.0, 1.0),
        pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.4])),
        "b",
        np.array([50.0]),
        np.array([2.0]),
        np.array([-0.1]),
        np.array([0.2]),
    )
    model.appendBodyToJoint(j2, pin.Inertia.FromSphere(0.5, 0.05), pin.SE3.Identity())
    model.damping = np.array([0.3, 0.2])
    model.friction = np.array([0.1, 0.05])
    robot = pinobs.load(model, friction=True)
    back = pinobs.load(write_urdf(robot, tmp_path / "unaligned.urdf"), friction=True)
    _assert_same_dynamics(robot, back, rng)
    np.testing.assert_array_equal(back.model.damping, model.damping)
    np.testing.assert_array_equal(back.model.friction, model.friction)
    for limit in ("lowerPositionLimit", "upperPositionLimit", "effortLimit", "velocityLimit"):
        np.testing.assert_array_equal(getattr(back.model, limit)[1:], getattr(model, limit)[1:])


def test_what_a_urdf_cannot_say_is_refused_naming_it(tmp_path: Path) -> None:
    go1 = pinobs.load("go1", lock={"root_joint": (0, 0, 0.3, 0, 0, 0, 1)})
    with pytest.raises(pinobs.ModelFileError, match=r"joint 'root_joint' locked, which is not a"):
        write_urdf(go1, tmp_path / "x.urdf")
    model = pinobs.load("planar_3r").model.copy()
    model.gravity.linear = np.array([0.0, 0.0, -1.62])
    with pytest.raises(pinobs.ModelFileError, match=r"gravity \[0\.0, 0\.0, -1\.62\]"):
        write_urdf(pinobs.load(model), tmp_path / "x.urdf")
    top = pinobs.load("top").model.copy()  # a spherical joint that is not the root
    j = top.addJoint(1, pin.JointModelSpherical(), pin.SE3(np.eye(3), np.ones(3)), "ball")
    top.appendBodyToJoint(j, pin.Inertia.FromSphere(1.0, 0.1), pin.SE3.Identity())
    with pytest.raises(pinobs.ModelFileError, match=r"joint 'ball' is a JointModelSpherical"):
        write_urdf(pinobs.load(top), tmp_path / "x.urdf")
    assert not (tmp_path / "x.urdf").exists()


@pytest.mark.parametrize("source", ["ur5", "model"])
def test_the_armature_is_written_beside_the_urdf_and_loaded_back(
    source: str, tmp_path: Path, rng: np.random.Generator
) -> None:
    """A URDF cannot hold a rotor inertia: the sidecar ``<name>.pinobs.json`` does, from a
    rewritten URDF or one generated from a ``pin.Model``; writing a robot without armature
    to the same file removes the sidecar, so it is not read back for it."""
    robot = pinobs.load("ur5")
    model = robot.model.copy()
    model.armature = np.array([0.0, 0.5, 0.2, 0.0, 0.1, 0.05])
    geared = robot.with_model(model) if source == "ur5" else pinobs.load(model)
    path = tmp_path / "geared.urdf"
    back = pinobs.load(write_urdf(geared, path))
    sidecar = json.loads((tmp_path / "geared.pinobs.json").read_text())
    assert sidecar["armature"] == {
        "shoulder_lift_joint": 0.5,
        "elbow_joint": 0.2,
        "wrist_2_joint": 0.1,
        "wrist_3_joint": 0.05,
    }
    np.testing.assert_array_equal(back.model.armature, model.armature)
    _assert_same_dynamics(geared, back, rng)
    write_urdf(robot, path)
    assert not (tmp_path / "geared.pinobs.json").exists()
    assert not np.any(pinobs.load(path).model.armature)

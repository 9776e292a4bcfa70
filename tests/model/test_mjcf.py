"""MJCF files compiled by MuJoCo and rebuilt in Pinocchio, checked against MuJoCo itself."""

from __future__ import annotations

import builtins
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import pinobs
from pinobs.model.loading import _models_dir
from pinobs.model.mjcf import MASS_MATRIX_RTOL, build_from_mujoco, cross_check

mujoco = pytest.importorskip("mujoco")

# every joint type, several joints in one body with off-centre anchors, a joint
# reference, unaligned axes, rotated bodies and inertias, default-class masses,
# armature and damping, and a second body tree
TREES = """<mujoco model="trees">
  <option><flag contact="disable"/></option>
  <default>
    <joint armature="0.02" damping="0.1"/>
    <geom mass="0.7"/>
    <default class="light"><geom mass="0.05"/></default>
  </default>
  <worldbody>
    <body name="base" pos="0.1 -0.2 1" euler="10 20 30">
      <freejoint name="root"/>
      <geom type="box" size="0.3 0.2 0.1" mass="3"/>
      <body name="wrist" pos="0.3 0 0" quat="0.9 0.1 -0.3 0.2">
        <joint name="rx" type="hinge" axis="1 0 0" pos="0 0.05 0" ref="0.4"/>
        <joint name="ry" type="hinge" axis="0.3 1 -0.2" pos="0.02 0 0.1"/>
        <joint name="sz" type="slide" axis="0 0.2 1" pos="0.5 0.5 0.5"/>
        <geom type="capsule" fromto="0 0 0 0.4 0.1 -0.2" size="0.03"/>
        <geom type="sphere" pos="0.4 0.1 -0.2" size="0.05" class="light"/>
        <body name="ball" pos="0.4 0.1 -0.2" axisangle="0 1 1 0.7">
          <joint name="sph" type="ball" pos="0.01 -0.02 0.03"/>
          <geom type="ellipsoid" size="0.1 0.05 0.02" pos="0.1 0 0" euler="0 40 10"/>
        </body>
      </body>
    </body>
    <body name="arm" pos="2 0 0.5">
      <joint name="shoulder" type="hinge" axis="0 0 1"/>
      <geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.04"/>
      <body name="forearm" pos="0.5 0 0">
        <joint name="elbow" type="hinge" axis="0 0 -1" ref="-0.3"/>
        <geom type="capsule" fromto="0 0 0 0.4 0 0.05" size="0.03" class="light"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def _file(tmp_path: Path, text: str, name: str = "model.xml") -> Path:
    f = tmp_path / name
    f.write_text(text)
    return f


@pytest.mark.parametrize(("name", "mass"), [("mjcf_cartpole", 1.1), ("mjcf_acrobot", 2.0)])
def test_dm_control_style_files_keep_mujocos_masses_armature_and_damping(
    name: str, mass: float
) -> None:
    path = _models_dir() / f"{name}.xml"
    robot = pinobs.load(path)
    mj = mujoco.MjModel.from_xml_path(str(path))
    total = sum(i.mass for i in robot.model.inertias)
    assert total == pytest.approx(mass, rel=1e-12) and total == pytest.approx(
        float(mj.body_mass.sum()), rel=1e-9
    )
    np.testing.assert_array_equal(robot.model.armature, mj.dof_armature)
    np.testing.assert_array_equal(robot.model.damping, mj.dof_damping)
    assert robot.friction and robot.has_friction  # MJCF damping used by default
    assert not pinobs.load(path, friction=False).has_friction


@pytest.mark.parametrize("name", ["mjcf_cartpole", "mjcf_acrobot", "trees"])
def test_mass_matrix_equals_mj_full_m_at_20_random_configurations(
    name: str, tmp_path: Path
) -> None:
    path = _file(tmp_path, TREES) if name == "trees" else _models_dir() / f"{name}.xml"
    model, mj, mapping, _ = build_from_mujoco(path)
    assert model.nv == mj.nv
    worst = cross_check(model, mj, mapping, samples=20, seed=1)
    assert worst < MASS_MATRIX_RTOL


def _mujoco_qacc(mj: Any, qpos: np.ndarray, qvel: np.ndarray, qfrc: np.ndarray) -> np.ndarray:
    data = mujoco.MjData(mj)
    data.qpos[:], data.qvel[:], data.qfrc_applied[:] = qpos, qvel, qfrc
    mujoco.mj_forward(mj, data)
    return np.array(data.qacc)


def test_forward_dynamics_with_damping_equal_mujocos_on_every_joint_type(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    path = _file(tmp_path, TREES)
    robot = pinobs.load(path)
    _, mj, mapping, _ = build_from_mujoco(path)
    assert robot.nv == 6 + 3 + 3 + 2 and robot.nq == 7 + 3 + 4 + 2
    for _ in range(5):
        q = robot.random_configuration(rng, scale=np.pi)
        v, tau = rng.normal(size=robot.nv), rng.normal(size=robot.nv)
        jac = mapping.velocity_jacobian(q)
        qacc = _mujoco_qacc(mj, mapping.qpos_from_q(q), jac @ v, np.linalg.solve(jac.T, tau))
        a = robot.forward_dynamics(q, v, tau)
        # qvel = J v, so qacc = J a + J̇ v; J̇ v = [R (ω × v_lin); 0] on the free joint
        rot = jac[:3, :3]
        expected = jac @ a
        expected[:3] += rot @ np.cross(v[3:6], v[:3])
        np.testing.assert_allclose(qacc, expected, rtol=1e-9, atol=1e-9 * np.abs(qacc).max())


def test_configuration_maps_round_trip_and_convert_quaternion_order(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    robot = pinobs.load(_file(tmp_path, TREES))
    _, _, mapping, _ = build_from_mujoco(_file(tmp_path, TREES))
    q = robot.random_configuration(rng)
    qpos = mapping.qpos_from_q(q)
    np.testing.assert_allclose(mapping.q_from_qpos(qpos), q, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(qpos[3:7], [q[6], *q[3:6]])  # MuJoCo w, x, y, z
    # hinge "rx" measured from ref = 0.4 (MJCF angles are in degrees by default)
    assert qpos[7] == pytest.approx(q[7] + np.deg2rad(0.4), rel=1e-15)
    # MuJoCo's qpos0 is the neutral configuration but for the free body's pose in the file
    q0 = mapping.q_from_qpos(mapping.qpos0)
    np.testing.assert_array_equal(q0[7:], robot.neutral()[7:])
    np.testing.assert_array_equal(q0[:3], [0.1, -0.2, 1.0])


def test_a_disagreement_with_mujoco_names_the_body_and_both_values(tmp_path: Path) -> None:
    model, mj, mapping, _ = build_from_mujoco(_models_dir() / "mjcf_acrobot.xml")
    model.armature[1] += 1e-3
    with pytest.raises(
        pinobs.ModelError,
        match=r"M\(q\)\[1, 1\] \(dof of body 'lower_arm'\).*Pinocchio .*MuJoCo mj_fullM",
    ):
        cross_check(model, mj, mapping)
    model, mj, mapping, _ = build_from_mujoco(_models_dir() / "mjcf_acrobot.xml")
    model.inertias[2] = model.inertias[2] + model.inertias[2]
    with pytest.raises(pinobs.ModelError, match=r"total mass: Pinocchio 3\.0 kg, MuJoCo 2\.0 kg"):
        cross_check(model, mj, mapping)


def test_joint_stiffness_is_named_in_a_warning(tmp_path: Path) -> None:
    text = (_models_dir() / "mjcf_acrobot.xml").read_text()
    text = text.replace('<joint damping=".05"', '<joint stiffness="3" damping=".05"')
    with pytest.warns(pinobs.ModelWarning, match=r"stiffness \(springs\) of shoulder, elbow"):
        pinobs.load(_file(tmp_path, text))


def test_a_root_joint_cannot_be_added_to_an_mjcf_file(tmp_path: Path) -> None:
    with pytest.raises(pinobs.GainError, match="declare <freejoint/>"):
        pinobs.load(_models_dir() / "mjcf_acrobot.xml", root_joint="freeflyer")


def test_a_root_joint_naming_the_files_own_root_is_accepted_and_another_refused(
    tmp_path: Path,
) -> None:
    text = """<mujoco><worldbody><body name="box"><freejoint/>
      <geom type="box" size="0.1 0.2 0.3" mass="1"/></body></worldbody></mujoco>"""
    path = _file(tmp_path, text)
    robot = pinobs.load(path, root_joint="freeflyer")  # was: "declare <freejoint/>", declared
    assert robot.nv == 6 and robot.root_joint is None  # the file's own: reloads as it is
    with pytest.raises(
        pinobs.GainError, match=r"root_joint='fixed': .* model\.xml's is freeflyer: leave out"
    ):
        pinobs.load(path, root_joint="fixed")  # was accepted, and the box floated
    with pytest.raises(pinobs.GainError, match=r"trees\.xml's is fixed and freeflyer"):
        pinobs.load(_file(tmp_path, TREES, "trees.xml"), root_joint="freeflyer")


def _without_mujoco(monkeypatch: pytest.MonkeyPatch) -> None:
    real_import = builtins.__import__

    def no_mujoco(name: str, *args: Any, **kwargs: Any) -> Any:
        if name == "mujoco":
            raise ImportError("no mujoco")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_mujoco)


def test_without_mujoco_pinocchios_parser_loads_with_a_warning_saying_what_it_misses(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    _without_mujoco(monkeypatch)
    with pytest.warns(pinobs.ModelWarning, match=r"MuJoCo is not installed.*<default> classes"):
        robot = pinobs.load(_models_dir() / "mjcf_acrobot.xml", check=False)
    # what the warning is about: Pinocchio's parser weighs the capsules by density
    assert sum(i.mass for i in robot.model.inertias) > 10.0


_INERTIAL = '<inertial pos="0 0 0" mass="1" diaginertia="0.1 0.1 0.1"/>'
_BIG = np.finfo(float).max
# (file, expected lower, upper): what MuJoCo compiles (q = qpos - ref)
SLIDE_LIMITS = {
    "degree": (  # MuJoCo's default angle unit; a slide's range is in metres whatever it says
        f"""<mujoco><worldbody><body name="a">
          <joint name="s" type="slide" axis="1 0 0" range="-0.3 0.5" limited="true"/>{_INERTIAL}
          <body name="b"><joint name="h" axis="0 0 1" range="-90 45" ref="10"/>{_INERTIAL}
          <body name="c"><joint name="off" type="slide" range="-0.3 0.5" limited="false"/>
          {_INERTIAL}</body></body></body></worldbody></mujoco>""",
        [-0.3, -np.pi / 2 - np.pi / 18, -_BIG],
        [0.5, np.pi / 4 - np.pi / 18, _BIG],
    ),
    "classes": (  # range, ref and type from <default> classes, a childclass, autolimits off
        f"""<mujoco><compiler autolimits="false"/><default>
          <joint type="slide" range="-0.3 0.5" limited="true"/>
          <default class="c"><joint range="-0.2 0.4" ref="0.1"/></default></default>
          <worldbody><body name="a"><joint name="s" axis="1 0 0"/>{_INERTIAL}
          <body name="b" childclass="c"><joint name="t" axis="1 0 0"/>{_INERTIAL}
          <joint name="h" type="hinge" axis="0 0 1" range="-90 90"/>
          <body name="c"><joint name="u" axis="0 1 0" limited="false"/>{_INERTIAL}
          </body></body></body></worldbody></mujoco>""",
        [-0.3, -0.3, -np.pi / 2 - np.pi / 1800, -_BIG],
        [0.5, 0.3, np.pi / 2 - np.pi / 1800, _BIG],
    ),
}


@pytest.mark.parametrize("case", sorted(SLIDE_LIMITS))
def test_without_mujoco_slide_ranges_and_limited_are_read_as_mujoco_compiles_them(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, case: str
) -> None:
    """Pinocchio's parser scaled slide ranges by π/180 under angle="degree" (-0.3..0.5 m read
    as -0.0052..0.0087 m) and limited joints whose limited="false"."""
    text, lower, upper = SLIDE_LIMITS[case]
    path = _file(tmp_path, text)
    through_mujoco = pinobs.load(path)
    _without_mujoco(monkeypatch)
    with pytest.warns(pinobs.ModelWarning, match="MuJoCo is not installed"):
        fallback = pinobs.load(path)
    for robot in (through_mujoco, fallback):
        np.testing.assert_allclose(robot.model.lowerPositionLimit, lower, rtol=1e-12)
        np.testing.assert_allclose(robot.model.upperPositionLimit, upper, rtol=1e-12)


def test_without_mujoco_a_root_joint_is_added_before_the_files_joints(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Pinocchio 4 has no buildModelFromMJCF(path, joint): it was a Boost ArgumentError;
    under a top body with joints its parser drops the root joint: refused, not ignored."""
    _without_mujoco(monkeypatch)
    text, lower, upper = SLIDE_LIMITS["degree"]
    with pytest.warns(pinobs.ModelWarning, match="MuJoCo is not installed"):
        with pytest.raises(pinobs.GainError, match=r"model\.xml's has its own: leave out"):
            pinobs.load(_file(tmp_path, text), root_joint="freeflyer")
    welded = text.replace('<body name="a">', f'<body name="a">{_INERTIAL}<body name="a2">', 1)
    welded = welded.replace("</worldbody>", "</body></worldbody>")
    with pytest.warns(pinobs.ModelWarning, match="MuJoCo is not installed"):
        robot = pinobs.load(_file(tmp_path, welded), root_joint="freeflyer")
    assert robot.model.names[1] == "root_joint" and robot.nq == 7 + 3
    np.testing.assert_allclose(robot.model.lowerPositionLimit[7:], lower, rtol=1e-12)
    np.testing.assert_allclose(robot.model.upperPositionLimit[7:], upper, rtol=1e-12)


@pytest.mark.parametrize("units", ["degree", "radian"])
def test_without_mujoco_the_arms_limits_are_mujocos(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, units: str
) -> None:
    path = _file(tmp_path, ARM_MJCF.format(**(ARM_DEGREES if units == "degree" else ARM_RADIANS)))
    through_mujoco = pinobs.load(path)
    _without_mujoco(monkeypatch)
    with pytest.warns(pinobs.ModelWarning, match="MuJoCo is not installed"):
        fallback = pinobs.load(path)
    for attr in ("lowerPositionLimit", "upperPositionLimit"):  # j3 (slide) was -0.052..-0.047
        np.testing.assert_allclose(
            getattr(fallback.model, attr), getattr(through_mujoco.model, attr), rtol=1e-12
        )


def test_without_mujoco_an_include_is_refused_and_gravity_options_are_kept(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _without_mujoco(monkeypatch)
    body = """<body name="l0" pos="0 0 0.1"><joint name="j0" type="hinge" axis="0 1 0"/>
      <inertial pos="0.2 0 0" mass="1" diaginertia="0.01 0.01 0.001"/></body>"""
    _file(tmp_path, f"<mujoco>{body.replace('l0', 'l1').replace('j0', 'j1')}</mujoco>", "part.xml")
    main = f'<mujoco><worldbody><include file="part.xml"/>{body}</worldbody></mujoco>'
    with pytest.raises(pinobs.ModelFileError, match=r"includes part\.xml, which Pinocchio's"):
        pinobs.load(_file(tmp_path, main))  # was loaded with nv = 1 of MuJoCo's 2
    moon = f'<mujoco><option gravity="0 0 -1.62"/><worldbody>{body}</worldbody></mujoco>'
    off = moon.replace("/>", '><flag gravity="disable"/></option>', 1)
    for text, gravity in ((moon, [0, 0, -1.62]), (off, [0, 0, 0])):  # both were -9.81
        with pytest.warns(pinobs.ModelWarning, match="MuJoCo is not installed"):
            robot = pinobs.load(_file(tmp_path, text))
        np.testing.assert_array_equal(robot.model.gravity.linear, gravity)


DM_CONTROL_SUITE = [
    "acrobot",
    "ball_in_cup",
    "cartpole",
    "cheetah",
    "dog",
    "finger",
    "fish",
    "hopper",
    "humanoid",
    "humanoid_CMU",
    "manipulator",
    "pendulum",
    "point_mass",
    "quadruped",
    "reacher",
    "stacker",
    "swimmer",
    "walker",
]


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::pinobs.errors.ModelWarning")  # springs, tendons: named
@pytest.mark.parametrize("name", DM_CONTROL_SUITE)
def test_dm_control_suite_as_shipped_matches_mujoco(name: str) -> None:
    """Every model of dm_control's suite (its XML files; ``pip install --no-deps dm_control``)."""
    import importlib.resources

    pytest.importorskip("dm_control")
    path = Path(str(importlib.resources.files("dm_control") / "suite" / f"{name}.xml"))
    model, mj, mapping, _ = build_from_mujoco(path)
    total = sum(i.mass for i in model.inertias)
    assert total == pytest.approx(float(mj.body_mass.sum()), rel=1e-9, abs=0)
    assert cross_check(model, mj, mapping, samples=20, seed=2) < MASS_MATRIX_RTOL
    assert pinobs.load(path).nv == mj.nv  # the sanity checks pass too


def test_the_ur5_mjcf_is_the_urdfs_ur5_plus_its_armature(rng: np.random.Generator) -> None:
    """``models/mjcf_ur5.xml`` (written by ``benchmarks/mujoco_truth.py --write-ur5``)."""
    mjcf, urdf = pinobs.load(_models_dir() / "mjcf_ur5.xml"), pinobs.load("ur5")
    np.testing.assert_array_equal(mjcf.model.armature, np.full(6, 0.1))
    np.testing.assert_array_equal(mjcf.model.damping, np.full(6, 0.5))
    for _ in range(5):
        q, v = urdf.random_configuration(rng, scale=np.pi), rng.normal(size=6)
        np.testing.assert_allclose(
            mjcf.mass_matrix(q), urdf.mass_matrix(q) + 0.1 * np.eye(6), rtol=0, atol=1e-12
        )
        np.testing.assert_allclose(
            mjcf.inverse_dynamics(q, v, np.zeros(6)),
            urdf.inverse_dynamics(q, v, np.zeros(6)),
            rtol=0,
            atol=1e-12,
        )


def test_friction_derivative_stays_finite_and_silent_at_high_speed() -> None:
    """MJCF damping switches friction on; |v| ≫ v_s must not overflow sech² (warnings are errors)."""
    robot = pinobs.load(_models_dir() / "mjcf_acrobot.xml")
    d = robot.friction_derivative(np.array([50.0, -80.0]))
    np.testing.assert_array_equal(d, -robot.model.damping)


def test_visual_geoms_sit_where_mujoco_puts_them(tmp_path: Path, rng: np.random.Generator) -> None:
    """Every primitive geom's world pose equals MuJoCo's ``geom_xpos``/``geom_xmat``."""
    import pinocchio as pin

    path = _file(tmp_path, TREES)
    robot = pinobs.load(path)
    _, mj, mapping, _ = build_from_mujoco(path)
    vm = robot.visual_model
    assert vm is not None and vm.ngeoms == mj.ngeom  # every geom of TREES is a primitive
    data = mujoco.MjData(mj)
    for _ in range(3):
        q = robot.random_configuration(rng, scale=np.pi)
        data.qpos[:] = mapping.qpos_from_q(q)
        mujoco.mj_forward(mj, data)
        gdata = pin.GeometryData(vm)
        pin.updateGeometryPlacements(robot.model, robot.model.createData(), vm, gdata, q)
        for g in range(mj.ngeom):
            np.testing.assert_allclose(gdata.oMg[g].translation, data.geom_xpos[g], atol=1e-12)
            np.testing.assert_allclose(
                gdata.oMg[g].rotation, data.geom_xmat[g].reshape(3, 3), atol=1e-12
            )


# a 3-joint arm: MJCF angles in degrees (MuJoCo's default), joint refs, a joint-level
# actuatorfrcrange, motors with ctrlrange × gear (one range asymmetric) ...
ARM_MJCF = """<mujoco model="arm">
  <compiler inertiafromgeom="false" angle="{angle}"/>
  <worldbody>
    <body name="l1" pos="0 0 0.1">
      <joint name="j1" type="hinge" axis="0 1 0" range="{r1}" actuatorfrcrange="-20 20"/>
      <inertial pos="0 0 0.2" mass="1" diaginertia="0.01 0.01 0.001"/>
      <body name="l2" pos="0 0 0.4">
        <joint name="j2" type="hinge" axis="0 1 0" range="{r2}" ref="{ref2}"/>
        <inertial pos="0 0 0.2" mass="0.5" diaginertia="0.005 0.005 0.0005"/>
        <body name="l3" pos="0 0 0.4">
          <joint name="j3" type="slide" axis="0 0 1" range="-0.1 0.2" ref="0.05"/>
          <inertial pos="0 0 0" mass="0.2" diaginertia="0.001 0.001 0.001"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor joint="j2" ctrlrange="-1 1" gear="5"/>
    <motor joint="j3" ctrlrange="-2 3" gear="10"/>
  </actuator>
</mujoco>
"""

# ... and the same arm as URDF: q = 0 is MuJoCo's qpos0 (the refs), so the limits shift by them
ARM_URDF = """<robot name="arm">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0 0 0.2"/><mass value="1"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0 0 0.2"/><mass value="0.5"/>
    <inertia ixx="0.005" iyy="0.005" izz="0.0005" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="l3"><inertial><mass value="0.2"/>
    <inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 1 0"/>
    <limit lower="-1.5707963267948966" upper="0.7853981633974483" effort="20" velocity="10"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0 0.4"/><axis xyz="0 1 0"/>
    <limit lower="-0.6981317007977318" upper="0.8726646259971648" effort="5" velocity="10"/></joint>
  <joint name="j3" type="prismatic"><parent link="l2"/><child link="l3"/>
    <origin xyz="0 0 0.4"/><axis xyz="0 0 1"/>
    <limit lower="-0.15" upper="0.15" effort="30" velocity="10"/></joint>
</robot>
"""

ARM_DEGREES = {"angle": "degree", "r1": "-90 45", "r2": "-30 60", "ref2": "10"}
ARM_RADIANS = {
    "angle": "radian",
    "r1": f"{-np.pi / 2!r} {np.pi / 4!r}",
    "r2": f"{-np.pi / 6!r} {np.pi / 3!r}",
    "ref2": f"{np.pi / 18!r}",
}


@pytest.mark.parametrize("units", [ARM_DEGREES, ARM_RADIANS], ids=["degree", "radian"])
def test_mjcf_joint_ranges_and_efforts_equal_the_same_arms_urdf(
    tmp_path: Path, rng: np.random.Generator, units: dict[str, str]
) -> None:
    mjcf = pinobs.load(_file(tmp_path, ARM_MJCF.format(**units)))
    urdf = pinobs.load(_file(tmp_path, ARM_URDF, "arm.urdf"))
    for attr in ("lowerPositionLimit", "upperPositionLimit", "effortLimit"):
        np.testing.assert_allclose(
            getattr(mjcf.model, attr), getattr(urdf.model, attr), rtol=1e-12, err_msg=attr
        )
    for _ in range(3):  # and it is the same arm
        q = urdf.random_configuration(rng)
        np.testing.assert_allclose(mjcf.mass_matrix(q), urdf.mass_matrix(q), rtol=1e-12)


def test_an_excitation_of_an_mjcf_arm_stays_inside_its_ranges_and_efforts(tmp_path: Path) -> None:
    from pinobs.model.excitation import excite

    robot = pinobs.load(_file(tmp_path, ARM_MJCF.format(**ARM_DEGREES)), friction=False)
    ex = excite(robot, duration=2.0, rate=50.0, candidates=4, refine=0)
    lo, hi = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    assert np.all(ex.q >= lo) and np.all(ex.q <= hi)  # j3 reached -1.53 m of [-0.15, 0.15]
    assert np.all(np.abs(ex.tau) <= robot.model.effortLimit)


def _one_joint(
    tmp_path: Path,
    *,
    joint: str = 'damping="0.3" frictionloss="0.2"',
    body: str = "",
    option: str = "",
    act: str = "",
) -> Path:
    text = f"""<mujoco>
  <option>{option}</option>
  <worldbody>
    <body name="link" pos="0 0 0.1" {body}>
      <joint name="j" type="hinge" axis="0 1 0" {joint}/>
      <inertial pos="0.2 0 0" mass="1" diaginertia="0.01 0.01 0.001"/>
    </body>
  </worldbody>
  <actuator>{act}</actuator>
</mujoco>"""
    return _file(tmp_path, text)


@pytest.mark.parametrize(
    ("act", "joint", "option", "effort"),
    [
        ('<motor joint="j" ctrlrange="-2 1" gear="3"/>', "", "", 6.0),
        ('<motor joint="j" ctrlrange="-2 1" gear="-3" forcerange="-1 1"/>', "", "", 3.0),
        (
            '<motor joint="j" ctrlrange="-1 1" gear="3"/><motor joint="j" ctrlrange="-1 1"/>',
            "",
            "",
            4.0,
        ),
        ('<motor joint="j" ctrlrange="-2 1" gear="3"/>', 'actuatorfrcrange="-4 5"', "", 5.0),
        ('<motor joint="j" ctrlrange="-2 1" gear="3"/>', "", '<flag clampctrl="disable"/>', None),
        ('<position joint="j" ctrlrange="-1 1" kp="100"/>', "", "", None),
        ('<position joint="j" kp="100" forcerange="-7 7"/>', "", "", 7.0),
        ("", "", "", None),  # no actuator
    ],
    ids=[
        "motor",
        "forcerange",
        "two-motors",
        "actuatorfrcrange",
        "clampctrl-off",
        "position-servo",
        "servo-forcerange",
        "unactuated",
    ],
)
def test_mjcf_effort_limit_is_the_largest_torque_its_actuators_can_apply(
    tmp_path: Path, act: str, joint: str, option: str, effort: float | None
) -> None:
    model = pinobs.load(_one_joint(tmp_path, joint=joint, option=option, act=act)).model
    expected = np.finfo(float).max if effort is None else effort
    assert model.effortLimit[0] == expected


def test_mjcf_disable_flags_are_honoured(tmp_path: Path) -> None:
    model = pinobs.load(
        _one_joint(tmp_path, joint='range="-30 60" damping="0.3" frictionloss="0.2"')
    ).model
    assert model.gravity.linear[2] == -9.81 and model.damping[0] == 0.3
    assert model.friction[0] == 0.2 and model.upperPositionLimit[0] == pytest.approx(np.pi / 3)
    off = '<flag gravity="disable" damper="disable" frictionloss="disable" limit="disable"/>'
    j = 'range="-30 60" damping="0.3" frictionloss="0.2"'
    model = pinobs.load(_one_joint(tmp_path, joint=j, option=off)).model
    np.testing.assert_array_equal(model.gravity.linear, np.zeros(3))  # was (0, 0, -9.81)
    assert model.damping[0] == 0.0 and model.friction[0] == 0.0
    assert model.upperPositionLimit[0] == np.finfo(float).max


def test_mjcf_gravity_disabled_or_fully_compensated_gives_mujocos_dynamics(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    for how in ({"option": '<flag gravity="disable"/>'}, {"body": 'gravcomp="1"'}):
        robot = pinobs.load(_one_joint(tmp_path, joint="", **how))
        np.testing.assert_array_equal(robot.model.gravity.linear, np.zeros(3))  # was -9.81
        _, mj, mapping, _ = build_from_mujoco(tmp_path / "model.xml")
        for _ in range(3):
            q, v, tau = rng.normal(size=1), rng.normal(size=1), rng.normal(size=1)
            qacc = _mujoco_qacc(mj, mapping.qpos_from_q(q), v, tau)
            np.testing.assert_allclose(robot.forward_dynamics(q, v, tau), qacc, rtol=1e-10)


def test_partial_gravity_compensation_is_named_in_a_warning(tmp_path: Path) -> None:
    with pytest.warns(pinobs.ModelWarning, match=r"gravcomp\) of link \(0\.5\): .*full weight"):
        model = pinobs.load(_one_joint(tmp_path, body='gravcomp="0.5"')).model
    assert model.gravity.linear[2] == -9.81


def test_unnamed_mjcf_joints_bodies_and_geoms_get_names_no_other_has(tmp_path: Path) -> None:
    text = """<mujoco>
  <worldbody>
    <body name="body2" pos="0 0 0.1">
      <joint type="hinge" axis="0 1 0"/>
      <geom name="geom1" type="sphere" size="0.1" mass="1"/>
      <body pos="0.4 0 0">
        <joint name="joint0" type="hinge" axis="0 1 0"/>
        <geom type="sphere" size="0.1" mass="1"/>
      </body>
    </body>
  </worldbody>
</mujoco>"""
    robot = pinobs.load(_file(tmp_path, text))
    assert list(robot.model.names) == ["universe", "joint0_2", "joint0"]  # was joint0 twice
    bodies = [f.name for f in robot.model.frames if f.type.name == "BODY"]
    assert bodies == ["body2", "body2_2"]
    assert robot.visual_model is not None
    assert [g.name for g in robot.visual_model.geometryObjects] == ["geom1", "geom1_2"]

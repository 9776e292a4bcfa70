"""Degenerate models: each gets its outcome (error naming the body, warning, or silence)."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import pinobs

ARM = """<?xml version="1.0"?>
<robot name="arm">
  <link name="base"/>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="upper"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="10" velocity="10"/>
  </joint>
  <link name="upper">
    <inertial><origin xyz="0 0 -0.25"/><mass value="1.0"/>
      <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.001"/></inertial>
  </link>
  <joint name="j2" type="revolute">
    <parent link="upper"/><child link="lower"/><origin xyz="0 0 -0.5"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="10" velocity="10"/>{mimic}
  </joint>
  <link name="lower">
    <inertial><origin xyz="0 0 -0.25"/><mass value="{mass}"/>
      <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/></inertial>
  </link>
  <joint name="tool_mount" type="fixed">
    <parent link="lower"/><child link="tool"/><origin xyz="0 0 -0.5"/>
  </joint>
  <link name="tool"/>
</robot>
"""


def _arm(tmp_path: Path, *, mimic: str = "", **inertial: str) -> Path:
    values = {"mass": "0.5", "ixx": "0.01", "iyy": "0.01", "izz": "0.0005"} | inertial
    f = tmp_path / "arm.urdf"
    f.write_text(ARM.format(mimic=mimic, **values))
    return f


def test_a_sound_arm_with_a_massless_tool_frame_loads_silently(tmp_path: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        robot = pinobs.load(_arm(tmp_path))
    assert robot.nv == 2


@pytest.mark.parametrize("text", ["nan", "abc"])
def test_an_unreadable_mass_is_an_error_naming_the_link_and_the_text(
    tmp_path: Path, text: str
) -> None:
    with pytest.raises(pinobs.ModelError, match=rf"link 'lower'.*mass='{text}'.*massless"):
        pinobs.load(_arm(tmp_path, mass=text))


def test_an_unreadable_inertia_entry_is_an_error_naming_it(tmp_path: Path) -> None:
    with pytest.raises(pinobs.ModelError, match=r"link 'lower'.*iyy='1e-2x'"):
        pinobs.load(_arm(tmp_path, iyy="1e-2x"))


INERTIAL = '<inertial><origin xyz="0 0 -0.25"/><mass value="0.5"/>'
INERTIA = '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.0005"/>'


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [  # what urdfdom did: kept a point mass, dropped the inertial, kept the first one
        (INERTIA, "", r"link 'lower': <inertial> has no <inertia>: urdfdom keeps a point mass"),
        (' iyz="0" izz="0.0005"', ' izz="0.0005"', r"link 'lower': <inertial> iyz=None is not"),
        ('<mass value="0.5"/>', "", r"link 'lower': <inertial> no mass value: .*massless"),
        (
            INERTIA + "</inertial>",
            INERTIA + "</inertial>" + INERTIAL + INERTIA + "</inertial>",
            r"link 'lower': 2 <inertial> elements: urdfdom keeps the first",
        ),
    ],
    ids=["no-inertia", "no-iyz", "no-mass", "two-inertials"],
)
def test_an_incomplete_or_second_inertial_is_an_error_naming_the_link(
    tmp_path: Path, old: str, new: str, message: str
) -> None:
    f = _arm(tmp_path)
    text = f.read_text()
    i = text.index('<link name="lower">')  # the second link's inertial
    f.write_text(text[:i] + text[i:].replace(old, new, 1))
    with pytest.raises(pinobs.ModelError, match=message):
        pinobs.load(f)


def test_a_duplicate_link_name_is_a_file_error_naming_it(tmp_path: Path) -> None:
    f = _arm(tmp_path)
    f.write_text(
        f.read_text().replace('<link name="tool"/>', '<link name="tool"/><link name="upper"/>')
    )
    with pytest.raises(pinobs.ModelFileError, match=r"link 'upper' defined more than once"):
        pinobs.load(f)  # was "The XML stream does not contain a valid URDF model."


def test_a_zero_joint_axis_is_an_error_naming_the_joint(tmp_path: Path) -> None:
    f = _arm(tmp_path)
    f.write_text(f.read_text().replace('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>', 1))
    with pytest.raises(pinobs.ModelError, match=r"joint\(s\) 'j1' have <axis xyz='0 0 0'>"):
        pinobs.load(f)  # was "the mass matrix is singular … Give them an <inertial>"


def test_a_negative_mass_is_an_error_naming_the_body(tmp_path: Path) -> None:
    with pytest.raises(
        pinobs.ModelError, match=r"body 'lower \(body of joint j2\)' has a negative mass -0\.5 kg"
    ):
        pinobs.load(_arm(tmp_path, mass="-0.5"))


def test_a_negative_principal_moment_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(
        pinobs.ModelError, match=r"body 'lower \(body of joint j2\)'.*negative principal moment"
    ):
        pinobs.load(_arm(tmp_path, ixx="-0.01"))


def test_a_broken_triangle_inequality_warns_naming_the_body_and_still_loads(
    tmp_path: Path,
) -> None:
    with pytest.warns(
        pinobs.ModelWarning,
        match=r"triangle inequality.*'lower \(body of joint j2\)' \[0\.0005, 0\.01, 0\.1\]",
    ):
        robot = pinobs.load(_arm(tmp_path, izz="0.1", iyy="0.0005"))
    assert robot.nv == 2


def test_a_joint_moving_only_massless_links_makes_m_singular_and_is_an_error(
    tmp_path: Path,
) -> None:
    f = _arm(tmp_path, mass="0", ixx="0", iyy="0", izz="0")
    with pytest.raises(
        pinobs.ModelError, match=r"mass matrix is singular.*along joint 'j2'.*lower"
    ):
        pinobs.load(f)
    assert pinobs.load(f, check=False).nv == 2  # the escape hatch


def test_a_mimic_joint_in_a_file_is_refused_unless_declared_independent(tmp_path: Path) -> None:
    f = _arm(tmp_path, mimic='\n    <mimic joint="j1" multiplier="-2" offset="0.1"/>')
    with pytest.raises(pinobs.ModelError, match=r"joint 'j2' mimics 'j1' \(q = -2·q_j1 \+ 0\.1"):
        pinobs.load(f)
    robot = pinobs.load(f, mimic="independent")
    assert robot.nv == 2
    # a perturbed or identified copy is reloaded as this one was (a saved run's meta: play)
    assert robot.perturbed(inertia_scale=[1.1, 1.1]).mimic == robot.copy().mimic == "independent"
    with pytest.raises(pinobs.GainError, match="mimic='couple'"):
        pinobs.load(f, mimic="couple")


def test_the_command_line_loads_a_mimic_file_with_the_option_its_error_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from pinobs.cli import main

    f = _arm(tmp_path, mimic='\n    <mimic joint="j1"/>')
    assert main(["check", "ii", "--robot", str(f)]) == 2
    err = capsys.readouterr().err
    assert "--mimic independent (the pinobs command)" in err  # was mimic='independent' only
    assert main(["check", "ii", "--robot", str(f), "--mimic", "independent"]) in (0, 1)
    assert "Assumption 1" in capsys.readouterr().out
    # a saved run replays with the mimic choice it was run with (play refused the file before)
    run = tmp_path / "run.npz"
    common = ["--robot", str(f), "--mimic", "independent", "--duration", "0.2"]
    assert main(["run", *common, "--observer", "kf", "--save", str(run)]) == 0
    assert main(["play", str(run), "--html", str(tmp_path / "p.html"), "--no-progress"]) == 0
    # and estimate --out-dir passes it to each log's task (refused before)
    from pinobs.io import write_log

    res = pinobs.Result.load(run)
    (tmp_path / "logs").mkdir()
    write_log(tmp_path / "logs" / "a.csv", res.t, res.q_meas, res.tau)
    many = ["--log", str(tmp_path / "logs"), "--out-dir", str(tmp_path / "out"), "--workers", "0"]
    argv = ["estimate", "--robot", str(f), "--mimic", "independent", "--observer", "kf"]
    assert main([*argv, *many, "--noise", "1e-3", "--no-progress"]) == 0


def test_registry_robots_with_mimic_grippers_load_them_as_independent_joints() -> None:
    assert pinobs.load("panda").nv == 9
    with pytest.raises(pinobs.ModelError, match="panda_finger_joint2"):
        pinobs.load("panda", mimic="error")


@pytest.mark.parametrize(
    ("dynamics", "message"),
    [
        ('damping="-0.1"', r"joint 'j1': <dynamics damping='-0\.1'> is not a finite number ≥ 0"),
        # Pinocchio's parser said only "min_dry_friction are greater than max_dry_friction"
        ('friction="-0.2"', r"joint 'j1': <dynamics friction='-0\.2'> is not a finite number"),
        ('damping="nan"', r"joint 'j1': <dynamics damping='nan'>"),
    ],
    ids=["negative-damping", "negative-friction", "nan-damping"],
)
def test_a_negative_urdf_damping_or_friction_is_an_error_naming_the_joint_and_value(
    tmp_path: Path, dynamics: str, message: str
) -> None:
    f = _arm(tmp_path)
    f.write_text(
        f.read_text().replace(
            'effort="10" velocity="10"/>', f'effort="10" velocity="10"/><dynamics {dynamics}/>', 1
        )
    )
    with pytest.raises(pinobs.ModelError, match=message):
        pinobs.load(f)
    with pytest.raises(pinobs.ModelError, match=message):  # not a dynamics check: always
        pinobs.load(f, check=False)


@pytest.mark.parametrize(
    ("limit", "message"),
    [
        ('lower="3" upper="-3"', r"joint 'j1': <limit lower=3 upper=-3> is inverted"),
        (
            'lower="0.5" upper="0.5"',
            r"joint 'j1': <limit lower=0\.5 upper=0\.5> leaves the joint no motion",
        ),
    ],
    ids=["inverted", "no-motion"],
)
def test_inverted_or_degenerate_urdf_limits_are_an_error_naming_the_joint(
    tmp_path: Path, limit: str, message: str
) -> None:
    f = _arm(tmp_path)
    f.write_text(f.read_text().replace('lower="-3" upper="3"', limit, 1))
    with pytest.raises(pinobs.ModelError, match=message):
        pinobs.load(f)


@pytest.mark.parametrize("limit", ['lower="0" upper="0"', ""], ids=["zeros", "left-out"])
def test_zero_urdf_limits_read_as_no_limits_with_one_warning_naming_the_joints(
    tmp_path: Path, limit: str
) -> None:
    f = _arm(tmp_path)
    f.write_text(f.read_text().replace('lower="-3" upper="3"', limit))  # both joints
    with pytest.warns(
        pinobs.ModelWarning, match=r"joint\(s\) j1, j2 have <limit lower=0 upper=0>"
    ) as rec:
        robot = pinobs.load(f)
    assert len(rec) == 1
    big = np.finfo(float).max  # Pinocchio's "no limit" (they were [0, 0])
    np.testing.assert_array_equal(robot.model.lowerPositionLimit, [-big, -big])
    np.testing.assert_array_equal(robot.model.upperPositionLimit, [big, big])


def test_a_registered_robot_with_zero_limits_loads_unlimited_and_silently() -> None:
    robot = pinobs.load("double_pendulum")  # warnings are errors
    np.testing.assert_array_equal(robot.model.upperPositionLimit, np.full(2, np.finfo(float).max))


def test_a_pin_models_joint_values_are_checked_naming_the_joint() -> None:
    model = pinobs.load("cartpole").model.copy()
    model.damping[:] = [0.0, -0.5]
    with pytest.raises(
        pinobs.ModelError, match=r"joint 'pole_theta' has viscous damping \[-0\.5\]"
    ):
        pinobs.load(model)
    model = pinobs.load("cartpole").model.copy()
    model.lowerPositionLimit[0], model.upperPositionLimit[0] = 1.0, -1.0
    with pytest.raises(
        pinobs.ModelError,
        match=r"joint 'cart_x' has position limits lower \[1\.0\] > upper",
    ):
        pinobs.load(model)
    assert pinobs.load(model, check=False).nv == 2


def test_a_pin_model_is_checked_too() -> None:
    model = pinobs.load("cartpole").model.copy()
    model.armature[:] = [0.0, -1.0]  # negative armature: M indefinite
    with pytest.raises(pinobs.ModelError, match=r"mass matrix is indefinite.*joint 'pole_theta'"):
        pinobs.load(model)
    model = pinobs.load("cartpole").model.copy()
    inertia = model.inertias[2]
    model.inertias[2] = type(inertia)(float("nan"), inertia.lever, inertia.inertia)
    with pytest.raises(pinobs.ModelError, match=r"'pole \(body of joint pole_theta\)'.*non-finite"):
        pinobs.load(model)


def test_romeo_small_warns_about_its_shoulder_inertia_but_loads() -> None:
    with pytest.warns(
        pinobs.ModelWarning, match=r"'RShoulderYawLink \(body of joint RShoulderYaw\)'"
    ):
        robot = pinobs.load("romeo_small")
    q = robot.random_configuration(np.random.default_rng(0))
    assert np.linalg.eigvalsh(robot.mass_matrix(q))[0] > 0


def test_full_romeo_is_refused_for_its_massless_fingers_and_loads_unchecked() -> None:
    # Which massless hand joint is found first depends on the example-robot-data version
    # (LFinger.. before 6.0.0, LHand or LThumb1 with it): the property is that the joint named
    # is a hand joint that moves no inertia about its axis, so M(q) is singular along it.
    with pytest.raises(pinobs.ModelError, match=r"mass matrix is singular.*along joint") as err:
        pinobs.load("romeo")
    named = re.search(r"along joint '([^']+)'", str(err.value))
    assert named is not None
    joint = named.group(1)
    assert re.fullmatch(r"[LR](Hand|Finger\d+|Thumb\d+)", joint), joint
    robot = pinobs.load("romeo", check=False)
    assert robot.nv > 0
    q = robot.random_configuration(np.random.default_rng(0))
    m = robot.mass_matrix(q)
    iv = robot.model.joints[robot.model.getJointId(joint)].idx_v
    assert m[iv, iv] <= 1e-12 * np.abs(m).max()  # no inertia about its axis: a zero diagonal


def test_the_cli_loads_a_model_the_check_refuses_with_no_check(tmp_path: Path, capsys) -> None:
    """Issue 36: the TX40's URDF (M singular at its last link) was refused by every command
    with no way to load it unchecked; a model-free observer does not need M."""
    from pinobs.cli import main
    from pinobs.io import write_log

    f = _arm(tmp_path, mass="0", ixx="0", iyy="0", izz="0")
    t = np.arange(300) * 1e-3
    q = np.column_stack([0.3 * np.sin(3 * t), 0.2 * np.cos(2 * t)])
    log = tmp_path / "log.csv"
    write_log(log, t, q, np.zeros_like(q))
    args = ["estimate", "--robot", str(f), "--observer", "kf", "--log", str(log)]
    args += ["--noise", "1e-6", "--no-progress", "--out"]
    assert main([*args, str(tmp_path / "a.csv")]) == 2
    assert "mass matrix is singular" in capsys.readouterr().err
    assert main([*args, str(tmp_path / "b.csv"), "--no-check"]) == 0
    est = np.loadtxt(tmp_path / "b.csv", delimiter=",", skiprows=1)
    assert est.shape == (300, 5) and np.isfinite(est[1:]).all()

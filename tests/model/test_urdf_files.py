"""URDF files as users have them: ``package://`` meshes, pin.Model / RobotWrapper sources."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from pinocchio.robot_wrapper import RobotWrapper

import pinobs
from pinobs.model.loading import _erd_share_dir

UR = "example-robot-data/robots/ur_description"


def _copy_ur5(dest: Path) -> Path:
    """Copy the wheel's ur_description (URDF + meshes) to ``dest``; return the URDF's path."""
    src = _erd_share_dir() / UR
    shutil.copytree(src / "urdf", dest / "urdf")
    shutil.copytree(src / "meshes" / "ur5", dest / "meshes" / "ur5")
    return dest / "urdf" / "ur5_robot.urdf"


def _mesh_files(robot: pinobs.Robot) -> list[Path]:
    assert robot.visual_model is not None
    return [Path(g.meshPath) for g in robot.visual_model.geometryObjects if Path(g.meshPath).suffix]


def test_a_copied_urdf_finds_its_package_meshes_in_its_parent_folders(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    urdf = _copy_ur5(tmp_path / "ur_description")
    assert "package://example-robot-data/robots/ur_description/meshes" in urdf.read_text()
    robot = pinobs.load(urdf)
    files = _mesh_files(robot)
    assert robot.nv == 6 and len(files) == 7
    assert all(f.is_file() and tmp_path in f.parents for f in files)
    ref = pinobs.load("ur5").collision_model
    assert robot.collision_model is not None and ref is not None
    assert robot.collision_model.ngeoms == ref.ngeoms


def test_package_dirs_resolve_meshes_kept_apart_from_the_urdf(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    pkgs = tmp_path / "pkgs"
    urdf_dir = tmp_path / "robot"
    urdf_dir.mkdir()
    _copy_ur5(pkgs / "example-robot-data" / "robots" / "ur_description")
    urdf = urdf_dir / "ur5.urdf"
    shutil.copy(pkgs / "example-robot-data" / "robots" / "ur_description/urdf/ur5_robot.urdf", urdf)
    with pytest.warns(pinobs.ModelWarning, match=r"14 mesh\(es\) not found.*package_dirs") as rec:
        bare = pinobs.load(urdf)
    assert len(rec) == 1  # warned once, not per mesh
    assert bare.visual_model is None and bare.collision_model is None
    robot = pinobs.load(urdf, package_dirs=[pkgs])
    assert all(pkgs in f.parents for f in _mesh_files(robot))
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(pkgs))
    assert all(pkgs in f.parents for f in _mesh_files(pinobs.load(urdf)))
    monkeypatch.delenv("ROS_PACKAGE_PATH")
    prefix = tmp_path / "install"
    (prefix / "share").mkdir(parents=True)
    (prefix / "share" / "example-robot-data").symlink_to(pkgs / "example-robot-data")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(prefix))
    files = _mesh_files(pinobs.load(urdf))
    assert len(files) == 7 and all(f.is_file() for f in files)


def test_without_meshes_the_dynamics_are_those_of_the_full_model(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, rng: np.random.Generator
) -> None:
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    urdf = tmp_path / "ur5.urdf"
    shutil.copy(_erd_share_dir() / UR / "urdf" / "ur5_robot.urdf", urdf)
    with pytest.warns(pinobs.ModelWarning):
        bare = pinobs.load(urdf)
    full = pinobs.load("ur5")
    q, v, tau = full.random_configuration(rng), rng.normal(size=6), rng.normal(size=6)
    np.testing.assert_array_equal(bare.mass_matrix(q), full.mass_matrix(q))
    np.testing.assert_array_equal(
        bare.forward_dynamics(q, v, tau), full.forward_dynamics(q, v, tau)
    )


def test_stick_figure_stands_in_for_missing_meshes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("meshcat")
    from pinobs.visualization.playback.geometry import visual_model

    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    urdf = tmp_path / "ur5.urdf"
    shutil.copy(_erd_share_dir() / UR / "urdf" / "ur5_robot.urdf", urdf)
    with pytest.warns(pinobs.ModelWarning):
        bare = pinobs.load(urdf)
    assert visual_model(bare).ngeoms > 0


def test_a_pin_model_and_a_robot_wrapper_load_as_copies(rng: np.random.Generator) -> None:
    ur5 = pinobs.load("ur5")
    robot = pinobs.load(ur5.model)
    assert robot.model is not ur5.model and robot.nv == 6 and robot.visual_model is None
    q = ur5.random_configuration(rng)
    np.testing.assert_array_equal(robot.mass_matrix(q), ur5.mass_matrix(q))
    wrapper = RobotWrapper(ur5.model, ur5.collision_model, ur5.visual_model)
    wrapped = pinobs.load(wrapper)
    assert wrapped.visual_model is not None and wrapped.visual_model.ngeoms == 7
    with pytest.raises(pinobs.GainError, match="root_joint='freeflyer' applies to files"):
        pinobs.load(ur5.model, root_joint="freeflyer")


def test_other_sources_raise_a_type_error_saying_what_is_accepted() -> None:
    with pytest.raises(pinobs.ModelTypeError, match=r"from a int \(3\).*pinocchio\.Model") as info:
        pinobs.load(3)  # type: ignore[arg-type]
    assert isinstance(info.value, TypeError)
    with pytest.raises(pinobs.ModelFileError, match="no moving joint"):
        pinobs.load(pin.Model())


def test_meshes_in_comments_do_not_count_as_missing(tmp_path: Path) -> None:
    urdf = tmp_path / "one.urdf"
    urdf.write_text(
        """<robot name="one"><link name="base"/>
        <joint name="j" type="revolute"><parent link="base"/><child link="arm"/>
          <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
        <link name="arm"><inertial><mass value="1"/>
          <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
          <!-- <visual><geometry><mesh filename="package://gone/arm.stl"/></geometry></visual> -->
          <visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual>
        </link></robot>"""
    )
    robot = pinobs.load(urdf)  # no warning (they are errors here)
    assert robot.visual_model is not None and robot.visual_model.ngeoms == 1

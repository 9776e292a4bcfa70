"""Finding and loading robots."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import pinobs
from pinobs.model import robot_entries

PROJECT_MODELS = {
    "cartpole": (2, 2),
    "pendulum": (1, 1),
    "planar_3r": (3, 3),
    "top": (4, 3),
    "rigid_body": (7, 6),
}


@pytest.mark.parametrize(("name", "dims"), PROJECT_MODELS.items())
def test_project_models_load_with_their_dimensions(name: str, dims: tuple[int, int]) -> None:
    robot = pinobs.load(name)
    assert (robot.nq, robot.nv) == dims
    assert robot.visual_model is not None and robot.visual_model.ngeoms > 0


def test_cartpole_is_prismatic_cart_and_revolute_pole() -> None:
    robot = pinobs.load("cartpole")
    assert [j.shortname() for j in robot.model.joints[1:]] == ["JointModelPX", "JointModelRY"]


@pytest.mark.parametrize(
    "name",
    [
        "ur5",
        "panda",
        "z1",
        "so100",
        "double_pendulum",
        "go1",
        # its shoulder inertia breaks the triangle inequality (tests/model/test_sanity.py)
        pytest.param(
            "romeo_small",
            marks=pytest.mark.filterwarnings("ignore::pinobs.errors.ModelWarning"),
        ),
        "pr2",
    ],
)
def test_example_robot_data_robots_load_with_meshes(name: str) -> None:
    robot = pinobs.load(name)
    assert robot.nv > 0
    assert robot.visual_model is not None and robot.visual_model.ngeoms > 0
    # primitives have meshPath "BOX", "SPHERE", ...; meshes have a file path
    meshes = [g.meshPath for g in robot.visual_model.geometryObjects if Path(g.meshPath).suffix]
    assert meshes and all(Path(p).is_file() for p in meshes)


def test_legged_robots_default_to_a_free_flyer_and_root_joint_overrides() -> None:
    assert pinobs.load("go1").joints[0].kind == "se3"
    assert pinobs.load("go1", root_joint="fixed").joints[0].kind == "vector"
    assert pinobs.load("top").joints[0].kind == "so3"
    assert pinobs.load("rigid_body", root_joint="spherical").nv == 3


def test_unknown_name_raises_a_keyerror_saying_which_names_are_close() -> None:
    with pytest.raises(
        pinobs.UnknownNameError, match=r"unknown robot 'ur55'; did you mean 'ur5'"
    ) as info:
        pinobs.load("ur55")
    assert isinstance(info.value, KeyError)
    assert "cartpole" not in str(info.value)  # was every one of the ~100 names
    with pytest.raises(pinobs.UnknownNameError, match=r"unknown robot 'UR5'; did you mean 'ur5'\?"):
        pinobs.load("UR5")
    with pytest.raises(pinobs.UnknownNameError, match=r"known: a1, .*ur5, .* more URDFs") as info:
        pinobs.load("nosuchbot")  # nothing close: the table's names, not the wheel's 35 others
    assert "alex_nub_hands" not in str(info.value)


def test_missing_file_raises_file_not_found(tmp_path: Path) -> None:
    with pytest.raises(pinobs.ModelFileError, match="does not exist") as info:
        pinobs.load(tmp_path / "nope.urdf")
    assert isinstance(info.value, FileNotFoundError)


def test_malformed_file_raises_model_file_error_naming_it(tmp_path: Path) -> None:
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'></robot")
    with pytest.raises(pinobs.ModelFileError, match=r"cannot parse robot file .*bad\.urdf") as info:
        pinobs.load(bad)
    assert "ur5" not in str(info.value)  # the robot names were appended


def test_bad_root_joint_is_rejected() -> None:
    with pytest.raises(pinobs.GainError, match="root_joint='ball'"):
        pinobs.load("cartpole", root_joint="ball")


def test_a_urdf_path_loads(tmp_path: Path) -> None:
    src = Path(str(pinobs.load("pendulum").source))
    assert src.name == "pendulum"
    robot = pinobs.load(Path(pinobs.model.loading._models_dir()) / "pendulum.urdf")
    assert robot.nv == 1 and robot.name == "pendulum"


def test_mjcf_file_loads(tmp_path: Path) -> None:
    f = tmp_path / "arm.xml"
    f.write_text(
        """<mujoco><worldbody><body name="l1"><joint name="j1" type="hinge" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.02" mass="1"/></body></worldbody></mujoco>"""
    )
    robot = pinobs.load(f)
    assert robot.nv == 1


def test_registry_is_sorted_and_models_readme_lists_every_project_model() -> None:
    names = pinobs.robot_names()
    assert names == sorted(names)
    readme = (Path(pinobs.model.loading._models_dir()) / "README.md").read_text()
    for e in robot_entries():
        if e.origin == "pinobs":
            assert f"`{e.name}`" in readme


@pytest.mark.parametrize("name", ["top", "rigid_body", "pr2"])
def test_check_configuration_rejects_non_unit_quaternions_and_renormalises_close_ones(
    name: str,
) -> None:
    robot = pinobs.load(name)
    q = robot.random_configuration(np.random.default_rng(0))
    s = robot._quat_slices[0] if robot._quat_slices else robot._circle_slices[0]
    near = q.copy()
    near[s] *= 1 + 1e-6
    np.testing.assert_allclose(np.linalg.norm(robot.check_configuration(near)[s]), 1.0, atol=1e-15)
    far = q.copy()
    far[s] *= 1.1
    with pytest.raises(pinobs.ConfigurationError, match=r"norm 1\.1"):
        robot.check_configuration(far)


def test_every_urdf_the_example_robot_data_wheel_ships_has_a_name() -> None:
    from pinobs.model.loading import _erd_share_dir

    robots = _erd_share_dir() / "example-robot-data" / "robots"
    files = {str(f.relative_to(robots)) for f in robots.glob("*/*/*.urdf")}
    named = {e.file for e in robot_entries() if e.origin == "example-robot-data"}
    assert files and files <= named
    assert all(n.isidentifier() for n in pinobs.robot_names())


@pytest.mark.parametrize(
    ("name", "nv"), [("ur5_gripper", 6), ("allegro_right_hand", 16), ("iris", 4)]
)
def test_robots_found_in_the_wheel_but_not_in_the_table_load(name: str, nv: int) -> None:
    robot = pinobs.load(name)
    assert robot.nv == nv and robot.root_joint == "fixed"


def test_an_existing_urdf_with_another_suffix_loads_as_a_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from pinobs.model.loading import _models_dir

    (tmp_path / "pendulum.urdf.bak").write_text((_models_dir() / "pendulum.urdf").read_text())
    (tmp_path / "pendulum_copy").write_text((_models_dir() / "pendulum.urdf").read_text())
    monkeypatch.chdir(tmp_path)
    for source in ("./pendulum.urdf.bak", "pendulum.urdf.bak", "pendulum_copy"):
        robot = pinobs.load(source)  # was: "unknown robot" (judged a name by its suffix)
        assert (robot.nq, robot.nv) == (1, 1)


def test_a_directory_or_a_non_robot_file_is_refused_saying_what_it_is(tmp_path: Path) -> None:
    with pytest.raises(pinobs.errors.ModelFileError, match="is a directory; give a URDF/MJCF"):
        pinobs.load(tmp_path)  # was: "does not exist"
    notes = tmp_path / "notes.txt"
    notes.write_text("hello\n")
    with pytest.raises(pinobs.errors.ModelFileError, match=r"neither a URDF \(<robot>\) nor"):
        pinobs.load(notes)

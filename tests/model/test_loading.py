"""Finding and loading robots."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pinocchio as pin
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


def test_a_urdfs_sidecar_sets_the_armature_and_a_bad_one_is_refused_naming_it(
    tmp_path: Path,
) -> None:
    src = Path(pinobs.model.loading._models_dir()) / "planar_3r.urdf"
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(src.read_text())
    sidecar = tmp_path / "arm.pinobs.json"
    head = '{"format": "pinobs-sidecar", "version": 1, "armature": '
    sidecar.write_text(head + '{"joint2": 0.2, "joint3": 0.1}}')
    robot = pinobs.load(urdf)
    np.testing.assert_array_equal(robot.model.armature, [0.0, 0.2, 0.1])
    plain = pinobs.load("planar_3r")
    q = plain.neutral()
    np.testing.assert_allclose(
        robot.mass_matrix(q) - plain.mass_matrix(q), np.diag([0.0, 0.2, 0.1]), atol=1e-12
    )
    for body, match in (
        ('{"elbow": 0.2}}', r"joint 'elbow', which the robot does not have; .*joint1, joint2"),
        ('{"joint2": -0.2}}', r"armature -0\.2 of joint 'joint2' must be a finite number ≥ 0"),
        ('{"joint2": [0.1, 0.2]}}', r"joint 'joint2' has 1 velocity coordinate"),
        ("{", r"cannot parse the sidecar"),
    ):
        sidecar.write_text(head + body if body != "{" else body)
        with pytest.raises(pinobs.ModelFileError, match=match):
            pinobs.load(urdf)
    sidecar.write_text('{"armature": {}}')
    with pytest.raises(pinobs.ModelFileError, match="not a pinobs sidecar"):
        pinobs.load(urdf)


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


# ------------------------------------------------------------------ locked joints
def _full_configuration(full: pinobs.Robot, locked: pinobs.Robot, q: np.ndarray) -> np.ndarray:
    """The full robot's q: the locked robot's joints from ``q``, the locked ones at their values."""
    out = np.array(pin.neutral(full.model))
    blocks = {b.name: b for b in full.joints}
    for b in locked.joints:
        f = blocks[b.name]
        out[f.idx_q : f.idx_q + f.nq] = q[b.idx_q : b.idx_q + b.nq]
    for name, value in locked.locked.items():
        f = blocks[name]
        if isinstance(value, tuple):
            out[f.idx_q : f.idx_q + f.nq] = value
        elif f.kind == "circle":
            out[f.idx_q : f.idx_q + 2] = np.cos(value), np.sin(value)
        else:
            out[f.idx_q] = value
    return out


def _free_indices(full: pinobs.Robot, locked: pinobs.Robot) -> np.ndarray:
    blocks = {b.name: b for b in full.joints}
    return np.concatenate(
        [np.arange(blocks[b.name].idx_v, blocks[b.name].idx_v + b.nv) for b in locked.joints]
    )


def _assert_is_the_full_models_free_block(
    full: pinobs.Robot, locked: pinobs.Robot, rng: np.random.Generator
) -> None:
    """M(q) and c(q, v) + g(q) of the locked robot are the full robot's rows and columns of
    the free joints, at the locked values with zero velocity on the locked joints."""
    free = _free_indices(full, locked)
    for _ in range(5):
        q = locked.random_configuration(rng)
        v = rng.normal(size=locked.nv)
        qf = _full_configuration(full, locked, q)
        vf = np.zeros(full.nv)
        vf[free] = v
        np.testing.assert_allclose(
            locked.mass_matrix(q), full.mass_matrix(qf)[np.ix_(free, free)], rtol=0, atol=1e-12
        )
        np.testing.assert_allclose(
            locked.nonlinear_effects(q, v),
            full.nonlinear_effects(qf, vf)[free],
            rtol=0,
            atol=1e-11,
        )


FINGERS = ["panda_finger_joint1", "panda_finger_joint2"]


def test_locking_panda_fingers_leaves_the_arm_with_the_full_models_dynamics(
    rng: np.random.Generator,
) -> None:
    full = pinobs.load("panda")
    robot = pinobs.load("panda", lock=FINGERS)
    assert (robot.nq, robot.nv) == (7, 7)
    assert robot.joint_names == full.joint_names[:7]
    assert robot.locked == dict.fromkeys(FINGERS, 0.0)  # neutral
    _assert_is_the_full_models_free_block(full, robot, rng)
    opened = pinobs.load("panda", lock={FINGERS[0]: 0.03, FINGERS[1]: 0.01})
    assert opened.locked == {FINGERS[0]: 0.03, FINGERS[1]: 0.01}
    _assert_is_the_full_models_free_block(full, opened, rng)
    q = opened.random_configuration(rng)
    assert not np.allclose(opened.mass_matrix(q), robot.mass_matrix(q), atol=1e-9)  # (it matters)


@pytest.mark.parametrize(
    ("name", "lock"),
    [
        ("ur5", {"elbow_joint": 0.7}),  # a middle joint: the bodies after it stay free
        ("cartpole_continuous", {"pole_theta": 0.4}),  # a continuous joint, by its angle
        ("cartpole_continuous", {"cart_x": 0.3}),  # prismatic
        ("go1", ["FL_hip_joint", "FL_thigh_joint", "FL_calf_joint"]),  # under a free-flyer
    ],
)
def test_a_locked_model_is_the_full_models_free_block_at_the_locked_values(
    name: str, lock: list[str] | dict[str, object], rng: np.random.Generator
) -> None:
    full = pinobs.load(name)
    robot = pinobs.load(name, lock=lock)
    assert set(robot.locked) == set(lock)
    assert robot.nv == full.nv - sum(b.nv for b in full.joints if b.name in lock)
    _assert_is_the_full_models_free_block(full, robot, rng)


def test_a_lock_pattern_locks_the_joints_it_matches_as_their_names_do() -> None:
    """``lock=["FL_*"]`` is ``lock=[FL_hip_joint, FL_thigh_joint, FL_calf_joint]``: the same
    reduced model; a value given to a pattern goes to each joint it matches."""
    named = pinobs.load("go1", lock=["FL_hip_joint", "FL_thigh_joint", "FL_calf_joint"])
    patterned = pinobs.load("go1", lock=["FL_*"])
    assert patterned.locked == named.locked and patterned.joint_names == named.joint_names
    q = patterned.random_configuration(np.random.default_rng(0))
    np.testing.assert_array_equal(patterned.mass_matrix(q), named.mass_matrix(q))
    bent = pinobs.load("go1", lock={"F?_calf_joint": -1.2})
    assert bent.locked == {"FL_calf_joint": -1.2, "FR_calf_joint": -1.2}


def test_a_lock_pattern_that_matches_nothing_or_a_joint_named_twice_is_an_error() -> None:
    with pytest.raises(pinobs.UnknownNameError, match=r"names \['hand_\*'\], which robot"):
        pinobs.load("go1", lock=["hand_*"])
    with pytest.raises(pinobs.GainError, match="'FL_calf_joint' more than once"):
        pinobs.load("go1", lock=["FL_*", "FL_calf_joint"])


def test_multi_dof_joints_lock_at_their_nq_coordinates(rng: np.random.Generator) -> None:
    full = pinobs.load("rigid_body", root_joint="freeflyer")
    model = full.model.copy()  # a pendulum hung under the body, to keep one joint free
    jid = model.addJoint(1, pin.JointModelRY(), pin.SE3(np.eye(3), np.array([0, 0, -0.3])), "hinge")
    model.appendBodyToJoint(jid, pin.Inertia.FromBox(0.7, 0.1, 0.2, 0.3), pin.SE3.Identity())
    base = pinobs.load(model)
    pose = (0.1, 0.2, 0.3, 0.0, 0.6, 0.0, 0.8)
    robot = pinobs.load(model, lock={"root_joint": pose})
    assert robot.nv == 1 and robot.locked == {"root_joint": pose}
    _assert_is_the_full_models_free_block(base, robot, rng)
    with pytest.raises(pinobs.DimensionError, match=r"'root_joint' has nq = 7 coordinates"):
        pinobs.load(model, lock={"root_joint": 0.5})
    with pytest.raises(pinobs.GainError, match=r"quaternion .* not of unit norm"):
        pinobs.load(model, lock={"root_joint": (0, 0, 0, 0, 0, 0, 2.0)})


def test_lock_works_for_urdf_files_mjcf_files_and_pin_models(rng: np.random.Generator) -> None:
    from pinobs.model.loading import _models_dir

    urdf = _models_dir() / "planar_3r.urdf"
    full = pinobs.load(urdf)
    joint = full.joint_names[1]
    for source in (urdf, full.model, pin.RobotWrapper(full.model)):
        robot = pinobs.load(source, lock={joint: -0.5})
        assert robot.locked == {joint: -0.5} and robot.nv == 2
        _assert_is_the_full_models_free_block(full, robot, rng)
    mjcf = _models_dir() / "mjcf_acrobot.xml"
    acrobot = pinobs.load(mjcf)
    robot = pinobs.load(mjcf, lock={"elbow": 0.3})
    assert robot.joint_names == ("shoulder",) and robot.friction == acrobot.friction
    _assert_is_the_full_models_free_block(acrobot, robot, rng)


def test_locked_geometry_sits_where_the_full_models_does(rng: np.random.Generator) -> None:
    full = pinobs.load("panda")
    robot = pinobs.load("panda", lock={FINGERS[0]: 0.03, FINGERS[1]: 0.02})
    q = robot.random_configuration(rng)
    qf = _full_configuration(full, robot, q)
    placements = {}
    for r, x in ((full, qf), (robot, q)):
        geom = r.visual_model
        data = geom.createData()
        pin.updateGeometryPlacements(r.model, r.model.createData(), geom, data, x)
        placements[r] = {g.name: data.oMg[k] for k, g in enumerate(geom.geometryObjects)}
    assert placements[robot].keys() == placements[full].keys()
    fingers = [n for n in placements[full] if "finger" in n]
    assert fingers
    for name, pose in placements[full].items():
        assert pose.isApprox(placements[robot][name], 1e-12), name


def test_copies_of_a_locked_robot_keep_what_was_locked() -> None:
    import pickle

    robot = pinobs.load("panda", lock={FINGERS[0]: 0.03})
    assert robot.nv == 8
    for copy in (
        robot.copy(),
        robot.perturbed(inertia_scale=np.ones(8)),
        robot.with_model(robot.model.copy(), name="other"),
        pickle.loads(pickle.dumps(robot)),
    ):
        assert copy.locked == {FINGERS[0]: 0.03}
    again = pinobs.load(robot.source, lock=robot.locked)  # what it keeps reloads it
    q = robot.random_configuration(np.random.default_rng(1))
    np.testing.assert_array_equal(again.mass_matrix(q), robot.mass_matrix(q))


def test_a_mimic_joint_that_is_locked_is_not_refused(tmp_path: Path) -> None:
    from tests.model.test_sanity import ARM

    arm = tmp_path / "arm.urdf"
    mimic = '<mimic joint="j1" multiplier="2"/>'
    arm.write_text(ARM.format(mimic=mimic, mass="1.0", ixx="0.02", iyy="0.02", izz="0.001"))
    with pytest.raises(pinobs.ModelError, match="mimics"):
        pinobs.load(arm)
    assert pinobs.load(arm, lock=["j2"]).joint_names == ("j1",)


def test_bad_locks_are_refused_naming_the_joint_and_what_is_valid() -> None:
    with pytest.raises(
        pinobs.UnknownNameError,
        match=r"lock \(--lock\) names \['finger'\].*"
        r"its joints: \['panda_joint1', .*'panda_finger_joint2'\]",
    ) as info:
        pinobs.load("panda", lock=["finger"])
    assert isinstance(info.value, KeyError)
    with pytest.raises(pinobs.UnknownNameError, match="did you mean 'panda_finger_joint1'"):
        pinobs.load("panda", lock=["panda_finger_joint"])
    with pytest.raises(pinobs.ModelTypeError, match=r"lock=\['panda_joint1'\] locks that joint"):
        pinobs.load("panda", lock="panda_joint1")
    with pytest.raises(pinobs.GainError, match=r"outside the position limits \[0, 0\.04\]"):
        pinobs.load("panda", lock={FINGERS[0]: 0.5})
    with pytest.raises(pinobs.GainError, match="more than once"):
        pinobs.load("panda", lock=[FINGERS[0], FINGERS[0]])
    with pytest.raises(pinobs.GainError, match="locks every moving joint"):
        pinobs.load("planar_3r", lock=list(pinobs.load("planar_3r").joint_names))
    with pytest.raises(pinobs.DimensionError, match="has nq = 1 coordinates"):
        pinobs.load("panda", lock={FINGERS[0]: [0.01, 0.02]})
    with pytest.raises(pinobs.NonFiniteError, match="not finite"):
        pinobs.load("panda", lock={FINGERS[0]: float("nan")})


def test_a_locked_joints_massless_bodies_are_not_refused() -> None:
    # full romeo is refused for its massless hands (test_sanity); locking them loads it checked
    full = pinobs.load("romeo", check=False)
    hands = [n for n in full.joint_names if re.fullmatch(r"[LR](Hand|Finger\d+|Thumb\d+)", n)]
    robot = pinobs.load("romeo", lock=hands)
    assert robot.nv == full.nv - len(hands)

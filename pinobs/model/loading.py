"""Find and load robots: the project's ``models/``, example-robot-data, or a file.

The example-robot-data wheel installs URDFs and meshes under its cmeel prefix
(``<site-packages>/cmeel.prefix/share/example-robot-data/robots``) and no
Python loader, so the table below maps its robot names to files.  Meshes are
resolved through the ``package://example-robot-data/...`` URIs with the
prefix's ``share`` folder as package directory.

**Files.**  An MJCF file (``.xml``/``.mjcf``) is compiled by MuJoCo when it is
installed, the model built from it and ``M(q)`` cross-checked with ``mj_fullM``
(:mod:`pinobs.model.mjcf`; without MuJoCo: :mod:`pinobs.model.mjcf_loading`).
A URDF's rotor inertias (``model.armature``, which URDF cannot hold) are read
from the sidecar ``<name>.pinobs.json`` beside it when there is one
(:mod:`pinobs.model.sidecar`: ``pinobs identify`` and
:func:`~pinobs.model.urdf_writer.write_urdf` write it); a sidecar naming a joint
the robot does not have is refused, naming it.

**Friction** (:func:`load`'s ``friction``): the joint friction of the URDF's
``<dynamics damping friction>`` tags, or the friction law of its sidecar when it
has one (``pinobs identify --friction-law``: :mod:`pinobs.model.friction`).
``friction=None`` means off for URDFs (many published ones carry placeholder
values: pr2's torso has 20000 N·s/m; switch it on when yours are identified) and
on for MJCF files loaded through MuJoCo (their ``damping`` and ``frictionloss``,
which MJCF authors mean).

**Checks** (:func:`load`'s ``check``): models whose dynamics cannot be right are
refused (:mod:`pinobs.model.sanity`): non-finite, negative or dropped masses,
impossible inertias, negative damping or friction, inverted position limits, a
mass matrix singular or indefinite at sampled configurations.  ``check=False``
skips these checks (a URDF's ``<dynamics>`` and ``<limit>`` values are checked
whatever it says).  A URDF revolute or prismatic joint with ``<limit lower="0"
upper="0">`` (or neither attribute) has no position limits, with one
:class:`~pinobs.errors.ModelWarning` naming such joints of a file (a registered
robot loads silently).
"""

from __future__ import annotations

import difflib
import importlib.metadata
import importlib.resources
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cache, partial
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from pinocchio.robot_wrapper import RobotWrapper

from pinobs.errors import (
    GainError,
    ModelFileError,
    ModelTypeError,
    ModelWarning,
    PinobsError,
    UnknownNameError,
)
from pinobs.model.locking import LockSpec, is_locked, lock_joints, lock_names
from pinobs.model.mjcf import MujocoMap, cross_check
from pinobs.model.mjcf_loading import load_mjcf
from pinobs.model.robot import Robot
from pinobs.model.sanity import check_model, check_urdf
from pinobs.model.sidecar import apply_sidecar, read_friction_law, read_model_error_psd
from pinobs.model.urdf import read_urdf

__all__ = ["LockSpec", "RobotEntry", "load", "resolve_source", "robot_entries", "robot_names"]


_ROOT_JOINTS: dict[str, type | None] = {
    "fixed": None,
    "spherical": pin.JointModelSpherical,
    "freeflyer": pin.JointModelFreeFlyer,
    "planar": pin.JointModelPlanar,
}


@dataclass(frozen=True)
class RobotEntry:
    """One registered robot.

    Attributes:
        name: registry name.
        origin: ``"pinobs"`` (the project's ``models/``) or ``"example-robot-data"``.
        file: path of the URDF relative to its collection.
        root_joint: root joint used when ``load`` is given none.
        description: one line for ``pinobs list``.
    """

    name: str
    origin: str
    file: str
    root_joint: str
    description: str


_PINOBS = "pinobs"
_ERD = "example-robot-data"

_ENTRIES: tuple[RobotEntry, ...] = (
    RobotEntry("cartpole", _PINOBS, "cartpole.urdf", "fixed", "pendulum on a cart, nv = 2"),
    RobotEntry(
        "cartpole_continuous",
        _PINOBS,
        "cartpole_continuous.urdf",
        "fixed",
        "the cart-pole with a continuous pole joint, nq = 3, nv = 2",
    ),
    RobotEntry("pendulum", _PINOBS, "pendulum.urdf", "fixed", "simple pendulum, nv = 1"),
    RobotEntry("planar_3r", _PINOBS, "planar_3r.urdf", "fixed", "3-link planar arm, nv = 3"),
    RobotEntry("rigid_body", _PINOBS, "rigid_body.urdf", "freeflyer", "free rigid body, SE(3)"),
    RobotEntry("top", _PINOBS, "top.urdf", "spherical", "axisymmetric heavy top, SO(3)"),
    # example-robot-data (names follow its own loader where it has one)
    RobotEntry("a1", _ERD, "a1_description/urdf/a1.urdf", "freeflyer", "Unitree A1 quadruped"),
    RobotEntry(
        "anymal",
        _ERD,
        "anymal_b_simple_description/robots/anymal.urdf",
        "freeflyer",
        "ANYmal B quadruped",
    ),
    RobotEntry(
        "anymal_c",
        _ERD,
        "anymal_c_simple_description/urdf/anymal.urdf",
        "freeflyer",
        "ANYmal C quadruped",
    ),
    RobotEntry(
        "asr_twodof", _ERD, "asr_twodof_description/urdf/TwoDofs.urdf", "fixed", "2-DOF planar arm"
    ),
    RobotEntry("b1", _ERD, "b1_description/urdf/b1.urdf", "freeflyer", "Unitree B1 quadruped"),
    RobotEntry(
        "baxter", _ERD, "baxter_description/urdf/baxter.urdf", "fixed", "Rethink Baxter, two arms"
    ),
    RobotEntry("bolt", _ERD, "bolt_description/robots/bolt.urdf", "freeflyer", "ODRI Bolt biped"),
    RobotEntry(
        "double_pendulum",
        _ERD,
        "double_pendulum_description/urdf/double_pendulum.urdf",
        "fixed",
        "double pendulum",
    ),
    RobotEntry(
        "double_pendulum_continuous",
        _ERD,
        "double_pendulum_description/urdf/double_pendulum_continuous.urdf",
        "fixed",
        "double pendulum, continuous joints",
    ),
    RobotEntry(
        "double_pendulum_simple",
        _ERD,
        "double_pendulum_description/urdf/double_pendulum_simple.urdf",
        "fixed",
        "double pendulum, simple shapes",
    ),
    RobotEntry(
        "finger_edu",
        _ERD,
        "finger_edu_description/robots/finger_edu.urdf",
        "fixed",
        "ODRI finger, 3 DOF",
    ),
    RobotEntry(
        "g1",
        _ERD,
        "g1_description/urdf/g1_29dof_rev_1_0.urdf",
        "freeflyer",
        "Unitree G1 humanoid, 29 DOF",
    ),
    RobotEntry("go1", _ERD, "go1_description/urdf/go1.urdf", "freeflyer", "Unitree Go1 quadruped"),
    RobotEntry("go2", _ERD, "go2_description/urdf/go2.urdf", "freeflyer", "Unitree Go2 quadruped"),
    RobotEntry(
        "hyq", _ERD, "hyq_description/robots/hyq_no_sensors.urdf", "freeflyer", "IIT HyQ quadruped"
    ),
    RobotEntry(
        "icub_reduced",
        _ERD,
        "icub_description/robots/icub_reduced.urdf",
        "freeflyer",
        "iCub humanoid, reduced",
    ),
    RobotEntry("kinova", _ERD, "kinova_description/robots/kinova.urdf", "fixed", "Kinova arm"),
    RobotEntry(
        "laikago",
        _ERD,
        "laikago_description/urdf/laikago.urdf",
        "freeflyer",
        "Unitree Laikago quadruped",
    ),
    RobotEntry(
        "panda", _ERD, "panda_description/urdf/panda.urdf", "fixed", "Franka Panda arm with gripper"
    ),
    RobotEntry(
        "pr2",
        _ERD,
        "pr2_description/urdf/pr2.urdf",
        "fixed",
        "Willow Garage PR2 (continuous joints)",
    ),
    RobotEntry(
        "romeo_small",
        _ERD,
        "romeo_description/urdf/romeo_small.urdf",
        "freeflyer",
        "Aldebaran Romeo humanoid",
    ),
    RobotEntry(
        "simple_humanoid",
        _ERD,
        "simple_humanoid_description/urdf/simple_humanoid.urdf",
        "freeflyer",
        "simple humanoid",
    ),
    RobotEntry("so100", _ERD, "so_arm_description/urdf/so100.urdf", "fixed", "SO-100 low-cost arm"),
    RobotEntry("so101", _ERD, "so_arm_description/urdf/so101.urdf", "fixed", "SO-101 low-cost arm"),
    RobotEntry(
        "solo8", _ERD, "solo_description/robots/solo.urdf", "freeflyer", "ODRI Solo 8 quadruped"
    ),
    RobotEntry(
        "solo12", _ERD, "solo_description/robots/solo12.urdf", "freeflyer", "ODRI Solo 12 quadruped"
    ),
    RobotEntry(
        "talos",
        _ERD,
        "talos_data/robots/talos_reduced.urdf",
        "freeflyer",
        "PAL Talos humanoid, reduced",
    ),
    RobotEntry(
        "talos_arm", _ERD, "talos_data/robots/talos_left_arm.urdf", "fixed", "PAL Talos left arm"
    ),
    RobotEntry(
        "tiago",
        _ERD,
        "tiago_description/robots/tiago.urdf",
        "fixed",
        "PAL TIAGo mobile manipulator",
    ),
    RobotEntry("ur3", _ERD, "ur_description/urdf/ur3_robot.urdf", "fixed", "Universal Robots UR3"),
    RobotEntry("ur5", _ERD, "ur_description/urdf/ur5_robot.urdf", "fixed", "Universal Robots UR5"),
    RobotEntry(
        "ur10", _ERD, "ur_description/urdf/ur10_robot.urdf", "fixed", "Universal Robots UR10"
    ),
    RobotEntry("xarm7", _ERD, "xarm_description/urdf/xarm7.urdf", "fixed", "UFACTORY xArm 7"),
    RobotEntry("z1", _ERD, "z1_description/urdf/z1.urdf", "fixed", "Unitree Z1 arm"),
)


@cache
def _all_entries() -> dict[str, RobotEntry]:
    """The table above plus every other URDF the example-robot-data wheel ships.

    The others get the file's stem as name (lower case, ``-`` → ``_``, a trailing
    ``_robot`` dropped; the folder's name in front where two files share a stem)
    (``.`` too) and a fixed root: pass ``root_joint`` for a floating base.
    """
    entries = {e.name: e for e in _ENTRIES}
    try:
        robots = _erd_share_dir() / "example-robot-data" / "robots"
    except ModelFileError:
        return entries
    known = {e.file for e in _ENTRIES if e.origin == _ERD}
    files = sorted(str(f.relative_to(robots)) for f in robots.glob("*/*/*.urdf"))
    stems: dict[str, int] = {}
    for f in files:
        stems[Path(f).stem] = stems.get(Path(f).stem, 0) + 1
    for f in files:
        if f in known:
            continue
        stem = Path(f).stem
        name = stem.lower().replace("-", "_").replace(".", "_").removesuffix("_robot")
        if stems[stem] > 1 or name in entries:
            name = f"{Path(f).parts[0].removesuffix('_description')}_{name}"
        if name not in entries:
            entries[name] = RobotEntry(name, _ERD, f, "fixed", f"example-robot-data {f}")
    return entries


def robot_entries() -> tuple[RobotEntry, ...]:
    """Every robot :func:`load` knows by name, sorted by name."""
    return tuple(sorted(_all_entries().values(), key=lambda e: e.name))


def robot_names() -> list[str]:
    """Names accepted by :func:`load`, sorted."""
    return sorted(_all_entries())


def _models_dir() -> Path:
    """The project's ``models/`` folder (shipped as package data ``pinobs._models``)."""
    return Path(str(importlib.resources.files("pinobs._models")))


@cache
def _erd_share_dir() -> Path:
    """``<prefix>/share`` of the example-robot-data wheel (holds ``example-robot-data/robots``)."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError as exc:
        raise ModelFileError(
            "example-robot-data is not installed; `pip install example-robot-data` provides "
            "its robots (pinobs' own models need nothing)"
        ) from exc
    for f in dist.files or ():
        parts = Path(str(f)).parts
        if "example-robot-data" in parts and "share" in parts:
            i = parts.index("share")
            return Path(str(dist.locate_file(Path(*parts[: i + 1]))))
    raise ModelFileError("example-robot-data is installed but ships no share/ folder")


_SUFFIXES = (".urdf", ".xml", ".mjcf")


def _root_tag(path: Path) -> str | None:
    """The root element's tag of an XML file, or ``None`` if it is not XML."""
    try:
        for _, element in ET.iterparse(path, events=("start",)):
            return str(element.tag)
    except (ET.ParseError, OSError, UnicodeDecodeError):
        return None
    return None


def _is_urdf(path: Path) -> bool:
    """``.urdf`` files, and files of another suffix (not ``.xml``/``.mjcf``) whose root
    element is ``<robot>`` (a copy such as ``arm.urdf.bak``)."""
    suffix = path.suffix.lower()
    if suffix in _SUFFIXES:
        return suffix == ".urdf"
    return _root_tag(path) == "robot"


def resolve_source(source: str | Path) -> tuple[Path, list[Path], str, str]:
    """Return (file, package dirs, default root joint, display name) for ``source``, a
    registry name or a URDF/MJCF path (as :func:`load` takes it; its errors)."""
    entry = _all_entries().get(str(source))
    if entry is not None:
        if entry.origin == _PINOBS:
            folder = _models_dir()
            return folder / entry.file, [folder], entry.root_joint, entry.name
        share = _erd_share_dir()
        path = share / "example-robot-data" / "robots" / entry.file
        return path, [share], entry.root_joint, entry.name
    path = Path(source)
    if path.is_dir():
        raise ModelFileError(
            f"robot {str(path)!r} is a directory; give a URDF/MJCF file in it or a robot name"
        )
    if path.is_file():  # an existing file is a file whatever its suffix (arm.urdf.bak)
        if path.suffix.lower() not in _SUFFIXES and _root_tag(path) not in ("robot", "mujoco"):
            raise ModelFileError(
                f"robot file {str(path)!r} is neither a URDF (<robot>) nor an MJCF (<mujoco>) "
                "file; give one, or a robot name (pinobs list)"
            )
        return path, [], "fixed", path.stem
    looks_like_path = path.suffix.lower() in (".urdf", ".xml", ".mjcf") or len(path.parts) > 1
    if not looks_like_path:
        raise UnknownNameError(
            f"unknown robot {str(source)!r}; {_did_you_mean(str(source))}give a path to a "
            "URDF/MJCF file or a robot name (pinobs list)"
        )
    if not path.is_file():
        raise ModelFileError(
            f"robot file {str(path)!r} does not exist; give an existing URDF/MJCF file "
            "or a robot name (pinobs list)"
        )
    return path, [], "fixed", path.stem


def _did_you_mean(name: str) -> str:
    """``"did you mean 'ur5'? "`` for a name close to registered ones (case ignored), else the
    table's names (the wheel's other URDFs are counted, not listed)."""
    names = robot_names()
    lower = {n.lower(): n for n in names}
    close = difflib.get_close_matches(name.lower(), list(lower), n=3, cutoff=0.6)
    if name.lower() in lower:  # only the case differs
        close = [name.lower()]
    if close:
        return "did you mean " + " or ".join(repr(lower[c]) for c in close) + "? "
    table = [e.name for e in _ENTRIES]
    more = len(names) - len(table)
    return f"known: {', '.join(sorted(table))}" + (
        f" and {more} more URDFs of example-robot-data; " if more else "; "
    )


def _from_pinocchio(
    source: pin.Model | RobotWrapper, root_joint: str | None, friction: bool | None
) -> Robot:
    """A :class:`Robot` around a ``pin.Model`` or a ``RobotWrapper`` (models copied, not shared)."""
    if root_joint is not None:
        raise GainError(
            f"root_joint={root_joint!r} applies to files and registry names only; a "
            "pin.Model or RobotWrapper already has its root joint: pass root_joint=None"
        )
    if isinstance(source, RobotWrapper):
        model, visual, collision = source.model, source.visual_model, source.collision_model
    else:
        model, visual, collision = source, None, None
    if model.nv == 0:
        raise ModelFileError(f"the pin.Model {model.name!r} has no moving joint (nv = 0)")
    name = model.name or "model"
    return Robot(
        model.copy(),
        name=name,
        source=f"<{type(source).__name__} {name}>",
        visual_model=visual.copy() if visual is not None else None,
        collision_model=collision.copy() if collision is not None else None,
        friction=bool(friction),
        root_joint=None,
    )


def _load_urdf(
    path: Path,
    package_dirs: list[str | Path],
    joint_type: type | None,
    *,
    mimic: str,
    check: bool,
    registered: bool,
    locked: frozenset[str] = frozenset(),
) -> tuple[pin.Model, Any]:
    """Model of a URDF and a loader of its geometry, meshes resolved as :mod:`pinobs.model.urdf` says.

    The file is checked first (:func:`~pinobs.model.sanity.check_urdf`).  Its
    revolute and prismatic joints with ``<limit lower="0" upper="0">`` (or
    without both attributes) get no position limits (Pinocchio's ±1.8e308):
    that is how many exporters write "no limits".  One
    :class:`~pinobs.errors.ModelWarning` lists them for a file (none for a
    registered robot: ``double_pendulum`` is written so).

    When meshes are missing, the dynamics load alone (no geometry) and one
    :class:`~pinobs.errors.ModelWarning` says which meshes (the playback then
    draws a stick figure).  Otherwise the geometry is built on first use.
    """
    facts = read_urdf(path, package_dirs)
    # a locked mimic joint is fixed
    free_mimics = tuple(m for m in facts.mimics if not is_locked(m[0], locked))
    check_urdf(replace(facts, mimics=free_mimics), mimic=mimic, inertials=check)
    args = (joint_type(),) if joint_type is not None else ()
    model = pin.buildModelFromXML(facts.xml, *args)
    if facts.zero_limits:
        lower = np.array(model.lowerPositionLimit, dtype=float)
        upper = np.array(model.upperPositionLimit, dtype=float)
        for name in facts.zero_limits:
            iq = model.joints[model.getJointId(name)].idx_q
            lower[iq], upper[iq] = -np.finfo(float).max, np.finfo(float).max
        model.lowerPositionLimit, model.upperPositionLimit = lower, upper
        if not registered:
            warnings.warn(
                f"{path}: joint(s) {', '.join(facts.zero_limits)} have <limit lower=0 upper=0> "
                "(or no lower/upper), read as no position limits; give their real range, "
                "or write type continuous, to silence this",
                ModelWarning,
                stacklevel=4,
            )
    if facts.missing_meshes:
        shown = ", ".join(facts.missing_meshes[:3])
        more = len(facts.missing_meshes) - 3
        warnings.warn(
            f"{path}: {len(facts.missing_meshes)} mesh(es) not found "
            f"({shown}{', …' if more > 0 else ''}); the dynamics are loaded without geometry "
            "(the playback draws a stick figure). Pass package_dirs=[folder that contains the "
            "package folder], or set ROS_PACKAGE_PATH / AMENT_PREFIX_PATH, to find package:// meshes",
            ModelWarning,
            stacklevel=4,
        )
        return model, partial(_given_geometry, None)
    return model, partial(_urdf_geometry, facts.xml)


def load(
    source: str | Path | pin.Model | RobotWrapper,
    *,
    root_joint: str | None = None,
    friction: bool | None = None,
    package_dirs: Sequence[str | Path] | None = None,
    mimic: str | None = None,
    lock: LockSpec | None = None,
    check: bool = True,
) -> Robot:
    """Load a robot by registry name, file path, ``pin.Model`` or ``RobotWrapper``.

    Args:
        source: a name from :func:`robot_names` (the project's ``models/`` or
            example-robot-data), a path to a URDF (``.urdf``) or MJCF
            (``.xml``/``.mjcf``) file (module docstring: files, sidecars), or a Pinocchio
            ``Model`` or ``RobotWrapper`` (copied; its geometry, if any, kept).
        root_joint: ``None`` (the registry's default: free-flyer for legged
            robots and the rigid body, spherical for the top, fixed otherwise;
            fixed for files; the model's own for a ``pin.Model``), ``"fixed"``,
            ``"spherical"``, ``"freeflyer"`` or ``"planar"``.
        friction: include the joint friction of the URDF's ``<dynamics damping
            friction>`` tags in the dynamics (:meth:`Robot.friction_torque`), or the
            friction law of its sidecar when it has one; ``None``: off for URDFs, on for
            MJCF files loaded through MuJoCo (module docstring: friction).
        package_dirs: folders searched for ``package://pkg/…`` mesh URIs (each
            holding the folder ``pkg``, or being it), before ``ROS_PACKAGE_PATH``,
            ``AMENT_PREFIX_PATH`` and the file's parent folders
            (:mod:`pinobs.model.urdf`).  Meshes still missing: the dynamics
            load without geometry and a :class:`~pinobs.errors.ModelWarning` says so.
        mimic: what to do with URDF ``<mimic>`` joints, which Pinocchio's
            forward dynamics cannot couple: ``"error"`` (refuse, naming the
            joint) or ``"independent"`` (each a joint of its own).  ``None``:
            ``"independent"`` for registry names (panda's and talos' grippers),
            ``"error"`` for files.  A mimic joint that is locked is fixed: no longer refused.
        lock: joints to lock (those a log does not record: a Panda's fingers): a list of
            joint names (each at its neutral value) or a mapping name → value (module
            docstring of :mod:`pinobs.model.locking`).
        check: refuse models whose dynamics cannot be right (module docstring: checks);
            ``False`` skips these checks.

    Raises:
        UnknownNameError: ``source`` is neither a registered name nor a path.
        ModelFileError: the file is missing or cannot be parsed; its sidecar cannot be
            parsed or names a joint the robot does not have.
        ModelTypeError: ``source`` is of another type.
        ModelError: the model fails a check (``check=True``), has mimic joints
            (``mimic="error"``), a URDF negative ``<dynamics>`` value or an
            inverted ``<limit>``, or (MJCF) its mass or ``M(q)`` differs from
            MuJoCo's; the message names the body or joint.
        GainError: ``root_joint`` is not one of the accepted values; a ``lock`` value
            outside its joint's limits, a joint named twice, or every moving joint locked.
        UnknownNameError: ``lock`` names a joint the robot does not have (the message
            lists its joints).
        DimensionError: a ``lock`` value with another count than its joint's ``nq``.
    """
    if mimic not in (None, "error", "independent"):
        raise GainError(f"mimic={mimic!r} is not accepted; use None, 'error' or 'independent'")
    if isinstance(source, pin.Model | RobotWrapper):
        robot = lock_joints(_from_pinocchio(source, root_joint, friction), lock)
    elif isinstance(source, str | Path):
        robot = _load_file(source, root_joint, friction, package_dirs, mimic, lock, check)
    else:
        raise ModelTypeError(
            f"cannot load a robot from a {type(source).__name__} ({source!r}); give a registry "
            "name (pinobs.robot_names()), a path to a URDF/MJCF file, a pinocchio.Model or a "
            "pinocchio.RobotWrapper"
        )
    if check:  # (after locking: a locked joint's massless bodies are no longer refused)
        check_model(robot.model)
    return robot


def _load_file(
    source: str | Path,
    root_joint: str | None,
    friction: bool | None,
    package_dirs: Sequence[str | Path] | None,
    mimic: str | None,
    lock: LockSpec | None,
    check: bool,
) -> Robot:
    """:func:`load` of a registry name or a file (its arguments), before the model checks."""
    path, default_dirs, default_root, name = resolve_source(source)
    root = default_root if root_joint is None else root_joint
    if root not in _ROOT_JOINTS:
        raise GainError(
            f"root_joint={root_joint!r} is not accepted; use None, "
            + ", ".join(repr(k) for k in _ROOT_JOINTS)
        )
    joint_type = _ROOT_JOINTS[root]
    dirs: list[str | Path] = [*(package_dirs or ()), *default_dirs]
    compiled: tuple[Any, MujocoMap] | None = None
    registered = str(source) in _all_entries()
    try:
        if _is_urdf(path):
            model, geometry = _load_urdf(
                path,
                dirs,
                joint_type,
                mimic=mimic or ("independent" if registered else "error"),
                check=check,
                registered=registered,
                locked=lock_names(lock),
            )
            apply_sidecar(model, path)  # the armature a URDF cannot hold (pinobs.model.sidecar)
        else:
            model, visual, _, compiled = load_mjcf(path, joint_type, root_joint)
            geometry = partial(_given_geometry, visual)
            if friction is None and compiled is not None:
                friction = True  # MJCF authors mean their damping (unlike URDF placeholders)
    except PinobsError:
        raise
    except (RuntimeError, ValueError, OSError, ET.ParseError) as exc:
        raise ModelFileError(
            f"cannot parse robot file {str(path)!r} (from source {str(source)!r}): {exc}"
        ) from exc
    if model.nv == 0:
        raise ModelFileError(
            f"robot {str(source)!r} has no moving joint; a single rigid body needs "
            "root_joint='spherical' or 'freeflyer'"
        )
    if compiled is not None:
        cross_check(model, *compiled)
    robot = Robot(
        model,
        name=name,
        source=str(source),
        friction=bool(friction),
        root_joint=None if compiled is not None else root,  # MuJoCo: the file's own root
        geometry=geometry,  # meshes: on first draw
        package_dirs=package_dirs or (),  # the URDF writer resolves the meshes with them
    )
    robot.mimic = mimic  # as asked (a saved run reloads its robot so: pinobs play)
    robot = lock_joints(robot, lock)
    return _with_sidecar(robot, path, friction=bool(friction)) if _is_urdf(path) else robot


def _with_sidecar(robot: Robot, urdf: Path, *, friction: bool) -> Robot:
    """``robot`` with what the sidecar beside ``urdf`` holds beyond the armature
    (:mod:`pinobs.model.sidecar`): a friction law beyond the tags (with ``friction``) and an
    identified model's own acceleration error."""
    if friction:
        law = read_friction_law(robot.model, urdf, locked=frozenset(robot.locked))
        if law is not None:
            mimic = robot.mimic
            robot = robot.with_model(robot.model, friction_law=law)
            robot.mimic = mimic
    robot.model_error_psd = read_model_error_psd(urdf)
    return robot


def _urdf_geometry(xml: str, model: pin.Model) -> tuple[Any, Any]:
    """``(visual, collision)`` of a URDF whose meshes were resolved (:func:`read_urdf`), built on
    demand: meshes took 4 of the 4.3 s of loading go1 and 187 MB of a pickled UR5.  Geometry
    that cannot be read gives ``(None, None)`` and a :class:`~pinobs.errors.ModelWarning`."""
    try:
        return (
            pin.buildGeomFromUrdfString(model, xml, pin.GeometryType.VISUAL),
            pin.buildGeomFromUrdfString(model, xml, pin.GeometryType.COLLISION),
        )
    except (RuntimeError, ValueError) as exc:
        warnings.warn(
            f"the robot's geometry could not be read ({exc}); the playback draws a stick figure",
            ModelWarning,
            stacklevel=2,
        )
        return None, None


def _given_geometry(visual: Any, model: pin.Model) -> tuple[Any, Any]:
    """Geometry built with the model (MJCF): handed over as it is."""
    return visual, None

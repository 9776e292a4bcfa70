"""Write a robot's dynamics back into its URDF (calibrated models that every tool loads).

The source URDF is rewritten, not regenerated, so visuals, collisions,
limits and anything else it says are kept.  What changes:

* Pinocchio merges the links fixed to a joint's child link into one body; the
  identified inertia of that body is written as the ``<inertial>`` of the
  child link (its frame is the joint frame), and the ``<inertial>`` of the
  links fixed to it are removed (their mass is in the merged one).  URDF
  stores the inertia at the centre of mass ``c``:
  ``I_c = I_o − m (|c|² 1 − c cᵀ)`` (parallel-axis theorem) with ``I_o`` at
  the frame origin (Pinocchio's ``Inertia`` holds ``m``, ``c``, ``I_c``).
* ``<dynamics damping friction>`` of every moving joint: the model's viscous
  and Coulomb coefficients, read back by ``pinobs.load(path, friction=True)``.
* every ``<mesh filename>`` becomes the absolute path of the file it named,
  found as :func:`pinobs.load` found it (:func:`~pinobs.model.urdf.resolve_mesh`:
  ``package://`` URIs through the package directories the robot was loaded
  with, relative paths from the source URDF's folder), so the written file
  loads its meshes from any folder of the same machine (copy the meshes and
  edit the paths to move it to another).  A ``package://`` URI that resolved
  to nothing is kept as it is; a relative path that did is written absolute
  from the source's folder all the same.

* the joints :func:`pinobs.load` locked (``lock=``, :attr:`Robot.locked`) become
  ``type="fixed"`` joints whose ``<origin>`` is the joint's origin composed with
  its motion at the locked value (a rotation about the axis for revolute and
  continuous joints, a translation along it for prismatic ones), their
  ``<axis>``, ``<limit>``, ``<dynamics>``, ``<mimic>``, ``<calibration>`` and
  ``<safety_controller>`` dropped: Pinocchio then merges their bodies as
  ``pin.buildReducedModel`` did, so the file loads without ``lock=``.

* the rotor inertias (``model.armature``), which URDF cannot hold, go to a sidecar
  beside the file, ``<name>.pinobs.json`` (:mod:`pinobs.model.sidecar`), which
  :func:`pinobs.load` reads back; a robot without armature writes none (and removes a
  stale one of that name).

A robot built from a ``pin.Model`` (or a ``RobotWrapper``) has no URDF behind
it: one is generated from the model (:func:`_generated_urdf`), with its kinematic
tree, inertias, limits and joint friction and no geometry.

Numbers are written with ``repr`` (17 significant digits), so a model
reloaded from the file has the same dynamics to rounding.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pinocchio as pin

from pinobs.errors import ModelFileError
from pinobs.model.robot import Robot
from pinobs.model.sidecar import write_sidecar
from pinobs.model.urdf import resolve_mesh

__all__ = ["generated_root_joint", "write_urdf"]


def _fmt(*xs: float) -> str:
    return " ".join(repr(float(x)) for x in xs)


_MOTION_ONLY = ("axis", "limit", "dynamics", "mimic", "calibration", "safety_controller")


def _vec(text: str | None, default: tuple[float, float, float]) -> np.ndarray:
    return np.array([float(x) for x in text.split()] if text else default, dtype=float)


def _fix_locked(robot: Robot, joints: dict[str | None, ET.Element], source: Path) -> None:
    """Each joint of ``robot.locked`` made a fixed joint at its locked value (module docstring)."""
    for name, value in robot.locked.items():
        joint = joints.get(name)
        kind = joint.get("type") if joint is not None else None
        if joint is None or kind not in ("revolute", "continuous", "prismatic"):
            what = f"a {kind} joint" if joint is not None else "not a joint of the file"
            raise ModelFileError(
                f"robot {robot.name!r} has joint {name!r} locked, which is {what} in "
                f"{str(source)!r}: only revolute, continuous and prismatic joints are written "
                "back as fixed ones"
            )
        if not isinstance(value, float | int):
            raise ModelFileError(f"locked joint {name!r} has value {value!r}; one number expected")
        axis_el = joint.find("axis")
        axis = _vec(axis_el.get("xyz") if axis_el is not None else None, (1.0, 0.0, 0.0))
        axis = axis / np.linalg.norm(axis)  # (urdfdom normalises it too)
        origin = joint.find("origin")
        placement = pin.SE3(
            pin.rpy.rpyToMatrix(
                *_vec(origin.get("rpy") if origin is not None else None, (0, 0, 0))
            ),
            _vec(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0)),
        )
        if kind == "prismatic":
            motion = pin.SE3(np.eye(3), float(value) * axis)
        else:
            motion = pin.SE3(pin.AngleAxis(float(value), axis).matrix(), np.zeros(3))
        fixed = placement * motion
        for tag in _MOTION_ONLY:
            for el in joint.findall(tag):
                joint.remove(el)
        if origin is None:
            origin = ET.SubElement(joint, "origin")
        origin.set("xyz", _fmt(*fixed.translation))
        origin.set("rpy", _fmt(*pin.rpy.matrixToRpy(fixed.rotation)))
        joint.set("type", "fixed")


def _source_urdf(robot: Robot) -> tuple[Path, list[Path]]:
    """The URDF ``robot`` was loaded from, and the package directories its meshes were
    searched in (those given to :func:`pinobs.load`, then the registry's)."""
    from pinobs.model.loading import resolve_source

    try:
        path, dirs = resolve_source(robot.source)[:2]
    except Exception as exc:  # unknown name, missing file: say what we need
        raise ModelFileError(
            f"cannot find the URDF robot {robot.name!r} came from ({robot.source!r}): {exc}"
        ) from exc
    if path.suffix.lower() != ".urdf":
        raise ModelFileError(
            f"robot {robot.name!r} comes from {str(path)!r}; only URDF sources can be rewritten"
        )
    return path, [*robot.package_dirs, *dirs]


def _absolute_meshes(root: ET.Element, source: Path, package_dirs: list[Path]) -> None:
    """Every ``<mesh filename>`` under ``root`` made an absolute path (module docstring)."""
    for mesh in root.iter("mesh"):
        uri = mesh.get("filename")
        if uri is None:
            continue
        found = resolve_mesh(uri, source, package_dirs)
        if found is None and not uri.startswith("package://"):
            plain = Path(uri.removeprefix("file://"))
            found = plain if plain.is_absolute() else source.resolve().parent / plain
        if found is not None:
            mesh.set("filename", str(found))


def _inertial(link: ET.Element, inertia: pin.Inertia) -> None:
    """``link``'s ``<inertial>`` (replacing any): ``inertia`` in the link's frame."""
    for el in link.findall("inertial"):
        link.remove(el)
    el = ET.SubElement(link, "inertial")
    ET.SubElement(el, "origin", xyz=_fmt(*inertia.lever), rpy="0 0 0")
    ET.SubElement(el, "mass", value=_fmt(inertia.mass))
    ic = np.asarray(inertia.inertia)
    ET.SubElement(
        el,
        "inertia",
        ixx=_fmt(ic[0, 0]),
        ixy=_fmt(ic[0, 1]),
        ixz=_fmt(ic[0, 2]),
        iyy=_fmt(ic[1, 1]),
        iyz=_fmt(ic[1, 2]),
        izz=_fmt(ic[2, 2]),
    )


def _friction(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """Viscous and Coulomb coefficients per velocity coordinate (zero with friction off): its
    friction law's ``F_v`` and mean Coulomb level (the rest of a law goes to the sidecar)."""
    law = robot.friction_law  # (zero with friction off; the tags' own law by default)
    return np.array(law.viscous), 0.5 * (law.coulomb_pos + law.coulomb_neg)


def _rewritten_urdf(robot: Robot) -> ET.ElementTree[ET.Element]:
    """The robot's source URDF with its inertials, friction and locked joints (module docstring)."""
    source, package_dirs = _source_urdf(robot)
    tree: ET.ElementTree[ET.Element] = ET.parse(source)
    root = tree.getroot()
    _absolute_meshes(root, source, package_dirs)
    links = {link.get("name"): link for link in root.findall("link")}
    joints = {joint.get("name"): joint for joint in root.findall("joint")}  # not <transmission>s
    model = robot.model
    for i in range(1, model.njoints):
        frames = [f for f in model.frames if f.type == pin.FrameType.BODY and f.parentJoint == i]
        own = joints.get(model.names[i])
        child_el = own.find("child") if own is not None else None
        child_link = child_el.get("link") if child_el is not None else None
        frames.sort(key=lambda f: f.name != child_link)  # the joint's child link first
        if not frames or frames[0].name not in links:
            continue
        child = frames[0]
        for f in frames[1:]:  # merged into this body (fixed or locked): drop their own inertials
            other = links.get(f.name)
            if other is not None:
                for el in other.findall("inertial"):
                    other.remove(el)
        _inertial(links[child.name], child.placement.actInv(model.inertias[i]))
    damping, coulomb = _friction(robot)
    for b in robot.joints:
        joint = joints.get(b.name)
        if joint is None or b.nv != 1:
            continue
        for el in joint.findall("dynamics"):
            joint.remove(el)
        ET.SubElement(
            joint, "dynamics", damping=_fmt(damping[b.idx_v]), friction=_fmt(coulomb[b.idx_v])
        )
    _fix_locked(robot, joints, source)
    return tree


#: Pinocchio joint types a generated URDF writes, by ``shortname()``: URDF type and axis.
_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}
_URDF_JOINTS: dict[str, tuple[str, tuple[float, float, float] | None]] = {
    **{f"JointModelR{a}": ("revolute", e) for a, e in _AXES.items()},
    **{f"JointModelRUB{a}": ("continuous", e) for a, e in _AXES.items()},
    **{f"JointModelP{a}": ("prismatic", e) for a, e in _AXES.items()},
    "JointModelRevoluteUnaligned": ("revolute", None),
    "JointModelRevoluteUnboundedUnaligned": ("continuous", None),
    "JointModelPrismaticUnaligned": ("prismatic", None),
}
_ROOTS = {
    "JointModelFreeFlyer": "freeflyer",
    "JointModelSpherical": "spherical",
    "JointModelPlanar": "planar",
}
#: Pinocchio's "no position limit" (and what ``pinobs.load`` gives a joint without one).
_NO_LIMIT = float(np.finfo(float).max)


def generated_root_joint(model: pin.Model) -> str:
    """The ``root_joint`` to load a URDF generated from ``model`` with (:func:`write_urdf`)."""
    if model.njoints > 1 and model.parents[1] == 0:
        return _ROOTS.get(model.joints[1].shortname(), "fixed")
    return "fixed"


def _generated_urdf(robot: Robot) -> ET.ElementTree[ET.Element]:
    """A URDF of ``robot``'s model alone: one link per joint, at the joint's frame, holding
    its body's inertia; joints with their placement, axis, limits and friction; no geometry.
    A free-flyer, spherical or planar root joint (the only joint on the world, at the
    identity) is left out: its body is the URDF's root link, loaded back with that
    ``root_joint`` (:func:`generated_root_joint`).

    Raises:
        ModelFileError: the model has what a URDF cannot say: another joint type, a
            gravity other than the URDF loaders' ``(0, 0, -9.81)``.
    """
    model = robot.model
    floating = _check_generable(robot)
    names: dict[int, str] = {}  # joint id -> its link's name
    link_name = _link_namer(model, floating)
    root = ET.Element("robot", name=model.name or robot.name)
    first = 1 if floating else 0
    damping, coulomb = _friction(robot)
    for i in range(first, model.njoints):
        names[i] = link_name(i)
        link = ET.SubElement(root, "link", name=names[i])
        if i > 0:
            _inertial(link, model.inertias[i])
    for i in range(first + 1, model.njoints):
        _joint_element(root, robot, i, names, damping, coulomb)
    return ET.ElementTree(root)


def _check_generable(robot: Robot) -> bool:
    """Whether ``robot``'s model has a floating root (left out of the URDF), after checking
    that a URDF can say its gravity and its root (:func:`_generated_urdf`'s errors)."""
    model = robot.model
    if not np.array_equal(np.asarray(model.gravity.linear), [0.0, 0.0, -9.81]) or np.any(
        model.gravity.angular
    ):
        raise ModelFileError(
            f"robot {robot.name!r} has gravity {np.asarray(model.gravity.linear).tolist()}, "
            "which a URDF cannot hold (URDF loaders use (0, 0, -9.81))"
        )
    root_kind = generated_root_joint(model)
    floating = root_kind != "fixed"
    if floating:
        if (
            sum(1 for p in model.parents[1:] if p == 0) > 1
            or not model.jointPlacements[1].isIdentity()
        ):
            raise ModelFileError(
                f"robot {robot.name!r}: its {root_kind} root joint is not the only joint on the "
                "world at the identity, which a URDF loaded with root_joint cannot say"
            )
    return floating


def _link_namer(model: pin.Model, floating: bool) -> Callable[[int], str]:
    """A function naming joint ``i``'s link: its body frame's name at the joint's frame,
    else ``<joint>_link``; unique among the links' and joints' names."""
    taken = {model.names[i] for i in range(model.njoints)}  # link names must differ from joints'

    def link_name(i: int) -> str:
        body = [
            f.name
            for f in model.frames
            if f.type == pin.FrameType.BODY and f.parentJoint == i and f.placement.isIdentity()
        ]
        if i == 0 and not floating:
            body = [
                f.name for f in model.frames if f.type == pin.FrameType.BODY and f.parentJoint == 0
            ] or ["world_link"]
        name = body[0] if body and body[0] not in taken else f"{model.names[i]}_link"
        while name in taken:
            name += "_"
        taken.add(name)
        return name

    return link_name


def _joint_element(
    root: ET.Element,
    robot: Robot,
    i: int,
    names: dict[int, str],
    damping: np.ndarray,
    coulomb: np.ndarray,
) -> None:
    """Joint ``i`` of ``robot``'s model written into ``root``: placement, axis, limits,
    friction (``damping``, ``coulomb`` by velocity index)."""
    model = robot.model
    joint = model.joints[i]
    short = joint.shortname()
    if short not in _URDF_JOINTS:
        raise ModelFileError(
            f"robot {robot.name!r}: joint {model.names[i]!r} is a {short}, which a URDF "
            "cannot say (revolute, continuous and prismatic joints can, and a free-flyer, "
            "spherical or planar root); load the robot from its URDF with "
            "pinobs.load(path, lock=...) to write it back"
        )
    kind, axis = _URDF_JOINTS[short]
    el = ET.SubElement(root, "joint", name=model.names[i], type=kind)
    placement = model.jointPlacements[i]
    ET.SubElement(
        el,
        "origin",
        xyz=_fmt(*placement.translation),
        rpy=_fmt(*pin.rpy.matrixToRpy(placement.rotation)),
    )
    ET.SubElement(el, "parent", link=names[model.parents[i]])
    ET.SubElement(el, "child", link=names[i])
    ET.SubElement(el, "axis", xyz=_fmt(*(axis if axis is not None else joint.extract().axis)))
    iq, iv = joint.idx_q, joint.idx_v
    limit = {
        "effort": _fmt(min(float(model.effortLimit[iv]), _NO_LIMIT)),
        "velocity": _fmt(min(float(model.velocityLimit[iv]), _NO_LIMIT)),
    }
    if kind != "continuous":
        limit["lower"] = _fmt(max(float(model.lowerPositionLimit[iq]), -_NO_LIMIT))
        limit["upper"] = _fmt(min(float(model.upperPositionLimit[iq]), _NO_LIMIT))
    ET.SubElement(el, "limit", limit)
    ET.SubElement(el, "dynamics", damping=_fmt(damping[iv]), friction=_fmt(coulomb[iv]))


def write_urdf(robot: Robot, path: str | Path) -> str:
    """Write ``robot``'s inertials, joint friction and locked joints into a copy of its source
    URDF, or, for a robot built from a ``pin.Model``, a URDF generated from its model; its
    armature (rotor inertias) into the sidecar ``<name>.pinobs.json`` beside it
    (:mod:`pinobs.model.sidecar`), which :func:`pinobs.load` reads.

    Mesh filenames are written as absolute paths (module docstring), so the copy
    shows the robot's meshes wherever it is written on this machine.  A generated
    URDF has no geometry; load it back with ``root_joint=generated_root_joint(model)``.

    Args:
        robot: a robot loaded from a URDF (directly or via a calibrated copy of one), or
            from a ``pin.Model`` or ``RobotWrapper``.
        path: the file to write.

    Returns:
        The URDF's path, as a string.

    Raises:
        ModelFileError: the robot's source is not a URDF file that can be found; a
            locked joint the file cannot fix (not a revolute, continuous or prismatic
            joint of it); a ``pin.Model`` a URDF cannot say (:func:`_generated_urdf`).
    """
    bare = robot.source.startswith("<")  # "<Model name>", "<RobotWrapper name>": no file
    tree = _generated_urdf(robot) if bare else _rewritten_urdf(robot)
    ET.indent(tree)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    tree.write(tmp, encoding="utf-8", xml_declaration=True)
    tmp.replace(out)
    law = robot.friction_law if robot.friction else None
    write_sidecar(robot.model, out, law, robot.model_error_psd)
    return str(out)

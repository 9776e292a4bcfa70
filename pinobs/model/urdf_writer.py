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

Numbers are written with ``repr`` (17 significant digits), so a model
reloaded from the file has the same dynamics to rounding.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin

from pinobs.errors import ModelFileError
from pinobs.model.robot import Robot
from pinobs.model.urdf import resolve_mesh

__all__ = ["write_urdf"]


def _fmt(*xs: float) -> str:
    return " ".join(repr(float(x)) for x in xs)


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


def write_urdf(robot: Robot, path: str | Path) -> str:
    """Write ``robot``'s inertials and joint friction into a copy of its source URDF.

    Mesh filenames are written as absolute paths (module docstring), so the copy
    shows the robot's meshes wherever it is written on this machine.

    Args:
        robot: a robot loaded from a URDF (directly or via a calibrated copy of one).
        path: the file to write.

    Returns:
        The path written, as a string.

    Raises:
        ModelFileError: the robot's source is not a URDF file that can be found.
    """
    source, package_dirs = _source_urdf(robot)
    tree = ET.parse(source)
    root = tree.getroot()
    _absolute_meshes(root, source, package_dirs)
    links = {link.get("name"): link for link in root.findall("link")}
    joints = {joint.get("name"): joint for joint in root.findall("joint")}  # not <transmission>s
    model = robot.model
    for i in range(1, model.njoints):
        frames = [f for f in model.frames if f.type == pin.FrameType.BODY and f.parentJoint == i]
        if not frames or frames[0].name not in links:
            continue
        child = frames[0]
        inertia = child.placement.actInv(model.inertias[i])  # in the child link's frame
        link = links[child.name]
        for f in frames[1:]:  # merged into this body: drop their own inertials
            other = links.get(f.name)
            if other is not None:
                for el in other.findall("inertial"):
                    other.remove(el)
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
    damping = np.asarray(model.damping) if robot.friction else np.zeros(model.nv)
    coulomb = np.asarray(model.friction) if robot.friction else np.zeros(model.nv)
    for b in robot.joints:
        joint = joints.get(b.name)
        if joint is None or b.nv != 1:
            continue
        for el in joint.findall("dynamics"):
            joint.remove(el)
        ET.SubElement(
            joint, "dynamics", damping=_fmt(damping[b.idx_v]), friction=_fmt(coulomb[b.idx_v])
        )
    ET.indent(tree)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    tree.write(tmp, encoding="utf-8", xml_declaration=True)
    tmp.replace(out)
    return str(out)

"""What a URDF file says before Pinocchio reads it: meshes, inertials, mimic joints, joint values.

Pinocchio's URDF parser (urdfdom underneath) fails on a mesh it cannot find,
drops an ``<inertial>`` whose mass is not a number with only a message on
stderr, and either ignores ``<mimic>`` or builds a mimic joint its dynamics
algorithms refuse.  This module reads the XML itself so :func:`pinobs.load`
can resolve meshes, warn once when some are missing, and name the link or
joint at fault.

Mesh URIs are resolved as follows (first hit wins):

* ``package://pkg/rel``: ``d/pkg/rel`` and, when ``d`` is itself the folder
  ``pkg``, ``d/rel``, for ``d`` in the caller's ``package_dirs``, then the
  entries of ``ROS_PACKAGE_PATH``, then ``<prefix>/share`` for the prefixes of
  ``AMENT_PREFIX_PATH``; then the URDF file's parent folders (up to
  :data:`ANCESTOR_LEVELS` up), tried as package directories and as the
  package's own folder with ``rel``'s leading folders dropped one at a time
  (so a copy of ``ur_description/{urdf,meshes}`` finds
  ``package://example-robot-data/robots/ur_description/meshes/…``);
* ``file://path`` and plain paths: absolute, or relative to the URDF's folder.
"""

from __future__ import annotations

import math
import os
import re
import xml.etree.ElementTree as ET
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

__all__ = ["ANCESTOR_LEVELS", "UrdfFacts", "read_urdf", "resolve_mesh"]

#: How many parent folders of a URDF file are searched for its meshes.
ANCESTOR_LEVELS = 4

_INERTIA = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
_MESH_ATTR = re.compile(r"(<mesh\b[^>]*?\bfilename\s*=\s*)([\"'])(.*?)\2", re.DOTALL)


@dataclass(frozen=True)
class UrdfFacts:
    """A URDF's text with its meshes resolved, and what Pinocchio would lose reading it.

    Attributes:
        xml: the file's text, every resolvable mesh URI replaced by an absolute path.
        missing_meshes: mesh URIs that resolved to no existing file.
        mimics: ``(joint, mimicked joint, multiplier, offset)`` per ``<mimic>`` tag.
        bad_inertials: ``(link, what is wrong)`` for each ``<inertial>`` urdfdom
            drops or keeps in part: a value that is not a finite number, a missing
            ``<mass>``, ``<inertia>`` or attribute, a second ``<inertial>``.
        duplicates: ``"link 'name'"`` or ``"joint 'name'"`` for each name given twice.
        zero_axes: revolute, continuous and prismatic joints with ``<axis xyz="0 0 0">``.
        bad_dynamics: ``(joint, attribute, text)`` for each ``<dynamics damping friction>``
            value that is negative or not a finite number.
        bad_limits: ``(joint, lower, upper)`` for each revolute or prismatic joint whose
            ``<limit>`` has ``lower > upper``, or ``lower = upper`` other than 0.
        zero_limits: revolute and prismatic joints whose ``<limit>`` has
            ``lower = upper = 0`` (an attribute left out reads 0): the "no limits"
            convention of many exporters.
    """

    xml: str
    missing_meshes: tuple[str, ...]
    mimics: tuple[tuple[str, str, float, float], ...]
    bad_inertials: tuple[tuple[str, str], ...]
    duplicates: tuple[str, ...]
    zero_axes: tuple[str, ...]
    bad_dynamics: tuple[tuple[str, str, str], ...]
    bad_limits: tuple[tuple[str, float, float], ...]
    zero_limits: tuple[str, ...]


def _search_dirs(package_dirs: Sequence[str | Path]) -> list[Path]:
    dirs = [Path(d) for d in package_dirs]
    dirs += [Path(p) for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
    dirs += [
        Path(p) / "share" for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p
    ]
    return dirs


def resolve_mesh(uri: str, urdf_file: Path, package_dirs: Sequence[str | Path]) -> Path | None:
    """The existing file a mesh URI of ``urdf_file`` names, or ``None`` (order: module docstring)."""
    base = urdf_file.resolve().parent
    if uri.startswith("package://"):
        pkg, _, rel = uri[len("package://") :].partition("/")
        for d in _search_dirs(package_dirs):
            for cand in (d / pkg / rel, d / rel if d.name == pkg else None):
                if cand is not None and cand.is_file():
                    return cand.resolve()
        parts = Path(rel).parts
        for anc in [base, *base.parents][: ANCESTOR_LEVELS + 1]:
            if (anc / pkg / rel).is_file():
                return (anc / pkg / rel).resolve()
            for k in range(len(parts) - (2 if len(parts) > 1 else 1) + 1):
                cand = anc.joinpath(*parts[k:])
                if cand.is_file():
                    return cand.resolve()
        return None
    path = Path(uri[len("file://") :] if uri.startswith("file://") else uri)
    cand = path if path.is_absolute() else base / path
    return cand.resolve() if cand.is_file() else None


def _number(text: str | None, default: float) -> float | None:
    """``float(text)`` if it is a finite number, ``default`` if absent, else ``None``."""
    if text is None:
        return default
    try:
        x = float(text)
    except ValueError:
        return None
    return x if math.isfinite(x) else None


def read_urdf(path: Path, package_dirs: Sequence[str | Path]) -> UrdfFacts:
    """Read ``path``: resolve its meshes and list its mimic joints and unreadable inertials.

    Raises:
        xml.etree.ElementTree.ParseError: the file is not well-formed XML.
        OSError: the file cannot be read.
    """
    text = path.read_text()
    xml, missing = _resolved_meshes(text, path, package_dirs)
    root = ET.fromstring(text)
    live = {m.get("filename") for m in root.iter("mesh")}  # not those in comments
    missing = [uri for uri in missing if uri in live]
    dynamics, bad_limits, zero_limits = _joint_values(root)
    return UrdfFacts(
        xml=xml,
        missing_meshes=tuple(dict.fromkeys(missing)),
        mimics=tuple(_mimics(root)),
        bad_inertials=tuple(_bad_inertials(root)),
        duplicates=tuple(
            f"{kind} {n!r}"
            for kind in ("link", "joint")
            for n, k in Counter(e.get("name", "?") for e in root.findall(kind)).items()
            if k > 1
        ),
        zero_axes=tuple(_zero_axes(root)),
        bad_dynamics=tuple(dynamics),
        bad_limits=tuple(bad_limits),
        zero_limits=tuple(zero_limits),
    )


def _resolved_meshes(
    text: str, path: Path, package_dirs: Sequence[str | Path]
) -> tuple[str, list[str]]:
    """``text`` with its mesh filenames resolved (:func:`resolve_mesh`), and the URIs not
    found (those in comments included)."""
    missing: list[str] = []

    def _sub(m: re.Match[str]) -> str:
        found = resolve_mesh(m.group(3), path, package_dirs)
        if found is None:
            missing.append(m.group(3))
            return m.group(0)
        return f"{m.group(1)}{m.group(2)}{found}{m.group(2)}"

    return _MESH_ATTR.sub(_sub, text), missing


def _joint_values(
    root: ET.Element,
) -> tuple[list[tuple[str, str, str]], list[tuple[str, float, float]], list[str]]:
    """The top-level joints' ``<dynamics>`` values that are not numbers >= 0, their inverted
    ``<limit>`` ranges, and the revolute and prismatic joints whose limits are both 0."""
    dynamics: list[tuple[str, str, str]] = []
    bad_limits: list[tuple[str, float, float]] = []
    zero_limits: list[str] = []
    for joint in root.findall("joint"):
        name = joint.get("name", "?")
        tag = joint.find("dynamics")
        for attr in ("damping", "friction"):
            t = tag.get(attr) if tag is not None else None
            x = _number(t, 0.0)
            if x is None or x < 0:
                dynamics.append((name, attr, str(t)))
        limit = joint.find("limit")
        if limit is not None and joint.get("type") in ("revolute", "prismatic"):
            lower, upper = _number(limit.get("lower"), 0.0), _number(limit.get("upper"), 0.0)
            if lower is None or upper is None:
                continue  # urdfdom's own error names it
            if lower == upper == 0.0:
                zero_limits.append(name)
            elif lower >= upper:
                bad_limits.append((name, lower, upper))
    return dynamics, bad_limits, zero_limits


def _mimics(root: ET.Element) -> list[tuple[str, str, float, float]]:
    """``(joint, mimicked joint, multiplier, offset)`` of every ``<mimic>`` joint."""
    mimics = []
    for joint in root.iter("joint"):
        mimic = joint.find("mimic")
        if mimic is not None:
            mimics.append(
                (
                    joint.get("name", "?"),
                    mimic.get("joint", "?"),
                    _number(mimic.get("multiplier"), 1.0) or 0.0,
                    _number(mimic.get("offset"), 0.0) or 0.0,
                )
            )
    return mimics


def _bad_inertials(root: ET.Element) -> list[tuple[str, str]]:
    """``(link, what is wrong)`` of each ``<inertial>`` urdfdom would drop, garble or
    reduce to a point mass, and of each link with more than one."""
    bad: list[tuple[str, str]] = []
    for link in root.findall("link"):
        name = link.get("name", "?")
        inertials = link.findall("inertial")
        if len(inertials) > 1:
            bad.append((name, f"{len(inertials)} <inertial> elements: urdfdom keeps the first"))
        if not inertials:
            continue
        mass = inertials[0].find("mass")
        inertia = inertials[0].find("inertia")
        massless = "urdfdom drops the inertial (the link would be massless)"
        value = mass.get("value") if mass is not None else None
        if value is None or _number(value, 0.0) is None:
            text = "no mass value" if value is None else f"mass={value!r} is not a finite number"
            bad.append((name, f"<inertial> {text}: {massless}"))
            continue
        if inertia is None:
            bad.append((name, "<inertial> has no <inertia>: urdfdom keeps a point mass"))
            continue
        for attr in _INERTIA:
            t = inertia.get(attr)
            if t is None or _number(t, 0.0) is None:
                bad.append(
                    (
                        name,
                        f"<inertial> {attr}={t!r} is not a finite number: urdfdom drops or "
                        "garbles the inertial (a massless link or a point mass)",
                    )
                )
    return bad


def _zero_axes(root: ET.Element) -> list[str]:
    """The top-level revolute, continuous and prismatic joints whose ``<axis>`` is zero."""
    zero_axes = []
    for joint in root.findall("joint"):
        axis = joint.find("axis")
        if axis is not None and joint.get("type") in ("revolute", "continuous", "prismatic"):
            xyz = [_number(x, 0.0) for x in (axis.get("xyz") or "").split()]
            if len(xyz) == 3 and all(x == 0.0 for x in xyz):
                zero_axes.append(joint.get("name", "?"))
    return zero_axes

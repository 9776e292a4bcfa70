"""MJCF files: compiled by MuJoCo when it is installed, else read by Pinocchio's parser.

Through MuJoCo the model is built from the compiled model
(:mod:`pinobs.model.mjcf`).  Without it, Pinocchio's MJCF parser reads the file
and what it gets wrong is corrected here: the gravity of ``<option>`` and the
joint position limits as MuJoCo compiles them (:func:`_mjcf_limits`).
:func:`pinobs.load` calls :func:`load_mjcf` for every ``.xml``/``.mjcf`` file.
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from itertools import accumulate
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from pinobs.errors import GainError, ModelFileError, ModelWarning
from pinobs.model.mjcf import MujocoMap, build_from_mujoco

__all__ = ["load_mjcf"]


def load_mjcf(
    path: Path, joint_type: type | None, root_joint: str | None
) -> tuple[
    pin.Model, pin.GeometryModel | None, pin.GeometryModel | None, tuple[Any, MujocoMap] | None
]:
    """An MJCF model built from MuJoCo's compiled model, or from Pinocchio's parser without MuJoCo.

    Through MuJoCo (:mod:`pinobs.model.mjcf`) the root joint is the file's
    own (declare a ``<freejoint/>`` in it): a ``root_joint`` other than ``None``
    must name it (:class:`~pinobs.errors.GainError` otherwise), and the visual
    geometry is MuJoCo's primitive geoms (no meshes).  Without MuJoCo one
    :class:`~pinobs.errors.ModelWarning` says what Pinocchio's parser misses;
    its joint limits are corrected (:func:`_mjcf_limits`), and a ``root_joint``
    is added above a top body without joints (a :class:`~pinobs.errors.GainError`
    for one with joints, under which the parser would drop it).

    Returns:
        ``(model, visual geometry or None, None, (mj_model, map) or None)``: the last is
        MuJoCo's compiled model and the map its ``M(q)`` is cross-checked with
        (:func:`~pinobs.model.mjcf.cross_check`), ``None`` without MuJoCo.
    """
    try:
        import mujoco  # noqa: F401  (optional extra pinobs[mujoco])
    except ImportError:
        root = ET.parse(path).getroot()
        included = [e.get("file", "?") for e in root.iter("include")]
        if included:
            raise ModelFileError(
                f"{path} includes {', '.join(included)}, which Pinocchio's MJCF parser drops "
                "(their bodies would be missing); install MuJoCo (pip install 'pinobs[mujoco]') "
                "to load it"
            ) from None
        warnings.warn(
            f"{path}: MuJoCo is not installed (pip install 'pinobs[mujoco]'), so Pinocchio's "
            "MJCF parser reads the file: it ignores geom masses set in <default> classes "
            "(density is used instead), settotalmass and joint stiffness, keeps only the first "
            "body tree, and MuJoCo's M(q) cannot be cross-checked",
            ModelWarning,
            stacklevel=4,
        )
        if joint_type is not None:  # Pinocchio 4's buildModelFromMJCF(path, joint) is no more
            build = getattr(pin, "buildModelFromMJCFAndRootJoint", pin.buildModelFromMJCF)
            model = build(str(path), joint_type())
            if "root_joint" not in model.names:  # the parser drops it under a jointed top body
                raise GainError(
                    f"root_joint={root_joint!r}: Pinocchio's MJCF parser adds a root joint only "
                    f"under a top body without joints, and {path.name}'s has its own: leave out "
                    "root_joint, or install MuJoCo (pip install 'pinobs[mujoco]')"
                ) from None
        else:
            model = pin.buildModelFromMJCF(str(path))
        model.gravity = pin.Motion(_mjcf_gravity(root), np.zeros(3))  # the parser ignores it
        _mjcf_limits(root, model, path)  # the parser scales slide ranges, ignores limited
        try:
            visual = pin.buildGeomFromMJCF(model, str(path), pin.GeometryType.VISUAL)
        except (RuntimeError, ValueError):
            visual = None
        return model, visual, None, None
    model, mj, mapping, visual = build_from_mujoco(path)
    if root_joint is not None:
        own = _mjcf_roots(mj)
        if own != {root_joint}:
            how = {
                "freeflyer": "; to float it, declare <freejoint/> in its top body",
                "spherical": "; to pivot it, declare <joint type='ball'/> in its top body",
            }.get(root_joint, "")
            raise GainError(
                f"root_joint={root_joint!r}: an MJCF file loaded through MuJoCo keeps its own "
                f"root, and {path.name}'s is {' and '.join(sorted(own))}: leave out root_joint"
                + how
            )
    return model, visual, None, (mj, mapping)


def _mjcf_gravity(root: ET.Element) -> np.ndarray:
    """``<option gravity>`` (MuJoCo's default ``0 0 -9.81``), zero under ``<flag gravity="disable">``."""
    gravity, enabled = np.array([0.0, 0.0, -9.81]), True
    for option in root.iter("option"):
        if option.get("gravity") is not None:
            gravity = np.array([float(x) for x in option.get("gravity", "").split()])
            if gravity.shape != (3,):
                raise ValueError(f"<option gravity={option.get('gravity')!r}> is not 3 numbers")
        for flag in option.iter("flag"):
            enabled = flag.get("gravity", "enable" if enabled else "disable") == "enable"
    return gravity if enabled else np.zeros(3)


def _mjcf_joint_classes(root: ET.Element) -> dict[str, dict[str, str]]:
    """Joint attributes of each ``<default>`` class, inherited from the enclosing classes
    as MuJoCo does (``"main"``: the top-level default)."""
    classes: dict[str, dict[str, str]] = {"main": {}}

    def walk(default: ET.Element, inherited: dict[str, str]) -> None:
        attrs = dict(inherited)
        for joint in default.findall("joint"):
            attrs.update(joint.attrib)
        classes[default.get("class", "main")] = attrs
        for child in default.findall("default"):
            walk(child, attrs)

    for top in root.findall("default"):
        walk(top, {})
    return classes


def _mjcf_joint(
    attrs: dict[str, str], degree: bool, autolimits: bool
) -> tuple[str | None, int, tuple[float, float] | None]:
    """``(name, nq, limits)`` of a ``<joint>`` with these attributes (its class's and its own),
    as MuJoCo compiles it (:func:`_mjcf_limits`); ``limits`` ``None`` but for a hinge or a
    slide."""
    kind = attrs.get("type", "hinge")
    if kind not in ("hinge", "slide"):
        return attrs.get("name"), 7 if kind == "free" else 4, None
    scale = np.pi / 180.0 if kind == "hinge" and degree else 1.0
    ref = scale * float(attrs.get("ref", "0"))
    lo, hi = (scale * float(x) for x in attrs.get("range", "0 0").split())
    limited = attrs.get("limited", "auto")
    on = limited == "true" or (limited == "auto" and autolimits and "range" in attrs)
    big = np.finfo(float).max
    return attrs.get("name"), 1, (lo - ref, hi - ref) if on else (-big, big)


def _mjcf_joints(root: ET.Element) -> list[tuple[str | None, int, tuple[float, float] | None]]:
    """``(name, nq, limits)`` of every joint of the file's first body tree, in order, as
    MuJoCo compiles them (:func:`_mjcf_joint`; :func:`_mjcf_limits`)."""
    compiler: dict[str, str] = {}
    for el in root.iter("compiler"):
        compiler.update(el.attrib)
    degree = compiler.get("angle", "degree") != "radian"
    autolimits = compiler.get("autolimits", "true") == "true"
    classes = _mjcf_joint_classes(root)
    joints: list[tuple[str | None, int, tuple[float, float] | None]] = []

    def walk(body: ET.Element, childclass: str) -> None:
        childclass = body.get("childclass", childclass)
        for el in body:
            if el.tag == "freejoint":
                joints.append((el.get("name"), 7, None))
            elif el.tag == "joint":
                attrs = {**classes.get(el.get("class", childclass), {}), **el.attrib}
                joints.append(_mjcf_joint(attrs, degree, autolimits))
        for child in body.findall("body"):
            walk(child, childclass)

    worldbody = root.find("worldbody")
    first = worldbody.find("body") if worldbody is not None else None
    if first is not None:
        walk(first, "main")
    return joints


def _mjcf_limits(root: ET.Element, model: pin.Model, path: Path) -> None:
    """Hinge and slide position limits of a model from Pinocchio's MJCF parser, set in place
    to MuJoCo's (those the MuJoCo path gives: :mod:`pinobs.model.mjcf`).

    Pinocchio's parser (4.1) multiplies every joint ``range`` by π/180 under
    ``<compiler angle="degree">`` (MuJoCo's default), slide joints' too, whose
    range MuJoCo reads in metres (a slide ``range="-0.3 0.5"`` became ±0.005–0.009 m),
    and it limits a joint with a ``range`` whatever its ``limited`` says.  So the
    limits are read here from the file as MuJoCo compiles them: a joint's
    attributes are its ``class``'s (else the nearest ``childclass`` of its
    bodies', else the top-level ``<default>``'s) overridden by its own; it is
    limited when ``limited="true"``, or ``"auto"`` (the default) with a ``range``
    under ``autolimits`` (the default); a hinge's ``range`` and ``ref`` are in
    degrees unless ``angle="radian"``; ``q = qpos − ref`` (as the MuJoCo path),
    so the limits are ``range − ref``; an unlimited joint gets Pinocchio's "no
    limit" (±1.8e308).  Only the first body tree is read, as the parser does;
    if its joints do not line up with the model's ``q``, the parser's limits are
    kept and a :class:`~pinobs.errors.ModelWarning` says so.
    """
    joints = _mjcf_joints(root)
    offset = model.nq - sum(nq for _, nq, _ in joints)  # a root joint pinobs added comes first
    idx_q = list(accumulate((nq for _, nq, _ in joints), initial=offset))[:-1]
    lined_up = offset >= 0 and all(
        model.joints[model.getJointId(name)].idx_q == i
        for (name, _, _), i in zip(joints, idx_q, strict=True)
        if name is not None and model.existJointName(name)
    )
    if not lined_up:
        warnings.warn(
            f"{path}: the joints of its first body tree do not line up with the model Pinocchio's "
            "MJCF parser built, so its joint limits are the parser's (which scales slide ranges "
            "by π/180 under angle='degree' and ignores limited='false'); install MuJoCo "
            "(pip install 'pinobs[mujoco]') to load it",
            ModelWarning,
            stacklevel=5,
        )
        return
    lower = np.array(model.lowerPositionLimit, dtype=float)
    upper = np.array(model.upperPositionLimit, dtype=float)
    for (_, _, limits), i in zip(joints, idx_q, strict=True):
        if limits is not None:
            lower[i], upper[i] = limits
    model.lowerPositionLimit, model.upperPositionLimit = lower, upper


def _mjcf_roots(mj: Any) -> set[str]:
    """How the file's top bodies hang on the world, as ``root_joint`` names: ``"freeflyer"``
    (a free joint), ``"spherical"`` (a ball joint), ``"fixed"`` (welded or hinged)."""
    kinds = {0: "freeflyer", 1: "spherical"}  # mjtJoint free, ball
    return {
        kinds.get(int(mj.jnt_type[mj.body_jntadr[b]]), "fixed") if mj.body_jntnum[b] else "fixed"
        for b in range(1, mj.nbody)
        if mj.body_parentid[b] == 0
    } or {"fixed"}

"""What a URDF cannot hold, saved beside it: the rotor inertia (armature) per joint.

URDF has no tag for a drive's rotor inertia reflected through its reduction
(Pinocchio's ``model.armature``, which its CRBA and ABA add to ``M``'s diagonal), which
``pinobs.identify`` identifies.  :func:`~pinobs.model.urdf_writer.write_urdf` writes it
to a small JSON file beside the URDF, ``<name>.pinobs.json`` for ``<name>.urdf``
(:func:`sidecar_path`)::

    {"format": "pinobs-sidecar", "version": 1, "armature": {"elbow_joint": 0.25, ...}}

values in kg·m² (revolute) or kg (prismatic), a list of ``nv`` numbers for a joint of
several velocity coordinates, joints left out having none; and :func:`pinobs.load`
reads it when it is there.  Friction stays in the URDF (``<dynamics damping
friction>``) unless it is more than those tags say (an identified smoothing velocity, an
asymmetric Coulomb level, a Stribeck curve, an offset: :mod:`pinobs.model.friction`); then
the sidecar holds the whole law of each one-coordinate joint as well::

    "friction": {"elbow_joint": {"law": "stribeck", "viscous": 4.1, "coulomb_pos": 9.0,
                 "coulomb_neg": 9.0, "static": 11.2, "offset": 0.0, "smoothing": 0.02,
                 "stribeck_velocity": 0.05}, ...}

(:meth:`~pinobs.model.friction.FrictionLaw.as_dict`), which replaces the tags when the
robot is loaded with ``friction=True`` (the tags still hold ``F_v`` and the mean Coulomb
level, for other readers of the URDF).  An identified model also keeps its own acceleration
error as a white-noise density [rad²/s³] (:attr:`pinobs.model.Robot.model_error_psd`, what the
model-based observers take as their ``accel_psd`` when given none)::

    "model_error_psd": 0.0034

read back by :func:`read_model_error_psd`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from pinobs.errors import GainError, ModelFileError
from pinobs.model.friction import FrictionLaw

__all__ = [
    "SIDECAR_FORMAT",
    "SIDECAR_SUFFIX",
    "apply_sidecar",
    "read_friction_law",
    "read_model_error_psd",
    "sidecar_path",
    "write_sidecar",
]

#: What a URDF's sidecar is called: the URDF's name with this suffix instead of ``.urdf``.
SIDECAR_SUFFIX = ".pinobs.json"

#: The ``"format"`` field of a sidecar file.
SIDECAR_FORMAT = "pinobs-sidecar"


def sidecar_path(urdf: str | Path) -> Path:
    """The sidecar of a URDF: ``robot.urdf`` → ``robot.pinobs.json`` (beside it)."""
    path = Path(urdf)
    stem = path.name[: -len(path.suffix)] if path.suffix else path.name
    return path.with_name(stem + SIDECAR_SUFFIX)


def write_sidecar(
    model: pin.Model,
    urdf: str | Path,
    friction_law: FrictionLaw | None = None,
    model_error_psd: float | None = None,
) -> Path | None:
    """Write ``model``'s nonzero armature, ``friction_law`` when given and more than the
    URDF's tags say (:attr:`~pinobs.model.friction.FrictionLaw.is_urdf`) and
    ``model_error_psd`` when given, beside ``urdf``; returns the file, or ``None`` (and a stale
    sidecar from an earlier write removed) when there is nothing to write."""
    path = sidecar_path(urdf)
    laws: dict[str, Any] = {}
    if friction_law is not None and not friction_law.is_urdf:
        for i in range(1, model.njoints):
            joint = model.joints[i]
            if joint.nv == 1:  # (the law per coordinate; a multi-dof joint keeps the tags')
                laws[str(model.names[i])] = friction_law.as_dict(joint.idx_v)
    armature = np.asarray(model.armature, dtype=float)
    entries: dict[str, Any] = {}
    for i in range(1, model.njoints):
        joint = model.joints[i]
        if joint.nv == 0:
            continue
        values = armature[joint.idx_v : joint.idx_v + joint.nv]
        if np.any(values != 0.0):
            entries[str(model.names[i])] = (
                float(values[0]) if joint.nv == 1 else [float(x) for x in values]
            )
    if not entries and not laws and model_error_psd is None:
        path.unlink(missing_ok=True)  # an earlier model's armature would be read back
        return None
    content: dict[str, Any] = {"format": SIDECAR_FORMAT, "version": 1, "armature": entries}
    if laws:
        content["friction"] = laws
    if model_error_psd is not None:
        content["model_error_psd"] = float(model_error_psd)
    text = json.dumps(content, indent=2)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def apply_sidecar(model: pin.Model, urdf: str | Path) -> Path | None:
    """Set ``model.armature`` from the sidecar beside ``urdf`` when there is one (joints it
    does not name keep theirs); returns the file read, or ``None``.

    Raises:
        ModelFileError: the sidecar cannot be parsed, names a joint the model does not have
            (listing those it has), or gives a value that is not a finite number ≥ 0 per
            velocity coordinate of its joint.
    """
    path = sidecar_path(urdf)
    data = _read(path)
    if data is None:
        return None
    entries = data.get("armature", {})
    if not isinstance(entries, dict):
        raise ModelFileError(f'sidecar {str(path)!r}: "armature" must map joint names to values')
    names = [str(model.names[i]) for i in range(1, model.njoints) if model.joints[i].nv > 0]
    armature = np.array(model.armature, dtype=float)
    for name, value in entries.items():
        if name not in names:
            raise ModelFileError(
                f"sidecar {str(path)!r} gives an armature for joint {name!r}, which the robot "
                f"does not have; its moving joints: {', '.join(names)}"
            )
        joint = model.joints[model.getJointId(name)]
        values = [value] if joint.nv == 1 and not isinstance(value, list) else value
        if not isinstance(values, list) or len(values) != joint.nv:
            raise ModelFileError(
                f"sidecar {str(path)!r}: joint {name!r} has {joint.nv} velocity coordinate(s); "
                f"give as many armature values, got {value!r}"
            )
        for x in values:
            ok = isinstance(x, int | float) and not isinstance(x, bool)
            if not ok or not math.isfinite(x) or x < 0:
                raise ModelFileError(
                    f"sidecar {str(path)!r}: armature {x!r} of joint {name!r} must be a "
                    "finite number ≥ 0 [kg·m² or kg]"
                )
        armature[joint.idx_v : joint.idx_v + joint.nv] = values
    model.armature = armature
    return path


def _read(path: Path) -> dict[str, Any] | None:
    """The parsed sidecar at ``path``, or ``None`` when there is none."""
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelFileError(f"cannot parse the sidecar {str(path)!r}: {exc}") from exc
    if not isinstance(data, dict) or data.get("format") != SIDECAR_FORMAT:
        raise ModelFileError(
            f'{str(path)!r} is not a pinobs sidecar (no "format": "{SIDECAR_FORMAT}"); '
            "move it away or rename it"
        )
    return data


def read_friction_law(
    model: pin.Model, urdf: str | Path, *, locked: frozenset[str] = frozenset()
) -> FrictionLaw | None:
    """The friction law of the sidecar beside ``urdf``, on ``model``'s coordinates, or
    ``None`` when there is no sidecar or it has no ``"friction"``.

    Coordinates it does not name keep the URDF tags' law
    (:meth:`~pinobs.model.friction.FrictionLaw.from_urdf` of ``model.damping``,
    ``model.friction``); joints in ``locked`` (fixed by ``pinobs.load(..., lock=...)``)
    are skipped.

    Raises:
        ModelFileError: the sidecar cannot be parsed, names a joint the model does not have
            (listing those it has), or gives an entry that is not a valid law.
    """
    path = sidecar_path(urdf)
    data = _read(path)
    if data is None or "friction" not in data:
        return None
    entries = data["friction"]
    if not isinstance(entries, dict):
        raise ModelFileError(f'sidecar {str(path)!r}: "friction" must map joint names to laws')
    names = [str(model.names[i]) for i in range(1, model.njoints) if model.joints[i].nv == 1]
    law = FrictionLaw.from_urdf(model.damping, model.friction)
    labels = set()
    for name, entry in entries.items():
        if name in locked:
            continue
        if name not in names:
            raise ModelFileError(
                f"sidecar {str(path)!r} gives a friction law for joint {name!r}, which the "
                f"robot does not have; its one-coordinate joints: {', '.join(names)}"
            )
        if not isinstance(entry, dict):
            raise ModelFileError(f"sidecar {str(path)!r}: joint {name!r}'s friction {entry!r}")
        try:
            law = law.with_coordinate(model.joints[model.getJointId(name)].idx_v, entry)
        except GainError as exc:
            raise ModelFileError(f"sidecar {str(path)!r}, joint {name!r}: {exc}") from exc
        labels.add(str(entry.get("law", "")))
    return FrictionLaw(
        **{k: getattr(law, k) for k in law.__dataclass_fields__ if k != "law"},
        law=labels.pop() if len(labels) == 1 else "mixed",
    )


def read_model_error_psd(urdf: str | Path) -> float | None:
    """The ``"model_error_psd"`` [rad²/s³] of the sidecar beside ``urdf``, or ``None`` when
    there is no sidecar or it has none.

    Raises:
        ModelFileError: the sidecar cannot be parsed, or its value is not a finite number > 0.
    """
    path = sidecar_path(urdf)
    data = _read(path)
    if data is None or "model_error_psd" not in data:
        return None
    x = data["model_error_psd"]
    ok = isinstance(x, int | float) and not isinstance(x, bool)
    if not ok or not math.isfinite(x) or x <= 0:
        raise ModelFileError(
            f"sidecar {str(path)!r}: model_error_psd {x!r} must be a finite number > 0 [rad²/s³]"
        )
    return float(x)

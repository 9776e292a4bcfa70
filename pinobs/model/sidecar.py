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
friction>``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from pinobs.errors import ModelFileError

__all__ = ["SIDECAR_FORMAT", "SIDECAR_SUFFIX", "apply_sidecar", "sidecar_path", "write_sidecar"]

#: What a URDF's sidecar is called: the URDF's name with this suffix instead of ``.urdf``.
SIDECAR_SUFFIX = ".pinobs.json"

#: The ``"format"`` field of a sidecar file.
SIDECAR_FORMAT = "pinobs-sidecar"


def sidecar_path(urdf: str | Path) -> Path:
    """The sidecar of a URDF: ``robot.urdf`` → ``robot.pinobs.json`` (beside it)."""
    path = Path(urdf)
    stem = path.name[: -len(path.suffix)] if path.suffix else path.name
    return path.with_name(stem + SIDECAR_SUFFIX)


def write_sidecar(model: pin.Model, urdf: str | Path) -> Path | None:
    """Write ``model``'s nonzero armature beside ``urdf``; returns the file, or ``None``
    (and a stale sidecar from an earlier write removed) when the model has none."""
    path = sidecar_path(urdf)
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
    if not entries:
        path.unlink(missing_ok=True)  # an earlier model's armature would be read back
        return None
    text = json.dumps({"format": SIDECAR_FORMAT, "version": 1, "armature": entries}, indent=2)
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

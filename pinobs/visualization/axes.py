"""What the velocity axes of the plots and of the playback chart say: names, units, ranges.

Shared by :mod:`pinobs.visualization.plots` (matplotlib) and the chart of
:func:`pinobs.visualization.write_html` (plain JavaScript), so both show the
same labels, units and y-ranges.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from pinobs.model import Robot
from pinobs.model.robot import Vector

__all__ = ["clip_start", "slide_axis", "velocity_labels", "velocity_range", "velocity_units"]

_COMPONENTS = {
    "so3": ("ωx", "ωy", "ωz"),
    "se3": ("vx", "vy", "vz", "ωx", "ωy", "ωz"),
    "se2": ("vx", "vy", "ω"),
}


def velocity_labels(robot: Robot) -> list[str]:
    """One label per velocity coordinate: the joint name, with the component for multi-DOF joints."""
    labels = [""] * robot.nv
    for j in robot.joints:
        comps = _COMPONENTS.get(j.kind)
        for k in range(j.nv):
            if j.nv == 1:
                labels[j.idx_v] = j.name
            else:
                comp = comps[k] if comps is not None and k < len(comps) else str(k)
                labels[j.idx_v + k] = f"{j.name} {comp}"
    return labels


def slide_axis(model: pin.Model, joint_id: int) -> Vector | None:
    """Unit axis, in the joint's frame, of a joint that only slides (prismatic: Pinocchio's
    ``PX``, ``PY``, ``PZ`` and unaligned joints), or ``None`` for any other joint.

    Read from the joint's motion subspace ``S`` (one column, no angular part), so every
    prismatic joint model counts.
    """
    joint = model.joints[joint_id]
    if joint.nv != 1:
        return None
    jdata = joint.createData()
    joint.calc(jdata, pin.neutral(model))
    S = np.asarray(jdata.S, dtype=float).reshape(6, -1)[:, 0]  # [linear; angular]
    linear = float(np.linalg.norm(S[:3]))
    if linear == 0.0 or np.any(S[3:] != 0.0):
        return None
    return S[:3] / linear


def velocity_units(robot: Robot) -> list[str]:
    """Unit of each velocity coordinate: ``"m/s"`` (prismatic joints, linear parts of
    free-flyer and planar joints) or ``"rad/s"`` (everything that turns)."""
    units = ["rad/s"] * robot.nv
    for j in robot.joints:
        if j.kind in ("se3", "se2"):
            for k in range(3 if j.kind == "se3" else 2):
                units[j.idx_v + k] = "m/s"
        elif slide_axis(robot.model, robot.model.getJointId(j.name)) is not None:
            units[j.idx_v] = "m/s"
    return units


def velocity_range(
    t: ArrayLike, truth: ArrayLike, estimates: Sequence[ArrayLike], start: float
) -> tuple[float, float]:
    """y-range of one velocity axis: the truth over the whole run and the estimates from
    ``start`` on [s], plus a 10 % margin (same unit as the curves).

    An estimate's start transient (a perturbed start converging) is often far
    larger than the motion; leaving it out keeps the motion readable.  Curves
    beyond the range are clipped, and the caller says so.  NaN samples are
    ignored.

    Args:
        t: sample times [s], shape ``(n,)``.
        truth: true velocity, shape ``(n,)``.
        estimates: estimated velocities, each of shape ``(n,)``.
        start: time from which the estimates count [s].
    """
    t = np.asarray(t, dtype=float)
    late = t >= start
    y = np.concatenate(
        [np.asarray(truth, dtype=float).ravel()]
        + [np.asarray(e, dtype=float).ravel()[late] for e in estimates]
    )
    y = y[np.isfinite(y)]
    if y.size == 0:
        return -1.0, 1.0
    lo, hi = float(y.min()), float(y.max())
    pad = 0.1 * (hi - lo) if hi > lo else max(0.1 * abs(hi), 1e-3)
    return lo - pad, hi + pad


def clip_start(t: ArrayLike, convergence_times: Sequence[float]) -> float:
    """Where the estimates start to count for the y-range [s]: the slowest finite convergence
    time (:func:`pinobs.evaluation.convergence_time`), at most the middle of the run."""
    t = np.asarray(t, dtype=float)
    finite = [c for c in convergence_times if math.isfinite(c)]
    middle = float(t[0] + 0.5 * (t[-1] - t[0]))
    return min(max(finite, default=float(t[0])), middle)

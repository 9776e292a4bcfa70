"""What a legged log's IMU and contacts say against the model (issue 38, bad input).

Two checks after :func:`~pinobs.io.legged_run.legged_run` has the contact flags, each a
warning in the run's warnings (``pinobs estimate`` prints them):

* **The IMU's frame** (:func:`frame_notes`).  On a row where some feet touch the ground,
  the feet's centroid ``c`` (from the joint angles, in the IMU frame:
  ``FootKinematics.positions_and_jacobians``) lies below the IMU, and the accelerometer,
  averaged over such rows, reads gravity's reaction, up (``Rᵀ(0, 0, g)`` at rest: the
  trunk's own accelerations average out over a stance or a gait).  So the angle

      θ = ∠(ā, −c̄),   ā = mean acc,   c̄ = mean over the rows of c / |c|,

  is the trunk's mean tilt from the ground plane plus the feet's offset from below the
  IMU: measured 15.5° on SEROW's real Go1 log, 13.3–13.7° on the MuJoCo go1 standing,
  swaying and trotting (3 s, seed 0; go1's ``imu_link`` is 7 cm ahead of the root, the
  feet's centroid behind it), 0.8–1.3° on TALOS standing and stepping (IMU at the base);
  the go1 log with its IMU's x and z axes swapped gives 97°
  (``tests/io/test_legged_checks.py``).  Above :data:`FRAME_ANGLE` it is said, with θ.
  Not seen here: a rotation of the IMU about the vertical (its accelerometer still reads
  up), a gyro in another frame than the accelerometer.
* **Contacts never set** (:func:`contact_notes`): no foot in contact on any row, so the
  filter integrated the IMU alone: said with the force columns' largest value (a
  threshold above every force, or forces in other units).
"""

from __future__ import annotations

import math

import numpy as np

from pinobs.io.readers import Log
from pinobs.model.robot import Vector

__all__ = ["FRAME_ANGLE", "contact_notes", "frame_notes"]

#: Above this angle [°] between the accelerometer's up and the legs' up, the IMU's frame is
#: said to be in doubt (module docstring).
FRAME_ANGLE = 45.0
#: The check reads at most this many rows with a foot in contact, evenly spread.
FRAME_ROWS = 400


def frame_notes(kinematics: object, log: Log, flags: np.ndarray, imu_frame: str) -> list[str]:
    """The IMU's frame against the legs (module docstring): one line if ``θ > FRAME_ANGLE``.

    Args:
        kinematics: the filter's (``positions_and_jacobians(q_joints)``: feet in the IMU frame,
            in the order of ``flags``' columns).
        log: the log (``q[:, 7:]`` the joints, ``imu_acc``).
        flags: contact flags ``(N, feet)``.
        imu_frame: the frame's name, for the message.
    """
    acc = log.imu_acc
    if acc is None or not flags.size:
        return []
    joints = log.q[:, 7:]
    rows = np.flatnonzero(
        flags.any(axis=1) & np.isfinite(acc).all(axis=1) & np.isfinite(joints).all(axis=1)
    )
    if rows.size == 0:
        return []
    rows = rows[np.linspace(0, rows.size - 1, min(FRAME_ROWS, rows.size)).astype(int)]
    down = np.zeros(3)
    for k in rows:
        c = _feet(kinematics, joints[k])[flags[k]].mean(axis=0)
        down += c / max(float(np.linalg.norm(c)), 1e-12)
    up = np.mean(acc[rows], axis=0)
    theta = _angle(up, -down)
    if not theta > FRAME_ANGLE:  # (nan: a zero mean, nothing to say)
        return []
    return [
        f"the accelerometer's mean reading over {rows.size} rows with a foot on the ground "
        f"points {theta:.0f}° from the legs' up (the feet below the IMU, from the joint "
        f"angles): the IMU's axes look like they are not those of frame {imu_frame!r} "
        "(--imu-frame, or the columns' axes swapped or flipped); the base attitude, its "
        "velocity and the feet's measurements are then wrong"
    ]


def contact_notes(flags: np.ndarray, log: Log) -> list[str]:
    """One line if no foot is in contact on any row (module docstring)."""
    if not flags.size or flags.any():
        return []
    if log.foot_force is not None and np.isfinite(log.foot_force).any():
        peak = float(np.nanmax(log.foot_force))
        why = f"the force columns peak at {peak:.4g} N, below the contact threshold"
    else:
        why = "the contact columns are 0 on every row"
    return [
        f"no foot is in contact on any row ({why}): the filter integrated the IMU alone and "
        "its velocity and position drift; give the threshold in the force columns' units "
        "(--contact-force ON [OFF]) or contact.<foot> flags"
    ]


def _feet(kinematics: object, q_joints: Vector) -> Vector:
    """The feet's positions in the IMU frame ``(K, 3)``: ``FootKinematics.positions`` (no
    Jacobians), else the first of ``positions_and_jacobians`` (a ``ContactKinematics``)."""
    positions = getattr(kinematics, "positions", None)
    if positions is not None:
        return positions(q_joints)  # type: ignore[no-any-return]
    return kinematics.positions_and_jacobians(q_joints)[0]  # type: ignore[attr-defined,no-any-return]


def _angle(a: Vector, b: Vector) -> float:
    """The angle between ``a`` and ``b`` [°] (``nan`` if one is zero)."""
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    if na == 0.0 or nb == 0.0:
        return math.nan
    return math.degrees(math.acos(max(-1.0, min(1.0, float(a @ b) / (na * nb)))))

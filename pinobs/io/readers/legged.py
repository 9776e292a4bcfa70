"""Legged-robot columns of a table log: the trunk IMU, foot forces or contact flags.

Columns (CSV, TSV, Parquet, DataFrame), beside ``t`` and the joints' ``q.<joint>``:

- ``imu.gyro.x|y|z``: angular velocity [rad/s] and ``imu.acc.x|y|z``: specific force
  [m/s²] (what an accelerometer measures: ``Rᵀ(p̈ − g)``, +9.81 up at rest), in the IMU's
  frame; all six or none;
- ``force.<foot frame>``: the normal force on that foot [N], or ``contact.<foot frame>``:
  whether it touches the ground (0 or 1); each foot a frame of the model.

A robot with a free-flyer root whose log has the IMU columns but no base pose
(``q.root_joint.*``, ``q0..q6``) is read with that block NaN: legged robots do not
measure it; an observer that estimates the base from the IMU and the legs fills it.

Checks on the first chunk (warnings, :class:`~pinobs.errors.SensorWarning`, and said in
:attr:`Log.notes`): an accelerometer whose mean norm is near 1 (it reads in g, not
m/s²: ``|mean acc|`` ≈ 9.81 m/s² whenever the trunk's mean acceleration is small), a
gyro above ``GYRO_LIMIT`` (most MEMS gyros saturate at ±2000 °/s = 34.9 rad/s: larger
values are deg/s).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from pinobs.errors import DimensionError, LogFormatError, SensorWarning
from pinobs.model import Robot
from pinobs.model.robot import Vector

GYRO = ("imu.gyro.x", "imu.gyro.y", "imu.gyro.z")
ACC = ("imu.acc.x", "imu.acc.y", "imu.acc.z")
#: Above this, a gyro column is taken for deg/s [rad/s] (±2000 °/s, a MEMS gyro's range).
GYRO_LIMIT = 35.0
#: Standard gravity [m/s²].
G = 9.80665
#: ``|mean acc|`` within this band [m/s²] reads as an accelerometer in g.
G_UNITS_BAND = (0.5, 2.0)


@dataclass(frozen=True)
class LeggedColumns:
    """The legged columns a table has (``()`` where it has none)."""

    gyro: tuple[str, ...] = ()
    acc: tuple[str, ...] = ()
    feet: tuple[str, ...] = ()
    force: tuple[str, ...] = ()  # force.<foot>, one per foot, or ()
    contact: tuple[str, ...] = ()  # contact.<foot>, one per foot, or ()

    @property
    def used(self) -> list[str]:
        return [*self.gyro, *self.acc, *self.force, *self.contact]

    @property
    def imu(self) -> bool:
        return bool(self.gyro)


def _imu_columns(names: set[str], where: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``imu.gyro.*`` and ``imu.acc.*``: all six or none; anything else under ``imu.`` refused."""
    given = sorted(c for c in names if c.startswith("imu."))
    if not given:
        return (), ()
    unknown = [c for c in given if c not in GYRO + ACC]
    if unknown:
        raise DimensionError(
            f"{where}: columns {unknown} are not IMU columns pinobs reads; they are "
            f"{list(GYRO + ACC)} (gyro [rad/s], specific force [m/s²])"
        )
    lacking = [c for c in GYRO + ACC if c not in names]
    if lacking:
        raise DimensionError(
            f"{where}: has IMU columns {given} but lacks {lacking}; give all of "
            f"{list(GYRO + ACC)} (or none)"
        )
    return GYRO, ACC


def _foot_columns(
    names: Sequence[str], robot: Robot, where: str
) -> tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...]]:
    """``(feet, force columns, contact columns)``; every foot a frame of the model."""
    force = [c for c in names if c.startswith("force.")]
    contact = [c for c in names if c.startswith("contact.")]
    frames = [f.name for f in robot.model.frames]
    for col in force + contact:
        foot = col.split(".", 1)[1]
        if foot not in frames:
            feet_like = [f for f in frames if "foot" in f.lower()] or frames
            raise DimensionError(
                f"{where}: column {col!r} names foot frame {foot!r}, which robot "
                f"{robot.name!r} does not have; its frames include {feet_like}"
            )
    f_feet = [c.split(".", 1)[1] for c in force]
    c_feet = [c.split(".", 1)[1] for c in contact]
    if force and contact and sorted(f_feet) != sorted(c_feet):
        raise DimensionError(
            f"{where}: force columns for feet {f_feet} and contact columns for {c_feet}: "
            "give both for the same feet, or one kind"
        )
    feet = tuple(f_feet or c_feet)
    return (
        feet,
        tuple(f"force.{f}" for f in feet) if force else (),
        tuple(f"contact.{f}" for f in feet) if contact else (),
    )


def legged_columns(header: Sequence[str], robot: Robot, where: str) -> LeggedColumns:
    """The legged columns of ``header`` (module docstring); refused naming what is wrong."""
    gyro, acc = _imu_columns(set(header), where)
    feet, force, contact = _foot_columns(header, robot, where)
    return LeggedColumns(gyro, acc, feet, force, contact)


def free_flyer_root(robot: Robot) -> str | None:
    """The name of the robot's free-flyer root joint, or ``None``."""
    first = robot.joints[0] if robot.joints else None
    return first.name if first is not None and first.kind == "se3" else None


@dataclass(frozen=True)
class LeggedArrays:
    """The legged arrays of a chunk (``None`` where the log has none)."""

    imu_gyro: Vector | None = None
    imu_acc: Vector | None = None
    foot_force: Vector | None = None
    contact: Vector | None = None
    feet: tuple[str, ...] = ()


def legged_arrays(
    arrays: Mapping[str, Vector],
    n: int,
    cols: LeggedColumns | None,
    lines: Sequence[int],
    unit: str,
) -> LeggedArrays:
    """The chunk's IMU and foot arrays; a contact flag other than 0, 1 (or empty) refused."""
    if cols is None:
        return LeggedArrays()

    def stack(names: tuple[str, ...]) -> Vector | None:
        if not names:
            return None
        return np.column_stack([arrays[c] for c in names]).reshape(n, len(names))

    contact = stack(cols.contact)
    if contact is not None:
        bad = np.flatnonzero(~(np.isnan(contact) | (contact == 0) | (contact == 1)).all(axis=1))
        if bad.size:
            row = int(bad[0])
            col = next(c for k, c in enumerate(cols.contact) if contact[row, k] not in (0.0, 1.0))
            raise LogFormatError(
                f"column {col!r}, {unit} {int(lines[row])}: {float(arrays[col][row])!r} is not a contact "
                "flag (0 or 1); a force [N] is a force.<foot> column"
            )
    return LeggedArrays(stack(cols.gyro), stack(cols.acc), stack(cols.force), contact, cols.feet)


def unit_notes(gyro: Vector | None, acc: Vector | None) -> list[str]:
    """What the IMU's values say of its units (module docstring), one line per suspicion."""
    notes = []
    if acc is not None and np.isfinite(acc).any():
        mean = float(np.linalg.norm(np.nanmean(acc, axis=0)))
        if G_UNITS_BAND[0] < mean < G_UNITS_BAND[1]:
            notes.append(
                f"columns {list(ACC)}: |mean| = {mean:.3g}, near 1 rather than {G:.2f} m/s²: "
                f"the accelerometer looks like it reads in g; multiply it by {G} "
                "(specific force in m/s² is read)"
            )
    if gyro is not None and np.isfinite(gyro).any():
        peak = float(np.nanmax(np.abs(gyro)))
        if peak > GYRO_LIMIT:
            k = int(np.nanargmax(np.nanmax(np.abs(gyro), axis=0)))
            notes.append(
                f"column {GYRO[k]!r}: |ω| up to {peak:.4g}, above {GYRO_LIMIT} rad/s (a "
                "±2000 °/s gyro's range): it looks like deg/s; multiply it by π/180"
            )
    for note in notes:
        warnings.warn(note, SensorWarning, stacklevel=4)
    return notes


def legged_notes(
    robot: Robot, q: Vector, gyro: Vector | None, acc: Vector | None
) -> tuple[str, ...]:
    """What is said of a legged log as a whole, from its first chunk: its units
    (:func:`unit_notes`) and a base pose not in it."""
    if gyro is None and acc is None:
        return ()
    notes = unit_notes(gyro, acc)
    root = free_flyer_root(robot)
    if root is not None and q.shape[0] and np.isnan(q[:, :7]).all():
        notes.append(
            f"the base pose ({root}, q0..q6) is not in the log: read as NaN; an observer "
            "that estimates the base from the IMU and the legs fills it, a joint observer "
            "sees every row as a dropped sample: run it on the legs alone, "
            f"pinobs.load({robot.name!r}, root_joint='fixed') (--root-joint fixed)"
        )
    return tuple(notes)

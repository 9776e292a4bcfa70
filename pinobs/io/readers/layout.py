"""Where the robot's ``t``, ``q`` and ``tau`` are among a table's columns (CSV, Parquet,
DataFrame): names matched to the joints, what is missing said."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pinobs.errors import DimensionError, OptionError
from pinobs.io.drives import Drives
from pinobs.io.readers.legged import LeggedColumns, free_flyer_root, legged_columns
from pinobs.model import Robot


@dataclass(frozen=True)
class Layout:
    """Where the robot's ``t``, ``q`` and ``tau`` are among a table's columns."""

    t: str | None  # None: no t column, the rows sampled at ``rate``
    q: tuple[tuple[str, ...], ...]  # per q block: its columns (one angle column for a circle)
    q_angle: tuple[bool, ...]  # per q block: given as an angle
    q_slices: tuple[slice, ...]
    tau: tuple[str, ...] | None
    tick: str | None = None  # the log's own sample counter (pinobs.io.clock)
    drives: Drives | None = None  # how motor-side columns map to the joints (pinobs.io.drives)
    motor: tuple[str, ...] = ()  # qm.<joint> per joint: positions from the motors (drives)
    current: tuple[str, ...] = ()  # i.<joint> per joint: torques from the currents (drives)
    legged: LeggedColumns | None = None  # IMU, foot forces or contacts (readers.legged)
    rate: float | None = None  # [Hz] with no t column: row k at t = k / rate

    @property
    def used(self) -> list[str]:
        cols = [*(c for block in self.q for c in block), *self.motor, *self.current]
        cols = ([self.t] if self.t is not None else []) + cols
        legged = self.legged.used if self.legged is not None else []
        return cols + list(self.tau or ()) + ([self.tick] if self.tick else []) + legged


def joint_blocks(robot: Robot) -> list[tuple[str, str, int, int, int, int]]:
    """``(name, kind, idx_q, nq, idx_v, nv)`` of every joint."""
    return [(b.name, b.kind, b.idx_q, b.nq, b.idx_v, b.nv) for b in robot.joints]


def motor_layout(
    header: Sequence[str], robot: Robot, where: str, drives: Drives | None
) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The ``qm.<joint>`` and ``i.<joint>`` columns (:mod:`pinobs.io.drives`) read through
    ``drives``: each all or none; a column ``drives`` cannot read, or drives the log does not
    use, refused naming them."""
    names = set(header)
    found = {}
    for kind, what in (("qm", "motor position"), ("i", "motor current")):
        want = [f"{kind}.{n}" for n in robot.joint_names]
        have = [c for c in want if c in names]
        if have and drives is not None and len(have) < len(want):
            raise DimensionError(
                f"{where}: has {what} columns {have} but lacks "
                f"{[c for c in want if c not in names]}: give one per joint"
            )
        found[kind] = tuple(have)
    if drives is None:
        return (), ()
    drives.check(robot)
    motor, current = found["qm"], found["i"]
    q_too = [f"q.{n}" for n in robot.joint_names if f"q.{n}" in names] if motor else []
    tau_too = [f"tau.{n}" for n in robot.joint_names if f"tau.{n}" in names] if current else []
    if q_too or tau_too:
        raise DimensionError(
            f"{where}: has both {list(q_too or tau_too)} and "
            f"{list(motor if q_too else current)}: the joint's own and the motor's; keep one "
            "(drop or rename the other)"
        )
    unused = _unused_drives(drives, header, motor, current)
    if unused:
        raise OptionError(f"{where}: drives given but not used: {'; '.join(unused)}")
    if current:
        drives.joint_torques(np.zeros((0, robot.nv)))  # refuses a missing constant or ratio
    if motor:
        drives.joint_positions(np.zeros((0, robot.nv)))
    return motor, current


def _unused_drives(
    drives: Drives, header: Sequence[str], motor: tuple[str, ...], current: tuple[str, ...]
) -> list[str]:
    """The parts of ``drives`` a log with these ``motor`` position and ``current`` columns
    does not use, each with why."""
    unused = []
    if drives.matrix is not None and not (motor or current):
        unused.append("gear_ratio or transmission (no qm.<joint> or i.<joint> columns)")
    if drives.motor_constant is not None and not current:
        unused.append("motor_constant (no i.<joint> current columns)")
    if drives.position_offset is not None and not motor:
        unused.append("position_offset (no qm.<joint> motor position columns)")
    if drives.torque_scale is not None and (
        current or not any(c.startswith("tau") for c in header)
    ):
        unused.append(
            "torque_scale (it scales tau.<joint> columns; "
            + ("currents take motor_constant)" if current else "the log has none)")
        )
    return unused


class _Picker:
    """The one column among candidate names that gives a value, refused when several do."""

    def __init__(self, header: Sequence[str], where: str) -> None:
        self.names = set(header)
        self.counts = Counter(header)
        self.where = where

    def one(self, candidates: list[str], what: str) -> str | None:
        found = [c for c in candidates if c in self.names]
        if len(found) > 1:
            raise DimensionError(f"{self.where}: columns {found} all give {what}; keep one")
        if found and self.counts[found[0]] > 1:  # (the first was used, silently)
            raise DimensionError(
                f"{self.where}: {self.counts[found[0]]} columns are named {found[0]!r} (after "
                "columns=..., if given); keep one"
            )
        return found[0] if found else None


@dataclass
class _QColumns:
    """Per joint: its q columns, whether given as one angle, its slice of q; what is missing."""

    cols: list[tuple[str, ...]] = field(default_factory=list)
    angle: list[bool] = field(default_factory=list)
    slices: list[slice] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)  # the columns lacking, as said
    absent: list[str] = field(default_factory=list)  # joints with a q column missing


def _q_columns(
    pick: _Picker, robot: Robot, motor: tuple[str, ...], unmeasured: str | None = None
) -> _QColumns:
    """Each joint's ``q<k>`` or ``q.<joint>[.<k>]`` columns (or one angle of a circle); the
    joint ``unmeasured`` (a legged robot's free-flyer root) may have none: read as NaN."""
    out = _QColumns()
    for name, kind, iq, nq, _, _ in joint_blocks(robot):
        out.slices.append(slice(iq, iq + nq))
        if motor:  # every q from the motors (drives)
            out.cols.append(())
            out.angle.append(kind == "circle")
            continue
        cols: list[str] = []
        for k in range(nq):
            named = f"q.{name}" if nq == 1 else f"q.{name}.{k}"
            cols.append(pick.one([f"q{iq + k}", named], f"q{iq + k}") or "")
        if all(cols):
            out.cols.append(tuple(cols))
            out.angle.append(False)
        elif name == unmeasured and not any(cols):
            out.cols.append(())  # NaN (from_arrays)
            out.angle.append(False)
        elif kind == "circle" and not any(cols) and f"q.{name}" in pick.names:
            out.cols.append((f"q.{name}",))
            out.angle.append(True)
        else:
            out.missing += [
                f"q{iq + k} or q.{name}" + ("" if nq == 1 else f".{k}")
                for k, c in enumerate(cols)
                if not c
            ]
            out.absent.append(name)
            out.cols.append(tuple(cols))
            out.angle.append(False)
    return out


def _refuse_beyond(header: Sequence[str], robot: Robot, where: str) -> None:
    """Positional columns past the robot's nq, nv: another robot's log."""
    beyond = [
        c
        for c in header
        for kind, n in (("q", robot.nq), ("tau", robot.nv))
        if c.startswith(kind) and c[len(kind) :].isdigit() and int(c[len(kind) :]) >= n
    ]
    if beyond:  # another robot's log (or this one loaded without its root joint)
        raise DimensionError(
            f"{where}: columns {beyond} are beyond robot {robot.name!r}'s nq = {robot.nq}, "
            f"nv = {robot.nv}: the log of another robot, or a floating base loaded fixed "
            "(root_joint=...)? Drop or rename them (columns=...) if they are not its own"
        )


def _refuse_missing(
    header: Sequence[str],
    robot: Robot,
    where: str,
    t: str | None,
    q: _QColumns,
    motor: bool,
    rate: float | None = None,
) -> str | None:
    """``t`` (``None``: no t column, the rows sampled at ``rate``); refused when some joint's
    q columns are missing, or ``t`` without a ``rate``, saying what the robot needs."""
    if (t is not None or rate is not None) and not q.missing:
        return t
    lack = (["t"] if t is None and rate is None else []) + q.missing
    motor_only = [c for c in header if c.startswith("qm.")] if q.missing and not motor else []
    partial = bool(q.absent) and len(q.absent) < len(robot.joints)
    lock = lock_hint(q.absent, robot.joint_names) if partial else ""
    if motor_only:
        lock += (
            f". Columns {motor_only} are motor positions: read them through the drives "
            "(drives=pinobs.io.Drives(gear_ratio=...), --gear-ratio or --transmission)"
        )
    raise DimensionError(
        f"{where}: columns {list(header)} lack {lack}; "
        f"robot {robot.name!r} needs t, then q0..q{robot.nq - 1} (nq = {robot.nq}) or "
        + (
            "q.<joint> for each joint"
            if partial
            else f"q.<joint> for joints {list(robot.joint_names)}"
        )
        + ", and optionally "
        f"tau0..tau{robot.nv - 1} or tau.<joint> (or map other names with columns=...)"
        + (NO_T_HINT if "t" in lack else "")
        + lock
    )


#: What a table without a ``t`` column may give instead (:func:`_refuse_missing`).
NO_T_HINT = ", or give the sample rate (rate=..., --rate R) if the rows are sampled at a fixed rate"


def _tau_candidates(pick: _Picker, robot: Robot, current: tuple[str, ...]) -> list[str | None]:
    """Per velocity coordinate: its torque column, or ``None`` (read from currents: ``None``)."""
    tau_cols: list[str | None] = []
    for name, _, _, _, iv, nv in joint_blocks(robot):
        for k in range(nv):
            named = f"tau.{name}" if nv == 1 else f"tau.{name}.{k}"
            tau_cols.append(None if current else pick.one([f"tau{iv + k}", named], f"tau{iv + k}"))
    return tau_cols


def _tau_columns(
    tau_cols: list[str | None],
    header: Sequence[str],
    robot: Robot,
    where: str,
    current: tuple[str, ...],
) -> tuple[str, ...] | None:
    """The torque columns, all or none (motor currents instead need their drives)."""
    tau: tuple[str, ...] | None = None
    if any(c is not None for c in tau_cols):
        absent = [f"tau{i}" for i, c in enumerate(tau_cols) if c is None]
        if absent:
            raise DimensionError(
                f"{where}: has some torque columns but lacks {absent} (nv = {robot.nv})"
            )
        tau = tuple(c for c in tau_cols if c is not None)
    currents = [c for c in header if c.startswith("i.")]
    if tau is None and not current and currents:
        raise OptionError(
            f"{where}: columns {currents} are motor currents [A] and the log has no torque "
            "columns: give their scale, drives=pinobs.io.Drives(motor_constant=..., "
            "gear_ratio=...) (--motor-constant, --gear-ratio), to read them as torques "
            "τ = N·k·i, or drop them"
        )
    return tau


def table_layout(
    header: Sequence[str],
    robot: Robot,
    where: str,
    drives: Drives | None = None,
    rate: float | None = None,
) -> Layout:
    """Match column names to the robot (module docstring); raise naming what is missing.

    ``rate`` [Hz]: a table without a ``t`` column is read as sampled at it (its row ``k`` at
    ``t = k / rate``); a ``t`` column, when there is one, is used instead.
    """
    motor, current = motor_layout(header, robot, where, drives)
    pick = _Picker(header, where)
    t = pick.one(["t"], "t")
    legged = legged_columns(header, robot, where)
    unmeasured = free_flyer_root(robot) if legged.imu and not motor else None
    q = _q_columns(pick, robot, motor, unmeasured)
    tau_cols = _tau_candidates(pick, robot, current)
    _refuse_beyond(header, robot, where)
    t = _refuse_missing(header, robot, where, t, q, bool(motor), rate)
    tau = _tau_columns(tau_cols, header, robot, where, current)
    tick = pick.one(["tick"], "the sample counter")
    return Layout(
        t,
        tuple(q.cols),
        tuple(q.angle),
        tuple(q.slices),
        tau,
        tick,
        drives=drives,
        motor=motor,
        current=current,
        legged=legged if legged.used else None,
        rate=rate if t is None else None,
    )


def lock_hint(absent: Sequence[str], joints: Sequence[str] = ()) -> str:
    """What to do when a log records some of the robot's ``joints`` but not ``absent``: lock
    them, three or more of a name's prefix by one pattern (``'hand_*'``) that matches none of
    the recorded joints."""
    items = lock_items(absent, joints)
    flags = " ".join(f"--lock '{n}'" if "*" in n else f"--lock {n}" for n in items)
    return (
        f". If the log does not record those joints (a gripper's fingers, a hand, a head), "
        f"lock them at a fixed value: pinobs.load(..., lock={items}) (or lock={{name: value}}), "
        f"or {flags} (the pinobs command)"
    )


def lock_items(absent: Sequence[str], joints: Sequence[str]) -> list[str]:
    """``absent`` as names and ``prefix_*`` patterns: the shortest prefix (whole ``_``-words)
    that matches three or more absent joints and none of the others of ``joints``."""
    recorded = [j for j in joints if j not in set(absent)]
    out: list[str] = []
    covered: set[str] = set()
    for name in absent:
        if name in covered:
            continue
        words = name.split("_")
        for k in range(1, len(words)):
            prefix = "_".join(words[:k]) + "_"
            hits = [a for a in absent if a.startswith(prefix)]
            if len(hits) >= 3 and not any(j.startswith(prefix) for j in recorded):
                out.append(prefix + "*")
                covered.update(hits)
                break
        else:
            out.append(name)
            covered.add(name)
    return out


def clean_header(header: Sequence[Any], columns: Mapping[str, str] | None) -> list[str]:
    out = [str(h).strip().strip('"').strip("'").strip() for h in header]
    if columns:
        unknown = sorted(set(columns) - set(out))
        if unknown:
            raise DimensionError(
                f"columns mapping names {unknown}, which the log does not have; it has {out}"
            )
        out = [columns.get(h, h) for h in out]
    return out

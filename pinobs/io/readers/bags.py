"""ROS bags (rosbag2 sqlite3 or MCAP, ROS 1) read with ``rosbags``: JointState messages as rows."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from pinobs.errors import DimensionError, LogFormatError
from pinobs.io.readers.bag_sensors import BagSensors, bag_sensors
from pinobs.io.readers.layout import joint_blocks
from pinobs.io.readers.legged import free_flyer_root
from pinobs.io.readers.log import Log
from pinobs.io.readers.table import INSTALL_IO
from pinobs.model import Robot
from pinobs.model.robot import Vector

BAG_FILES = {".bag", ".mcap", ".db3"}
JOINT_STATE = ("sensor_msgs/msg/JointState", "sensor_msgs/JointState")


def is_bag(path: Path) -> bool:
    return (path.is_dir() and (path / "metadata.yaml").is_file()) or (
        path.suffix.lower() in BAG_FILES
    )


def _open_bag(path: Path, robot: Robot) -> Any:
    """An opened ``rosbags`` reader of ``path``; a robot JointState cannot carry refused."""
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise ModuleNotFoundError(f"reading ROS bags needs rosbags: {INSTALL_IO}") from exc
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except (AnyReaderError, OSError) as exc:
        raise LogFormatError(f"bag {str(path)!r} cannot be opened: {exc}") from None
    return reader


def _measured_joints(robot: Robot, sensors: BagSensors | None) -> list[Any]:
    """The joints a JointState carries: all, but a legged robot's free-flyer root when the
    bag has its IMU (its pose then NaN, :mod:`pinobs.io.readers.legged`)."""
    unmeasured = free_flyer_root(robot) if sensors is not None and sensors.imu else None
    for name, kind, *_ in joint_blocks(robot):
        if kind not in ("vector", "circle") and name != unmeasured:
            raise DimensionError(
                f"joint {name!r} of {robot.name!r} is a {kind} joint, which "
                "sensor_msgs/JointState cannot carry; load the robot with a fixed root"
                + (", or record the trunk's sensor_msgs/Imu in the bag" if kind == "se3" else "")
            )
    return [b for b in robot.joints if b.name != unmeasured]


def _joint_state_topic(reader: Any, path: Path, topic: str | None) -> tuple[str, list[Any]]:
    """The JointState topic read (``topic``, or the only one) and its connections."""
    states = [c for c in reader.connections if c.msgtype in JOINT_STATE]
    topics = sorted({c.topic for c in states})
    if not topics:  # (a sweep found "0 topics []", nothing on what the bag holds)
        present = sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})
        raise DimensionError(
            f"bag {str(path)!r} has no sensor_msgs/JointState topic; its topics: {present}"
        )
    if topic is None:
        if len(topics) != 1:
            raise DimensionError(
                f"bag {str(path)!r} has {len(topics)} sensor_msgs/JointState topics "
                f"{topics}; choose one with topic=... (--topic)"
            )
        topic = topics[0]
    if topic not in topics:
        raise DimensionError(
            f"bag {str(path)!r} has no sensor_msgs/JointState topic {topic!r}; "
            f"its JointState topics: {topics}"
        )
    return topic, [c for c in states if c.topic == topic]


def _joint_row(
    msg: Any,
    names: list[str],
    robot: Robot,
    joints: list[Any],
    lacking: list[str],
    notes: list[str],
) -> tuple[Vector, Vector, int]:
    """``q``, ``tau`` of one JointState message (NaN where a joint lacks), the effort's size;
    what is wrong with it added to ``notes``."""
    pos = np.asarray(msg.position, dtype=float)
    eff = np.asarray(msg.effort, dtype=float)
    where = {n: i for i, n in enumerate(names)}
    q = np.full(robot.nq, np.nan)
    tau = np.full(robot.nv, np.nan)
    if lacking:
        notes.append(f"no position for joints {lacking}")
    for b in joints:
        i = where.get(b.name)
        if i is None:
            continue
        if i < pos.size:
            if b.kind == "circle":
                q[b.idx_q : b.idx_q + 2] = np.cos(pos[i]), np.sin(pos[i])
            else:
                q[b.idx_q] = pos[i]
        if i < eff.size:
            tau[b.idx_v] = eff[i]
    if eff.size and any(np.isnan(tau[b.idx_v : b.idx_v + b.nv]).any() for b in joints):
        notes.append("effort lacks some joints")
    return q, tau, int(eff.size)


class _Rows:
    """The rows of the chunk being read, and what is said of the log as a whole."""

    def __init__(
        self, robot: Robot, topic: str, joints: list[Any], sensors: BagSensors | None
    ) -> None:
        self.robot, self.topic, self.joints, self.sensors = robot, topic, joints, sensors
        self.start = 0  # rows already yielded
        self.skipped: list[int] = []  # messages of another publisher
        self.others: set[str] = set()  # the joints they name
        self.any_tau = False
        self.receive_time = False  # the header stamps are t, unless left unset (0)
        self.clear()

    def clear(self) -> None:
        self.t: list[float] = []
        self.q: list[Vector] = []
        self.tau: list[Vector] = []
        self.n: list[int] = []  # message numbers (messages of another publisher are skipped)
        self.problems: list[tuple[int, str]] = []
        seq = getattr(self, "seq", [])
        self.seq: list[float] | None = None if seq is None else []  # ROS 1 header.seq

    def stamp(self, msg: Any, received: int, notes: list[str]) -> float:
        """The row's time: the header stamp, or the receive time when stamps are unset."""
        stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        if not self.n and self.start == 0 and stamp == 0.0:
            # a sweep found such a bag read as one row at t = 0 and the rest repeats of it
            self.receive_time = True
            notes.append(
                "header stamps unset (0): the bag's receive times are used as t for every message"
            )
        elif stamp == 0.0 and not self.receive_time:
            notes.append("header stamp unset (0)")
        return 1e-9 * received if self.receive_time else stamp

    def add(
        self, number: int, msg: Any, received: int, names: list[str], lacking: list[str]
    ) -> None:
        notes: list[str] = []
        self.t.append(self.stamp(msg, received, notes))
        self.n.append(number)
        seq = getattr(msg.header, "seq", None)  # ROS 2 headers have none
        if seq is None:
            self.seq = None
        elif self.seq is not None:
            self.seq.append(float(seq))
        q, tau, n_eff = _joint_row(msg, names, self.robot, self.joints, lacking, notes)
        self.any_tau = self.any_tau or n_eff > 0
        if notes:
            self.problems.append((number, "; ".join(notes)))
        self.q.append(q)
        self.tau.append(tau)

    def flush(self, notes: tuple[str, ...] = ()) -> Log:
        r = self.robot
        log = _bag_log(
            self.t, self.q, self.tau, self.n, self.problems, self.any_tau, r.nq, r.nv, notes,
            self.seq,
        )  # fmt: skip
        self.start += len(self.t)
        self.clear()
        if self.sensors is None:
            return log
        legged, said = self.sensors.at(log.t, log.lines)
        merged: dict[int, list[str]] = {}
        for k, text in (*log.problems, *said):
            merged.setdefault(k, []).append(text)
        problems = tuple((k, "; ".join(v)) for k, v in sorted(merged.items()))
        return replace(log, problems=problems, **vars(legged))

    def said(self) -> tuple[str, ...]:
        """Messages skipped, said once; none of them the robot's: refused."""
        if self.skipped and not self.start and not self.t:
            raise DimensionError(
                f"topic {self.topic!r}: the JointState joints {sorted(self.others)} "
                f"include none of the joints of robot {self.robot.name!r}, "
                f"{[b.name for b in self.joints]}"
            )
        if not self.skipped:
            return ()
        return (
            f"{len(self.skipped)} messages on {self.topic!r} (the first: message "
            f"{self.skipped[0]}) carry none of the joints of robot {self.robot.name!r} (they "
            f"name {sorted(self.others)}: another publisher on the topic?): skipped, not rows",
        )


def bag_chunks(path: Path, robot: Robot, topic: str | None, chunk_rows: int) -> Iterator[Log]:
    """The ``sensor_msgs/JointState`` messages on ``topic`` as rows, chunk by chunk."""
    reader = _open_bag(path, robot)
    try:
        sensors = bag_sensors(reader, str(path), robot)
        joints = _measured_joints(robot, sensors)
        index = [b.name for b in joints]
        topic, conns = _joint_state_topic(reader, path, topic)
        rows = _Rows(robot, topic, joints, sensors)
        for number, (conn, received, raw) in enumerate(reader.messages(connections=conns)):
            msg: Any = reader.deserialize(raw, conn.msgtype)
            names = list(msg.name)
            n_pos = len(msg.position)
            where = {n: i for i, n in enumerate(names)}
            lacking = [n for n in index if n not in where or where[n] >= n_pos]
            if len(lacking) == len(index):
                # another publisher on the topic (a gripper's JointState): not a row of this
                # robot (a sweep found it refused at message 0, or every one a dropped row)
                rows.skipped.append(number)
                rows.others.update(names)
                continue
            rows.add(number, msg, received, names, lacking)
            if len(rows.t) == chunk_rows:
                yield rows.flush()
        try:
            said = rows.said()
        except DimensionError as exc:
            raise DimensionError(f"bag {str(path)!r}, {exc}") from None
        if rows.t or rows.start == 0 or said:
            yield rows.flush(said)
    finally:
        reader.close()


def _bag_log(
    t: list[float],
    q: list[Vector],
    tau: list[Vector],
    numbers: list[int],
    problems: list[tuple[int, str]],
    any_tau: bool,
    nq: int,
    nv: int,
    notes: tuple[str, ...] = (),
    seq: list[float] | None = None,
) -> Log:
    n = len(t)
    return Log(
        t=np.array(t, dtype=float),
        q=np.array(q, dtype=float).reshape(n, nq),
        tau=np.array(tau, dtype=float).reshape(n, nv) if any_tau else None,
        problems=tuple(problems),
        lines=np.array(numbers, dtype=int),
        unit="message",
        notes=notes,
        tick=None if seq is None or len(seq) != n else np.array(seq, dtype=float),
    )

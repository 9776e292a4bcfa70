"""A legged robot's IMU and foot forces in a ROS bag, joined on the JointState rows.

Topics read beside the JointState one (with ``rosbags``):

- ``sensor_msgs/msg/Imu`` (one topic): ``angular_velocity`` as ``imu_gyro`` [rad/s],
  ``linear_acceleration`` as ``imu_acc`` [m/s², specific force];
- ``geometry_msgs/msg/WrenchStamped`` (one topic per foot): ``wrench.force.z`` (the
  normal force along the sensor's z axis) as ``foot_force`` [N] of the foot named by the
  header's ``frame_id``, or else by the topic's last name (``/force/FL_foot``), a frame
  of the model.

Alignment: the JointState rows are the log's rows (none added, none dropped).  Each
sensor is linearly interpolated at the row's stamp between the two messages around it
(its header stamps; its receive times if they are unset).  A row outside the sensor's
span, or whose two messages are more than ``MAX_GAP_PERIODS`` of the sensor's median
period apart (a dropout), gets NaN for that sensor and a problem naming the topic; no
value is held or extrapolated.  The sensor messages are read first, whole (7 floats
per IMU message), then the JointState messages stream.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pinobs.errors import DimensionError
from pinobs.io.readers.legged import LeggedArrays
from pinobs.model import Robot
from pinobs.model.robot import Vector

IMU = ("sensor_msgs/msg/Imu", "sensor_msgs/Imu")
WRENCH = ("geometry_msgs/msg/WrenchStamped", "geometry_msgs/WrenchStamped")
#: A gap between two sensor messages longer than this many median periods is a dropout.
MAX_GAP_PERIODS = 5.0


@dataclass(frozen=True)
class _Series:
    """One sensor topic's messages: stamps ``(m,)`` [s] and values ``(m, k)``."""

    topic: str
    t: Vector
    x: Vector

    def at(self, t: Vector) -> tuple[Vector, Vector]:
        """Values at ``t`` (linear interpolation), and which rows could not have one."""
        n = t.size
        out = np.full((n, self.x.shape[1]), np.nan)
        if self.t.size < 2:
            return out, np.ones(n, dtype=bool)
        j = np.searchsorted(self.t, t, side="right")  # self.t[j-1] <= t < self.t[j]
        inside = (j > 0) & (j < self.t.size) | (t == self.t[-1])
        j = np.clip(j, 1, self.t.size - 1)
        gap = self.t[j] - self.t[j - 1]
        period = float(np.median(np.diff(self.t)))
        ok = inside & (gap <= MAX_GAP_PERIODS * period) & np.isfinite(t)
        w = np.where(ok, (t - self.t[j - 1]) / np.where(gap > 0, gap, 1.0), 0.0)
        both = self.x[j - 1] * (1 - w)[:, None] + self.x[j] * w[:, None]
        out[ok] = both[ok]
        return out, ~ok


@dataclass(frozen=True)
class BagSensors:
    """The IMU and foot-force topics of a bag, read whole."""

    imu: _Series | None
    feet: tuple[str, ...]
    forces: tuple[_Series, ...]

    def at(self, t: Vector, numbers: Vector) -> tuple[LeggedArrays, list[tuple[int, str]]]:
        """The legged arrays at the rows' stamps ``t``; rows without a value said."""
        said: dict[int, list[str]] = {}

        def one(series: _Series) -> Vector:
            x, lost = series.at(t)
            for i in np.flatnonzero(lost):
                said.setdefault(int(numbers[i]), []).append(
                    f"no {series.topic} message around its stamp (a gap or outside "
                    f"{series.t[0]:.6f}..{series.t[-1]:.6f} s): NaN"
                )
            return x

        gyro = acc = force = None
        if self.imu is not None:
            both = one(self.imu)
            gyro, acc = both[:, :3], both[:, 3:]
        if self.forces:
            force = np.column_stack([one(s)[:, 0] for s in self.forces])
        problems = [(k, "; ".join(v)) for k, v in sorted(said.items())]
        return LeggedArrays(gyro, acc, force, None, self.feet), problems


def _stamps(reader: Any, conns: list[Any]) -> tuple[Vector, list[Any]]:
    """Stamps [s] (header, or receive times if unset) and messages of ``conns``, by stamp."""
    stamps, msgs, received = [], [], []
    for conn, rec, raw in reader.messages(connections=conns):
        msg = reader.deserialize(raw, conn.msgtype)
        stamps.append(msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)
        received.append(1e-9 * rec)
        msgs.append(msg)
    t = np.array(received if stamps and not any(stamps) else stamps, dtype=float)
    order = np.argsort(t, kind="stable")
    return t[order], [msgs[i] for i in order]


def _foot_of(conn: Any, msgs: list[Any], robot: Robot, path: str) -> str:
    frames = [f.name for f in robot.model.frames]
    frame_id = msgs[0].header.frame_id if msgs else ""
    last = conn.topic.rstrip("/").rsplit("/", 1)[-1]
    for name in (frame_id, last):
        if name in frames:
            return str(name)
    feet_like = [f for f in frames if "foot" in f.lower()] or frames
    raise DimensionError(
        f"bag {path!r}: WrenchStamped topic {conn.topic!r} (frame_id {frame_id!r}) names no "
        f"foot frame of robot {robot.name!r}; its frames include {feet_like}"
    )


def bag_sensors(reader: Any, path: str, robot: Robot) -> BagSensors | None:
    """The bag's IMU and WrenchStamped topics (module docstring), or ``None`` if it has none."""
    imus = [c for c in reader.connections if c.msgtype in IMU]
    wrenches = [c for c in reader.connections if c.msgtype in WRENCH]
    if not imus and not wrenches:
        return None
    topics = sorted({c.topic for c in imus})
    if len(topics) > 1:
        raise DimensionError(
            f"bag {path!r} has {len(topics)} sensor_msgs/Imu topics {topics}; pinobs reads "
            "one (the trunk's): keep it alone in the bag"
        )
    imu = None
    if imus:
        t, msgs = _stamps(reader, imus)
        w = [(m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z) for m in msgs]
        f = [
            (m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z)
            for m in msgs
        ]
        x = np.hstack([np.array(w, dtype=float), np.array(f, dtype=float)]).reshape(-1, 6)
        imu = _Series(topics[0], t, x)
    feet, forces = [], []
    for topic in sorted({c.topic for c in wrenches}):
        conns = [c for c in wrenches if c.topic == topic]
        t, msgs = _stamps(reader, conns)
        foot = _foot_of(conns[0], msgs, robot, path)
        if foot in feet:
            raise DimensionError(f"bag {path!r}: two WrenchStamped topics for foot {foot!r}")
        feet.append(foot)
        z = np.array([m.wrench.force.z for m in msgs], dtype=float).reshape(-1, 1)
        forces.append(_Series(topic, t, z))
    return BagSensors(imu, tuple(feet), tuple(forces))

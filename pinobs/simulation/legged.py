"""Legged robots in MuJoCo as the truth for base estimation: go1 standing, swaying, trotting
(TALOS standing, swaying and stepping: :mod:`pinobs.simulation.humanoid`, whose names are
also importable from here).

The robot is example-robot-data's go1 URDF compiled by MuJoCo (its ``<visual>``
meshes, ``.dae`` that MuJoCo cannot read, and ``<transmission>`` tags removed;
the root link's 1 µg inertia, not positive definite as written, dropped), with
a free joint on the root link, a floor plane, a torque motor per joint
(``|τ|`` ≤ the URDF's effort limit) and an IMU site on ``imu_link``.  Only the
four foot spheres (radius 2 cm) touch the floor (friction 1); nothing else
collides.  Armature ``ARMATURE`` on each joint stands for the rotors' reflected
inertia; it changes no kinematics.

Controller (joint space, at every physics step)::

    τ = clip(τ_ff + K_p (q_ref − q) + K_d (q̇_ref − q̇), ±τ_max),   τ_ff = −Σ_j J_jᵀ (m g / n) u

where ``q_ref`` is the inverse kinematics (:class:`pinobs.model.FootKinematics`,
Newton's method) of foot targets in the base frame, and ``τ_ff`` shares the
robot's weight ``m g`` among the ``n`` feet meant to be down (``u`` the world's
up in the base frame as the reference has it; a virtual-model feed-forward): ``"stand"`` holds the
nominal stance; ``"sway"`` keeps the feet where they stand and moves the base
by sinusoids (position 3 cm, roll/pitch/yaw 0.1 rad, incommensurate
frequencies 0.3-0.9 Hz); ``"trot"`` moves diagonal pairs of feet in the base
frame (stance: backwards at the commanded speed; swing: forwards along a
raised cosine 6 cm high), an open-loop trot commanded at 0.25 m/s, 0.4 s period (it walks about 0.23 m/s).

Sensors, sampled at ``rate`` (``substeps`` physics steps of ``1/(rate·substeps)`` s
between samples; MuJoCo's semi-implicit Euler)::

    imu.gyro  = mean over the sample's steps of MuJoCo's gyro  + b_g + n_g     [rad/s]
    imu.acc   = mean over the sample's steps of MuJoCo's accelerometer + b_a + n_a   [m/s²]
    q.<joint> = Δ_j round((q + n_q) / Δ_j)   (Δ_j = 0: q + n_q)                 [rad]
    force.<foot> = Σ normal contact forces on that foot's sphere + n_f         [N]

MuJoCo's accelerometer reads the specific force ``Rᵀ(p̈ − g)`` of the site
(+9.81 m/s² up at rest).  The IMU readings at ``t_k`` are averaged over
``[t_k, t_{k+1})`` (an IMU's Δv/Δt, what a held-input filter needs), the other
columns are the state at ``t_k``.  Biases ``b`` are drawn once per run
(σ :attr:`LeggedNoise.gyro_bias`, :attr:`LeggedNoise.acc_bias`) and then random-walk;
noises are white, from a seeded generator.  Truth columns (``truth.*``): base
position ``p`` and orientation quaternion ``(x, y, z, w)`` in the world, base
linear ``v`` and angular ``w`` velocity in the base frame (Pinocchio's
``v[0:6]`` of go1's free flyer), ``v_world`` the base's world velocity, the
true joint angles, the biases, and ``contact.<foot>`` (1 while MuJoCo has a
contact on that foot).  The base is the root link (``base`` = ``trunk``).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import ConfigurationError, GainError, SimulationFailed, UnknownNameError
from pinobs.model import FootKinematics, Robot, load
from pinobs.model.loading import resolve_source

__all__ = [
    "ARMATURE",
    "GO1_FEET",
    "LEGGED_MOTIONS",
    "LeggedNoise",
    "LeggedRun",
    "go1_mujoco_spec",
    "simulate_legged",
]

Vector = NDArray[np.floating[Any]]

#: The motions :func:`simulate_legged` can make.
LEGGED_MOTIONS = ("stand", "sway", "trot")
#: go1's foot frames, in Pinocchio's joint order (FL, FR, RL, RR).
GO1_FEET = ("FL_foot", "FR_foot", "RL_foot", "RR_foot")
#: Joint armature [kg·m²] (rotor inertia through the gear, each joint).
ARMATURE = 0.01
FOOT_RADIUS = 0.02  # [m], go1.urdf's foot collision sphere
STANCE = (0.0, 0.8, -1.6)  # hip, thigh, calf [rad]
KP, KD = 80.0, 2.0  # [N·m/rad], [N·m·s/rad]
SETTLE = 1.0  # [s] simulated before the first sample (unrecorded)


@dataclass(frozen=True)
class LeggedNoise:
    """Sensor noise of :func:`simulate_legged` (standard deviations).

    Attributes:
        gyro: gyro white noise density [rad/s/√Hz] (σ per sample: ``gyro·√rate``).
        acc: accelerometer white noise density [m/s²/√Hz].
        gyro_bias: σ of the initial gyro bias [rad/s].
        acc_bias: σ of the initial accelerometer bias [m/s²].
        gyro_walk: gyro bias random walk [rad/s²/√Hz].
        acc_walk: accelerometer bias random walk [m/s³/√Hz].
        encoder: joint encoder noise per sample [rad].
        force: foot force noise per sample [N].
        encoder_step: the encoders' resolution Δ [rad]: one for every joint, or one per
            joint (in the model's order); 0: not quantised.  The noisy angle is rounded to
            it (``Δ round((q + n_q)/Δ)``), so a still joint repeats its reading when
            ``encoder ≲ Δ/2`` and dithers between neighbouring steps above that, as the
            real Go1 log's do (steps of 6e-5 rad, hip and thigh, and 4e-5 rad, calf;
            35-57 % of the still rows repeat the previous reading).  The reading's error
            has variance ``≈ encoder² + Δ²/12`` (Widrow & Kollár 2008, *Quantization
            Noise*, §4.1; exact for ``encoder ≳ Δ``).
    """

    gyro: float = 2e-3
    acc: float = 2e-2
    gyro_bias: float = 5e-3
    acc_bias: float = 5e-2
    gyro_walk: float = 1e-4
    acc_walk: float = 1e-3
    encoder: float = 5e-4
    force: float = 2.0
    encoder_step: float | tuple[float, ...] = 0.0

    def __post_init__(self) -> None:
        steps = self.encoder_step
        for value in steps if isinstance(steps, tuple) else (steps,):
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise GainError(f"LeggedNoise.encoder_step: finite numbers ≥ 0, got {steps!r}")
        for f in fields(self):
            if f.name == "encoder_step":
                continue
            value = getattr(self, f.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise GainError(f"LeggedNoise.{f.name} must be a finite number ≥ 0, got {value!r}")


@dataclass(frozen=True)
class LeggedRun:
    """A simulated run: one row per sample, named columns (read-only arrays).

    Attributes:
        motion: ``"stand"``, ``"sway"``, ``"trot"`` (go1) or ``"step"`` (TALOS).
        seed: the noise generator's seed.
        rate: sample rate [Hz].
        feet: foot frame names (``force.<foot>``, ``contact.<foot>``).
        joints: joint names in Pinocchio's order (``q.<joint>``).
        columns: column name → values, shape ``(n,)`` each, ``"t"`` first.
        noise: the sensor noise used.
    """

    motion: str
    seed: int
    rate: float
    feet: tuple[str, ...]
    joints: tuple[str, ...]
    columns: dict[str, Vector] = field(repr=False)
    noise: LeggedNoise = field(default_factory=LeggedNoise)

    def __getitem__(self, name: str) -> Vector:
        try:
            return self.columns[name]
        except KeyError:
            raise UnknownNameError(
                f"no column {name!r}; the columns are {', '.join(self.columns)}"
            ) from None

    def stack(self, *names: str) -> Vector:
        """Columns side by side, shape ``(n, len(names))``."""
        return np.column_stack([self[n] for n in names])

    @property
    def t(self) -> Vector:
        """Sample times [s]."""
        return self.columns["t"]

    def q_joints(self, *, truth: bool = False) -> Vector:
        """Joint angles ``(n, 12)`` [rad], measured (or true)."""
        prefix = "truth.q." if truth else "q."
        return self.stack(*(prefix + j for j in self.joints))

    def gyro(self) -> Vector:
        """Gyro readings ``(n, 3)`` [rad/s]."""
        return self.stack("imu.gyro.x", "imu.gyro.y", "imu.gyro.z")

    def acc(self) -> Vector:
        """Accelerometer readings (specific force) ``(n, 3)`` [m/s²]."""
        return self.stack("imu.acc.x", "imu.acc.y", "imu.acc.z")

    def forces(self) -> Vector:
        """Measured foot normal forces ``(n, len(feet))`` [N]."""
        return self.stack(*("force." + f for f in self.feet))

    def base_q(self) -> Vector:
        """True base pose ``(n, 7)``: position [m], quaternion ``(x, y, z, w)``."""
        return self.stack(*(f"truth.p.{a}" for a in "xyz"), *(f"truth.quat.{a}" for a in "xyzw"))

    def base_v(self) -> Vector:
        """True base twist ``(n, 6)`` in the base frame: linear [m/s], angular [rad/s]."""
        return self.stack(*(f"truth.v.{a}" for a in "xyz"), *(f"truth.w.{a}" for a in "xyz"))


# ----------------------------------------------------------------- the model
def go1_mujoco_spec() -> Any:
    """go1's URDF compiled by MuJoCo with a free joint, a floor, motors and an IMU site
    (module docstring); returns the ``mujoco.MjSpec`` (compile it with ``.compile()``)."""
    import mujoco  # optional extra pinobs[mujoco]

    path = resolve_source("go1")[0]
    root = ET.parse(path).getroot()
    for link in root.iter("link"):
        for visual in link.findall("visual"):
            link.remove(visual)
        if link.get("name") == "base":  # 1e-6 kg with a non-positive-definite inertia
            inertial = link.find("inertial")
            if inertial is not None:
                link.remove(inertial)
    for tag in root.findall("transmission"):
        root.remove(tag)
    extra = ET.SubElement(root, "mujoco")
    ET.SubElement(extra, "compiler", discardvisual="true", fusestatic="false", angle="radian")
    spec = mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"))
    spec.option.timestep = 1e-3
    spec.body("base").add_freejoint(name="root")
    feet = {spec.body(f) for f in GO1_FEET}
    for geom in spec.geoms:
        touches = geom.parent in feet  # only the feet touch the floor
        geom.contype, geom.conaffinity = (1 if touches else 0), 0
        if touches:
            geom.condim = 3
    add_imu_and_floor(spec, "imu_link")
    for joint in spec.joints:
        if joint.type != mujoco.mjtJoint.mjJNT_HINGE:
            continue
        joint.armature = ARMATURE
        limit = 35.55 if "calf" in joint.name else 23.7  # go1.urdf's effort limits [N·m]
        spec.add_actuator(
            name=joint.name,
            target=joint.name,
            trntype=mujoco.mjtTrn.mjTRN_JOINT,
            ctrllimited=True,
            ctrlrange=[-limit, limit],
        )
    return spec


def add_imu_and_floor(spec: Any, imu_body: str) -> None:
    """Add the floor (the only geom the feet touch) and an IMU site on ``imu_body`` with its
    gyro and accelerometer (sensors ``gyro``, ``acc``) to the MuJoCo ``spec``."""
    import mujoco

    spec.worldbody.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0.0, 0.0, 0.05],
        contype=0,
        conaffinity=1,
        friction=[1.0, 0.005, 0.0001],
    )
    spec.body(imu_body).add_site(name="imu")
    for name, kind in (
        ("gyro", mujoco.mjtSensor.mjSENS_GYRO),
        ("acc", mujoco.mjtSensor.mjSENS_ACCELEROMETER),
    ):
        spec.add_sensor(name=name, type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE, objname="imu")


# --------------------------------------------------------------- references
class _Gait:
    """Foot targets in the base frame and base targets for a motion (module docstring)."""

    def __init__(self, motion: str, nominal: Vector, height: float) -> None:
        self.motion = motion
        self.nominal = nominal  # feet in the base frame at the stance, (4, 3)
        self.height = height  # base height over the floor at the stance [m]
        self.speed = 0.25  # [m/s], trot
        self.period = 0.4  # [s], trot
        self.lift = 0.06  # [m], trot
        self.ramp = 0.5  # [s] to reach full amplitude / speed

    def feet(self, t: float) -> tuple[Vector, Vector, Vector]:
        """Foot targets in the base frame at ``t`` (``t = 0``: the first sample), (4, 3); which
        feet are meant to be on the ground, (4,) bools; the world's up in the base frame."""
        up = np.array([0.0, 0.0, 1.0])
        all_feet = np.ones(4, dtype=bool)
        if t <= 0.0 or self.motion == "stand":
            return self.nominal, all_feet, up
        s = min(1.0, t / self.ramp)
        s = s * s * (3.0 - 2.0 * s)  # smooth start
        if self.motion == "sway":
            p = (
                0.03
                * s
                * np.array([math.sin(2 * math.pi * 0.5 * t), math.sin(2 * math.pi * 0.7 * t), 0.0])
            )
            p[2] = 0.03 * s * math.sin(2 * math.pi * 0.9 * t)
            rpy = (
                0.1
                * s
                * np.array(
                    [
                        math.sin(2 * math.pi * 0.6 * t),
                        math.sin(2 * math.pi * 0.4 * t + 1.0),
                        math.sin(2 * math.pi * 0.3 * t + 2.0),
                    ]
                )
            )
            R = _rpy(rpy)
            world = self.nominal  # feet stay; base at (p, R) relative to its stance pose
            return (world - p) @ R, all_feet, R.T @ up  # rows: Rᵀ (f − p)
        # trot: phase per diagonal pair; stance half moves back, swing half forwards and up
        out = self.nominal.copy()
        down = np.ones(4, dtype=bool)
        half = 0.5 * self.period
        stride = self.speed * s * half  # distance the base moves during one stance [m]
        for j, offset in enumerate((0.0, half, half, 0.0)):  # FL, FR, RL, RR
            phase = ((t + offset) % self.period) / half  # [0, 1) stance, [1, 2) swing
            if phase < 1.0:
                x = 0.5 * stride - stride * phase
                z = 0.0
            else:
                u = phase - 1.0
                down[j] = False
                x = -0.5 * stride + stride * (0.5 - 0.5 * math.cos(math.pi * u))
                z = self.lift * 0.5 * (1.0 - math.cos(2 * math.pi * u)) * s
            out[j, 0] += x
            out[j, 2] += z
        return out, down, up


def _rpy(rpy: Vector) -> Vector:
    """``R = Rz(yaw) Ry(pitch) Rx(roll)``."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _inverse_kinematics(legs: FootKinematics, targets: Vector, q0: Vector) -> Vector:
    """Joint angles putting the feet at ``targets`` (base frame), Newton from ``q0``, leg by leg."""
    q = q0.copy()
    for _ in range(20):
        h, jac = legs.positions_and_jacobians(q)
        err = targets - h
        if float(np.abs(err).max()) < 1e-10:
            break
        for j in range(4):
            cols = slice(3 * j, 3 * j + 3)
            q[cols] += np.linalg.solve(jac[j][:, cols], err[j])
    return q


# --------------------------------------------------------------- simulation
def check_arguments(
    motion: str, motions: tuple[str, ...], duration: float, rate: float, substeps: int
) -> None:
    if motion not in motions:
        raise UnknownNameError(f"unknown motion {motion!r}; one of {', '.join(motions)}")
    if not (duration > 0 and rate > 0 and isinstance(substeps, int) and substeps >= 1):
        raise ConfigurationError(
            f"duration ({duration!r} s) and rate ({rate!r} Hz) must be > 0 and substeps "
            f"({substeps!r}) an integer ≥ 1"
        )


def simulate_legged(
    motion: str,
    duration: float,
    *,
    seed: int = 0,
    rate: float = 500.0,
    substeps: int = 2,
    noise: LeggedNoise | None = None,
    robot: Robot | None = None,
) -> LeggedRun:
    """Simulate go1 in MuJoCo for ``duration`` [s] sampled at ``rate`` [Hz] (module docstring).

    Args:
        motion: one of :data:`LEGGED_MOTIONS`.
        duration: recorded time [s] (after an unrecorded settling second).
        seed: seed of the sensor noise.
        rate: sample rate [Hz].
        substeps: physics steps per sample.
        noise: sensor noise (:class:`LeggedNoise`).
        robot: go1 as Pinocchio loads it (``pinobs.load("go1")``; loaded if not given).

    Raises:
        UnknownNameError: an unknown motion.
        ConfigurationError: a non-positive duration, rate or substeps.
        SimulationFailed: the robot fell (base below 12 cm) or MuJoCo's state became
            non-finite.
    """
    check_arguments(motion, LEGGED_MOTIONS, duration, rate, substeps)
    robot = robot if robot is not None else load("go1")
    legs = FootKinematics(robot, GO1_FEET)
    spec = go1_mujoco_spec()
    spec.option.timestep = 1.0 / (rate * substeps)
    mj = spec.compile()
    weight = 9.81 * float(np.sum(mj.body_mass))  # [N]
    stance = np.tile(STANCE, 4)
    nominal = legs.positions(stance)
    height = FOOT_RADIUS - float(nominal[:, 2].mean()) + 1e-3
    gait = _Gait(motion, nominal, height)
    first = round(-SETTLE * rate)
    memory = {"q_ref": stance.copy(), "q_prev": stance.copy()}

    def reference(k: int, t: float, _: Any) -> tuple[Vector, Vector, Vector]:
        targets, down, up = gait.feet(t)
        q_ref = _inverse_kinematics(legs, targets, memory["q_ref"])
        # the weight shared by the feet meant to be down: τ = −Σ J_jᵀ f_j (virtual model)
        _, jac = legs.positions_and_jacobians(q_ref)
        share = weight / max(int(down.sum()), 1)
        tau_ff = -share * np.einsum("jki,k->i", jac[down], up)
        dq_ref = (q_ref - memory["q_prev"]) * rate if k > first else np.zeros(12)
        memory["q_ref"], memory["q_prev"] = q_ref, q_ref.copy()
        return q_ref, dq_ref, tau_ff

    machine = Machine("go1", mj, robot, GO1_FEET, stance, height, KP, KD, 0.12)
    return record_run(machine, motion, reference, duration, seed, rate, substeps, noise)


@dataclass(frozen=True)
class Machine:
    """A compiled MuJoCo model and what :func:`record_run` needs of it."""

    name: str
    mj: Any
    robot: Robot
    feet: tuple[str, ...]
    stance: Vector  # joint angles at the start [rad]
    height: float  # base height at the start [m]
    kp: float  # [N·m/rad]
    kd: float  # [N·m·s/rad]
    fallen: float  # base height below which it fell [m]


@dataclass(frozen=True)
class _Wiring:
    """Where :func:`record_run` reads and drives a compiled MuJoCo model (indices into its
    arrays); the joints in Pinocchio's order."""

    joints: tuple[str, ...]
    qadr: NDArray[np.intp]  # each joint's qpos address
    vadr: NDArray[np.intp]  # each joint's qvel address
    act: NDArray[np.intp]  # each joint's motor
    limit: Vector  # each motor's torque limit [N·m] (inf: unlimited)
    foot_bodies: list[int]
    floor: int
    imu_gyro: int  # sensordata address of the gyro
    imu_acc: int  # sensordata address of the accelerometer

    @classmethod
    def of(cls, mj: Any, robot: Robot, feet: tuple[str, ...]) -> _Wiring:
        joints = tuple(j.name for j in robot.joints[1:])
        act = np.array([mj.actuator(j).id for j in joints])
        return cls(
            joints=joints,
            qadr=np.array([mj.joint(j).qposadr[0] for j in joints]),
            vadr=np.array([mj.joint(j).dofadr[0] for j in joints]),
            act=act,
            limit=np.where(mj.actuator_ctrllimited[act] > 0, mj.actuator_ctrlrange[act, 1], np.inf),
            foot_bodies=[mj.body(f).id for f in feet],
            floor=mj.geom("floor").id,
            imu_gyro=mj.sensor("gyro").adr[0],
            imu_acc=mj.sensor("acc").adr[0],
        )


def record_run(
    machine: Machine,
    motion: str,
    reference: Any,
    duration: float,
    seed: int,
    rate: float,
    substeps: int,
    noise: LeggedNoise | None,
) -> LeggedRun:
    """Run ``reference(k, t, data) -> (q_ref, q̇_ref, τ_ff)`` (``data``: MuJoCo's state at
    ``t``, to read, not to change) through the joint PD law on ``machine``
    and sample the sensors and the truth (module docstring)."""
    import mujoco

    noise = noise if noise is not None else LeggedNoise()
    mj, feet, name = machine.mj, machine.feet, machine.name
    data = mujoco.MjData(mj)
    wiring = _Wiring.of(mj, machine.robot, feet)
    steps = noise.encoder_step
    if isinstance(steps, tuple) and len(steps) != wiring.qadr.size:
        raise ConfigurationError(
            f"LeggedNoise.encoder_step has {len(steps)} entries; {name} has "
            f"{wiring.qadr.size} joints (give one step, or one per joint)"
        )
    data.qpos[:3] = (0.0, 0.0, machine.height)
    data.qpos[3:7] = (1.0, 0.0, 0.0, 0.0)
    data.qpos[wiring.qadr] = machine.stance
    mujoco.mj_forward(mj, data)

    n = round(duration * rate) + 1
    settle = round(SETTLE * rate)
    rng = np.random.default_rng(seed)
    bias = np.concatenate([rng.normal(0.0, noise.gyro_bias, 3), rng.normal(0.0, noise.acc_bias, 3)])
    walk = np.repeat([noise.gyro_walk, noise.acc_walk], 3) * math.sqrt(1.0 / rate)
    white = np.repeat([noise.gyro, noise.acc], 3) * math.sqrt(rate)

    rows: list[Vector] = []
    for k in range(-settle, n):
        t = k / rate
        ref = reference(k, t, data)
        qpos, qvel = data.qpos.copy(), data.qvel.copy()
        imu, forces, qacc_mean = _advance(mujoco, machine, data, wiring, ref, substeps)
        if not np.all(np.isfinite(data.qpos)):
            raise SimulationFailed(
                f"{name} {motion}: MuJoCo's state is not finite at t = {t:.3f} s"
            )
        if qpos[2] < machine.fallen:
            raise SimulationFailed(
                f"{name} {motion}: fell (base at {qpos[2]:.3f} m) at t = {t:.3f} s; seed {seed}"
            )
        imu /= substeps
        qacc_mean /= substeps
        if k < 0:
            continue
        bias = bias + walk * rng.normal(size=6) if k > 0 else bias
        reading = imu + bias + white * rng.normal(size=6)
        truth = (qpos, qvel, qacc_mean, bias)
        rows.append(_row(t, reading, forces, truth, wiring, noise, rng))
    cols: dict[str, Vector] = {}
    table = np.array(rows)
    for i, column_name in enumerate(_column_names(feet, wiring.joints)):
        column = np.ascontiguousarray(table[:, i])
        column.setflags(write=False)
        cols[column_name] = column
    return LeggedRun(motion, seed, float(rate), feet, wiring.joints, cols, noise)


def _advance(
    mujoco: Any,
    machine: Machine,
    data: Any,
    wiring: _Wiring,
    ref: tuple[Vector, Vector, Vector],
    substeps: int,
) -> tuple[Vector, Vector, Vector]:
    """The ``substeps`` physics steps of one sample under the joint PD law towards ``ref`` =
    ``(q_ref, q̇_ref, τ_ff)`` (module docstring): the sums over them of the IMU's readings
    (gyro, accelerometer) and of the base's acceleration, and the feet's normal forces
    before the first step."""
    q_ref, dq_ref, tau_ff = ref
    h = machine.mj.opt.timestep
    imu = np.zeros(6)
    forces: Vector = np.zeros(len(wiring.foot_bodies))
    qacc_sum = np.zeros(3)
    g, a = wiring.imu_gyro, wiring.imu_acc
    for s in range(substeps):
        q_j = data.qpos[wiring.qadr]
        dq_j = data.qvel[wiring.vadr]
        data.ctrl[wiring.act] = np.clip(
            tau_ff + machine.kp * (q_ref + dq_ref * s * h - q_j) + machine.kd * (dq_ref - dq_j),
            -wiring.limit,
            wiring.limit,
        )
        mujoco.mj_step(machine.mj, data)  # sensors and contacts: of the state before this step
        imu[:3] += data.sensordata[g : g + 3]
        imu[3:] += data.sensordata[a : a + 3]
        qacc_sum += data.qacc[:3]
        if s == 0:
            forces = _foot_forces(mujoco, machine.mj, data, wiring.foot_bodies, wiring.floor)
    return imu, forces, qacc_sum


def _encoders(q: Vector, noise: LeggedNoise, rng: np.random.Generator) -> Vector:
    """The joints' readings: ``Δ round((q + n_q)/Δ)`` per joint (``Δ = 0``: ``q + n_q``)."""
    x = q + noise.encoder * rng.normal(size=q.size)
    step = np.broadcast_to(np.asarray(noise.encoder_step, dtype=float), q.shape)
    if not step.any():
        return x
    return np.where(step > 0, np.round(x / np.where(step > 0, step, 1.0)) * step, x)


def _row(
    t: float,
    reading: Vector,
    forces: Vector,
    truth: tuple[Vector, Vector, Vector, Vector],
    wiring: _Wiring,
    noise: LeggedNoise,
    rng: np.random.Generator,
) -> Vector:
    """One sample's row of a :class:`LeggedRun` (:func:`_column_names`' order): the IMU
    ``reading``, the feet's ``forces`` and the joints' angles with their noises drawn from
    ``rng`` (in that order), then the truth (``qpos``, ``qvel``, the base's mean
    acceleration, the IMU's biases) and the contacts."""
    qpos, qvel, qacc_mean, bias = truth
    quat_wxyz = qpos[3:7]
    R = _rotation_wxyz(quat_wxyz)
    v_world = qvel[:3]
    return np.concatenate(
        [
            [t],
            reading,
            forces + noise.force * rng.normal(size=forces.size),
            _encoders(qpos[wiring.qadr], noise, rng),
            qpos[:3],
            quat_wxyz[[1, 2, 3, 0]],
            R.T @ v_world,
            qvel[3:6],
            v_world,
            qacc_mean,
            qpos[wiring.qadr],
            qvel[wiring.vadr],
            bias,
            (forces > 0).astype(float),
        ]
    )


def _column_names(feet: tuple[str, ...], joints: tuple[str, ...]) -> list[str]:
    """The columns of a :class:`LeggedRun`, in order (module docstring)."""
    return (
        ["t"]
        + [f"imu.gyro.{a}" for a in "xyz"]
        + [f"imu.acc.{a}" for a in "xyz"]
        + [f"force.{f}" for f in feet]
        + [f"q.{j}" for j in joints]
        + [f"truth.p.{a}" for a in "xyz"]
        + [f"truth.quat.{a}" for a in "xyzw"]
        + [f"truth.v.{a}" for a in "xyz"]
        + [f"truth.w.{a}" for a in "xyz"]
        + [f"truth.v_world.{a}" for a in "xyz"]
        + [f"truth.acc_world.{a}" for a in "xyz"]
        + [f"truth.q.{j}" for j in joints]
        + [f"truth.dq.{j}" for j in joints]
        + [f"truth.bias.gyro.{a}" for a in "xyz"]
        + [f"truth.bias.acc.{a}" for a in "xyz"]
        + [f"contact.{f}" for f in feet]
    )


def _rotation_wxyz(quat: Vector) -> Vector:
    w, x, y, z = quat / np.linalg.norm(quat)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _foot_forces(mujoco: Any, mj: Any, data: Any, feet: list[int], floor: int) -> Vector:
    """Sum of the normal contact forces [N] between each foot's geoms and the floor."""
    out = np.zeros(len(feet))
    wrench = np.zeros(6)
    for i in range(data.ncon):
        con = data.contact[i]
        g1, g2 = int(con.geom1), int(con.geom2)
        if floor not in (g1, g2):
            continue
        body = int(mj.geom_bodyid[g2 if g1 == floor else g1])
        if body in feet:
            mujoco.mj_contactForce(mj, data, i, wrench)
            out[feet.index(body)] += wrench[0]
    return out


#: The humanoid's names, moved to :mod:`pinobs.simulation.humanoid`, still importable from here.
_HUMANOID_NAMES = frozenset(
    ("HUMANOID_MOTIONS", "TALOS_FEET", "TALOS_STANCE", "simulate_humanoid", "talos_mujoco_spec")
)


def __getattr__(name: str) -> Any:
    """``from pinobs.simulation.legged import simulate_humanoid`` (PEP 562): the humanoid's
    names, from :mod:`pinobs.simulation.humanoid` (imported on first use: it imports this)."""
    if name in _HUMANOID_NAMES:
        from pinobs.simulation import humanoid

        return getattr(humanoid, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

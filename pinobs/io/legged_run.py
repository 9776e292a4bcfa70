"""A legged robot's log through the contact-aided invariant EKF (issue 38, item 4).

:func:`estimate_legged` runs :class:`~pinobs.observers.inekf.InvariantEKF` over a log
read with the legged columns (:mod:`pinobs.io.readers.legged`: ``imu.gyro.*``,
``imu.acc.*``, ``force.<foot>`` or ``contact.<foot>``, the joints' ``q.<joint>``) and
returns the full free-flyer estimate, a :class:`~pinobs.io.LogRun` like every other
observer's (``q`` of size ``nq``: base position, quaternion ``xyzw``, joints; ``v`` of
size ``nv``: the base's linear velocity in the base frame (Pinocchio's convention), its
angular velocity, the joints').  So the writers, the playback and the CLI
(``pinobs estimate --observer inekf``) take it unchanged.

* **Joint velocities**: the model-free ``kf`` over the joint columns (the robot with its
  root locked), run through :func:`~pinobs.io.estimate_log` with the usual row rules.
* **Contacts** (``contacts=``): ``"force"`` (default): the log's ``contact.<foot>``
  flags, else the ``force.<foot>`` columns through
  :func:`~pinobs.observers.contacts.contacts_from_forces` (threshold and hysteresis;
  defaults from the robot's weight); ``"probability"``: the force and the foot's speed
  as the filter predicts it from the previous row (SEROW's,
  :class:`~pinobs.observers.contacts.ContactProbability`), row by row.
* **Slip**: ``foot_gate=p`` gates each foot by its own innovation (the filter's
  ``foot_gate``): a foot that slides while flagged in contact is re-anchored, not measured.
* **Noise** (defaults): the filter's ``joint_std`` measured on the log's joint columns
  where they move least (:func:`~pinobs.observers.noise.still_noise_std`) and its ``slip_speed`` (the contact
  noise from each foot's predicted speed), with :data:`LEGGED_GAINS`; ``joint_std=None,
  slip_speed=False`` is the white foot noise of ``gains`` alone.
* **Rolling feet** (``foot_radius``, default ``"urdf"``): each foot measured at its point
  that touched the ground, which a rolling sphere leaves still
  (:mod:`pinobs.observers.rolling`), with the radius of the foot's collision sphere in the
  robot's URDF (:func:`pinobs.model.foot_sphere_radius`: go1 0.02 m; 0 where a foot has no
  sphere, e.g. TALOS's flat soles, and for a robot not loaded from a URDF, said in the
  warnings).  The filters' own default stays 0; this runner's is the URDF's because the
  MuJoCo go1 benchmark (``benchmarks/legged_truth.md``, table ``rolling_gains``: 10 s seeds
  0-2, 60 s seeds 0-1, truth start, gains unchanged) gains with it: trot base velocity RMS
  0.0123 → 0.0084 m/s, the walking axis inside ±2σ 86.4 → 99.6 %; sway 0.0112 → 0.0090;
  stand unchanged (0.00675 → 0.00677).  The real Go1 log was not used to choose it.
  ``foot_radius=0`` is the runner as it was (the foot frames measured).  ``rolling_lift``
  (default ``True``, as the filters'): the touched point's cycloid rise ``r (1 − cos φ)``
  removed (rolling.py's R5, exact, no parameter): MuJoCo go1 trot, the vertical axis inside
  ±2σ 90.4 → 93.4 % (10 s, seeds 0-2) and 91.7 → 94.5 % (60 s, seeds 0-1), velocity RMS
  −4 %, stand and sway unchanged; ``rolling_lift=False`` is R4 alone, the default before.
* **Consistency**: ``run.consistency`` is the feet's NIS over the stance rows
  (:func:`~pinobs.observers.legs.stance_consistency`: mean NIS per degree of freedom and
  the fraction of rows inside their 95 % χ² interval).
* **IMU frame** (``imu_frame``): ``imu_link`` if the model has it, else the root.  It may
  move relative to the root (TALOS's ``imu_link``, on the torso): the filter's body is then
  that frame, the feet are measured in it through the torso joints and the root's twist
  takes the joints' velocities between, ``kf``'s (:mod:`pinobs.observers.imu_link`).
* **Start**: the first row with a finite IMU reading and finite joint angles.  The base
  pose is the log's where it has one; else the base at the origin, its roll and pitch
  from the accelerometer (at rest it reads ``Rᵀ(0, 0, g)``) and yaw zero: the filter's
  position and yaw are then relative to the start (they are unobservable from an IMU and
  legs alone; Hartley et al. 2020).
* **Rows**: every log row gets a row of the output; a row with a NaN IMU reading or NaN
  joint angles, or that does not advance the time, is not fed to the filter, holds NaN
  and is reported in ``bad_rows`` (nothing is bridged silently).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from pinobs.errors import (
    DimensionError,
    LogFormatError,
    ObserverDiverged,
    OptionError,
    PinobsError,
)
from pinobs.io.legged_checks import contact_notes, frame_notes
from pinobs.io.readers import Log
from pinobs.io.runs import estimate_log
from pinobs.io.stream import LogRun
from pinobs.model import FootKinematics, Robot, foot_sphere_radii, load
from pinobs.model.noise import third_difference_std
from pinobs.model.robot import Vector
from pinobs.observers import make_observer
from pinobs.observers.checks import positive
from pinobs.observers.contacts import (
    ContactProbability,
    contacts_from_forces,
    default_thresholds,
)
from pinobs.observers.inekf import InEKFGains, InvariantEKF, rotation_to_quaternion
from pinobs.observers.legs import UpdateInputs, check_time, stance_consistency
from pinobs.observers.noise import STILL_STD, joint_noise_std, still_noise_std, stillest_rows

#: ``contacts=`` of :func:`estimate_legged`.
CONTACT_MODES = ("force", "probability")

#: ``joint_std=`` rules of :func:`estimate_legged`: ``"log"`` (default), σ_q from the log's
#: stillest second (:func:`~pinobs.observers.noise.still_noise_std`); ``"first-second"``,
#: from its first second (kf's rule; the default before: on the real Go1 log, which settles
#: in its first second, 0.4-1.9e-4 rad, 2-5× what its still stretches show).
JOINT_STD_RULES = ("log", "first-second")

#: ``foot_radius=`` rule of :func:`estimate_legged` (its default): the radius of the feet's
#: collision spheres in the robot's URDF (module docstring, "Rolling feet").
FOOT_RADIUS_URDF = "urdf"

#: Rows whose feet's placements :func:`legged_run` computes at once (``_Rows.preload``).
PRELOAD_ROWS = 512

#: The IMU frame used when the model has one of this name and none is given.
IMU_FRAME = "imu_link"

#: The gains when none are given: :class:`~pinobs.observers.inekf.InEKFGains`' IMU densities,
#: with the foot's noise split as the filter's eqs. (4) and (9) put it.  The encoders' σ_q is
#: measured on the log (``joint_std="log"``); ``kinematics`` is only a floor R_0 under
#: ``J Σ_q Jᵀ`` (10 µm) and ``contact`` one under the slip term ``|ṗ_j|² h`` (1e-4 m/s/√Hz:
#: 5 µm per sample at 400 Hz).  Chosen on the MuJoCo go1 (stand, sway, trot, 10 s, seed 0;
#: docs/benchmarks/legged.md): stance rows inside their 95 % χ² interval 86 / 87 / 83 %
#: (the white 0.1 m/s/√Hz and 1 mm before: 0 %); R_0 of 0, 10 or 30 µm changed that by ≤ 1 %.
#: The real Go1 log was not used to choose them.  ``imu_noise="log"`` replaces the IMU's
#: densities by those measured on the log (with the filter's eq. 10; off by default).
LEGGED_GAINS = InEKFGains(contact=1e-4, kinematics=1e-5)


def _contacts(robot: Robot, log: Log, on: float | None, off: float | None) -> np.ndarray:
    """Contact flags ``(N, feet)``: the log's, else from its foot forces."""
    if log.contact is not None:
        return contacts_from_forces(log.contact, 0.5, 0.25)  # 0/1 flags; NaN keeps
    if log.foot_force is None:
        raise LogFormatError(
            "inekf needs the feet's contacts: give force.<foot frame> [N] or "
            "contact.<foot frame> (0/1) columns (pinobs.io.readers.legged)"
        )
    d_on, d_off = default_thresholds(robot)
    on = d_on if on is None else on
    off = (d_off if on == d_on else 0.5 * on) if off is None else off
    return contacts_from_forces(log.foot_force, on, off)


def _start_pose(q0: Vector, acc: Vector, placement: tuple[Vector, Vector]) -> Vector:
    """The first row's free-flyer ``q``: the log's base pose if finite, else gravity-aligned."""
    q = q0.copy()
    if np.all(np.isfinite(q[:7])):
        return q
    up = acc / np.linalg.norm(acc)  # the world's z in the IMU frame (at rest)
    # R_imu: world from IMU with yaw 0; its last row is up (R_imu^T e_z = up)
    x = np.cross([0.0, 1.0, 0.0], up)
    if np.linalg.norm(x) < 1e-9:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(up, x)
    R_imu = np.vstack([x, y, up])
    R_bi, _ = placement
    q[:3] = 0.0
    q[3:7] = rotation_to_quaternion(R_imu @ R_bi.T)  # the root's from the IMU's
    return q


def estimate_legged(
    robot: Robot,
    log: Log,
    *,
    imu_frame: str | None = None,
    contact_on: float | None = None,
    contact_off: float | None = None,
    gains: InEKFGains | None = None,
    contacts: str = "force",
    probability: ContactProbability | None = None,
    foot_gate: float | None = None,
    joint_std: ArrayLike | str | None = "log",
    slip_speed: bool = True,
    imu_noise: str | None = None,
    foot_radius: float | str = FOOT_RADIUS_URDF,
    rolling_lift: bool = True,
) -> LogRun:
    """The free-flyer estimate over a legged log (module docstring).

    Args:
        robot: a robot with a free-flyer root (``pinobs.load("go1")``).
        log: read with its legged columns (:func:`pinobs.io.read_log`).
        imu_frame: the IMU's frame; default ``imu_link`` if the model has it, else the root.
        contact_on, contact_off: force thresholds [N] (:mod:`pinobs.observers.contacts`).
        gains: the filter's noise levels (:class:`~pinobs.observers.inekf.InEKFGains`;
            default :data:`LEGGED_GAINS` with the gyro's and accelerometer's densities
            measured on the log's stillest second, where it has one).
        contacts: ``"force"`` or ``"probability"`` (module docstring).
        probability: its parameters (default :meth:`ContactProbability.for_robot`).
        foot_gate: the filter's foot gate (outlier probability; ``None``: off).
        joint_std: the encoders' σ per joint [rad] in the filter's foot noise
            ``J Σ_q Jᵀ``: ``"log"`` (default) measured on the log's joint columns where
            they move least (:func:`~pinobs.observers.noise.still_noise_std`),
            ``"first-second"`` over its first second
            (:func:`~pinobs.observers.noise.joint_noise_std`, kf's σ rule), an array (one
            per joint), or ``None``: ``gains.joint`` for every joint.
        slip_speed: the filter's ``slip_speed`` (each foot's contact noise grows with its
            predicted speed; ``False``: the white ``gains.contact`` alone, as before).
        imu_noise: ``"log"``: the gyro's and accelerometer's densities measured on the log's
            stillest second (replacing those of ``gains``), and the gyro's taken out of the
            feet's speeds (the filter's ``slip_gyro``, eq. 10); ``None`` (default): ``gains``'.
            Off by default: the real Go1 log's stillest second gives densities (gyro 3.6e-4,
            accelerometer 1.1e-3 per √Hz) far below what its walking shows, and the filter
            then trusts its IMU so that SEROW's contact probability loses the feet and the
            velocity runs away (``benchmarks/legged_truth.md``).
        foot_radius: the feet's sphere radius [m] (the filter's ``foot_radius``: each foot
            measured at its point that touched the ground), or ``"urdf"`` (default): the
            radius of the feet's collision spheres in the robot's URDF, 0 where a foot has
            none.  Default the URDF's, not the filter's 0: on the MuJoCo go1 it lowers the
            trot's base velocity error 0.0123 → 0.0084 m/s and the sway's 0.0112 → 0.0090,
            the stand's unchanged (module docstring); ``0``: the foot frames, as before.
        rolling_lift: the filter's (rolling.py's R5), default ``True``; ``False``: R4 alone.

    Raises:
        LogFormatError: no IMU columns, no contact or force columns (no force columns
            with ``contacts="probability"``).
        OptionError: ``contacts`` not one of :data:`CONTACT_MODES`, a ``joint_std`` string
            not in :data:`JOINT_STD_RULES`, or one on a log too short to measure σ_q from; a
            ``foot_radius`` that is neither a number nor ``"urdf"``, or ``"urdf"`` with feet
            whose spheres differ (the filter takes one radius).
        GainError: a negative ``joint_std``; a ``foot_radius`` that is negative or not finite.
        UnsupportedRobotError: a robot without a free-flyer root (the filter's).
        UnknownNameError: a foot or IMU frame not in the model.
    """
    return legged_run(
        robot,
        log,
        imu_frame=imu_frame,
        contact_on=contact_on,
        contact_off=contact_off,
        gains=gains,
        contacts=contacts,
        probability=probability,
        foot_gate=foot_gate,
        joint_std=joint_std,
        slip_speed=slip_speed,
        imu_noise=imu_noise,
        foot_radius=foot_radius,
        rolling_lift=rolling_lift,
    ).run


class LeggedDetail(NamedTuple):
    """:func:`legged_run`'s result: the run and, per log row, what the filter was given and said.

    Attributes:
        run: the :class:`~pinobs.io.LogRun` (:func:`estimate_legged`'s).
        contacts: the contact flags used ``(N, feet)`` (in the order of ``log.feet``).
        nis: the feet's NIS per row (NaN where no foot was measured).
        nis_dof: its degrees of freedom per row (3 × feet measured; 0: none).
    """

    run: LogRun
    contacts: np.ndarray
    nis: np.ndarray
    nis_dof: np.ndarray


def _make_filter(
    robot: Robot,
    fixed: Robot,
    log: Log,
    imu_frame: str | None,
    gains: InEKFGains | None,
    foot_gate: float | None,
    joint_std: ArrayLike | str | None,
    slip_speed: bool,
    imu_noise: str | None,
    foot_radius: float | str,
    rolling_lift: bool = True,
) -> tuple[InvariantEKF, list[str]]:
    """:func:`legged_run`'s filter, and what its set-up measured on the log (said once)."""
    radius, said_r = _foot_radius(robot, log.feet, foot_radius)
    sigma_q, said_q = _joint_std(fixed, log, joint_std)
    gains, said_g = _imu_gains(fixed, log, gains, imu_noise)
    imu_frame = IMU_FRAME if imu_frame is None and robot.model.existFrame(IMU_FRAME) else imu_frame
    filt = InvariantEKF(
        robot,
        log.feet,
        gains=gains,
        imu_frame=imu_frame,
        foot_gate=foot_gate,
        joint_std=sigma_q,
        slip_speed=slip_speed,
        foot_radius=radius,
        slip_gyro=gains.gyro if imu_noise == "log" else 0.0,
        rolling_lift=rolling_lift,
    )
    return filt, [*said_q, *said_g, *said_r]


def legged_run(
    robot: Robot,
    log: Log,
    *,
    imu_frame: str | None = None,
    contact_on: float | None = None,
    contact_off: float | None = None,
    gains: InEKFGains | None = None,
    contacts: str = "force",
    probability: ContactProbability | None = None,
    foot_gate: float | None = None,
    joint_std: ArrayLike | str | None = "log",
    slip_speed: bool = True,
    imu_noise: str | None = None,
    foot_radius: float | str = FOOT_RADIUS_URDF,
    rolling_lift: bool = True,
) -> LeggedDetail:
    """:func:`estimate_legged` (same arguments), with the contacts and the NIS per row."""
    if log.imu_gyro is None or log.imu_acc is None:
        raise LogFormatError(
            "inekf needs the trunk IMU: imu.gyro.x|y|z [rad/s] and imu.acc.x|y|z [m/s²] columns"
        )
    prob, flags = _contact_setup(robot, log, contacts, probability, contact_on, contact_off)
    feet = (joint_std, slip_speed, imu_noise, foot_radius, rolling_lift)
    fixed = _joints_robot(robot)  # (built once: σ_q, the IMU's densities and the joints' kf)
    filt, said_setup = _make_filter(robot, fixed, log, imu_frame, gains, foot_gate, *feet)
    joints = _joint_velocities(fixed, log)
    n = len(log)
    bad: list[tuple[int, str]] = list(joints.bad_rows)
    usable = (
        np.isfinite(log.t)
        & np.all(np.isfinite(log.imu_gyro), axis=1)
        & np.all(np.isfinite(log.imu_acc), axis=1)
        & np.all(np.isfinite(log.q[:, 7:]), axis=1)
    )
    previous: float | None = None
    said: list[str] = [*joints.warnings, *said_setup]
    rows, out = _Rows(log, joints.v, prob, _preloading(filt), usable), _Outputs()
    # (Python floats, bools and flag lists: per-row reads; "probability" sets the flags' rows)
    times, fed, now = log.t.tolist(), usable.tolist(), flags.tolist()
    for k in range(n):
        if not k % PRELOAD_ROWS:  # (a block's first row)
            rows.preload(k)
        if not fed[k] or (previous is not None and times[k] <= previous):
            bad.append((int(log.lines[k]), _why(log, k, usable[k])))
            if prob is not None and k:
                now[k] = now[k - 1]
            continue
        if prob is not None:
            now[k] = rows.probable(filt, prob, k, now[k - 1] if k else None)
        est = _step(filt, robot, log, k, now[k], rows, previous is None)
        if est is None:
            said.append(f"inekf diverged at t = {log.t[k]:.6g} s: the rows after it are NaN")
            bad.extend((int(log.lines[j]), "after the filter diverged") for j in range(k, n))
            break
        previous = times[k]
        out.add(k, est)
    if prob is not None:
        flags[:] = now
    q_out, v_out, nis, dof, gated = out.arrays(robot, n, joints.v, rows.q)
    frame = getattr(filt.kinematics, "imu_frame", None) or robot.model.names[1]
    said += contact_notes(flags, log) + frame_notes(filt.kinematics, log, flags, frame)
    done = int(np.all(np.isfinite(q_out), axis=1).sum())
    run = LogRun(
        t=log.t.copy(),
        q=q_out,
        v=v_out,
        bad_rows=sorted(set(bad)),
        warnings=said,
        rows=n,
        estimated=done,
        measured=done,
        unit=log.unit,
        period=joints.period,
        consistency=stance_consistency(nis, dof, gated),
    )
    return LeggedDetail(run, flags, nis, dof)


class _Outputs:
    """The estimates of the rows fed, kept per row as Python lists and made :func:`legged_run`'s
    arrays at the end: the reset's ``q`` and ``v`` (an estimate's fields only: it holds the
    filter's covariance), then each update's root rows and quaternion
    (:meth:`~pinobs.observers.inekf.InvariantEKF.update_rows`: no estimate made)."""

    def __init__(self) -> None:
        self.rows: list[int] = []
        self.nis: list[float] = []
        self.dof: list[int] = []
        self.gated = 0
        #: the rows given as estimates (the reset's), their q and v
        self.full: list[int] = []
        self.q: list[Vector] = []
        self.v: list[Vector] = []
        #: the rows given as update_rows' (base, quat)
        self.based: list[int] = []
        self.bases: list[Vector] = []
        self.quats: list[Vector] = []

    def add(self, k: int, est: Any) -> None:
        """Row ``k``'s estimate (an :class:`~pinobs.observers.legs.InEKFEstimate`), or
        ``update_rows``' tuple ``(base, quat, nis, nis_dof, gated)``."""
        self.rows.append(k)
        if isinstance(est, tuple):
            base, quat, nis, dof, gated = est
            self.based.append(k)
            self.bases.append(base)
            self.quats.append(quat)
        else:
            nis, dof, gated = est.nis, est.nis_dof, est.gated
            self.full.append(k)
            self.q.append(est.q)
            self.v.append(est.v)
        self.nis.append(math.nan if nis is None else nis)
        self.dof.append(dof)
        self.gated += len(gated)

    def arrays(
        self, robot: Robot, n: int, dq: Vector, joints: Vector
    ) -> tuple[Vector, Vector, Vector, np.ndarray, int]:
        """``(q, v, nis, dof, gated)`` over the ``n`` rows: NaN (dof 0) where none was fed;
        ``v``'s joints those of ``dq`` (what update passes through; reset shows none); the
        rows of ``update_rows`` as :meth:`~pinobs.observers.legs.LeggedSetup.estimate` makes
        an estimate's ``q``, ``v`` (the quaternion's sign ``w >= 0``, the angles ``joints``)."""
        q, v = np.full((n, robot.nq), np.nan), np.full((n, robot.nv), np.nan)
        nis, dof = np.full(n, np.nan), np.zeros(n, dtype=int)
        if self.full:
            q[self.full], v[self.full] = self.q, self.v
        if self.based:
            rows, base, quat = np.array(self.based), np.array(self.bases), np.array(self.quats)
            q[rows, :3], q[rows, 3:7] = base[:, 0], np.where(quat[:, 3:] < 0, -quat, quat)
            q[rows, 7:] = joints[rows]
            v[rows, :3], v[rows, 3:6] = base[:, 2], base[:, 1]
        if self.rows:
            rows = np.array(self.rows)
            nis[rows], dof[rows] = self.nis, self.dof
            v[rows, 6:] = dq[rows]
        return q, v, nis, dof, self.gated


def _contact_setup(
    robot: Robot,
    log: Log,
    contacts: str,
    probability: ContactProbability | None,
    contact_on: float | None,
    contact_off: float | None,
) -> tuple[ContactProbability | None, np.ndarray]:
    """The contact model and the flags per row: from the forces' thresholds now, or (mode
    ``"probability"``) all clear, to be set row by row as the filter runs."""
    if contacts not in CONTACT_MODES:
        raise OptionError(f"contacts={contacts!r}: choose one of {', '.join(CONTACT_MODES)}")
    if contacts != "probability":
        return None, _contacts(robot, log, contact_on, contact_off)
    if log.foot_force is None:
        raise LogFormatError("contacts='probability' needs force.<foot frame> [N] columns")
    prob = ContactProbability.for_robot(robot) if probability is None else probability
    return prob, np.zeros((len(log), len(log.feet)), dtype=bool)


def _preloading(filt: InvariantEKF) -> FootKinematics | None:
    """The filter's legs if its rolling feet read their shared placements (what
    :meth:`_Rows.preload` fills), else ``None``."""
    kinematics = filt.kinematics
    if filt.setup.rolling is None or not isinstance(kinematics, FootKinematics):
        return None
    return kinematics


def _why(log: Log, k: int, usable: bool) -> str:
    if not usable:
        return "no IMU reading or joint angle: not fed to inekf"
    return f"time {log.t[k]!r} does not advance: not fed to inekf"


class _Rows:
    """The log's rows as the filter's checked inputs (:class:`UpdateInputs`), checked once for
    the whole log: the joint angles, the readings ``(gyro, acc)`` and the joint velocities
    (rows, not copies; C-contiguous as :meth:`Robot.check_vector` makes them), and which
    velocity rows are finite.  The rows fed are the usable ones (finite time, IMU and
    angles: :func:`legged_run`'s ``usable``), so each ``update``'s own checks would pass;
    the time is checked per row (:func:`check_time`), as ``update`` does."""

    def __init__(
        self,
        log: Log,
        dq: Vector,
        prob: ContactProbability | None = None,
        kinematics: FootKinematics | None = None,
        usable: np.ndarray | None = None,
    ) -> None:
        assert log.imu_gyro is not None and log.imu_acc is not None
        self.q = np.ascontiguousarray(log.q[:, 7:], dtype=float)
        #: the legs whose placements :meth:`preload` computes a block at a time (``None``:
        #: none), and the rows fed (the others' angles are not asked for)
        self._kinematics = kinematics
        self._usable = np.ones(len(self.q), dtype=bool) if usable is None else usable
        self.reading = np.ascontiguousarray(np.hstack([log.imu_gyro, log.imu_acc]), dtype=float)
        self.dq = np.ascontiguousarray(dq, dtype=float)
        self.dq_finite = np.all(np.isfinite(self.dq), axis=1).tolist()
        #: with ``contacts="probability"``: each row's force factor of ``p``
        #: (:meth:`ContactProbability.force_factor`), for the whole log at once
        self.force_factor: list[list[float]] = []
        if prob is not None and log.foot_force is not None:
            self.force_factor = prob.force_factor(log.foot_force).tolist()

    def preload(self, k: int) -> None:
        """At a block's first row ``k``: the feet's placements and Jacobians of its usable rows
        (:data:`PRELOAD_ROWS` from ``k``) computed at once
        (:meth:`pinobs.model.FootKinematics.preload`: the same values the filter's calls
        then find, without a call's NumPy work each row)."""
        if self._kinematics is None or k % PRELOAD_ROWS:
            return
        block = slice(k, k + PRELOAD_ROWS)
        self._kinematics.preload(self.q[block][self._usable[block]])

    def probable(
        self, filt: InvariantEKF, prob: ContactProbability, k: int, previous: list[bool] | None
    ) -> list[bool]:
        """Row ``k``'s flags from its forces and the feet's speeds the filter predicts (the
        first row, or without joint velocities: the force alone, speed 0): ``p > ½``, a NaN
        ``p`` keeping the foot's ``previous`` flag (False on the first row):
        :func:`~pinobs.observers.contacts.contact_flags` of ``prob(force, speed)``."""
        feet = len(self.force_factor[k])
        if previous is not None and self.dq_finite[k]:
            speed = filt.foot_speeds_checked(self.q[k], self.dq[k], self.reading[k])
        else:
            speed = np.zeros(feet)
        before = [False] * feet if previous is None else previous
        return prob.row_flags(self.force_factor[k], speed, before)

    def inputs(self, filt: InvariantEKF, t: float, k: int, flags: list[bool]) -> UpdateInputs:
        """Row ``k`` as ``update`` would check it (its time after the filter's)."""
        dq = self.dq[k] if self.dq_finite[k] else None
        return UpdateInputs(check_time(t, filt.state.t), self.q[k], self.reading[k], flags, dq)


def _step(
    filt: InvariantEKF,
    robot: Robot,
    log: Log,
    k: int,
    flags: list[bool],
    rows: _Rows,
    first: bool,
) -> Any:
    """The filter reset (first row) or updated with row ``k`` (its contact ``flags``);
    ``None`` if it diverged."""
    assert log.imu_gyro is not None and log.imu_acc is not None
    if first:
        gyro, acc = log.imu_gyro[k], log.imu_acc[k]
        dq = rows.dq[k] if rows.dq_finite[k] else None
        # the IMU's placement at the first row's angles (a fixed frame's: imu_placement);
        # a FootKinematics: legged_run's filter is built from a robot
        kin: Any = filt.kinematics
        q0 = _start_pose(log.q[k], acc, kin.imu_motion(log.q[k, 7:])[:2])
        v0 = np.zeros(robot.nv)
        if dq is not None:
            v0[6:] = dq
        return filt.reset(log.t[k], q0, v0, gyro=gyro, acc=acc, contacts=flags)
    try:
        return filt.update_rows(rows.inputs(filt, log.t[k], k, flags))
    except ObserverDiverged:
        return None


def _joints_robot(robot: Robot) -> Robot:
    """The robot with its free-flyer root locked (its joints alone)."""
    names = list(robot.model.names)
    if robot.nq < 7 or len(names) < 2:
        raise DimensionError(f"{robot.name}: inekf needs a free-flyer root joint")
    return load(robot.model, lock=[names[1]])


def _joint_std(
    fixed: Robot, log: Log, joint_std: ArrayLike | str | None
) -> tuple[ArrayLike | None, list[str]]:
    """``joint_std`` for the filter and what to say of it: ``"log"`` → σ̂ per joint from the
    log's stillest second (:func:`~pinobs.observers.noise.still_noise_std`: third
    differences where the joints move least, at least the readings' rounding δ/√12);
    ``"first-second"`` → over the first second (:func:`~pinobs.observers.noise.joint_noise_std`,
    kf's σ rule)."""
    if not isinstance(joint_std, str):
        return joint_std, []
    if joint_std not in JOINT_STD_RULES:
        raise OptionError(
            f"joint_std={joint_std!r}: give {' or '.join(map(repr, JOINT_STD_RULES))}, "
            "σ per joint [rad] or None"
        )
    if joint_std == "log":
        sigma = still_noise_std(log.t, log.q[:, 7:], fixed)
        where = "its stillest second"
    else:
        found = joint_noise_std(log.t, log.q[:, 7:], fixed)
        sigma, where = (None if found is None else found[0]), "its first second"
    if sigma is None:
        raise OptionError(
            f"joint_std={joint_std!r}: the log has too few finite, evenly spaced rows to "
            "measure the encoders' σ from; give joint_std (σ per joint [rad]) or None "
            "(gains.joint)"
        )
    return sigma, [
        f"inekf: the encoders' σ per joint measured on the log ({where}): "
        f"{np.min(sigma):.2g}-{np.max(sigma):.2g} rad; pass joint_std to override"
    ]


def _foot_radius(
    robot: Robot, feet: tuple[str, ...], foot_radius: float | str
) -> tuple[float, list[str]]:
    """The filter's ``foot_radius`` [m] and what to say of it: a number, checked (finite,
    ``>= 0``), or ``"urdf"``: the feet's collision spheres
    (:func:`pinobs.model.foot_sphere_radius`), which must agree (one radius per filter); 0,
    said, for a robot whose feet the URDF does not tell."""
    if isinstance(foot_radius, str):
        if foot_radius != FOOT_RADIUS_URDF:
            raise OptionError(
                f"foot_radius={foot_radius!r}: give {FOOT_RADIUS_URDF!r} (the URDF's foot "
                "spheres) or a radius [m] >= 0"
            )
        try:
            radii = foot_sphere_radii(robot, feet)  # (the URDF read once)
        except PinobsError as exc:  # not a URDF robot, a foot frame not a link: no sphere known
            return 0.0, [
                f"inekf: foot_radius='urdf' but {robot.name}'s foot spheres are not known "
                f"({str(exc).split(';')[0]}): the foot frames measured (radius 0); pass "
                "foot_radius [m]"
            ]
        if len(set(radii.values())) > 1:
            raise OptionError(
                f"foot_radius='urdf': the URDF's foot spheres differ ({radii}) and the filter "
                "takes one radius; give foot_radius [m]"
            )
        radius = next(iter(radii.values()), 0.0)
        if radius <= 0:
            return 0.0, []
        return radius, [
            f"inekf: the feet measured where they touched the ground (rolling spheres of "
            f"{radius:g} m, the URDF's); pass foot_radius=0 for the foot frames"
        ]
    return float(positive("foot_radius", foot_radius, allow_zero=True) or 0.0), []


def _imu_gains(
    fixed: Robot, log: Log, gains: InEKFGains | None, imu_noise: str | None
) -> tuple[InEKFGains, list[str]]:
    """``gains`` (default :data:`LEGGED_GAINS`), with ``imu_noise="log"`` the gyro's and
    accelerometer's white densities measured on the log's stillest second
    (:func:`~pinobs.observers.noise.stillest_rows`, the joints'):
    ``σ_a = √(mean over the axes of σ̂²) · √T``, ``σ̂`` each axis' per-sample σ (robust third
    differences, :func:`pinobs.model.noise.third_difference_std`), ``T`` the sample period
    (a reading held over ``T`` has variance ``σ_a²/T``); kept where the log does not tell."""
    assert log.imu_gyro is not None and log.imu_acc is not None
    base = LEGGED_GAINS if gains is None else gains
    if imu_noise is None:
        return base, []
    if imu_noise != "log":
        raise OptionError(f"imu_noise={imu_noise!r}: give 'log' or None")
    rows = stillest_rows(log.t, log.q[:, 7:], fixed)
    if rows is None:
        return base, []
    t = log.t[rows]
    period = float(np.median(np.diff(t))) if rows.size > 1 else math.nan
    found = {}
    for name, x in (("gyro", log.imu_gyro), ("accel", log.imu_acc)):
        sigma = third_difference_std(x[rows], t, rows, min_runs=9)
        if sigma is not None and np.isfinite(period) and np.all(sigma > STILL_STD):
            found[name] = float(np.sqrt(np.mean(sigma**2) * period))
    if not found:
        return base, []
    return replace(base, **found), [
        "inekf: the IMU's white noise densities measured on the log (its stillest second): "
        + ", ".join(f"{k} {v:.2g}" for k, v in found.items())
        + " (per √Hz); pass gains to override"
    ]


def _joint_velocities(fixed: Robot, log: Log) -> LogRun:
    """``kf`` over the joint columns: the robot with its free-flyer root locked."""
    joint_log = replace(
        log,
        q=log.q[:, 7:],
        tau=None,
        imu_gyro=None,
        imu_acc=None,
        foot_force=None,
        contact=None,
        feet=(),
        notes=(),
    )
    with warnings.catch_warnings(record=True) as caught:  # (kf's σ from the log: said in
        warnings.simplefilter("always")  # the run's warnings, as the rest of the run's are)
        run = estimate_log(make_observer("kf", fixed), joint_log)
    return replace(run, warnings=[*run.warnings, *(str(w.message) for w in caught)])


__all__ = [
    "CONTACT_MODES",
    "FOOT_RADIUS_URDF",
    "IMU_FRAME",
    "JOINT_STD_RULES",
    "LEGGED_GAINS",
    "LeggedDetail",
    "estimate_legged",
    "legged_run",
]

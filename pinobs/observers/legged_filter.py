""":class:`LeggedFilter`, the thin base of the two contact-aided filters
(:class:`pinobs.observers.inekf.InvariantEKF`, :class:`pinobs.observers.qekf.QuaternionEKF`).

It runs their common sample (:meth:`LeggedFilter.update`: propagate with the held reading,
marginalise the feet that lifted off, remove the gated ones, update with those that stay,
add the new and the gated ones, store the reading, check and convert the estimate); a family
gives only its mathematics (``_initial_covariance``, ``_propagate``, ``_update``,
``_foot_noise``; optionally ``_landing_attitude``, ``_legs``, ``_gate``, ``_remember``).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from pinobs.model import Robot
from pinobs.observers.base import Vector
from pinobs.observers.imu_link import smoothed
from pinobs.observers.legs import (
    GRAVITY,
    ContactKinematics,
    InEKFEstimate,
    InEKFGains,
    InEKFPrior,
    LeggedSetup,
    LegState,
    ResetInputs,
    UpdateInputs,
    remove_feet,
    replace_state,
)

__all__ = ["LeggedFilter", "landing_densities"]

_I3 = np.eye(3)


def landing_densities(
    qc: Vector, gains: InEKFGains, landed: Sequence[float], start: float, h: float
) -> Vector:
    """``Q_c`` (:func:`~pinobs.observers.legs.noise_densities`, feet in state order) with each foot's density raised
    by ``gains.landing²`` over the part of the step ``[start, start + h]`` that falls in its
    first ``gains.landing_time`` of contact (``landed``: each foot's contact start [s], one per
    foot in the state), as a fraction of the step: the variance the step adds is then that
    of a walk of density ``landing`` over exactly that window, whatever the sampling;
    read-only.  ``qc`` itself where no foot is in its window or ``landing`` or
    ``landing_time`` is 0 (scalar arithmetic: a few feet, every sample)."""
    window = gains.landing_time
    if gains.landing == 0.0 or window == 0.0 or h <= 0.0:
        return qc
    shares = [min(max((t0 + window - start) / h, 0.0), 1.0) for t0 in landed]
    if not any(shares):
        return qc
    out = np.array(qc, dtype=float)
    for i, share in enumerate(shares):
        if share:
            out[9 + 3 * i : 12 + 3 * i] += share * gains.landing**2
    out.setflags(write=False)
    return out


class LeggedFilter(ABC):
    """A contact-aided filter's ``reset``/``update`` around its family's mathematics (module
    docstring).  Takes the arguments of :class:`pinobs.observers.inekf.InvariantEKF` that both
    families take (there in full).

    Raises:
        GainError: an ``imu_hold`` that is neither ``"previous"`` nor ``"average"``.
        UnknownNameError: a foot frame that is not in the model (names the frames).
        UnsupportedRobotError: a robot without a free-flyer root joint.
    """

    def __init__(
        self,
        robot: Robot | ContactKinematics,
        feet: Sequence[str] | None = None,
        *,
        gains: InEKFGains | None = None,
        gravity: ArrayLike = GRAVITY,
        imu_hold: str = "previous",
        imu_frame: str | None = None,
        foot_radius: float = 0.0,
        rolling_lift: bool = True,
    ) -> None:
        #: the legs, options and conversions (:class:`pinobs.observers.legs.LeggedSetup`)
        self.setup = LeggedSetup(
            type(self).__name__,
            robot,
            feet,
            gains=gains,
            gravity=gravity,
            imu_hold=imu_hold,
            imu_frame=imu_frame,
            foot_radius=foot_radius,
            rolling_lift=rolling_lift,
        )
        s = self.setup
        self.imu_hold, self.kinematics = s.imu_hold, s.kinematics
        self.gains, self.gravity = s.gains, s.gravity
        self.feet, self.imu_placement = s.feet, s.imu_placement
        self._state: LegState | None = None
        #: each foot's contact start [s] (``InEKFGains.landing``; ``-inf``: not yet)
        self._landed = [-math.inf] * len(self.feet)
        self._estimate: InEKFEstimate | None = None
        #: :meth:`setup.estimate`'s arguments for the last estimate, not made yet (:meth:`update_rows`)
        self._pending: tuple[Any, ...] | None = None
        self._warned = False
        #: the lever arm's gyro low-passed (imu_link.py's (M4): an IMU frame off the root, τ > 0)
        self._smooths = s.imu_off_root and self.gains.lever_tau > 0

    def __repr__(self) -> str:
        return f"{type(self).__name__}(feet={self.feet})"

    @property
    def state(self) -> LegState:
        """The current state (raises before ``reset``)."""
        if self._state is None:
            raise self.setup.not_reset()
        return self._state

    @property
    def estimate(self) -> InEKFEstimate:
        """The last estimate (raises before ``reset``; made now if :meth:`update_rows` left it)."""
        if self._estimate is None:
            if self._pending is None:
                raise self.setup.not_reset()
            self._estimate = self.setup.estimate(*self._pending)  # (finite: checked then)
            self._pending = None
        return self._estimate

    def _last(self) -> InEKFEstimate | None:
        """The last estimate (:attr:`estimate`), ``None`` before ``reset``."""
        return None if self._estimate is None and self._pending is None else self.estimate

    def reset(
        self,
        t: float,
        q: ArrayLike,
        v: ArrayLike | None = None,
        *,
        gyro: ArrayLike | None = None,
        acc: ArrayLike | None = None,
        contacts: Mapping[str, bool] | Sequence[bool] | None = None,
        prior: InEKFPrior | None = None,
        bias: ArrayLike | None = None,
    ) -> InEKFEstimate:
        """Start at time ``t`` [s] from the free-flyer configuration ``q`` (``nq`` entries:
        base pose, joint angles) and velocity ``v`` (``nv``: base-frame linear and angular,
        joints; zero if not given).

        Args:
            gyro: the gyro reading at ``t`` [rad/s], held until the first update (given
                with ``acc`` or not at all).
            acc: the accelerometer reading at ``t`` [m/s²], held likewise.
            contacts: feet in contact at ``t`` (added to the state), as in :meth:`update`.
            prior: initial uncertainty (:class:`InEKFPrior`).
            bias: initial ``(b_g, b_a)`` [rad/s, m/s²] (zero if not given).

        Raises:
            DimensionError: an input of the wrong shape (named).
            ConfigurationError: ``q[3:7]`` not a unit quaternion.
            UnknownNameError: contacts naming an unknown foot or missing one.
            GainError: a ``prior`` that is not an :class:`InEKFPrior`.
        """
        a = self.setup.reset_inputs(t, q, v, gyro, acc, contacts, prior, bias)
        P = self._initial_covariance(a)
        lever = smoothed(None, a.imu, 0.0) if self._smooths and a.imu is not None else None
        state = LegState(a.t, a.R, a.x, (), a.bias, P, a.imu, a.t, lever)
        self._landed = [-math.inf] * len(self.feet)
        h, jac = self._legs(a.q_joints, a.R, a.flags)
        self._remember(None, h)
        state = self._add_feet(state, [j for j, f in enumerate(a.flags) if f], h, jac)
        self._commit(state, a.q_joints, None, None, a.imu, a.t if state.feet else None, rates=a.dq)
        self.setup.settle(state.R)
        self._warned = False
        return self.estimate

    def update(
        self,
        t: float,
        q: ArrayLike,
        gyro: ArrayLike,
        acc: ArrayLike,
        contacts: Mapping[str, bool] | Sequence[bool],
        *,
        joint_velocities: ArrayLike | None = None,
    ) -> InEKFEstimate:
        """One sample: propagate to ``t`` [s] with the held IMU reading, correct with the feet
        in contact, store this reading.

        Args:
            t: time [s], after the previous one.
            q: joint angles (``nq − 7``) or a full free-flyer ``q`` (``nq``; its base part
                is ignored).
            gyro: angular velocity in the IMU's frame [rad/s], shape ``(3,)``.
            acc: specific force in the IMU's frame [m/s²] (``Rᵀ(p̈ − g)``: +9.81 up at rest),
                shape ``(3,)``.
            contacts: each foot name → in contact (every foot named), or a sequence of
                bools in the order of ``feet``.
            joint_velocities: passed through to ``estimate.v[6:]`` (NaN if not given); with an
                IMU frame that moves (:mod:`~pinobs.observers.imu_link`), the root's twist
                ``v[0:6]`` takes them too (NaN without them).

        Raises:
            NotResetError: before ``reset``.
            DimensionError: an input of the wrong shape (named), a contacts sequence of the
                wrong length or a non-bool flag.
            UnknownNameError: contacts naming a foot that is not one of ``feet``, or
                missing one.
            TimestampError: ``t`` not after the previous update.
            ObserverDiverged: a non-finite estimate (the state is left as it was).
        """
        state = self.state
        return self.update_checked(
            self.setup.update_inputs(state.t, t, q, gyro, acc, contacts, joint_velocities)
        )

    def update_checked(self, u: UpdateInputs) -> InEKFEstimate:
        """:meth:`update` with its arguments already checked, as
        :meth:`~pinobs.observers.legs.LeggedSetup.update_inputs` returns them: for a caller
        that has checked a whole log at once (:func:`pinobs.io.legged_run.legged_run`, through
        :meth:`update_rows`), which then answers for what :meth:`update` checks each sample (``u.t`` after the state's by
        more than ``TIME_EPS``, finite arrays of the right shapes, one bool per foot).  The
        arrays are read, not copied, and must not change while the filter holds them (the
        reading is kept until the next sample).

        Raises:
            NotResetError: before ``reset``.
            ObserverDiverged: a non-finite estimate (the state is left as it was).
        """
        state = self.state
        new, h, nis, used, gated, lever = self._advance(state, u)
        contact_time = u.t if any(u.flags) else None
        self._commit(
            new,
            u.q_joints,
            u.joint_velocities,
            nis,
            u.reading,
            contact_time,
            used,
            gated,
            lever=lever,
        )
        self.setup.settle(new.R)
        self._remember(u, h, u.t - state.t)
        return self.estimate

    def update_rows(self, u: UpdateInputs) -> tuple[Vector, Vector, float | None, int, tuple]:
        """:meth:`update_checked`, returning the root's rows instead of an estimate: ``(base,
        quat, nis, nis_dof, gated)``, ``base`` the rows ``p_b, ω_b, v_b, R_b v_b`` and ``quat``
        ``R_b``'s unit quaternion ``xyzw`` before its sign is made ``w >= 0``
        (:meth:`LeggedSetup.base`), ``gated`` indices into ``feet``.  The estimate is made
        only if asked for (:attr:`estimate`): for a log's runner, which keeps ``q`` and ``v``
        alone (:func:`pinobs.io.legged_run.legged_run`).  ``u``'s arrays are read, not copied,
        and must not change until then.

        Raises:
            NotResetError: before ``reset``.
            ObserverDiverged: a non-finite estimate (the state is left as it was).
        """
        state = self.state
        new, h, nis, used, gated, lever = self._advance(state, u)
        contact_time = u.t if any(u.flags) else None
        new = self._stored(new, u.reading, contact_time, lever)
        if not self.setup.finite(new):
            raise self.setup.diverged(new, self._last())
        _, base, quat = self.setup.base(new, u.q_joints, u.joint_velocities)
        self._state, self._estimate = new, None
        self._pending = (new, None, u.q_joints, u.joint_velocities, nis, 3 * used, gated)
        self.setup.settle(new.R)
        self._remember(u, h, u.t - state.t)
        return base, quat, nis, 3 * used, gated

    def _advance(
        self, state: LegState, u: UpdateInputs
    ) -> tuple[LegState, Vector, float | None, int, tuple[int, ...], Vector | None]:
        """The state propagated to ``u.t`` and corrected (not stored), the feet's positions
        ``h`` (:meth:`_legs`), the NIS, the number of feet measured and those gated, and the
        lever arm's low-passed gyro to store (imu_link.py's (M4); ``None``: none)."""
        new = self._propagate(state, self.setup.held(state, u.reading), u.t - state.t, u.t)
        h, jac = self._legs(u.q_joints, new.R, u.flags)
        new, nis, used, gated = self._correct(new, u.flags, h, jac)
        lever = None
        if self._smooths:  # imu_link.py's (M4)
            lever = smoothed(state.lever, u.reading, u.t - state.t, self.gains.lever_tau)
        self._warned = self.setup.warn_without_contact(self._warned, u.t, u.flags, new.last_contact)
        return new, h, nis, used, gated, lever

    # ------------------------------------------------------ the family's part
    @abstractmethod
    def _initial_covariance(self, a: ResetInputs) -> Vector:
        """The covariance of the error (no feet) at ``reset`` from ``a.prior``."""

    @abstractmethod
    def _propagate(self, state: LegState, imu: Vector, dt: float, t: float) -> LegState:
        """Mean and covariance over ``dt`` [s] with the reading ``imu`` held, to time ``t``."""

    @abstractmethod
    def _update(
        self, state: LegState, measured: list[int], h: Vector, jac: Vector
    ) -> tuple[LegState, float]:
        """One update with every foot in the state (``measured``, in state order), and its NIS."""

    @abstractmethod
    def _foot_noise(self, R: Vector, jac: Vector) -> Vector:
        """A foot's measurement noise in the world frame, ``R N_j Rᵀ``, from its Jacobian
        ``J_j`` (3, n)."""

    def _landing_attitude(self, R: Vector, h: Vector) -> Vector | None:
        """The block of a landing foot's error on the attitude error (``None``: none, as the
        invariant error's)."""
        return None

    def _legs(self, q_joints: Vector, R: Any = None, flags: Any = None) -> tuple[Vector, Vector]:
        """The feet's positions and Jacobians (:meth:`LeggedSetup.legs`)."""
        return self.setup.legs(q_joints, R, flags)

    def _gate(self, state: LegState, h: Vector, jac: Vector) -> tuple[LegState, tuple[int, ...]]:
        """The feet a gate rejects, removed (to be re-anchored), and their indices into
        ``feet``; here none."""
        return state, ()

    def _landing(self, qc: Vector, state: LegState, dt: float) -> Vector:
        """``Q_c`` with the landing term of the feet in ``state`` over the step from
        ``state.t`` (:func:`landing_densities`)."""
        if self.gains.landing == 0.0 or self.gains.landing_time == 0.0:
            return qc  # (landing_densities' own answer, without the list)
        landed = [self._landed[j] for j in state.feet]
        return landing_densities(qc, self.gains, landed, state.t, dt)

    def _remember(self, u: UpdateInputs | None, h: Vector, dt: float = 0.0) -> None:
        """What the next step needs of this one (after the commit; ``u`` ``None`` at
        ``reset``, before the feet are added); here nothing."""
        return

    # ----------------------------------------------------------- the shared part
    def _correct(
        self, state: LegState, flags: list[bool], h: Vector, jac: Vector
    ) -> tuple[LegState, float | None, int, tuple[int, ...]]:
        """Contacts ended are removed, those gated removed too (:meth:`_gate`), one update
        with those that continue, and new ones and the gated added.  Returns the state, the
        NIS, the number of feet measured and those gated (indices into ``feet``)."""
        ended = [s for s, j in enumerate(state.feet) if not flags[j]]
        if ended:
            state = remove_feet(state, ended)
        state, gated = self._gate(state, h, jac)
        measured = list(state.feet)
        nis = None
        if measured:
            state, nis = self._update(state, measured, h, jac)
        new = [j for j, f in enumerate(flags) if f and j not in measured]
        if new:
            state = self._add_feet(state, new, h, jac)
        return state, nis, len(measured), gated

    def _add_feet(self, state: LegState, new: list[int], h: Vector, jac: Vector) -> LegState:
        """The feet ``new`` (indices into ``feet``) added before the biases at
        ``d̂_j = p̂ + R̂ h_j``, their error ``δp``'s plus the family's attitude block
        (:meth:`_landing_attitude`) plus their noise: ``P ← F P Fᵀ + R N_j Rᵀ`` (the invariant
        EKF's eq. 6, the quaternion EKF's eq. 5)."""
        R, x, P = state.R, state.x, state.P
        for j in new:
            n = P.shape[0]
            at = n - 6  # the new block goes before the biases
            F = np.zeros((n + 3, n))
            F[:at, :at] = np.eye(at)
            attitude = self._landing_attitude(R, h[j])
            if attitude is not None:
                F[at : at + 3, 0:3] = attitude
            F[at : at + 3, 6:9] = _I3
            F[at + 3 :, at:] = np.eye(6)
            P = F @ P @ F.T
            P[at : at + 3, at : at + 3] += self._foot_noise(R, jac[j])
            x = np.vstack([x, x[1] + R @ h[j]])
            self._landed[j] = state.t
        return replace_state(state, x=x, P=P, feet=state.feet + tuple(new))

    def _commit(
        self,
        state: LegState,
        q_joints: Vector,
        dq: Vector | None,
        nis: float | None,
        reading: Vector | None,
        contact_time: float | None,
        measured: int = 0,
        gated: tuple[int, ...] = (),
        rates: Vector | None = None,
        lever: Vector | None = None,
    ) -> None:
        """Store the new state with the reading to hold (and the time of a contact, if any;
        ``lever``: the lever arm's low-passed gyro, if any) and its estimate
        (ObserverDiverged, the state left as it was, if not finite); ``rates``: the joints'
        velocities for a moving IMU frame's root twist (``dq`` if not given; reset's
        ``v[6:]``)."""
        state = self._stored(state, reading, contact_time, lever)
        estimate = self.setup.estimate(
            state, self._last(), q_joints, dq, nis, 3 * measured, gated, rates
        )
        self._state, self._estimate, self._pending = state, estimate, None

    @staticmethod
    def _stored(
        state: LegState,
        reading: Vector | None,
        contact_time: float | None,
        lever: Vector | None = None,
    ) -> LegState:
        """``state`` with the reading to hold, the time of a contact and the lever arm's
        low-passed gyro (each if any: one copy of the fields)."""
        return replace_state(
            state,
            imu=reading if reading is not None else state.imu,
            last_contact=state.last_contact if contact_time is None else contact_time,
            lever=state.lever if lever is None else lever,
        )

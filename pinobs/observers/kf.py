"""Per-joint constant-acceleration Kalman filter: the strongest model-free baseline.

Each tangent direction i carries ``x_i = (δq_i, v_i, a_i)`` with white jerk of
spectral density ``jerk_psd`` [rad²/s⁵] and measurement noise variance σ²:

    F(h) = [[1, h, h²/2], [0, 1, h], [0, 0, 1]],
    Q(h) = j · [[h⁵/20, h⁴/8, h³/6], [h⁴/8, h³/3, h²/2], [h³/6, h²/2, h]],   R = σ².

All directions share F, Q and R, so they share one 3×3 covariance: the cost
is O(nv).  On Lie-group joints the position part lives in the tangent space:
predict ``q ← q ⊕ (v h + a h²/2)``, correct with the innovation
``e = difference(q̂, q_meas)`` and ``q ← q ⊕ K₀ e``.

Defaults: σ = ``noise_std`` (1e-6 if not given, so the filter trusts the
encoder), ``jerk_psd`` = 1e3 rad²/s⁵ (an arm tracking smooth references;
tune it with ``pinobs bench``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, cast

import numpy as np
from numpy.typing import NDArray

from pinobs.model import Robot
from pinobs.observers.base import Observer, Vector, positive, register
from pinobs.observers.ekf import _LazyKernel

__all__ = [
    "BankState",
    "ConstantAccelerationKF",
    "ErrorState",
    "KFBank",
    "KFGains",
    "WhiteJerkFilter",
]

_NOISE_FLOOR = 1e-6  # [rad] σ assumed when no noise_std is given


@dataclass(frozen=True)
class KFGains:
    """Validated options of :class:`ConstantAccelerationKF`.

    Attributes:
        jerk_psd: white-jerk spectral density [rad²/s⁵], > 0.
        meas_std: measurement noise standard deviation [rad], > 0.
    """

    jerk_psd: float
    meas_std: float

    def __post_init__(self) -> None:
        positive("jerk_psd", self.jerk_psd)
        positive("meas_std", self.meas_std)


class _State(NamedTuple):
    q: Vector
    v: Vector
    a: Vector
    P: Vector  # 3×3 covariance shared by every direction


def transition(h: float, jerk_psd: float) -> tuple[Vector, Vector]:
    """``(F(h), Q(h))`` of the white-jerk model (module docstring)."""
    F = np.array([[1.0, h, 0.5 * h * h], [0.0, 1.0, h], [0.0, 0.0, 1.0]])
    Q = jerk_psd * np.array(
        [
            [h**5 / 20, h**4 / 8, h**3 / 6],
            [h**4 / 8, h**3 / 3, h**2 / 2],
            [h**3 / 6, h**2 / 2, h],
        ]
    )
    return F, Q


def _predicted(
    robot: Robot, q: Vector, v: Vector, a: Vector, P: Vector, F: Vector, Q: Vector, h: float
) -> tuple[Vector, Vector, Vector, Vector]:
    """The prediction over ``h``: ``q ⊕ (v h + a h²/2)``, ``v + a h``, ``a``, ``F P Fᵀ + Q``."""
    return robot.integrate(q, v * h + 0.5 * h * h * a), v + h * a, a, F @ P @ F.T + Q


def _corrected(
    robot: Robot, q: Vector, v: Vector, a: Vector, P: Vector, r: float, q_meas: Vector
) -> tuple[Vector, Vector, Vector, Vector]:
    """The update with ``q_meas``: per direction the shared gain ``K = P[:, 0] / (P₀₀ + r)``, the
    innovation ``e = difference(q, q_meas)``, and ``P`` in the Joseph form (not symmetrised)."""
    K = P[:, 0] / (P[0, 0] + r)
    e = robot.difference(q, q_meas)
    IKH = np.eye(3) - np.outer(K, [1.0, 0.0, 0.0])
    P = IKH @ P @ IKH.T + r * np.outer(K, K)
    return robot.integrate(q, K[0] * e), v + K[1] * e, a + K[2] * e, P


@register
class ConstantAccelerationKF(Observer[_State]):
    """Per-joint Kalman filter on a constant-acceleration (white-jerk) model.

    Args:
        robot: the robot (only its Lie-group operations are used).
        jerk_psd: white-jerk spectral density [rad²/s⁵].
        v0_std: initial velocity standard deviation [rad/s] when ``v0`` is not given.
        rate: sample rate hint [Hz] (not needed: the filter uses the actual intervals).
        noise_std: position noise standard deviation [rad or m], the measurement noise.
    """

    name = "kf"
    summary = "per-joint constant-acceleration Kalman filter (model-free baseline)"
    uses_torque = False
    uses_noise_std = True
    #: :func:`pinobs.smooth` can run its backward pass over this filter (through
    #: :meth:`smoothing_filter`: the model-free smoother).
    smoothable = True

    def __init__(
        self,
        robot: Robot,
        *,
        jerk_psd: float = 1e3,
        v0_std: float = 1.0,
        rate: float | None = None,
        noise_std: float | None = None,
    ) -> None:
        super().__init__(robot, rate=rate, noise_std=noise_std)
        positive("v0_std", v0_std)
        self.v0_std = float(v0_std)
        self.gains = KFGains(jerk_psd=jerk_psd, meas_std=self.noise_std or _NOISE_FLOOR)

    @property
    def options(self) -> dict[str, object]:
        return {**super().options, "jerk_psd": self.gains.jerk_psd, "meas_std": self.gains.meas_std}

    def _initial_state(self, q0: Vector, v0: Vector) -> _State:
        P = np.diag(np.array([self.gains.meas_std**2, self.v0_std**2, (10.0 * self.v0_std) ** 2]))
        return _State(q0.copy(), v0.copy(), np.zeros_like(v0), P)

    def _step(self, state: _State, dt: float, q_meas: Vector | None, tau: Vector) -> _State:
        F, Q = transition(dt, self.gains.jerk_psd)
        q, v, a, P = _predicted(self.robot, state.q, state.v, state.a, state.P, F, Q, dt)
        if q_meas is not None:
            q, v, a, P = _corrected(self.robot, q, v, a, P, self.gains.meas_std**2, q_meas)
        return _State(q, v, a, 0.5 * (P + P.T))

    def _output(self, state: _State) -> tuple[Vector, Vector]:
        return state.q, state.v

    def smoothing_filter(self) -> WhiteJerkFilter:
        """This filter as :func:`pinobs.smooth` runs it (:class:`WhiteJerkFilter`)."""
        return WhiteJerkFilter(self.robot, self.gains, self.v0_std)


def _kron_eye(A: Vector, eye: Vector) -> Vector:
    """``A ⊗ I`` (a broadcast product: ``np.kron`` costs 10× more at these sizes)."""
    n = A.shape[0] * eye.shape[0]
    return (A[:, None, :, None] * eye[:, None]).reshape(n, n)


class ErrorState(NamedTuple):
    """:class:`WhiteJerkFilter`'s state: the mean, and the covariance of the error state
    ``(δq, δv, δa)`` (each block ``nv`` long)."""

    q: Vector
    v: Vector
    d: Vector  # the acceleration a, named as the smoother's further vector part (the EKF's d)
    P: Vector  # (3nv, 3nv): P₃ ⊗ I, the directions' shared 3×3 covariance
    P3: Vector  # that 3×3 covariance


class WhiteJerkFilter:
    """:class:`ConstantAccelerationKF` with its predict and correct apart, for the RTS
    smoother (:class:`pinobs.observers.smoothing.SmoothableFilter`): the model-free smoother.

    The same equations (module docstring), stated for the whole error state
    ``x = (δq, δv, δa)`` of ``3 nv`` coordinates: every direction has the same
    ``F(h)``, ``Q(h)`` and ``R``, and the measurement ``H = [I 0 0]``, so the covariance is
    ``P = P₃ ⊗ I`` and the transition ``Φ = F(h) ⊗ I`` (the Kronecker product keeps the
    ``δq, δv, δa`` blocks in that order); the filter runs on ``P₃`` as the causal one does,
    and its states carry ``P`` for the smoother's backward pass.  ``a`` is the state's
    ``d``, the part after ``v`` that the smoother treats as a vector.  Takes no torque.
    """

    def __init__(self, robot: Robot, gains: KFGains, v0_std: float) -> None:
        self.robot, self.gains, self.v0_std = robot, gains, float(v0_std)
        self._cache: tuple[float, Vector, Vector, Vector] | None = None
        self._eye = np.eye(robot.nv)

    @property
    def options(self) -> dict[str, object]:
        return {"jerk_psd": self.gains.jerk_psd, "meas_std": self.gains.meas_std}

    def _full(self, q: Vector, v: Vector, a: Vector, P3: Vector) -> ErrorState:
        return ErrorState(q, v, a, _kron_eye(P3, self._eye), P3)

    def _initial_state(self, q0: Vector, v0: Vector) -> ErrorState:
        """As :meth:`ConstantAccelerationKF._initial_state`."""
        P3 = np.diag([self.gains.meas_std**2, self.v0_std**2, (10.0 * self.v0_std) ** 2])
        return self._full(q0.copy(), v0.copy(), np.zeros_like(v0), P3)

    def _predict(self, state: ErrorState, dt: float, tau: Vector) -> tuple[ErrorState, Vector]:
        """``(state⁻, Φ)`` (``tau`` is not used)."""
        if self._cache is None or self._cache[0] != dt:
            F, Q = transition(dt, self.gains.jerk_psd)
            self._cache = (dt, F, Q, _kron_eye(F, self._eye))
        _, F, Q, Phi = self._cache
        return self._full(
            *_predicted(self.robot, state.q, state.v, state.d, state.P3, F, Q, dt)
        ), Phi.copy()

    def _correct(self, state: ErrorState, q_meas: Vector) -> ErrorState:
        q, v, a, P = _corrected(
            self.robot, state.q, state.v, state.d, state.P3, self.gains.meas_std**2, q_meas
        )
        return self._full(q, v, a, 0.5 * (P + P.T))


class BankState(NamedTuple):
    """States of a bank of ``F`` per-joint filters (:class:`KFBank`): rows are filters."""

    q: Vector  # (F, nq)
    v: Vector  # (F, nv)
    a: Vector  # (F, nv)
    P: Vector  # (F, 3, 3)
    innovation: Vector | None  # (F, nv): each filter's innovation at the last sample


def _bank_rows_loops(
    q: Vector,
    v: Vector,
    a: Vector,
    P: Vector,
    t: Vector,
    q_meas: Vector,
    measured: NDArray[np.bool_],
    jerk: Vector,
    meas_var: float,
    ll: Vector,
    e: Vector,
    X: Vector,
    PX: Vector,
) -> None:
    """A bank of filters on vector joints over rows ``1..`` of ``(t, q_meas, measured)``, from
    its state at ``t[0]``, in loops (compiled by numba); the state arrays updated in place.

    The equations of the module docstring per filter ``f`` (row) and row ``k``, with
    ``h = t[k] − t[k−1]``: predict with ``F(h)`` and ``Q(h) = jerk[f] · Q₁(h)``, then, if
    ``measured[k]``, the gain ``K = P⁻[:, 0] / S`` with ``S = P⁻₀₀ + σ²``, the innovation
    ``e = q_meas[k] − q⁻`` per joint, the Joseph form
    ``P = (I − K e₀ᵀ) P⁻ (I − K e₀ᵀ)ᵀ + σ² K Kᵀ`` (symmetrised), and
    ``ll[f] += log N(e; 0, S I)`` (the prediction-error decomposition, Schweppe 1965).  ``e``
    receives the innovations of the last row, when it is measured.  When ``X`` has rows,
    ``X[k] = (q, v, a)`` and ``PX[k] = P`` of filter 0 at every row ``k`` (row 0 included).
    """
    nf, nv = v.shape
    store = X.shape[0] > 0
    F = np.eye(3)
    Q1 = np.zeros((3, 3))
    FP = np.empty((3, 3))
    Pp = np.empty((3, 3))
    C = np.empty((3, 3))
    K = np.empty(3)
    h_prev = math.nan
    for k in range(t.size):
        if k > 0:
            h = t[k] - t[k - 1]
            if h != h_prev:
                F[0, 1], F[0, 2], F[1, 2] = h, 0.5 * h * h, h
                Q1[0, 0], Q1[0, 1], Q1[0, 2] = h**5 / 20, h**4 / 8, h**3 / 6
                Q1[1, 1], Q1[1, 2], Q1[2, 2] = h**3 / 3, h**2 / 2, h
                Q1[1, 0], Q1[2, 0], Q1[2, 1] = Q1[0, 1], Q1[0, 2], Q1[1, 2]
                h_prev = h
            for f in range(nf):
                for i in range(3):  # FP = F P
                    for j in range(3):
                        s = 0.0
                        for m in range(3):
                            s += F[i, m] * P[f, m, j]
                        FP[i, j] = s
                for i in range(3):  # P⁻ = F P Fᵀ + Q
                    for j in range(3):
                        s = 0.0
                        for m in range(3):
                            s += FP[i, m] * F[j, m]
                        Pp[i, j] = s + jerk[f] * Q1[i, j]
                for i in range(nv):
                    q[f, i] = q[f, i] + v[f, i] * h + 0.5 * h * h * a[f, i]
                    v[f, i] = v[f, i] + h * a[f, i]
                if not measured[k]:
                    for i in range(3):
                        for j in range(3):
                            P[f, i, j] = Pp[i, j]
                    continue
                s = Pp[0, 0] + meas_var
                for i in range(3):
                    K[i] = Pp[i, 0] / s
                sq = 0.0
                for i in range(nv):
                    ei = q_meas[k, i] - q[f, i]
                    e[f, i] = ei
                    sq += ei * ei
                    q[f, i] += K[0] * ei
                    v[f, i] += K[1] * ei
                    a[f, i] += K[2] * ei
                ll[f] -= 0.5 * (sq / s + nv * math.log(2.0 * math.pi * s))
                for i in range(3):  # C = (I − K e₀ᵀ) P⁻
                    for j in range(3):
                        C[i, j] = Pp[i, j] - K[i] * Pp[0, j]
                for i in range(3):  # C (I − K e₀ᵀ)ᵀ + σ² K Kᵀ
                    for j in range(3):
                        Pp[i, j] = C[i, j] - C[i, 0] * K[j] + meas_var * K[i] * K[j]
                for i in range(3):
                    for j in range(3):
                        P[f, i, j] = 0.5 * (Pp[i, j] + Pp[j, i])
        if store:
            for i in range(nv):
                X[k, 0, i], X[k, 1, i], X[k, 2, i] = q[0, i], v[0, i], a[0, i]
            for i in range(3):
                for j in range(3):
                    PX[k, i, j] = P[0, i, j]


_NO_STORE = np.empty((0, 3, 0))
_NO_PX = np.empty((0, 3, 3))
_ROW_MEASURED = (np.array([False, False]), np.array([False, True]))  # KFBank.step's rows
_bank_kernel = _LazyKernel(
    _bank_rows_loops,
    np.zeros((1, 1)),
    np.zeros((1, 1)),
    np.zeros((1, 1)),
    np.tile(np.eye(3), (1, 1, 1)),
    np.array([0.0, 1e-3]),
    np.zeros((2, 1)),
    np.array([False, True]),
    np.ones(1),
    1.0,
    np.zeros(1),
    np.zeros((1, 1)),
    np.zeros((2, 3, 1)),
    np.zeros((2, 3, 3)),
)


class KFBank:
    """Several :class:`ConstantAccelerationKF` filters with different ``jerk_psd``, stepped together.

    The same equations as the family (module docstring), one filter per row
    of the arrays.  On robots whose joints are all vector joints a step is one
    compiled loop (:func:`_bank_rows_loops`, numba; a NumPy step cost about 15 ``pin.aba``
    calls on a UR5, mostly in dispatching small-array operations); otherwise NumPy
    arrays, the configuration part filter by filter through ``integrate``/``difference``.
    Both paths are tested equal to separate :class:`ConstantAccelerationKF` filters.
    Each step also returns every filter's innovation ``e = difference(q̂⁻, q_meas)``,
    which the adaptive observer uses to pick the best filter per joint.
    """

    def __init__(self, robot: Robot, jerk_psd: tuple[float, ...], meas_std: float) -> None:
        self.robot = robot
        self.jerk = np.array([float(positive("jerk_psd", j) or 0.0) for j in jerk_psd])
        self.meas_var = float(positive("meas_std", meas_std) or 0.0) ** 2
        self._cache: tuple[float, Vector, Vector] | None = None
        self._ll = np.zeros(self.jerk.size)  # step's scratch (its log-likelihood is not kept)
        if robot.is_vector_space:
            _bank_kernel.load()

    def initial(self, q0: Vector, v0: Vector, v0_std: float) -> BankState:
        n = self.jerk.size
        P = np.diag([self.meas_var, v0_std**2, (10.0 * v0_std) ** 2])
        return BankState(
            np.tile(q0, (n, 1)), np.tile(v0, (n, 1)), np.zeros((n, v0.size)),
            np.tile(P, (n, 1, 1)), None,
        )  # fmt: skip

    def log_likelihoods(self, t: Vector, q: Vector, good: Vector, v0_std: float) -> Vector:
        """Each filter's innovation log-likelihood over a log, in one pass: ``Σ_k log N(e_k;
        0, S_k I)`` over the measured samples ``k ≥ 1`` (``good[k]``), ``S_k = P⁻₀₀ + σ²``
        (the prediction-error decomposition, Schweppe 1965), started at ``q[0]`` with
        ``v = 0`` (:meth:`initial`); what :func:`pinobs.observers.smoothing.select_accel_psd`
        computes for ``kf`` filter by filter (tested equal)."""
        return self.run(t, q, good, v0_std, store=False)[0]

    def run(
        self, t: Vector, q: Vector, good: Vector, v0_std: float, *, store: bool = True
    ) -> tuple[Vector, Vector, Vector]:
        """The bank over a log from :meth:`initial` at ``q[0]`` with ``v = 0``: each filter's
        innovation log-likelihood (:meth:`log_likelihoods`) and, with ``store``, the first
        filter's state at every row, ``X[k] = (q, v, a)`` of shape ``(3, nv)`` and its 3×3
        covariance ``PX[k]`` (``X`` and ``PX`` empty without).  On vector joints one compiled
        pass (:func:`_bank_rows_loops`), otherwise :meth:`step` row by row."""
        nv = self.robot.nv
        state = self.initial(q[0], np.zeros(nv), v0_std)
        ll = np.zeros(self.jerk.size)
        n = t.size if store else 0
        X, PX = np.empty((n, 3, nv)), np.empty((n, 3, 3))
        if self.robot.is_vector_space and _bank_kernel.compiled is not None:
            q_meas = np.ascontiguousarray(np.where(good[:, None], q, 0.0), dtype=float)
            _bank_kernel.compiled(
                *(np.array(x) for x in state[:4]), np.ascontiguousarray(t, dtype=float), q_meas,
                np.ascontiguousarray(good, dtype=bool), self.jerk, self.meas_var, ll,
                np.empty((self.jerk.size, nv)), X if store else _NO_STORE, PX,
            )  # fmt: skip
            return ll, X, PX
        h_prev, F0, q00 = math.nan, np.empty(3), 0.0
        for k in range(t.size):
            if k > 0:
                h = float(t[k] - t[k - 1])
                if h != h_prev:
                    F, Q = transition(h, 1.0)
                    h_prev, F0, q00 = h, F[0], float(Q[0, 0])
                S = np.einsum("j,fjk,k->f", F0, state.P, F0) + self.jerk * q00 + self.meas_var
                state = self.step(state, h, q[k] if good[k] else None)
                if good[k]:
                    e = cast(Vector, state.innovation)
                    ll -= 0.5 * (np.einsum("fi,fi->f", e, e) / S + nv * np.log(2.0 * math.pi * S))
            if store:
                X[k] = state.q[0], state.v[0], state.a[0]
                PX[k] = state.P[0]
        return ll, X, PX

    def step(self, state: BankState, dt: float, q_meas: Vector | None) -> BankState:
        r = self.robot
        if r.is_vector_space and _bank_kernel.compiled is not None:
            measured = q_meas is not None
            q, v, a, P = state.q.copy(), state.v.copy(), state.a.copy(), state.P.copy()
            e = np.empty_like(v)
            rows = np.empty((2, v.shape[1]))
            if measured:
                rows[1] = q_meas
            _bank_kernel.compiled(
                q, v, a, P, np.array([0.0, dt]), rows, _ROW_MEASURED[measured], self.jerk,
                self.meas_var, self._ll, e, _NO_STORE, _NO_PX,
            )  # fmt: skip
            return BankState(q, v, a, P, e if measured else None)
        if self._cache is None or self._cache[0] != dt:
            F, Q = transition(dt, 1.0)
            self._cache = (dt, F, self.jerk[:, None, None] * Q)
        _, F, Q = self._cache
        step = state.v * dt + 0.5 * dt * dt * state.a
        q = np.array([r.integrate(x, s) for x, s in zip(state.q, step, strict=True)])
        v = state.v + dt * state.a
        a = state.a
        P = F @ state.P @ F.T + Q
        if q_meas is None:
            return BankState(q, v, a, P, None)
        e = np.array([r.difference(x, q_meas) for x in q])
        K = P[:, :, 0] / (P[:, 0, 0] + self.meas_var)[:, None]  # (F, 3)
        q = np.array([r.integrate(x, k * y) for x, k, y in zip(q, K[:, 0], e, strict=True)])
        v = v + K[:, 1:2] * e
        a = a + K[:, 2:3] * e
        IKH = np.eye(3) - K[:, :, None] * np.array([1.0, 0.0, 0.0])  # Joseph form, per filter
        P = IKH @ P @ IKH.transpose(0, 2, 1) + self.meas_var * K[:, :, None] * K[:, None, :]
        return BankState(q, v, a, 0.5 * (P + P.transpose(0, 2, 1)), e)

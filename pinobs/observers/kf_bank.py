"""The banks of ``kf`` filters: the white-jerk filter's equations, :class:`KFBank` (several
densities stepped together) and :class:`AutoBank` (``jerk_psd="auto"``: the bank, its profile
likelihood and mixture).

The equations, the auto bank's likelihood and why it is built so are in the
:mod:`pinobs.observers.kf` module docstring; the banks run as compiled loops
(:mod:`pinobs.observers.kf_kernels`) on vector, continuous, spherical and free-flyer joints,
as NumPy arrays otherwise (planar joints, or numba absent).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple, cast

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import UnsupportedRobotError
from pinobs.model import Robot
from pinobs.observers.base import GateState, Vector, gate_threshold, positive
from pinobs.observers.gating import SPIKE_ALPHA
from pinobs.observers.kf_fused import fused_work, gated_kernel, update_kernel
from pinobs.observers.kf_kernels import (
    auto_kernel,
    auto_layout,
    bank_kernel,
    joint_table,
    rows_kernel,
)

_F64 = np.dtype(np.float64)
_new_tuple = tuple.__new__  # a NamedTuple made without its __new__, a Python call (step)

__all__ = [
    "AUTO_GATE_SAMPLES",
    "AUTO_LAMBDAS",
    "AUTO_MEMORY",
    "AutoBank",
    "AutoState",
    "BankState",
    "KFBank",
    "KFState",
    "corrected",
    "predicted",
    "transition",
]


class KFState(NamedTuple):
    """A ``kf`` filter's state (one density): the mean and the directions' shared covariance."""

    q: Vector
    v: Vector
    a: Vector
    P: Vector  # 3×3 covariance shared by every direction
    gate: GateState = GateState()  # the outlier gate's bookkeeping (NIS of the last measurement)


def transition(h: float, jerk_psd: float) -> tuple[Vector, Vector]:
    """``(F(h), Q(h))`` of the white-jerk model (:mod:`pinobs.observers.kf`)."""
    F = np.array([[1.0, h, 0.5 * h * h], [0.0, 1.0, h], [0.0, 0.0, 1.0]])
    Q = jerk_psd * np.array(
        [
            [h**5 / 20, h**4 / 8, h**3 / 6],
            [h**4 / 8, h**3 / 3, h**2 / 2],
            [h**3 / 6, h**2 / 2, h],
        ]
    )
    return F, Q


def predicted(
    robot: Robot, q: Vector, v: Vector, a: Vector, P: Vector, F: Vector, Q: Vector, h: float
) -> tuple[Vector, Vector, Vector, Vector]:
    """The prediction over ``h``: ``q ⊕ (v h + a h²/2)``, ``v + a h``, ``a``, ``F P Fᵀ + Q``."""
    return robot.integrate(q, v * h + 0.5 * h * h * a), v + h * a, a, F @ P @ F.T + Q


def corrected(
    robot: Robot,
    q: Vector,
    v: Vector,
    a: Vector,
    P: Vector,
    gate: GateState,
    r: float,
    threshold: float,
    q_meas: Vector,
) -> KFState:
    """The update of the prediction ``q, v, a, P`` (``P`` its 3×3 covariance; ``gate`` the
    gate's state) with ``q_meas``: the innovation ``e = difference(q, q_meas)``,
    ``S = P₀₀ + r``, the outlier gate on ``NIS = |e|² / S``
    (:meth:`pinobs.observers.base.GateState.measured`, ``threshold``: a rejected measurement
    leaves the prediction), else per direction the shared gain ``K = P[:, 0] / S`` and ``P`` in
    the Joseph form; ``P`` symmetrised."""
    s = P[0, 0] + r
    e = robot.difference(q, q_meas)
    gate = gate.measured(float(e.dot(e)) / s, threshold, e.size, SPIKE_ALPHA)
    if gate.gated:
        return KFState(q, v, a, 0.5 * (P + P.T), gate)
    K = P[:, 0] / s
    IKH = np.eye(3) - np.outer(K, [1.0, 0.0, 0.0])
    P = IKH @ P @ IKH.T + r * np.outer(K, K)
    q = robot.integrate(q, K[0] * e)
    return KFState(q, v + K[1] * e, a + K[2] * e, 0.5 * (P + P.T), gate)


#: ``jerk_psd="auto"``: the bank's dimensionless densities ``λ = (j / σ²) T⁵``
#: (:mod:`pinobs.observers.kf`), every decade from 1e-14 (a bandwidth of about 0.005 / T)
#: to 1e2 (about the raw difference).
AUTO_LAMBDAS: tuple[float, ...] = tuple(float(10.0**e) for e in range(-14, 3))

#: ``jerk_psd="auto"``: measured samples (effective count ``N``) before the outlier gate acts.
AUTO_GATE_SAMPLES = 20.0

#: ``jerk_psd="auto"``: the likelihoods' default memory [measured samples].  In samples, not
#: seconds: the grid's filters remember from about 1 (λ = 1e2) to 200 samples (λ = 1e-14,
#: ``λ^(−1/6)`` periods), and the likelihood needs many such spans.  Measured (velocity RMS
#: over the best fixed density on the run): 1 kHz simulations (ur5, start error 0.05 rad,
#: 0.5 rad/s) 0.97–0.98× at 100 samples, 1.14–1.15× at 300, 1.3–1.7× at 500 to 2000 (the
#: start's transient, remembered, holds the density up); UR10e and TIAGo logs (~100 Hz)
#: within 5 % of each other from 50 to 1000 samples.
AUTO_MEMORY = 100.0


class BankState(NamedTuple):
    """States of a bank of ``F`` per-joint filters (:class:`KFBank`): rows are filters."""

    q: Vector  # (F, nq)
    v: Vector  # (F, nv)
    a: Vector  # (F, nv)
    P: Vector  # (F, 3, 3)
    innovation: Vector | None  # (F, nv): each filter's innovation at the last sample


class AutoState(NamedTuple):
    """``jerk_psd="auto"``'s state: a bank of ``n_f`` filters and their likelihoods.

    The arrays lie in one float64 buffer ``x`` (:func:`~pinobs.observers.kf_kernels.auto_layout`:
    the compiled step takes one array and allocates one, issue 39), read through the
    properties below as read-only views; a step writes a new buffer, never this one."""

    x: Vector  # the buffer: q, v, a, A, w, e, P, B, the mixture (kf_kernels.auto_layout)
    shape: tuple[int, int, int]  # (n_f, nq, nv)
    jerk: Vector  # (n_f,): ρ_f σ₀² [rad²/s⁵] (empty until the period is known)
    n: float  # N: the forgotten count of measured samples
    gate: GateState = GateState()

    def _view(self, i: int, *shape: int) -> Vector:
        """Part ``i`` of :func:`~pinobs.observers.kf_kernels.auto_layout`, read-only."""
        o = auto_layout(*self.shape)
        out = self.x[o[i] : o[i + 1]].reshape(shape)
        out.setflags(write=False)
        return out

    @property
    def bank(self) -> BankState:
        """The filters' states, rows (:class:`KFBank`); the innovations only after a
        measurement the gate kept."""
        nf, nq, nv = self.shape
        kept = self.gate.nis is not None and not self.gate.gated
        return BankState(
            self._view(0, nf, nq), self._view(1, nf, nv), self._view(2, nf, nv),
            self._view(6, nf, 3, 3), self._view(5, nf, nv) if kept else None,
        )  # fmt: skip

    @property
    def A(self) -> Vector:
        """``(n_f, nv)``: the forgotten sums of ``e² / S``."""
        return self._view(3, self.shape[0], self.shape[2])

    @property
    def B(self) -> Vector:
        """``(n_f,)``: the forgotten sums of ``log S``."""
        return self._view(7, self.shape[0])

    @property
    def w(self) -> Vector:
        """``(n_f, nv)``: the mixture's weights."""
        return self._view(4, self.shape[0], self.shape[2])

    @property
    def mix(self) -> Vector:
        """``(nq + nv,)``: the estimate, ``q`` then ``v``."""
        return self._view(8, self.shape[1] + self.shape[2])


def _auto_weights(n: float, A: Vector, B: Vector) -> Vector:
    """The mixture's weights ``w_fi ∝ exp(−(L_fi − min_f L_fi) / 2)``, ``L_fi = N log(A_fi /
    N) + B_f`` (:mod:`pinobs.observers.kf`; uniform before any sample)."""
    if n <= 0.0:
        return np.full(A.shape, 1.0 / A.shape[0])
    L = n * np.log(np.maximum(A, 1e-300) / n) + B[:, None]  # profile likelihood (Mehra 1970)
    w = np.exp(-0.5 * (L - L.min(axis=0)))
    return cast(Vector, w / w.sum(axis=0))


_NO_STORE = np.empty((0, 3, 0))
_NO_PX = np.empty((0, 3, 3))
_ROW_MEASURED = (np.array([False, False]), np.array([False, True]))  # KFBank.step's rows
_NO_USED = np.zeros(0, dtype=bool)


class KFBank:
    """Several :class:`~pinobs.observers.kf.ConstantAccelerationKF` filters with different
    ``jerk_psd``, stepped together.

    The same equations as the family (:mod:`pinobs.observers.kf`), one filter per row
    of the arrays.  On vector, continuous, spherical and free-flyer joints a step is one
    compiled loop (:func:`~pinobs.observers.kf_kernels.bank_rows_loops`, numba, the group's
    ``integrate``/``difference`` in it; a NumPy step cost about 15 ``pin.aba``
    calls on a UR5, mostly in dispatching small-array operations); otherwise NumPy
    arrays, the configuration part filter by filter through ``integrate``/``difference``.
    Both paths are tested equal to separate
    :class:`~pinobs.observers.kf.ConstantAccelerationKF` filters.
    Each step also returns every filter's innovation ``e = difference(q̂⁻, q_meas)``,
    which the adaptive observer uses to pick the best filter per joint; :meth:`step` has no
    outlier gate (the adaptive observer gives it only the samples its own gate keeps),
    :meth:`run` over a log has the filters' (``outlier_probability``).
    """

    def __init__(
        self,
        robot: Robot,
        jerk_psd: tuple[float, ...],
        meas_std: float,
        outlier_probability: float | None = None,
    ) -> None:
        self.robot = robot
        self.jerk = np.array([float(positive("jerk_psd", j) or 0.0) for j in jerk_psd])
        self.meas_var = float(positive("meas_std", meas_std) or 0.0) ** 2
        self.gate = gate_threshold(outlier_probability, robot.nv)[1]
        self._cache: tuple[float, Vector, Vector] | None = None
        n = self.jerk.size  # step's scratch (its likelihood and gate are not kept)
        self._scratch_ll, self._scratch_level = np.zeros(n), np.ones(n)
        self._scratch_run = np.zeros(n, dtype=np.int64)
        #: the joints as the compiled loops take them (``None``: the NumPy path)
        self.table = joint_table(robot.joints, robot.nq, robot.nv)
        if self.table is not None:
            bank_kernel.load()

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
        (the prediction-error decomposition, Schweppe 1965; a sample the gate rejects counted
        at the gate), started at ``q[0]`` with ``v = 0`` (:meth:`initial`); what
        :func:`pinobs.smoothing.select_accel_psd` computes for ``kf`` filter by
        filter (tested equal)."""
        return self.run(t, q, good, v0_std, store=False)[0]

    def run(
        self, t: Vector, q: Vector, good: Vector, v0_std: float, *, store: bool = True
    ) -> tuple[Vector, Vector, Vector, Vector]:
        """The bank over a log from :meth:`initial` at ``q[0]`` with ``v = 0``, with the outlier
        gate: each filter's innovation log-likelihood (:meth:`log_likelihoods`) and, with
        ``store``, the first filter's state at every row, ``X[k] = (q, v, a)`` of shape
        ``(3, nv)``, its 3×3 covariance ``PX[k]`` and whether it was corrected with the row's
        measurement, ``used[k]`` (all three empty without; ``store`` needs ``nq = nv``).  One
        compiled pass (:func:`~pinobs.observers.kf_kernels.bank_rows_loops`) where the joints
        allow (:attr:`table`), otherwise each filter in
        turn as :class:`~pinobs.observers.kf.ConstantAccelerationKF` steps."""
        nv, n_f = self.robot.nv, self.jerk.size
        if store and self.robot.nq != nv:
            raise UnsupportedRobotError(
                f"{self.robot.name}: KFBank.run(store=True) stores q in the rows of v: it needs "
                f"vector joints (nq = nv), not nq={self.robot.nq}, nv={nv}"
            )
        n = t.size if store else 0
        X, PX, used = np.empty((n, 3, nv)), np.empty((n, 3, 3)), np.zeros(n, dtype=bool)
        ll = np.zeros(n_f)
        state = self.initial(q[0], np.zeros(nv), v0_std)
        if self.table is not None and bank_kernel.compiled is not None:
            q_meas = np.ascontiguousarray(np.where(good[:, None], q, 0.0), dtype=float)
            bank_kernel.compiled(
                *(np.array(x) for x in state[:4]), np.ascontiguousarray(t, dtype=float), q_meas,
                np.ascontiguousarray(good, dtype=bool), self.jerk, self.meas_var, self.gate,
                np.full(n_f, float(nv)), np.zeros(n_f, dtype=np.int64), ll,
                np.empty((n_f, nv)), X if store else _NO_STORE, PX, used if store else _NO_USED,
                self.table,
            )  # fmt: skip
            return ll, X, PX, used
        for f in range(n_f):  # the causal filter's own steps, the likelihood as _forward's
            one = KFState(state.q[f], state.v[f], state.a[f], state.P[f])
            for k in range(t.size):
                if k > 0:
                    h = float(t[k] - t[k - 1])
                    F, Q = transition(h, float(self.jerk[f]))
                    qk, vk, ak, Pk = predicted(self.robot, one.q, one.v, one.a, one.P, F, Q, h)
                    one = KFState(qk, vk, ak, Pk, one.gate.predicted())
                    if good[k]:
                        s = Pk[0, 0] + self.meas_var
                        one = corrected(
                            self.robot, qk, vk, ak, Pk, one.gate, self.meas_var, self.gate, q[k]
                        )
                        cap = one.gate.limit(self.gate, nv) if one.gate.gated else math.inf
                        nis = min(cast(float, one.gate.nis), cap)
                        ll[f] -= 0.5 * (nis + nv * math.log(2.0 * math.pi * s))
                if store and f == 0:
                    X[k], PX[k], used[k] = (
                        (one.q, one.v, one.a),
                        one.P,
                        k > 0 and one.gate.nis is not None and not one.gate.gated,
                    )
        return ll, X, PX, used

    def step(self, state: BankState, dt: float, q_meas: Vector | None) -> BankState:
        r = self.robot
        if self.table is not None and bank_kernel.compiled is not None:
            measured = q_meas is not None
            q, v, a, P = state.q.copy(), state.v.copy(), state.a.copy(), state.P.copy()
            e = np.empty_like(v)
            rows = np.empty((2, q.shape[1]))
            if measured:
                rows[1] = q_meas
            bank_kernel.compiled(
                q, v, a, P, np.array([0.0, dt]), rows, _ROW_MEASURED[measured], self.jerk,
                self.meas_var, math.inf, self._scratch_level, self._scratch_run, self._scratch_ll,
                e, _NO_STORE, _NO_PX, _NO_USED, self.table,
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


class AutoBank:
    """``jerk_psd="auto"`` of :class:`~pinobs.observers.kf.ConstantAccelerationKF`: a bank of
    ``n_f`` filters on the grid :data:`AUTO_LAMBDAS`, their forgotten profile likelihoods and
    the mixture (the :mod:`pinobs.observers.kf` module docstring), on :class:`AutoState`.

    Args:
        robot: the robot (only its Lie-group operations are used).
        meas_std: σ₀ [rad or m]: every filter's measurement noise (the scales' unit).
        memory: the likelihoods' memory [measured samples]: ``γ = exp(−1 / memory)``.
        gate: the outlier gate's NIS threshold (``inf``: no gate).
    """

    def __init__(self, robot: Robot, meas_std: float, memory: float, gate: float) -> None:
        self.robot, self.meas_std, self.memory, self.gate = robot, meas_std, memory, gate
        self._cache: KFBank | None = None
        self._forget = math.exp(-1.0 / memory)  # γ
        self._var = float(meas_std) ** 2  # as KFBank's meas_var
        self._no_sample = np.zeros(robot.nv)
        self._dof = float(robot.nv)  # the gate's level before any (outlier_gate)
        self._table = joint_table(robot.joints, robot.nq, robot.nv)  # None: the NumPy step
        self._shape = (len(AUTO_LAMBDAS), robot.nq, robot.nv)  # AutoState.shape
        layout = auto_layout(*self._shape)  # the state's buffer (kf_kernels.auto_layout)
        self._size = layout[-1]
        #: where the mixture (``q`` then ``v``) lies in an :class:`AutoState`'s buffer
        self.mixture = slice(layout[8], layout[9])
        self._direct = self._direct_step()
        self._sample_shape = (robot.nq,)
        #: the whole plain update in one compiled call (:mod:`pinobs.observers.kf_fused`), on
        #: vector joints (a sample to normalise is the base's); else ``None``
        self.fused = self._fused_update()
        self._bounds = np.array(robot.absurd_torque, dtype=np.float64)  # (Robot.absurd_torque)

    def work(self, split: float, span: float) -> Vector:
        """:attr:`fused`'s array (:func:`~pinobs.observers.kf_fused.fused_work`, no state in it
        yet) with the observer's sub-step and pause limits ``split``, ``span``."""
        return fused_work(
            split, span, self._var, self._forget, self.gate, self._dof, AUTO_GATE_SAMPLES,
            self._shape[1], self._bounds, self._shape[0], self._size,
        )  # fmt: skip

    def _direct_step(self) -> Any:
        """The compiled step and gate (:data:`~pinobs.observers.kf_fused.gated_kernel`) without
        numba's dispatcher (:meth:`step`), loaded now, not at the first update; ``None``: the
        NumPy step."""
        if self._table is None:
            return None
        gated_kernel.load()
        if auto_kernel.compiled is None or gated_kernel.compiled is None:
            return None
        return gated_kernel.unchecked()

    def _fused_update(self) -> Any:
        """:data:`~pinobs.observers.kf_fused.update_kernel`'s machine code (loaded now), where
        the step is compiled and the joints are vector joints; else ``None``."""
        if self._direct is None or self._table is None or self._table.shape[0]:
            return None
        update_kernel.load()
        return update_kernel.unchecked()

    def __getstate__(self) -> dict[str, Any]:
        """Pickled without the compiled code (no pickle has it): loaded again."""
        return {**self.__dict__, "_direct": None, "fused": None}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._direct = self._direct_step()
        self.fused = self._fused_update()

    @property
    def compiled(self) -> bool:
        """Whether :meth:`step` is the compiled kernel (vector, continuous, spherical and
        free-flyer joints; numba present)."""
        return self._table is not None and auto_kernel.compiled is not None

    def initial(self, q0: Vector, v0: Vector, P: Vector, rate: float | None) -> AutoState:
        """Every filter at ``(q0, v0, a = 0)`` with the 3×3 covariance ``P``, uniform weights;
        ``rate`` [Hz] sets the grid's period ``T = 1/rate`` (``None``: the first interval)."""
        n_f, nv = len(AUTO_LAMBDAS), v0.size
        jerk = np.empty(0) if rate is None else self.grid(1.0 / rate)
        bank = BankState(
            np.tile(q0, (n_f, 1)), np.tile(v0, (n_f, 1)), np.zeros((n_f, nv)),
            np.tile(P, (n_f, 1, 1)), None,
        )  # fmt: skip
        w = np.full((n_f, nv), 1.0 / n_f)
        return self._packed(bank, jerk, 0.0, np.zeros((n_f, nv)), np.zeros(n_f), w, GateState())

    def restart(self, state: AutoState, fresh: AutoState) -> AutoState:
        """``fresh`` (:meth:`initial`) with what ``state`` learned: its grid, count,
        likelihood sums and weights."""
        return self._packed(fresh.bank, state.jerk, state.n, state.A, state.B, state.w, fresh.gate)

    def _packed(
        self, bank: BankState, jerk: Vector, n: float, A: Vector, B: Vector, w: Vector,
        gate: GateState,
    ) -> AutoState:  # fmt: skip
        """The :class:`AutoState` of these arrays, in a new buffer, with their mixture
        (:meth:`_mixture`; the NumPy step's, the start's)."""
        o = auto_layout(*self._shape)
        x = np.empty(self._size)
        e = np.zeros(A.shape) if bank.innovation is None else bank.innovation
        for i, part in enumerate((bank.q, bank.v, bank.a, A, w, e, bank.P, B)):
            x[o[i] : o[i + 1]] = part.ravel()
        q, v = self._mixture(w, bank)
        x[o[8] : o[9]] = np.concatenate([q, v])
        return AutoState(x, self._shape, jerk, n, gate)

    def grid(self, period: float) -> Vector:
        """The bank's densities ``ρ_f σ₀² = λ_f σ₀² / T⁵`` [rad²/s⁵] (``T`` the period [s];
        :mod:`pinobs.observers.kf`)."""
        return np.array(AUTO_LAMBDAS) * self.meas_std**2 / period**5

    def densities(self, state: AutoState) -> Vector:
        """Each joint's density ``exp Σ_f w_fi log(ρ_f ĉ_fi σ₀²)`` [rad²/s⁵] (``nan`` before
        the first measured sample)."""
        if state.n <= 0.0 or not state.jerk.size:
            return np.full(self.robot.nv, math.nan)
        scale = np.maximum(state.A / state.n, 1e-300)
        return cast(Vector, np.exp(np.sum(state.w * np.log(state.jerk[:, None] * scale), axis=0)))

    def noise_stds(self, state: AutoState) -> Vector:
        """Each joint's noise ``√exp Σ_f w_fi log(ĉ_fi σ₀²)`` [rad or m] (``nan`` before a
        measured sample)."""
        if state.n <= 0.0:
            return np.full(self.robot.nv, math.nan)
        scale = np.maximum(state.A / state.n, 1e-300) * self.meas_std**2
        return cast(Vector, np.sqrt(np.exp(np.sum(state.w * np.log(scale), axis=0))))

    def _mixture(self, w: Vector, b: BankState) -> tuple[Vector, Vector]:
        """The mixture ``(Σ_f w_f q_f, Σ_f w_f v_f)`` (the estimate; the compiled step's
        :func:`~pinobs.observers.kf_kernels.auto_step_loops` computes it too); on Lie groups
        the configurations mixed in the tangent space of the filter of largest total weight."""
        v = np.sum(w * b.v, axis=0)
        if self.robot.is_vector_space:
            return np.sum(w * b.q, axis=0), v
        ref = int(np.argmax(w.sum(axis=1)))  # the mixture in the tangent space of one filter
        d = np.array([self.robot.difference(b.q[ref], x) for x in b.q])
        return self.robot.integrate(b.q[ref], np.sum(w * d, axis=0)), v

    def _bank(self, jerk: Vector) -> KFBank:
        """The :class:`KFBank` stepping the filters of densities ``jerk`` (built once)."""
        if self._cache is None or not np.array_equal(self._cache.jerk, jerk):
            self._cache = KFBank(self.robot, tuple(jerk.tolist()), self.meas_std)
        return self._cache

    def step(self, state: AutoState, h: float, q_meas: Vector | None) -> AutoState:
        """One step of the bank (:mod:`pinobs.observers.kf`): each filter's
        prediction and correction (:meth:`KFBank.step`: the equations of :meth:`step`),
        the forgotten likelihood sums, the mixture's weights.  Where :attr:`compiled`, one
        call (:func:`~pinobs.observers.kf_kernels.auto_step_loops`, the same equations, tested
        equal to the NumPy ones to 1e-12) into arrays allocated here (the state before is kept
        as it was), the count and the gate's state after it decided in the same call
        (:func:`~pinobs.observers.kf_fused.gated_step_loops`, as the fused update decides them);
        otherwise NumPy (:meth:`_step_numpy`).

        The compiled path is written for its cost (issue 39: every ``kf`` update): the new
        state's arrays in one buffer (:class:`AutoState`: one ``np.empty`` and five arrays to
        pass, against nine and nineteen), its named tuples by ``tuple.__new__`` (their own
        ``__new__`` is a Python call), the kernel's machine code called without numba's
        dispatcher (:meth:`~pinobs.observers.linalg.LazyKernel.unchecked`: its arguments the
        state's own buffers and the sample, here a writable C-contiguous float64 ``(nq,)``
        array, else copied to one first; paced at 1 kHz on a UR5 the call took 14.2–14.8 µs
        against 16.8–19.8 through the dispatcher)."""
        kernel, table = self._direct, self._table
        if kernel is None or table is None:
            return self._step_numpy(state, h, q_meas)
        jerk = state.jerk if state.jerk.size else self.grid(h)
        gate = state.gate
        if q_meas is None:
            q_meas = self._no_sample
        elif not q_meas.flags.carray or q_meas.dtype is not _F64:  # (not update's own copy)
            q_meas = np.array(q_meas, dtype=np.float64)  # C-contiguous, writable
        if q_meas.shape != self._sample_shape and gated_kernel.compiled is not None:
            kernel = gated_kernel.compiled  # (never from update: numba's checks)
        x = np.empty(self._size)
        n, after = kernel(
            state.x, x, jerk, q_meas, table, h, self._var, self._forget, self.gate, self._dof,
            AUTO_GATE_SAMPLES, self._shape[1], q_meas is not self._no_sample, state.n,
            -1.0 if gate.level is None else gate.level, gate.run,
            0.0 if gate.drift is None else gate.drift,
        )  # fmt: skip
        # the count and GateState after the step, decided with it (kf_fused.gated_step_loops)
        return _new_tuple(AutoState, (x, self._shape, jerk, n, _new_tuple(GateState, after)))

    def rows(
        self, state: AutoState, t0: float, t: Vector, q: Vector, v_max: Vector
    ) -> tuple[AutoState, Vector, Vector, NDArray[np.bool_]]:
        """:meth:`step` measured at each row of ``t``, ``q`` in turn (``t0`` the state's time), in
        one compiled call (:func:`~pinobs.observers.kf_kernels.auto_rows_loops`: the same
        kernel, count and gate, the same bits), stopping before a row whose mixture is not
        finite or has ``|v̂_i| > v_max_i``.  Returns the state after the rows taken, their
        mixtures ``(q̂, v̂)`` (rows taken × ``nq + nv``), NIS and rejections; none taken (and
        ``state``) where the step is not compiled or the grid not set (a first step's)."""
        nq, nv = self._shape[1], self.robot.nv
        if auto_kernel.compiled is None or self._table is None or not state.jerk.size:
            return state, np.empty((0, nq + nv)), np.empty(0), np.zeros(0, dtype=bool)
        rows_kernel.load()
        t, q = np.ascontiguousarray(t, dtype=float), np.ascontiguousarray(q, dtype=float)
        v_max = np.ascontiguousarray(np.broadcast_to(np.asarray(v_max, dtype=float), (nv,)))
        m, gate, x = t.size, state.gate, state.x.copy()
        mixes, nis, gated = np.empty((m, nq + nv)), np.empty(m), np.zeros(m, dtype=bool)
        done, n, level, known, run, drift = rows_kernel.compiled(  # type: ignore[misc]
            x, t0, t, q, state.jerk, self._table, self._var, self._forget, self.gate, self._dof,
            state.n, 0.0 if gate.level is None else gate.level, gate.level is not None,
            gate.run, 0.0 if gate.drift is None else gate.drift, nq, AUTO_GATE_SAMPLES, v_max,
            mixes, nis, gated,
        )  # fmt: skip
        if not done:
            return state, mixes[:0], nis[:0], gated[:0]
        after = GateState(
            float(nis[done - 1]), bool(gated[done - 1]), run, level if known else None,
            drift or None,
        )  # fmt: skip
        return (
            AutoState(x, self._shape, state.jerk, n, after),
            mixes[:done],
            nis[:done],
            gated[:done],
        )

    def _softened(self, pred: BankState, e: Vector, s: Vector, r: float) -> BankState:
        """The prediction ``pred`` corrected by the innovations ``e`` (``(n_f, nv)``) with the
        innovation variances ``s`` (``(n_f,)``: the soft gate's ``α S_f``): per filter the gain
        ``K = P⁻[:, 0] / s``, ``P`` in the Joseph form with ``R = r`` (as
        :func:`~pinobs.observers.kf_kernels.kalman_correct`)."""
        K = pred.P[:, :, 0] / s[:, None]  # (n_f, 3)
        q = np.array(
            [self.robot.integrate(x, k * y) for x, k, y in zip(pred.q, K[:, 0], e, strict=True)]
        )
        IKH = np.eye(3) - K[:, :, None] * np.array([1.0, 0.0, 0.0])
        P = IKH @ pred.P @ IKH.transpose(0, 2, 1) + r * K[:, :, None] * K[:, None, :]
        return BankState(
            q, pred.v + K[:, 1:2] * e, pred.a + K[:, 2:3] * e, 0.5 * (P + P.transpose(0, 2, 1)), e
        )

    def _step_numpy(self, state: AutoState, h: float, q_meas: Vector | None) -> AutoState:
        """:meth:`step` in NumPy, the configurations filter by filter (planar joints, or
        numba absent)."""
        jerk = state.jerk if state.jerk.size else self.grid(h)
        bank = self._bank(jerk)
        A, B, w = state.A, state.B, state.w
        if q_meas is None:
            new = bank.step(state.bank, h, None)
            return self._packed(new, jerk, state.n, A, B, w, state.gate.predicted())
        new = bank.step(state.bank, h, q_meas)
        e = cast(Vector, new.innovation)  # (n_f, nv): difference(q⁻_f, q_meas)
        f0 = np.array([1.0, h, 0.5 * h * h])  # F's first row: S = (F P Fᵀ)₀₀ + j h⁵/20 + σ₀²
        S = np.einsum("i,fij,j->f", f0, state.bank.P, f0) + jerk * h**5 / 20 + bank.meas_var
        z = e * e / S[:, None]
        if state.n >= AUTO_GATE_SAMPLES:  # the scales ĉ and weights before this sample
            floor = bank.meas_var / S[:, None]  # ĉ S_f ≥ σ₀² (kf module docstring)
            nis = float(np.sum(state.w * z / np.maximum(state.A / state.n, floor)))
            gate = state.gate.measured(nis, self.gate, self.robot.nv, SPIKE_ALPHA)
        else:  # too few samples for a scale: reported (with σ₀), not gated
            gate = GateState(float(np.sum(state.w * z)))
        if gate.gated:  # the soft gate's correction (its likelihoods unchanged)
            alpha = nis / gate.limit(self.gate, self.robot.nv)  # α = NIS / limit (kf module)
            soft = self._softened(bank.step(state.bank, h, None), e, alpha * S, bank.meas_var)
            return self._packed(soft, jerk, state.n, A, B, w, gate)
        forget = self._forget  # γ (:mod:`pinobs.observers.kf`)
        n = forget * state.n + 1.0  # the forgotten sums (:mod:`pinobs.observers.kf`)
        A, B = forget * A + z, forget * B + np.log(S)
        return self._packed(new, jerk, n, A, B, _auto_weights(n, A, B), gate)

"""The Rauch–Tung–Striebel smoother over any :class:`~pinobs.observers.base.GaussianFilter`:
the forward pass (:func:`forward_pass`), the backward pass on a window (:func:`_backward`),
and :class:`Smoother`, the two fed one sample at a time; :class:`Smoothed`, the result."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from pinobs.errors import (
    NonFiniteError,
    OptionError,
)
from pinobs.model import Robot
from pinobs.model.robot import read_only
from pinobs.observers.base import (
    GaussianFilter,
    Vector,
)
from pinobs.observers.linalg import cholesky_solve, lapack_posv
from pinobs.smoothing.band import (
    NOISE_KERNEL_MAX,
    noise_backward,
    noise_backward_kernel,
    noise_forward_kernel,
    noise_step,
    was_gated,
)
from pinobs.smoothing.constants import BANDS

__all__ = ["Smoothed", "Smoother", "forward_pass", "log_rows"]

_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class Smoothed:
    """Smoothed estimates, one row per log sample (read-only arrays).

    Attributes:
        t: sample times [s], shape ``(N,)``.
        q: smoothed configurations, shape ``(N, nq)``.
        v: smoothed velocities [rad/s or m/s], shape ``(N, nv)``.
        v_std: their standard deviations ``sqrt(diag P^s)`` [rad/s or m/s], shape ``(N, nv)``.
        log_likelihood: ``log p(q_1..q_N)`` of the measurements under the filter's
            model, the sum of the innovations' Gaussian log densities [nats]
            (for choosing ``accel_psd``: :func:`select_accel_psd`).
        consistency: the filter–smoother velocity consistency ``ρ``
            (:attr:`Smoother.consistency`, no ground truth): about 1 when the
            densities explain the log, ≫ 1 when they are too small (the band is
            too narrow), < 1 when too large; NaN with nothing to compare.
        options: the filter's resolved options and the smoother's (chunk, overlap, lag).
    """

    t: Vector
    q: Vector
    v: Vector
    v_std: Vector
    log_likelihood: float
    consistency: float
    options: dict[str, Any]

    def __post_init__(self) -> None:
        for k in ("t", "q", "v", "v_std"):
            object.__setattr__(self, k, read_only(getattr(self, k)))


class _Step(NamedTuple):
    """What the backward pass keeps of one sample."""

    filt: Any  # x⁺_k (a filter state: q, v, P[, d])
    pred: Any  # x⁻_{k+1} (None at the last sample seen so far)
    Phi: Any  # Φ_k (None likewise)
    noise: Any = None  # band="noise": (Pⁿ_k, K_k or None), the noise-driven covariance and gain
    F: Any = None  # band="noise": F_k, the Jacobian of the mean's step (None likewise)


def forward_pass(
    filt: GaussianFilter,
    rows: Iterator[tuple[float, Vector | None, Vector]],
    k0: int,
    flow: bool = False,
) -> Iterator[tuple[int, Any | None, Vector | None, Any, float, Vector | None]]:
    """The filter over a log's rows ``(t, q or None, tau)`` from its first good sample
    (``k0`` in the caller's numbering); pulls one row per value yielded.

    Yields ``(k, x⁻_k, Φ_{k−1}, x⁺_k, log N(e_k; 0, S_k), F_{k−1})`` (``None, None,
    ·, 0, None`` at ``k = 0``; ``x⁺_k = x⁻_k`` and 0 at a dropped sample; ``F`` the
    Jacobian of the mean's step with ``flow`` (:class:`GaussianFilter`), else
    ``None``), where
    ``e_k = q_k ⊖ q⁻_k`` and ``S_k = P⁻_qq + σ² I`` are the innovation and its
    covariance (the prediction-error decomposition of the likelihood,
    Schweppe 1965, "Evaluation of likelihood functions for Gaussian signals").
    A sample the filter's outlier gate rejects (``NIS = eᵀ S⁻¹ e`` above the gate's ``g``)
    counts as at the gate, ``NIS`` replaced by ``g``: the log-density of the contaminated
    Gaussian ``(1 − ε) N(e; 0, S) + ε u`` (Huber 1964, "Robust estimation of a location
    parameter") by its larger component, ``u`` level with ``N`` at the gate, so that one
    glitch does not decide a density or a latency (it did: one sample 1 rad off moved
    ``"auto"`` from 1e-9 to 1 on a 2 s UR5 log, the RMS from 1.4e-5 to 1.3e-2 rad/s).
    """
    model = filt.robot
    nv = model.nv
    meas_var = filt.gains.meas_std**2
    t_prev, q0, tau_prev = next(rows)
    if q0 is None:
        raise NonFiniteError(f"sample {k0} has no configuration; the smoother starts on one")
    state = filt.initial_state(model.check_configuration(q0, what=f"q[{k0}]"), np.zeros(nv))
    yield 0, None, None, state, 0.0, None
    for k, (t, q, tau) in enumerate(rows, start=1):
        F: Vector | None = None
        if flow:
            pred, Phi, F = filt.predict_flow(state, float(t - t_prev), tau_prev)
        else:
            pred, Phi = filt.predict(state, float(t - t_prev), tau_prev)
        ll = 0.0
        if q is not None:
            q_meas = model.check_configuration(q, what=f"q[{k0 + k}]")
            e = model.difference(pred.q, q_meas)
            # S = U'U (LAPACK dposv: the factor and S⁻¹e at once); log det S = 2 Σ log Uᵢᵢ
            chol, s_inv_e, info = lapack_posv()(pred.P[:nv, :nv] + meas_var * np.eye(nv), e)
            if info != 0:
                raise NonFiniteError(
                    f"sample {k0 + k} (t = {t:.6g} s): the filter is lost (its innovation "
                    "covariance is not positive definite): the model does not explain the log "
                    "at these densities; check the model and the torques, or smooth with "
                    "accel_psd='auto' or observer='adaptive'"
                )
            nis = float(e @ s_inv_e)
            state = filt.correct(pred, q_meas)
            if was_gated(state):  # rejected by the filter's outlier gate
                nis = min(nis, filt.gate_limit(state))
            ll = -(0.5 * nis + np.log(np.diagonal(chol)).sum() + 0.5 * nv * _LOG_2PI)
        else:
            state = pred
        t_prev, tau_prev = t, tau
        yield k, pred, Phi, state, ll, F


def log_rows(
    t: Vector, q: Vector, tau: Vector, good: Vector
) -> Iterator[tuple[float, Vector | None, Vector]]:
    return ((float(t[k]), q[k] if good[k] else None, tau[k]) for k in range(t.size))


class _Fed:
    """An iterator over a queue the caller fills before each pull (push-driven :func:`forward_pass`)."""

    def __init__(self) -> None:
        self.queue: deque[tuple[float, Vector | None, Vector]] = deque()

    def __iter__(self) -> _Fed:
        return self

    def __next__(self) -> tuple[float, Vector | None, Vector]:
        if not self.queue:
            raise StopIteration
        return self.queue.popleft()


class Smoother:
    """The smoother fed one sample at a time (what :func:`smooth` runs on arrays).

    :meth:`push` runs the filter one step and, each time ``chunk`` samples and
    after them ``overlap`` measured ones are buffered (a sample without a
    measurement does not contract the backward pass's error: a gap in the overlap
    would shorten it), the backward pass over them, returning the first
    ``chunk`` samples smoothed; :meth:`close` smooths the rest.  Memory: the
    buffered samples' states.  Samples are numbered from 0 (the first pushed,
    which must carry a configuration); each result is
    ``(k, q^s_k, v^s_k, var v^s_k)``, in order.

    Attributes:
        log_likelihood: the innovations' summed log densities so far [nats].
        consistency: ``ρ``, the mean over the samples smoothed so far and their
            velocity coordinates of ``(v^s_k − v⁺_k)ᵢ² / (P⁺_k − P^s_k)_{vᵢvᵢ}``
            (NaN before any).  Under the filter's model the smoothed error
            ``x^s − x`` is uncorrelated with every measurement, hence with
            ``x⁺ − x^s`` (a function of them), so ``P⁺ = Cov(x⁺ − x^s) + P^s``:
            ``x⁺ − x^s`` has covariance ``P⁺ − P^s`` and ``E[ρ] = 1``, a check of the
            densities from the log alone (tested on a linear Gaussian model).  ``ρ ≫ 1``: the model
            error is larger than the densities say (bands too narrow); ``ρ < 1``:
            smaller.  It tests the filter's covariance, which the smoother's
            inherits; measured under a learned model's smooth residual error
            (:mod:`pinobs.smoothing`) the smoother's band is wider than ``ρ`` says.

    Args:
        filt: the filter (a :class:`GaussianFilter`).
        chunk: samples smoothed per backward pass (``None``: everything at :meth:`close`).
        overlap: measured samples after a chunk that its backward pass starts from.
    """

    def __init__(
        self, filt: GaussianFilter, chunk: int | None, overlap: int, band: str = "model"
    ) -> None:
        if band not in BANDS[:2]:  # "inflated" needs the whole log's ρ: smooth() scales at the end
            raise OptionError(f"band={band!r}: a Smoother gives one of {list(BANDS[:2])}")
        self._fed = _Fed()
        self._gen = forward_pass(filt, self._fed, 0, flow=band == "noise")
        self._model = filt.robot
        self._chunk, self._over = chunk, overlap
        self._meas_var = float(filt.gains.meas_std**2)
        self._noise: tuple[Vector, Vector | None] | None = None  # band="noise": (Pⁿ⁺, K) last
        if band == "noise" and 2 * self._model.nv <= NOISE_KERNEL_MAX:
            noise_forward_kernel.load()
            noise_backward_kernel.load()
        self._band = band
        self._buf: list[_Step] = []
        self._measured: list[bool] = []  # each buffered sample's: had a configuration
        self._tail = 0  # how many of the buffered samples after the first chunk were measured
        self._start = 0
        self.log_likelihood = 0.0
        self._rho_sum, self._rho_n = 0.0, 0

    @property
    def consistency(self) -> float:
        """``ρ`` over the samples smoothed so far (class docstring); NaN before any."""
        return self._rho_sum / self._rho_n if self._rho_n else math.nan

    @property
    def consistency_terms(self) -> int:
        """How many (sample, joint) terms :attr:`consistency` averages (to pool logs' ``ρ``)."""
        return self._rho_n

    def push(
        self, t: float, q: Vector | None, tau: Vector
    ) -> list[tuple[int, Vector, Vector, Vector]]:
        """One sample: ``t`` [s], measured ``q`` (``None``: dropped), ``tau`` held from ``t``."""
        self._fed.queue.append((t, q, tau))
        _, pred, Phi, state, ll, F = next(self._gen)
        self.log_likelihood += ll
        if self._band == "noise":
            nv = self._model.nv
            self._noise = noise_step(self._noise, pred, F, state, nv, self._meas_var)
        if pred is not None:
            self._buf[-1] = self._buf[-1]._replace(pred=pred, Phi=Phi, F=F)
        self._buf.append(_Step(state, None, None, self._noise))
        self._measured.append(q is not None)
        if self._chunk is None:
            return []
        if len(self._buf) > self._chunk:
            self._tail += q is not None
        if len(self._buf) >= self._chunk + self._over and self._tail >= self._over:
            done = self._back(self._chunk)
            self._tail = sum(self._measured[self._chunk :])
            return done
        return []

    def close(self) -> list[tuple[int, Vector, Vector, Vector]]:
        """Smooth the samples still buffered (the log's end: no later samples)."""
        return self._back(len(self._buf)) if self._buf else []

    def _back(self, keep: int) -> list[tuple[int, Vector, Vector, Vector]]:
        nv = self._model.nv
        out: list[tuple[int, Vector, Vector, Vector]] = []

        var_s: list[Vector] = []  # diag P^s, for ρ

        def emit(i: int, qs: Vector, vs: Vector, var: Vector, var_n: Vector | None) -> None:
            if i < keep:
                band = var if var_n is None else var_n
                out.append((self._start + i, qs, vs, band[nv : 2 * nv]))
                var_s.append(var[nv : 2 * nv])

        _backward(self._model, self._buf, emit, self._meas_var)
        if out:  # ρ's terms (v^s − v⁺)² / (P⁺ − P^s)_vv, where that variance is not ~0
            filt = [step.filt for step in reversed(self._buf[:keep])]  # out's order: last first
            var_f = np.array([f.P.diagonal()[nv : 2 * nv] for f in filt])
            dvar = var_f - np.array(var_s)
            diff = np.array([o[2] for o in out]) - np.array([f.v for f in filt])
            ok = dvar > 1e-9 * var_f  # not at the last sample (the smoother is the filter there)
            self._rho_sum += float(np.sum(diff[ok] ** 2 / dvar[ok]))
            self._rho_n += int(np.count_nonzero(ok))
        del self._buf[:keep], self._measured[:keep]
        self._start += keep
        out.reverse()
        return out


def _plain(state: Any) -> Vector:
    """The vector-space part of the error state: ``v`` (and the torque offset ``d``)."""
    d = getattr(state, "d", None)
    return state.v if d is None else np.concatenate([state.v, d])


def _backward(
    robot: Robot,
    steps: Sequence[_Step],
    emit: Callable[[int, Vector, Vector, Vector, Vector | None], None],
    meas_var: float = 0.0,
) -> None:
    """RTS backward pass over ``steps`` (:mod:`pinobs.smoothing`), from the last one's filtered state.

    Calls ``emit(i, q^s_i, v^s_i, diag P^s_i, diag Pⁿˢ_i)`` for every index, last
    first; ``Pⁿˢ`` (``None`` unless the steps carry :func:`noise_step`'s
    covariances; its velocity entries only, the others NaN) is the smoothed
    error's covariance driven by the measurement noise alone.  The smoothed error obeys
    ``e^s_k = e⁺_k + G_k (e^s_{k+1} − F_k e⁺_k)`` with
    ``e⁺_{k+1} = A_{k+1} F_k e⁺_k + K_{k+1} n_{k+1}`` (``A = I − K H``, no process
    noise; ``F_k`` the Jacobian of the mean's step, :func:`noise_step`, while
    ``G_k`` is the smoother's, from ``Φ_k``), so ``e^s_k = B_k e⁺_k + u_k`` with
    ``u_k`` independent of ``e⁺_k``::

        B_k = I + G_k (B_{k+1} A_{k+1} F_k − F_k)                 B_N = I
        U_k = G_k (σ² B_{k+1} K_{k+1} K_{k+1}ᵀ B_{k+1}ᵀ + U_{k+1}) G_kᵀ   U_N = 0
        Pⁿˢ_k = B_k Pⁿ⁺_k B_kᵀ + U_k

    (at the window's end the smoother is the filter: ``B = I``, ``U = 0``).
    """
    nv = robot.nv
    last = steps[-1]
    q_s, x_s, P_s = last.filt.q, _plain(last.filt), last.filt.P
    noise = last.noise is not None
    if noise:
        m = P_s.shape[0]
        B: Vector = np.eye(m)
        U: Vector = np.zeros((m, m))
    var_n = None
    if noise:
        var_n = np.full(m, np.nan)
        var_n[nv : 2 * nv] = last.noise[0].diagonal()[nv : 2 * nv]
    emit(len(steps) - 1, q_s, x_s[:nv], np.diag(P_s), var_n)
    for i in range(len(steps) - 2, -1, -1):
        filt, pred, Phi, pn_k, F = steps[i]
        # G_k = P⁺_k Φ_kᵀ (P⁻_{k+1})⁻¹, as (P⁻⁻¹ Φ P⁺)ᵀ (P symmetric)  [Särkkä 2013, Thm 8.2]
        G = cholesky_solve(pred.P, Phi @ filt.P)[0].T
        # δ_k = G_k (x^s_{k+1} ⊖ x⁻_{k+1}); x^s_k = x⁺_k ⊕ δ_k  [ibid., mean on the manifold]
        delta = G @ np.concatenate([robot.difference(pred.q, q_s), x_s - _plain(pred)])
        q_s = robot.integrate(filt.q, delta[:nv])
        x_s = _plain(filt) + delta[nv:]
        # P^s_k = P⁺_k + G_k (P^s_{k+1} − P⁻_{k+1}) G_kᵀ  [ibid.]
        P_s = filt.P + G @ (P_s - pred.P) @ G.T
        P_s = 0.5 * (P_s + P_s.T)
        var_n = None
        if noise:  # the docstring's B, U recursion
            var_n = np.full(m, np.nan)  # the velocity entries: all that v_std needs
            B, U, var_n[nv : 2 * nv] = noise_backward(
                B, U, G, F, steps[i + 1].noise[1], pn_k[0], meas_var, nv
            )
        emit(i, q_s, x_s[:nv], np.diag(P_s), var_n)

"""Never behind a model-free filter: a model-based observer blended per joint with ``kf``.

Two shared pieces (issue 36, item 2), used by every model-based family:

1. **The blend** (:class:`NeverBehind`, ``make_observer(name, robot, never_behind=True)``):
   the family's observer and a model-free :class:`~pinobs.observers.kf.ConstantAccelerationKF`
   run side by side on the same samples (composition: the wrapper holds both observers
   and their states, and steps each through its own family interface).  Each is scored
   per coordinate by its one-step prediction of the next sample: with ``(q̂ᵢ, v̂ᵢ)`` its
   estimate at ``t_k`` and ``â`` the blend's acceleration (finite difference of its last
   two velocities, common to both),

       eᵢ = difference(q̂ᵢ ⊕ (h v̂ᵢ + ½ h² â), q_{k+1}),    sᵢ ← sᵢ + (h/T)(eᵢ² − sᵢ),

   (``T`` = ``window``; a sample the ``kf``'s outlier gate rejects is not scored; one the
   model-based observer's gate rejects is: a lost model rejects the samples).
   The measurement noise ``n_{k+1}`` enters both ``eᵢ`` alike and is independent of both
   predictions (made before it), so the difference of the scores measures the difference
   of the predictors' errors, not the noise.  The weights are the posterior probabilities
   of the two predictors given the window's innovations, Gaussian with a common variance
   ``S = max(min(s_m, s_kf), σ²)`` (the multiple-model weights of Magill 1965; Bar-Shalom,
   Li & Kirubarajan 2001, §11.6.2, with a forgetting window instead of a growing one):

       ℓ = κ (N/2) (s_kf − s_m) / S,    N = T/h,    w = 1 / (1 + e^{−ℓ}),

   (the scores are exponential means started at zero: until the window has filled,
   ``sᵢ`` is divided by the weight gathered so far, ``c = 1 − (1 − h/T)^k``, and ``N`` is
   ``c T/h``; the log-odds start from a prior ``ℓ₀ = 50`` for the model that fades as the
   window fills, ``ℓ += (1 − c) ℓ₀``: the model is trusted until the data disagree)

   ``κ`` (``sharpness``) scales the count ``N`` of innovations in the window (before any
   sample is scored the model is trusted, ``w = 1``); and the output

       v̂ = w v̂_m + (1 − w) v̂_kf,    q̂ = q̂_kf ⊕ w · difference(q̂_kf, q̂_m).

   With an exact model the model-based predictor wins every window (``w → 1``: its
   accuracy is kept); with a useless one the ``kf`` wins (``w → 0``: the tuned
   model-free accuracy).  **Lost**: when the model-based estimate stops being finite, its
   step raises, or its score exceeds ``lost_ratio²`` times the ``kf``'s on some joint, it
   is re-seeded from the blend (its family's initial state at ``(q̂, v̂)``, its score set
   to ``lost_ratio`` times the ``kf``'s, so its weight stays near zero until its
   predictions have beaten the ``kf``'s over a window) and :attr:`NeverBehind.reseeds` counts it.

2. **The disturbance density learned from the innovations** (:func:`match_density`,
   ``ekf``'s ``disturbance_psd="auto"``): a per-joint random-walk density ``ψᵢ``
   matched to the innovations by covariance matching (Mehra 1972, §IV; Myers & Tapley
   1976): the windowed ratio of the squared innovation to its predicted variance,

       rᵢ ← rᵢ + (h/T)(eᵢ² / Sᵢᵢ − rᵢ),    ψᵢ ← clip(ψᵢ · rᵢ^{h/T_ψ}, ψ_min, ψ_max),

   drives ``ψ`` up while the filter under-predicts its innovations (``r > 1``: model
   error it does not carry) and down while it over-predicts them (``r < 1``), a
   multiplicative stochastic approximation whose fixed point is ``E[e²] = S``
   (Mehra's consistency condition, joint by joint).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from pinobs.errors import GainError, ObserverDiverged, OptionError
from pinobs.model import Robot
from pinobs.observers.base import Observer, Vector, observer_class, positive

__all__ = ["NeverBehind", "match_density"]

#: Bounds of the windowed NIS ratio in :func:`match_density` (one window moves ψ by at
#: most this factor).
RATIO_CLIP = (1e-2, 1e2)


def match_density(
    psd: Vector, ratio: Vector, e: Vector, s: Vector, dt: float, *, window: float, bounds: Vector
) -> tuple[Vector, Vector]:
    """One step of the covariance matching of module docstring item 2: ``(ψ, r)`` updated.

    Args:
        psd: the densities ``ψ`` per coordinate (any unit; returned in it).
        ratio: the windowed ratios ``r`` of the squared innovation to its predicted variance.
        e: this sample's innovation per coordinate.
        s: its predicted variance per coordinate (``Sᵢᵢ``), > 0.
        dt: the step [s].
        window: ``T`` [s], the averaging window of ``r`` and the time constant of ``ψ``.
        bounds: ``(2, n)`` or ``(2,)``: ``ψ_min``, ``ψ_max``.
    """
    lam = min(1.0, dt / window)
    ratio = ratio + lam * (e * e / s - ratio)  # Mehra 1972 §IV: E[e eᵀ] = S at the optimum
    r = np.clip(ratio, *RATIO_CLIP)
    psd = np.clip(psd * r**lam, bounds[0], bounds[1])  # ψ ← ψ r^{h/T}
    return psd, ratio


#: Bound of the log-odds ``ℓ`` (``1 − w`` or ``w`` ≥ 2e-22).
_LOG_ODDS = 50.0


class _State(NamedTuple):
    model: Any  # the model-based observer's state
    kf: Any  # the kf's state
    s: Vector  # (2, nv): windowed mean squared one-step prediction error, model then kf
    c: float  # the weight the window has gathered so far, 1 − (1 − h/T)^k (s / c: the mean)
    w: Vector  # the model-based weight per coordinate
    q: Vector  # the blend
    v: Vector
    v_prev: Vector  # the blend's v̂ one step before (â)
    dt_prev: float  # that step [s] (0: none yet)


class NeverBehind(Observer[_State]):
    """A model-based observer blended per joint with ``kf`` (module docstring, item 1).

    Built by ``make_observer(name, robot, never_behind=True, ...)`` (or directly).

    Args:
        robot: the model.
        observer: the registered name of the model-based observer.
        options: its options (``rate`` and ``noise_std`` are passed to both observers).
        reference_options: options of the model-free ``kf``.
        window: ``T`` [s], the scores' averaging window.
        sharpness: ``κ``, the weight of the window's innovation count in the log-odds.
        lost_ratio: RMS prediction error ratio (model over kf) beyond which the
            model-based observer is re-seeded from the blend.
        rate: sample rate hint [Hz].
        noise_std: position noise standard deviation [rad or m].
    """

    name = "never_behind"  # not registered: the option never_behind=True of every family
    summary = "a model-based observer blended per joint with kf by their one-step predictions"
    uses_noise_std = True

    def __init__(
        self,
        robot: Robot,
        *,
        observer: str = "ekf",
        options: dict[str, Any] | None = None,
        reference_options: dict[str, Any] | None = None,
        window: float = 0.2,
        sharpness: float = 1.0,
        lost_ratio: float = 100.0,
        rate: float | None = None,
        noise_std: float | None = None,
    ) -> None:
        super().__init__(robot, rate=rate, noise_std=noise_std)
        self.window = float(positive("window", window) or 0.0)
        self.sharpness = float(positive("sharpness", sharpness) or 0.0)
        self.lost_ratio = float(positive("lost_ratio", lost_ratio) or 0.0)
        if self.lost_ratio <= 1.0:
            raise GainError(f"lost_ratio={lost_ratio!r}: give a ratio above 1")
        cls = observer_class(observer)
        if not cls.uses_torque:
            raise OptionError(
                f"never_behind blends a model-based observer with kf; {observer!r} is model-free"
            )
        if cls is NeverBehind:
            raise OptionError("never_behind cannot wrap itself")
        opts = dict(options or {})
        for k in ("rate", "noise_std"):
            if k in opts:
                raise OptionError(f"give {k} to never_behind, not in options (it passes it on)")
        given = {"rate": rate, "noise_std": noise_std}
        self.model = cls(robot, **opts, **given)
        self.reference = observer_class("kf")(robot, **dict(reference_options or {}), **given)
        self.reseeds = 0

    @property
    def options(self) -> dict[str, Any]:
        return {
            **super().options,
            "observer": self.model.name,
            "model_options": self.model.options,
            "reference_options": self.reference.options,
            "window": self.window,
            "sharpness": self.sharpness,
            "lost_ratio": self.lost_ratio,
        }

    def set_latency(self, latency: float) -> None:
        """Refused (but for 0): the blend steps both observers forward and cannot predict
        without committing (give the latency to a family observer instead)."""
        if latency:
            raise OptionError("never_behind takes no latency; give it to the observer alone")
        super().set_latency(latency)

    @property
    def weights(self) -> Vector:
        """The current model-based weight ``w`` per coordinate (module docstring)."""
        if self._state is None:
            return np.full(self.robot.nv, np.nan)
        return np.array(self._state.w)

    # ---------------------------------------------------------------- states
    def _initial_state(self, q0: Vector, v0: Vector) -> _State:
        self.reseeds = 0
        nv = self.robot.nv
        m = self.model._initial_state(q0, v0)
        k = self.reference._initial_state(q0, v0)
        return _State(m, k, np.zeros((2, nv)), 0.0, np.ones(nv), q0.copy(), v0.copy(), v0, 0.0)

    def _restart_state(self, state: _State, q: Vector) -> _State:
        nv = self.robot.nv
        zero = np.zeros(nv)
        m = self.model._restart_state(state.model, q)
        k = self.reference._restart_state(state.kf, q)
        return _State(m, k, np.zeros((2, nv)), 0.0, np.ones(nv), q.copy(), zero, zero, 0.0)

    def _predicted_q(self, q: Vector, v: Vector, acc: Vector, dt: float) -> Vector:
        return self.robot.integrate(q, dt * v + 0.5 * dt * dt * acc)

    def _step(self, state: _State, dt: float, q_meas: Vector | None, tau: Vector) -> _State:
        r = self.robot
        kf = self.reference._step(state.kf, dt, q_meas, tau)
        q_kf, v_kf = self.reference._output(kf)
        lost = False
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # a lost model: handled below
                m = self.model._step(state.model, dt, q_meas, tau)
                q_m, v_m = self.model._output(m)
            lost = not (np.all(np.isfinite(q_m)) and np.all(np.isfinite(v_m)))
        except (ObserverDiverged, np.linalg.LinAlgError, ArithmeticError):
            lost = True
        s, c = state.s, state.c
        if not lost and q_meas is not None:
            if not self.reference._innovation(kf)[1]:  # an outlier to the kf's gate: not scored
                acc = (state.v - state.v_prev) / state.dt_prev if state.dt_prev > 0 else 0.0 * tau
                qm0, vm0 = self.model._output(state.model)
                qk0, vk0 = self.reference._output(state.kf)
                e_m = r.difference(self._predicted_q(qm0, vm0, acc, dt), q_meas)
                e_k = r.difference(self._predicted_q(qk0, vk0, acc, dt), q_meas)
                lam = min(1.0, dt / self.window)
                s = s + lam * (np.stack([e_m * e_m, e_k * e_k]) - s)  # scores (docstring)
                c = c + lam * (1.0 - c)
                lost = bool(np.any(s[0] > self.lost_ratio**2 * s[1])) and c > 0.5
        if lost:  # re-seeded from the blend (module docstring): the last finite output
            self.reseeds += 1
            m = self.model._initial_state(state.q, state.v)
            m = self.model._step(m, dt, q_meas, tau)
            q_m, v_m = self.model._output(m)
            s = s.copy()
            s[0] = np.maximum(s[0], self.lost_ratio * s[1])  # to prove itself: w ≈ 0 until then
        w = np.ones(r.nv)  # nothing scored yet: the model trusted (the prior)
        if c > 0.0:
            mean = s / c  # the window's mean so far (an exponential mean started at zero)
            floor = np.maximum(np.minimum(mean[0], mean[1]), (self.noise_std or 0.0) ** 2)
            n = c * self.window / dt  # the innovations in the window so far
            with np.errstate(divide="ignore", invalid="ignore"):
                ell = self.sharpness * 0.5 * n * (mean[1] - mean[0]) / floor
            ell = np.nan_to_num(ell, nan=0.0) + (1.0 - c) * _LOG_ODDS  # the prior, fading
            ell = np.clip(ell, -_LOG_ODDS, _LOG_ODDS)
            w = 1.0 / (1.0 + np.exp(-ell))  # Bar-Shalom, Li & Kirubarajan 2001 §11.6.2
        v = w * v_m + (1.0 - w) * v_kf
        q = r.integrate(q_kf, w * r.difference(q_kf, q_m))
        return _State(m, kf, s, c, w, q, v, state.v, dt)

    def _after_commit(self, state: _State, t: float, q: Vector | None, tau: Vector) -> _State:
        m = self.model._after_commit(state.model, t, q, tau)
        k = self.reference._after_commit(state.kf, t, q, tau)
        return state._replace(model=m, kf=k)

    def _innovation(self, state: _State) -> tuple[float | None, bool]:
        return self.model._innovation(state.model)

    def _output(self, state: _State) -> tuple[Vector, Vector]:
        return state.q, state.v

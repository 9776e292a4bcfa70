"""Adaptive EKF: learns the robot's dynamics online and never falls behind a model-free filter.

Three parts, each on code shared with the rest of pinobs:

1. **The filter** is an :class:`~pinobs.observers.ekf.ExtendedKalmanFilter`
   (``AdaptiveEKF.core``, held, not inherited: copied per model and regime into the
   state, 5, and driven through its public ``initial_state``, ``step``, ``replace_robot``)
   with its joint-torque offset state ``d`` (``disturbance_psd``), run on the
   current learned model ``θ̂`` and the learned torque offset ``b̂``::

       v̇ = M_θ̂⁻¹(q)(τ + b̂ + d + τ_f,θ̂(v) − c_θ̂(q, v) − g_θ̂(q)),   ḋ = w_d.

   The two noise densities (white acceleration ``q_w``, offset ``q_d``, the
   latter scaled per joint by ``M̄ᵢᵢ²`` as in ``ekf``) follow three regimes:

   * ``warmup`` until the first solve: ``warmup_accel_psd`` = 1e-2 and
     ``disturbance_psd`` = 1 (the nominal model is not trusted yet);
   * ``nominal`` when a solve finds nothing better than the nominal model
     (model selection, below): the exact-model densities of ``ekf``
     (``validated_*`` = 1e-8);
   * ``learned`` once a learned model is installed: ``accel_psd`` = 1e-6 and
     ``learned_disturbance_psd`` = 1e-4 (a learned model is good, not exact).

   These defaults were chosen on UR5, cart-pole and planar_3r runs
   (``benchmarks/learning.py`` reports Panda and z1 as well).

   Learned friction goes where it costs least.  A joint friction that cannot
   make the prediction stiff, ``λᵢ h ≤ 0.1`` with ``λᵢ = max (M_θ̂⁻¹)ᵢᵢ
   |∂τ_f,ᵢ/∂v|`` over the configurations the consistency check sampled (the
   slope peaks at ``v = 0``), is a torque held over each step, evaluated at
   the mid-step velocity extrapolated from the last step,
   ``τ_f,θ̂(v̂ + (h/2)(v̂ − v̂₋)/h₋)`` (second order; for a linear friction a
   two-step Adams–Bashforth step, stable for ``λh < 1``), and left out of the
   filter's model; stiffer friction stays in the model, where ``ekf``'s
   stiff-friction path (substeps, ``exp(Ah)`` by squaring) handles it at
   about 17 ``pin.aba`` calls more per update on a UR5 (measured on a loaded
   machine: ``ekf`` with the offset state, 45 against 28).  The covariance of a
   held friction misses its slope ``−M⁻¹ ∂τ_f/∂v``, at most ``0.1/h`` [1/s].

2. **The identification** (:mod:`pinobs.model.identification`, the same
   machinery as ``pinobs identify``): every committed sample joins a buffer;
   each ``window`` seconds of data (plus the half-width of the zero-phase
   smoother, so velocities are centred fits) give ``nv`` momentum-form rows

       [Y_M(q₂,v₂) − Y_M(q₁,v₁) − ∫Y_G dt] π + D∫v + F_c∫tanh(v/v_s) − b Δt = ∫τ dt     (MATH §9)

   kept for the last ``horizon`` seconds (the integrals by trapezoids of
   4 ms; the smoother's edge fits are skipped: only samples ``half_window``
   inside what it smooths are kept).  Every ``resolve_every`` seconds
   the rows are solved (nominal prior, robust reweighting; identifiable
   base parameters by pivoted QR, the regressor's condition number
   reported).  A friction coefficient within 3σ of its nominal value (zero
   for a URDF without friction) is kept nominal: friction the data do not
   show would cost every prediction (above).  A solve is installed only if the learned masses are positive
   and ``M_θ̂(q) ≻ 0`` at configurations sampled from the buffer (otherwise
   the last model is kept and :meth:`consistency` says so; unless the solve only validates
   the current model and fits its rows exactly, rows ≤ rank: unphysical there by
   rounding, it validates as a physical one would, ``Learner._inconclusive``), and only if it
   explains the rows better than the current model by more than fitting
   noise would: the robust (Huber) loss must drop by more than
   ``r + 3√r`` (``r`` the number of identifiable combinations; the expected
   drop from fitting pure noise is ``r/2``), and only if the filter's
   innovations say the current model does not explain the data (running
   mean NIS above twice its expectation; a model that explains the data is
   not replaced: velocities smoothed from the samples carry a bias that a
   fit would otherwise chase).  Trust in the nominal model is revoked at
   once, between solves, when the running NIS exceeds ten times its
   expectation: the latest solve is installed (or the warm-up resumes).  When a model is
   installed the offset state ``d`` is set to zero (the new model explains
   what it was absorbing).  A trajectory that does not excite a parameter
   cannot teach it: such parameters stay at their nominal values
   (:meth:`parameters` marks them).

3. **Never behind** (and never lost: should the model-based filter's estimate
   or covariance stop being finite (:func:`lost_filter`), it restarts on the model-free estimate
   in the warm-up regime, and :meth:`consistency` counts it; if the restarted
   filter is lost at once, the learned model itself does not hold and is
   dropped for the nominal one (said in ``rejected``); the blend then
   starts from ``s = v0_std²`` and blames the model fully until a solve
   replaces it): a bank of per-joint constant-acceleration Kalman filters
   (:class:`~pinobs.observers.kf.ConstantAccelerationKF`, white-jerk
   densities ``jerk_psd`` = 1e-2 … 1e5, :data:`JERK_PSD`: from a real arm logged at
   100 Hz through 4-digit encoders to a simulated one at 1 kHz)
   runs beside it; per velocity coordinate the one with the smallest running
   mean squared innovation (the one-step prediction error, which the best
   model minimises; averaged over ``blend_time``) is the model-free estimate
   ``v̂_kf``, and its covariance gives its variance ``P_kf``.  The
   model-based error variance is estimated from the recent disagreement
   ``e = v̂_model − v̂_kf``,
   ``s_i ← s_i + (h/T_b)(max(e_i² − P_kf, 0) − s_i)`` (``T_b`` = ``blend_time``),
   and the output is the inverse-variance blend

       v̂ = w v̂_model + (1 − w) v̂_kf,   w = P_kf / (P_kf + s),

   (``q̂`` likewise, in the tangent space at ``q̂_model``).  The ``kf``'s own
   variance understates its error (its white-jerk model is wrong too), so
   the disagreement is blamed on the model only as far as the model-based
   filter's innovations say it is inconsistent: the target of ``s`` is
   multiplied by ``clip((NIS̄/nv − 2)/2, 0, 1)`` (``NIS̄`` the running mean of
   the normalized innovation squared).  With an exact model ``w = 1``; with
   a wrong one the innovations grow and ``w → 0``.  The bank skips what the model-based
   filter's gate rejects, unless that filter is lost (restarted, not replaced since): on a
   UR10e log, lost every 2–4 steps, its gate starved the bank (240 of 706 samples), ``P_kf``
   grew to 1.35 rad²/s², the lost filter got weight: 3.4× kf (0.99× since).  On robots whose joints
   are all vector joints the bank and the blend are compiled loops (numba;
   in NumPy the bank alone cost about 15 ``pin.aba`` calls per update on a
   UR5),
   tested equal to the NumPy path that Lie-group robots take.

Learning happens only from samples the base class has committed
(:meth:`Observer.after_commit`), so a rejected update, a gated outlier or
a prediction that is not kept (under a known latency) teaches nothing.

4. **Off the loop** (``learning="background"``; issue 39).  Synchronous (the
   default, for offline replays: :func:`pinobs.estimate`, smoothing, the
   benchmarks), the rows of each window and each solve run inside the
   ``update`` that completes them: on a UR5 at 1 kHz 1.2–1.6 ms every 0.1 s
   (``smooth_path`` 0.3 ms, the regressor 0.7 ms) and 4–9 ms every 0.5 s
   (the solve), measured on a loaded 2-core machine.  In the background
   they run in a worker process (:class:`~pinobs.observers.worker.Worker`:
   not a thread, whose Python and Pinocchio calls hold the GIL the loop
   waits for — the window rows hold it nearly throughout; measured in that
   module's docstring).  The update only does the bookkeeping (the buffer,
   the interval, when to solve) and sends a window's samples or a solve's
   inputs (the current model, the configurations to check ``M(q) ≻ 0`` at);
   it never waits: a result is taken at the first update after it is done,
   in order, and changes the learner as it would have synchronously (a
   late solve is used late: installed then, compared with the model that
   was current when it was asked for).  One solve at a time: while one is
   out, the next is asked for when it is back.  Given the time to finish
   before each result is taken (the test hook ``Learner.join``), the
   output equals the synchronous one (tested to 1e-12: it is bit-identical);
   fed as fast as it runs, a UR5 with a payload made the same number of
   solves or one fewer, its velocity RMS within ±10 % of the synchronous
   one.  Nothing of SciPy's is imported for it (its QR and least squares are NumPy's
   LAPACK, the smoothing NumPy's; :func:`~pinobs.observers.adaptive_learner.load_learning`).

5. **A pure step** (issue 37).  What it learned lives in its state (``AdaptiveState.model``: the
   learned model and the filter run on it, the offset, the regime, the restarts; the
   learner), never on the observer: ``step`` reads it and returns it changed (a restart) in
   a new state, so a step that is not kept (a latency's prediction, the warm-up step)
   changes nothing.  The learner is the one part changed in place, and only by
   :meth:`~AdaptiveEKF.after_commit`, on the state the base has just committed: there it
   takes the sample, and a background job's result done by then (the sample boundary), and
   a new model or regime goes into the committed state.  Read from the latest state:
   :attr:`~AdaptiveEKF.regime`, :attr:`~AdaptiveEKF.restarts`, :meth:`~AdaptiveEKF.snapshot`.

6. **One call** (issue 39): a plain update with a sample is :mod:`pinobs.observers.adaptive_fused`'s,
   the step, the blend, the estimate and the learner's row in compiled calls (the same bits).
"""

from __future__ import annotations

import copy
import math
from dataclasses import replace
from typing import Any

import numpy as np

from pinobs.errors import (
    GainError,
    ObserverDiverged,
    OptionError,
    UnsupportedRobotError,
)
from pinobs.model import Robot
from pinobs.model.identification import (
    ParameterSet,
)
from pinobs.observers.adaptive_blend import (
    JERK_PSD,
    NIS_TRUSTED,
    REJECTED_RUN,
    BankBlend,
    bank_blend_kernel,
    blend_inputs,
    blend_state,
    lost_filter,
    model_free,
    numpy_blend,
    offsets,
    packed,
)
from pinobs.observers.adaptive_fused import NIS_REVOKED, VECTOR_TABLE, FusedParts, update_fused
from pinobs.observers.adaptive_learner import (
    Learner,
    check_options,
    learning_worker,
    load_learning,
)
from pinobs.observers.adaptive_state import AdaptiveModel as _Model
from pinobs.observers.adaptive_state import AdaptiveState as _State
from pinobs.observers.adaptive_state import ModelSnapshot
from pinobs.observers.base import (
    LIKELY_CAUSES,
    Consistency,
    Observer,
    Vector,
    positive,
    register,
)
from pinobs.observers.ekf import EKFState, ExtendedKalmanFilter
from pinobs.observers.kf_bank import KFBank
from pinobs.observers.worker import Worker

__all__ = ["AdaptiveEKF", "ModelSnapshot"]


_new_tuple = tuple.__new__  # a NamedTuple made without its __new__, a Python call (step)


#: ``λ h`` up to which a learned joint friction is a held input of the filter rather than part
#: of its model (``λ = (M⁻¹)ᵢᵢ |∂τ_f,ᵢ/∂v|``, largest over the configurations the learner
#: checked): the friction held at the extrapolated mid-step velocity (:meth:`AdaptiveEKF._torque`)
#: is, for a linear friction, a two-step Adams–Bashforth step, stable for ``λh < 1``; the 10×
#: margin covers configurations the check did not sample.  Stiffer friction stays in the
#: model (``ekf``'s stiff-friction path, which costs its substeps and ``exp(Ah)`` by squaring).
_HELD_FRICTION_STIFFNESS = 0.1


#: Where the learner's windows and solves run (:class:`AdaptiveEKF`, ``learning``).
_LEARNING = ("sync", "background")


@register
class AdaptiveEKF(Observer["_State"]):
    """EKF that identifies its model online and blends with a model-free filter (module docstring).

    A composition: ``core``, an :class:`~pinobs.observers.ekf.ExtendedKalmanFilter` copied
    with the model and densities the learner sets (its ``replace_robot`` and ``gains``) into
    the state, driven through its public ``initial_state`` and ``step``; the learner; a bank
    of model-free ``kf`` (:class:`~pinobs.observers.kf.KFBank`).

    Args:
        robot: the nominal model (the identification's prior).
        window: identification window [s] (one block of ``nv`` rows each).
        half_window: half-width of the zero-phase smoother of the measured path [s].
        horizon: rows kept for the solve [s] (a sliding window).
        resolve_every: time between solves [s].
        friction: learn joint friction.
        offset: learn a torque offset.
        accel_psd: white-acceleration density once a model is learned [rad²/s³].
        warmup_accel_psd: the same before the first solve.
        disturbance_psd: density of the torque-offset state (as in ``ekf``) before the first solve [rad²/s⁵].
        learned_disturbance_psd: the same once a model is learned.
        validated_accel_psd: ``accel_psd`` while a solve finds nothing better than
            the nominal model (the exact-model regime of ``ekf``).
        validated_disturbance_psd: ``disturbance_psd`` in that regime.
        blend: blend with the model-free ``kf`` (never behind it).
        blend_time: averaging time of the disagreement [s].
        jerk_psd: the white-jerk densities of the ``kf`` bank [rad²/s⁵] (module docstring).
        q0_std: initial configuration standard deviation [rad] (as in ``ekf``).
        v0_std: initial velocity standard deviation [rad/s] (as in ``ekf``).
        d0_std: initial standard deviation of the torque offset [N·m or N] (as in ``ekf``).
        outlier_probability: the outlier gate (as in ``ekf``; the ``kf`` skips what it rejects).
        rate: sample rate [Hz]: the identification windows are counted in samples of
            ``1/rate``; not given, of the stream's first interval.  Either way, ten
            consecutive intervals off it by more than half (that agree among themselves)
            replace it, said in ``consistency().details["rejected"]``.  Jitter within
            ±h/2 is not a gap.
        noise_std: position noise standard deviation [rad or m].
        learning: ``"sync"``: the identification runs inside ``update`` (offline replays:
            the results do not depend on the machine's pace); ``"background"``: in a worker
            process, its results taken when they are done (a live loop: no update waits for
            it; module docstring, 4).  The observer then owns a process (started from
            multiprocessing's fork server: a script that makes one guards its top-level
            code with ``if __name__ == "__main__":``), which ends when it is dropped.
    """

    name = "adaptive"
    uses_noise_std = True
    fresh_output = True  # (output: copied out of the state's buffer)
    #: :func:`pinobs.smooth` smooths its model-based filter, the learned model frozen per window
    smoothable = True
    learns_model = True
    summary = "EKF that identifies its model online, blended with kf: never behind it (model-based)"

    def __init__(
        self,
        robot: Robot,
        *,
        window: float = 0.1,
        half_window: float = 0.05,
        horizon: float = 10.0,
        resolve_every: float = 0.5,
        friction: bool = True,
        offset: bool = True,
        accel_psd: float = 1e-6,
        warmup_accel_psd: float = 1e-2,
        disturbance_psd: float = 1.0,
        learned_disturbance_psd: float = 1e-4,
        validated_accel_psd: float = 1e-8,
        validated_disturbance_psd: float = 1e-8,
        blend: bool = True,
        blend_time: float = 0.2,
        jerk_psd: tuple[float, ...] = JERK_PSD,
        q0_std: float = 0.1,
        v0_std: float = 1.0,
        d0_std: float = 1.0,
        outlier_probability: float | None = 1e-6,
        rate: float | None = None,
        noise_std: float | None = None,
        learning: str = "sync",
    ) -> None:
        if learning not in _LEARNING:
            raise GainError(f"learning={learning!r} must be one of {', '.join(_LEARNING)}")
        super().__init__(robot, rate=rate, noise_std=noise_std)
        #: The model-based filter (class docstring).
        self.core = ExtendedKalmanFilter(
            robot, accel_psd=warmup_accel_psd, q0_std=q0_std, v0_std=v0_std,
            disturbance_psd=disturbance_psd, d0_std=d0_std,
            outlier_probability=outlier_probability, rate=rate, noise_std=noise_std,
        )  # fmt: skip
        check_options(
            window=window, half_window=half_window, horizon=horizon, resolve_every=resolve_every,
            accel_psd=accel_psd, blend_time=blend_time,
            learned_disturbance_psd=learned_disturbance_psd,
            validated_accel_psd=validated_accel_psd,
            validated_disturbance_psd=validated_disturbance_psd,
        )  # fmt: skip
        self._nominal = self.core.robot
        self._learn_options = dict(
            window=float(window), half_window=float(half_window), horizon=float(horizon),
            resolve_every=float(resolve_every), friction=bool(friction), offset=bool(offset),
            rate=None if self.rate is None else float(self.rate),
        )  # fmt: skip
        self.learning = learning
        self._start_learning(learning)
        self.blend = bool(blend)
        self.blend_time = float(blend_time)
        self._bank = self._make_bank(jerk_psd)
        self._regimes = {  # (accel_psd, disturbance density) per regime
            "warmup": (float(warmup_accel_psd), float(disturbance_psd)),
            "nominal": (float(validated_accel_psd), float(validated_disturbance_psd)),
            "learned": (float(accel_psd), float(learned_disturbance_psd)),
        }
        zero = np.zeros(self.robot.nv)
        # what is read of it before a reset (afterwards, of its latest state: _model)
        self._idle = _Model(self.core, self._nominal, None, zero, "warmup", zero, 0, False, 0)

    def _start_learning(self, learning: str) -> None:
        """The learner: its SciPy modules imported now (synchronous, :func:`load_learning`), or
        its worker process started now, not waited for (:func:`learning_worker`; it ends when
        the observer is dropped)."""
        self._worker: Worker | None = None
        if learning == "sync":
            load_learning()
        else:
            friction, offset = (bool(self._learn_options[k]) for k in ("friction", "offset"))
            self._worker = learning_worker(self._nominal, friction, offset)
        self._learner = self._new_learner()  # read before a reset (each reset makes its own)
        if self._learner.reg.size == 0:
            name = self.robot.name
            raise UnsupportedRobotError(f"robot {name!r} has no dynamic parameter to learn")

    def _new_learner(self) -> Learner:
        """A :class:`~pinobs.observers.adaptive_learner.Learner` afresh from the nominal model."""
        options: dict[str, Any] = self._learn_options
        return Learner(self._nominal, **options, worker=self._worker)

    def _make_bank(self, jerk_psd: tuple[float, ...]) -> KFBank:
        """The blend's bank of ``kf`` filters of densities ``jerk_psd`` (checked: a non-empty
        sequence of numbers > 0); the compiled blend loaded now on vector joints."""
        try:
            jerks = tuple(float(positive("jerk_psd", j) or 0.0) for j in jerk_psd)
        except TypeError:
            raise GainError(f"jerk_psd={jerk_psd!r} must be a sequence of numbers > 0") from None
        if not jerks:
            raise GainError("jerk_psd needs at least one density")
        bank = KFBank(self.robot, jerks, self.core.gains.meas_std)
        if self.blend and self.robot.is_vector_space:
            bank_blend_kernel.load()
        self._vector = self.robot.is_vector_space  # (a Python property: read once)
        self._fused = self._vector and bank_blend_kernel.compiled is not None  # (blend_state)
        self._bank_blas = self.blend and not self._fused  # (NumPy's bank may call a BLAS)
        self._nq = self.robot.nq
        self._shape = (bank.jerk.size, self._nq, self.robot.nv)  # (_State.shape)
        self._estimate = slice(*offsets(*self._shape)[7:10:2])  # q̂ then v̂ (output)
        # a plain update whole in one Python call (Observer._update_fused; adaptive_fused)
        fused = self._fused and type(self) is AdaptiveEKF
        self._fused_parts = (
            FusedParts.build(self._estimate, self.robot.nv, blend=self.blend) if fused else None
        )
        self._fused_path = self._fused_parts is not None
        self._no_sample = np.zeros(self.robot.nq)  # the compiled step's q_meas without one
        return bank

    _update_fused = update_fused  # (Observer.update's first offer: adaptive_fused.update_fused)

    #: The caller's choice (``False``: never the one-BLAS-thread limit; :attr:`uses_blas`).
    _blas_limit = True

    @property
    def uses_blas(self) -> bool:  # type: ignore[override]
        """Whether :meth:`update` runs on one BLAS thread (:attr:`Observer.uses_blas`): not
        where none of its parts calls a BLAS (11–12 µs an update in a paced loop): the
        model-based filter's compiled step (``core.uses_blas``, of the latest state's model) and
        the compiled bank and blend (vector joints).  The learner's windows and solves run on
        one BLAS thread of their own, in the update (``learning="sync"``) as in the worker
        process.  Set ``False``: never for the rest of the update (as on any family)."""
        if not self._blas_limit:
            return False
        state = self._state
        core = self.core if state is None else state.model.core
        return self._bank_blas or core.uses_blas

    @uses_blas.setter
    def uses_blas(self, value: bool) -> None:
        self._blas_limit = bool(value)

    @property
    def options(self) -> dict[str, Any]:
        return {
            **self.core.options,
            **self._learn_options,
            "accel_psd": self._regimes["learned"][0],
            "warmup_accel_psd": self._regimes["warmup"][0],
            "learned_disturbance_psd": self._regimes["learned"][1],
            "validated_accel_psd": self._regimes["nominal"][0],
            "validated_disturbance_psd": self._regimes["nominal"][1],
            "blend": self.blend,
            "blend_time": self.blend_time,
            "jerk_psd": self._bank.jerk.tolist(),
            "learning": self.learning,
        }

    # ---------------------------------------------------------------- learning
    # What it learned is read from its latest committed state (module docstring, 5).
    def _model(self) -> _Model:
        return self._idle if self._state is None else self._state.model

    def _learning(self) -> Learner:
        return self._learner if self._state is None else self._state.learner

    @property
    def regime(self) -> str:
        """``"warmup"``, ``"nominal"`` or ``"learned"`` (module docstring, 1)."""
        return self._model().regime

    @property
    def restarts(self) -> int:
        """Times the model-based filter was lost and restarted since the reset."""
        return self._model().restarts

    def learned_robot(self) -> Robot:
        """A :class:`Robot` carrying the current estimate (friction included; the nominal one before the first solve)."""
        return self._model().learned.copy()

    def snapshot(self) -> ModelSnapshot:
        """The learned model, offset and regime densities now (read only: the filter is unchanged).

        The model is the filter's, with the learned friction it takes as a held input
        (:meth:`_install`) put back: the learned model whole."""
        m = self._model()
        accel, dist = self._regimes[m.regime]
        robot = m.core.robot if m.held is None else m.learned
        return ModelSnapshot(robot.copy(), m.offset.copy(), m.regime, accel, dist * m.m_bar2)

    def lost(self) -> bool:
        """Whether the model-based filter's estimate or covariance is not finite, or its
        latest update diverged (with the blend, the next update restarts it; without, it
        stays lost: every update raises ``ObserverDiverged`` until :meth:`reset`).  A
        diverged update keeps the last finite state, so this said ``False`` then (a sweep)."""
        if self._state is None:
            return False
        return self._diverged or lost_filter(self._state.ekf)

    def parameters(self) -> ParameterSet:
        """The learned parameters with names and standard deviations (nominal before the first solve)."""
        lr = self._learning()
        reg = lr.reg
        nominal = reg.nominal()
        if lr.theta is None or lr.std is None or lr.excited is None:
            prior = reg.prior_std()
            return ParameterSet(reg.names, nominal, prior, nominal, np.zeros(reg.size, bool))
        return ParameterSet(reg.names, lr.theta.copy(), lr.std.copy(), nominal, lr.excited.copy())

    def consistency(self) -> Consistency:
        """The NIS test of the base class, with what the learner did in ``details``:
        solves, the regressor's condition number and rank, rejected solves (a
        failed re-solve keeps the last model and is listed here: the latest
        :data:`~pinobs.observers.adaptive_learner.REJECTED_KEPT`), the blend
        weights.  ``"inconsistent"`` whatever the
        NIS after :data:`~pinobs.observers.adaptive_blend.REJECTED_RUN` rejected solves in a row (no physical model
        fits the data)."""
        lr = self._learning()
        base = super().consistency()
        if lr.rejected_run >= REJECTED_RUN:  # no model from the data: the NIS cannot see it
            cause = lr.rejection_cause()
            singular = cause.startswith("no rows")  # (then the usual suspects are not)
            causes = (cause,) if singular else (cause, *LIKELY_CAUSES)
            base = replace(base, verdict="inconsistent", causes=causes)
        details = {
            "solves": lr.solves,
            "installs": lr.installs,
            "inconclusive": lr.inconclusive,
            "last_loss_drop": lr.last_drop,
            "condition": float(lr.condition),
            "rank": lr.rank,
            "n_parameters": lr.reg.size,
            "rows": lr.row_count,
            "rejected": list(lr.rejected),
            "warming_up": lr.theta is None,
            "regime": self.regime,
            "restarts": self.restarts,
            "blend_weight": None if self._state is None else self._weights(self._state).tolist(),
        }
        return replace(base, details=details)

    def _set_regime(
        self, model: _Model, ekf: EKFState, regime: str, robot: Robot | None = None
    ) -> tuple[_Model, EKFState]:
        """Switch the process noise: ``warmup`` (nominal model not trusted yet), ``nominal``
        (a solve found nothing better: the exact-model densities), ``learned`` (a learned
        model); on a new filter (``model.core``'s copy, on ``robot`` if given) when it changes."""
        accel, dist = self._regimes[regime]
        if robot is not None or regime != model.regime:
            core = copy.copy(model.core)  # (shares its scratch buffer: one step at a time)
            if robot is not None:
                core.replace_robot(robot)
            core.gains = replace(core.gains, accel_psd=accel)
            model = model._replace(core=core, regime=regime)
        if ekf.d_psd is None:
            return model, ekf
        return model, ekf._replace(d_psd=dist * model.m_bar2)  # per joint, as ekf: psd · M̄ᵢᵢ²

    def _install(self, model: _Model, lr: Learner, ekf: EKFState) -> tuple[_Model, EKFState]:
        """Install the learner's model: friction that cannot be stiff (``λᵢ h ≤``
        :data:`_HELD_FRICTION_STIFFNESS`) as a held input, the rest in the filter's model."""
        assert lr.theta is not None
        name = f"{self._nominal.name}~learned"
        learned = lr.reg.with_parameters(lr.theta, name=name)
        theta = lr.theta
        held_friction = None
        if lr.reg.friction and learned.has_friction:
            # λᵢ = max (M⁻¹)ᵢᵢ |∂τ_f,ᵢ/∂v| (its largest slope is at v = 0)
            lam = lr.minv_max * np.abs(learned.friction_derivative(np.zeros(self.robot.nv)))
            held = lam * lr.h <= _HELD_FRICTION_STIFFNESS
            if np.any(held & (lam > 0)):
                n, nj = lr.reg.n_inertial, lr.reg.n_joint
                cols = held[list(lr.reg.actuated)]
                theta = theta.copy()
                theta[n : n + nj][cols] = 0.0
                theta[n + nj : n + 2 * nj][cols] = 0.0
                held_friction = held.astype(float)
        model = model._replace(learned=learned, held=held_friction, offset=lr.reg.offsets(lr.theta))
        # the filter's model is the learned one itself unless friction is held: shared (no
        # one changes a Robot, and each call on its pin.Data finishes before the next;
        # built twice, 0.5 ms each on a UR5, issue 39)
        robot = learned if theta is lr.theta else lr.reg.with_parameters(theta, name=name)
        model, ekf = self._set_regime(model, ekf, "learned", robot)
        if ekf.d is None:
            return model, ekf
        return model, ekf._replace(d=np.zeros_like(ekf.d))  # the new model explains what d absorbed

    # ------------------------------------------------------------------ filter
    def initial_state(self, q0: Vector, v0: Vector) -> _State:
        # a reset starts learning afresh from the nominal model, on a filter of its own
        core = copy.copy(self.core)
        core.replace_robot(self._nominal.copy())
        m_bar2 = np.diag(self._nominal.mass_matrix(q0)) ** 2
        offset = np.zeros(self.robot.nv)
        model = _Model(core, self._nominal, None, offset, "warmup", m_bar2, 0, False, 0)
        ekf = core.initial_state(q0, v0)
        kf = self._bank.initial(q0, v0, core.gains.v0_std)
        score = np.zeros((self._bank.jerk.size, self.robot.nv))
        s = np.zeros(self.robot.nv)  # the model is trusted until the data disagree
        learner = self._new_learner()
        x = blend_state(self._shape, kf, score, s, q0, v0, buffer=self._fused)
        state = _State(ekf, x, self._shape, 0.0, ekf.v, 0.0, model, learner)
        self._warm(state, q0)
        return state

    def _warm(self, state: _State, q0: Vector) -> None:
        """One step from ``state`` to ``q0``, thrown away: the first ``update`` then runs
        on paths already taken (NumPy's and the filters' first calls, their caches: the
        kernels are compiled or loaded when the observer is made, SciPy imported then too).
        UR5 in a loop paced at 1 kHz, first update 820–1065 µs without it, 295–406 µs with it
        (median update 200 µs).  ``step`` is pure: nothing to put back."""
        h = 1.0 / self.rate if self.rate else 1e-3
        with np.errstate(all="ignore"):
            self.step(state, h, q0, np.zeros(self.robot.nv))

    def restart_state(self, state: _State, q: Vector) -> _State:
        """After a pause: the filter and the bank afresh at ``q`` (zero velocity), in the
        current regime; the learned model, offset and learner kept (a reset would relearn)."""
        zero = np.zeros(self.robot.nv)
        model = state.model
        model, ekf = self._set_regime(model, model.core.initial_state(q, zero), model.regime)
        kf = self._bank.initial(q, zero, model.core.gains.v0_std)
        score = np.zeros((self._bank.jerk.size, self.robot.nv))
        x = blend_state(self._shape, kf, score, zero, q, zero, buffer=self._fused)
        return _State(ekf, x, self._shape, state.t, ekf.v, 0.0, model, state.learner)

    def _model_free(self, state: _State) -> tuple[Vector, ...]:
        """Per coordinate, the bank's ``kf`` with the smallest running innovation:
        ``(its v, its velocity variance, its tangent offset from the EKF's q̂)``."""
        return model_free(self.robot, state.kf, state.score, state.ekf.q)

    def _weights(self, state: _State) -> Vector:
        if not self.blend:
            return np.ones(self.robot.nv)
        p_kf = self._model_free(state)[1]
        return p_kf / (p_kf + state.s + 1e-300)

    def _torque(self, state: _State, dt: float, tau: Vector) -> Vector:
        """The torque the filter's model is given over the next step of ``dt`` [s]: ``τ + b̂``,
        plus, on the joints where it is an input (:meth:`_install`), the learned friction at
        the mid-step velocity extrapolated from the last step, ``τ_f,θ̂(v̂ + (h/2)(v̂ − v̂₋)/h₋)``
        (``v̂₋``, ``h₋``: the state's ``v_prev``, ``dt_prev``; no extrapolation before
        a first step).  Held at ``v̂`` alone, its error would be first order,
        ``h |∂τ_f/∂v| |a| h/2`` per step (7e-4 rad/s on a UR5 started on a noise-free truth);
        extrapolated, second order (tested)."""
        m = state.model
        if m.held is None:
            return tau + m.offset
        v = state.ekf.v
        v_mid = v + (0.5 * dt / state.dt_prev) * (v - state.v_prev) if state.dt_prev > 0 else v
        return tau + m.offset + m.held * m.learned.friction_torque(v_mid)

    @np.errstate(over="ignore", invalid="ignore")  # (a decorator: 1 Python call, not 3)
    def _core_step(
        self, core: ExtendedKalmanFilter, ekf: EKFState, dt: float, q: Vector | None, tau: Vector
    ) -> EKFState:
        """The model-based filter's step, overflows quiet; one whose covariance overflowed to a
        singular innovation covariance, or that its family says diverged, comes back with a NaN
        velocity (lost: restarted by :meth:`step`).  On UR10e logs at ~95 Hz the warm-up filter's
        velocity variance reached 6e10 before ``solve`` raised ``LinAlgError``, which escaped
        the restart and left the re-initialisation to :func:`pinobs.estimate`."""
        try:
            return core.step(ekf, dt, q, tau)
        except (ObserverDiverged, np.linalg.LinAlgError, ArithmeticError):
            return ekf._replace(v=np.full_like(ekf.v, np.nan))

    def _restart(
        self, state: _State, dt: float, q_meas: Vector | None, tau: Vector
    ) -> tuple[_State, EKFState]:
        """The model-based filter is lost (a learned model that does not hold): restarted on
        the model-free estimate, in the warm-up regime, rather than fail; ``(state with the
        restart, its step)``.  Said and counted in the state's model (committed with it)."""
        t = state.t + dt
        v_kf, _, dq_kf = self._model_free(state)
        model = state.model
        restart = model.core.initial_state(self.robot.integrate(state.ekf.q, dq_kf), v_kf)
        model, restart = self._set_regime(model, restart, "warmup")
        state = state._replace(ekf=restart, dt_prev=0.0, model=model)
        ekf = self._core_step(model.core, restart, dt, q_meas, self._torque(state, dt, tau))
        said: tuple[str, ...] = ()
        if lost_filter(ekf) and model.learned is not self._nominal:
            # lost again at once: the learned model itself does not hold (a mass matrix
            # not positive definite away from the configurations its solve checked, held
            # friction stiff there: solo12 with friction, a Panda at hard stops raised
            # ObserverDiverged); back to the nominal model, which the learner may replace
            core = copy.copy(model.core)
            core.replace_robot(self._nominal.copy())
            zero = np.zeros(self.robot.nv)
            model = model._replace(core=core, learned=self._nominal, held=None, offset=zero)
            state = state._replace(model=model)
            said = (
                f"learned model dropped at t = {t:.6g} s (the filter restarted on it was "
                "lost at once): back to the nominal model",
            )
            ekf = self._core_step(core, restart, dt, q_meas, self._torque(state, dt, tau))
        ekf = restart if lost_filter(ekf) else ekf  # lost at once on the nominal one too
        said += (f"model-based filter restarted at t = {t:.6g} s",)
        # the next solve must beat the current model to end it (restarted)
        model = model._replace(restarts=model.restarts + 1, restarted=True, said=model.said + said)
        # the blend's error variance of the lost filter overflowed with it: the restarted
        # one starts with its initial velocity variance (the blend follows the kf first)
        s = np.full(self.robot.nv, model.core.gains.v0_std**2)
        if isinstance(state.x, BankBlend):
            return state._replace(model=model, x=state.x._replace(s=s)), ekf
        x = state.x.copy()
        x[slice(*offsets(*state.shape)[6:8])] = s
        return state._replace(model=model, x=x), ekf

    def step(self, state: _State, dt: float, q_meas: Vector | None, tau: Vector) -> _State:
        model = state.model
        core = model.core
        torque = tau + model.offset if model.held is None else self._torque(state, dt, tau)
        if core.compiled_step:
            # _core_step without its errstate (the compiled step raises no NumPy warning:
            # ExtendedKalmanFilter.compiled_step): 4 Python calls less an update (issue 39)
            try:
                ekf = core.step(state.ekf, dt, q_meas, torque)
            except (ObserverDiverged, np.linalg.LinAlgError, ArithmeticError):
                ekf = state.ekf._replace(v=np.full_like(state.ekf.v, np.nan))
        else:
            ekf = self._core_step(core, state.ekf, dt, q_meas, torque)
        t = state.t + dt
        if not self.blend:
            return state._replace(ekf=ekf, t=t, v_prev=state.ekf.v, dt_prev=dt)
        lam = min(1.0, dt / self.blend_time)
        kernel = bank_blend_kernel.compiled if self._vector else None
        if kernel is None:  # the bank's step and the blend in NumPy (Lie-group joints)
            if lost_filter(ekf):
                state, ekf = self._restart(state, dt, q_meas, tau)
            meas, blame = blend_inputs(ekf, state.model, q_meas)
            kf = self._bank.step(state.kf, dt, meas)
            score, s, q, v = numpy_blend(self.robot, kf, state.score, state.s, ekf, lam, blame)
            x: Vector | BankBlend = BankBlend(kf, score, s, q, v)
        else:  # one compiled call: whether the filter is lost, then the bank and the blend
            bank = self._bank
            for check in (True, False):
                xs = state.x  # (a BankBlend: made while the kernel was not loaded)
                xs = packed(state.shape, *xs) if isinstance(xs, BankBlend) else xs
                x = np.empty(xs.size)
                meas, blame = blend_inputs(ekf, state.model, q_meas)
                if kernel(
                    xs, x, state.shape[1], dt, self._no_sample if meas is None else meas,
                    meas is not None, bank.jerk, bank.meas_var, ekf.q, ekf.v, ekf.P, lam, blame,
                    check, VECTOR_TABLE,
                ):  # fmt: skip
                    break
                state, ekf = self._restart(state, dt, q_meas, tau)  # lost (module docstring, 3)
        return _new_tuple(
            _State, (ekf, x, state.shape, t, state.ekf.v, dt, state.model, state.learner)
        )

    def after_commit(self, state: _State, t: float, q: Vector | None, tau: Vector) -> _State:
        """Teach the learner the committed sample (with the torque held from it on, MATH §7);
        install a new model or leave the warm-up when a solve says so.  The one place the
        learner changes (module docstring, 5): what the steps since the last commit said
        (restarts) joins its ``rejected`` first, as when they said it."""
        model, ekf, lr = state.model, state.ekf, state.learner
        if model.said:
            lr.rejected.extend(model.said)
        nv = self._shape[2]  # (Robot.nv asks Pinocchio: a call)
        level = float(nv) if ekf.gate.level is None else ekf.gate.level
        # the first solve only ends the warm-up: the nominal model gets its chance with the
        # exact-model densities, and its innovations decide at the next solve
        # (a learned model is refined at every solve; only the nominal one is protected)
        explained = (model.regime == "warmup" and not model.restarted) or (
            model.regime == "nominal" and level <= NIS_TRUSTED * nv
        )
        if math.isnan(lr.next_solve):
            # the reset time; inside never_behind (which is the one reset) the first sample's
            lr.start(float(self._reset_args[0]) if self._reset_args else t)
        restarted = model.restarted
        if lr.add(t, q, tau, explained=explained, gated=q is None and bool(ekf.gate.gated)):
            model, ekf = self._install(model, lr, ekf)
            restarted = False
        elif model.regime == "nominal" and level > NIS_REVOKED * nv:
            # the nominal model stopped explaining the data between solves: do not wait
            if lr.candidate is not None:
                lr.theta = lr.candidate
                lr.installs += 1
                model, ekf = self._install(model, lr, ekf)
            else:  # nothing physical solved yet (Learner._inconclusive): the next solve decides
                lr.validated = False
                model, ekf = self._set_regime(model, ekf, "warmup")
        elif lr.validated and model.regime == "warmup" and not model.restarted:
            # the nominal model explains the data (a learned one, after a restart)
            model, ekf = self._set_regime(model, ekf, "learned" if lr.installs else "nominal")
        if model is state.model and lr.rejected_run == model.rejected_run and not model.said:
            return state if ekf is state.ekf else state._replace(ekf=ekf)
        model = model._replace(restarted=restarted, rejected_run=lr.rejected_run, said=())
        return state._replace(ekf=ekf, model=model)

    def innovation(self, state: _State) -> tuple[float | None, bool]:
        return state.ekf.gate.nis, state.ekf.gate.gated

    def output(self, state: _State) -> tuple[Vector, Vector]:
        """The blended estimate ``(q̂, v̂)``, copies (:attr:`fresh_output`), or without the blend the EKF's."""
        if not self.blend:
            return state.ekf.q.copy(), state.ekf.v.copy()
        x = state.x
        if isinstance(x, BankBlend):
            return x.q.copy(), x.v.copy()
        out = x[self._estimate].copy()
        return out[: self._nq], out[self._nq :]

    def smoothing_filter(self) -> ExtendedKalmanFilter:
        """None: a smoother runs it causally and replays its learned models frozen
        (:attr:`learns_model`; :func:`pinobs.smooth`).

        Raises:
            OptionError: always.
        """
        raise OptionError(
            "adaptive learns its model: pinobs.smooth runs it causally, then replays its "
            "learned models frozen per window (model_window)"
        )

    @property
    def disturbance(self) -> Vector | None:
        """The EKF's estimated joint-torque offset ``d`` beyond the learned offset [N·m or N]."""
        if self._state is None or self._state.ekf.d is None:
            return None
        return np.array(self._state.ekf.d)

    def covariance(self) -> Vector:
        """The EKF's covariance of ``(δq, δv, δd)`` (before the blend), a copy."""
        if self._state is None:
            return self.core.covariance()  # NaN: not reset
        return np.array(self._state.ekf.P)

"""Extended Kalman filter on the configuration manifold: the model-based baseline.

State ``(q̂, v̂)`` with ``q̂`` on the configuration group and an error state in
the tangent space, ``q = q̂ ⊕ δq``, ``v = v̂ + δv``, ``δx = (δq, δv) ∈ R^{2nv}``
with covariance ``P`` (2nv × 2nv).

Prediction over a sample interval ``h`` with the torque ``τ`` held (MATH §7):
the mean by one RKMK4 step (:func:`pinobs.model.dynamics_rk4`) of

    q̇ = q · v,   v̇ = a(q, v, τ) = M⁻¹(q)(τ + τ_f(v) − c(q, v) − g(q)),

the covariance by the linearised error dynamics, to first order in ``δx``:

    δq̇ = −ad_v̂ δq + δv,                 (q̂ exp(δq))' = q̂ exp(δq) v; ad_v̂ δq = [v̂, δq]
    δv̇ = ∂a/∂q δq + ∂a/∂v δv + w,        w white, E[w wᵀ] = ``accel_psd`` · I δ(t)

(``τ_f`` the robot's joint friction, zero unless its URDF has some;
``∂a/∂q`` along ``integrate``, analytic from ``pin.computeABADerivatives``;
``ad_v̂`` is zero for vector and continuous joints).  With
``A = [[−ad_v̂, I], [∂a/∂q, ∂a/∂v]]`` evaluated at the start of the interval,

    Φ = I + Ah + (Ah)²/2 + (Ah)³/6 ≈ exp(A h),   Q_d = q_w [[h³/3 I, h²/2 I], [h²/2 I, h I]],   P⁻ = Φ P Φᵀ + Q_d.

(the truncation, ``‖Ah‖⁴/24``, is below 1e-6 at 1 kHz on a UR5, where
``‖A h‖ ≈ 0.03``; ``scipy.linalg.expm`` costs 20× more for nothing).
``Q_d`` is the white-acceleration covariance of a double integrator, the
leading term of Van Loan's integral when ``‖A h‖ ≪ 1``.

Implementation (issue 18).  One ``pin.computeABADerivatives`` per update gives
``A`` and the first RK4 stage; ``A`` lives in a preallocated buffer whose
constant blocks are written once; ``Q_d`` is cached per sample interval.  For
``nv ≤ 12`` the Joseph update and ``Φ`` are one compiled loop each (numba,
imported and loaded by the constructor; compiled once per installation with
``cache=True``), where NumPy would spend its time dispatching a dozen
12 × 12 operations; above, NumPy (BLAS products, a LAPACK Cholesky).  Both
paths live in :mod:`pinobs.observers.linalg`, shared with the other filters,
and are tested equal to the dense pre-optimisation implementation to 1e-12.
On a vector-space robot without friction (``nv ≤ 12``) the whole step is four
compiled calls around Pinocchio's four (issue 39, :mod:`pinobs.observers.fused`:
RK4 stages, ``Φ P Φᵀ + Q_d``, the last stage with the Joseph correction; on the filter's
own ``pin.Data``): on a UR5, 23 → 14 ``pin.aba`` per update (``measure_cost``, CPU
time; five calls then, 12.7 → 11.7 with four), equal to the NumPy step to rounding (tested).  With Lie-group or continuous
joints (no friction), :class:`_LieFast`: the RKMK4 step compiled between Pinocchio's
calls up to ``nv = 12`` (:class:`~pinobs.observers.fused_lie.LieRK4`); from ``nv = 28``
without the offset state, the whole step by blocks (:mod:`pinobs.observers.blockstep`:
``Φ`` from ``A``'s blocks in two BLAS products, ``Φ P Φᵀ`` in two more, a compiled
Cholesky gain, the Joseph update's lower block triangle (now ``P⁻ − Zᵀ Z``), the compiled RKMK4, the
arithmetic between them compiled; with the update's input checks of issue 39): a talos
(nv = 38) 31.4 → 22.7 ``pin.aba`` per update (``measure_cost``, CPU time, median of six
processes each, the trees alternating, load 3.0–3.4), of which Pinocchio's four calls are
7.2, the eight BLAS products 6.5 and the gain 1.7; a go1 (nv = 18) 32.9 → 22.1; then 44 → 33
Python calls an update (go1: 43 → 32) and a faster gain, 9.8 µs (talos) and 6.8 µs (go1) less
an update (in-process A/B, CPU time), the same bits.  Then ``Φ`` by ``A``'s block rows (two
``nv × nv × 2nv`` products) and ``P⁺ = P⁻ − Zᵀ Z``, ``Z = U⁻ᵀ P⁻_q·`` (``S = Uᵀ U``; the Joseph
form's value for the optimal gain, Bar-Shalom, Li & Kirubarajan 2001 §5.2.3; the Joseph form
above ``P⁻_qq,ii > 10⁴ R``): the talos's covariance algebra 11.3 → 9.0 ``pin.aba``, 43 µs less,
estimates within 1e-14 of the Joseph step's over 60 s (:mod:`pinobs.observers.blockstep`).
The compiled step's kernels without numba's dispatcher where the state is its own (the one it
returned last) and the sample a float64 array of unit stride: UR5 2.7 µs less an update in a
paced 1 kHz loop (in-process A/B, load 6.3), the same bits.  Then a plain update without the
offset state whole in one Python call (:mod:`pinobs.observers.ekf_fused`: the base's checks,
the step, the estimate and the commit; 12 → 2 Python calls an update): UR5 47.7 → 40.9 µs
(18.3 → 15.7 warm ``pin.aba``) in a paced 1 kHz loop (in-process A/B against the base's path,
tick by tick, load 6.6), the same bits.  Then (issue 39, the same bits) the prediction
kernel skips the exact zeros of ``A``'s constant blocks and takes ``(Φ P) Φᵀ`` by whole rows
(:func:`~pinobs.observers.fused.ekf_predict_loops`: 3.04 → 2.47 µs warm on a UR5; the update
10.85 → 10.60 ``pin.aba``, 0.66 µs less, Panda 11.58 → 11.18, in-process A/B, load 2.5), the
correction's triangular solves run by rows (``fused._joseph_rows``: the finish kernel 3.47 →
2.85 µs warm), and a large robot's plain update with a sample is one offer too
(:func:`~pinobs.observers.ekf_fused.update_blocks`; talos 22.04 → 21.16 ``pin.aba``).  With
all three, ``measure_cost`` (thread CPU, 8 fresh processes alternated with the code before,
load 3–4): UR5 11.53 → 10.99, Panda 12.13 → 11.16, talos 23.31 → 22.74 (medians).
predict and correct (:meth:`predict`, :meth:`correct`: smoothers, the offset state) take
``Φ`` and the Joseph update on ``A``'s blocks (:mod:`pinobs.observers.blocks`).

Joint friction (Coulomb's smoothed step, :meth:`pinobs.model.Robot.friction_torque`,
``τ_f = −D v − F_c tanh(v/v_s)``) makes the error dynamics stiff near ``v = 0``:
its slope ``−F_c/v_s`` (200 N·m·s/rad for 2 N·m at v_s = 0.01 rad/s) enters
``∂a/∂v`` as ``−M⁻¹ F_c/v_s``, so ``λ h`` reaches 55 on a Panda's wrist at
1 kHz (``λ = (M⁻¹)ᵢᵢ F_c/v_s``).  The third-order series above is then
meaningless (it grows like ``(λh)³/6``) and so is one RK4 step (stable for
``λh < 2.785``): before this treatment the filter ended at 4 rad/s RMS on a
Panda with F_c = 1–3 N·m in both truth and model.  With friction the model
is kept as it is (no slope dropped) and both steps are made valid:

* the mean takes ``n`` RK4 substeps, ``n = ⌈λ h / 2.5⌉`` with ``λ`` the
  largest ``(M⁻¹)ᵢᵢ |∂τ_f,ᵢ/∂v|`` at the velocity nearest zero each joint
  can reach in the step, ``max(|vᵢ| − |aᵢ| h, 0)``
  (:func:`pinobs.model.integrators.friction_substeps`; one substep away from zero velocity);
* ``Φ = exp(A h)`` by scaling and squaring (:func:`stiff_transition_matrix`:
  the series on ``A h / 2ˢ``, squared ``s`` times, ``‖A h‖∞ / 2ˢ ≤ 1/4``),
  which contracts the velocity covariance of a sticking joint as the
  friction does.

Measured (Panda, F_c uniform in 1–3 N·m (seeded), pd tracking, 1 kHz,
σ = 1e-4 rad, 3 s, the truth integrated with 40 substeps, RMS after 0.75 s):
``ekf`` 9.1e-5 → 3.9e-5 (seed 0), 6.0e-5 → 3.4e-5 (seed 1) without → with
friction: friction makes sticking joints easier, not harder.  The cost grows
only in the samples where a joint can reach zero velocity.

Update with ``q_meas = q ⊕ n``, ``n ~ N(0, σ² I)``: innovation
``e = difference(q̂⁻, q_meas) ≈ δq + n`` (so ``H = [I 0]``), gain
``K = P⁻Hᵀ(H P⁻Hᵀ + σ² I)⁻¹``, ``(δq, δv) = K e``, ``q̂ = q̂⁻ ⊕ δq``,
``v̂ = v̂⁻ + δv``, and the Joseph form
``P = (I − KH) P⁻ (I − KH)ᵀ + K σ² Kᵀ`` keeps ``P`` symmetric positive
definite.  The covariance is not re-expressed in the tangent space of the
corrected ``q̂`` (that reset, ``J_r(δq)``, differs from the identity by
``O(|δq|)``, below 1e-3 once the filter has converged).

Defaults: σ = ``noise_std`` (1e-6 rad if not given, so the filter trusts the
encoder); initial standard deviations ``q0_std`` = 0.1 rad, ``v0_std`` =
1 rad/s; ``accel_psd`` = the robot's own model-error density when it has one
(:attr:`pinobs.Robot.model_error_psd`: ``pinobs.identify`` measures it on its fitted rows,
``ψ = mean(e²)·h̄`` of the identified dynamics' acceleration error against the
Savitzky–Golay accelerations less their noise floor,
:mod:`pinobs.model.identification.model_error`), else 1e-8 rad²/s³, i.e. the filter
trusts the model; an ``accel_psd`` given always wins.  ``accel_psd`` stands for the
model error and is the one number to tune.  On the real UR10e
(``benchmarks/real_ekf_phases.md``, three held-out logs) ``ekf`` alone on the identified
model was 7.4–20× the default ``kf`` at 1e-8 and 1.40–1.74× at the density the
identification stored (0.0106 rad²/s³; 1.28–1.56× at 3.4e-3, matched to its one-step
error).
Measured on a UR5 tracking the ``pd`` reference at 1 kHz, σ = 1e-4 rad,
2 s (velocity RMS error after 0.5 s):

    accel_psd [rad²/s³]     1e-10    1e-8     1e-6     1e-4     1e-2     1
    exact model             3.0e-5   3.4e-5   1.3e-4   7.9e-4   4.6e-3   2.5e-2
    +0.5 kg on the wrist    —        3.8e-1   1.3e-1   3.8e-2   1.2e-2   2.5e-2

so with an uncertain payload or friction raise it to 1e-2 (the per-joint
``kf``, which needs no model, scores 5.2e-3 on both).

Input-disturbance augmentation (option ``disturbance_psd``, the mitigation of
model errors a practitioner would choose).  The state gains a joint-torque
offset ``d`` [N·m or N] that the model lacks (payload, friction, inertia
errors all show up as one), a random walk of density ``disturbance_psd``
[N²·m²/s]::

    v̇ = M⁻¹(q)(τ + d + τ_f(v) − c − g),     ḋ = w_d,
    A = [[−ad_v̂, I, 0], [∂a/∂q, ∂a/∂v, M⁻¹], [0, 0, 0]],   Q_d += diag(0, 0, disturbance_psd · h · I).

The offset is observable from positions alone (it is an acceleration bias
seen through two integrators); it costs a (3nv)² covariance instead of
(2nv)².  ``disturbance_psd`` is given as an *acceleration* density j
[rad²/s⁵] and converted per joint with the nominal inertia at the reset
configuration, ``psd_τ,i = j · M̄ᵢᵢ²``, so one number means the same on a
wrist and a shoulder, and on robots it was not tuned on.  Measured on a UR5
(pd tracking, 1 kHz, σ = 1e-4 rad, 3 s, velocity RMS after 0.75 s; the
truths of :mod:`pinobs.simulation.mismatch`; tuned ``kf``: 5.3e-3 to 7.5e-3):

    scenario             ekf (default)   accel_psd=1e-2   disturbance_psd: 1      10
    exact                4.0e-5          4.6e-3           3.5e-3                  6.2e-3
    inertia ±5 %         3.0e-1          1.1e-2           3.5e-3                  6.2e-3
    ±20 % + payload      2.9             8.4e-2           1.1e-2                  7.8e-3
    friction             1.2             4.7e-2           7.1e-3                  6.9e-3

It turns a filter that is lost under model error into one about as good as
the best model-free filter; it does not recover the exact-model accuracy
(the offset absorbs model error only as fast as its density allows, and
errors that vary with the motion, like a payload's gravity torque or viscous
friction, vary as fast as the motion).

The density learned from the innovations (``disturbance_psd="auto"``, issue 36).
One number cannot fit an exact model (where any density costs accuracy: 3.5e-3
against 4.0e-5 above) and a wrong one.  With ``"auto"`` each joint's density ``ψᵢ``
(in N²·m²/s) is matched to the filter's own innovations by covariance matching,
:func:`pinobs.observers.neverbehind.match_density` (Mehra 1972 §IV, Myers & Tapley
1976), at every sample ``h``, in the log domain (``S = P⁻_qq + σ² I``, the predicted
innovation covariance; ``T`` = ``AUTO_WINDOW``)::

    log ψᵢ ← log ψᵢ + (h/T) (clip(log(eᵢ² / Sᵢᵢ), −8, 5) − m),   m = E[clip(log χ²₁)],

between ``AUTO_PSD_BOUNDS · M̄ᵢᵢ²``, from ``AUTO_PSD_START · M̄ᵢᵢ²``: the density grows
while the model under-predicts the innovations and shrinks while the filter
over-predicts them.  A gated sample does not count.  The offset starts with
``d0_std`` = ``AUTO_D0_ACCEL · M̄ᵢᵢ`` (a grossly wrong model's torque error, absorbed in
the first samples) unless ``d0_std`` is given.

The density's ceiling.  ``ψᵢ`` is also kept at or below ``AUTO_CEILING · σ² / h⁵ · M̄ᵢᵢ²``
(``AUTO_CEILING`` = 1): at ``ψ h⁵ / σ² = 1`` the offset's random walk alone adds ``σ²/20``
of position variance per sample (``Q₀₀ = ψ h⁵/20``, the constant-acceleration filter's), so
the filter already follows every sample and a denser offset only feeds the measurement noise
into ``d``, whose torque then swings the linearisation out of its validity (``‖A h‖`` grows
with ``d`` through the velocity terms).  Without it, at 100 Hz the density ran away
(UR5, masses ×3 in the truth, pd tracking, σ = 1e-4: to 2e7 rad²/s⁵ on a joint, NaN; the
plain ``ekf`` NaN too; with it 1.34× the ``kf``, 1.8e-2 against 1.3e-2 rad/s; ``AUTO_CEILING``
chosen there: 0.01 → 2.4×, 0.1 → 1.26×, 1 → 1.34×, 20 → 2.9×).  At 1 kHz with σ = 1e-4 the
ceiling (1e7 rad²/s⁵, below ``AUTO_PSD_BOUNDS``' top, 1e8) is not reached on those runs
(exact model 5.1e-5, ×3 1.6e-2: unchanged).  On the UR10e logs of
``benchmarks/real_logs_bound.py`` (100 Hz, the model ``identify`` fits on
``real_logs.UR10E_FIT``, σ 2.9e-5 to 4.1e-5), ``ekf`` with ``"auto"`` alone diverged
(rad/s errors: 338× and 1380× the default ``kf`` on the two logs traced); with the ceiling
it is 1.5–2.9× on seven logs (the benchmark's six: 1.4–2.7×).  What remains is the
structure's, model plus random-walk offset: the same model's acceleration with an offset
tuned on the reference (the benchmark's *id bound*) is 1.5–5.4× the ``kf``, the best fixed
``(accel_psd, disturbance_psd)`` of its grid 1.27–2.3×.  ``never_behind=True`` blends the
filter with the ``kf`` (:mod:`pinobs.observers.neverbehind`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pinobs.errors import DimensionError, GainError
from pinobs.model import Robot, dynamics_rk4
from pinobs.model.integrators import friction_rk4
from pinobs.observers import blocks
from pinobs.observers.base import (
    Observer,
    Vector,
    gate_threshold,
    positive,
    register,
)
from pinobs.observers.blockstep import BlockStep
from pinobs.observers.checks import model_accel_psd
from pinobs.observers.ekf_fused import FastPath as _FastPath
from pinobs.observers.ekf_fused import update_fused
from pinobs.observers.ekf_state import (
    AUTO_CEILING,
    AUTO_D0_ACCEL,
    AUTO_PSD_BOUNDS,
    AUTO_PSD_START,
    AUTO_WINDOW,
    EKFGains,
    EKFState,
    ad_matrix,
    double_integrator_noise,
)
from pinobs.observers.fused import compiled_vector_space
from pinobs.observers.fused_lie import LieRK4
from pinobs.observers.linalg import (
    KERNEL_MAX_NV,
    identity,
    joseph_update,
    scaled_identity,
    stiff_transition_matrix,
    transition_matrix,
    warm_linear_algebra,
)
from pinobs.observers.neverbehind import match_density

# the state, the options and the pieces shared with ibrir_kalman: defined in ekf_state
__all__ = [
    "AUTO_CEILING",
    "AUTO_D0_ACCEL",
    "AUTO_PSD_BOUNDS",
    "AUTO_PSD_START",
    "AUTO_WINDOW",
    "EKFGains",
    "EKFState",
    "ExtendedKalmanFilter",
    "ad_matrix",
    "double_integrator_noise",
]


_new_tuple = tuple.__new__  # a NamedTuple made without its __new__ (the fast paths' EKFState)
_F64 = np.dtype(np.float64)


@register
class ExtendedKalmanFilter(Observer[EKFState]):
    """Error-state EKF on the configuration manifold with the exact Pinocchio model.

    Args:
        robot: the model (its dynamics are the filter's process model).
        accel_psd: white-acceleration noise density [rad²/s³] (model error); ``None``: the
            robot's :attr:`~pinobs.Robot.model_error_psd`, else 1e-8 (module docstring).
        q0_std: initial configuration standard deviation [rad].
        v0_std: initial velocity standard deviation [rad/s].
        disturbance_psd: density of a random-walk joint-torque offset estimated
            with the state, as an acceleration density [rad²/s⁵] scaled by the
            nominal inertia (module docstring); ``"auto"``: learned per joint from the
            innovations (module docstring); ``None``: no offset.
        d0_std: initial standard deviation of that offset [N·m or N]; ``None``: 1, or
            with ``"auto"`` ``AUTO_D0_ACCEL · M̄ᵢᵢ``.
        outlier_probability: false-alarm probability ``p`` of the outlier gate
            (:meth:`correct`); ``None`` switches the gate off.
        rate: sample rate hint [Hz] (not needed: the filter uses the actual intervals).
        noise_std: position noise standard deviation [rad or m], the measurement noise.
    """

    name = "ekf"
    uses_noise_std = True
    #: :func:`pinobs.smooth` can run its backward pass over this filter's states.
    smoothable = True
    summary = "extended Kalman filter on the manifold, exact model (model-based baseline)"

    def __init__(
        self,
        robot: Robot,
        *,
        accel_psd: float | None = None,
        q0_std: float = 0.1,
        v0_std: float = 1.0,
        disturbance_psd: float | str | None = None,
        d0_std: float | None = None,
        outlier_probability: float | None = 1e-6,
        rate: float | None = None,
        noise_std: float | None = None,
    ) -> None:
        super().__init__(robot, rate=rate, noise_std=noise_std)
        self.outlier_probability, self._gate = gate_threshold(outlier_probability, robot.nv)
        sigma = self.noise_std_used
        accel_psd = model_accel_psd(robot, accel_psd)  # the robot's own model error, or 1e-8
        self.gains = EKFGains(accel_psd=accel_psd, meas_std=sigma, q0_std=q0_std, v0_std=v0_std)
        self.auto = disturbance_psd == "auto"
        if isinstance(disturbance_psd, str) and not self.auto:
            raise GainError(f"disturbance_psd={disturbance_psd!r}: give a number, 'auto' or None")
        self.disturbance_psd: float | None = (
            AUTO_PSD_START
            if self.auto
            else positive("disturbance_psd", disturbance_psd, allow_none=True)  # type: ignore[arg-type]
        )
        self.d0_std = positive("d0_std", d0_std, allow_none=True)
        self._scratch_A: Vector | None = None  # A's buffer (_jacobian)
        warm_linear_algebra(self.robot.nv)  # LAPACK and the compiled update, now
        self._fast: _FastPath | None = _FastPath.build(self)
        self._lie_fast = _LieFast.build(self)  # Lie-group joints (module docstring)
        # the compiled step makes no BLAS call (Observer.uses_blas; its rare ways back to
        # NumPy, ≤ 36 × 36 with nv ≤ 12, are below OpenBLAS's threading sizes)
        self.uses_blas = self._fast is None
        #: Whether :meth:`step` is the compiled one, which raises no NumPy floating-point
        #: warning (its arithmetic compiled or under ``np.errstate``: ``adaptive`` then
        #: calls it without an ``errstate`` of its own; issue 39).
        self.compiled_step = self._fast is not None
        # a plain update whole in one Python call (Observer._update_fused; pinobs.observers.
        # ekf_fused; by blocks on a large robot, update_blocks): this class's own step,
        # output, innovation and after_commit only
        self._fused_path = type(self) is ExtendedKalmanFilter and (
            self._fast is not None
            or (self._lie_fast is not None and self._lie_fast.blocks is not None)
        )

    _update_fused = update_fused  # (Observer.update's first offer: ekf_fused.update_fused)

    @property
    def options(self) -> dict[str, object]:
        g = self.gains
        return {
            **super().options,
            "accel_psd": g.accel_psd,
            "meas_std": g.meas_std,
            "q0_std": g.q0_std,
            "v0_std": g.v0_std,
            "disturbance_psd": "auto" if self.auto else self.disturbance_psd,
            "outlier_probability": self.outlier_probability,
        }

    # ------------------------------------------------------------ the model
    def vector_field(self, q: Vector, v: Vector, tau: Vector) -> tuple[Vector, Vector]:
        """``(q̇, v̇) = (v, a(q, v, τ))`` of the mean between samples (body-frame ``q̇``)."""
        return v, self.robot.forward_dynamics(q, v, tau)

    def error_jacobian(self, q: Vector, v: Vector, tau: Vector) -> Vector:
        """``A = [[−ad_v, I], [∂a/∂q, ∂a/∂v]]`` of the error dynamics (module docstring);
        with the disturbance, ``[[−ad_v, I, 0], [∂a/∂q, ∂a/∂v, M⁻¹], [0, 0, 0]]``.  A new array."""
        return np.array(self._jacobian(q, v, tau)[0])

    def _jacobian(self, q: Vector, v: Vector, tau: Vector) -> tuple[Vector, Vector | None, Vector]:
        """``(A, a(q, v, τ), M⁻¹)`` from one derivatives call; ``A`` is the filter's scratch
        buffer (overwritten by the next call), ``a`` and ``M⁻¹`` views into the robot's data
        (``a`` is ``None`` for a model without that call; ``M⁻¹`` symmetric with friction or
        the disturbance, else only its upper triangle is meaningful)."""
        r, nv = self.robot, self.robot.nv
        A = self._scratch_A
        if A is None:  # the constant blocks are written once
            n = (2 if self.disturbance_psd is None else 3) * nv
            A = self._scratch_A = np.zeros((n, n))
            A[:nv, nv : 2 * nv] = identity(nv)
        with_d = self.disturbance_psd is not None
        if isinstance(r, Robot):
            acc, da_dq, da_dv, minv = r.forward_dynamics_with_derivatives(
                q, v, tau, full_minv=with_d
            )
        else:  # a Robot-like model (pinobs.model.AnalyticMetric)
            acc = None
            da_dq, da_dv, minv = r.forward_dynamics_derivatives(q, v, tau)
        if r.has_lie_group_joints:
            np.negative(ad_matrix(r, v), out=A[:nv, :nv])
        A[nv : 2 * nv, :nv] = da_dq
        A[nv : 2 * nv, nv : 2 * nv] = da_dv
        if with_d:
            A[nv : 2 * nv, 2 * nv :] = minv
        return A, acc, minv

    @property
    def disturbance(self) -> Vector | None:
        """The estimated joint-torque offset ``d`` [N·m or N], or ``None`` without the option."""
        if self._state is None or self._state.d is None:
            return None
        return np.array(self._state.d)

    # ------------------------------------------------------------- the filter
    def initial_state(self, q0: Vector, v0: Vector) -> EKFState:
        nv = self.robot.nv
        std = np.concatenate([np.full(nv, self.gains.q0_std), np.full(nv, self.gains.v0_std)])
        if self.disturbance_psd is None:
            return EKFState(q0.copy(), v0.copy(), np.diag(std**2))
        m_bar = np.diag(self.robot.mass_matrix(q0))
        d0 = (
            self.d0_std
            if self.d0_std is not None
            else (AUTO_D0_ACCEL * m_bar if self.auto else 1.0)
        )
        std = np.concatenate([std, np.broadcast_to(d0, (nv,))])
        d_psd = self.disturbance_psd * m_bar**2
        if not self.auto:
            return EKFState(q0.copy(), v0.copy(), np.diag(std**2), np.zeros(nv), d_psd)
        return EKFState(
            q0.copy(), v0.copy(), np.diag(std**2), np.zeros(nv), d_psd, auto=True,
            psd_scale=m_bar**2,
        )  # fmt: skip

    def step(self, state: EKFState, dt: float, q_meas: Vector | None, tau: Vector) -> EKFState:
        if self._fast is not None:
            return self._fast.step(self, state, dt, q_meas, tau)
        lie = self._lie_fast
        if lie is not None and lie.blocks is not None and state.d is None:
            return lie.step(self, state, dt, q_meas, tau)
        # a filter being lost overflows: its update says so (ObserverDiverged), numpy does not
        with np.errstate(over="ignore", invalid="ignore"):
            pred, _ = self.predict(state, dt, tau)
            if q_meas is None:
                P = 0.5 * (pred.P + pred.P.T)
                return pred.moved(pred.q, pred.v, P, pred.gate.predicted(), pred.d, pred.d_psd)
            return self.corrected(pred, q_meas, dt)

    def corrected(self, pred: EKFState, q_meas: Vector, dt: float) -> EKFState:
        """:meth:`correct`, then (``disturbance_psd="auto"``) the density matched to the
        innovation of a measurement the gate let through (module docstring); ``dt`` [s] the
        prediction's interval."""
        new = self.correct(pred, q_meas)
        if not new.auto or new.d_psd is None or new.gate.gated:
            return new
        nv = self.robot.nv
        e = self.robot.difference(pred.q, q_meas)
        s = pred.P.diagonal()[:nv] + self.gains.meas_std**2  # Sᵢᵢ = P⁻_qq,ii + σ²
        return new.moved(new.q, new.v, new.P, new.gate, new.d, self.matched_density(pred, e, s, dt))

    def matched_density(self, pred: EKFState, e: Vector, s: Vector, dt: float) -> Vector:
        """``disturbance_psd="auto"``: the offset's density after the innovation ``e`` [rad]
        of predicted variance ``s`` [rad²] over ``dt`` [s] (module docstring)."""
        scale = pred.psd_scale
        if pred.d_psd is None or scale is None:
            raise GainError(
                "matched_density needs the state of an ekf with disturbance_psd='auto' "
                f"(this one has d_psd={'None' if pred.d_psd is None else 'fixed'})"
            )
        lo, hi = AUTO_PSD_BOUNDS
        hi = max(min(hi, AUTO_CEILING * self.gains.meas_std**2 / dt**5), lo)  # the ceiling
        bounds = np.array([lo * scale, hi * scale])  # (2, nv), per joint: ψ_τ = ψ M̄ᵢᵢ²
        return match_density(pred.d_psd, e, s, dt, window=AUTO_WINDOW, bounds=bounds)

    def predict(self, state: EKFState, dt: float, tau: Vector) -> tuple[EKFState, Vector]:
        """Prediction over ``dt`` [s] with ``tau`` held: ``(state⁻, Φ)``.

        Mean by one RKMK4 step of :meth:`vector_field` (with ``τ + d``), covariance
        ``P⁻ = Φ P Φᵀ + Q_d`` (module docstring; symmetric to rounding, not
        symmetrised: :meth:`correct` and :meth:`step` do that).  ``Φ`` (a new
        array) is returned for smoothers (Rauch-Tung-Striebel needs it).  One
        ``computeABADerivatives`` gives ``A`` and the first RK stage, three ABA
        calls the others.
        """
        d = state.d
        tau_in = tau if d is None else tau + d  # the offset acts as a torque (module docstring)
        return self._propagate(state, dt, tau_in, *self._jacobian(state.q, state.v, tau_in))

    def predict_flow(
        self, state: EKFState, dt: float, tau: Vector
    ) -> tuple[EKFState, Vector, Vector]:
        """:meth:`predict` and ``F``, the Jacobian of its mean's step, ``∂x⁻_{k+1}/∂x⁺_k``.

        ``Φ`` takes ``A`` at the step's start; along the step ``A`` changes
        (with ``q``, ``v``: ``h ΔA`` is 2e-3 of ``Φ − I`` on a Panda at 1 kHz), so
        ``Φ`` is the filter's approximation, not the mean's Jacobian.  ``F`` is the
        first Magnus term, the exponential of ``A``'s integral over the step by the
        trapezoid, ``F = exp(h (A(x⁺_k, τ) + A(x⁻_{k+1}, τ)) / 2)`` (Magnus 1954;
        error ``O(h³)``; 7.7e-6 of ``F − I`` against the RK4 step's finite-difference
        Jacobian on a Panda, against 2.3e-3 for ``Φ``), at one derivatives call
        more.  :mod:`pinobs.smoothing`'s noise band propagates the error
        with it.
        """
        d = state.d
        tau_in = tau if d is None else tau + d
        A, acc, minv = self._jacobian(state.q, state.v, tau_in)
        A0 = A.copy()  # (A is the scratch buffer, which the end's call overwrites)
        pred, Phi = self._propagate(state, dt, tau_in, A, acc, minv)
        A0 += self._jacobian(pred.q, pred.v, tau_in)[0]  # the same held torque and offset
        A0 *= 0.5
        stiff = self.robot.has_friction
        return pred, Phi, stiff_transition_matrix(A0, dt) if stiff else transition_matrix(A0, dt)

    def _propagate(
        self, state: EKFState, dt: float, tau_in: Vector, A: Vector, acc: Any, minv: Vector
    ) -> tuple[EKFState, Vector]:
        """:meth:`predict` given the torque (offset included) and the start's Jacobian call."""
        nv, d, lie = self.robot.nv, state.d, self._lie_fast
        if lie is not None:  # the same step, on A's blocks or compiled between the calls
            Phi = lie.transition(A, dt)
            if lie.rk4 is not None:
                q, v = lie.rk4.step(state.q, state.v, tau_in, dt, acc0=acc)
            else:
                q, v = dynamics_rk4(self.robot, state.q, state.v, tau_in, dt, acc0=acc)
        elif not self.robot.has_friction:
            Phi = transition_matrix(A, dt)
            # RKMK4 of vector_field; its first stage is the derivatives call's v̇
            q, v = dynamics_rk4(self.robot, state.q, state.v, tau_in, dt, acc0=acc)
        else:  # stiff near v = 0: Φ by scaling and squaring, the mean in substeps
            Phi = stiff_transition_matrix(A, dt)
            q, v = friction_rk4(self.robot, state.q, state.v, tau_in, dt, acc, np.diag(minv))
        P = Phi.dot(state.P).dot(Phi.T)
        P[: 2 * nv, : 2 * nv] += double_integrator_noise(nv, dt, self.gains.accel_psd)
        if d is not None and state.d_psd is not None:  # Q_d's offset block, diag(psd_τ h)
            P[2 * nv :, 2 * nv :].flat[:: nv + 1] += state.d_psd * dt
        # the gate's bookkeeping carries over
        return state.moved(q, v, P, state.gate, state.d, state.d_psd), Phi

    def correct(self, state: EKFState, q_meas: Vector) -> EKFState:
        """Correction of a predicted state with the measured ``q_meas`` (Joseph form, module docstring).

        The normalized innovation squared ``NIS = eᵀ S⁻¹ e`` comes free:
        ``K_q = P_qq S⁻¹ = I − R S⁻¹``, so ``S⁻¹ e = (e − K_q e) / R``.  A
        measurement the outlier gate rejects (:func:`pinobs.observers.base.outlier_gate`,
        threshold ``χ²_nv(1 − p)``) is not used: the estimate is the prediction.
        """
        nv = self.robot.nv
        q, v, d, P = state.q, state.v, state.d, state.P
        R = self.gains.meas_std**2
        e = self.robot.difference(q, q_meas)
        large = self._lie_fast is not None and nv >= blocks.MIN_NV
        dx, P_new = blocks.joseph_update(P, e, R) if large else joseph_update(P, e, R)
        nis = float(e @ (e - dx[:nv])) / R
        if nis * R < 1e-6 * float(e @ e):  # K_q ≈ I (P_qq ≫ R): e − K_q e lost its digits
            # and went negative (−9e294 on a filter being lost): eᵀ S⁻¹ e directly
            nis = float(e @ np.linalg.solve(P[:nv, :nv] + scaled_identity(nv, R), e))
        gate = state.gate.measured(nis, self._gate, nv)
        if gate.gated:
            return state.moved(state.q, state.v, 0.5 * (P + P.T), gate, state.d, state.d_psd)
        q = self.robot.integrate(q, dx[:nv])
        v = v + dx[nv : 2 * nv]
        if d is not None:
            d = d + dx[2 * nv :]
        return state.moved(q, v, P_new, gate, d, state.d_psd)  # P symmetric (joseph)

    def gate_limit(self, state: EKFState) -> float:
        """The NIS above which :meth:`correct` rejected ``state``'s measurement: the gate's
        threshold at its level (:func:`pinobs.observers.base.outlier_gate`)."""
        return state.gate.limit(self._gate, self.robot.nv)

    def smoothing_filter(self) -> ExtendedKalmanFilter:
        """The filter itself: its :meth:`predict` and :meth:`correct` are a
        :class:`~pinobs.observers.base.GaussianFilter`'s."""
        return self

    def replace_robot(self, robot: Robot) -> None:
        """Swap the filter's model between updates (an adaptive subclass's identified model).

        The state is kept; the next prediction uses ``robot``'s dynamics.  ``robot``
        must have the same configuration space (``nq``, ``nv``).
        """
        if (robot.nq, robot.nv) != (self.robot.nq, self.robot.nv):
            raise DimensionError(
                f"the new model has (nq, nv) = ({robot.nq}, {robot.nv}); "
                f"the filter's has ({self.robot.nq}, {self.robot.nv})"
            )
        old, fast = self.robot, self._fast
        self.robot = robot
        self._scratch_A = None  # sized by the robot
        if fast is not None and compiled_vector_space(robot) and robot.joints is old.joints:
            self._fast = fast.rebound(robot)  # the same tree (Robot.with_inertials)
        else:
            self._fast = _FastPath.build(self)
        self._lie_fast = _LieFast.build(self)
        self.uses_blas = self._fast is None
        self.compiled_step = self._fast is not None
        # a plain update whole in one Python call (Observer._update_fused; pinobs.observers.
        # ekf_fused; by blocks on a large robot, update_blocks): this class's own step,
        # output, innovation and after_commit only
        self._fused_path = type(self) is ExtendedKalmanFilter and (
            self._fast is not None
            or (self._lie_fast is not None and self._lie_fast.blocks is not None)
        )

    def output(self, state: EKFState) -> tuple[Vector, Vector]:
        return state.q, state.v

    def covariance(self) -> Vector:
        """The current covariance of ``(δq, δv)`` (``(2nv, 2nv)``; ``(3nv, 3nv)`` with ``δd``), a copy."""
        if self._state is None:
            n = (2 if self.disturbance_psd is None else 3) * self.robot.nv
            return np.full((n, n), np.nan)
        return np.array(self._state.P)


class _LieFast:
    """:meth:`ExtendedKalmanFilter.predict`, :meth:`~ExtendedKalmanFilter.correct` and
    :meth:`~ExtendedKalmanFilter.step` on a :class:`Robot` with Lie-group or continuous joints,
    without joint friction (issue 39).  Up to ``KERNEL_MAX_NV``: the RKMK4 step compiled
    between Pinocchio's calls (:class:`~pinobs.observers.fused_lie.LieRK4`, on its own
    ``pin.Data``).  Above, without the offset state: :meth:`step` by
    :class:`~pinobs.observers.blockstep.BlockStep` (numba loaded by the constructor; go1,
    nv = 18: 32.9 → 22.1 ``pin.aba`` per update, module docstring).
    From ``blocks.MIN_NV`` (a talos): :meth:`predict` and :meth:`correct` take ``Φ`` and the
    Joseph update on ``A``'s blocks (:mod:`pinobs.observers.blocks`; below, not faster: go1
    34.1 against 33.0 ``pin.aba``, the general products).  The same equations, equal to the
    general path to rounding (tested)."""

    def __init__(self, robot: Robot, offset: bool) -> None:
        self.nv = robot.nv
        self.rk4 = LieRK4.build(robot) if self.nv <= KERNEL_MAX_NV else None
        self.rows = blocks.bracket_rows(robot)  # where −ad_v̂ can be nonzero
        # the whole step by blocks (pinobs.observers.blockstep), without the offset state
        self.blocks = BlockStep(robot) if self.nv > KERNEL_MAX_NV and not offset else None

    @classmethod
    def build(cls, ekf: ExtendedKalmanFilter) -> _LieFast | None:
        """The Lie-group path of ``ekf``, or ``None`` where its robot does not qualify."""
        r = ekf.robot
        if not isinstance(r, Robot) or r.is_vector_space or r.has_friction:
            return None
        offset = ekf.disturbance_psd is not None
        small, large = r.nv <= KERNEL_MAX_NV, r.nv >= blocks.MIN_NV
        return cls(r, offset) if small or large or not offset else None

    def transition(self, A: Vector, h: float) -> Vector:
        """``Φ`` (:func:`~pinobs.observers.linalg.transition_matrix`), a new array."""
        if self.nv < blocks.MIN_NV:
            return transition_matrix(A, h)
        return blocks.transition(A, h, self.nv, self.rows)

    # a lost filter overflows: its update says so (ObserverDiverged), numpy does not (the
    # decorator's form: two Python calls less than a with statement's; issue 39)
    @np.errstate(over="ignore", invalid="ignore")
    def step(
        self, ekf: ExtendedKalmanFilter, state: EKFState, dt: float, q_meas: Vector | None,
        tau: Vector,
    ) -> EKFState:  # fmt: skip
        """:meth:`ExtendedKalmanFilter.step` by :class:`~pinobs.observers.blockstep.BlockStep`
        (no offset state), falling back on :meth:`~ExtendedKalmanFilter.correct` where it
        takes another way (``S`` not positive definite, ``K_q ≈ I``)."""
        b, r = self.blocks, ekf.gains.meas_std**2
        assert b is not None  # (the caller checked)
        q, v, P = b.predict(state.q, state.v, tau, dt, state.P, ekf.gains.accel_psd, r)
        if q_meas is None:  # (v and P: b's working memory, copied into the state)
            gate = state.gate.predicted()
            return state.moved(q, v.copy(), 0.5 * (P + P.T), gate, state.d, state.d_psd)
        e = b.difference(q, q_meas)  # (robot.difference, bound: a Python call less)
        dx, P_new, nis, v_new = b.correct(P, e, r, v)
        if nis != nis:  # NaN (S, P⁻_qq's size, or K_q ≈ I: b.correct): correct's other ways
            pred = state.moved(q, v.copy(), P.copy(), state.gate, state.d, state.d_psd)
            return ekf.corrected(pred, q_meas, dt)
        gate = state.gate.measured(nis, ekf._gate, self.nv)
        if gate.gated:
            return state.moved(q, v.copy(), 0.5 * (P + P.T), gate, state.d, state.d_psd)
        q = b.rk4.integrate(q, dx[: self.nv])  # (robot.integrate, bound)
        # state.moved's tuple, built here (a Python call less); v⁺ = v⁻ + dx_v by b.correct
        return _new_tuple(EKFState, (q, v_new, P_new, state.d, state.d_psd, gate, state.auto,
                                     state.psd_scale))  # fmt: skip

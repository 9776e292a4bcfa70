"""Offline identification with model-based velocities: ``pinobs.identify`` (``pinobs identify``).

The regressor of :mod:`pinobs.model.identification` needs the velocity ``v``
along the log; ``v`` enters it nonlinearly (``Y_M(q, v)``, ``C(q, v)ᵀv``), so
velocity noise is an errors-in-variables error the least squares cannot
average out.  A Savitzky–Golay fit of the measured positions
(:func:`pinobs.model.identification.smooth_path`) is model-free and noisy:
on the 15 s logs of ``benchmarks/learning.py`` (σ = 1e-4 rad) its held-out
residual equals that of the *true* parameters evaluated on the same
velocities (the floor it sets), and the default ``ekf`` on the model
identified from it was 0.15–0.79× the best tuned model-free filter, varying
with the noise's seed (UR5: 0.15 with seed 3, 0.62 with seed 4).  With the
truth's own velocities the same identification reaches 0.007× (UR5) and
0.02–0.04× (z1); with noise-free positions and Savitzky–Golay 0.007× and
0.07×: noise, not the fit's lag, is most of the error (log seed 3,
validation seed 7 of ``benchmarks/learning.py``).

So the velocities are re-estimated with the model just identified, and the
identification repeated (a fixed-point iteration)::

    θ⁰ = identify(q_meas, v_SG)                                  first pass
    (q̂, v̂)ⁱ = RTS smoother of ekf on robot(θⁱ⁻¹) over the log      (pinobs.smoothing)
    θⁱ = identify(q̂ⁱ, v̂ⁱ)                                        i = 1 … len(refine)

The smoother runs the EKF with a white-acceleration density ``refine[i−1]``
[rad²/s³] (the model's remaining error, decreasing as it improves: 1e-6
then 1e-7 by default) and a torque-offset state (``disturbance_psd`` =
1e-4 rad²/s⁵) that absorbs what the model still misses, fed ``τ + b``
(``b`` the offset identified so far).  Each contiguous stretch of the log
(:func:`pinobs.model.identification.segments`) is smoothed on its own (a
pass before the last one only over the fitted part: its held-out end is not
used).  The
position noise the smoother needs is the log's own (``noise_std``) or, when
not given, estimated from it (:func:`pinobs.observers.noise.estimate_noise_std`).

**Limitation: noisy torques.** The smoother takes the logged torques as exact
(only the model's error is white acceleration, ``refine[i]``).  White torque
noise ``σ_τ`` is an acceleration density ``M⁻¹ diag(σ_τ²) M⁻ᵀ h`` (0.014–0.9
rad²/s³ at 5 % of each joint's torque RMS, 1 kHz, on a UR5, a Panda and the
double pendulum: 4–7 decades above ``refine``'s), so the smoothed velocities
follow the integrated noise: at 5 % the first pass's RMS error was 3.4–12× the
Savitzky–Golay fit's (σ = 1e-4 rad).  The refined fit is then no better than
``refine=()``, and can be worse: with 5 % torque noise (per joint, of its RMS;
the friction truth of :mod:`pinobs.simulation.mismatch`, σ = 1e-4 rad, 6 s of
``pd`` at 1 kHz, 8 noise draws) its prediction error on a fresh 4 s trajectory
of the truth was 0.74–1.54× (geometric mean 1.00) that of ``refine=()`` on a
UR5 and 0.95–1.60× (1.20) on the double pendulum, where a fit on the *true*
velocities was 0.81–1.25× and 0.45–1.15×: the torque noise in ``∫ τ dt``
dominates both.  At 1 % (4 draws) the refined fit was 0.47–0.83× (UR5) and 0.81–1.51×
(double pendulum) of ``refine=()``; on clean torques 0.03–0.51× (UR5, Panda,
double pendulum; payload and friction truths; σ = 1e-4 and 1e-3), except one
double-pendulum payload log at σ = 1e-3 (1.38×).  No rule without the truth
was found to choose: modelling the torque noise in the smoother (that density
added to ``refine``'s) gave 0.81–1.25× ``refine=()`` on 9 logs (UR5, Panda,
double pendulum, seeds 1–3, 5 %) where the default gave 0.81–1.39×; the
held-out residual on the Savitzky–Golay velocities of the held-out end
(windows of 0.1–1 s) picked ``refine=()`` on a clean double-pendulum log where
the refined fit was 18× better.  The smoother's own consistency ``ρ`` (last
pass, pooled over the stretches: ``report["smoother_consistency"]``) says how
far the model and torques are from explaining the positions: 0.44–14.8 on the
clean logs (UR5 and double pendulum, seeds 1–3), 20–183 at 1 % torque noise,
108–4500 at 5 %; in the hundreds, compare with ``refine=()`` on data of your
own.

**The friction law's smoothing velocity** (issue 36).  Each smoother pass runs on the law
the pass before identified, its ``v_s`` included, and the next fit searches ``v_s``
(:func:`pinobs.model.friction_fit.search_smoothing`) on the velocities it gave; near zero
speed these are only as good as that ``v_s``.  So the first pass (Savitzky–Golay), whose
law only feeds the smoother, takes the ``v_s`` of least cross-validated residual
(``smoothing_minimum``); the refinements keep the one-standard-error rule (0.01 unless
another predicts better by more than one standard error).  Measured on logs made as
``tests/observers/test_calibration_friction.py``'s (planar_3r, each law of
:data:`~pinobs.model.friction.FRICTION_LAWS` with ``v_s`` = 0.0056 rad/s, Stribeck 0.0032,
``friction=True`` 0.01; 8 s of a PD-tracked multisine stopping every 1.5 s; exact torques;
seeds 1–3; "error": the friction coefficients' largest relative error), with the rule in
every pass (before):

- where ``|v| < 3 v_s`` one smoother pass (1e-7) on the first fit with the truth's ``v_s``
  errs by 0.11–0.39 mrad/s (median over the joints, per law), with a ``v_s`` 5.6× too
  high or low (Stribeck 10× high, 3.2× low) by 1.6–3.9, Savitzky–Golay by 2.4–3.4; fitted
  on the wrong one's velocities, the search chose that wrong ``v_s`` on 8 joints of 108,
  0.01 (the rule's anchor) on 52: the fit does not confirm its own law, but its
  coefficients (every law) were 1.5–680 % off (with the truth's ``v_s``: 0.05–80 %);
- σ = 1e-4 rad: the refinement kept the first pass's 0.01 on asymmetric seeds 1, 3 and
  Stribeck seed 1: error 21, 39 and 25 % against Savitzky–Golay's 9.7, 37 and 38 % and the
  true velocities' 0.07, 0.02 and 0.3 %; its torques predicted on a fresh trajectory (true
  states) 47 mN·m RMS on asymmetric seed 1 where Savitzky–Golay's gave 35.  Now: 1.1, 0.23
  and 1.8 %, 2.2 mN·m; Stribeck seed 2 2.0 → 1.7 %, offset-sigmoid 10, 18, 22 → 9.6, 18,
  20 %, Stribeck seed 3 81 % both (the true velocities' 83 %: not determined by this log),
  asymmetric seed 2 21 → 25 % (the true velocities' 16 %, joint 1's ``v_s`` 0.001);
- σ = 3e-5 rad, 16 bits per turn: before, the refinement found the ``v_s`` of a fit on the
  true velocities on 8 logs of 9, error 0.09–7.2 % (Savitzky–Golay 1.5–290 %); now
  asymmetric 0.25, 3.3, 0.72 → 0.18, 6.0, 0.59 % (seed 2 as above: 48 → 57 mN·m),
  Stribeck 0.94, 1.4, 62 → 1.1, 1.1, 65 %, offset-sigmoid seed 1 5.2 → 6.1 %.  (The CV
  minimum in the refinements too, tried: Stribeck seed 2 1.4 → 16 %, its minimum on the
  smoothed velocities joint 1's ``(v_s, v_st)`` = (0.001, 1) for (0.0032, 0.1));
- with 1 % torque noise (σ = 1e-4, before) the smoother's velocities near zero speed are
  worse than Savitzky–Golay's even on the truth's ``v_s`` (3.3–4.8 against 2.6–3.4
  mrad/s), and the error was 11–72 % (offset-sigmoid 250–810 %), Savitzky–Golay's 13–92 %
  (320–1200 %), the true velocities' 11–120 % (310–1000 %): the torques' noise dominates
  ("Limitation: noisy torques" above).

On the real UR10e (``benchmarks/real_friction.py``) every law's ``v_s`` stays 0.01 (Stribeck's
``v_st`` 0.1); the held-out residuals of the four fits with a search moved by −0.12 to
+0.31 % per joint, the three without one and the published model's are the same to the
bit.  On the real TX40 (``benchmarks/tx40_friction.py``, held-out N·m) the default law is
unchanged, offset-sigmoid and Stribeck within 2 % per joint, but the asymmetric law is
worse: j2 7.27 → 10.4 (moving rows 15.7 → 22.8), its final ``v_s`` 0.01 as before.  The smoother's own consistency ``ρ`` (every joint's ``v_s`` set) was least at the truth's
for the asymmetric law (0.83, 1.26 against 4.0, 9.3 at 0.01, σ = 1e-4) but not for
Stribeck with the levels fitted at 0.01 (116 at 0.0056 and 0.01, 184 at the truth's
0.0032), and flat with 1 % torque noise: not used.

**The torque offset** is not identified by default (``offset=False``): a
:class:`Robot` cannot carry a torque offset, so the observers run on
``.robot`` without it, and an offset the log does not have is confounded
with gravity (the shoulder's ``m·c``, on a trajectory about one mean
posture): identified anyway, it made the default ``ekf`` 1.6–3.4× less
accurate in ``benchmarks/learning.py`` (z1: 0.06 → 0.19× kf*; the
truths there have no offset).  On real logs (``benchmarks/real_logs.py``, held-out
20 %, N·m) it helped TIAGo's (``weighting="torque"``: torso, arm_1..4 0.519 0.816 2.89
1.38 0.844 → 0.503 0.744 2.58 1.33 0.850) and not the TX40's (j1..j4 1.96 5.34 1.03
0.642 → 2.21 5.58 1.00 0.550), whose held-out end is 79 % at rest and its fitted part
never; a choice inside the fitted part (its last 20 % held out, ``refine=()``) would have
taken it for j1..j3 and not j4: on j1, j2 and j4 the held-out end's opposite.  Give ``offset=True`` for a
torque sensor known to be biased, and add ``.offset`` to the torques fed to the
observers (the model is driven by ``τ + b``: module docstring of
:mod:`pinobs.model.identification`; subtracting it doubles the bias: on
a 4 s UR5 log read as ``τ + [0.5, −2, 1, 0.3, 0, −0.1]`` N·m, seed 0, the
``ekf`` on the calibrated model errs by 2.6 rad/s RMS, by 6.2e-3 adding
it, 8.0e-3 on the true torques).

The model layer cannot import the smoother (layers run one way), hence this
thin wrapper one layer up; the machinery is the model layer's, written once.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import IdentificationError, NonFiniteError, ObserverDiverged
from pinobs.model import Robot
from pinobs.model import identification as ident_model
from pinobs.model.identification import MAX_CONDITION, Identification, log_arrays, segments
from pinobs.model.identification.model_error import acceleration_error_psd, noise_floor_psd
from pinobs.observers.base import Vector, positive
from pinobs.observers.noise import joint_noise_std, moving_median
from pinobs.smoothing import smooth_quietly

__all__ = ["REFINE_ACCEL_PSD", "REFINE_DISTURBANCE_PSD", "identify"]

#: White-acceleration densities [rad²/s³] of the successive smoother passes (module docstring).
REFINE_ACCEL_PSD: tuple[float, ...] = (1e-6, 1e-7)

#: Torque-offset density [rad²/s⁵] of the smoothed EKF (adaptive's learned-model density).
REFINE_DISTURBANCE_PSD = 1e-4


def _noise_std(robot: Robot, t: Vector, q: Vector) -> float:
    """The log's position noise σ [rad or m]: the median over the joints that move of robust
    third differences (Gasser et al. 1986) over its first second, each at least the rounding
    of its printed positions (:func:`pinobs.observers.noise.joint_noise_std`,
    :func:`~pinobs.observers.noise.moving_median`), floored at 1e-9 (a
    noise-free log); on a joint at rest in that first second (its third differences there
    below the rounding of its printed positions), over all the rows instead, moving ones
    included.

    A first second at rest measured the rounding step, or nothing (then the floor 1e-9): on
    TIAGo's log (FIGAROH's, on the loop's clock) torso and arm_1..4 gave 1e-18 there, their
    rounding 4.4e-6, and σ = 5.2e-6; now 1.4e-5 (those joints over all their rows; every
    joint over all its rows: 2.5e-5, with which the held-out torque residuals of
    ``pinobs.identify`` were those of 5.2e-6 to 1.2 %: torso 0.518 and 0.517 N).  Over all the rows
    a slow log's own motion leaks into its third differences (``pinobs excite``'s
    noise-free 100 Hz trajectory: 1.3e-5 against its first second's 1.15e-5), hence the
    first second where it moves.  ``noise_std`` (``pinobs identify --noise``) overrides it.
    """
    found = joint_noise_std(t, q, robot, rest_over_all_rows=True)
    if found is None:
        raise IdentificationError("fewer than 12 finite samples to measure the noise on")
    return max(moving_median(found[0])[0], 1e-9)


def identify(
    robot: Robot,
    log: Any,
    *,
    friction: bool | str = True,
    offset: bool = False,
    armature: bool = True,
    holdout: float = 0.2,
    window: float = 0.1,
    max_condition: float = MAX_CONDITION,
    refine: Sequence[float] = REFINE_ACCEL_PSD,
    noise_std: float | None = None,
    torque: str = "held",
    weighting: str = "inertia",
    exclude: Sequence[str] = (),
    payload: str | None = None,
    smoothing: float | None = None,
) -> Identification:
    """Identify ``robot``'s dynamic parameters from a log, with model-based velocities.

    The arguments up to ``max_condition`` and the result are those of
    :func:`pinobs.model.identification.identify` (the log, the report, the
    errors it raises), except that ``offset`` is off by default (module docstring,
    "The torque offset").  This adds:

    Args:
        refine: white-acceleration densities [rad²/s³] of the smoother passes
            (module docstring); ``()`` keeps the Savitzky–Golay velocities
            (one pass, the cheapest).
        noise_std: the log's position noise [rad or m] (default: estimated,
            :func:`pinobs.observers.noise.estimate_noise_std`).
        torque: how the log's torques were taken, for ``∫ τ dt``: ``"held"`` over each
            sample (zero-order hold: ``pinobs.simulate``, most controllers) or
            ``"sampled"`` at the instants (``pinobs excite``'s trajectory: trapezoid);
            every pass (the model layer's ``torque``).
        weighting: the model layer's (the rows weighted by ``M⁻¹`` by default, or each
            torque channel by its own residual scale in N·m), every pass.
        exclude: the model layer's (joints whose torque channel is left out), every pass.
        payload: the model layer's (a load's ten parameters on a calibrated ``robot``).
        smoothing: the friction law's smoothing velocity [rad/s] instead of its search
            (the model layer's ``smoothing``), every pass.

    ``report["velocities"]`` says which velocities the last pass used
    (``"savgol"`` or ``"rts(accel_psd=…)"``), ``report["noise_std"]`` the σ
    the smoother was given and ``report["smoother_consistency"]`` the last
    smoother pass's consistency ``ρ`` (NaN with ``refine=()``): about 1 when
    the model and the torques explain the positions, in the hundreds under
    torque noise of a few percent, where the refinement may be worse than
    ``refine=()`` (module docstring, "Limitation: noisy torques"); ``report["observer_options"]``
    is empty (``ekf``, ``kalman``, ``riemannian`` with their defaults take ``robot.model_error_psd``,
    :func:`_with_model_error`).

    Raises:
        IdentificationError: as the model-layer ``identify``.
        GainError: a non-positive ``refine`` density or ``noise_std``.
    """
    for psd in refine:
        positive("refine accel_psd", psd)
    positive("noise_std", noise_std, allow_none=True)
    opts: dict[str, Any] = {
        "friction": friction,
        "offset": offset,
        "armature": armature,
        "holdout": holdout,
        "window": window,
        "max_condition": max_condition,
        "torque": torque,
        "weighting": weighting,
        "exclude": tuple(exclude),
        "payload": payload,
        "smoothing": smoothing,
    }
    # the Savitzky–Golay pass only feeds the smoother: v_s at the CV minimum (module docstring)
    current = ident_model.identify(robot, log, **opts, smoothing_minimum=bool(refine))
    arrays = log_arrays(robot, log, warn_filled=bool(refine))  # (no refine: NaN rows kept)
    if refine:
        current = _refined(robot, arrays, current, opts, refine, noise_std)
    else:  # nothing smoothed
        current.report["velocities"], current.report["smoother_consistency"] = "savgol", math.nan
    return _with_model_error(robot, current, arrays, noise_std)


def _with_model_error(
    robot: Robot,
    ident: Identification,
    log: tuple[Vector, Vector, Vector],
    noise_std: float | None,
) -> Identification:
    """``ident`` with its robot's :attr:`~pinobs.model.Robot.model_error_psd` set: the
    identified model's acceleration error on the fitted rows as a white-noise density beyond
    what the derivative estimate's own noise gives (issue 36)::

        ψ_j = mean_k(e_{k,j}²) · h̄ − ψ₀,    e = a_model(q̂, v̂, τ + b) − â,    ψ₀ = σ² Σ c₂² h̄

    (:func:`~pinobs.model.identification.model_error.acceleration_error_psd` against the
    Savitzky–Golay accelerations;
    ``ψ₀`` :func:`~pinobs.model.identification.model_error.noise_floor_psd` of the log's σ, the
    variance of a sum of independent errors less the estimator's), ``ψ = mean_j ψ_j``, stored
    when above ``ψ₀`` (a model error the estimate resolves), else ``None``: the model is then
    as good as its data can tell, and the observers trust it as exact (1e-8).  Measured with
    planar_3r identified from 4 s at σ = 1e-4 (its payload found): 9e-6 in all, ``ψ₀`` 8.4e-6,
    not stored; an ``ekf`` given it on the UR5's ``benchmarks/learning.py`` offline case was 3.4×
    less accurate than at 1e-8.  ``report["model_error_psd"]`` (``ψ``),
    ``report["model_error_psd_per_joint"]`` and ``report["model_error_floor"]`` (``ψ₀``)."""
    t, q, _ = log
    rows = t <= ident.report["fit_end"]
    raw, per_joint = acceleration_error_psd(ident.robot, log, rows=rows, offset=ident.offset)
    sigma = noise_std if noise_std is not None else ident.report.get("noise_std")
    if sigma is None:  # (refine=(): not estimated yet)
        sigma = _noise_std(robot, t, q)
    fit_t = t[rows & np.isfinite(t)]
    h = float(np.median(np.diff(fit_t))) if fit_t.shape[0] > 1 else math.nan
    floor = noise_floor_psd(float(sigma), h) if h > 0 else math.nan
    excess = [max(x - floor, 0.0) for x in per_joint]
    psd = float(np.mean(excess)) if math.isfinite(raw) else math.nan
    ident.robot.model_error_psd = psd if psd > floor else None  # (NaN: not stored)
    ident.report["model_error_psd"] = psd
    ident.report["model_error_psd_per_joint"] = excess
    ident.report["model_error_floor"] = floor
    return ident


def _refined(
    robot: Robot,
    log: tuple[Vector, Vector, Vector],
    current: Identification,
    opts: dict[str, Any],
    refine: Sequence[float],
    noise_std: float | None,
) -> Identification:
    """The passes of :func:`identify` after the first (``current``): each smooths the log
    ``(t, q, tau)`` on the model identified so far, at the next density of ``refine``, and
    identifies again from the smoothed path (module docstring)."""
    t, q, tau = log
    sigma = noise_std if noise_std is not None else _noise_std(robot, t, q)
    for i, psd in enumerate(refine):
        # a pass before the last one only feeds the next fit: its held-out end needs no smoothing
        last = i == len(refine) - 1
        rows = np.ones(t.shape, bool) if last else t <= current.report["fit_end"]
        current, rho = _refine_pass(robot, current, (t, q, tau), rows, psd, sigma, opts)
    current.report["noise_std"] = sigma
    current.report["smoother_consistency"] = rho
    # measured in benchmarks/learning.py: on a model identified this way the default ekf is
    # 1.1-5x more accurate than with the model-error densities the one-pass fit recommends
    current.report["observer_options"] = {}
    return current


def _refine_pass(
    robot: Robot,
    ident: Identification,
    log: tuple[Vector, Vector, Vector],
    rows: NDArray[np.bool_],
    accel_psd: float,
    noise_std: float,
    opts: dict[str, Any],
) -> tuple[Identification, float]:
    """One refinement pass of :func:`identify`: the model layer's fit (options ``opts``) on
    the path :func:`_smoothed_path` gives on ``ident``'s model, its rows weighted by the
    armature ``ident`` identified when the default weights would carry the floor's (the model
    layer's ``weight_model``: its second stage, without the first); and the smoother's ``ρ``."""
    t, q, tau = log
    path, rho = _smoothed_path(ident, t, q, tau, rows, accel_psd=accel_psd, noise_std=noise_std)
    reg = ident.regressor
    if opts["payload"] is None and reg.armature_weighted:
        opts = {**opts, "weight_model": reg.armature_weights(ident.parameters.values)}
    out = ident_model.identify(robot, log, path=path, **opts)
    out.report["velocities"] = f"rts(accel_psd={accel_psd:g})"
    return out, rho


def _smoothed_path(
    ident: Identification,
    t: Vector,
    q: Vector,
    tau: Vector,
    rows: NDArray[np.bool_],
    *,
    accel_psd: float,
    noise_std: float,
) -> tuple[tuple[Vector, Vector], float]:
    """RTS-smoothed ``(q, v)`` of every contiguous stretch of ``rows`` on the identified model,
    and the smoother's consistency ``ρ`` pooled over the stretches (each weighted by its number
    of terms: :attr:`pinobs.smoothing.Smoothed.consistency`; NaN with none smoothed).

    NaN elsewhere (where the model layer falls back on Savitzky–Golay).
    """
    robot = ident.robot
    q_out = np.full(q.shape, np.nan)
    v_out = np.full(tau.shape, np.nan)
    rho_sum, terms = 0.0, 0
    t_rows = np.where(rows, t, np.nan)  # rows left out break the stretches
    for seg in segments(t_rows, q, tau):
        if seg.stop - seg.start < 3:
            continue
        try:
            # a fit of torques no parameters explain (negated ones) can leave M(q) singular to
            # rounding, the rotors' armature at its bound 0 and a body's pseudo-inertia on the
            # PSD cone's boundary: the EKF's transition then overflows, which the base class
            # reports as NonFiniteError; numpy's own warnings on the way say nothing more
            with np.errstate(over="ignore", invalid="ignore"):
                sm = smooth_quietly(  # its consistency is not the user's concern here
                    robot,
                    (t[seg], q[seg], tau[seg] + ident.offset),
                    noise_std=noise_std,
                    accel_psd=accel_psd,
                    disturbance_psd=REFINE_DISTURBANCE_PSD,
                )
        except (NonFiniteError, ObserverDiverged):
            continue  # this stretch keeps the Savitzky–Golay velocities (build_rows)
        q_out[seg], v_out[seg] = sm.q, sm.v
        n = int(sm.options["consistency_terms"])
        if n > 0 and np.isfinite(sm.consistency):
            rho_sum, terms = rho_sum + sm.consistency * n, terms + n
    return (q_out, v_out), rho_sum / terms if terms else math.nan

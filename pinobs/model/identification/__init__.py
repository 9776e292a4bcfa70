"""Identification of a robot's dynamic parameters in momentum form (MATH §9).

One machinery for the offline :func:`identify` (``pinobs identify``) and the
online ``adaptive`` observer, in modules along its seams: ``regressor`` (the rows'
regressor, its parameters and priors), ``savgol`` (velocities of the measured path),
``leastsquares`` (the solve and physical consistency), ``rows`` (a log read, split and
made into rows), ``diagnostics`` (what the data say against a fit), ``payload`` (a load on a
calibrated robot), ``offline`` (:func:`identify`) and ``result`` (what it returns).  Every
public name is importable from here.

**Parameters.**  ``θ = (π, D, F_c, b)``: ``π`` stacks ten numbers per body in
Pinocchio's ``Inertia.toDynamicParameters()`` order (``m, m·c_x, m·c_y,
m·c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz``, the rotational inertia at the
joint frame's origin), named ``<body>.m``, ``<body>.mx``, …; per actuated
velocity coordinate ``j`` (revolute, prismatic, continuous joints) a viscous
``<joint>.damping`` ``D_j`` [N·m·s/rad], a Coulomb ``<joint>.coulomb``
``F_j`` [N·m], a rotor inertia ``<joint>.armature`` ``I_a,j`` [kg·m² or kg] (a
gear-reduced motor's, reflected through the reduction: Pinocchio's ``model.armature``,
which its CRBA and ABA add to ``M``'s diagonal) and a torque offset ``<joint>.offset``
``b_j`` [N·m].  The dynamics they describe::

    (M(q) + diag(I_a)) v̇ + C(q, v) v + g(q) = τ − D v − F_c tanh(v / v_s) + b

(``v_s`` = :data:`pinobs.tolerances.COULOMB_SMOOTHING_VELOCITY`, as in
:meth:`Robot.friction_torque`).  A torque fed at the wrong scale (motor
constants) is absorbed by a common scale of ``(π, D, F_c)``.  ``identify(...,
friction=LAW)`` replaces ``D v + F_c tanh(v/v_s)`` by a law of :mod:`pinobs.model.friction`
(its coefficients' columns ``∫ φ(v) dt``, its ``v_s`` chosen by cross-validation with the
one-standard-error rule: :mod:`pinobs.model.friction_fit`).

**Momentum form** (no acceleration).  With ``p = (M(q) + diag(I_a)) v``,
``ṗ = τ + C(q, v)ᵀ v − g(q) − D v − F_c tanh(v/v_s) + b`` (the armature is constant: it
adds nothing to ``Ṁ``), so over a window ``[t₁, t₂]``::

    [Y_M(q₂, v₂) − Y_M(q₁, v₁) − ∫ Y_G(q, v) dt] π + D ∫v dt + F_c ∫tanh(v/v_s) dt
        + I_a (v₂ − v₁) − b (t₂ − t₁) = ∫ τ dt                             (MATH §9)

``Y_M(q, v) π = M(q) v`` is Pinocchio's joint-torque regressor
(``computeJointTorqueRegressor``) of the zero-gravity model at zero velocity
with ``a = v``; ``Y_G(q, v) π = C(q, v)ᵀ v − g(q) = Ṁ v − (C v + g)`` is
``D_v Y_M(q, v) − Y(q, v, 0)`` (the derivative of ``Y_M`` along ``q ⊕ εv``
with ``v`` held, by a central difference of step
:data:`IDENTIFICATION_FD_STEP`; ``Y(q, v, 0)`` the regressor of ``C v + g``).
``∫ τ dt`` is exact for a zero-order-hold torque (``torque="held"``, MATH §7:
``pinobs.simulate``'s, a drive's commanded torque) or the trapezoidal rule for a
torque sampled at the instants (``torque="sampled"``: an excitation's, a torque
sensor's); the wrong one is off by ``h (τ(t₂) − τ(t₁))/2`` per window, a bias
∝ 1/rate (a 100 Hz excitation read as held: a spurious damping of 0.16 N·m·s/rad
on planar_3r, 0.016 at 1 kHz; a UR5 simulation read as sampled: acceleration error
0.15 against 2.7e-4).  The friction integrals use the trapezoidal rule at the full
rate, the drift integral every ``stride``-th sample.

**Dropped samples and irregular sampling** (:mod:`pinobs.model.sampling`).  The
integrals run over the log's true times: windows and quadrature nodes are placed
in time (a node on the first row at or after each multiple of the stride, a
dropped sample moving it to the next row, never splitting a window), a held
torque's missing samples are taken on the line between their neighbours, and the
Savitzky–Golay fit is made in real time.  Measured on 8 s planar_3r logs
(σ = 1e-4, seeds 1–5, ``benchmarks/irregular_logs.py``): with 8 % of the rows
dropped the acceleration error of the fit was 0.96–1.14× that of the clean log, geometric
mean 1.00 (``pinobs.identify``'s refined fit 0.51–1.12×, 0.84); sampled at intervals
uniform in 0.5–1.5 ms, 0.54–1.05×, 0.82 (0.93–1.07×, 0.99).  On a uniform log every row, window and
number is what it was.  ``v`` and a
smoothed ``q`` come from a zero-phase Savitzky–Golay fit of the measured
path (:func:`smooth_path`), or are given (``identify(..., path=(q, v))``;
``pinobs.identify`` gives a model-based smoother's:
:mod:`pinobs.calibration`).

**Weighting.**  With ``weighting="torque"`` each window's ``nv`` rows are
divided by ``t₂ − t₁`` only: its mean torque [N·m; N for a prismatic joint], and each
torque channel ``j`` is weighted by its own residual scale ``σ_j`` (``1.4826 · median |r|``
over its rows, re-estimated at each robust pass: :func:`solve`'s ``channel``), so that a
channel counts by how well it can be fitted, in its own units, whatever its link's
inertia.  A channel can be left out (``exclude``: a torque that is not measured, under
either weighting), and one that is zero on most rows is refused unless it is
(:data:`ZERO_TORQUE_SHARE`).  Measured (``benchmarks/real_logs.py``'s held-out torque
residual per joint, ``pinobs.identify``; the run of ``real_logs.json`` dated 2026-12-05): on
TIAGo, arm_5..7 left out, the torso's 0.519 N against 1.08 with ``M⁻¹`` weighting (nominal
1.28), arm_1..4 0.816 2.89 1.38 0.844 N·m against 0.841 3.08 1.40 0.839; on the UR10e,
pooled over the moving held-out logs, 3.41 5.16 1.93 0.562 0.794 0.727 against 3.44 5.14
1.95 0.561 0.794 0.725.  On simulated logs
the ``M⁻¹`` weighting is the better one (their residual is mostly the velocity estimate's
error ``M δv / T``, which ``M⁻¹`` whitens): planar_3r, σ = 1e-5, mass-matrix error 1.0e-2
against 1.1e-3 with ``refine=()`` and 2.8e-5 against 4.1e-6 refined; on
``benchmarks/learning.py``'s offline table the calibrated ``ekf`` 2.2× (UR5, 20 % inertia
error and payload) and 1.7× (Panda) less accurate, the one-pass Panda 5×.  Hence the
default, ``weighting="inertia"``: the real-data gain of the other is within 6 % on the
arms' joints (52 % on TIAGo's torso), the simulated loss 1.1–5× on the observers; on a
real robot whose light joints' torques are noisy (TIAGo's torso) try
``weighting="torque"``.  With ``weighting="inertia"`` each window's ``nv`` rows are weighted by
``M₀(q_mid)⁻¹ / (t₂ − t₁)`` (an acceleration-like residual, so every joint
counts alike; ``M₀`` the nominal mass matrix, and when the armature is identified
its armature raised by the prior's floor, :data:`PRIOR_ARMATURE_FLOOR` of the largest
``M̄ⱼⱼ`` of the joint's kind, on every actuated joint:
:attr:`MomentumRegressor.weight_robot`).  A
nominal model without rotors weighs a wrist's rows by its link's inertia alone,
2000× less than its rotor's on the UR10e (wrist 3: ``M̄`` 2e-4 kg·m², published
rotor 0.44); so weighted, and with the friction priors scaled by that small ``M̄``
too, the real UR10e logs (``benchmarks/real_logs.py``) gave wrist 3 a rotor of 0.08
and a held-out residual no better than without armature (3.27 N·m pooled, 3.34
without), and the fit depended on the prior's mean (3.27 from 0, 0.73 from the
published rotors); with the floor, 0.44 kg·m² and 0.73 N·m from either mean.
The weighted residuals of a fit with and without armature are then in different
units: compare them in torque (N·m), not in ``report["holdout_after"]``.  The floor is a
guess at rotors the data have not yet shown; kept as the weights, it cost a truth without
rotors dearly (UR5, links ±20 % and a payload: the wrists' rows ~8× under-weighted, the
one-pass ``ekf`` of ``benchmarks/learning.py`` 2.9× less accurate).  Hence two stages
(feasible generalised least squares): the fit weighted with the floor, then the fit
weighted by ``M₀(q)⁻¹`` carrying the armature that first fit identified
(:meth:`MomentumRegressor.armature_weights`, ``identify(weight_model=...)``;
``pinobs.identify``'s refined passes take the previous pass's, one stage each).  The
priors keep the floor's inertia (they do not depend on the data).  Measured: that
one-pass row 1.95e-3 → 6.6e-4 rad/s (before the floor: 6.7e-4); the UR10e's pooled
held-out torques 3.48 5.27 2.01 0.561 0.794 0.725 → 3.44 5.14 1.95 0.561 0.794 0.725 N·m
(wrist 3's rotor 0.436 → 0.439 kg·m²); TIAGo's held-out torso 0.648 → 0.611 N, arm_1..4
0.821 3.037 1.381 0.823 → 0.967 3.204 1.356 0.828 N·m.  Weighting by the whole first fit's
``M`` instead was better still on the simulated truths (one-pass UR5 5.9e-4, z1 2.7e-3 →
8.5e-4) but weighed the real TX40's joint 2 to a held-out residual of 16.8 N·m (6.6 so,
8.7 nominal): a fit's inertials compensate what the model cannot express.

**Armature: only where the data determine it** (:mod:`~pinobs.model.identification.armature`).
The fit with every rotor is tested once (at each of its stages until one is dropped): a
rotor inertia whose step from the model's own is within :data:`ARMATURE_SIGMAS` (2)
posterior standard deviations, or within :data:`ARMATURE_SHARE` (1 %) of its joint's
nominal inertia ``M̄ⱼⱼ``, is dropped (the model's own taken as known, no column) and the
fit is made again, its rows weighted by the nominal model carrying the rotors kept (none
kept: the fit without armature, weights and priors included).  A column the data do not
determine adds variance: on ``benchmarks/learning.py``'s simulated truths (no rotors) the
armature columns cost the one-pass ``ekf`` up to 1.16× (z1, links ±20 % and a payload)
against the fit without them; their spurious rotors had z up to 3.65 but were 0.06–0.8 %
of their joints' inertia (the 0.8 %, z1's joint 6, at z = 1.4), and with the test every
one is dropped and those rows are the fit without armature's, to the digit.  On real
arms every rotor is kept: the UR10e's (``benchmarks/real_logs.py``'s fit; smallest z 2.8,
the shoulder pan's, whose column is nearly link 1's inertia about the same axis), the
pooled held-out torques and wrist 3's 0.4385 kg·m² (published 0.44) unchanged; FIGAROH's
TX40 (joint 5's rotor 10× its link's inertia at z = 2.6), its held-out torques unchanged.
A z-test alone (3σ, the rotors tested again after each refit) dropped the TX40's rotors
one by one (joint 2's held-out residual 6.6 → 11 N·m); tested once, it kept a spurious z1
rotor (one-pass ``ekf`` 1.11×).  The thresholds are round values chosen with these
cases in view.

**Solve** (:func:`solve`).  A Gaussian prior ``θ ~ N(θ₀, diag(s²))`` pulls
toward the nominal model (``θ₀``: the URDF's inertials, friction and armature, zero
offset); directions the data cannot see stay nominal.  The residual scale
σ is estimated from the data, rows are re-weighted robustly (Huber,
iteratively: Coulomb switching near ``v = 0`` contaminates rows).  The
identifiable combinations (*base parameters*) are found by a pivoted QR of
the prior-scaled stacked regressor: its rank, the pivot columns' names and
the condition number of those columns are reported; a parameter whose
posterior standard deviation is above half its prior one was not excited by
the data (it stays near nominal, and a trajectory that does not excite it
cannot teach it).

**Physical consistency** (Wensing, Kim, Slotine 2017): each body's
pseudo-inertia ``J = [[Σ, h], [hᵀ, m]]``, ``Σ = ½ tr(Ī)·1 − Ī``, must be
positive semi-definite, and friction and armature non-negative.  When the linear solution
violates either, it is replaced by the closest consistent one in the
posterior's own metric, ``min (θ − θ̂)ᵀ Λ (θ − θ̂)`` subject to ``J_k ⪰ 0`` (and
friction, armature ``≥ 0``):
``J`` is linear in ``θ``, so this is convex (a small semidefinite program),
solved by a log-barrier interior-point method (:func:`_consistent`).  A
Euclidean projection of each ``J`` onto the PSD cone would be cheaper but
moves well-identified combinations as freely as unseen ones (measured: it
made the UR5's wrist residual 7× worse); the posterior metric moves what the
data did not fix.  (A log-Cholesky parametrisation, Rucker & Wensing 2022,
was tried first: non-convex, and Levenberg-Marquardt stalled on it.)
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pinobs.model.identification.armature import (
        ARMATURE_SHARE as ARMATURE_SHARE,
    )
    from pinobs.model.identification.armature import (
        ARMATURE_SIGMAS as ARMATURE_SIGMAS,
    )
    from pinobs.model.identification.armature import (
        determined_armature as determined_armature,
    )
    from pinobs.model.identification.diagnostics import (
        HOLDOUT_WORSE as HOLDOUT_WORSE,
    )
    from pinobs.model.identification.diagnostics import (
        OUTLIER_SHARE as OUTLIER_SHARE,
    )
    from pinobs.model.identification.diagnostics import (
        ROWS_PER_COMBINATION as ROWS_PER_COMBINATION,
    )
    from pinobs.model.identification.diagnostics import (
        STILL_RANGE as STILL_RANGE,
    )
    from pinobs.model.identification.diagnostics import (
        UNEXPLAINED_MIN as UNEXPLAINED_MIN,
    )
    from pinobs.model.identification.diagnostics import (
        UNEXPLAINED_WARN as UNEXPLAINED_WARN,
    )
    from pinobs.model.identification.diagnostics import (
        ZERO_TORQUE_SHARE as ZERO_TORQUE_SHARE,
    )
    from pinobs.model.identification.diagnostics import (
        check_zero_torques,
    )
    from pinobs.model.identification.drive_gains import (
        GAIN_NULL_TOL as GAIN_NULL_TOL,
    )
    from pinobs.model.identification.drive_gains import (
        GAIN_RANK_TOL as GAIN_RANK_TOL,
    )
    from pinobs.model.identification.drive_gains import DriveGains, identify_drive_gains
    from pinobs.model.identification.leastsquares import (
        CHANNEL_SIGMA_FLOOR as CHANNEL_SIGMA_FLOOR,
    )
    from pinobs.model.identification.leastsquares import (
        MAX_CONDITION as MAX_CONDITION,
    )
    from pinobs.model.identification.leastsquares import (
        MU_END as MU_END,
    )
    from pinobs.model.identification.leastsquares import (
        Solution,
        pseudo_inertia,
        solve,
    )
    from pinobs.model.identification.offline import identify
    from pinobs.model.identification.payload import (
        PRIOR_PAYLOAD_LENGTH as PRIOR_PAYLOAD_LENGTH,
    )
    from pinobs.model.identification.payload import (
        PRIOR_PAYLOAD_MASS as PRIOR_PAYLOAD_MASS,
    )
    from pinobs.model.identification.payload import (
        PayloadRegressor,
        identify_payload,
    )
    from pinobs.model.identification.regressor import (
        IDENTIFICATION_FD_STEP,
        MomentumRegressor,
        excluded_coordinates,
    )
    from pinobs.model.identification.regressor import (
        PRIOR_ARMATURE as PRIOR_ARMATURE,
    )
    from pinobs.model.identification.regressor import (
        PRIOR_ARMATURE_FLOOR as PRIOR_ARMATURE_FLOOR,
    )
    from pinobs.model.identification.regressor import (
        PRIOR_COULOMB as PRIOR_COULOMB,
    )
    from pinobs.model.identification.regressor import (
        PRIOR_DAMPING as PRIOR_DAMPING,
    )
    from pinobs.model.identification.regressor import (
        PRIOR_INERTIA as PRIOR_INERTIA,
    )
    from pinobs.model.identification.regressor import (
        PRIOR_OFFSET as PRIOR_OFFSET,
    )
    from pinobs.model.identification.regressor import (
        STRIBECK_VELOCITY as STRIBECK_VELOCITY,
    )
    from pinobs.model.identification.regressor import (
        SUFFIXES as SUFFIXES,
    )
    from pinobs.model.identification.regressor import (
        TORQUE_SAMPLING as TORQUE_SAMPLING,
    )
    from pinobs.model.identification.regressor import (
        WEIGHTINGS as WEIGHTINGS,
    )
    from pinobs.model.identification.result import Identification, ParameterSet, Report
    from pinobs.model.identification.rows import (
        MAX_FILL as MAX_FILL,
    )
    from pinobs.model.identification.rows import (
        SETTLE_WINDOWS as SETTLE_WINDOWS,
    )
    from pinobs.model.identification.rows import (
        build_rows as build_rows,
    )
    from pinobs.model.identification.rows import (
        fill_short_gaps as fill_short_gaps,
    )
    from pinobs.model.identification.rows import (
        log_arrays,
        segments,
    )
    from pinobs.model.identification.savgol import smooth_path

#: Each public name -> its module in this package, imported on first use (PEP 562
#: ``__getattr__``): ``adaptive``'s learner imports the regressor, the solve and the smoothing,
#: not the offline identification, its diagnostics, drive gains and payload (issue 39:
#: 8–10 ms of its ``make_observer``).
_LAZY = {
    "ARMATURE_SHARE": "armature",
    "ARMATURE_SIGMAS": "armature",
    "determined_armature": "armature",
    "HOLDOUT_WORSE": "diagnostics",
    "OUTLIER_SHARE": "diagnostics",
    "ROWS_PER_COMBINATION": "diagnostics",
    "STILL_RANGE": "diagnostics",
    "UNEXPLAINED_MIN": "diagnostics",
    "UNEXPLAINED_WARN": "diagnostics",
    "ZERO_TORQUE_SHARE": "diagnostics",
    "check_zero_torques": "diagnostics",
    "GAIN_NULL_TOL": "drive_gains",
    "GAIN_RANK_TOL": "drive_gains",
    "DriveGains": "drive_gains",
    "identify_drive_gains": "drive_gains",
    "CHANNEL_SIGMA_FLOOR": "leastsquares",
    "MAX_CONDITION": "leastsquares",
    "MU_END": "leastsquares",
    "Solution": "leastsquares",
    "pseudo_inertia": "leastsquares",
    "solve": "leastsquares",
    "identify": "offline",
    "PRIOR_PAYLOAD_LENGTH": "payload",
    "PRIOR_PAYLOAD_MASS": "payload",
    "PayloadRegressor": "payload",
    "identify_payload": "payload",
    "IDENTIFICATION_FD_STEP": "regressor",
    "MomentumRegressor": "regressor",
    "excluded_coordinates": "regressor",
    "PRIOR_ARMATURE": "regressor",
    "PRIOR_ARMATURE_FLOOR": "regressor",
    "PRIOR_COULOMB": "regressor",
    "PRIOR_DAMPING": "regressor",
    "PRIOR_INERTIA": "regressor",
    "PRIOR_OFFSET": "regressor",
    "STRIBECK_VELOCITY": "regressor",
    "SUFFIXES": "regressor",
    "TORQUE_SAMPLING": "regressor",
    "WEIGHTINGS": "regressor",
    "Identification": "result",
    "ParameterSet": "result",
    "Report": "result",
    "MAX_FILL": "rows",
    "SETTLE_WINDOWS": "rows",
    "build_rows": "rows",
    "fill_short_gaps": "rows",
    "log_arrays": "rows",
    "segments": "rows",
    "smooth_path": "savgol",
}


def __getattr__(name: str) -> Any:
    """A public name of :data:`_LAZY`, imported from its module on first use (then cached)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "ARMATURE_SHARE",
    "ARMATURE_SIGMAS",
    "IDENTIFICATION_FD_STEP",
    "DriveGains",
    "Identification",
    "MomentumRegressor",
    "ParameterSet",
    "PayloadRegressor",
    "Report",
    "Solution",
    "check_zero_torques",
    "determined_armature",
    "excluded_coordinates",
    "identify",
    "identify_drive_gains",
    "identify_payload",
    "log_arrays",
    "pseudo_inertia",
    "segments",
    "smooth_path",
    "solve",
]

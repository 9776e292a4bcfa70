"""Numerical tolerances, defined once.

Every threshold pinobs applies to user input or uses to pick a numerical
branch lives here, so that a reader can see them together.
"""

from __future__ import annotations

__all__ = [
    "ABSURD_LIMIT_FACTOR",
    "ABSURD_VALUE",
    "COULOMB_SMOOTHING_VELOCITY",
    "GAP_PERIODS",
    "II_ASSUMPTION1_TOL",
    "INERTIA_TRIANGLE_TOL",
    "JACOBI_FD_STEP",
    "LEFT_INVARIANT_INERTIA_TOL",
    "LIMIT_WARN_FRACTION",
    "MASS_MATRIX_SINGULAR_TOL",
    "MAX_GAP_PERIODS",
    "MAX_PLAUSIBLE_PERIOD",
    "MIN_PLAUSIBLE_PERIOD",
    "NEGLIGIBLE_MASS_FRACTION",
    "NO_CONTACT_WARN_TIME",
    "PAUSE_RESTART",
    "QUATERNION_NORM_TOL",
    "SERIES_ANGLE",
    "TIME_BACK_ROWS",
    "TIME_EPS",
]

#: A measured quaternion (or continuous-joint ``(cos, sin)`` pair) whose norm is
#: further than this from 1 is rejected; closer ones are renormalised.  Loose
#: enough for float32 logs, tight enough to catch a raw ``w, x, y, z`` mix-up.
QUATERNION_NORM_TOL = 1e-4

#: Two timestamps closer than this [s] count as duplicates.
TIME_EPS = 1e-12

#: The Lie-group observer accepts a robot when its mass matrix, sampled at a few
#: configurations, varies by less than this (relative, max-norm): the kinetic
#: energy is then left-invariant (a single rigid body on SO(3) or SE(3)).
LEFT_INVARIANT_INERTIA_TOL = 1e-9

#: Assumption 1 of Sarras et al. (``D_T ≡ 0``) counts as holding when the
#: relative residual of ``D_T`` (``pinobs.observers.ii.OrderingResult``) stays
#: below this on every sampled configuration.  Analytic factor derivatives give
#: ~1e-15 where it holds; central differences ~1e-9; failures are O(0.1-1).
II_ASSUMPTION1_TOL = 1e-6

#: Step [rad] of the central difference along ``v`` in the Riemannian
#: observer's Jacobi operator ``R(v, ·)v`` (``ε|v|``): truncation ~ε², rounding
#: ~1e-16/ε; 1e-5 balances them near 1e-10 relative.
JACOBI_FD_STEP = 1e-5

#: Coulomb friction ``F_c sign(v)`` is smoothed as ``F_c tanh(v / v_s)`` with this
#: ``v_s`` [rad/s or m/s]: 95 % of the full friction at 2 v_s = 0.02 rad/s.
COULOMB_SMOOTHING_VELOCITY = 1e-2

#: A logged position (torque) further outside the joint's URDF range than this
#: many ranges (effort limits) is absurd: the row's value is rejected.  A log in
#: degrees stays below it (it is warned about: :data:`LIMIT_WARN_FRACTION`).
ABSURD_LIMIT_FACTOR = 100.0

#: Without a finite URDF limit, a logged |position| [rad or m] or |torque|
#: [N·m or N] above this is absurd.
ABSURD_VALUE = 1e6

#: Positions further outside the URDF limits than this fraction of the joint's
#: range get a warning naming the joint (a log in degrees?).  Not less than 1:
#: simulated and real robots do stray somewhat past their URDF limits.
LIMIT_WARN_FRACTION = 1.0

#: A gap between two log rows longer than this many nominal sample periods is
#: propagated in sub-steps no longer than one period.
GAP_PERIODS = 3.0

#: A gap longer than this many nominal periods re-initialises the observer at the
#: next row (position from the row, zero velocity) instead of being propagated:
#: open-loop propagation with the torque held through a long gap drifts, and
#: the model-based observers then recover more slowly than from a restart
#: (UR5, PD input, 1 kHz, σ = 1e-4 rad: after a 0.1 s gap the ekf's velocity
#: error 50 ms later is 0.21 rad/s sub-stepped, 0.0017 rad/s re-initialised;
#: after 20 ms, 0.009 vs 0.001; the kf is the same either way).
MAX_GAP_PERIODS = 10.0

#: A live update more than this many seconds (and ``MAX_GAP_PERIODS`` periods) after the
#: previous one restarts the observer's state at its sample (position, zero velocity;
#: what it learned kept).  Shorter pauses are propagated in sub-steps of one period: a
#: restart starts from zero velocity, which after 12–50 ms on a UR5 (1 kHz, PD input)
#: costs more at the first sample (1.2–1.3 rad/s) than propagating (0.002–0.033), and
#: after 0.2 s less (0.88 against 0.54 at the first sample, but 1.3e-3 against 0.44 rad/s
#: 50 ms later; :func:`pinobs.observers.checks.propagate_gap`).
PAUSE_RESTART = 0.1

#: Log rows whose time is not after the previous accepted row are skipped one
#: by one; when this many in a row go on increasing among themselves (a clock
#: reset, or earlier rows stamped ahead), the observer restarts at the next one.
TIME_BACK_ROWS = 5

#: A body's principal moments may break ``I₃ ≤ I₁ + I₂`` (or dip below zero) by
#: this fraction of ``I₃`` before :func:`pinobs.load` refuses it: published
#: inertias are rounded to 3-6 digits, and flat plates sit exactly on the bound.
INERTIA_TRIANGLE_TOL = 1e-3

#: Bodies lighter than this fraction of the robot's total mass are placeholders
#: (1 mg dummy links): the inertia-shape checks skip them.
NEGLIGIBLE_MASS_FRACTION = 1e-6

#: ``M(q)`` counts as singular when ``λ_min ≤`` this ``· λ_max``.  Every
#: example-robot-data robot that loads has ``λ_min/λ_max ≥ 5e-8`` at random
#: configurations; a joint moving only massless links gives ~1e-17.
MASS_MATRIX_SINGULAR_TOL = 1e-12

#: A median sample period [s] at or beyond these is said to be in another unit
#: (:func:`pinobs.observers.base.time_unit_warning`): 10 Hz and 1 MHz.
MAX_PLAUSIBLE_PERIOD = 0.1
MIN_PLAUSIBLE_PERIOD = 1e-6

#: [rad] Below this rotation angle θ the SO(3) series ``Γ_m(φ) = Σ_n (φ^)ⁿ/(n+m)!``
#: (the exponential, its left Jacobian and the next one) are summed as Taylor series in θ²
#: to θ⁸ (truncation θ¹⁰/11! < 3e-18 here); above it their closed forms, whose
#: cancellation error (~1e-16/θ² in Γ_2's last coefficient) is then below 2e-14.
SERIES_ANGLE = 0.1

#: [s] A contact-aided filter (``pinobs.observers.inekf``) warns once when no foot has been
#: in contact for this long: its velocity is then the IMU's open-loop integral.
NO_CONTACT_WARN_TIME = 0.5

"""Identification of a robot's dynamic parameters in momentum form (MATH §9).

One machinery for the offline :func:`identify` (``pinobs identify``) and the
online ``adaptive`` observer.

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
(its coefficients' columns ``∫ φ(v) dt``, its ``v_s`` chosen by cross-validation:
:mod:`pinobs.model.friction_fit`).

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
(σ = 1e-4, seeds 1–3, ``benchmarks/irregular_logs.py``): with 8 % of the rows
dropped the acceleration error of the fit was 0.96–0.98× that of the clean log
(``pinobs.identify``'s refined fit 0.51–1.12×); sampled at intervals uniform in
0.5–1.5 ms, 0.54–0.96× (0.93–1.07×).  On a uniform log every row, window and
number is what it was.  ``v`` and a
smoothed ``q`` come from a zero-phase Savitzky–Golay fit of the measured
path (:func:`smooth_path`), or are given (``identify(..., path=(q, v))``;
``pinobs.identify`` gives a model-based smoother's:
:mod:`pinobs.observers.calibration`).

**Weighting.**  With ``weighting="torque"`` each window's ``nv`` rows are
divided by ``t₂ − t₁`` only: its mean torque [N·m; N for a prismatic joint], and each
torque channel ``j`` is weighted by its own residual scale ``σ_j`` (``1.4826 · median |r|``
over its rows, re-estimated at each robust pass: :func:`solve`'s ``channel``), so that a
channel counts by how well it can be fitted, in its own units, whatever its link's
inertia.  A channel can be left out (``exclude``: a torque that is not measured, under
either weighting), and one that is zero on most rows is refused unless it is
(:data:`ZERO_TORQUE_SHARE`).  Measured (``benchmarks/real_logs.py``'s held-out torque
residual per joint, ``pinobs.identify``): on TIAGo, arm_5..7 left out, the torso's 0.516 N
against 0.723 with ``M⁻¹`` weighting (nominal 1.276), arm_1..4 0.813 2.847 1.397 0.844 N·m
against 0.820 3.077 1.404 0.826; on the UR10e, pooled over the moving held-out logs, 3.41
5.16 1.94 0.562 0.794 0.727 against 3.48 5.27 2.01 0.561 0.794 0.725.  On simulated logs
the ``M⁻¹`` weighting is the better one (their residual is mostly the velocity estimate's
error ``M δv / T``, which ``M⁻¹`` whitens): planar_3r, σ = 1e-5, mass-matrix error 1.0e-2
against 1.1e-3 with ``refine=()`` and 2.8e-5 against 4.1e-6 refined; on
``benchmarks/learning.py``'s offline table the calibrated ``ekf`` 2.2× (UR5, 20 % inertia
error and payload) and 1.7× (Panda) less accurate, the one-pass Panda 5×.  Hence the
default, ``weighting="inertia"``: the real-data gain is 2–30 % on the residual, the
simulated loss 1.1–5× on the observers; on a real robot whose light joints' torques are
noisy (TIAGo's torso) try ``weighting="torque"``.  ``weighting="inertia"``.  With ``weighting="inertia"`` each window's ``nv`` rows are weighted by
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
units: compare them in torque (N·m), not in ``report["holdout_after"]``.

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

import functools
import itertools
import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from os import PathLike
from typing import Any, cast

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import (
    DimensionError,
    GainError,
    IdentificationError,
    OptionError,
    PinobsWarning,
    TimestampError,
)
from pinobs.model.friction import FRICTION_LAWS, FrictionLaw, friction_basis, law_terms
from pinobs.model.friction_fit import (
    candidate_columns,
    search_candidates,
    search_smoothing,
    widened,
)
from pinobs.model.noise import robust_rms, third_difference_std
from pinobs.model.robot import Robot, Vector
from pinobs.model.sampling import SPLIT_GAP_PERIODS, held_torque_integral, is_uniform
from pinobs.tolerances import ABSURD_LIMIT_FACTOR, ABSURD_VALUE

__all__ = [
    "IDENTIFICATION_FD_STEP",
    "Identification",
    "MomentumRegressor",
    "ParameterSet",
    "PayloadRegressor",
    "Solution",
    "check_zero_torques",
    "excluded_coordinates",
    "identify",
    "identify_payload",
    "log_arrays",
    "pseudo_inertia",
    "segments",
    "smooth_path",
    "solve",
]

#: Step ``ε`` of the central difference ``D_v Y_M ≈ (Y_M(q ⊕ εv) − Y_M(q ⊖ εv)) / 2ε``
#: (``ε`` in seconds: ``εv`` is the displacement over ε s); truncation ~ε²|v|², rounding ~1e-16/ε.
IDENTIFICATION_FD_STEP = 1e-5

SUFFIXES = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")

#: Relative prior standard deviation of the inertial parameters (0.5: the URDF
#: is trusted to within ±50 % per parameter, in units of the body's own scale).
PRIOR_INERTIA = 0.5

#: Prior standard deviations of friction and offset, as accelerations of each
#: joint's nominal inertia ``M̄ⱼⱼ``: damping 10 /s, Coulomb 5 rad/s², offset 5 rad/s².
PRIOR_DAMPING, PRIOR_COULOMB, PRIOR_OFFSET = 10.0, 5.0, 5.0

#: Prior standard deviation of the armature (rotor inertia), in units of each joint's
#: nominal inertia ``M̄ⱼⱼ`` (neutral configuration, armature included) and at least
#: :data:`PRIOR_ARMATURE_FLOOR` of the largest ``M̄ⱼⱼ`` of the joints of its kind
#: (:meth:`MomentumRegressor.armature_floor`).  A geared motor reflects ``J_m N²``: 0.1–3
#: kg·m² on an industrial arm (``J_m`` 1e-5–1e-4 kg·m², ``N`` 100–160), as much as the
#: arm's own inertia at the proximal joints and far more at the wrist (UR10e, Mamedov et
#: al. 2020: 3.7 kg·m² at the shoulder lift, 0.44 at wrist 3, whose link has 2e-4).
#: Hence a wide prior: a wrist's armature is not held near zero by its small link; the
#: prior mean is the model's own ``armature`` (usually 0) and the bound ``I_a ≥ 0`` keeps
#: an unexcited one there.  The floor also enters the rows' weights (module docstring).
#: Measured on the real UR10e logs with floors of 0.01, 0.03 and 0.1: pooled held-out
#: residuals within 3 % of each other; on TIAGo's log, 0.1 (then of the largest
#: ``M̄ⱼⱼ`` of any kind, the 19 kg torso's) raised the condition number from 8.4e5
#: (without armature) to 2.8e6, past :data:`MAX_CONDITION`, 0.01 to 9.5e5.
PRIOR_ARMATURE, PRIOR_ARMATURE_FLOOR = 1.0, 0.03

#: Default Stribeck velocity ``v_st`` [rad/s] of a Stribeck law's columns before its search.
STRIBECK_VELOCITY = 0.1

#: Last barrier weight of :func:`_consistent` (in units of the largest posterior precision).
MU_END = 1e-16

#: Refuse a log whose base regressor is worse conditioned than this.
MAX_CONDITION = 1e6


# ----------------------------------------------------------------- parameters
def pseudo_inertia(pi: Vector) -> Vector:
    """``J = [[Σ, h], [hᵀ, m]]``, ``Σ = ½ tr(Ī)·1 − Ī``, of one body's ten parameters (Wensing et al. 2017)."""
    m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = pi
    inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    out = np.empty((4, 4))
    out[:3, :3] = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    out[:3, 3] = out[3, :3] = (hx, hy, hz)
    out[3, 3] = m
    return out


def _from_pseudo_inertia(J: Vector) -> Vector:
    sigma = J[:3, :3]
    inertia = np.trace(sigma) * np.eye(3) - sigma
    return np.array(
        [
            J[3, 3],
            J[0, 3],
            J[1, 3],
            J[2, 3],
            inertia[0, 0],
            inertia[0, 1],
            inertia[1, 1],
            inertia[0, 2],
            inertia[1, 2],
            inertia[2, 2],
        ]
    )


@dataclass(frozen=True)
class ParameterSet:
    """Named dynamic parameters with standard deviations.

    Attributes:
        names: ``<body>.m`` … ``<joint>.offset``, in the order of :class:`MomentumRegressor`.
        values: the parameters (SI units: kg, kg·m, kg·m², N·m·s/rad, N·m).
        std: their posterior standard deviations (same units).
        nominal: the nominal (URDF) values.
        excited: whether the data fixed each parameter (posterior std below
            half the prior one).
    """

    names: tuple[str, ...]
    values: Vector
    std: Vector
    nominal: Vector
    excited: NDArray[np.bool_]

    def __getitem__(self, name: str) -> float:
        try:
            return float(self.values[self.names.index(name)])
        except ValueError:
            raise KeyError(f"no parameter {name!r}; e.g. {', '.join(self.names[:4])}") from None

    def as_rows(self) -> list[tuple[str, float, float, float, bool]]:
        """``(name, value, std, nominal, excited)`` per parameter."""
        return [
            (n, float(v), float(s), float(m), bool(e))
            for n, v, s, m, e in zip(
                self.names, self.values, self.std, self.nominal, self.excited, strict=True
            )
        ]


class MomentumRegressor:
    """The momentum-form regressor of a robot (module docstring): rows, names, nominal values.

    Args:
        robot: the nominal model (its inertials are the prior mean; its
            friction too when ``robot.friction`` is on).
        friction: identify friction per actuated joint: ``True`` the URDF's viscous +
            Coulomb law (``"viscous-coulomb"``), or the name of a law of
            :data:`~pinobs.model.friction.FRICTION_LAWS` (its terms' columns, each
            ``∫ φ(v) dt``: :func:`~pinobs.model.friction.friction_basis`).
        offset: identify a constant torque offset per actuated joint.
        smoothing: the smoothing velocity ``v_s`` [rad/s] of the friction columns, one per
            actuated joint (default: the robot's friction law's, the URDF's 0.01).
        stribeck_velocity: ``v_st`` [rad/s] of a Stribeck law's columns, one per actuated
            joint (default: the robot's law's where positive, else
            :data:`STRIBECK_VELOCITY`).
        armature: identify a rotor inertia per actuated joint (off by default here: the
            online ``adaptive`` learner keeps the model's; :func:`identify` turns it on).
            Off, the model's own armature is taken as known (moved to the torque side).
        weighting: how :meth:`system` weighs a window's ``nv`` rows: ``"inertia"`` by
            ``M₀(q_mid)⁻¹ / (t₂ − t₁)`` (acceleration-like, rad/s²; the online learner's)
            or ``"torque"`` by ``1 / (t₂ − t₁)``: the window's mean torque residual in N·m
            (N for a prismatic joint), which :func:`identify` then divides per channel by
            that channel's own residual scale (module docstring, "Weighting").
        exclude: joints whose torque channel is left out (:meth:`_inertia_weight`).
    """

    def __init__(
        self,
        robot: Robot,
        *,
        friction: bool | str = True,
        offset: bool = True,
        armature: bool = False,
        weighting: str = "inertia",
        exclude: Sequence[str] = (),
        smoothing: ArrayLike | None = None,
        stribeck_velocity: ArrayLike | None = None,
    ) -> None:
        _check_weighting(weighting)
        self.weighting = weighting
        #: velocity coordinates whose torque channel is left out (:func:`identify`'s
        #: ``exclude``): with ``weighting="inertia"`` their rows are zero and the others are
        #: weighted by the kept block's inverse mass matrix.
        self.excluded = excluded_coordinates(robot, exclude)
        self.robot = robot
        model = robot.model
        self._model = model.copy()
        self._data = self._model.createData()
        self._free = model.copy()
        self._free.gravity.setZero()
        self._free_data = self._free.createData()
        self._zero = np.zeros(model.nv)
        #: the friction law identified (None: no friction columns)
        self.friction_law: str | None = _law_name(friction)
        self.friction = self.friction_law is not None
        self.friction_terms = law_terms(self.friction_law) if self.friction_law else ()
        self.offset = bool(offset)
        self.armature = bool(armature)
        self.bodies = tuple(_body_name(model, i) for i in range(1, model.njoints))
        #: velocity coordinates with friction and offset columns (actuated 1-dof joints)
        self.actuated = tuple(
            b.idx_v for b in robot.joints if b.kind in ("vector", "circle") and b.nv == 1
        )
        self.actuated_names = tuple(
            b.name for b in robot.joints if b.kind in ("vector", "circle") and b.nv == 1
        )
        self.n_inertial = 10 * (model.njoints - 1)
        self.n_joint = len(self.actuated)
        names = [f"{b}.{s}" for b in self.bodies for s in SUFFIXES]
        law = robot.friction_law
        idx = list(self.actuated)
        self.smoothing = _per_joint(
            "smoothing", law.smoothing[idx] if smoothing is None else smoothing, self.n_joint
        )
        default_st = np.where(law.stribeck_velocity[idx] > 0, law.stribeck_velocity[idx], 0.0)
        if self.friction_law == "stribeck":
            default_st = np.where(default_st > 0, default_st, STRIBECK_VELOCITY)
        self.stribeck_velocity = _per_joint(
            "stribeck_velocity",
            default_st if stribeck_velocity is None else stribeck_velocity,
            self.n_joint,
            positive=self.friction_law == "stribeck",
        )
        # the friction columns' groups: (term, v_s, v_st) per actuated joint (the search of
        # identify() widens them: search_smoothing)
        self._groups = [(t, self.smoothing, self.stribeck_velocity) for t in self.friction_terms]
        for term in self.friction_terms:
            names += [f"{j}.{term}" for j in self.actuated_names]
        if self.armature:
            names += [f"{j}.armature" for j in self.actuated_names]
        if self.offset:
            names += [f"{j}.offset" for j in self.actuated_names]
        self.names: tuple[str, ...] = tuple(names)
        self._select = np.zeros((model.nv, self.n_joint))
        self._select[list(self.actuated), range(self.n_joint)] = 1.0
        # the armature taken as known (moved to the torque side): all of it, or, when it is
        # identified, that of the coordinates without a column (a free-flyer's)
        self._known_armature = np.array(model.armature, dtype=float)
        if self.armature:
            self._known_armature[list(self.actuated)] = 0.0
        self._weight_robot: Robot | None = None

    def _inertia_weight(self, mass: Vector) -> Vector:
        """``M⁻¹``, or with channels :attr:`excluded`, ``(M_KK)⁻¹`` on the kept coordinates
        ``K`` and zero rows for the others: the acceleration of the kept joints with the
        excluded ones held (their torques, unknown, then enter no row)."""
        if not self.excluded.size:
            return np.linalg.inv(mass)
        kept = np.setdiff1d(np.arange(mass.shape[0]), self.excluded)
        out = np.zeros_like(mass)
        out[np.ix_(kept, kept)] = np.linalg.inv(mass[np.ix_(kept, kept)])
        return out

    def armature_floor(self) -> Vector:
        """Per actuated joint, :data:`PRIOR_ARMATURE_FLOOR` of the largest nominal ``M̄ⱼⱼ``
        (neutral configuration) among the actuated joints of its kind: revolute ones
        [kg·m²] or prismatic ones [kg] (TIAGo's torso, 19 kg, is no scale for its wrist)."""
        model = self.robot.model
        m_bar = np.diag(self.robot.mass_matrix(self.robot.neutral()))[list(self.actuated)]
        prismatic = np.array(
            [
                model.joints[model.getJointId(n)].shortname().startswith("JointModelP")
                for n in self.actuated_names
            ],
            dtype=bool,
        )
        out = np.empty(self.n_joint)
        for kind in (True, False):
            if np.any(prismatic == kind):
                out[prismatic == kind] = PRIOR_ARMATURE_FLOOR * float(
                    m_bar[prismatic == kind].max()
                )
        return out

    @property
    def weight_robot(self) -> Robot:
        """The model whose ``M(q)⁻¹`` weights the rows: the nominal one, its armature raised
        by :meth:`armature_floor` on every actuated joint when the armature is identified (module docstring: a rotor unknown to the nominal model
        would otherwise be weighed by its link's inertia alone)."""
        if self._weight_robot is None:
            robot = self.robot
            if self.armature and self.n_joint:
                model = robot.model.copy()
                armature = np.array(model.armature, dtype=float)
                armature[list(self.actuated)] += self.armature_floor()
                model.armature = armature
                robot = robot.with_model(model)
            self._weight_robot = robot
        return self._weight_robot

    @property
    def armature_slice(self) -> slice:
        """Where the armature columns are in ``θ`` (empty when not identified)."""
        start = self.n_inertial + len(self.friction_terms) * self.n_joint
        return slice(start, start + (self.n_joint if self.armature else 0))

    @property
    def size(self) -> int:
        """Number of parameters."""
        return len(self.names)

    # -------------------------------------------------------------- values
    def nominal(self) -> Vector:
        """``θ₀``: the robot's inertials, its friction (if on), its armature and a zero offset."""
        model = self.robot.model
        parts = [model.inertias[i].toDynamicParameters() for i in range(1, model.njoints)]
        law, idx = self.robot.friction_law, list(self.actuated)  # (zero when friction is off)
        mean_c = 0.5 * (law.coulomb_pos + law.coulomb_neg)
        static = np.where(law.stribeck_velocity > 0, law.static, mean_c)  # F_s = F_c: Coulomb
        prior_mean = {
            "damping": law.viscous,
            "coulomb": mean_c,
            "coulomb_pos": law.coulomb_pos,
            "coulomb_neg": law.coulomb_neg,
            "static": static,
            "friction_offset": law.offset,
        }
        parts += [np.asarray(prior_mean[term])[idx] for term in self.friction_terms]
        if self.armature:
            parts.append(np.asarray(model.armature)[list(self.actuated)])
        if self.offset:
            parts.append(np.zeros(self.n_joint))
        return np.concatenate(parts)

    def prior_std(self) -> Vector:
        """Prior standard deviations ``s`` (module constants; each body's own mass and size scale)."""
        model = self.robot.model
        parts: list[Vector] = []
        for i in range(1, model.njoints):
            inertia = model.inertias[i]
            m = max(float(inertia.mass), 1e-3)
            lever = float(np.linalg.norm(inertia.lever))
            rot = float(np.trace(inertia.inertia)) / 2.0
            length = max(lever, math.sqrt(max(rot, 1e-9) / m), 0.02)
            scale = np.array([m, *(3 * [m * length]), *(6 * [m * length**2])])
            parts.append(PRIOR_INERTIA * scale)
        if self.friction or self.offset or self.armature:
            idx = list(self.actuated)
            m_nom = np.diag(self.robot.mass_matrix(self.robot.neutral()))[idx]
            # friction and offset as accelerations of the inertia the weights assume (the
            # armature's floor added when it is identified: a wrist's rotor is not held to its
            # link's scale, nor is its friction)
            wr = self.weight_robot
            m_bar = np.maximum(np.diag(wr.mass_matrix(wr.neutral()))[idx], 1e-6)
            prior = {"damping": PRIOR_DAMPING, "friction_offset": PRIOR_OFFSET}
            for term in self.friction_terms:
                parts.append(prior.get(term, PRIOR_COULOMB) * m_bar)
            if self.armature:
                floor = self.armature_floor()
                parts.append(np.maximum(PRIOR_ARMATURE * np.maximum(m_nom, 1e-6), floor))
            if self.offset:
                parts.append(PRIOR_OFFSET * m_bar)
        return np.concatenate(parts)

    def with_parameters(self, theta: ArrayLike, *, name: str | None = None) -> Robot:
        """A copy of the robot carrying ``θ`` (inertials, armature; friction switched on if
        identified).

        The offset is not part of a :class:`Robot` (it belongs to the torque
        sensor); read it from the parameters.
        """
        theta = np.asarray(theta, dtype=float)
        if theta.shape != (self.size,):
            raise DimensionError(f"θ must have shape ({self.size},), got {theta.shape}")
        model = self.robot.model.copy()
        for k, i in enumerate(range(1, model.njoints)):
            pi = theta[10 * k : 10 * k + 10]
            model.inertias[i] = pin.Inertia.FromDynamicParameters(pi)
        friction, law = self.robot.friction, None
        if self.friction:
            law = self.friction_model(theta)
            # the tags keep F_v and the mean Coulomb level (a reader of the URDF alone)
            model.damping = np.array(law.viscous)
            model.friction = 0.5 * (law.coulomb_pos + law.coulomb_neg)
            friction = True
            if self.friction_law == "viscous-coulomb" and law.is_urdf:
                law = None  # the tags say it all (as before friction laws)
        if self.armature:
            armature = np.array(model.armature, dtype=float)
            armature[list(self.actuated)] = theta[self.armature_slice]
            model.armature = armature
        # same geometry, shared and never loaded here (with_model)
        return self.robot.with_model(
            model, name=name or f"{self.robot.name}*", friction=friction, friction_law=law
        )

    def friction_model(self, theta: Vector) -> FrictionLaw:
        """The robot's friction law with the actuated joints' replaced by ``θ``'s
        (:mod:`pinobs.model.friction`; this regressor's ``v_s``, ``v_st``)."""
        base = self.robot.friction_law  # zero when the robot's friction is off
        values = {
            k: np.array(getattr(base, k), dtype=float)
            for k in ("viscous", "coulomb_pos", "coulomb_neg", "static", "offset")
        }
        smoothing = np.array(base.smoothing, dtype=float)
        stribeck = np.array(base.stribeck_velocity, dtype=float)
        idx = list(self.actuated)
        smoothing[idx], stribeck[idx] = self.smoothing, self.stribeck_velocity
        values["static"][idx] = values["offset"][idx] = 0.0  # (the law's own terms only)
        if self.friction_law != "stribeck":
            stribeck[idx] = 0.0
        n0, n = self.n_inertial, self.n_joint
        for k, term in enumerate(self.friction_terms):
            x = theta[n0 + k * n : n0 + (k + 1) * n]
            if term == "coulomb":
                values["coulomb_pos"][idx] = values["coulomb_neg"][idx] = x
            else:
                key = {"damping": "viscous", "friction_offset": "offset"}.get(term, term)
                values[key][idx] = x
        return FrictionLaw(
            **values,
            smoothing=smoothing,
            stribeck_velocity=stribeck,
            law=self.friction_law or "viscous-coulomb",
        )

    def offsets(self, theta: Vector) -> Vector:
        """The torque offset ``b`` per velocity coordinate (zero where none is identified)."""
        out = np.zeros(self.robot.nv)
        if self.offset and self.n_joint:
            out[list(self.actuated)] = theta[len(theta) - self.n_joint :]
        return out

    # ---------------------------------------------------------------- rows
    def momentum(self, q: Vector, v: Vector) -> Vector:
        """``Y_M(q, v)`` with ``Y_M π = M(q) v``, shape ``(nv, n_inertial)``."""
        return np.array(
            pin.computeJointTorqueRegressor(self._free, self._free_data, q, self._zero, v)
        )

    def drift(self, q: Vector, v: Vector) -> Vector:
        """``Y_G(q, v)`` with ``Y_G π = C(q, v)ᵀ v − g(q)`` (module docstring), shape ``(nv, n_inertial)``."""
        eps = IDENTIFICATION_FD_STEP
        model = self._model
        plus = self.momentum(pin.integrate(model, q, eps * v), v)
        minus = self.momentum(pin.integrate(model, q, -eps * v), v)
        cg = pin.computeJointTorqueRegressor(model, self._data, q, v, self._zero)
        return (plus - minus) / (2.0 * eps) - cg

    def system(
        self,
        t: Vector,
        q: Vector,
        v: Vector,
        tau: Vector,
        *,
        window: int,
        stride: int = 1,
        weight_robot: Robot | None = None,
        torque: str = "held",
    ) -> tuple[Vector, Vector]:
        """The weighted rows ``(A, y)`` of consecutive windows of ``window`` periods.

        Args:
            t, q, v, tau: one contiguous stretch of samples: ``(N,)``, ``(N, nq)``,
                ``(N, nv)``, ``(N, nv)`` (``tau[k]`` held from ``t[k]`` to ``t[k+1]``).
                Its intervals may be uneven: dropped samples and irregular sampling
                (:mod:`pinobs.model.sampling`) are integrated over their true times.
            window: periods per window (a multiple of ``stride``; the period ``h`` is the
                median interval: a window spans ``window·h`` seconds, from the first row
                at or after its start, and ends on the first row at or after
                ``window·h`` later, less half a period; on a uniform log, ``window`` rows).
            stride: quadrature step of the regressor integrals, in periods (the drift
                is evaluated on the first row at or after each ``stride·h``).
            weight_robot: the model whose ``M⁻¹`` weights the rows (default: the nominal one).
            torque: ``"held"`` (``tau[k]`` held from ``t[k]`` to ``t[k+1]``, as
                ``pinobs.simulate`` and a drive fed commanded torques do; a missing sample's
                torque on the line between its neighbours:
                :func:`~pinobs.model.sampling.held_torque_integral`) or
                ``"sampled"`` (the torque at the instants, integrated by trapezoid: an
                excitation's or a torque sensor's).
        """
        _check_torque(torque)
        nodes, bounds = _window_nodes(t, window, stride)
        n_win = len(bounds) - 1
        if n_win < 1:
            return np.zeros((0, self.size)), np.zeros(0)
        wr = weight_robot or self.weight_robot
        nv = self.robot.nv
        rows, rhs = [], []
        # ∫τ dt as the torque was sampled (module docstring); friction integrals by
        # trapezoid at full rate
        if torque == "held":
            tau_int = held_torque_integral(t, tau)
        else:
            tau_int = _cumtrapz(tau, t)
        vf = v[:, list(self.actuated)]
        # friction columns: ∫ φ(v) dt of each group's term (pinobs.model.friction), the
        # groups' columns on their joints' rows
        trap_f = (
            _cumtrapz(
                np.hstack([friction_basis(term, vf, vs, vst) for term, vs, vst in self._groups]),
                t,
            )
            if self._groups
            else np.zeros((t.shape[0], 0))
        )
        select_f = np.tile(self._select, len(self._groups))
        ym_prev = self.momentum(q[0], v[0])
        g_prev = self.drift(q[0], v[0])
        for w in range(n_win):
            j0, j1 = bounds[w], bounds[w + 1]
            k0, k1 = int(nodes[j0]), int(nodes[j1])
            acc = np.zeros((nv, self.n_inertial))
            g_a = g_prev
            k_prev = k0
            for k in nodes[j0 + 1 : j1 + 1]:
                g_b = self.drift(q[k], v[k])
                acc += 0.5 * (t[k] - t[k_prev]) * (g_a + g_b)
                g_a, k_prev = g_b, int(k)
            g_prev = g_a
            ym = self.momentum(q[k1], v[k1])
            block = [ym - ym_prev - acc]
            ym_prev = ym
            if self._groups:
                block.append(select_f * (trap_f[k1] - trap_f[k0]))
            if self.armature:  # diag(I_a) (v₂ − v₁): the rotors' momentum
                block.append(self._select * (vf[k1] - vf[k0]))
            if self.offset:
                block.append(-self._select * (t[k1] - t[k0]))
            a = np.hstack(block)
            b = tau_int[k1] - tau_int[k0] - self._known_armature * (v[k1] - v[k0])
            if self.weighting == "torque":  # the window's mean torque [N·m, N]
                rows.append(a / (t[k1] - t[k0]))
                rhs.append(b / (t[k1] - t[k0]))
                continue
            # weight: M₀(q_mid)⁻¹ / (t₂ − t₁) (MATH §9), q_mid the row nearest the middle time
            mid = (k0 + k1) // 2
            if k1 - k0 != window:
                mid = k0 + int(np.argmin(np.abs(t[k0 : k1 + 1] - 0.5 * (t[k0] + t[k1]))))
            weight = self._inertia_weight(wr.mass_matrix(q[mid])) / (t[k1] - t[k0])
            rows.append(weight @ a)
            rhs.append(weight @ b)
        return np.vstack(rows), np.concatenate(rhs)

    def window_ends(self, t: Vector, window: int, stride: int = 1) -> list[float]:
        """The end times [s] of the windows :meth:`system` makes of ``t``."""
        nodes, bounds = _window_nodes(t, window, stride)
        return [float(t[nodes[j]]) for j in bounds[1:]]


def _window_nodes(t: Vector, window: int, stride: int) -> tuple[NDArray[np.intp], list[int]]:
    """The quadrature rows of :meth:`MomentumRegressor.system` and, as positions among them,
    its windows' bounds.

    Node ``j`` is the first row at or after ``t₀ + j·stride·h − h/2`` (``h`` the median
    interval), duplicates (a gap longer than a stride) merged; window ``w`` runs from node
    ``w·window/stride`` to the next such one.  On a uniform log the nodes are every
    ``stride``-th row and the windows every ``window`` rows, exactly.
    """
    n = t.shape[0]
    if n < 2:
        return np.zeros(1, dtype=np.intp), [0]
    h = float(np.median(np.diff(t)))
    per = max(1, window // stride)
    count = int((t[-1] - t[0]) / (stride * h)) + 2
    targets = t[0] + np.arange(count) * (stride * h) - 0.5 * h
    targets[0] = t[0]
    raw = np.searchsorted(t, targets, side="left")
    raw = raw[raw < n]
    n_win = (raw.size - 1) // per
    raw = raw[: n_win * per + 1]
    nodes = np.unique(raw)
    # a window's bound is its first raw node's row: its place among the unique nodes
    bound_rows = raw[::per]
    bounds = np.searchsorted(nodes, bound_rows).tolist()
    # windows emptied by a gap longer than a window are merged into the next
    kept = [bounds[0]]
    for b in bounds[1:]:
        if b > kept[-1]:
            kept.append(b)
    return nodes.astype(np.intp), kept


#: How a log's torques were sampled (:meth:`MomentumRegressor.system`).
TORQUE_SAMPLING = ("held", "sampled")

#: How a window's rows are weighted (:class:`MomentumRegressor`, :func:`identify`).
WEIGHTINGS = ("torque", "inertia")


def _check_weighting(weighting: object) -> None:
    if weighting not in WEIGHTINGS:
        raise OptionError(
            f"weighting={weighting!r}: give 'torque' (each torque channel by its own residual "
            "scale in N·m) or 'inertia' (rows by M⁻¹, acceleration-like)"
        )


def _check_torque(torque: object) -> None:
    if torque not in TORQUE_SAMPLING:
        raise OptionError(
            f"torque={torque!r}: give 'held' (zero-order hold, pinobs.simulate's) or "
            "'sampled' (the torque at the sample instants, an excitation's or a sensor's)"
        )


def _cumtrapz(y: Vector, t: Vector) -> Vector:
    out = np.zeros_like(y)
    out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t)[:, None], axis=0)
    return out


def _body_name(model: pin.Model, joint: int) -> str:
    """The name of the body a joint carries (its first BODY frame), else the joint's name."""
    for frame in model.frames:
        if frame.type == pin.FrameType.BODY and frame.parentJoint == joint:
            return str(frame.name)
    return str(model.names[joint])


# ---------------------------------------------------------------- velocities
def smooth_path(
    robot: Robot,
    t: Vector,
    q: Vector,
    *,
    half_window: int,
    order: int = 4,
    edges: bool = True,
) -> tuple[Vector, Vector]:
    """Zero-phase Savitzky–Golay estimates ``(q_s, v)`` of a sampled path.

    The path is developed into the tangent space, ``u_k = u_{k−1} + difference(q_{k−1}, q_k)``
    (for vector joints ``u = q − q₀``); ``u`` is fitted by a polynomial of
    degree ``order`` over ``2·half_window + 1`` samples around each one
    (``scipy.signal.savgol_filter``), giving ``v = u̇`` and
    ``q_s = q_k ⊕ (û_k − u_k)``.  Near the ends the fit is the edge polynomial;
    ``edges=False`` skips those fits (the first and last ``half_window`` samples are
    then not meaningful, the others are the same: the online learner keeps only them).

    Off a uniform grid (dropped samples, irregular sampling: an interval more than
    :data:`~pinobs.model.sampling.UNIFORM_TOL` off the median ``h``) the same fit is made in
    real time (:func:`_local_polynomial`): over the rows within ``(half_window + ½)·h`` of
    each one (near the ends, of the time ``half_window·h`` from the end), as
    ``savgol_filter`` fits the rows of a uniform grid; ``edges`` is then ignored.
    """
    from scipy.signal import savgol_filter  # lazily: import pinobs stays light

    n = t.shape[0]
    length = 2 * half_window + 1
    h = float(np.median(np.diff(t))) if n > 1 else math.nan
    uniform = is_uniform(t, h)
    if n < length and (uniform or n <= order or t[-1] - t[0] < (length - 1.5) * h):
        raise IdentificationError(
            f"{n} samples are too few to smooth over {length}; give a longer log"
        )
    if robot.is_vector_space:
        u = q - q[0]
    else:
        steps = np.array([robot.difference(q[k - 1], q[k]) for k in range(1, n)])
        u = np.concatenate([np.zeros((1, robot.nv)), np.cumsum(steps, axis=0)])
    order = min(order, length - 1)
    if not uniform:
        u_s, v = _local_polynomial(t, u, half_window * h, order, 0.5 * h)
    elif edges:
        v = savgol_filter(u, length, order, deriv=1, delta=h, axis=0, mode="interp")
        u_s = savgol_filter(u, length, order, axis=0, mode="interp")
    else:  # savgol_filter's convolutions, their coefficients computed once
        from scipy.ndimage import convolve1d  # lazily: import pinobs stays light

        c_v, c_u = _savgol_coefficients(length, order, h)
        v = convolve1d(u, c_v, axis=0, mode="nearest")
        u_s = convolve1d(u, c_u, axis=0, mode="nearest")
    if robot.is_vector_space:
        return q[0] + u_s, v
    q_s = np.array([robot.integrate(q[k], u_s[k] - u[k]) for k in range(n)])
    return q_s, v


def _local_polynomial(
    t: Vector, u: Vector, reach: float, order: int, slack: float
) -> tuple[Vector, Vector]:
    """``(û, u̇)`` at every row: the least-squares polynomial of degree ``order`` in time
    through the rows within ``reach + slack`` [s] of the row (near the ends, of the point
    ``reach`` from the end), and its derivative: the Savitzky–Golay fit on uneven times.
    The degree is lowered to fit the window with the fewest rows."""
    n = t.shape[0]
    radius = reach + slack
    centre = np.clip(t, t[0] + reach, t[-1] - reach)
    lo = np.searchsorted(t, centre - radius, side="left")
    hi = np.searchsorted(t, centre + radius, side="right")
    span = int(np.max(hi - lo))
    fewest = int(np.min(hi - lo))
    if fewest < 2:
        raise IdentificationError(
            f"a gap in the log leaves a row alone within ±{radius:.3g} s: no slope to fit there "
            "(give a longer half window, or split the log at the gap)"
        )
    order = min(order, fewest - 1)  # a window the drops left with few rows: a lower degree
    u_s = np.empty_like(u)
    v = np.empty_like(u)
    for a in range(0, n, 512):  # in blocks: (rows, span, order + 1) per block
        k = np.arange(a, min(a + 512, n))
        idx = lo[k, None] + np.arange(span)[None, :]
        inside = idx < hi[k, None]
        idx = np.minimum(idx, n - 1)
        x = (t[idx] - t[k, None]) / radius  # scaled to [-2, 2]: a well-conditioned Gram matrix
        design = np.cumprod(np.broadcast_to(x[..., None], (*x.shape, order + 1)), axis=2)
        design = np.concatenate([np.ones((*x.shape, 1)), design[..., :order]], axis=2)
        design *= inside[..., None]
        design_t = design.transpose(0, 2, 1)
        gram = design_t @ design
        rhs = design_t @ u[idx]
        fit = np.linalg.solve(gram, rhs)  # the coefficients; the first two: value and slope
        u_s[k], v[k] = fit[:, 0], fit[:, 1] / radius
    return u_s, v


@functools.lru_cache(maxsize=16)
def _savgol_coefficients(length: int, order: int, h: float) -> tuple[Vector, Vector]:
    """Savitzky–Golay convolution coefficients of ``u̇`` and ``u`` (:func:`smooth_path`)."""
    from scipy.signal import savgol_coeffs  # lazily: import pinobs stays light

    c_v = savgol_coeffs(length, order, deriv=1, delta=h)
    c_u = savgol_coeffs(length, order)
    c_v.setflags(write=False)
    c_u.setflags(write=False)
    return c_v, c_u


# --------------------------------------------------------------------- solve
@dataclass(frozen=True)
class Solution:
    """The result of :func:`solve`.

    Attributes:
        theta: the parameters (physically consistent).
        std: posterior standard deviations.
        excited: per parameter, whether the data fixed it (posterior std < ½ prior std), booleans.
        rank: number of identifiable combinations (pivoted QR).
        base: names of the pivot columns, one per identifiable combination.
        condition: condition number of the prior-scaled regressor on those columns.
        sigma: robust residual scale of the weighted rows [rad/s²-like, or N·m with
            channels: the median row's].
        projected: whether physical consistency moved the linear solution.
        n_rows: rows used.
        channel_sigma: per channel (:func:`solve`'s ``channel``, in increasing order), its
            residual scale; one value (``sigma``) without channels.
    """

    theta: Vector
    std: Vector
    excited: NDArray[np.bool_]
    rank: int
    base: tuple[str, ...]
    condition: float
    sigma: float
    projected: bool
    n_rows: int
    precision: Vector = field(repr=False, default_factory=lambda: np.zeros((0, 0)))
    channel_sigma: Vector = field(repr=False, default_factory=lambda: np.zeros(0))


def solve(
    reg: MomentumRegressor | PayloadRegressor,
    A: Vector,
    y: Vector,
    *,
    theta0: Vector | None = None,
    prior_std: Vector | None = None,
    irls: int = 4,
    huber: float = 1.345,
    consistent: bool = True,
    channel: NDArray[np.intp] | None = None,
) -> Solution:
    """Regularised, robust least squares for ``A θ ≈ y`` (module docstring).

    Minimises ``Σᵢ ρ(rᵢ/σ) + ½|(θ − θ₀)/s|²`` with ``r = Aθ − y``, ``ρ`` Huber's
    loss (iteratively re-weighted) and σ re-estimated from the residuals'
    median absolute deviation at each pass; then enforces physical
    consistency (``consistent=False`` skips that last step: the online
    observer checks ``M(q) ≻ 0`` instead, which costs a thousandth).

    ``channel``: per row, the torque channel it belongs to (``(n_rows,)`` integers); each
    channel then has its own σ (``σ_c = 1.4826 · median |r_i|`` over its rows, at least
    :data:`CHANNEL_SIGMA_FLOOR` of the largest), re-estimated at each pass: rows of
    torques in N·m weighted by their own noise (module docstring, "Weighting").  ``None``:
    one σ for all rows (rows made commensurable by their weights beforehand).

    Raises:
        IdentificationError: no rows, or nothing identifiable.
    """
    if A.shape[0] == 0:
        raise IdentificationError("no complete window of data: the log is too short")
    # small dense problems: one BLAS thread is 4x faster than two fighting over a busy machine
    with _blas_controller().limit(limits=1):
        return _solve(reg, A, y, theta0, prior_std, irls, huber, consistent, channel)


@functools.cache
def _blas_controller() -> Any:
    """threadpoolctl's view of the loaded BLAS libraries, scanned once (a scan costs about
    2 ms, which the online learner would pay at every solve)."""
    import scipy.linalg  # noqa: F401  (its BLAS loaded before the scan)
    from threadpoolctl import ThreadpoolController  # lazily: import pinobs stays light

    return ThreadpoolController()


def _solve(
    reg: MomentumRegressor | PayloadRegressor,
    A: Vector,
    y: Vector,
    theta0: Vector | None,
    prior_std: Vector | None,
    irls: int,
    huber: float,
    consistent: bool,
    channel: NDArray[np.intp] | None = None,
) -> Solution:
    theta0 = reg.nominal() if theta0 is None else theta0
    s = reg.prior_std() if prior_std is None else prior_std
    As = A * s  # columns in prior units: u = (θ − θ₀)/s
    r0 = y - A @ theta0
    from scipy.linalg import qr  # lazily: import pinobs stays light

    if not np.any(As):
        raise IdentificationError("the regressor is zero: the log never moves the robot")
    # first pass: σ from an almost unregularised fit
    u = np.linalg.lstsq(As, r0, rcond=None)[0]
    sig = _row_sigma(As @ u - r0, channel)
    # identifiable combinations: pivoted QR of the prior-scaled rows, each over its σ (one
    # scalar without channels: the rank and condition number are those of As)
    _, R, piv = qr(As / sig[:, None], mode="economic", pivoting=True)
    diag = np.abs(np.diag(R))
    if diag.size == 0 or diag[0] == 0.0:
        raise IdentificationError("the regressor is zero: the log never moves the robot")
    rank = int(np.sum(diag > 1e-8 * diag[0]))
    base = tuple(reg.names[i] for i in piv[:rank])
    sv = np.linalg.svd((As / sig[:, None])[:, piv[:rank]], compute_uv=False)
    condition = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    w = np.ones(A.shape[0])
    eye = np.eye(reg.size)
    prec_u = eye
    for it in range(irls + 1):
        res = As @ u - r0
        sig = _row_sigma(res, channel)
        sigma = float(np.median(sig))
        z = np.abs(res) / sig
        w = np.where(z <= huber, 1.0, huber / np.maximum(z, 1e-300))
        Aw = As * (w / sig**2)[:, None]
        prec_u = Aw.T @ As + eye  # posterior precision in u-units (≥ I)
        prec_u = 0.5 * (prec_u + prec_u.T)
        lam, vec = np.linalg.eigh(prec_u)  # by eigenvalues: huge row weights make it stiff
        lam = np.maximum(lam, 1.0)
        if it < irls:
            u = vec @ ((vec.T @ (Aw.T @ r0)) / lam)
    cov_u = (vec / lam) @ vec.T
    std = s * np.sqrt(np.diag(cov_u))
    theta = theta0 + s * u
    theta_c = _consistent(reg, theta, prec_u, s) if consistent else theta
    projected = not np.array_equal(theta_c, theta)
    return Solution(
        theta=theta_c,
        std=std,
        excited=std < 0.5 * s,
        rank=rank,
        base=base,
        condition=condition,
        sigma=sigma,
        projected=projected,
        n_rows=int(A.shape[0]),
        precision=prec_u / np.outer(s, s),
        channel_sigma=_channel_sigma(res, channel),
    )


#: A channel's residual scale is taken as at least this share of the largest channel's
#: (:func:`solve`): a channel fitted to rounding (a noise-free simulation) would otherwise
#: outweigh the others by 1e10.
CHANNEL_SIGMA_FLOOR = 1e-6


def _channel_sigma(res: Vector, channel: NDArray[np.intp] | None) -> Vector:
    """Per channel (in the order of ``np.unique(channel)``), ``1.4826 · median |r|`` over its
    rows, at least :data:`CHANNEL_SIGMA_FLOOR` of the largest; one value without channels."""
    if channel is None:
        return np.array([max(1.4826 * float(np.median(np.abs(res))), 1e-300)])
    labels = np.unique(channel)
    out = np.array([1.4826 * float(np.median(np.abs(res[channel == c]))) for c in labels])
    return np.maximum(out, max(CHANNEL_SIGMA_FLOOR * float(out.max()), 1e-300))


def _row_sigma(res: Vector, channel: NDArray[np.intp] | None) -> Vector:
    """Per row, the σ of its channel (:func:`_channel_sigma`)."""
    per = _channel_sigma(res, channel)
    if channel is None:
        return np.full(res.shape, per[0])
    return per[np.searchsorted(np.unique(channel), channel)]


def _is_consistent(reg: MomentumRegressor | PayloadRegressor, theta: Vector) -> bool:
    for k in range(reg.n_inertial // 10):
        J = pseudo_inertia(theta[10 * k : 10 * k + 10])
        if np.linalg.eigvalsh(J)[0] < 0.0 or J[3, 3] <= 0:
            return False
    if np.any(theta[_nonnegative(reg)] < 0):
        return False
    return True


def _nonnegative(reg: MomentumRegressor | PayloadRegressor) -> NDArray[np.intp]:
    """The indices of ``θ`` that must not be negative: friction (not its offset, which does not
    dissipate: :mod:`pinobs.model.friction`) and armature."""
    n0, n = reg.n_inertial, reg.n_joint
    friction = np.concatenate(
        [
            np.arange(n0 + k * n, n0 + (k + 1) * n)
            for k, term in enumerate(reg.friction_terms)
            if term != "friction_offset"
        ]
        or [np.zeros(0, dtype=np.intp)]
    )
    arm = reg.armature_slice
    return np.concatenate([friction, np.arange(arm.start, arm.stop)]).astype(np.intp)


def _pseudo_inertia_basis() -> Vector:
    """``E_i = ∂J/∂π_i`` (10 × 4 × 4) of :func:`pseudo_inertia`, which is linear."""
    return np.array([pseudo_inertia(e) for e in np.eye(10)])


_E = _pseudo_inertia_basis()


def _consistent(
    reg: MomentumRegressor | PayloadRegressor, theta: Vector, prec_u: Vector, s: Vector
) -> Vector:
    """The closest physically consistent ``θ`` in the posterior metric (module docstring).

    ``min_u (u − û)ᵀ Λ (u − û)`` over ``u = (θ − θ₀)/s`` subject to every
    body's ``J(θ) ⪰ 0`` and friction and armature ``≥ 0``: a convex problem (``J`` is
    linear in ``θ``), solved by a log-barrier interior-point method (Boyd &
    Vandenberghe, *Convex Optimization*, 2004, §11.3): Newton steps on
    ``(u − û)ᵀΛ(u − û) − μ (Σ_k log det J_k + Σ_j log f_j)`` (``f``: friction and
    armature) for μ = 1, 0.1, …,
    :data:`MU_END` (``Λ`` scaled to a unit largest eigenvalue; each centring stops
    when the Newton decrement is below ``μ/100``), from a strictly feasible start
    (the nominal model, nudged inside).  Newton steps by a full solve: a
    least-squares solve's cut-off at ``1e-16·λ_max`` dropped the weakly seen
    directions, which are the ones consistency moves, and left the solution
    100–10⁴× off the optimum on a noise-free log (UR5, residual 1.7 against
    4.4e-5).
    """
    if _is_consistent(reg, theta):
        return theta
    theta0 = reg.nominal()
    nb = reg.n_inertial // 10
    fr = _nonnegative(reg)
    u_hat = (theta - theta0) / s
    # strictly feasible start: each nominal J nudged inside, friction and armature positive
    start = theta0.copy()
    for k in range(nb):
        J0 = pseudo_inertia(theta0[10 * k : 10 * k + 10])
        eps = 1e-6 * max(float(np.max(np.abs(J0))), 1e-9)
        lam_min = float(np.linalg.eigvalsh(J0)[0])
        start[10 * k : 10 * k + 10] = _from_pseudo_inertia(
            J0 + (max(0.0, -lam_min) + eps) * np.eye(4)
        )
    start[fr] = np.maximum(theta0[fr], 0.0) + 1e-6 * s[fr]
    u = (start - theta0) / s
    # the metric scaled to a unit largest eigenvalue, so that μ and the stopping rule are
    # relative: the precision of a nearly noise-free log reaches 1e15 (measured, UR5)
    prec_u = prec_u / float(np.linalg.eigvalsh(prec_u)[-1])
    E = [_E * s[10 * k : 10 * k + 10, None, None] for k in range(nb)]  # ∂J_k/∂u

    def barrier(u: Vector) -> tuple[float, Vector, Vector] | None:
        th = theta0 + s * u
        val, grad, hess = 0.0, np.zeros(u.size), np.zeros((u.size, u.size))
        for k in range(nb):
            J = pseudo_inertia(th[10 * k : 10 * k + 10])
            try:
                c = np.linalg.cholesky(J)
            except np.linalg.LinAlgError:
                return None
            val -= 2.0 * float(np.sum(np.log(np.diag(c))))
            Ji = np.linalg.inv(c).T @ np.linalg.inv(c)  # J⁻¹ from the factor (J ≻ 0 here)
            JE = np.einsum("ab,ibc->iac", Ji, E[k])  # J⁻¹ E_i
            sl = slice(10 * k, 10 * k + 10)
            grad[sl] -= np.einsum("iaa->i", JE)  # −tr(J⁻¹E_i)
            hess[sl, sl] += np.einsum("iab,jba->ij", JE, JE)  # tr(J⁻¹E_i J⁻¹E_j)
        if fr.size:
            f = th[fr]
            if np.any(f <= 0):
                return None
            val -= float(np.sum(np.log(f)))
            grad[fr] -= s[fr] / f
            hess[fr, fr] += (s[fr] / f) ** 2
        return val, grad, hess

    def objective(u: Vector, mu: float) -> float | None:
        b = barrier(u)
        if b is None:
            return None
        d = u - u_hat
        return float(d @ prec_u @ d) + mu * b[0]

    mu = 1.0
    while mu >= MU_END:
        for _ in range(50):
            b = barrier(u)
            assert b is not None  # u stays strictly feasible by the line search
            d = u - u_hat
            grad = 2.0 * prec_u @ d + mu * b[1]
            hess = 2.0 * prec_u + mu * b[2]
            try:  # not lstsq: its cut-off would drop the weak directions consistency must move
                step = -np.linalg.solve(hess, grad)
            except np.linalg.LinAlgError:
                step = -np.linalg.lstsq(hess, grad, rcond=None)[0]
            decrement = float(-grad @ step)
            if not decrement >= 1e-2 * mu:  # centred (or a non-finite step: keep u)
                break
            f0 = objective(u, mu)
            assert f0 is not None
            a = 1.0
            while a > 1e-12:
                f1 = objective(u + a * step, mu)
                if f1 is not None and f1 <= f0 - 0.25 * a * decrement:
                    break
                a *= 0.5
            else:
                break
            u = u + a * step
        mu *= 0.1
    return theta0 + s * u


# ------------------------------------------------------------------ offline
@dataclass(frozen=True)
class Identification:
    """What :func:`identify` learned from a log.

    Attributes:
        robot: the calibrated :class:`Robot` (identified inertials and armature, friction
            on when identified); the torque offset is not part of it.
        parameters: every parameter with its standard deviation.
        offset: the identified torque offset per velocity coordinate [N·m].
        report: fit diagnostics (see :func:`identify`).
        regressor: the :class:`MomentumRegressor` used (its ``names`` order).
    """

    robot: Robot
    parameters: ParameterSet
    offset: Vector
    report: dict[str, Any]
    regressor: MomentumRegressor = field(repr=False)

    def save(self, path: str) -> str:
        """Write the calibrated robot as a URDF, its armature in a sidecar file beside it
        (:func:`pinobs.model.urdf_writer.write_urdf`); returns the URDF's path."""
        from pinobs.model.urdf_writer import write_urdf

        return write_urdf(self.robot, path)


def segments(t: Vector, q: Vector, tau: Vector) -> list[slice]:
    """Contiguous stretches of finite rows, of two rows or more, split where a row is not
    finite or an interval is longer than :data:`~pinobs.model.sampling.SPLIT_GAP_PERIODS`
    median intervals.

    Within a stretch the intervals are the log's own: dropped samples (an interval of a
    few periods) and irregular sampling are used as they are
    (:mod:`pinobs.model.sampling`).

    Raises:
        IdentificationError: the median interval is not positive (timestamps repeated).
    """
    good = np.isfinite(t) & np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(tau), axis=1)
    if good.sum() < 2:
        return []
    h = float(np.median(np.diff(t[good])))
    if not h > 0.0:
        raise IdentificationError(
            f"the log's median sample interval is {h:g} s: its timestamps repeat; give each "
            "sample its own time"
        )
    out, start = [], None
    for k in range(t.shape[0]):
        ok = bool(good[k]) and (
            start is None or (0.0 < t[k] - t[k - 1] <= SPLIT_GAP_PERIODS * h and bool(good[k - 1]))
        )
        if ok and start is None:
            start = k
        elif not ok:
            if start is not None:
                out.append(slice(start, k))
            start = k if good[k] else None
    if start is not None:
        out.append(slice(start, t.shape[0]))
    return [seg for seg in out if seg.stop - seg.start >= 2]


#: A given path's samples closer than this many half windows (of :func:`build_rows`) to
#: the end of its stretch are not used: a smoother started afresh on each stretch has not
#: converged there.  Measured (UR5, σ = 1e-4, RTS on the identified model, gaps of 20
#: rows): its velocity error is 30–130× the interior's at a stretch's first sample, 2–5× at
#: 20 samples, 1–2× at 50, 1× at 100 (two half windows at 1 kHz).
SETTLE_WINDOWS = 2


def _settled_runs(finite: NDArray[np.bool_], settle: int) -> list[slice]:
    """The runs of ``finite``, each without its first and last ``settle`` samples."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], finite.astype(np.int8), [0]])))
    out = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if b - a > 2 * settle + 1:
            out.append(slice(int(a) + settle, int(b) - settle))
    return out


def build_rows(
    reg: MomentumRegressor | PayloadRegressor,
    t: Vector,
    q: Vector,
    tau: Vector,
    *,
    window: float = 0.1,
    half_window: float = 0.05,
    quadrature: float = 0.002,
    path: tuple[Vector, Vector] | None = None,
    torque: str = "held",
) -> tuple[Vector, Vector, list[float]]:
    """Weighted rows of every contiguous stretch of a log, and the window end times.

    Args:
        window: window length [s].
        half_window: half-width of the Savitzky–Golay fit of :func:`smooth_path` [s].
        quadrature: longest trapezoid step of the regressor integrals [s].
        path: estimated ``(q, v)`` at every sample, ``(N, nq)`` and ``(N, nv)``
            (e.g. a model-based smoother's), used instead of :func:`smooth_path`
            on every stretch where it is finite, except within :data:`SETTLE_WINDOWS`
            half windows of its runs' ends (those rows are not used).
        torque: how the torques were sampled (:meth:`MomentumRegressor.system`).
    """
    As, ys, ends = [], [], []
    for seg in segments(t, q, tau):
        ts, qs, taus = t[seg], q[seg], tau[seg]
        h = float(np.median(np.diff(ts)))
        stride = max(1, round(quadrature / h))
        win = max(stride, round(window / h / stride) * stride)
        hw = max(2, round(half_window / h))
        if ts[-1] - ts[0] < (max(win, 2 * hw) - 0.5) * h:  # (uniform: fewer rows than that)
            continue
        given = None if path is None else np.all(np.isfinite(path[1][seg]), axis=1)
        if given is None or not given.any():  # no estimate given, or none for this stretch
            q_s, v = smooth_path(reg.robot, ts, qs, half_window=hw)
            parts = [(slice(0, ts.shape[0]), q_s, v)]
        else:
            assert path is not None
            parts = [
                (run, path[0][seg][run], path[1][seg][run])
                for run in _settled_runs(given, SETTLE_WINDOWS * hw)
            ]
        for run, q_s, v in parts:
            A, y = reg.system(ts[run], q_s, v, taus[run], window=win, stride=stride, torque=torque)
            As.append(A)
            ys.append(y)
            ends += reg.window_ends(ts[run], win, stride)
    if not As:
        return np.zeros((0, reg.size)), np.zeros(0), []
    return np.vstack(As), np.concatenate(ys), ends


def log_arrays(
    robot: Robot, log: Any, *, warn_filled: bool = True
) -> tuple[Vector, Vector, Vector]:
    """``(t, q, tau)`` of a log as :func:`identify` reads it, checked against ``robot``, short
    runs of NaN rows filled (:func:`fill_short_gaps`, with a :class:`PinobsWarning`;
    ``warn_filled=False`` leaves them).

    ``log``: a tuple ``(t, q, tau)``, or an object with ``t``, ``q``, ``tau``
    (a ``Log``); a simulation ``Result`` is read through its measured
    ``q_meas``, never its true ``q``.

    Raises:
        IdentificationError: no torques.
        DimensionError: shapes that do not fit ``robot``.
        TimestampError: finite times that repeat or step back.
    """
    if isinstance(log, (tuple, list)):
        if len(log) != 3:
            raise DimensionError(
                f"log is a sequence of {len(log)} arrays; identification needs (t, q, tau)"
            )
        t, q, tau = log
    elif isinstance(log, Mapping) and {"t", "q"} <= set(log):
        t, q, tau = log["t"], log["q"], log.get("tau")
    elif hasattr(log, "t") and hasattr(log, "q"):
        # a simulation Result carries the truth in q: identify from what was measured
        t, tau = log.t, getattr(log, "tau", None)
        q = log.q_meas if hasattr(log, "q_meas") else log.q
    else:
        read = (
            " (read a file with pinobs.io.read_log(path, robot))"
            if isinstance(log, (str, PathLike)) or hasattr(log, "columns")
            else ""
        )
        raise DimensionError(
            f"log is a {type(log).__name__}; give a pinobs.io.Log, a pinobs.Result, (t, q, tau) "
            f"arrays or a mapping with 't', 'q', 'tau'{read}"
        )
    if tau is None:
        raise IdentificationError("the log has no torques: identification needs tau columns")
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    tau = np.asarray(tau, dtype=float)
    if (
        t.ndim != 1
        or q.ndim != 2
        or q.shape != (t.shape[0], robot.nq)
        or tau.shape != (t.shape[0], robot.nv)
    ):
        raise DimensionError(
            f"log shapes t {t.shape}, q {q.shape}, tau {tau.shape} do not fit robot "
            f"{robot.name!r} (t (N,), q (N, nq = {robot.nq}), tau (N, nv = {robot.nv}))"
        )
    with np.errstate(invalid="ignore"):
        absurd = np.abs(tau) > robot.absurd_torque
    if absurd.any():
        k, j = (int(i[0]) for i in np.nonzero(absurd))
        raise IdentificationError(
            f"{int(absurd.any(axis=1).sum())} row(s) have absurd torques, the first tau[{k}] "
            f"(t = {t[k]:.9g} s) = {tau[k, j]:.6g} on coordinate {j}, beyond "
            f"{robot.absurd_torque[j]:.6g} ({ABSURD_LIMIT_FACTOR:g}× the URDF effort limit, "
            f"{ABSURD_VALUE:g} without one): check the torques' units, or set those rows to NaN"
        )
    tf = t[np.isfinite(t)]
    back = np.flatnonzero(np.diff(tf) <= 0.0)
    if back.size:
        k = int(back[0])
        raise TimestampError(
            f"the log's times do not increase: {back.size} finite row(s) repeat or step back, "
            f"the first at t = {tf[k]:.9g} s followed by t = {tf[k + 1]:.9g} s; give each sample "
            "its own, increasing time (sort the log and drop duplicated rows)"
        )
    if warn_filled:
        q, tau, filled = fill_short_gaps(robot, t, q, tau)
        if filled:
            warnings.warn(
                f"{filled} row(s) with NaN positions or torques, in runs of at most "
                f"{MAX_FILL} rows, were filled by interpolating their neighbours (longer runs "
                "split the log into stretches)",
                PinobsWarning,
                stacklevel=3,
            )
    return t, q, tau


#: Runs of at most this many rows with NaN positions or torques between finite rows are
#: filled by interpolation (:func:`fill_short_gaps`); a longer run splits the log.  At 1 kHz
#: the linear interpolation errs by ``|q̈|(4h)²/8`` ≈ 2e-5 rad at 10 rad/s², below the noise.
MAX_FILL = 3


def fill_short_gaps(robot: Robot, t: Vector, q: Vector, tau: Vector) -> tuple[Vector, Vector, int]:
    """``(q, tau, n)``: runs of at most :data:`MAX_FILL` rows whose positions or torques are
    not finite, between finite rows, interpolated linearly in time (on the configuration
    manifold for ``q``); ``n`` the rows filled.  Not where the run and its neighbours span
    more than 1.5 median intervals per step (dropped samples beside it: the interpolation
    would span too long; the rows then split the log).

    A missing sample broke the log into stretches that each need their own smoothing
    start-up and lose their ends: with 2 % of a UR5 log's rows NaN (single rows), the
    stretches averaged 50 samples, shorter than one window.
    """
    good = np.isfinite(t) & np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(tau), axis=1)
    if good.all() or good.sum() < 2:
        return q, tau, 0
    q, tau = q.copy(), tau.copy()
    h = float(np.median(np.diff(t[good])))
    idx = np.flatnonzero(good)
    filled = 0
    for a, b in itertools.pairwise(idx):
        gap = b - a - 1
        if gap == 0 or gap > MAX_FILL or not np.all(np.isfinite(t[a : b + 1])):
            continue
        steps = np.diff(t[a : b + 1])
        if np.any(steps <= 0.0) or t[b] - t[a] > 1.5 * (gap + 1) * h:  # a drop beside them
            continue
        for k in range(a + 1, b):
            s = (t[k] - t[a]) / (t[b] - t[a])
            q[k] = robot.interpolate(q[a], q[b], s)
            tau[k] = (1.0 - s) * tau[a] + s * tau[b]
        filled += gap
    return q, tau, filled


#: Rows of the fit per identifiable combination below which ``warnings`` says the log is
#: too short (one or fewer: refused).  Measured (8 s logs cut short, σ = 1e-4, acceleration
#: error against the truth's): planar_3r at 2 s (3.2 rows per combination) 5.3 against the
#: nominal's 3.7, at 4 s (6.4) 0.084; UR5 at 2 s (2.0) 1.06, at 4 s (4.0) 0.16, at 8 s
#: (8.0) 0.040; a 0.5 s log has as many rows as combinations (planar_3r: 5.9 against 3.7).
ROWS_PER_COMBINATION = 5

#: A joint whose held-out residual the fit makes more than this many times the nominal
#: model's is named in the report's ``warnings`` (the fit does not predict unseen data there).
HOLDOUT_WORSE = 2.0

#: A coordinate where the fit leaves more of its torque side unexplained
#: (``report["unexplained"]``) than this many times what noise alone would leave
#: (``report["unexplained_floor"]``, :func:`_unexplained`), and more than
#: :data:`UNEXPLAINED_MIN`, is named in ``warnings``.
UNEXPLAINED_WARN = 3.0

#: The share left unexplained below which no coordinate is named, whatever the noise floor
#: (model-form errors the noise model does not cover: Coulomb switching, quadrature).
UNEXPLAINED_MIN = 0.01


#: A window whose residual alone exceeds this share of the coordinate's typical torque
#: side (and :data:`UNEXPLAINED_WARN` times the noise floor) is named in ``warnings``.
OUTLIER_SHARE = 0.5


def _percent(x: float) -> str:
    """A share as a percentage; ``"no torque"`` where there is none to share (not "inf %")."""
    return f"{100 * x:.3g} %" if math.isfinite(x) else "no torque"


def _fit_warnings(report: dict[str, Any]) -> list[str]:
    """What the data say against the fit.

    * The coordinates where it leaves more of the torque side unexplained than
      :data:`UNEXPLAINED_WARN` times what noise alone would (:func:`_unexplained`), and
      more than :data:`UNEXPLAINED_MIN` (no parameters of this robot explain these torques).
      A fixed 50 % bar let a double pendulum's negated torques (26–32 % unexplained) write
      link1 at 7.15 kg (truth 0.32).  Measured with ``pinobs.identify`` on 6 s logs at
      1 kHz (double pendulum, UR5, Panda; seeds 1–3; σ = 1e-4 and 1e-3; payload and
      friction mismatches): no clean log warned (0 of 37; the largest share left 0.91 %,
      UR5), every negated (36 of 36), reversed-order (36 of 36) and friction-less fit of
      a plant with friction (18 of 18) did, leaving 10–187 %, 3.3–148 % and 31–91 % on
      their worst coordinate (double pendulum and UR5; Panda's defects with
      ``refine=()``: its refinement smoother takes minutes on them).  With
      ``refine=()``: 0 of 36 clean logs, 36 of 36 negated.
    * Windows whose residual alone is more than :data:`OUTLIER_SHARE` of the torques (a
      spike, a glitch): named by their end times.
    * Cross-validation on its held-out end, unseen by it: the coordinates whose prediction
      residual it makes more than :data:`HOLDOUT_WORSE` times the nominal model's, or that
      nothing was held out (the fit then goes unchecked).  Found by a sweep: a 0.45 s log
      moved a 2 kg link to 38 kg with nothing held out, and a 3 s pendulum log made the
      held-out residual 33× the nominal's, both without a word.
    """
    said = []
    if report.get("filled_rows"):
        said.append(
            f"{report['filled_rows']} row(s) with NaN positions or torques, in runs of at most "
            f"{MAX_FILL} rows, were filled by interpolating their neighbours"
        )
    left_out = set(report.get("excluded", []))
    unexplained = [
        f"{name} ({_percent(u)}; noise alone would leave {_percent(f)})"
        for name, u, f in zip(
            report["coordinates"], report["unexplained"], report["unexplained_floor"], strict=True
        )
        if name not in left_out
        and not math.isnan(u)  # not told (a payload's fit)
        and not u <= max(UNEXPLAINED_WARN * f, UNEXPLAINED_MIN)
    ]
    if unexplained:
        said.append(
            "the fit leaves more of the torques unexplained than noise would on "
            + ", ".join(unexplained)
            + ": no parameters of this robot explain them; check the torques' sign and units "
            "(N·m, N), their joint order, that they drive this robot, and friction (identify "
            "it unless the joints have none)"
        )
    out = report.get("outlier_windows", [])
    if out:
        said.append(
            f"{len(out)} window(s) of {report['rows'] // len(report['coordinates'])} leave more "
            f"than {100 * OUTLIER_SHARE:.3g} % of the torques unexplained, ending at t = "
            + ", ".join(f"{x:.6g}" for x in out[:5])
            + (", …" if len(out) > 5 else "")
            + " s: check the log there (a torque spike, a glitch); they were down-weighted"
        )
    if report["holdout_rows"] == 0:
        said.append(
            "nothing was held out (holdout = 0, or the log's end has no complete window): the "
            "fit is not checked against data it has not seen"
        )
        return said
    worse = [
        f"{name} ({before:.3g} → {after:.3g})"
        for name, before, after in zip(
            report["coordinates"], report["holdout_before"], report["holdout_after"], strict=True
        )
        if name not in left_out and after > HOLDOUT_WORSE * before
    ]
    if worse:
        said.append(
            "the identified model predicts the held-out end worse than the nominal one on "
            + ", ".join(worse)
            + ": the log may be too short or not exciting enough there, or the nominal already "
            "right; check before using it"
        )
    return said


def _difference_noise(x: Vector, t: Vector, rows: NDArray[np.intp]) -> Vector:
    """Per column, the white-noise σ of the samples ``x`` (rows ``rows`` of the log, taken
    at ``t``) of a smooth signal (:func:`~pinobs.model.noise.third_difference_std`); zero
    where too few rows are evenly spaced to tell."""
    sigma = third_difference_std(x, t, rows)
    return np.zeros(x.shape[1]) if sigma is None else sigma


def _unexplained(
    reg: MomentumRegressor,
    A: Vector,
    y: Vector,
    sol: Solution,
    t: Vector,
    q: Vector,
    tau: Vector,
    window: float,
) -> tuple[list[float], list[float]]:
    """Per coordinate, the share of the torque side the fit leaves unexplained and the share
    noise alone would leave (:data:`UNEXPLAINED_WARN`).

    ``unexplained_j = S(r_j) / S(y_j)`` with ``r = Aθ − y`` the weighted rows' residual and
    ``S(x) = √(median(x²) / median(χ²₁))`` (the RMS of Gaussian rows, unmoved by a few
    outlying windows: a single torque spike is not "100 % unexplained").

    The noise floor: a window's weighted row is ``M₀⁻¹ (ΔM v − ∫Y_G π − ∫τ) / T``.  A
    velocity error ``δv`` at its two ends (independent: the smoother's span is about a
    window) adds ``(δv₂ − δv₁)/T``, RMS ``√2 σ_v / T``, with ``σ_v = σ_q ‖c_v‖`` the
    Savitzky–Golay derivative's noise gain on the position noise ``σ_q`` (an upper bound
    for the model-based smoother's); white torque noise ``σ_τ`` adds
    ``M₀⁻¹ σ_τ √(h/T)``.  A least-squares fit of ``p`` combinations to ``n`` rows absorbs
    ``p/n`` of it, so noise alone leaves ::

        floor_j = √((2 σ_v²/T² + Σ_k (M₀⁻¹)_jk² σ_τk² h/T) · (n − p)/n) / S(y_j)

    (rows in N·m, ``weighting="torque"``: ``2 Σ_k M₀,jk² σ_vk²/T² + σ_τj² h/T`` inside.)

    ``σ_q`` and ``σ_τ`` are measured on the log (:func:`_difference_noise`).
    """
    nv = reg.robot.nv
    res = (A @ sol.theta - y).reshape(-1, nv)
    scale = robust_rms(y.reshape(-1, nv))
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(scale > 0, robust_rms(res) / scale, math.inf)
    good = np.isfinite(t) & np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(tau), axis=1)
    rows = np.flatnonzero(good)
    h = float(np.median(np.diff(t[rows])))
    robot = reg.robot
    if robot.is_vector_space:
        u = q[rows]
    else:
        u = np.array([robot.difference(q[rows[0]], q[k]) for k in rows])
    sigma_q = _difference_noise(u, t[rows], rows)
    sigma_tau = _difference_noise(tau[rows], t[rows], rows)
    hw = max(2, round(0.05 / h))  # build_rows' default half window
    c_v, _ = _savgol_coefficients(2 * hw + 1, min(4, 2 * hw), h)
    sigma_v = sigma_q * float(np.linalg.norm(c_v))
    # the rows' own weighting model (a nominal M singular without rotors is regular with them)
    m_mid = reg.weight_robot.mass_matrix(q[rows[rows.size // 2]])
    if reg.weighting == "torque":  # rows in N·m: M δv / T and the torque noise itself
        var = 2.0 * (m_mid**2 @ sigma_v**2) / window**2 + sigma_tau**2 * h / window
    else:
        m_inv = np.linalg.inv(m_mid)
        var = 2.0 * sigma_v**2 / window**2 + (m_inv**2 @ sigma_tau**2) * h / window
    n = A.shape[0]
    dof = max(n - sol.rank, 0) / n
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = np.where(scale > 0, np.sqrt(var * dof) / scale, 0.0)
    return share.tolist(), floor.tolist()


#: A coordinate whose motion over the fitted part spans less than this [rad or m] is named
#: as not moving when the log is refused as not exciting.
STILL_RANGE = 1e-3


def _spans(robot: Robot, t: Vector, q: Vector) -> tuple[Vector, NDArray[np.bool_]]:
    """Per velocity coordinate, the range of motion over the finite rows [rad or m] and
    whether it is still: within :data:`STILL_RANGE` or ten times its noise."""
    rows = np.flatnonzero(np.isfinite(t) & np.all(np.isfinite(q), axis=1))
    if rows.size == 0:
        return np.zeros(robot.nv), np.ones(robot.nv, bool)
    if robot.is_vector_space:
        u = q[rows] - q[rows[0]]
    else:
        u = np.array([robot.difference(q[rows[0]], q[k]) for k in rows])
    span = u.max(axis=0) - u.min(axis=0)
    return span, span < np.maximum(STILL_RANGE, 10.0 * _difference_noise(u, t[rows], rows))


def _not_excited(reg: MomentumRegressor, A: Vector, sol: Solution, t: Vector, q: Vector) -> str:
    """For the refusal of a log that does not excite the dynamics: the coordinates that
    (nearly) never move, and the parameters of the least excited combination (the smallest
    singular direction of the prior-scaled base columns)."""
    robot = reg.robot
    span, still = _spans(robot, t, q)
    names = [b.name if b.nv == 1 else f"{b.name}.{k}" for b in robot.joints for k in range(b.nv)]
    said = ""
    named = [f"{n} ({x:.2g})" for n, x, s in zip(names, span, still, strict=True) if s]
    if named:
        said += f"; never moving (range [rad or m]): {', '.join(named)}"
    cols = [reg.names.index(n) for n in sol.base]
    _, _, vt = np.linalg.svd(A[:, cols] * reg.prior_std()[cols], full_matrices=False)
    weak = vt[-1]
    top = np.argsort(-np.abs(weak))[:4]
    said += "; least excited: " + " ".join(
        f"{'+' if weak[i] >= 0 else '−'}{abs(weak[i]):.2g}·{sol.base[i]}" for i in top
    )
    return said


def _why_no_window(t: Vector, q: Vector, tau: Vector) -> str:
    """What broke the log into stretches too short for a window (for the refusal)."""
    good = np.isfinite(t) & np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(tau), axis=1)
    if good.sum() < 2:
        return ": fewer than two finite rows"
    dt = np.diff(t[good])
    h = float(np.median(dt))
    long = dt > SPLIT_GAP_PERIODS * h
    if long.mean() > 0.01:
        return (
            f": {100 * long.mean():.3g} % of its intervals between finite rows are gaps longer "
            f"than {SPLIT_GAP_PERIODS:g} median intervals ({h:.3g} s), the longest "
            f"{float(dt.max()):.3g} s; dropped samples are used as they are, but a gap that "
            "long splits the log (record without such gaps, or fill them)"
        )
    return f": {100 * (1 - good.mean()):.3g} % of its rows have NaN (gaps split it)"


def _rows_of(
    path: tuple[Vector, Vector] | None, rows: NDArray[np.bool_]
) -> tuple[Vector, Vector] | None:
    return None if path is None else (path[0][rows], path[1][rows])


def _holdout_in_newton_metres(
    reg: MomentumRegressor | PayloadRegressor,
    unweighted: Callable[[], MomentumRegressor | PayloadRegressor],
    rows: tuple[Vector, Vector],
    log: tuple[Vector, Vector, Vector],
    **options: Any,
) -> tuple[Vector, Vector]:
    """The held-out rows in N·m: ``rows`` themselves when ``reg`` already weights by torque,
    else the same windows built again through ``unweighted()`` (their mean torques)."""
    A_h, _ = rows
    if reg.weighting == "torque" or A_h.shape[0] == 0:
        return rows
    A_nm, y_nm, _ = build_rows(unweighted(), *log, **options)
    return A_nm, y_nm


#: A torque channel with more than this share of its finite rows exactly zero is refused
#: (named) unless excluded: a joint whose effort is not measured most of the time (TIAGo's
#: wrist, arm_5..7: 88–90 % zeros) would otherwise be fitted to "no torque".
ZERO_TORQUE_SHARE = 0.5


def _coordinate_names(robot: Robot) -> list[str]:
    """A name per velocity coordinate: the joint's, ``<joint>.<k>`` for a joint of several."""
    return [b.name if b.nv == 1 else f"{b.name}.{k}" for b in robot.joints for k in range(b.nv)]


def excluded_coordinates(robot: Robot, exclude: Sequence[str]) -> NDArray[np.intp]:
    """The velocity coordinates of the joints named in ``exclude`` (sorted).

    Raises:
        OptionError: a name that is not one of the robot's joints (listing them), or a
            string given instead of a list of names.
    """
    if isinstance(exclude, str):
        raise OptionError(f"exclude={exclude!r}: give a list of joint names, e.g. [{exclude!r}]")
    out: list[int] = []
    for name in exclude:
        found = [b for b in robot.joints if b.name == name]
        if not found:
            raise OptionError(
                f"exclude names {name!r}, which is not a joint of {robot.name!r}; its joints: "
                + ", ".join(robot.joint_names)
            )
        out += range(found[0].idx_v, found[0].idx_v + found[0].nv)
    return np.array(sorted(set(out)), dtype=np.intp)


def check_zero_torques(robot: Robot, tau: Vector, excluded: NDArray[np.intp]) -> None:
    """Refuse a log whose torque channel of an actuated, not excluded joint is zero on more
    than :data:`ZERO_TORQUE_SHARE` of its finite rows (naming them all).

    Raises:
        IdentificationError: such channels, with the option that leaves them out.
    """
    zero = []
    for b in robot.joints:
        if b.kind not in ("vector", "circle") or b.nv != 1 or b.idx_v in excluded:
            continue
        x = tau[:, b.idx_v]
        x = x[np.isfinite(x)]
        share = float(np.mean(x == 0.0)) if x.size else 1.0
        if share > ZERO_TORQUE_SHARE:
            zero.append((b.name, share))
    if zero:
        names = [n for n, _ in zero]
        raise IdentificationError(
            "torque channel(s) "
            + ", ".join(f"{n} ({100 * z:.3g} % of the rows exactly 0)" for n, z in zero)
            + f": more than {100 * ZERO_TORQUE_SHARE:g} % zeros, not a measured torque; leave "
            f"them out with exclude={names!r} (pinobs identify: "
            + " ".join(f"--exclude-torque {n}" for n in names)
            + ")"
        )


#: Prior standard deviations of a payload's parameters (:class:`PayloadRegressor`): its mass
#: in units of the robot's total mass, its first and second moments as that mass at
#: :data:`PRIOR_PAYLOAD_LENGTH` from the frame.  The prior mean is no payload (all zero).
PRIOR_PAYLOAD_MASS, PRIOR_PAYLOAD_LENGTH = 1.0, 0.25


class PayloadRegressor:
    """The momentum-form rows of a payload's ten inertial parameters ``φ`` on an otherwise
    known (calibrated) robot.

    ``φ`` (``m, m·c, I`` at the frame's origin, in the frame's axes, Pinocchio's
    ``toDynamicParameters`` order) adds ``T φ`` to the parameters of the joint carrying the
    frame, ``T`` the (linear) action of the frame's placement on dynamic parameters
    (:meth:`placement_map`).  With ``A`` and ``y`` the rows of :class:`MomentumRegressor` on
    the robot (its friction included when on; its armature known) and ``θ_c`` its
    parameters::

        A_p = A[:, π_j] T,    y_p = y − A θ_c

    (a load fixed to a body changes nothing else: Atkeson, An & Hollerbach 1986, "Estimation
    of inertial parameters of manipulator loads and links", §3).

    Args:
        robot: the calibrated robot (taken as exact).
        frame: a frame (body, link or tool frame) of the robot, moved by a joint.
        weighting, exclude: as :class:`MomentumRegressor`'s.
    """

    n_joint = 0
    friction = False
    friction_terms: tuple[str, ...] = ()
    offset = False
    armature = False

    def __init__(
        self, robot: Robot, frame: str, *, weighting: str = "inertia", exclude: Sequence[str] = ()
    ) -> None:
        model = robot.model
        if not isinstance(frame, str) or not model.existFrame(frame):
            bodies = [str(f.name) for f in model.frames if f.type == pin.FrameType.BODY]
            raise OptionError(
                f"payload={frame!r} is not a frame of {robot.name!r}; its bodies: "
                + ", ".join(bodies)
            )
        f = model.frames[model.getFrameId(frame)]
        if f.parentJoint == 0:
            raise OptionError(
                f"payload={frame!r} is fixed to the world: a load there moves nothing; give a "
                "frame moved by a joint (the end effector's)"
            )
        self.robot = robot
        self.frame = frame
        self.joint = int(f.parentJoint)
        self.placement = f.placement
        self.weighting = weighting
        self.base = MomentumRegressor(
            robot,
            friction=robot.friction,
            offset=False,
            armature=False,
            weighting=weighting,
            exclude=exclude,
        )
        self._theta = self.base.nominal()
        self._cols = slice(10 * (self.joint - 1), 10 * self.joint)
        self._map = self.placement_map(self.placement)
        self.n_inertial = 10
        self.names = tuple(f"payload.{s_}" for s_ in SUFFIXES)
        self.armature_slice = slice(10, 10)

    @staticmethod
    def placement_map(placement: pin.SE3) -> Vector:
        """``T`` (10 × 10) with ``(X·I)`` 's dynamic parameters ``= T π(I)``, ``X`` the
        placement: the action is linear in ``(m, m·c, I_origin)``, so its columns are
        differences of the action on an inertia and on that inertia plus a unit step."""
        ref = pin.Inertia(1.0, np.zeros(3), np.eye(3))
        pi0 = ref.toDynamicParameters()
        out0 = placement.act(ref).toDynamicParameters()
        cols = [
            placement.act(pin.Inertia.FromDynamicParameters(pi0 + e)).toDynamicParameters() - out0
            for e in np.eye(10)
        ]
        return np.array(cols).T

    @property
    def size(self) -> int:
        """Number of parameters (10)."""
        return 10

    def nominal(self) -> Vector:
        """The prior mean: no payload."""
        return np.zeros(10)

    def prior_std(self) -> Vector:
        """:data:`PRIOR_PAYLOAD_MASS` of the robot's mass, at :data:`PRIOR_PAYLOAD_LENGTH`."""
        model = self.robot.model
        m = PRIOR_PAYLOAD_MASS * max(sum(float(i.mass) for i in model.inertias), 1e-3)
        length = PRIOR_PAYLOAD_LENGTH
        return np.array([m, *(3 * [m * length]), *(6 * [m * length**2])])

    def with_parameters(self, phi: ArrayLike, *, name: str | None = None) -> Robot:
        """The robot carrying the payload ``φ`` (added to its joint's inertia)."""
        phi = np.asarray(phi, dtype=float)
        model = self.robot.model.copy()
        pi = model.inertias[self.joint].toDynamicParameters() + self._map @ phi
        model.inertias[self.joint] = pin.Inertia.FromDynamicParameters(pi)
        return self.robot.with_model(
            model, name=name or f"{self.robot.name}+payload", friction=self.robot.friction
        )

    def system(
        self,
        t: Vector,
        q: Vector,
        v: Vector,
        tau: Vector,
        *,
        window: int,
        stride: int = 1,
        weight_robot: Robot | None = None,
        torque: str = "held",
    ) -> tuple[Vector, Vector]:
        """``(A_p, y_p)`` of :meth:`MomentumRegressor.system`'s windows (class docstring)."""
        A, y = self.base.system(
            t, q, v, tau, window=window, stride=stride, weight_robot=weight_robot, torque=torque
        )
        return A[:, self._cols] @ self._map, y - A @ self._theta

    def window_ends(self, t: Vector, window: int, stride: int = 1) -> list[float]:
        """As :meth:`MomentumRegressor.window_ends`."""
        return self.base.window_ends(t, window, stride)


def identify_payload(
    robot: Robot,
    log: Any,
    frame: str,
    *,
    holdout: float = 0.2,
    window: float = 0.1,
    path: tuple[ArrayLike, ArrayLike] | None = None,
    torque: str = "held",
    exclude: Sequence[str] = (),
    weighting: str = "inertia",
) -> Identification:
    """The ten inertial parameters of a load attached to ``frame`` of a calibrated ``robot``
    (:class:`PayloadRegressor`), everything else fixed; physically consistent (the load's
    pseudo-inertia ``⪰ 0``, Wensing et al. 2017, by :func:`solve`).

    Rows weighted as :func:`identify`'s (by default through ``M⁻¹``; ``weighting="torque"``:
    each torque channel in N·m by its own residual scale); the held-out report is in N·m
    either way.  The result's ``robot`` carries the payload; ``report["payload"]`` gives
    its mass [kg], centre of mass [m, in ``frame``] and rotational inertia about it
    [kg·m², in ``frame``'s axes]; ``report["holdout_torque_before"]`` is the robot without
    it.  Other arguments and report keys: :func:`identify`'s.
    """
    _check_options(False, False, False, holdout, window, MAX_CONDITION)
    _check_torque(torque)
    _check_weighting(weighting)
    excluded = excluded_coordinates(robot, exclude)
    reg = PayloadRegressor(robot, frame, weighting=weighting, exclude=exclude)
    t, q, tau = log_arrays(robot, log, warn_filled=False)
    check_zero_torques(robot, tau, excluded)
    q, tau, filled = fill_short_gaps(robot, t, q, tau)
    est: tuple[Vector, Vector] | None = None
    if path is not None:
        est = (np.asarray(path[0], dtype=float), np.asarray(path[1], dtype=float))
    finite = np.isfinite(t)
    if finite.sum() < 2:
        raise IdentificationError("the log has fewer than two finite times")
    t_start, t_end = float(np.min(t[finite])), float(np.max(t[finite]))
    split = t_end - holdout * (t_end - t_start)
    fit = t <= split
    A, y, _ = build_rows(
        reg, t[fit], q[fit], tau[fit], window=window, path=_rows_of(est, fit), torque=torque
    )
    if A.shape[0] == 0:
        raise IdentificationError(
            "no complete window of contiguous finite samples in the log" + _why_no_window(t, q, tau)
        )
    nv = robot.nv
    channel = np.tile(np.arange(nv), A.shape[0] // nv)
    used = ~np.isin(channel, excluded)
    sol = solve(reg, A[used], y[used], channel=channel[used] if weighting == "torque" else None)
    A_h, y_h, _ = (
        build_rows(
            reg, t[~fit], q[~fit], tau[~fit], window=window, path=_rows_of(est, ~fit), torque=torque
        )
        if holdout > 0
        else (np.zeros((0, 10)), np.zeros(0), [])
    )

    def per_joint(A_: Vector, y_: Vector, th: Vector) -> list[float]:
        if A_.shape[0] == 0:
            return [math.nan] * nv
        return np.sqrt(np.mean((A_ @ th - y_).reshape(-1, nv) ** 2, axis=0)).tolist()

    phi = sol.theta
    inertia = pin.Inertia.FromDynamicParameters(phi) if phi[0] > 0 else None
    torque_sigma = np.full(nv, math.nan)
    if weighting == "torque":
        torque_sigma[np.unique(channel[used])] = sol.channel_sigma
    coordinates = _coordinate_names(robot)
    zero = np.zeros(10)
    holdout_before, holdout_after = per_joint(A_h, y_h, zero), per_joint(A_h, y_h, phi)
    A_nm, y_nm = _holdout_in_newton_metres(
        reg,
        lambda: PayloadRegressor(robot, frame, weighting="torque", exclude=exclude),
        (A_h, y_h),
        (t[~fit], q[~fit], tau[~fit]),
        window=window,
        path=_rows_of(est, ~fit),
        torque=torque,
    )
    report: dict[str, Any] = {
        "payload": {
            "frame": frame,
            "mass": float(phi[0]),
            "com": [math.nan] * 3 if inertia is None else inertia.lever.tolist(),
            "inertia": [[math.nan] * 3] * 3 if inertia is None else inertia.inertia.tolist(),
            "mass_std": float(sol.std[0]),
        },
        "residual_before": per_joint(A, y, zero),
        "residual_after": per_joint(A, y, phi),
        # (not told here: the rows' torque side is what the calibrated robot leaves, whose
        # share the payload explains says nothing of the model's)
        "unexplained": [math.nan] * nv,
        "unexplained_floor": [math.nan] * nv,
        "outlier_windows": [],
        "holdout_before": holdout_before,
        "holdout_after": holdout_after,
        "holdout_torque_before": per_joint(A_nm, y_nm, zero),
        "holdout_torque_after": per_joint(A_nm, y_nm, phi),
        "weighting": weighting,
        "excluded": [coordinates[j] for j in excluded],
        "torque_sigma": torque_sigma.tolist(),
        "condition": sol.condition,
        "rank": sol.rank,
        "n_parameters": 10,
        "base": list(sol.base),
        "not_excited": [n for n, e in zip(reg.names, sol.excited, strict=True) if not e],
        "moved_by_consistency": [],
        "projected": sol.projected,
        "rows": sol.n_rows,
        "torque": torque,
        "holdout_rows": int(A_h.shape[0]),
        "fit_end": split,
        "sigma": sol.sigma,
        "filled_rows": filled,
        "joints": list(robot.joint_names),
        "coordinates": coordinates,
        "observer_options": {"accel_psd": 1e-6, "disturbance_psd": 1e-4},
    }
    report["warnings"] = _fit_warnings(report)
    if sol.condition > MAX_CONDITION:
        report["warnings"].append(
            f"the payload's parameters are poorly excited: condition number "
            f"{sol.condition:.3g} > {MAX_CONDITION:.3g}; those not excited stay near zero"
        )
    params = ParameterSet(
        names=reg.names, values=phi, std=sol.std, nominal=zero, excited=sol.excited
    )
    return Identification(
        robot=reg.with_parameters(phi, name=f"{robot.name}+payload"),
        parameters=params,
        offset=np.zeros(nv),
        report=report,
        regressor=reg.base,
    )


def _check_options(
    friction: object,
    offset: object,
    armature: object,
    holdout: object,
    window: object,
    max_condition: object,
) -> None:
    """:func:`identify`'s options: booleans, numbers in range (named in the error)."""
    for name, flag in (("offset", offset), ("armature", armature)):
        if not isinstance(flag, (bool, np.bool_)):
            raise OptionError(f"{name}={flag!r}: give True or False")
    if _law_name(friction) == "offset-sigmoid" and offset:
        raise OptionError(
            "friction='offset-sigmoid' has its own offset F_0 per joint, which offset=True's "
            "column would duplicate: give offset=False"
        )
    for name, x in (("holdout", holdout), ("window", window), ("max_condition", max_condition)):
        if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.number)):
            raise OptionError(f"{name}={x!r}: give a number")
    h, w, c = (float(cast(float, x)) for x in (holdout, window, max_condition))
    if not 0.0 <= h < 1.0:
        raise DimensionError(f"holdout={holdout!r} must be in [0, 1)")
    if not 0.0 < w < math.inf:
        raise GainError(f"window={window!r} [s]: give a finite length > 0 (default 0.1)")
    if not c > 1.0:
        raise GainError(f"max_condition={max_condition!r}: give a number > 1 (default 1e6)")


def identify(
    robot: Robot,
    log: Any,
    *,
    friction: bool | str = True,
    offset: bool = True,
    armature: bool = True,
    holdout: float = 0.2,
    window: float = 0.1,
    max_condition: float = MAX_CONDITION,
    path: tuple[ArrayLike, ArrayLike] | None = None,
    torque: str = "held",
    weighting: str = "inertia",
    exclude: Sequence[str] = (),
    payload: str | None = None,
    smoothing: float | None = None,
) -> Identification:
    """Identify ``robot``'s dynamic parameters from a recorded log (module docstring).

    Args:
        robot: the nominal model (the prior).
        log: anything with arrays ``t`` ``(N,)``, ``q`` ``(N, nq)``, ``tau``
            ``(N, nv)`` (a ``Log``), a simulation ``Result`` (its measured
            ``q_meas`` is used, never the truth), or a tuple ``(t, q, tau)``.
            Its intervals are used as they are: dropped samples (rows missing from a
            fixed-rate loop's log) and irregular sampling (:mod:`pinobs.model.sampling`).
            Short runs of NaN rows are filled (:func:`fill_short_gaps`), longer ones are
            gaps; windows never straddle a gap, nor an interval longer than
            :data:`~pinobs.model.sampling.SPLIT_GAP_PERIODS` median intervals.
        friction, offset: identify joint friction and a torque offset.  ``friction``:
            ``True`` the URDF's viscous + Coulomb law (``v_s`` fixed at 0.01 rad/s), or a
            law of :data:`~pinobs.model.friction.FRICTION_LAWS` (``"offset-sigmoid"``,
            ``"stribeck"``, ``"asymmetric"``), whose coefficients are fitted linearly and
            whose smoothing velocity ``v_s`` (and Stribeck ``v_st``) per joint is chosen on
            a grid by cross-validation over the fitted part
            (:func:`pinobs.model.friction_fit.search_smoothing`); the law goes with the calibrated
            robot (and its sidecar when saved).  ``"offset-sigmoid"`` carries its own
            offset ``F_0`` (part of the robot's friction; not dissipative): give
            ``offset=False`` with it.
        armature: identify a rotor inertia per actuated joint (``model.armature``, added to
            ``M``'s diagonal; prior mean the model's own, usually 0, width
            :data:`PRIOR_ARMATURE`); ``False`` keeps the model's as known.
        holdout: fraction of the log (its end) kept out of the fit to report
            the prediction error on unseen data.
        window: integration window [s].
        max_condition: refuse when the base regressor is worse conditioned.
        path: estimated ``(q, v)`` at every sample of the log, ``(N, nq)`` [rad, m]
            and ``(N, nv)`` [rad/s, m/s], used in the regressor instead of the
            Savitzky–Golay fit (:func:`smooth_path`) of the measured positions
            (``pinobs.identify`` passes a model-based smoother's).
        torque: ``"held"`` (zero-order hold: ``pinobs.simulate``, commanded torques) or
            ``"sampled"`` (at the sample instants: ``pinobs excite``, a torque sensor);
            the wrong one biases the fit ∝ 1/rate (module docstring).
        weighting: ``"inertia"`` (default): the rows weighted by ``M₀⁻¹``
            (acceleration-like); ``"torque"``: each window's rows are its mean torque
            residual [N·m, N], each torque channel weighted by its own residual scale
            (re-estimated robustly at each pass, ``report["torque_sigma"]``) (module
            docstring, "Weighting": which wins where).
        exclude: names of joints whose torque channel is left out of the fit (a torque
            that is not measured, or mostly zero: refused unless excluded,
            :data:`ZERO_TORQUE_SHARE`); their parameters stay near nominal unless other
            channels see them.  With ``weighting="inertia"`` the kept rows are weighted by
            the kept joints' block of ``M₀``, inverted (the excluded joints held).
        payload: a body or frame name: identify only the ten inertial parameters of a load
            rigidly attached to it (:func:`identify_payload`), ``robot`` taken as calibrated
            (its inertials, friction, armature fixed: ``friction``, ``offset``, ``armature``
            and ``max_condition`` do not apply; a poorly excited load is said in
            ``warnings``).
        smoothing: the friction law's smoothing velocity ``v_s`` [rad/s], the same for every
            joint, instead of its search (``None``; a Stribeck law's ``v_st`` is still
            searched); ``friction=True``'s is 0.01 unless given.

    The report: ``residual_before`` / ``residual_after`` per joint (RMS of the
    weighted rows, rad/s²-like, on the fitted part) and ``holdout_before`` /
    ``holdout_after`` (on the held-out end), ``condition``, ``rank``,
    ``base`` (names of the identifiable combinations' pivots),
    ``not_excited`` (parameters the data did not fix: near nominal unless physical
    consistency moved them), ``moved_by_consistency`` (those of them it moved by more
    than half their prior standard deviation), ``projected`` (physical consistency
    moved the solution), ``rows``, ``fit_end`` (the last time of
    the fitted part [s]), ``unexplained`` (per coordinate, the fraction of the
    torque side the fit leaves, robust RMS of ``Aθ − y`` over that of ``y``) and
    ``unexplained_floor`` (what noise alone would leave: :func:`_unexplained`),
    ``holdout_torque_before`` / ``holdout_torque_after`` (the held-out windows' mean
    torque residual RMS per coordinate [N·m; N for a prismatic joint], whatever the
    weighting), ``weighting``, ``excluded`` (coordinates left out), ``torque_sigma`` (per
    coordinate, its channel's residual scale [N·m, N]; NaN when excluded or with
    ``weighting="inertia"``),
    ``outlier_windows`` (end times [s] of windows the fit leaves mostly unexplained),
    ``filled_rows`` (NaN rows interpolated: :func:`fill_short_gaps`), ``warnings``
    (what the data say against the fit: :func:`_fit_warnings`), and ``observer_options``:
    what to give ``ekf`` on the calibrated model (``accel_psd=1e-6``,
    ``disturbance_psd=1e-4``: a calibrated model is good, not exact; the
    default ``ekf`` trusts it as if it were exact, and was 1.3–30× less
    accurate for it in ``benchmarks/learning.py``).

    Raises:
        IdentificationError: no torques, too short, never moves, or not
            exciting enough (condition number above ``max_condition``).
    """
    _check_options(friction, offset, armature, holdout, window, max_condition)
    _check_torque(torque)
    _check_weighting(weighting)
    if payload is not None:
        return identify_payload(
            robot,
            log,
            payload,
            holdout=holdout,
            window=window,
            path=path,
            torque=torque,
            exclude=exclude,
            weighting=weighting,
        )
    excluded = excluded_coordinates(robot, exclude)
    t, q, tau = log_arrays(robot, log, warn_filled=False)
    q, tau, filled = fill_short_gaps(robot, t, q, tau)
    est: tuple[Vector, Vector] | None = None
    if path is not None:
        est = (np.asarray(path[0], dtype=float), np.asarray(path[1], dtype=float))
        if est[0].shape != q.shape or est[1].shape != tau.shape:
            raise DimensionError(
                f"path shapes q {est[0].shape}, v {est[1].shape} do not fit the log: "
                f"give ({t.shape[0]}, {robot.nq}) and ({t.shape[0]}, {robot.nv})"
            )
    if smoothing is not None and not (
        isinstance(smoothing, int | float) and 0.0 < smoothing < math.inf
    ):
        raise GainError(f"smoothing={smoothing!r} [rad/s]: give a finite velocity > 0 or None")
    reg = MomentumRegressor(
        robot,
        friction=friction,
        offset=offset,
        armature=armature,
        weighting=weighting,
        exclude=exclude,
        smoothing=smoothing,
    )
    # a law with its smoothing velocity identified: rows of every candidate's columns
    cands = (
        search_candidates(reg.friction_law, smoothing)
        if reg.friction_law not in (None, "viscous-coulomb")
        else []
    )
    rows_reg = widened(reg, cands) if cands else reg
    finite = np.isfinite(t)
    t_end = float(np.max(t[finite])) if finite.any() else 0.0
    t_start = float(np.min(t[finite])) if finite.any() else 0.0
    if t_end - t_start < 4 * window:
        raise IdentificationError(
            f"the log spans {t_end - t_start:.3g} s; identification needs at least "
            f"{4 * window:.3g} s (and a few seconds of rich motion to be useful)"
        )
    h = float(np.median(np.diff(t[finite]))) if finite.sum() > 1 else math.nan
    if h > window / 4:
        raise IdentificationError(
            f"the log's median sample interval is {h:.3g} s, too coarse for windows of "
            f"{window:g} s (four samples at least); if its times are in milliseconds, give "
            "seconds (t / 1000), else a longer window"
        )
    split = t_end - holdout * (t_end - t_start)
    fit = t <= split
    A, y, ends = build_rows(
        rows_reg, t[fit], q[fit], tau[fit], window=window, path=_rows_of(est, fit), torque=torque
    )
    if A.shape[0] == 0:
        raise IdentificationError(
            "no complete window of contiguous finite samples in the log" + _why_no_window(t, q, tau)
        )
    span, still = _spans(robot, t[fit], q[fit])
    if still.all():
        raise IdentificationError(
            "the robot never moves in this log: nothing to identify (largest range of motion "
            f"{float(span.max()):.3g} rad or m, within {STILL_RANGE:g} or ten times the noise)"
        )
    check_zero_torques(robot, tau, excluded)
    nv = robot.nv
    channel = np.tile(np.arange(nv), A.shape[0] // nv)
    used_rows = ~np.isin(channel, excluded)
    searched: dict[str, Any] = {}
    if cands:  # (the search's own least squares, unweighted by channel)
        choice, searched = search_smoothing(reg, A[used_rows], y[used_rows], cands)
        A = A[:, candidate_columns(reg, len(cands), choice)]
        reg = MomentumRegressor(
            robot,
            friction=friction,
            offset=offset,
            armature=armature,
            weighting=weighting,
            exclude=exclude,
            smoothing=[cands[c][0] for c in choice],  # (smoothing, when given, in all)
            stribeck_velocity=[cands[c][1] for c in choice],
        )
    sol = solve(
        reg,
        A[used_rows],
        y[used_rows],
        channel=channel[used_rows] if weighting == "torque" else None,
    )
    enough = ROWS_PER_COMBINATION * sol.rank
    need = enough / robot.nv * window / (1.0 - holdout)  # log length [s] giving that many rows
    used = f"{A.shape[0] // robot.nv} windows of {window:g} s ({sol.n_rows} rows)"
    if sol.n_rows <= sol.rank:
        raise IdentificationError(
            f"{used} for {sol.rank} identifiable combinations: the fit would interpolate the "
            f"data with nothing left to check it; give at least {need:.3g} s of contiguous, "
            f"exciting motion ({ROWS_PER_COMBINATION} rows per combination, holdout "
            f"{holdout:g} kept out)"
        )
    if sol.condition > max_condition:
        raise IdentificationError(
            f"the log does not excite the dynamics enough: condition number "
            f"{sol.condition:.3g} > {max_condition:.3g}"
            + _not_excited(reg, A[used_rows], sol, t[fit], q[fit])
            + (
                " (with the torques of "
                + ", ".join(_coordinate_names(robot)[j] for j in excluded)
                + " left out, what only they see is seen through the others' alone)"
                if excluded.size
                else ""
            )
            + "; record a richer trajectory (`pinobs excite`), or accept it with a larger "
            "max_condition (--max-condition)"
        )
    theta0 = reg.nominal()

    def per_joint(A_: Vector, y_: Vector, th: Vector | None) -> list[float]:
        if A_.shape[0] == 0:
            return [math.nan] * nv
        res = (y_ if th is None else A_ @ th - y_).reshape(-1, nv)
        return np.sqrt(np.mean(res**2, axis=0)).tolist()

    after = per_joint(A, y, sol.theta)
    unexplained, floor = _unexplained(reg, A, y, sol, t[fit], q[fit], tau[fit], window)
    res_w = np.abs(A @ sol.theta - y).reshape(-1, nv)
    bound = np.maximum(OUTLIER_SHARE, UNEXPLAINED_WARN * np.asarray(floor)) * robust_rms(
        y.reshape(-1, nv)
    )
    kept = ~np.isin(np.arange(nv), excluded)
    outliers = [ends[w] for w in np.flatnonzero(np.any((res_w > bound)[:, kept], axis=1))]
    for j in excluded:  # left out of the fit: nothing to say of how well it explains them
        unexplained[j] = floor[j] = math.nan

    A_h, y_h, _ = (
        build_rows(
            reg,
            t[~fit],
            q[~fit],
            tau[~fit],
            window=window,
            path=_rows_of(est, ~fit),
            torque=torque,
        )
        if holdout > 0
        else (np.zeros((0, reg.size)), np.zeros(0), [])
    )
    A_nm, y_nm = _holdout_in_newton_metres(
        reg,
        lambda: MomentumRegressor(
            robot, friction=friction, offset=offset, armature=armature, weighting="torque"
        ),
        (A_h, y_h),
        (t[~fit], q[~fit], tau[~fit]),
        window=window,
        path=_rows_of(est, ~fit),
        torque=torque,
    )
    torque_sigma = np.full(nv, math.nan)
    if weighting == "torque":
        torque_sigma[np.unique(channel[used_rows])] = sol.channel_sigma
    coordinates = _coordinate_names(robot)
    report: dict[str, Any] = {
        "residual_before": per_joint(A, y, theta0),
        "residual_after": after,
        # the fraction of the torque side left unexplained, robustly, and what noise leaves
        "unexplained": unexplained,
        "unexplained_floor": floor,
        # windows (their end times [s]) whose residual alone is a large share of the torques
        "outlier_windows": outliers,
        "holdout_before": per_joint(A_h, y_h, theta0),
        "holdout_after": per_joint(A_h, y_h, sol.theta),
        "holdout_torque_before": per_joint(A_nm, y_nm, theta0),
        "holdout_torque_after": per_joint(A_nm, y_nm, sol.theta),
        "weighting": weighting,
        "excluded": [coordinates[j] for j in excluded],
        "torque_sigma": torque_sigma.tolist(),
        "condition": sol.condition,
        "rank": sol.rank,
        "n_parameters": reg.size,
        "base": list(sol.base),
        "not_excited": [n for n, e in zip(reg.names, sol.excited, strict=True) if not e],
        # of those, the ones physical consistency moved by more than half their prior std
        "moved_by_consistency": [
            n
            for n, e, d, sd in zip(
                reg.names, sol.excited, sol.theta - theta0, reg.prior_std(), strict=True
            )
            if not e and sol.projected and abs(d) > 0.5 * sd
        ],
        "projected": sol.projected,
        "rows": sol.n_rows,
        "torque": torque,  # how ∫τ dt was taken (held or sampled)
        "holdout_rows": int(A_h.shape[0]),
        "fit_end": split,
        "sigma": sol.sigma,
        "filled_rows": filled,
        "joints": list(robot.joint_names),
        # the per-joint lists' entries: one per velocity coordinate (<joint>.<k> for several)
        "coordinates": coordinates,
        # a calibrated model is good, not exact: run ekf with these (adaptive's learned-model
        # densities; measured in benchmarks/learning.py, the plain ekf trusts it too much)
        "observer_options": {"accel_psd": 1e-6, "disturbance_psd": 1e-4},
    }
    if reg.friction:  # the law fitted, its velocities per actuated joint [rad/s]
        report["friction_law"] = {
            "law": reg.friction_law,
            "joints": list(reg.actuated_names),
            "smoothing": reg.smoothing.tolist(),
            "stribeck_velocity": reg.stribeck_velocity.tolist(),
            **searched,
        }
    report["warnings"] = _fit_warnings(report)
    if sol.n_rows < enough:
        report["warnings"].append(
            f"only {used} for {sol.rank} identifiable combinations (fewer than "
            f"{ROWS_PER_COMBINATION} rows each): the fit is loosely determined; give at least "
            f"{need:.3g} s of contiguous, exciting motion"
        )
    params = ParameterSet(
        names=reg.names, values=sol.theta, std=sol.std, nominal=theta0, excited=sol.excited
    )
    calibrated = reg.with_parameters(sol.theta, name=f"{robot.name}+id")
    return Identification(
        robot=calibrated,
        parameters=params,
        offset=reg.offsets(sol.theta),
        report=report,
        regressor=reg,
    )


# ------------------------------------------------------------ friction laws
def _law_name(friction: object) -> str | None:
    """``identify``'s ``friction``: ``True`` → the URDF's law, ``False`` → none, or a law's name.

    Raises:
        OptionError: anything else (naming the laws).
    """
    if isinstance(friction, bool | np.bool_):
        return "viscous-coulomb" if friction else None
    if isinstance(friction, str) and friction in FRICTION_LAWS:
        return friction
    raise OptionError(
        f"friction={friction!r}: give True, False or a friction law: "
        + ", ".join(sorted(FRICTION_LAWS))
    )


def _per_joint(name: str, value: ArrayLike, n: int, *, positive: bool = True) -> Vector:
    """``value`` as ``n`` finite numbers ``> 0`` (``≥ 0`` unless ``positive``), broadcast."""
    x = np.array(np.broadcast_to(np.asarray(value, dtype=float), (n,)), dtype=float)
    if not np.all(np.isfinite(x)) or np.any(x < 0) or (positive and np.any(x == 0)):
        raise GainError(f"{name}={x.tolist()} [rad/s]: give finite velocities > 0")
    return x

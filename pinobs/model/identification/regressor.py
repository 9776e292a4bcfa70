"""The momentum-form regressor (:class:`MomentumRegressor`), its parameters' names, nominal
values and priors, and the option checks shared by :func:`~pinobs.model.identification.identify`
(MATH §9; the package docstring of :mod:`pinobs.model.identification` derives the rows)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import cast

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import DimensionError, GainError, OptionError
from pinobs.model.friction import FRICTION_LAWS, FrictionLaw, friction_basis, law_terms
from pinobs.model.robot import Robot, Vector
from pinobs.model.sampling import held_torque_integral

__all__ = [
    "IDENTIFICATION_FD_STEP",
    "PRIOR_ARMATURE",
    "PRIOR_ARMATURE_FLOOR",
    "PRIOR_COULOMB",
    "PRIOR_DAMPING",
    "PRIOR_INERTIA",
    "PRIOR_OFFSET",
    "STRIBECK_VELOCITY",
    "SUFFIXES",
    "TORQUE_SAMPLING",
    "WEIGHTINGS",
    "MomentumRegressor",
    "check_options",
    "check_torque",
    "check_weighting",
    "coordinate_names",
    "excluded_coordinates",
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
            online ``adaptive`` learner keeps the model's; :func:`identify` turns it on), or
            on the actuated joints named only (:func:`identify`'s choice of the rotors the
            data determine: :mod:`pinobs.model.identification.armature`).  Where it is not
            identified, the model's own armature is taken as known (moved to the torque
            side).
        weighting: how :meth:`system` weighs a window's ``nv`` rows: ``"inertia"`` by
            ``M₀(q_mid)⁻¹ / (t₂ − t₁)`` (acceleration-like, rad/s²; the online learner's)
            or ``"torque"`` by ``1 / (t₂ − t₁)``: the window's mean torque residual in N·m
            (N for a prismatic joint), which :func:`identify` then divides per channel by
            that channel's own residual scale (module docstring, "Weighting").
        exclude: joints whose torque channel is left out (:meth:`_inertia_weight`).
        weight_model: the robot whose ``M(q)⁻¹`` weights the rows (:attr:`weight_robot`;
            :func:`identify`'s second stage passes its first stage's fit); default the
            nominal one, its armature raised by :meth:`armature_floor` when identified.
    """

    def __init__(
        self,
        robot: Robot,
        *,
        friction: bool | str = True,
        offset: bool = True,
        armature: bool | Sequence[str] = False,
        weighting: str = "inertia",
        exclude: Sequence[str] = (),
        smoothing: ArrayLike | None = None,
        stribeck_velocity: ArrayLike | None = None,
        weight_model: Robot | None = None,
    ) -> None:
        check_weighting(weighting)
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
        #: the actuated joints whose armature is identified (in the order of the joints)
        self.armature_joints = _armature_joints(robot, armature, self.actuated_names)
        self.armature = bool(self.armature_joints)
        self._arm_pos = [self.actuated_names.index(j) for j in self.armature_joints]
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
            names += [f"{j}.armature" for j in self.armature_joints]
        if self.offset:
            names += [f"{j}.offset" for j in self.actuated_names]
        self.names: tuple[str, ...] = tuple(names)
        self._select = np.zeros((model.nv, self.n_joint))
        self._select[list(self.actuated), range(self.n_joint)] = 1.0
        # the armature taken as known (moved to the torque side): all of it, or, when it is
        # identified, that of the coordinates without a column (a free-flyer's)
        self._known_armature = np.array(model.armature, dtype=float)
        if self.armature:
            self._known_armature[self.armature_coordinates] = 0.0
        self.weight_model = _weight_model(weight_model, robot)
        self._prior_robot: Robot | None = None

    @property
    def armature_coordinates(self) -> list[int]:
        """The velocity coordinates of :attr:`armature_joints`."""
        return [self.actuated[k] for k in self._arm_pos]

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
    def prior_robot(self) -> Robot:
        """The inertia the friction and offset priors are accelerations of: the nominal
        model, its armature raised by :meth:`armature_floor` on every joint whose armature
        is identified (module docstring: a rotor unknown to the nominal model
        would otherwise be weighed by its link's inertia alone).  Data-independent."""
        if self._prior_robot is None:
            robot = self.robot
            if self.armature and self.n_joint:
                model = robot.model.copy()
                armature = np.array(model.armature, dtype=float)
                armature[self.armature_coordinates] += self.armature_floor()[self._arm_pos]
                model.armature = armature
                robot = robot.with_model(model)
            self._prior_robot = robot
        return self._prior_robot

    def armature_weights(self, theta: ArrayLike) -> Robot:
        """The nominal robot carrying ``θ``'s armature on its joints with one: the weights'
        model of :func:`identify`'s second stage (the nominal inertials: a fit's, which
        compensate what the model cannot express, weighed the real TX40's joint 2 to a
        held-out residual of 16.8 N·m, against 6.6 with these and 8.7 nominal)."""
        model = self.robot.model.copy()
        armature = np.array(model.armature, dtype=float)
        armature[self.armature_coordinates] = np.asarray(theta, dtype=float)[self.armature_slice]
        model.armature = armature
        return self.robot.with_model(model)

    @property
    def weight_robot(self) -> Robot:
        """The model whose ``M(q)⁻¹`` weights the rows: :attr:`weight_model` when given
        (:func:`identify`'s second stage), else :attr:`prior_robot`."""
        return self.weight_model if self.weight_model is not None else self.prior_robot

    @property
    def armature_weighted(self) -> bool:
        """Whether the rows' default weights carry the armature's floor (``M⁻¹`` weights,
        armature columns): :func:`identify` then fits in two stages unless
        :attr:`weight_model` is given (package docstring, "Weighting")."""
        return self.weighting == "inertia" and self.armature and self.n_joint > 0

    @property
    def armature_slice(self) -> slice:
        """Where the armature columns are in ``θ`` (empty when not identified)."""
        start = self.n_inertial + len(self.friction_terms) * self.n_joint
        return slice(start, start + len(self._arm_pos))

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
            parts.append(np.asarray(model.armature)[self.armature_coordinates])
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
            wr = self.prior_robot
            m_bar = np.maximum(np.diag(wr.mass_matrix(wr.neutral()))[idx], 1e-6)
            prior = {"damping": PRIOR_DAMPING, "friction_offset": PRIOR_OFFSET}
            for term in self.friction_terms:
                parts.append(prior.get(term, PRIOR_COULOMB) * m_bar)
            if self.armature:
                floor = self.armature_floor()
                arm_std = np.maximum(PRIOR_ARMATURE * np.maximum(m_nom, 1e-6), floor)
                parts.append(arm_std[self._arm_pos])
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
            armature[self.armature_coordinates] = theta[self.armature_slice]
            model.armature = armature
        # same geometry, shared and never loaded here (with_model); the same tree
        return self.robot.with_inertials(
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
        check_torque(torque)
        nodes, bounds = _window_nodes(t, window, stride)
        n_win = len(bounds) - 1
        if n_win < 1:
            return np.zeros((0, self.size)), np.zeros(0)
        wr = weight_robot or self.weight_robot
        rows, rhs = [], []
        tau_int, vf, trap_f = self._integrals(t, v, tau, torque)
        select_f = np.tile(self._select, len(self._groups))
        ym_prev = self.momentum(q[0], v[0])
        g_prev = self.drift(q[0], v[0])
        for w in range(n_win):
            j0, j1 = bounds[w], bounds[w + 1]
            k0, k1 = int(nodes[j0]), int(nodes[j1])
            acc, g_prev = self._drift_integral(t, q, v, nodes[j0 + 1 : j1 + 1], k0, g_prev)
            ym = self.momentum(q[k1], v[k1])
            block = [ym - ym_prev - acc]
            ym_prev = ym
            if self._groups:
                block.append(select_f * (trap_f[k1] - trap_f[k0]))
            if self.armature:  # diag(I_a) (v₂ − v₁): the rotors' momentum
                block.append(self._select[:, self._arm_pos] * (vf[k1] - vf[k0])[self._arm_pos])
            if self.offset:
                block.append(-self._select * (t[k1] - t[k0]))
            a = np.hstack(block)
            b = tau_int[k1] - tau_int[k0] - self._known_armature * (v[k1] - v[k0])
            row, y = self._weighted(a, b, t, q, (k0, k1), window, wr)
            rows.append(row)
            rhs.append(y)
        return np.vstack(rows), np.concatenate(rhs)

    def _integrals(
        self, t: Vector, v: Vector, tau: Vector, torque: str
    ) -> tuple[Vector, Vector, Vector]:
        """``(∫τ dt, v_actuated, ∫φ(v) dt)`` cumulated over the rows (:meth:`system`)."""
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
        return tau_int, vf, trap_f

    def _drift_integral(
        self, t: Vector, q: Vector, v: Vector, nodes: NDArray[np.intp], k0: int, g_first: Vector
    ) -> tuple[Vector, Vector]:
        """``(∫ Y_G dt, Y_G at the last node)`` over a window from row ``k0`` (where ``Y_G`` is
        ``g_first``) through ``nodes``, by the trapezoidal rule."""
        acc = np.zeros((self.robot.nv, self.n_inertial))
        g_a = g_first
        k_prev = k0
        for k in nodes:
            g_b = self.drift(q[k], v[k])
            acc += 0.5 * (t[k] - t[k_prev]) * (g_a + g_b)
            g_a, k_prev = g_b, int(k)
        return acc, g_a

    def _weighted(
        self,
        a: Vector,
        b: Vector,
        t: Vector,
        q: Vector,
        rows: tuple[int, int],
        window: int,
        wr: Robot,
    ) -> tuple[Vector, Vector]:
        """A window's rows ``(a, b)`` from row ``k0`` to ``k1`` weighted (:attr:`weighting`)."""
        k0, k1 = rows
        if self.weighting == "torque":  # the window's mean torque [N·m, N]
            return a / (t[k1] - t[k0]), b / (t[k1] - t[k0])
        # weight: M₀(q_mid)⁻¹ / (t₂ − t₁) (MATH §9), q_mid the row nearest the middle time
        mid = (k0 + k1) // 2
        if k1 - k0 != window:
            mid = k0 + int(np.argmin(np.abs(t[k0 : k1 + 1] - 0.5 * (t[k0] + t[k1]))))
        weight = self._inertia_weight(wr.mass_matrix(q[mid])) / (t[k1] - t[k0])
        return weight @ a, weight @ b

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


def check_weighting(weighting: object) -> None:
    if weighting not in WEIGHTINGS:
        raise OptionError(
            f"weighting={weighting!r}: give 'torque' (each torque channel by its own residual "
            "scale in N·m) or 'inertia' (rows by M⁻¹, acceleration-like)"
        )


def check_torque(torque: object) -> None:
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


def coordinate_names(robot: Robot) -> list[str]:
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


def _armature_joints(robot: Robot, armature: object, actuated: tuple[str, ...]) -> tuple[str, ...]:
    """:class:`MomentumRegressor`'s ``armature``: every actuated joint (``True``), none
    (``False``) or those named, in the order of the joints.

    Raises:
        OptionError: a name that is not an actuated joint of ``robot`` (the valid ones named).
    """
    if isinstance(armature, (bool, np.bool_)):
        return actuated if armature else ()
    names = [armature] if isinstance(armature, str) else list(cast(Sequence[str], armature))
    unknown = [n for n in names if n not in actuated]
    if unknown:
        raise OptionError(
            f"armature names {unknown!r}, not actuated joints of {robot.name!r}; its actuated "
            "joints: " + ", ".join(actuated)
        )
    return tuple(j for j in actuated if j in names)


def check_options(
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


def _weight_model(weight_model: Robot | None, robot: Robot) -> Robot | None:
    """``weight_model``, checked to be a model of ``robot`` (its ``nv``)."""
    if weight_model is not None and weight_model.nv != robot.nv:
        raise DimensionError(
            f"weight_model has nv={weight_model.nv}; the robot has nv={robot.nv}: give a "
            "model of the same robot (identify's fit of it)"
        )
    return weight_model


def _per_joint(name: str, value: ArrayLike, n: int, *, positive: bool = True) -> Vector:
    """``value`` as ``n`` finite numbers ``> 0`` (``≥ 0`` unless ``positive``), broadcast."""
    x = np.array(np.broadcast_to(np.asarray(value, dtype=float), (n,)), dtype=float)
    if not np.all(np.isfinite(x)) or np.any(x < 0) or (positive and np.any(x == 0)):
        raise GainError(f"{name}={x.tolist()} [rad/s]: give finite velocities > 0")
    return x

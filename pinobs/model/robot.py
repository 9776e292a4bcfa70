"""A Pinocchio model with its dynamics and the geometry of its kinetic-energy metric.

This module is the only code in pinobs that calls Pinocchio's dynamics.

Conventions (Pinocchio's, see ``docs/theory/math.md`` §1-3):

* ``q`` has ``nq`` entries, ``v`` and every tangent vector ``nv``; quaternions
  are ``x, y, z, w``; a free-flyer's velocity is ``[linear; angular]`` in the
  body frame.
* ``integrate(q, v) = q ⊕ v = q · exp(v)``, ``difference(q0, q1) = log(q0⁻¹ q1)``.
* Tangent vectors are expressed in the frame ``{E_i}`` Pinocchio uses for
  ``v``.  For frame-constant fields X, Y the Levi-Civita connection is::

      ∇_X Y = ω(X, Y) = Γs(q)(X, Y) + ½ [X, Y]                    (MATH §2)

  with ``Γs(X, X) = M(q)⁻¹ c(q, X)`` (the geodesic spray) and ``[X, Y]`` the
  bracket of the frame fields (nonzero inside spherical, free-flyer and
  planar joints only).
* Directional derivatives are taken along the group exponential:
  ``D_X f(q) = d/dε f(integrate(q, εX))|₀`` (Pinocchio's own convention for
  its analytic derivatives).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import ConfigurationError, DimensionError, NonFiniteError
from pinobs.model.friction import FrictionLaw
from pinobs.model.joints import JointBlock, joint_blocks
from pinobs.model.perturbation import perturbed_model
from pinobs.tolerances import (
    ABSURD_LIMIT_FACTOR,
    ABSURD_VALUE,
    QUATERNION_NORM_TOL,
)

__all__ = ["JointBlock", "Robot", "read_only"]

Vector = NDArray[np.floating[Any]]
#: Builds ``(visual, collision)`` geometry for a model, on demand (a picklable callable).
GeometryLoader = Callable[
    [pin.Model], tuple["pin.GeometryModel | None", "pin.GeometryModel | None"]
]


#: What :meth:`Robot.with_inertials` shares: what ``__init__`` reads of the tree alone, or
#: was given (tested: with the rest, every attribute ``__init__`` sets).
_TREE_ATTRIBUTES = (
    "root_joint", "package_dirs", "mimic", "source", "_geometry_loader", "_zero_nv", "joints",
    "_quat_slices", "_circle_slices", "_unit_slices", "_bracket_blocks", "_vector_space",
    "_lower_mask",
)  # fmt: skip


class Robot:
    """A rigid multibody system: Pinocchio model, dynamics and metric geometry.

    Build one with :func:`pinobs.load`.  Each ``Robot`` owns its ``pin.Data``;
    use :meth:`copy` to give another consumer (the simulated plant, an
    observer) its own.

    Attributes:
        model: the Pinocchio model (gravity included).
        name: short name (registry name or file stem).
        source: where the model came from (registry name or file path).
        visual_model: Pinocchio visual geometry, or ``None``; built on first
            access when the robot came with a ``geometry`` loader (meshes are
            slow to load and large: only drawing needs them).
        collision_model: Pinocchio collision geometry, or ``None`` (same).
        friction: whether the model's joint friction (URDF ``<dynamics>``) is
            part of the dynamics (:meth:`friction_torque`).
        has_friction: whether that friction is nonzero.
        friction_law: the friction law :meth:`friction_torque` evaluates
            (:class:`pinobs.model.friction.FrictionLaw`): the tags' viscous + Coulomb by
            default, or the ``friction_law`` given (identified, or read from the URDF's
            sidecar); zero with ``friction`` off.
        root_joint: the root joint :func:`pinobs.load` added (``"fixed"``,
            ``"spherical"``, ``"freeflyer"``, ``"planar"``), or ``None`` if unknown.
        package_dirs: the ``package_dirs`` given to :func:`pinobs.load`, as
            absolute paths (the URDF writer resolves the source's meshes with them).
        locked: the joints :func:`pinobs.load` locked (``lock=``), name → value (a float
            for a one-dof joint, a continuous joint's angle; the joint's ``q`` otherwise),
            in model order; empty when none.  The URDF writer writes them as fixed joints
            at these values, and ``pinobs.load(robot.source, lock=robot.locked)`` reloads
            the same model.
        model_error_psd: the model's own acceleration error as a white-noise density
            [rad²/s³] (mean over the joints), measured by ``pinobs.identify`` on its fitted
            rows (:mod:`pinobs.model.identification.model_error`) or read from the URDF's
            sidecar; ``None`` for a model not identified.  ``ekf``, ``riemannian`` and
            ``kalman`` take it as their ``accel_psd`` when given none.
    """

    def __init__(
        self,
        model: pin.Model,
        *,
        name: str,
        source: str,
        visual_model: pin.GeometryModel | None = None,
        collision_model: pin.GeometryModel | None = None,
        friction: bool = False,
        root_joint: str | None = None,
        geometry: GeometryLoader | None = None,
        package_dirs: Sequence[str | Path] = (),
        locked: Mapping[str, float | tuple[float, ...]] | None = None,
        friction_law: FrictionLaw | None = None,
        model_error_psd: float | None = None,
    ) -> None:
        self.model = model
        self.model_error_psd = model_error_psd
        self.locked: dict[str, float | tuple[float, ...]] = dict(locked or {})
        self.root_joint = root_joint
        self.package_dirs = tuple(Path(d).resolve() for d in package_dirs)
        self.mimic: str | None = None  # how pinobs.load took URDF <mimic> joints, if asked
        self.name = name
        self.source = source
        self._geometry_loader = geometry
        self._geometry: tuple[Any, Any] | None = None  # (visual, collision) once built or given
        if visual_model is not None or collision_model is not None or geometry is None:
            self._geometry = (visual_model, collision_model)
        self._data = model.createData()
        self._set_friction(model, friction, friction_law)
        # Zero-gravity copy: aba(q, v, 0) on it is -M⁻¹ c(q, v), the geodesic spray.
        self._free = model.copy()
        self._free.gravity.setZero()
        self._free_data = self._free.createData()
        self._zero_nv = np.zeros(model.nv)
        self._zero_nv.setflags(write=False)
        self._set_joint_blocks(model)

    def _set_friction(
        self, model: pin.Model, friction: bool, friction_law: FrictionLaw | None
    ) -> None:
        """The friction attributes (:meth:`__init__`'s ``friction`` and ``friction_law``)."""
        # The URDF's <dynamics damping friction> tags (model.damping, .friction: ABA ignores
        # them), or a FrictionLaw given (identified, or a sidecar's) in their place.
        self.friction = bool(friction)
        if friction_law is not None and friction_law.nv != model.nv:
            raise DimensionError(
                f"friction_law has {friction_law.nv} coordinates; the model has nv={model.nv}"
            )
        self._given_law = friction_law
        law = friction_law
        if not friction:
            law = FrictionLaw.zero(model.nv)
        elif law is None:
            law = FrictionLaw.from_urdf(model.damping, model.friction)
        #: the friction law in use (zero when ``friction`` is off): :mod:`pinobs.model.friction`
        self.friction_law = law
        self.has_friction = bool(np.any(law.viscous) or law.has_coulomb or np.any(law.offset))
        # a viscous-only law is linear: no tanh to take
        self._linear_friction = not law.has_coulomb and not np.any(law.offset)
        self._neg_damping = -law.viscous
        self._neg_damping.setflags(write=False)

    def _set_joint_blocks(self, model: pin.Model) -> None:
        """The joint blocks and the slices of ``q`` and ``v`` built from them."""
        self.joints: tuple[JointBlock, ...] = joint_blocks(model)
        self._quat_slices = tuple(
            slice(b.idx_q + (3 if b.kind == "se3" else 0), b.idx_q + b.nq)
            for b in self.joints
            if b.kind in ("so3", "se3")
        )
        # (cos, sin) pairs: a continuous joint's q, and a planar joint's q[2:4] after (x, y)
        self._circle_slices = tuple(
            slice(b.idx_q, b.idx_q + 2) for b in self.joints if b.kind == "circle"
        ) + tuple(slice(b.idx_q + 2, b.idx_q + 4) for b in self.joints if b.kind == "se2")
        self._unit_slices = self._quat_slices + self._circle_slices  # unit-norm blocks of q
        self._bracket_blocks = tuple(b for b in self.joints if b.kind in ("so3", "se3", "se2"))
        self._vector_space = model.nq == model.nv and all(b.kind == "vector" for b in self.joints)
        # where Pinocchio may leave M and M⁻¹ unfilled
        self._lower_mask = np.tril(np.ones((model.nv, model.nv), dtype=bool), -1)
        self._lower_mask.setflags(write=False)  # (shared by with_inertials' robots)

    # ---------------------------------------------------------------- geometry
    @property
    def visual_model(self) -> Any:
        """Pinocchio visual geometry (``pin.GeometryModel``) or ``None``, built on first access."""
        return self._geometry_models()[0]

    @visual_model.setter
    def visual_model(self, value: Any) -> None:
        self._geometry = (value, self._geometry_models()[1])

    @property
    def collision_model(self) -> Any:
        """Pinocchio collision geometry (``pin.GeometryModel``) or ``None``, built on first access."""
        return self._geometry_models()[1]

    @collision_model.setter
    def collision_model(self, value: Any) -> None:
        self._geometry = (self._geometry_models()[0], value)

    def _geometry_models(self) -> tuple[Any, Any]:
        if self._geometry is None:
            loader = self._geometry_loader
            self._geometry = (None, None) if loader is None else loader(self.model)
        return self._geometry

    def _geometry_kwargs(self) -> dict[str, Any]:
        """What a copy needs to share this robot's geometry, loaded or not."""
        if self._geometry is None:
            return {"geometry": self._geometry_loader}
        return {
            "visual_model": self._geometry[0],
            "collision_model": self._geometry[1],
            "geometry": self._geometry_loader,
        }

    def __getstate__(self) -> dict[str, Any]:
        """Pickled without ``pin.Data`` (rebuilt) and, when a loader can rebuild it, without
        the geometry (meshes: a UR5's is 187 MB): it is reloaded on first access."""
        state = self.__dict__.copy()
        for k in ("_data", "_free_data"):
            state.pop(k, None)  # (_free_data: absent until first used, with_inertials)
        if self._geometry_loader is not None:
            state["_geometry"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self.__dict__.setdefault("locked", {})  # (pickled before robots kept it)
        self.__dict__.setdefault("model_error_psd", None)  # (pickled before robots kept it)
        self._data = self.model.createData()
        self._zero_nv.setflags(write=False)  # (pickle does not keep the flag)
        self._lower_mask.setflags(write=False)

    # ------------------------------------------------------------------ basics
    def __repr__(self) -> str:
        return f"Robot({self.name!r}, nq={self.nq}, nv={self.nv})"

    @property
    def nq(self) -> int:
        """Number of configuration coordinates."""
        return int(self.model.nq)

    @property
    def nv(self) -> int:
        """Dimension of the tangent space (number of velocities)."""
        return int(self.model.nv)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Names of the joints that move, in model order."""
        return tuple(b.name for b in self.joints)

    @property
    def is_vector_space(self) -> bool:
        """True when every joint is revolute/prismatic (``q`` lives in Rⁿ, nq = nv, ``⊕`` is ``+``)."""
        return self._vector_space

    @property
    def has_lie_group_joints(self) -> bool:
        """True when some joint's frame fields do not commute (spherical, free-flyer, planar)."""
        return bool(self._bracket_blocks)

    def copy(self) -> Robot:
        """The same model with fresh ``pin.Data`` (for another consumer)."""
        robot = self.with_inertials(self.model.copy())
        robot._free_data = robot._free.createData()  # now (not in a consumer's first update)
        return robot

    def with_inertials(
        self,
        model: pin.Model,
        *,
        name: str | None = None,
        friction: bool | None = None,
        friction_law: FrictionLaw | None = None,
    ) -> Robot:
        """:meth:`with_model` for a ``model`` that is a copy of this robot's
        (``model.copy()``) with other inertials, armature, damping or friction tags only: the
        same robot, built without re-reading the tree (its joint blocks and slices are this
        robot's, shared: immutable).  Unchecked: a model of another tree gives a wrong robot.
        What ``adaptive`` pays to install a learned model (issue 39): a UR5's
        ``MomentumRegressor.with_parameters`` 147–162 → 79–125 ``pin.aba``."""
        robot = Robot.__new__(Robot)
        robot.__dict__.update({k: self.__dict__[k] for k in _TREE_ATTRIBUTES})
        robot.model = model
        robot.locked = dict(self.locked)
        robot.model_error_psd = self.model_error_psd
        robot.name = self.name if name is None else name
        loader, geometry = self._geometry_loader, self._geometry
        if geometry is not None and geometry[0] is None and geometry[1] is None:
            geometry = None if loader is not None else geometry  # (as with_model: reloaded)
        robot._geometry = geometry
        robot._data = model.createData()
        law = self._given_law if friction_law is None else friction_law
        robot._set_friction(model, self.friction if friction is None else friction, law)
        return robot  # its zero-gravity copy built on first use (__getattr__)

    def __getattr__(self, name: str) -> Any:
        """``_free`` and ``_free_data`` (:meth:`__init__`'s zero-gravity copy and its data),
        built on first use where :meth:`with_inertials` left them out (a model copy and a
        ``pin.Data``, 12–17 ``pin.aba`` on a UR5; ``adaptive``'s filter never calls them)."""
        if name == "_free" and "model" in self.__dict__:
            free = self.model.copy()
            free.gravity.setZero()
            self._free = free
            return free
        if name == "_free_data" and "model" in self.__dict__:
            self._free_data = data = self._free.createData()
            return data
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def with_model(
        self,
        model: pin.Model,
        *,
        name: str | None = None,
        friction: bool | None = None,
        friction_law: FrictionLaw | None = None,
    ) -> Robot:
        """This robot on another ``pin.Model`` of the same tree (perturbed or identified
        parameters): same source, package directories, root joint, ``mimic``, locked joints
        and geometry (shared, loaded or not: building one never loads meshes); friction as
        this robot's unless given: its friction law when it was given one
        (:attr:`friction_law`), else the new model's ``<dynamics>`` tags."""
        robot = Robot(
            model,
            name=self.name if name is None else name,
            source=self.source,
            friction=self.friction if friction is None else friction,
            root_joint=self.root_joint,
            package_dirs=self.package_dirs,
            locked=self.locked,
            friction_law=self._given_law if friction_law is None else friction_law,
            model_error_psd=self.model_error_psd,
            **self._geometry_kwargs(),
        )
        robot.mimic = self.mimic  # a run of it is reloaded as this one was (pinobs play)
        return robot

    def perturbed(
        self,
        *,
        name: str | None = None,
        inertia_scale: ArrayLike | None = None,
        payload: tuple[float, ArrayLike] | None = None,
        damping: ArrayLike | None = None,
        coulomb: ArrayLike | None = None,
    ) -> Robot:
        """A copy of the robot with its dynamics changed (model-mismatch studies).

        Args:
            name: name of the copy (default: ``<name>~``).
            inertia_scale: one factor per moving body (``nv`` joints order, one
                per joint with ``nv > 0``): mass and rotational inertia scaled
                together, centre of mass kept, so the inertia stays physical.
            payload: ``(mass [kg], offset [m] in the tool body's frame)``: a
                point mass added to the last moving body, passing over prismatic
                joints after it (a Panda's fingers): the end effector of an arm.
            damping: viscous friction [N·m·s/rad] per velocity coordinate,
                replacing the model's (friction switched on).
            coulomb: Coulomb friction [N·m] per velocity coordinate, replacing
                the model's (friction switched on).
        """
        model, friction, law = perturbed_model(
            self, inertia_scale=inertia_scale, payload=payload, damping=damping, coulomb=coulomb
        )
        robot = self.with_model(
            model, name=name or f"{self.name}~", friction=friction, friction_law=law
        )
        robot.model_error_psd = None  # (another model than the one whose error it measured)
        return robot

    # ------------------------------------------------------------- validation
    def check_configuration(self, q: ArrayLike, *, what: str = "q") -> Vector:
        """``q`` as a float array, checked: shape ``(nq,)`` (or ``DimensionError``), finite (or
        ``NonFiniteError``), unit quaternions and continuous joints' ``(cos, sin)`` pairs (norm 1
        within :data:`pinobs.tolerances.QUATERNION_NORM_TOL`, or ``ConfigurationError``; then
        renormalised exactly)."""
        return self.normalized_units(self.check_vector(q, self.nq, what=what), what=what)

    def normalized_units(self, q: Vector, *, what: str = "q") -> Vector:
        """:meth:`check_configuration`'s last step on ``q``, a finite float array of shape
        ``(nq,)``, changed in place and returned: its unit-norm blocks checked (or
        ``ConfigurationError``) and divided by their norms."""
        for s in self._unit_slices:
            block = q[s]
            norm = math.sqrt(float(block.dot(block)))  # np.linalg.norm's arithmetic
            if abs(norm - 1.0) > QUATERNION_NORM_TOL:
                raise ConfigurationError(
                    f"{what}[{s.start}:{s.stop}] = {block.tolist()} has norm {norm:.6g}; "
                    f"unit quaternions and (cos, sin) pairs must have norm 1 "
                    f"within {QUATERNION_NORM_TOL:g}"
                )
            block /= norm
        return q

    @staticmethod
    def check_vector(x: ArrayLike, n: int, *, what: str) -> Vector:
        """Return ``x`` as a fresh float array of shape ``(n,)``, or raise.

        Raises:
            DimensionError: wrong shape or not numeric.
            NonFiniteError: NaN or infinite entries.
        """
        if getattr(getattr(x, "dtype", None), "kind", "f") in ("c", "b", "U", "S"):
            # complex was cut to its real part with a ComplexWarning, bools read as 0/1,
            # text parsed (a sweep): a real-valued array is asked for
            raise DimensionError(f"{what} must be a real array of shape ({n},), got {x!r}")
        try:
            arr = np.array(x, dtype=float)
        except (TypeError, ValueError) as exc:
            raise DimensionError(
                f"{what} must be a numeric array of shape ({n},), got {x!r}"
            ) from exc
        if arr.shape != (n,):
            raise DimensionError(f"{what} must have shape ({n},), got shape {arr.shape}")
        # fast path: a Python sum is finite iff every entry is (overflow: checked entry by entry)
        if not math.isfinite(sum(arr.tolist())) and not np.all(np.isfinite(arr)):
            bad = np.flatnonzero(~np.isfinite(arr)).tolist()
            raise NonFiniteError(f"{what} has non-finite entries at indices {bad}: {arr.tolist()}")
        return arr

    # ------------------------------------------------------------- Lie groups
    def neutral(self) -> Vector:
        """The neutral configuration (identity of every joint group)."""
        return np.asarray(pin.neutral(self.model), dtype=float)

    def random_configuration(self, rng: np.random.Generator, *, scale: float = 1.0) -> Vector:
        """A configuration ``neutral ⊕ ξ`` with ξ uniform in ``[-scale, scale]^nv`` [rad or m].

        Uses the caller's generator (Pinocchio's own sampler uses a global seed).
        """
        return self.integrate(self.neutral(), rng.uniform(-scale, scale, self.nv))

    def integrate(self, q: Vector, v: Vector) -> Vector:
        """``q ⊕ v = q · exp(v)``: move from ``q`` along tangent vector ``v`` for unit time."""
        return np.asarray(pin.integrate(self.model, q, v), dtype=float)

    def difference(self, q0: Vector, q1: Vector) -> Vector:
        """``log(q0⁻¹ q1) ∈ T_{q0}``: the tangent vector with ``q0 ⊕ difference = q1``."""
        return np.asarray(pin.difference(self.model, q0, q1), dtype=float)

    def interpolate(self, q0: Vector, q1: Vector, s: float) -> Vector:
        """``q0 ⊕ s · difference(q0, q1)``: the point a share ``s`` along the geodesic of the
        joints' group from ``q0`` (``s = 0``) to ``q1`` (``s = 1``); ``pin.interpolate`` on a
        Pinocchio model, written with this class's own operations so subclasses keep it."""
        return self.integrate(q0, s * self.difference(q0, q1))

    def integrate_jacobian(self, q: Vector, xi: Vector) -> Vector:
        """``∂(q ⊕ ξ)/∂ξ``: the right Jacobian of the exponential, in the frame at ``q ⊕ ξ``.

        The identity for vector and continuous joints; block-diagonal otherwise.
        """
        return np.array(pin.dIntegrate(self.model, q, xi, pin.ArgumentPosition.ARG1), dtype=float)

    def integrate_jacobian_solve(self, q: Vector, xi: Vector, u: Vector) -> Vector:
        """``(∂(q ⊕ ξ)/∂ξ)⁻¹ u``, the solve of :meth:`integrate_jacobian`, joint by joint.

        The Jacobian is the identity outside spherical, free-flyer and planar
        joints; inside them it is the block ``Jexp(ξ)`` (Pinocchio's
        ``Jexp3``/``Jexp6``), solved block by block: small solves instead of
        one ``nv × nv`` solve (go1: 18 × 18).  (``Jlog(exp ξ)`` would avoid
        the solve but Pinocchio's loses up to 1e-9 near small angles.)
        """
        out = np.array(u, dtype=float)
        gesv = _gesv()
        for b in self._bracket_blocks:
            s = slice(b.idx_v, b.idx_v + b.nv)
            if b.kind == "so3":
                jac = pin.Jexp3(xi[s])
            elif b.kind == "se3":
                jac = pin.Jexp6(xi[s])
            else:
                jac = self.integrate_jacobian(q, xi)[s, s]
            _, _, x, info = gesv(jac, u[s])  # LU with partial pivoting, as np.linalg.solve
            if info != 0:  # singular (|ξ| at 2π): NaN, reported by the observer's update
                x = np.full(b.nv, np.nan)
            out[s] = x
        return out

    @functools.cached_property
    def absurd_torque(self) -> Vector:
        """Per velocity coordinate, the |τ| [N·m or N] beyond which a torque is absurd:
        :data:`~pinobs.tolerances.ABSURD_LIMIT_FACTOR` times the URDF effort limit, or
        :data:`~pinobs.tolerances.ABSURD_VALUE` without a finite positive one (read only)."""
        eff = np.minimum(np.array(self.model.effortLimit, dtype=float), 2 * ABSURD_VALUE)
        ok = np.isfinite(eff) & (eff > 0) & (eff < ABSURD_VALUE)
        return read_only(np.where(ok, ABSURD_LIMIT_FACTOR * eff, ABSURD_VALUE))

    @functools.cached_property
    def absurd_torque_list(self) -> list[float]:
        """:attr:`absurd_torque` as a list of floats, for an update's plain-Python test of a
        torque joint by joint (issue 39: half the time of NumPy's on a talos, the same test)."""
        return list(self.absurd_torque.tolist())

    def off_unit_rows(self, qs: ArrayLike) -> NDArray[np.bool_]:
        """Which rows of ``qs`` ``(N, nq)`` have a quaternion or ``(cos, sin)`` pair off unit
        norm by more than :data:`pinobs.tolerances.QUATERNION_NORM_TOL` (what
        :meth:`check_configuration` refuses; rows with NaN are not counted)."""
        qs = np.asarray(qs, dtype=float)
        off = np.zeros(qs.shape[0], dtype=bool)
        with np.errstate(invalid="ignore"):
            for s in self._unit_slices:
                off |= np.abs(np.linalg.norm(qs[:, s], axis=1) - 1.0) > QUATERNION_NORM_TOL
        return off

    def normalize(self, q: Vector) -> Vector:
        """``q`` with its quaternions and ``(cos, sin)`` pairs projected to unit norm."""
        out = np.array(q, dtype=float)
        for s in self._unit_slices:
            block = out[s]
            block /= math.sqrt(block.dot(block))  # np.linalg.norm's arithmetic, less overhead
        return out

    def bracket(self, x: Vector, y: Vector) -> Vector:
        """``[X, Y]``: Lie bracket of the frame fields through ``x`` and ``y``.

        Zero between different joints and inside vector/continuous joints; the
        so(3) cross product inside a spherical joint; ``ad_x y`` of se(3)
        (``pin.Motion(x).cross(pin.Motion(y))``, linear first) inside a
        free-flyer; the se(2) bracket inside a planar joint.  (MATH §2)
        """
        out = np.zeros(self.nv)
        for b in self._bracket_blocks:
            s = slice(b.idx_v, b.idx_v + b.nv)
            xs, ys = x[s], y[s]
            if b.kind == "so3":
                out[s] = np.cross(xs, ys)
            elif b.kind == "se3":
                out[s] = pin.Motion(xs).cross(pin.Motion(ys)).vector
            else:  # se2, v = (vx, vy, w): [(u, a), (u', b)] = (a J u' - b J u, 0), J = rot(π/2)
                ax, ay = xs[2], ys[2]
                out[b.idx_v] = -ax * ys[1] + ay * xs[1]
                out[b.idx_v + 1] = ax * ys[0] - ay * xs[0]
        return out

    def bracket_matrix(self, x: Vector) -> Vector:
        """The matrix of ``y ↦ [x, y]`` (``ad_x``), shape ``(nv, nv)``, block-diagonal.

        ``skew(x)`` inside a spherical joint, se(3)'s ``ad_x`` (``pin.Motion(x).action``,
        linear first) inside a free-flyer, the se(2) bracket inside a planar joint
        (as :meth:`bracket`); zero elsewhere.
        """
        out = np.zeros((self.nv, self.nv))
        for b in self._bracket_blocks:
            i, xs = b.idx_v, x[b.idx_v : b.idx_v + b.nv]
            if b.kind == "so3":
                out[i : i + 3, i : i + 3] = pin.skew(xs)
            elif b.kind == "se3":
                out[i : i + 6, i : i + 6] = pin.Motion(xs).action
            else:  # se2: [x, y] = (x_w J y_u − y_w J x_u, 0), J = rot(π/2)
                out[i, i + 1], out[i, i + 2] = -xs[2], xs[1]
                out[i + 1, i], out[i + 1, i + 2] = xs[2], -xs[0]
        return out

    # --------------------------------------------------------------- dynamics
    def total_mass(self) -> float:
        """The sum of the bodies' masses [kg] (``pin.computeTotalMass``)."""
        return float(pin.computeTotalMass(self.model))

    def mass_matrix(self, q: Vector) -> Vector:
        """``M(q)``, symmetric positive definite, shape ``(nv, nv)`` [kg, kg·m, kg·m²]."""
        m = np.array(pin.crba(self.model, self._data, q))
        np.copyto(m, m.T, where=self._lower_mask)  # Pinocchio < 4 fills only the upper triangle
        return m

    def gravity(self, q: Vector) -> Vector:
        """``g(q)``: generalised gravity torque [N·m or N]."""
        return np.array(pin.computeGeneralizedGravity(self.model, self._data, q), dtype=float)

    def coriolis(self, q: Vector, v: Vector) -> Vector:
        """``c(q, v)``: Coriolis and centrifugal torque, quadratic in ``v``."""
        return np.array(pin.rnea(self._free, self._free_data, q, v, np.zeros(self.nv)), dtype=float)

    def coriolis_matrix(self, q: Vector, v: Vector) -> Vector:
        """``C(q, v)`` with ``C(q, v) v = c(q, v)`` (Pinocchio's factorisation, ``Ṁ - 2C`` skew)."""
        return np.array(pin.computeCoriolisMatrix(self.model, self._data, q, v), dtype=float)

    def mass_matrix_derivative(self, q: Vector, x: Vector) -> Vector:
        """``D_x M(q)``, shape ``(nv, nv)``: ``C(q, x) + C(q, x)ᵀ`` (``Ṁ = C + Cᵀ``), analytic.

        Checked against central differences along ``integrate`` (agree to 1e-9
        on cartpole, planar_3r, ur5, panda).
        """
        c = self.coriolis_matrix(q, x)
        return c + c.T

    def nonlinear_effects(self, q: Vector, v: Vector) -> Vector:
        """``c(q, v) + g(q)``."""
        return np.array(pin.nonLinearEffects(self.model, self._data, q, v), dtype=float)

    def friction_torque(self, v: Vector) -> Vector:
        """Joint friction torque ``τ_f(v) = −f(v)`` [N·m or N], ``f`` the friction law.

        ``f(v) = F_v v + (1 − e)[F_c⁺ s(1+s)/2 + F_c⁻ s(1−s)/2] + F_s s e + F_0``,
        ``s = tanh(v/v_s)``, ``e = exp(−(v/v_st)²)`` (:mod:`pinobs.model.friction`).  By
        default the URDF's ``<dynamics damping friction>`` tags: ``τ_f = −D v − F_c tanh(v /
        v_s)``, ``v_s`` = :data:`pinobs.tolerances.COULOMB_SMOOTHING_VELOCITY` (the step
        smoothed so the dynamics stay smooth: integrators and Jacobians need it); a law
        given to the robot (identified, or read from its sidecar) replaces them.  Zero when
        the robot was built with ``friction=False``.
        """
        if not self.has_friction:
            return np.zeros(self.nv)
        if self._linear_friction:  # (a viscous-only friction skips the zero Coulomb term's tanh)
            return self._neg_damping * v
        return -self.friction_law.force(v)

    def friction_derivative(self, v: Vector) -> Vector:
        """``∂τ_f/∂v``, diagonal, returned as its diagonal, shape ``(nv,)``
        (:meth:`pinobs.model.friction.FrictionLaw.force_derivative`, negated)."""
        if not self.has_friction:
            return np.zeros(self.nv)
        if self._linear_friction:
            return self._neg_damping.copy()
        return -self.friction_law.force_derivative(v)

    def friction_stiffness(self, v_near: Vector) -> Vector:
        """The largest ``|∂τ_f/∂v|`` over ``|v| ≥ v_near`` per coordinate (``v_near ≥ 0``)
        [N·m·s/rad]: :meth:`pinobs.model.friction.FrictionLaw.slope_bound` (the URDF's law:
        ``−∂τ_f/∂v(v_near)`` exactly)."""
        if not self.has_friction:
            return np.zeros(self.nv)
        if self._linear_friction:
            return -self._neg_damping
        return self.friction_law.slope_bound(v_near)

    def forward_dynamics(self, q: Vector, v: Vector, tau: Vector) -> Vector:
        """``v̇ = M⁻¹(τ + τ_f(v) − c(q, v) − g(q))`` by the articulated-body algorithm."""
        if self.has_friction:
            tau = tau + self.friction_torque(v)
        return pin.aba(self.model, self._data, q, v, tau)  # a fresh array (checked)

    def forward_dynamics_derivatives(
        self, q: Vector, v: Vector, tau: Vector
    ) -> tuple[Vector, Vector, Vector]:
        """``(∂v̇/∂q, ∂v̇/∂v, M⁻¹)`` of :meth:`forward_dynamics` (∂q along ``integrate``; friction included)."""
        _, dq, dv, minv = self.forward_dynamics_with_derivatives(q, v, tau, full_minv=True)
        return np.array(dq), np.array(dv), np.array(minv)

    def forward_dynamics_with_derivatives(
        self, q: Vector, v: Vector, tau: Vector, *, full_minv: bool = False
    ) -> tuple[Vector, Vector, Vector, Vector]:
        """``(v̇, ∂v̇/∂q, ∂v̇/∂v, M⁻¹)`` of :meth:`forward_dynamics`, from one analytic call.

        One ``pin.computeABADerivatives`` (which also runs ABA, hence ``v̇``);
        friction included, ``∂τ_f/∂v`` entering as ``M⁻¹ diag(∂τ_f/∂v)``.  The
        arrays are *views into the robot's* ``pin.Data``, overwritten by its
        next dynamics call: copy what you keep.  ``M⁻¹`` is made symmetric
        (its lower triangle copied from the upper one Pinocchio fills) when
        ``full_minv`` or when friction needs it; otherwise only its upper
        triangle is meaningful.
        """
        if self.has_friction:
            tau = tau + self.friction_torque(v)
        d = self._data
        pin.computeABADerivatives(self.model, d, q, v, tau)
        minv, dv = d.Minv, d.ddq_dv
        if full_minv or self.has_friction:
            np.copyto(minv, minv.T, where=self._lower_mask)  # reads only the upper triangle
        if self.has_friction:
            dv += minv * self.friction_derivative(v)
        return d.ddq, d.ddq_dq, dv, minv

    def inverse_dynamics(self, q: Vector, v: Vector, a: Vector) -> Vector:
        """``τ = M a + c(q, v) + g(q)`` by recursive Newton-Euler."""
        return np.array(pin.rnea(self.model, self._data, q, v, a), dtype=float)

    def kinetic_energy(self, q: Vector, v: Vector) -> float:
        """``½ vᵀ M(q) v`` [J]."""
        return float(pin.computeKineticEnergy(self.model, self._data, q, v))

    def potential_energy(self, q: Vector) -> float:
        """Gravitational potential energy [J] (zero at the world origin)."""
        return float(pin.computePotentialEnergy(self.model, self._data, q))

    def force_per_metric(self, q: Vector, tau: Vector) -> Vector:
        """``S = M⁻¹(τ - g(q))``: the applied force raised with the metric (MATH §4).

        Free motion is ``v̇ = -Γs(v, v) + S``.
        """
        return np.array(
            pin.aba(self._free, self._free_data, q, np.zeros(self.nv), tau - self.gravity(q)),
            dtype=float,
        )

    # --------------------------------------------------------------- geometry
    def metric(self, q: Vector, x: Vector, y: Vector) -> float:
        """``⟨x, y⟩_q = xᵀ M(q) y``: the kinetic-energy metric (twice the kinetic energy)."""
        return float(x @ self.mass_matrix(q) @ y)

    def geodesic_spray(self, q: Vector, x: Vector) -> Vector:
        """``Γs(q)(x, x) = M⁻¹ c(q, x)``: one zero-gravity ABA call (MATH §2)."""
        return -np.asarray(
            pin.aba(self._free, self._free_data, q, x, np.zeros(self.nv)), dtype=float
        )

    def christoffel(self, q: Vector, x: Vector, y: Vector) -> Vector:
        """``Γs(q)(x, y)``, the symmetric part of the connection, shape ``(nv,)``.

        By polarisation of the spray (MATH §2):
        ``Γs(x, y) = ¼ (Γs(x+y, x+y) - Γs(x-y, x-y))``; two ABA calls.
        For vector joints this is ``Γ^k_ij x^i y^j`` of ``M``.
        """
        return 0.25 * (self.geodesic_spray(q, x + y) - self.geodesic_spray(q, x - y))

    def connection(self, q: Vector, x: Vector, y: Vector) -> Vector:
        """``ω(x, y) = Γs(q)(x, y) + ½ [x, y]``: ``∇_X Y`` for frame-constant fields (MATH §2)."""
        return self.christoffel(q, x, y) + 0.5 * self.bracket(x, y)

    def spray_derivative(self, q: Vector, x: Vector) -> Vector:
        """``∂/∂q Γs(q)(x, x)``, shape ``(nv, nv)``: column j is ``D_{E_j} Γs(x, x)``.

        Analytic, from ``pin.computeABADerivatives`` on the zero-gravity model.
        """
        dq, _, _ = pin.computeABADerivatives(self._free, self._free_data, q, x, np.zeros(self.nv))
        return -np.array(dq, dtype=float)

    def spray_jacobians(self, q: Vector, x: Vector) -> tuple[Vector, Vector, Vector]:
        """``(Γs(x, x), ∂/∂q Γs(x, x), ∂/∂x Γs(x, x))`` from one analytic ABA-derivatives call.

        ``∂/∂x Γs(x, x) = 2 Γs(x, ·)``, so the third matrix gives ``Γs(x, y)``
        for every ``y`` at no further cost; the second has columns
        ``D_{E_j} Γs(x, x)`` (as :meth:`spray_derivative`).
        """
        d = self._free_data
        dq, dx, _ = pin.computeABADerivatives(self._free, d, q, x, self._zero_nv)
        return np.negative(d.ddq), np.negative(dq), np.negative(dx)  # fresh arrays

    def forward_dynamics_jacobians(
        self, q: Vector, v: Vector, tau: Vector
    ) -> tuple[Vector, Vector, Vector]:
        """``(v̇, ∂v̇/∂q, ∂v̇/∂v)`` of the rigid-body dynamics ``M⁻¹(τ − c − g)``, one analytic call.

        Joint friction is *not* included (unlike :meth:`forward_dynamics`):
        callers use this with other vectors than a velocity in the ``v`` slot
        (``∂v̇/∂v = −2Γs(v, ·)``); add ``M⁻¹ τ_f`` themselves.  ``∂q`` along
        ``integrate``.
        """
        dq, dv, _ = pin.computeABADerivatives(self.model, self._data, q, v, tau)
        return np.array(self._data.ddq), np.array(dq), np.array(dv)

    def christoffel_derivative(self, q: Vector, x: Vector, y: Vector, z: Vector) -> Vector:
        """``D_z[Γs(q)(x, y)]``: derivative of the symmetric part along ``z`` (two ABA derivative calls)."""
        return 0.25 * (self.spray_derivative(q, x + y) - self.spray_derivative(q, x - y)) @ z

    def curvature(self, q: Vector, x: Vector, y: Vector, z: Vector) -> Vector:
        """``R(x, y) z``, the Riemann curvature as a contraction, shape ``(nv,)``.

        For frame-constant fields (MATH §3)::

            R(X,Y)Z = D_X[ω(Y,Z)] - D_Y[ω(X,Z)] + ω(X, ω(Y,Z)) - ω(Y, ω(X,Z)) - ω([X,Y], Z)

        Convention ``R(X,Y) = ∇_X∇_Y - ∇_Y∇_X - ∇_[X,Y]`` (Maithripala eq. 5), so the
        sectional curvature is ``⟨R(X,Y)Y, X⟩ / (|X|²|Y|² - ⟨X,Y⟩²)``.
        Cost: four ABA-derivative calls and ten ABA calls, never the n⁴ tensor.
        """
        w_yz = self.connection(q, y, z)
        w_xz = self.connection(q, x, z)
        return (
            self.christoffel_derivative(q, y, z, x)
            - self.christoffel_derivative(q, x, z, y)
            + self.connection(q, x, w_yz)
            - self.connection(q, y, w_xz)
            - self.connection(q, self.bracket(x, y), z)
        )

    def sectional_curvature(self, q: Vector, x: Vector, y: Vector) -> float:
        """``K(x, y) = ⟨R(x,y)y, x⟩ / (|x|²|y|² - ⟨x,y⟩²)`` [1/(kg·m²)]."""
        m = self.mass_matrix(q)
        area2 = (x @ m @ x) * (y @ m @ y) - (x @ m @ y) ** 2
        return float(self.curvature(q, x, y, y) @ m @ x / area2)


@functools.cache
def _gesv() -> Any:
    """LAPACK ``dgesv`` (the LU solve behind ``np.linalg.solve``), imported on first use
    (``scipy.linalg`` costs 0.2 s at import); a 6 × 6 solve costs 1.9 µs through it
    against 8.7 µs through ``np.linalg.solve``'s checks and dispatch (measured here, loaded)."""
    from scipy.linalg.lapack import dgesv  # lazy: start-up time

    return dgesv


def read_only(x: ArrayLike) -> Vector:
    """A float copy of ``x`` that cannot be written to (estimates and results hand these out)."""
    out = np.array(x, dtype=float)
    out.setflags(write=False)
    return out

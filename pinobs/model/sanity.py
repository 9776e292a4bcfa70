"""Refuse models whose dynamics cannot be right, naming the body at fault.

Checked when :func:`pinobs.load` builds a model (``check=True``):

* every body's inertia (Pinocchio keeps each link's own inertia on its
  ``BODY`` frame): mass and inertia finite, mass ``m ≥ 0``, principal moments
  ``I₁ ≤ I₂ ≤ I₃`` about the centre of mass non-negative and satisfying the
  triangle inequality ``I₃ ≤ I₁ + I₂`` (``I₁ + I₂ − I₃ = 2 Σ m_k z_k² ≥ 0`` for
  any mass distribution), to :data:`~pinobs.tolerances.INERTIA_TRIANGLE_TOL`
  relative (a broken triangle inequality is only a :class:`ModelWarning`: the
  matrix is still positive definite).  Placeholder bodies lighter than
  :data:`~pinobs.tolerances.NEGLIGIBLE_MASS_FRACTION` of the robot skip the
  moment checks (a 1 mg dummy base with a rank-one inertia changes nothing);
* the mass matrix ``M(q)`` at :data:`MASS_MATRIX_SAMPLES` configurations drawn
  with a fixed seed: symmetric positive definite, ``λ_min(M) >``
  :data:`~pinobs.tolerances.MASS_MATRIX_SINGULAR_TOL` ``· λ_max(M)``.  A joint
  that moves no mass (massless links after it) makes ``M`` singular; the error
  names the joint along the eigenvector of ``λ_min``.

* every joint's values (:func:`check_joints`): damping and dry friction
  finite and ``≥ 0`` (a negative damping feeds energy in), position limits
  with ``lower ≤ upper``.

Zero-mass links that leave ``M`` regular (fixed-joint frames, sensor links,
intermediate links of a composite joint) are accepted silently: they are how
URDFs write frames.

A URDF's own text is checked before Pinocchio reads it (:func:`check_urdf`,
whatever ``check`` says: Pinocchio's parser fails on a negative friction with a
message that names no joint).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from pinobs.errors import ModelError, ModelFileError, ModelWarning
from pinobs.model.urdf import UrdfFacts
from pinobs.tolerances import (
    INERTIA_TRIANGLE_TOL,
    MASS_MATRIX_SINGULAR_TOL,
    NEGLIGIBLE_MASS_FRACTION,
)

__all__ = [
    "MASS_MATRIX_SAMPLES",
    "check_inertias",
    "check_joints",
    "check_mass_matrix",
    "check_model",
    "check_urdf",
    "mass_matrix_defect",
]

#: Configurations at which :func:`check_mass_matrix` samples ``M(q)``.
MASS_MATRIX_SAMPLES = 5

_SEED = 16  # fixed: the check is the same on every load


def _bodies(model: pin.Model) -> list[tuple[str, pin.Inertia]]:
    """``(name, inertia)`` of every link (its ``BODY`` frame) and every joint's rigid body.

    A joint's body sums the links welded to it; the root link under a root
    joint is only there (its frame carries no inertia).
    """
    links = [(f.name, f.inertia) for f in model.frames if f.type == pin.FrameType.BODY]
    first_link: dict[int, str] = {}
    for f in model.frames:
        if f.type == pin.FrameType.BODY:
            first_link.setdefault(f.parentJoint, f.name)
    joints = [
        (f"{first_link.get(j, '?')} (body of joint {model.names[j]})", model.inertias[j])
        for j in range(1, model.njoints)
    ]
    return links + joints


def check_inertias(model: pin.Model) -> None:
    """Refuse bodies with an impossible inertia; warn once for inertias no body can have.

    Raises:
        ModelError: a non-finite mass or inertia, a negative mass, or a
            negative principal moment, naming the body.

    Warns:
        ModelWarning: principal moments that break the triangle inequality
            (the matrix is still positive definite, so the dynamics are well
            posed, but no mass distribution has it: a typo, or an inertia not
            about the centre of mass), listing every such body.
    """
    bodies = _bodies(model)
    total = sum(abs(i.mass) for i in model.inertias if math.isfinite(i.mass))
    scale = max(
        (float(np.abs(i.inertia).max()) for _, i in bodies if np.all(np.isfinite(i.inertia))),
        default=0.0,
    )
    floor = INERTIA_TRIANGLE_TOL * 1e-6 * scale  # round-off of the model's largest inertia
    broken = []
    for name, inertia in bodies:
        mass = float(inertia.mass)
        rot = np.asarray(inertia.inertia, dtype=float)
        if not math.isfinite(mass) or not np.all(np.isfinite(rot)):
            raise ModelError(
                f"body {name!r} has a non-finite inertia (mass {mass}, inertia {rot.tolist()}); "
                "masses [kg] and inertias [kg·m²] must be finite numbers"
            )
        if mass < 0:
            raise ModelError(f"body {name!r} has a negative mass {mass} kg; masses must be ≥ 0")
        if mass < NEGLIGIBLE_MASS_FRACTION * total:
            continue
        moments = np.linalg.eigvalsh(0.5 * (rot + rot.T))  # principal moments, ascending
        i1, i2, i3 = (float(x) for x in moments)
        slack = INERTIA_TRIANGLE_TOL * i3 + floor
        if i1 < -slack:
            raise ModelError(
                f"body {name!r} has a negative principal moment of inertia: {moments.tolist()} "
                "kg·m² about its centre of mass; an inertia must be positive semidefinite"
            )
        if i3 > i1 + i2 + slack:
            broken.append(f"{name!r} {np.round(moments, 8).tolist()}")
    if broken:
        warnings.warn(
            "principal moments [kg·m²] breaking the triangle inequality I3 ≤ I1 + I2 (no mass "
            "distribution has them: a typo in ixx/iyy/izz, or an inertia not about the centre "
            "of mass?); the dynamics stay well posed: " + "; ".join(broken),
            ModelWarning,
            stacklevel=4,
        )


def _joint_of_velocity(model: pin.Model, k: int) -> int:
    return next(
        j
        for j in range(1, model.njoints)
        if model.joints[j].idx_v <= k < model.joints[j].idx_v + model.joints[j].nv
    )


def mass_matrix_defect(model: pin.Model, data: pin.Data, q: NDArray[np.float64]) -> str | None:
    """What is wrong with ``M(q)`` (Pinocchio's CRBA, symmetrised), or ``None``: singular or
    indefinite when ``λ_min(M) ≤`` :data:`~pinobs.tolerances.MASS_MATRIX_SINGULAR_TOL`
    ``· λ_max(M)``, said along the joint of the largest entry of ``λ_min``'s eigenvector, with
    the bodies it moves (they carry no mass or inertia about its axis)."""
    m = np.array(pin.crba(model, data, q))
    m = np.triu(m) + np.triu(m, 1).T
    eig, vec = np.linalg.eigh(m)
    if eig[0] > MASS_MATRIX_SINGULAR_TOL * eig[-1]:
        return None
    k = int(np.argmax(np.abs(vec[:, 0])))
    joint = _joint_of_velocity(model, k)
    bodies = [f.name for f in model.frames if f.type == pin.FrameType.BODY]
    after = [
        f.name
        for f in model.frames
        if f.type == pin.FrameType.BODY
        and (f.parentJoint == joint or joint in model.supports[f.parentJoint])
    ] or bodies[:1]
    kind = "indefinite" if eig[0] < -MASS_MATRIX_SINGULAR_TOL * eig[-1] else "singular"
    return (
        f"the mass matrix is {kind} (smallest eigenvalue {eig[0]:.3g} against largest "
        f"{eig[-1]:.3g}) at q = {np.round(q, 4).tolist()}, along joint "
        f"{model.names[joint]!r}: the bodies it moves ({', '.join(after[:6])}"
        f"{', …' if len(after) > 6 else ''}) carry no mass or inertia about its axis"
    )


def check_mass_matrix(model: pin.Model) -> None:
    """Raise :class:`ModelError` if ``M(q)`` is singular or indefinite at a sampled ``q``
    (:func:`mass_matrix_defect`).

    ``M`` is Pinocchio's CRBA (``model.armature`` on its diagonal), symmetrised; configurations are ``neutral ⊕ ξ``, ξ uniform
    in ``[-π, π]^nv`` with a fixed seed.
    """
    rng = np.random.default_rng(_SEED)
    data = model.createData()
    q0 = pin.neutral(model)
    for _ in range(MASS_MATRIX_SAMPLES):
        q = pin.integrate(model, q0, rng.uniform(-np.pi, np.pi, model.nv))
        said = mass_matrix_defect(model, data, q)
        if said is not None:
            raise ModelError(
                f"{said}. Give them an <inertial>, or make the joint fixed; check=False loads "
                "it anyway"
            )


_UNITS = {"damping": "viscous damping [N·m·s/rad or N·s/m]", "friction": "dry friction [N·m or N]"}


def _more(found: tuple[object, ...], what: str) -> str:
    """`` (2 more such joint(s))`` after the first of ``found``, or nothing."""
    return f" ({len(found) - 1} more {what})" if len(found) > 1 else ""


def check_urdf(facts: UrdfFacts, *, mimic: str, inertials: bool = True) -> None:
    """Raise :class:`ModelError` for what Pinocchio's URDF parser loses or garbles.

    * :class:`~pinobs.errors.ModelFileError`: a link or joint name given twice
      (urdfdom says only "not a valid URDF model");
    * a revolute, continuous or prismatic joint with ``<axis xyz="0 0 0">``;
    * an ``<inertial>`` value that is not a finite number (``mass="nan"``,
      ``"abc"``), or left out (no ``<mass>``, ``<inertia>`` or ``iyz``): urdfdom
      prints an error and drops the inertial or keeps its mass without inertia, so
      the link would silently be massless or a point mass; a second ``<inertial>``
      in a link (urdfdom keeps the first);
    * a ``<dynamics damping friction>`` value that is negative or not a finite
      number (a negative damping feeds energy in; Pinocchio's parser refuses a
      negative friction naming no joint);
    * a revolute or prismatic ``<limit>`` with ``lower > upper``, or ``lower =
      upper`` other than 0 (the joint could not move; ``lower = upper = 0`` is
      the "no limits" convention :func:`pinobs.load` reads as unlimited);
    * ``<mimic>`` joints when ``mimic="error"``: Pinocchio's ABA cannot couple
      joints, so they would move independently (``mimic="independent"`` accepts that).

    ``inertials=False`` leaves out the inertials.
    """
    if facts.duplicates:
        raise ModelFileError(
            f"{', '.join(facts.duplicates)} defined more than once; a URDF's link and joint "
            "names must be unique (a copied block not renamed?)"
        )
    if facts.zero_axes:
        raise ModelError(
            f"joint(s) {', '.join(map(repr, facts.zero_axes))} have <axis xyz='0 0 0'>, no "
            "direction to move along; give the axis as a nonzero vector (e.g. '0 0 1')"
        )
    if inertials and facts.bad_inertials:
        link, problem = facts.bad_inertials[0]
        raise ModelError(
            f"link {link!r}: {problem}. Write one <inertial> per link with a mass [kg] and all "
            "six inertia entries [kg·m²] as numbers"
        )
    if facts.bad_dynamics:
        joint, attr, text = facts.bad_dynamics[0]
        raise ModelError(
            f"joint {joint!r}: <dynamics {attr}={text!r}> is not a finite number ≥ 0"
            f"{_more(facts.bad_dynamics, 'such value(s)')}; a negative {attr} feeds energy into "
            f"the motion. Give the {_UNITS[attr]} as a number ≥ 0 (0: none)"
        )
    if facts.bad_limits:
        joint, lower, upper = facts.bad_limits[0]
        what = "is inverted" if lower > upper else "leaves the joint no motion"
        raise ModelError(
            f"joint {joint!r}: <limit lower={lower:g} upper={upper:g}> {what}"
            f"{_more(facts.bad_limits, 'such joint(s)')}; "
            "give lower < upper [rad or m] (swapped?), make the joint fixed, or write "
            "lower=upper=0 (or type continuous) for no limits"
        )
    if facts.mimics and mimic == "error":
        joint, target, mult, offset = facts.mimics[0]
        raise ModelError(
            f"joint {joint!r} mimics {target!r} (q = {mult:g}·q_{target} + {offset:g}"
            f"{f'; {len(facts.mimics) - 1} more mimic joint(s)' if len(facts.mimics) > 1 else ''}"
            "): Pinocchio's forward dynamics cannot couple joints. To load every mimic joint "
            "as a joint of its own pass mimic='independent' (pinobs.load) or --mimic "
            "independent (the pinobs command), or remove the <mimic> tags"
        )


def check_joints(model: pin.Model) -> None:
    """Raise :class:`ModelError` for a joint whose damping or dry friction is negative or not
    finite (a negative damping feeds energy in), or whose position limits are inverted
    (``lower > upper``), naming the joint and the value."""
    for j in range(1, model.njoints):
        joint = model.joints[j]
        v, q = (
            slice(joint.idx_v, joint.idx_v + joint.nv),
            slice(joint.idx_q, joint.idx_q + joint.nq),
        )
        for attr, what in (("damping", "viscous damping"), ("friction", "dry friction")):
            values = np.asarray(getattr(model, attr), dtype=float)[v]
            if not np.all(np.isfinite(values) & (values >= 0)):
                raise ModelError(
                    f"joint {model.names[j]!r} has {what} {values.tolist()}; it must be a finite "
                    "number ≥ 0 (a negative one feeds energy into the motion)"
                )
        lower = np.asarray(model.lowerPositionLimit, dtype=float)[q]
        upper = np.asarray(model.upperPositionLimit, dtype=float)[q]
        if np.any(lower > upper):
            raise ModelError(
                f"joint {model.names[j]!r} has position limits lower {lower.tolist()} > upper "
                f"{upper.tolist()}; give lower ≤ upper (swapped?)"
            )


def check_model(model: pin.Model) -> None:
    """:func:`check_joints`, :func:`check_inertias`, then :func:`check_mass_matrix`."""
    check_joints(model)
    check_inertias(model)
    check_mass_matrix(model)

"""Per-joint friction laws: viscous, (asymmetric) Coulomb, Stribeck and a constant offset.

One law per velocity coordinate ``j``, the friction *force* (what the drive must
overcome; the joint feels ``τ_f = −f(v)``, :meth:`pinobs.model.Robot.friction_torque`)::

    f(v) = F_v v + (1 − e) [F_c⁺ s(1 + s)/2 + F_c⁻ s(1 − s)/2] + F_s s e + F_0
    s = tanh(v / v_s),   e = exp(−(v / v_st)²)   (e = 0 when v_st = 0)

* ``F_v`` viscous [N·m·s/rad]; ``F_c⁺`` / ``F_c⁻`` the Coulomb level for ``v → +∞`` /
  ``v → −∞`` [N·m] (``s(1 ± s)/2 → 1`` there and ``→ 0`` on the other side: the
  smooth asymmetric step, equal levels giving ``F_c tanh(v/v_s)``);
* ``F_s`` the static (breakaway) level of the Stribeck curve, reached as ``|v| ≪ v_st``
  (Armstrong-Hélouvry, Dupont, Canudas de Wit 1994, *Automatica* 30(7), eq. (1):
  ``F_c + (F_s − F_c) exp(−(v/v_st)²)``, here each level times the smoothed sign);
* ``F_0`` a constant offset [N·m], as in the published UR10e model
  ``F_v v + F_c sign(v) + F_0`` (Mamedov et al. 2020): a gravity-model error or a
  torque-sensing bias absorbed by the friction, *not* dissipative (it can feed energy);
* ``v_s`` the smoothing velocity of the sign [rad/s]: the step is smoothed so the dynamics
  stay differentiable (integrators and Jacobians need it); identified, not fixed
  (:func:`pinobs.model.identification.identify`).

Every coefficient ``F_v, F_c⁺, F_c⁻, F_s ≥ 0`` makes each term have the sign of ``v``
(``|s| < 1``, so ``s(1 ± s)/2`` has the sign of ``s``), hence ``f(v) v ≥ 0``: the
friction dissipates energy.  ``F_0`` breaks that (documented, allowed any sign).

The law is linear in ``(F_v, F_c⁺, F_c⁻, F_s, F_0)``: :func:`friction_basis` gives the
regressor columns of each term (the identification's), and :meth:`FrictionLaw.force` is
their sum, so the two cannot disagree.  The URDF's ``<dynamics damping friction>`` is the
law ``F_v = damping``, ``F_c± = friction``, ``v_s`` =
:data:`pinobs.tolerances.COULOMB_SMOOTHING_VELOCITY`, no Stribeck, no offset
(:meth:`FrictionLaw.from_urdf`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from pinobs.errors import DimensionError, GainError, UnknownNameError
from pinobs.tolerances import COULOMB_SMOOTHING_VELOCITY

__all__ = [
    "FRICTION_LAWS",
    "FRICTION_TERMS",
    "FrictionLaw",
    "friction_basis",
    "law_terms",
]

Vector = np.ndarray

#: The laws :func:`pinobs.model.identification.identify` fits, and their terms (the
#: coefficients identified, in that order): ``viscous-coulomb`` is the URDF's
#: (``v_s`` fixed at :data:`~pinobs.tolerances.COULOMB_SMOOTHING_VELOCITY`), the others
#: have their smoothing velocity (and Stribeck velocity) identified.
FRICTION_LAWS: dict[str, tuple[str, ...]] = {
    "viscous-coulomb": ("damping", "coulomb"),
    "offset-sigmoid": ("damping", "coulomb", "friction_offset"),
    "stribeck": ("damping", "coulomb", "static"),
    "asymmetric": ("damping", "coulomb_pos", "coulomb_neg"),
}

#: Every term a law may have; all but ``friction_offset`` must be ``≥ 0`` (dissipative).
FRICTION_TERMS = ("damping", "coulomb", "coulomb_pos", "coulomb_neg", "static", "friction_offset")


#: Points of :meth:`FrictionLaw.slope_bound`'s grid, and the factor on its maximum.
SLOPE_POINTS, SLOPE_MARGIN = 48, 1.05


def law_terms(law: str) -> tuple[str, ...]:
    """The terms of a law of :data:`FRICTION_LAWS` (its name checked)."""
    try:
        return FRICTION_LAWS[law]
    except KeyError:
        raise UnknownNameError(
            f"unknown friction law {law!r}; known: {', '.join(sorted(FRICTION_LAWS))}"
        ) from None


def friction_basis(term: str, v: Vector, smoothing: Vector, stribeck: Vector) -> Vector:
    """The regressor column of one term of ``f(v)`` (module docstring), elementwise.

    Args:
        term: one of :data:`FRICTION_TERMS`.
        v: velocities [rad/s], any shape broadcasting with the next two.
        smoothing: ``v_s`` [rad/s], ``> 0``.
        stribeck: ``v_st`` [rad/s], ``≥ 0`` (``0``: no Stribeck term, ``e = 0``).
    """
    v = np.asarray(v, dtype=float)
    if term == "damping":
        return v.copy()
    if term == "friction_offset":
        return np.ones_like(v)
    s = np.tanh(v / smoothing)
    st = np.broadcast_to(np.asarray(stribeck, dtype=float), s.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.where(st > 0, np.exp(-np.square(v / np.where(st > 0, st, 1.0))), 0.0)
    if term == "coulomb":
        return s * (1.0 - e)
    if term == "coulomb_pos":
        return 0.5 * s * (1.0 + s) * (1.0 - e)
    if term == "coulomb_neg":
        return 0.5 * s * (1.0 - s) * (1.0 - e)
    if term == "static":
        return s * e
    raise UnknownNameError(f"unknown friction term {term!r}; known: {', '.join(FRICTION_TERMS)}")


#: :class:`FrictionLaw`'s array fields, in order, and the rows of them that must be ``≥ 0``.
_ARRAYS = (
    "viscous", "coulomb_pos", "coulomb_neg", "static", "offset", "smoothing", "stribeck_velocity"
)  # fmt: skip
_NON_NEGATIVE = [0, 1, 2, 3, 6]


@dataclass(frozen=True)
class FrictionLaw:
    """Friction per velocity coordinate (module docstring); arrays of shape ``(nv,)``.

    Attributes:
        viscous: ``F_v`` [N·m·s/rad or N·s/m], ``≥ 0``.
        coulomb_pos: ``F_c⁺`` [N·m or N], ``≥ 0``: the Coulomb level moving forward.
        coulomb_neg: ``F_c⁻`` [N·m or N], ``≥ 0``: moving backward.
        static: ``F_s`` [N·m or N], ``≥ 0``: the Stribeck static level (unused, and
            required 0, where ``stribeck_velocity`` is 0).
        offset: ``F_0`` [N·m or N], any sign (not dissipative).
        smoothing: ``v_s`` [rad/s or m/s], ``> 0``.
        stribeck_velocity: ``v_st`` [rad/s or m/s], ``≥ 0`` (0: no Stribeck term).
        law: a label: the name of the law it was identified as (:data:`FRICTION_LAWS`).
    """

    viscous: Vector
    coulomb_pos: Vector
    coulomb_neg: Vector
    static: Vector
    offset: Vector
    smoothing: Vector
    stribeck_velocity: Vector
    law: str = "viscous-coulomb"

    def __post_init__(self) -> None:
        # checked together, one read-only (7, nv) array whose rows are the fields (adaptive
        # builds two to four to install a learned model, issue 39: FrictionLaw.zero(6)
        # 25–30 → 9–17 pin.aba); one by one (below) where that fails, to say which is wrong
        try:
            x = np.array([getattr(self, k) for k in _ARRAYS], dtype=float)
        except (TypeError, ValueError):  # ragged, or not numbers
            x = np.zeros((0, 0))
        if (
            x.ndim == 2
            and x.shape[0] == len(_ARRAYS)
            and np.isfinite(x).all()
            and not (x[_NON_NEGATIVE] < 0).any()
        ):
            x.setflags(write=False)
            for k, row in zip(_ARRAYS, x, strict=True):
                object.__setattr__(self, k, row)
        else:
            self._check_each()
        if np.any(self.smoothing <= 0):
            raise GainError(f"friction smoothing={self.smoothing.tolist()} [rad/s] must be > 0")
        if np.any((self.stribeck_velocity == 0) & (self.static != 0)):
            raise GainError(
                "friction static level given where stribeck_velocity is 0 (no Stribeck term): "
                f"static={self.static.tolist()}, stribeck_velocity="
                f"{self.stribeck_velocity.tolist()}"
            )

    def _check_each(self) -> None:
        """Each array field a 1-D float array of ``viscous``'s shape, finite, ``≥ 0`` but the
        offset and the smoothing; stored read only (raises on the first that is not)."""
        arrays = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "law"}
        n = np.asarray(self.viscous).shape
        for name, value in arrays.items():
            x = np.array(value, dtype=float)
            if x.ndim != 1 or x.shape != n:
                raise DimensionError(
                    f"friction {name} must be one number per velocity coordinate, shape {n}; "
                    f"got shape {x.shape}"
                )
            if not np.all(np.isfinite(x)):
                raise GainError(f"friction {name}={x.tolist()} must be finite")
            low = name not in ("offset", "smoothing")
            if low and np.any(x < 0):
                raise GainError(
                    f"friction {name}={x.tolist()} must be ≥ 0 (dissipative friction; only the "
                    "offset may be negative)"
                )
            x.setflags(write=False)
            object.__setattr__(self, name, x)

    # ------------------------------------------------------------ construction
    @classmethod
    def zero(cls, nv: int) -> FrictionLaw:
        """No friction on ``nv`` coordinates."""
        z = np.zeros(nv)
        return cls(z, z, z, z, z, np.full(nv, COULOMB_SMOOTHING_VELOCITY), z)

    @classmethod
    def from_urdf(cls, damping: ArrayLike, coulomb: ArrayLike) -> FrictionLaw:
        """The URDF's ``<dynamics damping friction>``: ``F_v v + F_c tanh(v / v_s)``,
        ``v_s`` = :data:`~pinobs.tolerances.COULOMB_SMOOTHING_VELOCITY`."""
        d = np.asarray(damping, dtype=float)
        c = np.asarray(coulomb, dtype=float)
        z = np.zeros(d.shape)
        return cls(d, c, c, z, z, np.full(d.shape, COULOMB_SMOOTHING_VELOCITY), z)

    # ------------------------------------------------------------ evaluation
    @property
    def nv(self) -> int:
        """Number of velocity coordinates."""
        return int(self.viscous.shape[0])

    @property
    def is_urdf(self) -> bool:
        """Whether the URDF's tags say it all (:meth:`from_urdf` of its ``viscous`` and Coulomb)."""
        return bool(
            np.array_equal(self.coulomb_pos, self.coulomb_neg)
            and not np.any(self.static)
            and not np.any(self.offset)
            and np.all(self.smoothing == COULOMB_SMOOTHING_VELOCITY)
        )

    @functools.cached_property
    def _symmetric(self) -> bool:
        return bool(np.array_equal(self.coulomb_pos, self.coulomb_neg))

    @functools.cached_property
    def _has_static(self) -> bool:
        return bool(np.any(self.static))

    @functools.cached_property
    def has_coulomb(self) -> bool:
        """Whether any nonlinear (sign-like) term is nonzero."""
        return bool(np.any(self.coulomb_pos) or np.any(self.coulomb_neg) or np.any(self.static))

    @functools.cached_property
    def _urdf_terms(self) -> Vector | None:
        """``F_c`` when the law is the URDF's with a Coulomb term (:attr:`is_urdf`), else None."""
        return self.coulomb_pos if self.has_coulomb and self.is_urdf else None

    def force(self, v: Vector) -> Vector:
        """``f(v)`` (module docstring) [N·m or N], shape of ``v``."""
        if self._urdf_terms is not None:  # F_v v + F_c tanh(v / v_s): the general formula's
            # value to the last bit at a seventh of its cost (every robot without an
            # identified law; a plant calls it at every RK4 stage)
            s = np.tanh(np.asarray(v, dtype=float) / COULOMB_SMOOTHING_VELOCITY)
            return self.viscous * v + self._urdf_terms * s
        out = self.viscous * v + self.offset
        if self.has_coulomb:
            vs, vst = self.smoothing, self.stribeck_velocity
            if self._symmetric:  # s(1+s)/2 + s(1−s)/2 = s (the URDF's law, to the last bit)
                out = out + self.coulomb_pos * friction_basis("coulomb", v, vs, vst)
            else:
                out = out + self.coulomb_pos * friction_basis("coulomb_pos", v, vs, vst)
                out = out + self.coulomb_neg * friction_basis("coulomb_neg", v, vs, vst)
            if self._has_static:
                out = out + self.static * friction_basis("static", v, vs, vst)
        return np.asarray(out)

    def force_derivative(self, v: Vector) -> Vector:
        """``∂f/∂v`` (diagonal, as its diagonal), shape of ``v``.

        With ``s' = (1 − s²)/v_s`` and ``e' = −2 v e / v_st²``:
        ``f' = F_v + (1 − e) C' − e' C + F_s (e' s + e s')``,
        ``C = F_c⁺ s(1 + s)/2 + F_c⁻ s(1 − s)/2``, ``C' = s' (F_c⁺ (1 + 2s) + F_c⁻ (1 − 2s))/2``.
        """
        if self._urdf_terms is not None:  # the URDF's law: F_v + F_c sech²(v / v_s) / v_s
            t = np.tanh(np.asarray(v, dtype=float) / COULOMB_SMOOTHING_VELOCITY)
            return self.viscous + self._urdf_terms / COULOMB_SMOOTHING_VELOCITY * (1.0 - t**2)
        out = np.array(np.broadcast_to(self.viscous, np.shape(v)), dtype=float)
        if not self.has_coulomb:
            return out
        vs, vst = self.smoothing, self.stribeck_velocity
        s = np.tanh(v / vs)
        ds = (1.0 - s * s) / vs  # sech², no overflow
        cp, cn = self.coulomb_pos, self.coulomb_neg
        if self._symmetric:
            c, dc = cp * s, cp / vs * (1.0 - s * s)
        else:
            c = 0.5 * (cp * s * (1.0 + s) + cn * s * (1.0 - s))
            dc = 0.5 * ds * (cp * (1.0 + 2.0 * s) + cn * (1.0 - 2.0 * s))
        if not np.any(vst):
            return np.asarray(out + dc)
        on = vst > 0
        safe = np.where(on, vst, 1.0)
        e = np.where(on, np.exp(-np.square(v / safe)), 0.0)
        de = np.where(on, -2.0 * v / safe**2 * e, 0.0)
        return np.asarray(out + (1.0 - e) * dc - de * c + self.static * (de * s + e * ds))

    def slope_bound(self, v_near: Vector) -> Vector:
        """The largest ``|∂f/∂v|`` over ``|v| ≥ v_near`` (per coordinate, ``v_near ≥ 0``):
        what bounds the stiffness friction adds (:func:`pinobs.model.integrators.friction_substeps`).

        The URDF's law is steepest at its nearest velocity (``sech²`` falls with ``|v|``):
        ``|f'(v_near)|``, exactly.  Other laws are not monotone in ``|v|`` (an asymmetric
        step's slope ``s'(1 ± 2s)/2`` peaks at ``|v| ≈ 0.47 v_s``, a Stribeck term's where
        ``e'`` does, ``|v| = v_st/√2``): the largest ``|f'|`` at ``±(v_near + d)``, ``d`` on
        a geometric grid of :data:`SLOPE_POINTS` points from 0.01 to 3 times the law's
        velocity scales, times :data:`SLOPE_MARGIN` (measured on 300 random laws: the grid's
        maximum is within 2 % of a fine sweep's).
        """
        v_near = np.abs(np.asarray(v_near, dtype=float))
        if self.is_urdf:
            return np.asarray(self.force_derivative(v_near))
        scale = np.where(
            self.stribeck_velocity > 0,
            np.minimum(self.smoothing, self.stribeck_velocity),
            self.smoothing,
        )
        top = 3.0 * np.maximum(self.smoothing, self.stribeck_velocity)
        k = np.linspace(0.0, 1.0, SLOPE_POINTS)[:, None]
        d = 0.01 * scale * (top / (0.01 * scale)) ** k
        v = np.vstack([v_near[None, :] + 0.0 * d[:1], v_near + d])
        slope = np.maximum(np.abs(self.force_derivative(v)), np.abs(self.force_derivative(-v)))
        return np.asarray(SLOPE_MARGIN * slope.max(axis=0))

    def dissipates(self) -> bool:
        """Whether ``f(v) v ≥ 0`` for every ``v``: no offset (the coefficients are ``≥ 0``)."""
        return not np.any(self.offset)

    # ------------------------------------------------------------ storage
    def as_dict(self, index: int) -> dict[str, Any]:
        """The law of coordinate ``index`` as JSON-ready numbers (the sidecar's entry)."""
        out: dict[str, Any] = {"law": self.law}
        for f in fields(self):
            if f.name != "law":
                out[f.name] = float(getattr(self, f.name)[index])
        return out

    def with_coordinate(self, index: int, entry: dict[str, Any]) -> FrictionLaw:
        """A copy with coordinate ``index`` set from an :meth:`as_dict` entry (keys checked).

        Raises:
            GainError: a key is missing or unknown, or a value not a finite number.
        """
        names = [f.name for f in fields(self) if f.name != "law"]
        unknown = sorted(set(entry) - {*names, "law"})
        missing = sorted(set(names) - set(entry))
        if unknown or missing:
            raise GainError(
                f"friction entry {entry!r}: unknown keys {unknown}, missing {missing}; "
                f"give law and {', '.join(names)}"
            )
        values: dict[str, Any] = {}
        for name in names:
            x = entry[name]
            if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x):
                raise GainError(f"friction {name}={x!r} must be a finite number")
            arr = np.array(getattr(self, name), dtype=float)
            arr[index] = float(x)
            values[name] = arr
        return FrictionLaw(**values, law=str(entry.get("law", self.law)))

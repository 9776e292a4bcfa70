"""What an identification returns: named parameters (:class:`ParameterSet`), the fit's
:class:`Report` and the :class:`Identification` (calibrated robot, parameters, offset,
report)."""

from __future__ import annotations

from collections.abc import Iterator, MutableMapping
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pinobs.model.robot import Robot, Vector

if TYPE_CHECKING:
    from pinobs.model.identification.regressor import MomentumRegressor

__all__ = ["Identification", "ParameterSet", "Report"]


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


#: The :class:`Report` fields that are keys only when set (not ``None``).
OPTIONAL_KEYS = ("payload", "friction_law")


@dataclass(eq=False)
class Report(MutableMapping[str, Any]):
    """The fit diagnostics of :func:`~pinobs.model.identification.identify`, typed fields that
    also read and write as a mapping: ``report["rows"]`` is ``report.rows``, ``dict(report)``
    has the keys in the order below (``payload`` first when set, ``friction_law`` and
    ``warnings`` last), and a key that is not a field (``pinobs.identify``'s
    ``velocities``, ``noise_std``, ``smoother_consistency``) is kept in :attr:`extra`, after
    them.  Per-coordinate lists have one entry per velocity coordinate (:attr:`coordinates`).

    Attributes:
        residual_before: per coordinate, the RMS of the weighted rows on the fitted part with
            the nominal parameters (rad/s²-like; N·m with ``weighting="torque"``).
        residual_after: the same with the identified ones.
        unexplained: per coordinate, the fraction of the torque side the fit leaves, robust
            RMS of ``Aθ − y`` over that of ``y`` (NaN where excluded, or for a payload).
        unexplained_floor: what noise alone would leave
            (:func:`~pinobs.model.identification.diagnostics.unexplained_shares`).
        outlier_windows: end times [s] of windows the fit leaves mostly unexplained.
        holdout_before: per coordinate, the weighted rows' RMS on the held-out end, nominal.
        holdout_after: the same, identified.
        holdout_torque_before: the held-out windows' mean torque residual RMS per coordinate
            [N·m; N for a prismatic joint], whatever the weighting, nominal (for a payload:
            the robot without it).
        holdout_torque_after: the same, identified.
        weighting: ``"inertia"`` or ``"torque"``.
        excluded: the coordinates whose torques were left out.
        torque_sigma: per coordinate, its channel's residual scale [N·m, N]; NaN when
            excluded or with ``weighting="inertia"``.
        condition: condition number of the base regressor.
        rank: number of identifiable combinations.
        n_parameters: number of parameters.
        base: names of the identifiable combinations' pivots.
        not_excited: parameters the data did not fix (near nominal unless physical
            consistency moved them).
        moved_by_consistency: those of them physical consistency moved by more than half
            their prior standard deviation.
        projected: whether physical consistency moved the solution.
        rows: rows fitted.
        torque: how ``∫τ dt`` was taken, ``"held"`` or ``"sampled"``.
        holdout_rows: rows held out.
        fit_end: the last time of the fitted part [s].
        sigma: the robust residual scale of the weighted rows.
        filled_rows: NaN rows interpolated
            (:func:`~pinobs.model.identification.rows.fill_short_gaps`).
        joints: the robot's joint names.
        coordinates: a name per velocity coordinate (``<joint>.<k>`` for a joint of several).
        observer_options: what to give ``ekf`` on the calibrated model
            (``accel_psd=1e-6``, ``disturbance_psd=1e-4``: a calibrated model is good, not
            exact; the default ``ekf`` trusts it as if it were exact, and was 1.3–30× less
            accurate for it in ``benchmarks/learning.py``).
        warnings: what the data say against the fit
            (:func:`~pinobs.model.identification.diagnostics.fit_warnings`).
        friction_law: the friction law fitted and its velocities per actuated joint [rad/s]
            (a key only when friction was identified).
        payload: a payload's mass [kg], centre of mass [m, in its frame] and rotational
            inertia about it [kg·m², in the frame's axes] (a key only for
            ``identify(..., payload=...)``).
        extra: keys set that are not fields, in the order they were set.
    """

    residual_before: list[float]
    residual_after: list[float]
    unexplained: list[float]
    unexplained_floor: list[float]
    outlier_windows: list[float]
    holdout_before: list[float]
    holdout_after: list[float]
    holdout_torque_before: list[float]
    holdout_torque_after: list[float]
    weighting: str
    excluded: list[str]
    torque_sigma: list[float]
    condition: float
    rank: int
    n_parameters: int
    base: list[str]
    not_excited: list[str]
    moved_by_consistency: list[str]
    projected: bool
    rows: int
    torque: str
    holdout_rows: int
    fit_end: float
    sigma: float
    filled_rows: int
    joints: list[str]
    coordinates: list[str]
    observer_options: dict[str, float]
    warnings: list[str] = field(default_factory=list)
    friction_law: dict[str, Any] | None = None
    payload: dict[str, Any] | None = None
    extra: dict[str, Any] = field(default_factory=dict, repr=False)

    def _fields(self) -> tuple[str, ...]:
        return tuple(f.name for f in fields(self) if f.name != "extra")

    def _keys(self) -> list[str]:
        """The keys, in order: ``payload`` if set, the fields, ``friction_law`` if set,
        ``warnings``, then :attr:`extra`'s."""
        core = [k for k in self._fields() if k not in (*OPTIONAL_KEYS, "warnings")]
        head = ["payload"] if self.payload is not None else []
        tail = ["friction_law"] if self.friction_law is not None else []
        return [*head, *core, *tail, "warnings", *self.extra]

    def __getitem__(self, key: str) -> Any:
        if key in self.extra:
            return self.extra[key]
        if key in self._fields() and not (key in OPTIONAL_KEYS and getattr(self, key) is None):
            return getattr(self, key)
        raise KeyError(key)

    def __setitem__(self, key: str, value: Any) -> None:
        if key in self._fields():
            setattr(self, key, value)
        else:
            self.extra[key] = value

    def __delitem__(self, key: str) -> None:
        if key in self.extra:
            del self.extra[key]
        elif key in OPTIONAL_KEYS and getattr(self, key) is not None:
            setattr(self, key, None)
        elif key in self._fields():
            raise TypeError(f"{key!r} is a field every report has; it cannot be removed")
        else:
            raise KeyError(key)

    def __iter__(self) -> Iterator[str]:
        return iter(self._keys())

    def __len__(self) -> int:
        return len(self._keys())


@dataclass(frozen=True)
class Identification:
    """What :func:`identify` learned from a log.

    Attributes:
        robot: the calibrated :class:`Robot` (identified inertials and armature, friction
            on when identified); the torque offset is not part of it.
        parameters: every parameter with its standard deviation.
        offset: the identified torque offset per velocity coordinate [N·m].
        report: fit diagnostics (:class:`Report`; read as a mapping too).
        regressor: the :class:`MomentumRegressor` used (its ``names`` order).
    """

    robot: Robot
    parameters: ParameterSet
    offset: Vector
    report: Report
    regressor: MomentumRegressor = field(repr=False)

    def save(self, path: str) -> str:
        """Write the calibrated robot as a URDF, its armature in a sidecar file beside it
        (:func:`pinobs.model.urdf_writer.write_urdf`); returns the URDF's path."""
        from pinobs.model.urdf_writer import write_urdf

        return write_urdf(self.robot, path)

"""What an identification returns: named parameters (:class:`ParameterSet`) and the
:class:`Identification` (calibrated robot, parameters, offset, report)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pinobs.model.robot import Robot, Vector

if TYPE_CHECKING:
    from pinobs.model.identification.regressor import MomentumRegressor

__all__ = ["Identification", "ParameterSet"]


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

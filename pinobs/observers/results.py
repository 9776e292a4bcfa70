"""What an observer hands out: the estimate at one time and the consistency of its innovations."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["CONSISTENCY_WINDOW", "LIKELY_CAUSES", "Consistency", "Estimate"]

Vector = NDArray[np.floating[Any]]


@dataclass(frozen=True, init=False)
class Estimate:
    """An observer's estimate at one time.

    Attributes:
        t: time [s].
        q: estimated configuration, shape ``(nq,)`` (read-only).
        v: estimated velocity, shape ``(nv,)`` (read-only), Pinocchio's tangent frame.
        nis: normalized innovation squared ``eᵀ S⁻¹ e`` of this sample's
            measurement (``S`` the predicted innovation covariance; χ² with
            ``nv`` degrees of freedom when the model and noise level are
            right), or ``None`` (no covariance, or no measurement).
        gated: the measurement was rejected as an outlier (the estimate is the prediction).
    """

    t: float
    q: Vector
    v: Vector
    nis: float | None = None
    gated: bool = False

    def __init__(
        self, t: float, q: Vector, v: Vector, nis: float | None = None, gated: bool = False
    ) -> None:
        # the __init__ a frozen dataclass generates sets each field through
        # object.__setattr__; writing the instance's dict costs half (an Estimate is built
        # at every update of every observer; issue 39)
        d = self.__dict__
        d["t"], d["q"], d["v"], d["nis"], d["gated"] = t, q, v, nis, gated


@dataclass(frozen=True)
class Consistency:
    """Does the model explain the data?  A windowed test of the normalized innovation squared.

    Over the last ``samples`` measurements the mean NIS of a consistent filter
    is χ²(n·nv)/n: expectation ``expected`` (= nv), standard deviation
    ``√(2 nv / n)``.  ``verdict`` is ``"consistent"`` below ``bound`` (the
    expectation plus five standard deviations, plus 50 %: filters are tuned,
    not exact), ``"inconsistent"`` above it, ``"unknown"`` without a covariance
    or with fewer than 50 samples.

    Attributes:
        samples: measurements in the window.
        mean_nis: their mean NIS (NaN if none).
        expected: its expectation for a consistent filter (``nv``).
        bound: the threshold of the verdict.
        verdict: ``"consistent"``, ``"inconsistent"`` or ``"unknown"``.
        gated: measurements rejected as outliers since the reset.
        causes: what usually makes a model-based filter inconsistent (when it is).
        details: family-specific diagnostics (an adaptive observer's learning).
    """

    samples: int
    mean_nis: float
    expected: float
    bound: float
    verdict: str
    gated: int = 0
    causes: tuple[str, ...] = ()
    details: dict[str, Any] = field(default_factory=dict)

    def messages(self, name: str) -> list[str]:
        """What to tell of observer ``name``: a ``warning:`` line when the model does not
        explain the data, a ``note:`` line when outlier samples were rejected."""
        out = []
        if self.verdict == "inconsistent":
            out.append(
                f"warning: {name}: the model does not explain the data (mean NIS "
                f"{self.mean_nis:.3g} over the last {self.samples} samples, expected "
                f"{self.expected:g}); check " + "; ".join(self.causes)
            )
        if self.gated and self.details.get("soft_gate"):
            out.append(
                f"note: {name} down-weighted {self.gated} outlier sample(s) (its soft gate: the "
                "gain K/α, α = NIS / limit)"
            )
        elif self.gated:
            out.append(f"note: {name} rejected {self.gated} outlier sample(s)")
        return out

    def as_dict(self) -> dict[str, Any]:
        """Plain values, for JSON."""
        return {
            "samples": self.samples,
            "mean_nis": self.mean_nis,
            "expected": self.expected,
            "bound": self.bound,
            "verdict": self.verdict,
            "gated": self.gated,
            "causes": list(self.causes),
            **self.details,
        }


#: What to check when a model-based filter's innovations are too large (Consistency.causes).
LIKELY_CAUSES = (
    "link masses or inertias (a payload, CAD values): try `pinobs identify` (or the adaptive "
    "observer, which learns them)",
    "joint friction not in the model (URDF <dynamics>, load(..., friction=True))",
    "torque units or scale (gear ratios, motor constants, N·m vs mN·m), or a torque offset",
    "a measurement latency (give latency= if it is known)",
    "the noise level (noise_std smaller than the sensor's)",
)

#: Measurements in the consistency window.
CONSISTENCY_WINDOW = 1000

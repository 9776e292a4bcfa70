"""The feet's NIS over the stance rows of a contact-aided filter's run (issue 38).

:func:`stance_consistency` (re-exported by :mod:`pinobs.observers.legs`, where it was).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from pinobs.errors import DimensionError
from pinobs.observers.results import Consistency

__all__ = ["LEG_CAUSES", "NIS_INTERVAL", "stance_consistency"]


#: What to check when the feet's innovations are not χ² (:func:`stance_consistency`).
LEG_CAUSES = (
    "the foot noise levels (InEKFGains.contact, kinematics, joint): NIS/dof far below 1 "
    "while standing says they are too large",
    "contact detection: a foot flagged in contact while it lands or lifts (or slips) gives "
    "large NIS near the contact changes (contacts='probability', foot_gate=)",
    "the IMU's frame or units (--imu-frame; m/s² and rad/s)",
)
#: The two-sided probability of the per-row interval :func:`stance_consistency` counts.
NIS_INTERVAL = 0.95


def stance_consistency(nis: ArrayLike, dof: ArrayLike, gated: int = 0) -> Consistency:
    """The feet's NIS over the stance rows of a run: a :class:`Consistency` per degree of freedom.

    A row with feet measured (``dof = 3 × feet > 0``, the estimates' ``nis_dof``) has, for a
    consistent filter, ``NIS ~ χ²(dof)`` (Bar-Shalom, Li, Kirubarajan, *Estimation with
    Applications to Tracking and Navigation*, 2001, §5.4): so ``NIS/dof`` has mean 1, and
    each row falls inside ``[χ²_dof(2.5 %), χ²_dof(97.5 %)]`` with probability
    :data:`NIS_INTERVAL`.  Reported: ``mean_nis`` the mean of ``NIS/dof`` (``expected`` 1,
    ``bound`` as :class:`Consistency` puts it for ``Σ dof`` degrees of freedom, and a
    ``lower_bound`` likewise below 1: a mean far below 1 is a filter whose noise is too
    large, "inconsistent" too), ``gated`` the feet rejected by the foot gate, and in
    ``details`` the fractions of stance rows inside, below and above their interval, the
    median ``NIS/dof`` and the interval's probability.

    Raises:
        DimensionError: ``nis`` and ``dof`` of different shapes.
    """
    from scipy.stats import chi2

    z, k = np.asarray(nis, dtype=float), np.asarray(dof, dtype=float)
    if z.shape != k.shape or z.ndim != 1:
        raise DimensionError(f"nis {z.shape} and dof {k.shape} must be one row each")
    stance = (k > 0) & np.isfinite(z)
    n = int(stance.sum())
    if n == 0:
        return Consistency(0, math.nan, 1.0, math.nan, "unknown")
    z, k = z[stance], k[stance]
    r, tail = z / k, 0.5 * (1.0 - NIS_INTERVAL)
    dofs, at = np.unique(k, return_inverse=True)  # (a handful of dofs: each ppf once)
    lo, hi = chi2.ppf(tail, dofs)[at], chi2.ppf(1.0 - tail, dofs)[at]
    mean = float(r.mean())
    spread = 5.0 * math.sqrt(2.0 / float(k.sum()))  # five σ of the mean of NIS/dof
    bound, lower = 1.5 * (1.0 + spread), (1.0 - spread) / 1.5
    verdict = "unknown" if n < 50 else ("consistent" if lower <= mean <= bound else "inconsistent")
    details = {
        "per_dof": True,
        "lower_bound": lower,
        "interval": NIS_INTERVAL,
        "inside": float(np.mean((z >= lo) & (z <= hi))),
        "below": float(np.mean(z < lo)),
        "above": float(np.mean(z > hi)),
        "median_per_dof": float(np.median(r)),
    }
    causes = LEG_CAUSES if verdict == "inconsistent" else ()
    return Consistency(n, mean, 1.0, bound, verdict, gated, causes, details)

"""``adaptive``'s blend with its bank of ``kf`` filters on vector joints, compiled
(:mod:`pinobs.observers.adaptive` module docstring, 3).
:meth:`~pinobs.observers.adaptive.AdaptiveEKF.step` runs it, or the same equations in NumPy
on Lie-group joints (tested equal); :func:`lost_filter`: when the model-based filter is lost
for the blend.
"""

from __future__ import annotations

import math

import numpy as np

from pinobs.observers.base import Vector
from pinobs.observers.ekf import EKFState
from pinobs.observers.linalg import LazyKernel

__all__ = ["JERK_PSD", "blend_kernel", "blend_loops", "lost_filter"]

#: The bank's white-jerk densities [rad²/s⁵] (:mod:`pinobs.observers.adaptive` module
#: docstring, 3).  1e1 … 1e5 until the UR10e logs (~95 Hz, positions printed to 1e-4 rad, ``benchmarks/real_logs.py``), where
#: the best fixed ``kf`` density is 1e-2 … 1: with the bank's floor at 1e1 the blend's
#: model-free side alone was 3.0× the ``kf``'s RMS (0.027 against 0.0092 rad/s on
#: ur-19_09_27-11_32_02, its model-based filter lost and restarted all along, weight 0),
#: with 1e-2 … 1e5 1.13× (0.0104); the simulated learning table is unchanged.
JERK_PSD: tuple[float, ...] = tuple(float(10.0**k) for k in range(-2, 6))


def lost_filter(ekf: EKFState) -> bool:
    """Whether a model-based filter state's estimate or covariance holds NaN or ±inf, or its
    velocity's square overflows: the blend squares it (a UR10e log, a filter at 1e207 rad/s:
    the blend's ``s`` became ``inf − inf``, the estimate NaN, and :func:`pinobs.estimate`
    re-initialised the whole observer mid-log)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return not math.isfinite(float(ekf.v @ ekf.v) + ekf.P.sum())


def blend_loops(
    score: Vector,
    innovation: Vector,
    measured: bool,
    lam: float,
    bank_q: Vector,
    bank_v: Vector,
    bank_P: Vector,
    q: Vector,
    v: Vector,
    s: Vector,
    blame: float,
) -> tuple[Vector, Vector, Vector, Vector]:
    """The blend of :meth:`AdaptiveEKF.step` on vector joints, in loops (compiled by numba).

    Per coordinate ``i``: the scores ``score ← score + λ(e² − score)`` (if ``measured``),
    the filter ``b`` of the least score, ``v_kf = v_b``, ``P_kf = P_b,11``,
    ``s ← s + λ(blame · max((v − v_kf)² − P_kf, 0) − s)``, ``w = P_kf / (P_kf + s)``,
    ``v̂ = w v + (1 − w) v_kf``, ``q̂ = q + (1 − w)(q_b − q)`` (module docstring).
    Returns new arrays ``(score, s, q̂, v̂)``.
    """
    nf, nv = score.shape
    score_out = score.copy()
    if measured:
        for f in range(nf):
            for i in range(nv):
                score_out[f, i] = score[f, i] + lam * (innovation[f, i] ** 2 - score[f, i])
    s_out = np.empty(nv)
    q_out = np.empty(nv)
    v_out = np.empty(nv)
    for i in range(nv):
        b = 0
        for f in range(1, nf):
            if score_out[f, i] < score_out[b, i]:
                b = f
        p_kf = bank_P[b, 1, 1]
        d = v[i] - bank_v[b, i]
        s_out[i] = s[i] + lam * (blame * max(d * d - p_kf, 0.0) - s[i])
        w = p_kf / (p_kf + s_out[i] + 1e-300)
        v_out[i] = w * v[i] + (1.0 - w) * bank_v[b, i]
        q_out[i] = q[i] + (1.0 - w) * (bank_q[b, i] - q[i])
    return score_out, s_out, q_out, v_out


#: :func:`blend_loops` compiled (loaded when a blending ``adaptive`` on vector joints is made).
blend_kernel = LazyKernel(
    blend_loops,
    np.zeros((1, 1)), np.zeros((1, 1)), True, 0.5, np.zeros((1, 1)), np.zeros((1, 1)),
    np.tile(np.eye(3), (1, 1, 1)), np.zeros(1), np.zeros(1), np.zeros(1), 0.5,
)  # fmt: skip

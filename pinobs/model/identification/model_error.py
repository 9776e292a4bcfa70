"""The identified model's own acceleration error, as a white-noise density
(:func:`acceleration_error_psd`): what ``pinobs.identify`` stores on the robot it returns
(:attr:`pinobs.model.Robot.model_error_psd`) and what the model-based observers take as their
model-error density when given none (issue 36).

On the fitted rows of each stretch, ``e_k = a_model(q̂_k, v̂_k, τ_k + b) − â_k``:
``a_model`` the identified robot's forward dynamics (friction included,
:meth:`~pinobs.model.Robot.forward_dynamics`), ``b`` the identified torque offset,
``(q̂, v̂, â)`` the zero-phase Savitzky–Golay fit of the positions (polynomial of degree 4 over
``2·half_window + 1`` samples, its value and first two derivatives: the fit the
identification's own velocities come from, :func:`~pinobs.model.identification.smooth_path`).
The first and last ``half_window`` samples of a stretch (the edge polynomial's) are left out.
Off a uniform grid (a log's dropped or repeated rows left out) the same fit in real time
(:func:`~pinobs.model.identification.savgol.local_polynomial`).

**Conversion to a density** (the sampled-data contract, MATH §7).  The EKF's prediction over a
step ``h`` adds the velocity variance ``ψ h`` (:func:`~pinobs.observers.ekf_state.double_integrator_noise`);
an acceleration error white at the sample rate, of variance ``E[e²]``, adds ``h² E[e²]``.
Equal when::

    ψ_j = mean_k(e_{k,j}²) · h̄,        ψ = mean_j ψ_j

(``h̄`` the median interval), per joint and its mean over the joints (``ekf``'s ``accel_psd`` is
one number): the conversion ``benchmarks/real_ekf_phases.py``'s ``matched_accel_psd`` used on
one-step errors.  An error that is slow (correlated over many steps) is under-counted by it:
that density is a floor, not the whole model error.

**Floor.**  With an exact model, ``e = a − â`` is the fit's own error: its noise, of variance
``σ² Σ c₂²`` (``c₂`` the second-derivative coefficients, σ the position noise: the density
:func:`noise_floor_psd`), plus its smoothing bias on a fast motion (planar_3r's ``pd``
tracking, exact model: 1.07e-5 rad²/s³ in all at σ = 1e-4 against the noise's 8.4e-6;
1.2e-6 at σ = 1e-5 and 1e-6, where the bias is all of it).
"""

from __future__ import annotations

import math

import numpy as np

from pinobs.errors import IdentificationError
from pinobs.model.identification.savgol import local_polynomial
from pinobs.model.robot import Robot, Vector
from pinobs.model.sampling import is_uniform

__all__ = ["acceleration_error_psd", "noise_floor_psd"]


def acceleration_error_psd(
    robot: Robot,
    log: tuple[Vector, Vector, Vector],
    *,
    rows: Vector | None = None,
    offset: Vector | None = None,
    half_window: float = 0.05,
    order: int = 4,
) -> tuple[float, list[float]]:
    """``(ψ, ψ_j)`` [rad²/s³ or m²/s³]: ``robot``'s acceleration error on ``log = (t, q, tau)``
    as a white-noise density, its mean over the joints and per joint (module docstring);
    ``(nan, [nan…])`` when no stretch has enough rows.

    Args:
        rows: the rows to use (a boolean mask; default all): contiguous runs of them are the
            stretches (a row left out breaks one).
        offset: a torque offset added to ``tau`` [N·m or N] (the identified ``b``).
        half_window: half-width of the Savitzky–Golay fit [s].
        order: its polynomial degree.
    """
    from scipy.signal import savgol_filter  # lazily (0.45 s CPU: savgol.smooth_path's rule)

    from pinobs.model.identification.rows import segments

    t, q, tau = (np.asarray(x, dtype=float) for x in log)
    if offset is not None:
        tau = tau + np.asarray(offset, dtype=float)
    keep = np.ones(t.shape, bool) if rows is None else np.asarray(rows, bool)
    sq: list[Vector] = []
    hs: list[float] = []
    for seg in segments(np.where(keep, t, np.nan), q, tau):
        ts = t[seg]
        h = float(np.median(np.diff(ts)))
        hw = max(2, round(half_window / h))
        length = 2 * hw + 1
        if ts.shape[0] < length + 2 * hw:
            continue
        qs = q[seg]
        if robot.is_vector_space:
            u = qs - qs[0]
        else:
            steps = [robot.difference(qs[k - 1], qs[k]) for k in range(1, len(qs))]
            u = np.concatenate([np.zeros((1, robot.nv)), np.cumsum(steps, axis=0)])
        if is_uniform(ts, h):
            deg = min(order, length - 1)
            u_s, v, a = (
                savgol_filter(u, length, deg, deriv=d, delta=h, axis=0, mode="interp")
                for d in (0, 1, 2)
            )
        else:
            try:
                u_s, v, a = local_polynomial(ts, u, hw * h, order, 0.5 * h)
            except IdentificationError:  # a row alone in its window: no fit there
                continue
        inner = range(hw, len(ts) - hw)  # (the edge polynomial's rows left out)
        e = np.empty((len(inner), robot.nv))
        for i, k in enumerate(inner):
            qk = (
                qs[k] + (u_s[k] - u[k])
                if robot.is_vector_space
                else robot.integrate(qs[k], u_s[k] - u[k])
            )
            e[i] = robot.forward_dynamics(qk, v[k], tau[seg][k]) - a[k]
        sq.append(e**2)
        hs.append(h)
    if not sq:
        return math.nan, [math.nan] * robot.nv
    e2 = np.vstack(sq)
    per_joint = e2.mean(axis=0) * float(np.median(hs))  # ψ_j = mean(e²)·h̄ (module docstring)
    ok = np.isfinite(per_joint)
    psd = float(per_joint[ok].mean()) if ok.any() else math.nan
    return psd, [float(x) for x in per_joint]


def noise_floor_psd(
    noise_std: float, h: float, *, half_window: float = 0.05, order: int = 4
) -> float:
    """``σ² Σ c₂² · h`` [rad²/s³]: the density :func:`acceleration_error_psd` measures on an
    exact model from the position noise alone (``c₂`` the Savitzky–Golay second-derivative
    coefficients of its fit at the interval ``h`` [s]; σ ``noise_std`` [rad or m])."""
    from scipy.signal import savgol_coeffs

    hw = max(2, round(half_window / h))
    c2 = savgol_coeffs(2 * hw + 1, min(order, 2 * hw), deriv=2, delta=h)
    return float(noise_std**2 * np.sum(c2**2) * h)

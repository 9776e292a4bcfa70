"""Zero-phase Savitzky–Golay velocities of a measured path (:func:`smooth_path`), on a
uniform grid or in real time on an uneven one (:mod:`pinobs.model.sampling`)."""

from __future__ import annotations

import functools
import math
import sys

import numpy as np

from pinobs.errors import IdentificationError
from pinobs.model.robot import Robot, Vector
from pinobs.model.sampling import is_uniform

__all__ = ["convolve_nearest", "local_polynomial", "savgol_coefficients", "smooth_path"]


def smooth_path(
    robot: Robot,
    t: Vector,
    q: Vector,
    *,
    half_window: int,
    order: int = 4,
    edges: bool = True,
) -> tuple[Vector, Vector]:
    """Zero-phase Savitzky–Golay estimates ``(q_s, v)`` of a sampled path.

    The path is developed into the tangent space, ``u_k = u_{k−1} + difference(q_{k−1}, q_k)``
    (for vector joints ``u = q − q₀``); ``u`` is fitted by a polynomial of
    degree ``order`` over ``2·half_window + 1`` samples around each one
    (``scipy.signal.savgol_filter``), giving ``v = u̇`` and
    ``q_s = q_k ⊕ (û_k − u_k)``.  Near the ends the fit is the edge polynomial;
    ``edges=False`` skips those fits (the first and last ``half_window`` samples are
    then not meaningful, the others are the same: the online learner keeps only them).

    Off a uniform grid (dropped samples, irregular sampling: an interval more than
    :data:`~pinobs.model.sampling.UNIFORM_TOL` off the median ``h``) the same fit is made in
    real time (:func:`_local_polynomial`): over the rows within ``(half_window + ½)·h`` of
    each one (near the ends, of the time ``half_window·h`` from the end), as
    ``savgol_filter`` fits the rows of a uniform grid; ``edges`` is then ignored.
    """
    n = t.shape[0]
    length = 2 * half_window + 1
    h = float(np.median(np.diff(t))) if n > 1 else math.nan
    uniform = is_uniform(t, h)
    if n < length and (uniform or n <= order or t[-1] - t[0] < (length - 1.5) * h):
        raise IdentificationError(
            f"{n} samples are too few to smooth over {length}; give a longer log"
        )
    if robot.is_vector_space:
        u = q - q[0]
    else:
        steps = np.array([robot.difference(q[k - 1], q[k]) for k in range(1, n)])
        u = np.concatenate([np.zeros((1, robot.nv)), np.cumsum(steps, axis=0)])
    order = min(order, length - 1)
    if not uniform:
        u_s, v = _local_polynomial(t, u, half_window * h, order, 0.5 * h)
    elif edges:
        from scipy.signal import savgol_filter  # lazily: 0.45 s CPU (the learner: edges=False)

        v = savgol_filter(u, length, order, deriv=1, delta=h, axis=0, mode="interp")
        u_s = savgol_filter(u, length, order, axis=0, mode="interp")
    else:  # savgol_filter's convolutions, their coefficients computed once
        c_v, c_u = savgol_coefficients(length, order, h)
        v = convolve_nearest(u, c_v)
        u_s = convolve_nearest(u, c_u)
    if robot.is_vector_space:
        return q[0] + u_s, v
    q_s = np.array([robot.integrate(q[k], u_s[k] - u[k]) for k in range(n)])
    return q_s, v


def _local_polynomial(
    t: Vector, u: Vector, reach: float, order: int, slack: float
) -> tuple[Vector, Vector]:
    """``(û, u̇)`` at every row: the least-squares polynomial of degree ``order`` in time
    through the rows within ``reach + slack`` [s] of the row (near the ends, of the point
    ``reach`` from the end), and its derivative: the Savitzky–Golay fit on uneven times.
    The degree is lowered to fit the window with the fewest rows."""
    u_s, v, _ = local_polynomial(t, u, reach, order, slack)
    return u_s, v


def local_polynomial(
    t: Vector, u: Vector, reach: float, order: int, slack: float
) -> tuple[Vector, Vector, Vector]:
    """``(û, u̇, ü)``: :func:`_local_polynomial`'s fit and its second derivative (``0`` where
    the degree is below 2)."""
    n = t.shape[0]
    radius = reach + slack
    centre = np.clip(t, t[0] + reach, t[-1] - reach)
    lo = np.searchsorted(t, centre - radius, side="left")
    hi = np.searchsorted(t, centre + radius, side="right")
    span = int(np.max(hi - lo))
    fewest = int(np.min(hi - lo))
    if fewest < 2:
        raise IdentificationError(
            f"a gap in the log leaves a row alone within ±{radius:.3g} s: no slope to fit there "
            "(give a longer half window, or split the log at the gap)"
        )
    order = min(order, fewest - 1)  # a window the drops left with few rows: a lower degree
    u_s = np.empty_like(u)
    v = np.empty_like(u)
    acc = np.zeros_like(u)
    for a in range(0, n, 512):  # in blocks: (rows, span, order + 1) per block
        k = np.arange(a, min(a + 512, n))
        idx = lo[k, None] + np.arange(span)[None, :]
        inside = idx < hi[k, None]
        idx = np.minimum(idx, n - 1)
        x = (t[idx] - t[k, None]) / radius  # scaled to [-2, 2]: a well-conditioned Gram matrix
        design = np.cumprod(np.broadcast_to(x[..., None], (*x.shape, order + 1)), axis=2)
        design = np.concatenate([np.ones((*x.shape, 1)), design[..., :order]], axis=2)
        design *= inside[..., None]
        design_t = design.transpose(0, 2, 1)
        gram = design_t @ design
        rhs = design_t @ u[idx]
        fit = np.linalg.solve(gram, rhs)  # the coefficients; the first two: value and slope
        u_s[k], v[k] = fit[:, 0], fit[:, 1] / radius
        if order >= 2:
            acc[k] = 2.0 * fit[:, 2] / radius**2
    return u_s, v, acc


@functools.lru_cache(maxsize=16)
def savgol_coefficients(length: int, order: int, h: float) -> tuple[Vector, Vector]:
    """Savitzky–Golay convolution coefficients of ``u̇`` and ``u`` (:func:`smooth_path`)."""
    c_v = _savgol_coeffs(length, order, deriv=1, delta=h)
    c_u = _savgol_coeffs(length, order)
    c_v.setflags(write=False)
    c_u.setflags(write=False)
    return c_v, c_u


def _savgol_coeffs(length: int, order: int, deriv: int = 0, delta: float = 1.0) -> Vector:
    """``scipy.signal.savgol_coeffs(length, order, deriv, delta)`` for an odd ``length``
    (its centred, ``use="conv"`` coefficients), computed as it does, to the bit (tested):
    the least-squares ``c`` of ``A c = y``, ``A_ij = x_j^i`` with ``x`` the offsets
    ``length//2 … −length//2`` (reversed: convolution order), ``y = deriv!/δ^deriv · e_deriv``
    (Savitzky & Golay 1964; SciPy's ``_savitzky_golay.py``).  Here rather than SciPy's:
    ``scipy.signal`` costs 0.45 s CPU at import (issue 39: the adaptive learner's start-up).
    Solved by NumPy's ``lstsq``: LAPACK's ``dgelsd``, as ``scipy.linalg.lstsq``'s default
    driver, with the same cut-off (identical bits, tested; ``scipy.linalg``'s import cost
    ``adaptive``'s construction 0.13 s)."""
    pos = length // 2
    x = np.arange(-pos, length - pos, dtype=np.float64)[::-1]
    design = x ** np.arange(order + 1, dtype=np.float64).reshape(-1, 1)
    y = np.zeros(order + 1)
    y[deriv] = float(math.factorial(deriv)) / delta**deriv
    rcond = np.finfo(np.float64).eps * max(design.shape)
    return np.linalg.lstsq(design, y, rcond=rcond)[0]


def convolve_nearest(u: Vector, c: Vector) -> Vector:
    """``scipy.ndimage.convolve1d(u, c, axis=0, mode="nearest")`` for an odd-length ``c``, to
    the bit (tested): ``out_k = Σ_j c_j u_{k−j+m}`` (``m = len(c)//2``, ``u`` extended by
    its first and last rows), summed in SciPy's order: its ``NI_Correlate1D``
    (``ni_filters.c``) pairs the rows ``k ± j`` when the weights are (anti)symmetric to
    within ``DBL_EPSILON``, as Savitzky–Golay's are.  SciPy's when ``scipy.ndimage`` is
    imported already (the learner's worker process preloads it: 164 µs a window on a UR5
    against 265 µs here); otherwise not imported for it (0.06 s CPU: an observer's make)."""
    w = c[::-1]  # correlation weights
    n = w.shape[0]
    if n % 2 == 0:
        raise ValueError(f"convolve_nearest needs an odd number of weights, not {n}")
    ndimage = sys.modules.get("scipy.ndimage")
    if ndimage is not None:  # imported already (the learner's worker process): its C loop
        return np.asarray(ndimage.convolve1d(u, c, axis=0, mode="nearest"))
    half, m = n // 2, u.shape[0]
    eps = float(np.finfo(np.float64).eps)
    pairs = range(1, half + 1)
    sign = 0.0
    if all(abs(w[half + i] - w[half - i]) <= eps for i in pairs):
        sign = 1.0
    elif all(abs(w[half + i] + w[half - i]) <= eps for i in pairs):
        sign = -1.0
    pad = np.concatenate([np.repeat(u[:1], half, axis=0), u, np.repeat(u[-1:], half, axis=0)])

    def row(j: int) -> Vector:  # u_{k+j} for every k
        return pad[half + j : half + j + m]

    if sign == 0.0:
        out = row(half) * w[n - 1]
        for j in range(-half, half):
            out += row(j) * w[half + j]
        return out
    out = row(0) * w[half]
    for j in range(-half, 0):
        out += (row(j) + row(-j) if sign > 0 else row(j) - row(-j)) * w[half + j]
    return out

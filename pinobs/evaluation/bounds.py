"""Bounds on velocity accuracy when the reference itself is noisy.

Two tools for reading a benchmark whose "truth" is another estimate (a robot's own
velocity, a non-causal fit):

* :func:`three_cornered_hat`: three estimates ``X_i = x + e_i`` of one unknown signal
  ``x`` with mutually uncorrelated errors give each error's mean square from the
  three pairwise differences alone (Gray & Allan, *A method for estimating the
  frequency stability of an individual oscillator*, 1974):
  ``E[(X_i − X_j)²] = s_i + s_j`` ⇒ ``s_1 = (D_12 + D_13 − D_23) / 2`` (and cyclically),
  ``D_ij`` the mean square of ``X_i − X_j``.  With correlated errors ``s_1`` is off
  by ``c_23 − c_12 − c_13`` (``c_ij = E[e_i e_j]``); a negative result says the
  triple breaks the assumption, and is returned as such.
* :func:`second_difference_noise_std`: the white part of an estimate's error from the
  estimate alone, for a smooth signal sampled evenly:
  ``X_k − (X_{k−1} + X_{k+1})/2 = e_k − (e_{k−1} + e_{k+1})/2 + O(ẍ dt²)`` has variance
  ``1.5 σ²`` when ``e`` is white (σ² + 2·σ²/4), so ``σ = √(mean(r²)/1.5)``; a smooth
  (coloured) error part is not seen, the signal's curvature ``ẍ dt²/2`` adds to it.
* :func:`known_input_filter`: the per-coordinate Kalman filter of a double integrator
  driven by a *known* acceleration ``a(t)`` plus a white acceleration error of density
  ``accel_psd`` and a random-walk acceleration offset ``d`` of density
  ``disturbance_psd``::

      q̇ = v,   v̇ = a(t) + d + w_a,   ḋ = w_d,   y_k = q(t_k) + n_k,
      E[w_a w_a'] = s_a δ,   E[w_d w_d'] = s_d δ,   E[n²] = σ²,

  ``a`` taken linear between samples.  Given the true acceleration it is the
  best causal velocity estimate any model-based observer can reach with that
  sensor (an oracle); given a model's predicted acceleration, what that model's
  error allows.  With ``s_d = 0`` the offset stays 0 (a two-state filter).  With
  ``a = 0`` and ``s_a = 0`` it is the constant-acceleration filter (``d`` the
  acceleration, ``s_d`` its jerk density), and a model's acceleration ``â_k`` may then
  enter as a *measurement* of ``d``: ``â_k = d(t_k) + m_k``, ``E[m²] = σ_a²`` (a fusion
  that falls back to the model-free filter as ``σ_a → ∞``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pinobs.errors import DimensionError, GainError
from pinobs.model.robot import Vector

__all__ = [
    "KnownInputResult",
    "known_input_filter",
    "second_difference_noise_std",
    "three_cornered_hat",
]


def _as_2d(x: Vector, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2:
        raise DimensionError(f"{name} must be (rows,) or (rows, columns), got shape {a.shape}")
    return a


def three_cornered_hat(x1: Vector, x2: Vector, x3: Vector) -> tuple[Vector, Vector, Vector]:
    """Each estimate's error mean square, per column, from the pairwise differences.

    ``s_1 = (D_12 + D_13 − D_23)/2``, ``s_2 = (D_12 + D_23 − D_13)/2``,
    ``s_3 = (D_13 + D_23 − D_12)/2``, ``D_ij = mean((X_i − X_j)²)`` over the rows
    (Gray & Allan 1974; module docstring).  Rows where any estimate is not finite are
    left out.  Arrays ``(rows,)`` or ``(rows, columns)``, the same shape; returns three
    arrays ``(columns,)`` [the estimates' unit²], negative when the errors are correlated
    beyond what the differences can separate.
    """
    a, b, c = (_as_2d(x, n) for x, n in ((x1, "x1"), (x2, "x2"), (x3, "x3")))
    if not a.shape == b.shape == c.shape:
        raise DimensionError(f"three_cornered_hat: shapes differ: {a.shape}, {b.shape}, {c.shape}")
    ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1) & np.isfinite(c).all(axis=1)
    if ok.sum() < 2:
        raise DimensionError("three_cornered_hat needs at least 2 rows where all are finite")
    a, b, c = a[ok], b[ok], c[ok]
    d12, d13, d23 = (np.mean((u - w) ** 2, axis=0) for u, w in ((a, b), (a, c), (b, c)))
    # Gray & Allan (1974): the three-cornered hat
    return (d12 + d13 - d23) / 2, (d12 + d23 - d13) / 2, (d13 + d23 - d12) / 2


def second_difference_noise_std(x: Vector, t: Vector, *, rtol: float = 1e-3) -> Vector:
    """σ of the white part of ``x``'s error per column, from its evenly spaced triples.

    ``σ = √(mean(r_k²)/1.5)``, ``r_k = x_k − (x_{k−1} + x_{k+1})/2`` over the rows whose
    two neighbours are at the same distance in ``t`` to ``rtol`` relative (module
    docstring).  ``x`` (rows,) or (rows, columns), ``t`` (rows,) strictly increasing.
    """
    xx, tt = _as_2d(x, "x"), np.asarray(t, dtype=float)
    if tt.shape != (xx.shape[0],) or not np.all(np.diff(tt) > 0):
        raise DimensionError(f"t must be (rows,) = ({xx.shape[0]},) and strictly increasing")
    dt = np.diff(tt)
    even = np.abs(dt[1:] - dt[:-1]) <= rtol * dt[:-1]
    r = xx[1:-1] - (xx[:-2] + xx[2:]) / 2
    ok = even & np.isfinite(r).all(axis=1)
    if not ok.any():
        raise DimensionError("second_difference_noise_std: no evenly spaced finite triple")
    return np.sqrt(np.mean(r[ok] ** 2, axis=0) / 1.5)


@dataclass(frozen=True)
class KnownInputResult:
    """Output of :func:`known_input_filter`: velocity ``v`` (rows, n) at every row (the
    prediction where no measurement), the offset ``d`` (rows, n), and the innovations'
    negative log-likelihood per column ``nll`` (n,) (``½ Σ (ln 2πS + ν²/S)`` over the
    measured rows)."""

    v: np.ndarray
    d: np.ndarray
    nll: np.ndarray


def _discrete(dt: float, s_a: np.ndarray, s_d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(F, Q)`` of the module's model over ``dt`` (``Q`` per column, (n, 3, 3))."""
    f = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    qa = np.array([[dt**3 / 3, dt**2 / 2, 0.0], [dt**2 / 2, dt, 0.0], [0.0, 0.0, 0.0]])
    qd = np.array(
        [
            [dt**5 / 20, dt**4 / 8, dt**3 / 6],
            [dt**4 / 8, dt**3 / 3, dt**2 / 2],
            [dt**3 / 6, dt**2 / 2, dt],
        ]
    )
    return f, s_a[:, None, None] * qa + s_d[:, None, None] * qd


def _correct(
    x: np.ndarray, p: np.ndarray, y: np.ndarray, r: np.ndarray, i: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Kalman update of every column by the scalar measurement ``y = x[:, i] + noise``
    (variance ``r``); returns ``(x, p, nll)``, the innovation's negative log-likelihood
    (0 where ``r`` is infinite: no information)."""
    nu = y - x[:, i]
    s = p[:, i, i] + r
    gain = p[:, :, i] / s[:, None]
    x = x + gain * nu[:, None]
    p = p - gain[:, :, None] * p[:, i, None, :]
    nll = np.where(np.isfinite(s), 0.5 * (np.log(2 * np.pi * s) + nu * nu / s), 0.0)
    return x, (p + p.transpose(0, 2, 1)) / 2, nll


def _checked(
    t: Vector, q: Vector, a: Vector, am: Vector | None, gains: tuple
) -> tuple[np.ndarray, ...]:
    """``known_input_filter``'s inputs as arrays, refused with a clear error when bad."""
    tt = np.asarray(t, dtype=float)
    qq, aa = _as_2d(q, "q"), _as_2d(a, "a")
    rows, n = qq.shape
    if tt.shape != (rows,) or aa.shape != (rows, n):
        raise DimensionError(f"t {tt.shape}, q {qq.shape}, a {aa.shape}: need (rows,), (rows, n)")
    if rows < 2 or not np.all(np.diff(tt) > 0) or not np.isfinite(aa).all():
        raise DimensionError("t must be strictly increasing (≥ 2 rows) and a finite")
    sigma, s_a, s_d, s_m = (np.broadcast_to(np.asarray(x, dtype=float), (n,)).copy() for x in gains)
    if (sigma <= 0).any() or (s_a < 0).any() or (s_d < 0).any() or (s_m <= 0).any():
        raise GainError(
            f"noise_std > 0, densities ≥ 0, accel_noise_std > 0 needed: "
            f"{sigma}, {s_a}, {s_d}, {s_m}"
        )
    amm = np.full((rows, n), np.nan) if am is None else _as_2d(am, "accel_measurement")
    if am is not None and (amm.shape != (rows, n) or not np.isfinite(amm).all()):
        raise DimensionError(f"accel_measurement must be finite, (rows, n) = {(rows, n)}")
    return tt, qq, aa, amm, sigma, s_a, s_d, s_m


def known_input_filter(
    t: Vector,
    q: Vector,
    a: Vector,
    *,
    noise_std: float | Vector,
    accel_psd: float | Vector,
    disturbance_psd: float | Vector = 0.0,
    measured: Vector | None = None,
    v0: Vector | None = None,
    accel_measurement: Vector | None = None,
    accel_noise_std: float | Vector = math.inf,
) -> KnownInputResult:
    """Per-coordinate Kalman filter of ``q`` with the acceleration ``a`` known (module
    docstring for the model).

    Args:
        t: sample times [s], strictly increasing, (rows,).
        q: measured positions [rad or m], (rows, n).
        a: the known acceleration at each row [rad/s²], (rows, n); linear between rows
            (row k's input is used from ``t_k`` on: causal when ``a_k`` is known at ``t_k``).
        noise_std: σ of the position measurement [rad], scalar or (n,).
        accel_psd: ``s_a`` [rad²/s³], scalar or (n,), ≥ 0.
        disturbance_psd: ``s_d`` [rad²/s⁵], scalar or (n,), ≥ 0 (0: no offset state).
        measured: rows whose ``q`` is a measurement (default all); others only predict.
        v0: initial velocity (default 0; its variance is 1 [rad²/s²] either way).
        accel_measurement: a measurement ``â`` of the offset ``d`` at each row [rad/s²],
            (rows, n), used after ``q`` at the rows ``measured``; its innovations count
            in ``nll`` too.
        accel_noise_std: σ_a of ``accel_measurement`` [rad/s²], scalar or (n,), > 0.
    """
    tt, qq, aa, am, sigma, s_a, s_d, s_m = _checked(
        t, q, a, accel_measurement, (noise_std, accel_psd, disturbance_psd, accel_noise_std)
    )
    rows, n = qq.shape
    meas = np.ones(rows, bool) if measured is None else np.asarray(measured, bool)
    x = np.zeros((n, 3))
    x[:, 0] = qq[0]
    if v0 is not None:
        x[:, 1] = v0
    p = np.zeros((n, 3, 3))
    p[:, 0, 0], p[:, 1, 1], p[:, 2, 2] = sigma**2, 1.0, np.where(s_d > 0, 1.0, 0.0)
    v_out, d_out, nll = np.empty((rows, n)), np.empty((rows, n)), np.zeros(n)
    for k in range(rows):
        if k > 0:
            dt = tt[k] - tt[k - 1]
            f, qk = _discrete(dt, s_a, s_d)
            x = x @ f.T
            # a linear over [t_{k-1}, t_k]: ∫∫a = dt²(2a₀ + a₁)/6, ∫a = dt(a₀ + a₁)/2
            x[:, 0] += dt * dt * (2 * aa[k - 1] + aa[k]) / 6
            x[:, 1] += dt * (aa[k - 1] + aa[k]) / 2
            p = f @ p @ f.T + qk
        if meas[k]:
            x, p, e = _correct(x, p, qq[k], sigma**2, 0)  # H = [1 0 0]
            nll += e
            if accel_measurement is not None:  # independent, sequential: H = [0 0 1]
                x, p, e = _correct(x, p, am[k], s_m**2, 2)
                nll += e
        v_out[k], d_out[k] = x[:, 1], x[:, 2]
    return KnownInputResult(v=v_out, d=d_out, nll=nll)

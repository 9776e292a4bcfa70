"""Chunks and overlaps: how far back a window's backward pass must start to reproduce the
whole-log smoother (:func:`default_overlap`), and the window sizes in samples
(:func:`window_samples`)."""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from pinobs.errors import (
    ChunkWarning,
    CostWarning,
    GainError,
    OptionError,
)
from pinobs.model import Robot
from pinobs.observers.base import (
    GaussianFilter,
    Vector,
    positive,
)
from pinobs.observers.kf import KFGains
from pinobs.smoothing.constants import CHUNK_TOL, COST_WARN, OVERLAP_CONFIGURATIONS

__all__ = ["default_overlap", "spread_configurations", "window_samples"]


def default_overlap(
    accel_psd: float,
    meas_std: float,
    dt: float,
    tol: float = CHUNK_TOL,
    *,
    disturbance_psd: float | None = None,
    mass_matrices: Sequence[Vector] | None = None,
) -> float:
    """The overlap [s] after which a window's start-up error has decayed to ``tol`` of ``v_std``.

    The backward pass forgets its end condition at the rate of the steady-state
    filter's slowest pole (the smoother's backward dynamics has the mirror
    poles), hence ``overlap = ln(1/tol) / min |Re s|``.  The filter of a double
    integrator with white acceleration ``q_w`` [rad²/s³] measured with noise
    ``σ`` [rad] every ``h`` [s] (a noise density ``r = σ² h``) has the poles
    ``ω e^{±3iπ/4}``, ``ω = (q_w / r)^{1/4}``: ``overlap = √2 ln(1/tol) / ω``.

    With the EKF's torque-offset state (``disturbance_psd`` ``j`` [rad²/s⁵], a
    random walk converted per joint as ``j M̄ᵢᵢ²`` [N²·m²/s] with ``M̄`` the
    inertia at the filter's first sample, acting through ``M(q)⁻¹``) the
    offset's acceleration density is ``S = M⁻¹ diag(j M̄ᵢᵢ²) M⁻¹``.  In the
    eigenbasis of ``S`` (orthogonal, so the measurement and the white
    acceleration stay isotropic) each direction is a double integrator plus an
    acceleration bias of density ``λ`` (an eigenvalue of ``S``), the measured
    position's spectrum ``r + q_w/ω⁴ + λ/ω⁶``; the filter's poles are the
    left-half-plane roots of ``r s⁶ + q_w s² − λ = 0`` (its spectral factor).
    With ``u = s²`` the cubic ``r u³ + q_w u − λ`` has one positive root ``u₊``
    (a real pole, ``√u₊``, the offset's memory) and ``−u₊/2 ± i b`` with
    ``|u|² = λ / (r u₊)`` (the bandwidth's pair, ``Re s = √((|u| − u₊/2)/2)``).
    ``λ → 0``: the first case; ``q_w = 0``: third-order Butterworth poles,
    ``overlap = 2 ln(1/tol) / (λ/r)^{1/6}``.  The coupling of ``M`` matters: on
    a UR5 or a Panda the smallest ``λ`` is 0.07–0.1 ``j``, on the planar 3R
    0.02 ``j``, and the real pole ``≈ √(λ/q_w)`` then sets overlaps of 4–10 s
    where the isotropic ``λ = j`` gives 1.4 s (measured on a planar 3R's
    adaptive smoothing: 0.41 s of overlap left 3.2e-3 of ``v_std`` between the
    chunked and whole-log results, 9.45 s 5.5e-9).

    Args:
        mass_matrices: ``M(q)`` at configurations the log visits, the first at
            its first sample (``M̄``); ``None``: ``S = j I`` (the model-free
            ``kf``, white jerk ``jerk_psd``: ``accel_psd = 0``,
            ``disturbance_psd = jerk_psd``).  The overlap is the longest over
            them: the poles move with ``q`` and the time-varying filter is not
            the steady state of any of them (tested against the whole-log
            smoother, :mod:`tests.observers.test_smoothing`).
    """
    r = meas_std**2 * dt
    if accel_psd <= 0.0 and disturbance_psd is None:
        raise GainError(f"accel_psd={accel_psd!r} and no disturbance_psd: a filter without memory")
    if disturbance_psd is None:
        return math.sqrt(2.0) * math.log(1.0 / tol) / (accel_psd / r) ** 0.25
    if mass_matrices is None:
        densities = np.array([disturbance_psd])
    else:
        m_bar = np.diag(mass_matrices[0])
        densities = np.concatenate(
            [
                np.linalg.eigvalsh(_offset_density(m, disturbance_psd * m_bar**2))
                for m in mass_matrices
            ]
        )
    return math.log(1.0 / tol) / min(_slowest_pole(r, accel_psd, lam) for lam in densities)


def _offset_density(mass: Vector, torque_psd: Vector) -> Vector:
    """``M⁻¹ diag(torque_psd) M⁻¹``: a torque random walk's acceleration density."""
    m_inv = np.linalg.inv(mass)
    return (m_inv * torque_psd) @ m_inv


def _slowest_pole(r: float, q_w: float, lam: float) -> float:
    """``min |Re s|`` over the left-half-plane roots of ``r s⁶ + q_w s² − λ`` (:func:`default_overlap`)."""
    if lam <= 0.0:
        return 0.0  # an offset never driven: never forgotten
    if q_w <= 0.0:
        u = (lam / r) ** (1.0 / 3.0)
    else:  # the real root of u³ + p u − λ/r, p = q_w/r > 0 (trigonometric form: no cancellation)
        p = q_w / r
        u = (
            2.0
            * math.sqrt(p / 3.0)
            * math.sinh(math.asinh(1.5 * lam / (r * p) * math.sqrt(3.0 / p)) / 3.0)
        )
    pair = math.sqrt(lam / (r * u))  # |u| of the complex pair
    return min(math.sqrt(u), math.sqrt(max(pair - 0.5 * u, 0.0) / 2.0))


def spread_configurations(rows: Vector) -> Vector:
    """At most :data:`OVERLAP_CONFIGURATIONS` of ``rows``, evenly spaced, the first kept."""
    pick = np.linspace(0, len(rows) - 1, min(len(rows), OVERLAP_CONFIGURATIONS)).astype(int)
    return rows[np.unique(pick)]


def _samples(seconds: float, dt: float, what: str) -> int:
    positive(what, seconds)
    return max(1, math.ceil(seconds / dt - 1e-9))


def window_samples(
    filt: GaussianFilter,
    extra: Mapping[str, Any],
    accel_psd: float | str | None,
    chunk: float | None,
    overlap: float | None,
    lag: float | None,
    dt: float,
    meas_dt: float | None = None,
    *,
    robot: Robot,
    configurations: Vector,
    rows: int | None = None,
) -> tuple[int | None, int]:
    """``(chunk, overlap)`` in samples of ``dt`` [s] (``(None, 0)``: the whole log at once);
    the default overlap from the measurement interval ``meas_dt`` (default ``dt``; a re-timed
    log has rows between its measurements: :func:`retimed`) and, with a torque offset,
    ``robot``'s inertia at ``configurations`` (rows of ``q``, the first the filter's first:
    :func:`default_overlap`; ``adaptive``: the nominal model's inertia); ``rows``: the log's
    (``None``: streamed, not known), for the cost warning."""
    if lag is not None and (chunk is not None or overlap is not None):
        raise OptionError(
            f"lag={lag!r} sets the chunk and the overlap; give lag alone, or chunk and overlap"
        )
    if lag is not None:
        n = _samples(lag, dt, "lag")
        return n, n
    if chunk is None:
        if overlap is not None:
            raise OptionError(
                f"overlap={overlap!r} without chunk: the whole log is smoothed at once; give "
                "chunk too (or lag)"
            )
        return None, 0
    given = overlap
    # the longest memory: the smallest densities (adaptive: any window's)
    gains = filt.gains
    if isinstance(gains, KFGains):  # white jerk: the triple integrator alone
        pairs = [(0.0, gains.jerk_psd)]
    else:
        pairs = extra.get("model_densities") or [(gains.accel_psd, filt.disturbance_psd)]
    if isinstance(accel_psd, float) and not isinstance(gains, KFGains):
        # it replaces each window's, the offset's scaled
        pairs = [(accel_psd, None if d is None else d * accel_psd / a) for a, d in pairs]
    h = dt if meas_dt is None else meas_dt
    masses = None
    if not isinstance(gains, KFGains) and any(d is not None for _, d in pairs):
        masses = [robot.mass_matrix(q) for q in configurations]
    needed = max(
        default_overlap(a, gains.meas_std, h, disturbance_psd=d, mass_matrices=masses)
        for a, d in pairs
    )
    overlap = needed if given is None else given
    if overlap < needed:  # the backward error decays as exp(−rate·overlap): CHUNK_TOL at needed
        warnings.warn(
            ChunkWarning(
                f"overlap={overlap!r} s is shorter than the {needed:.3g} s over which the "
                f"filter's slowest mode decays to CHUNK_TOL = {CHUNK_TOL:g} (default_overlap): "
                f"chunked estimates can differ from the whole log's by the order of "
                f"{CHUNK_TOL ** (overlap / needed):.2g} of v_std at each chunk's end; give a "
                "longer overlap, or none (the default)"
            ),
            stacklevel=4,
        )
    n_chunk, n_over = _samples(chunk, dt, "chunk"), _samples(overlap, dt, "overlap")
    # every window's backward pass runs over its overlap (once over a log within one window)
    if n_over > COST_WARN * n_chunk and (rows is None or rows > n_chunk + n_over):
        warnings.warn(
            CostWarning(
                f"chunk={chunk!r} s with an overlap of {n_over * dt:.3g} s: the backward pass runs "
                f"{(n_chunk + n_over) / n_chunk:.0f}× over each sample, and the memory is set by "
                f"chunk + overlap anyway (a chunk as long as the overlap: 2×, at most twice the "
                "memory); give a longer chunk, or lag"
            ),
            stacklevel=4,
        )
    return n_chunk, n_over

"""Offline identification with model-based velocities: ``pinobs.identify`` (``pinobs identify``).

The regressor of :mod:`pinobs.model.identification` needs the velocity ``v``
along the log; ``v`` enters it nonlinearly (``Y_M(q, v)``, ``C(q, v)ᵀv``), so
velocity noise is an errors-in-variables error the least squares cannot
average out.  A Savitzky–Golay fit of the measured positions
(:func:`pinobs.model.identification.smooth_path`) is model-free and noisy:
on the 15 s logs of ``benchmarks/learning.py`` (σ = 1e-4 rad) its held-out
residual equals that of the *true* parameters evaluated on the same
velocities (the floor it sets), and the default ``ekf`` on the model
identified from it was 0.15–0.79× the best tuned model-free filter, varying
with the noise's seed (UR5: 0.15 with seed 3, 0.62 with seed 4).  With the
truth's own velocities the same identification reaches 0.007× (UR5) and
0.02–0.04× (z1); with noise-free positions and Savitzky–Golay 0.007× and
0.07×: noise, not the fit's lag, is most of the error (log seed 3,
validation seed 7 of ``benchmarks/learning.py``).

So the velocities are re-estimated with the model just identified, and the
identification repeated (a fixed-point iteration)::

    θ⁰ = identify(q_meas, v_SG)                                  first pass
    (q̂, v̂)ⁱ = RTS smoother of ekf on robot(θⁱ⁻¹) over the log      (pinobs.observers.smoothing)
    θⁱ = identify(q̂ⁱ, v̂ⁱ)                                        i = 1 … len(refine)

The smoother runs the EKF with a white-acceleration density ``refine[i−1]``
[rad²/s³] (the model's remaining error, decreasing as it improves: 1e-6
then 1e-7 by default) and a torque-offset state (``disturbance_psd`` =
1e-4 rad²/s⁵) that absorbs what the model still misses, fed ``τ + b``
(``b`` the offset identified so far).  Each contiguous stretch of the log
(:func:`pinobs.model.identification.segments`) is smoothed on its own (a
pass before the last one only over the fitted part: its held-out end is not
used).  The
position noise the smoother needs is the log's own (``noise_std``) or, when
not given, estimated from it (:func:`pinobs.observers.noise.estimate_noise_std`).

The model layer cannot import the smoother (layers run one way), hence this
thin wrapper one layer up; the machinery is the model layer's, written once.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import IdentificationError, NonFiniteError, ObserverDiverged
from pinobs.model import Robot
from pinobs.model import identification as ident_model
from pinobs.model.identification import MAX_CONDITION, Identification, log_arrays, segments
from pinobs.observers.base import Vector, positive
from pinobs.observers.noise import noise_from_log
from pinobs.observers.smoothing import _smooth

__all__ = ["REFINE_ACCEL_PSD", "REFINE_DISTURBANCE_PSD", "identify"]

#: White-acceleration densities [rad²/s³] of the successive smoother passes (module docstring).
REFINE_ACCEL_PSD: tuple[float, ...] = (1e-6, 1e-7)

#: Torque-offset density [rad²/s⁵] of the smoothed EKF (adaptive's learned-model density).
REFINE_DISTURBANCE_PSD = 1e-4


def _noise_std(robot: Robot, t: Vector, q: Vector) -> float:
    """The log's position noise σ [rad or m]: :func:`pinobs.observers.noise.noise_from_log`
    (the median over joints of robust third differences over its first second), floored at
    1e-9 (a noise-free log)."""
    found = noise_from_log(t, q, robot, floor=1e-9)
    if found is None:
        raise IdentificationError("fewer than 12 finite samples to measure the noise on")
    return found[0]


def identify(
    robot: Robot,
    log: Any,
    *,
    friction: bool = True,
    offset: bool = False,
    holdout: float = 0.2,
    window: float = 0.1,
    max_condition: float = MAX_CONDITION,
    refine: Sequence[float] = REFINE_ACCEL_PSD,
    noise_std: float | None = None,
    torque: str = "held",
) -> Identification:
    """Identify ``robot``'s dynamic parameters from a log, with model-based velocities.

    The arguments up to ``max_condition`` and the result are those of
    :func:`pinobs.model.identification.identify` (the log, the report, the
    errors it raises), except that ``offset`` is off by default: a
    :class:`Robot` cannot carry a torque offset, so the observers run on
    ``.robot`` without it, and an offset the log does not have is confounded
    with gravity (the shoulder's ``m·c``, on a trajectory about one mean
    posture): identified anyway, it made the default ``ekf`` 1.6–3.4× less
    accurate in ``benchmarks/learning.py`` (z1: 0.06 → 0.19× kf*; the
    truths there have no offset).  Give ``offset=True`` for a torque sensor
    known to be biased, and add ``.offset`` to the torques fed to the
    observers (the model is driven by ``τ + b``: module docstring of
    :mod:`pinobs.model.identification`; subtracting it doubles the bias: on
    a 4 s UR5 log read as ``τ + [0.5, −2, 1, 0.3, 0, −0.1]`` N·m, seed 0, the
    ``ekf`` on the calibrated model errs by 2.6 rad/s RMS, by 6.2e-3 adding
    it, 8.0e-3 on the true torques).  This adds:

    Args:
        refine: white-acceleration densities [rad²/s³] of the smoother passes
            (module docstring); ``()`` keeps the Savitzky–Golay velocities
            (one pass, the cheapest).
        noise_std: the log's position noise [rad or m] (default: estimated,
            :func:`pinobs.observers.noise.estimate_noise_std`).
        torque: how the log's torques were taken, for ``∫ τ dt``: ``"held"`` over each
            sample (zero-order hold: ``pinobs.simulate``, most controllers) or
            ``"sampled"`` at the instants (``pinobs excite``'s trajectory: trapezoid);
            every pass (the model layer's ``torque``).

    ``report["velocities"]`` says which velocities the last pass used
    (``"savgol"`` or ``"rts(accel_psd=…)"``) and ``report["noise_std"]`` the σ
    the smoother was given; ``report["observer_options"]`` is empty (run
    ``ekf`` and ``riemannian`` with their defaults on the refined model).

    Raises:
        IdentificationError: as the model-layer ``identify``.
        GainError: a non-positive ``refine`` density or ``noise_std``.
    """
    for psd in refine:
        positive("refine accel_psd", psd)
    if noise_std is not None:
        positive("noise_std", noise_std)
    opts: dict[str, Any] = {
        "friction": friction,
        "offset": offset,
        "holdout": holdout,
        "window": window,
        "max_condition": max_condition,
        "torque": torque,
    }
    current = ident_model.identify(robot, log, **opts)
    if not refine:
        current.report["velocities"] = "savgol"
        return current
    t, q, tau = log_arrays(robot, log)
    sigma = noise_std if noise_std is not None else _noise_std(robot, t, q)
    for i, psd in enumerate(refine):
        # a pass before the last one only feeds the next fit: its held-out end needs no smoothing
        last = i == len(refine) - 1
        rows = np.ones(t.shape, bool) if last else t <= current.report["fit_end"]
        path = _smoothed_path(current, t, q, tau, rows, accel_psd=psd, noise_std=sigma)
        current = ident_model.identify(robot, (t, q, tau), path=path, **opts)
        current.report["velocities"] = f"rts(accel_psd={psd:g})"
    current.report["noise_std"] = sigma
    # measured in benchmarks/learning.py: on a model identified this way the default ekf is
    # 1.1-5x more accurate than with the model-error densities the one-pass fit recommends
    current.report["observer_options"] = {}
    return current


def _smoothed_path(
    ident: Identification,
    t: Vector,
    q: Vector,
    tau: Vector,
    rows: NDArray[np.bool_],
    *,
    accel_psd: float,
    noise_std: float,
) -> tuple[Vector, Vector]:
    """RTS-smoothed ``(q, v)`` of every contiguous stretch of ``rows`` on the identified model.

    NaN elsewhere (where the model layer falls back on Savitzky–Golay).
    """
    robot = ident.robot
    q_out = np.full(q.shape, np.nan)
    v_out = np.full(tau.shape, np.nan)
    t_rows = np.where(rows, t, np.nan)  # rows left out break the stretches
    for seg in segments(t_rows, q, tau):
        if seg.stop - seg.start < 3:
            continue
        try:
            sm = _smooth(  # its consistency is not the user's concern here
                robot,
                (t[seg], q[seg], tau[seg] + ident.offset),
                noise_std=noise_std,
                accel_psd=accel_psd,
                disturbance_psd=REFINE_DISTURBANCE_PSD,
            )
        except (NonFiniteError, ObserverDiverged):
            continue  # this stretch keeps the Savitzky–Golay velocities (build_rows)
        q_out[seg], v_out[seg] = sm.q, sm.v
    return q_out, v_out

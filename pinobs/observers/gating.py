"""The outlier gate and the normalized innovation squared, one definition for every filter.

A family with an innovation covariance computes its NIS ``eᵀ S⁻¹ e`` and keeps the gate's
bookkeeping in its state (:class:`GateState`); the base reads it back
(:meth:`pinobs.observers.base.Observer.innovation`).
"""

from __future__ import annotations

import functools
import math
from statistics import NormalDist
from typing import NamedTuple, cast

import numpy as np

from pinobs.errors import GainError
from pinobs.observers.checks import positive
from pinobs.tolerances import MAX_GAP_PERIODS

__all__ = [
    "MAX_GATE_RUN",
    "MAX_SPIKE_RUN",
    "NIS_AVERAGING",
    "SPIKE_ALPHA",
    "GateState",
    "chi2_quantile",
    "gate_nis",
    "gate_threshold",
    "outlier_gate",
    "steady_innovation_variance",
]

#: Consecutive measurements the outlier gate may reject before it accepts one whatever its NIS
#: (but ``kf``'s spikes: :data:`SPIKE_ALPHA`, :data:`MAX_SPIKE_RUN`).
MAX_GATE_RUN = 1

#: Weight of each accepted NIS in the running mean that scales the gate.
NIS_AVERAGING = 0.01

#: ``kf``'s ``NIS / limit`` past which the sample a run would force in is a spike, rejected
#: (its soft gate keeps ``1 / α`` of the correction: under 1 %); after a spike, ``NIS`` over
#: this many times the run's drift (:func:`outlier_gate`).
SPIKE_ALPHA = 100.0

#: ``kf``'s spikes rejected in a row after the run (:data:`MAX_GATE_RUN`) before the next sample
#: is forced in whatever its NIS: a spike carries no information on the state (the ε part's
#: sample), as a dropped row, and the log reader re-initialises after a gap of
#: :data:`~pinobs.tolerances.MAX_GAP_PERIODS` periods (:mod:`pinobs.io.stream`); a jump of the
#: signal that lasts is taken then (:func:`outlier_gate`).
MAX_SPIKE_RUN = int(MAX_GAP_PERIODS)

_new_tuple = tuple.__new__


def chi2_quantile(dof: int, p: float) -> float:
    """The χ² quantile with upper tail ``p`` by Wilson-Hilferty (above the exact one: +4 % at dof 6, +15 % at dof 1, p = 1e-6).

    ``χ²_k(1 − p) ≈ k (1 − 2/(9k) + z √(2/(9k)))³``, ``z`` the normal quantile
    (Wilson & Hilferty 1931); the standard library's ``NormalDist`` keeps
    ``scipy.stats`` out of the import.
    """
    z = NormalDist().inv_cdf(1.0 - p)
    c = 2.0 / (9.0 * dof)
    return float(dof * (1.0 - c + z * math.sqrt(c)) ** 3)


def gate_threshold(outlier_probability: float | None, dof: int) -> tuple[float | None, float]:
    """Validate the ``outlier_probability`` option: ``(p, χ²_dof(1 − p))``; ``(None, inf)`` switches
    the gate off.

    Raises:
        GainError: ``p`` not a number in (0, 0.5).
    """
    p = positive("outlier_probability", outlier_probability, allow_none=True)
    if p is None:
        return None, math.inf
    if p >= 0.5:
        raise GainError(f"outlier_probability={p!r} must be in (0, 0.5) (or None: no gate)")
    return p, chi2_quantile(dof, p)


def gate_nis(threshold: float, level: float | None, dof: int) -> float:
    """The NIS above which :func:`outlier_gate` rejects a measurement at ``level``
    (``threshold · max(1, NIS̄ / dof)``; ``level`` ``None``: ``dof``)."""
    return threshold * max(1.0, (float(dof) if level is None else level) / dof)


def outlier_gate(
    nis: float, level: float | None, run: int, threshold: float, dof: int, spike: float = math.inf
) -> tuple[bool, float]:
    """The outlier gate of the filters with an innovation covariance: ``(reject, new level)``.

    A measurement whose NIS exceeds ``threshold · max(1, NIS̄ / dof)`` is
    rejected (``NIS̄`` = ``level``, a running mean of accepted NIS, so a filter
    whose model is off does not reject everything), unless :data:`MAX_GATE_RUN`
    were rejected in a row (``run``): then it is accepted whatever its NIS (a
    real jump, or a prediction gone wrong, not a spike) and the level raised
    to it.  Measured: with ten allowed rejections, a Panda whose model has
    stiff Coulomb friction lost track (prediction errors near v = 0 were
    gated while the prediction drifted); with one it does not.  ``kf`` (``spike`` =
    :data:`SPIKE_ALPHA`) rejects the sample that would be forced in if it is a spike, ``A``
    times past the limit, and after a spike those ``A`` times past the run's drift ``d`` (the
    NIS of the run's last rejection that was not a spike, :attr:`GateState.drift`; the limit
    if none), up to :data:`MAX_SPIKE_RUN` (``M``) spikes::

        limit = threshold · max(1, NIS̄ / dof)
        ref = limit (run ≤ MAX_GATE_RUN),  max(limit, d) (run > MAX_GATE_RUN)
        reject ⇔ NIS > limit and (run < MAX_GATE_RUN or (run < MAX_GATE_RUN + M and NIS > A · ref))
        d ← NIS                                         (rejected with NIS ≤ A · limit)
        NIS̄ ← max(NIS̄, NIS · dof / threshold)         (accepted with run ≥ MAX_GATE_RUN)
        NIS̄ ← NIS̄ + λ (min(NIS, 100 NIS̄) − NIS̄)       (accepted, d ← none; λ = NIS_AVERAGING)

    (``A`` = :data:`SPIKE_ALPHA` = 100), so the sample forced in after one rejection raises
    the limit at most ``A``-fold (then one step of the mean: at most 2-fold), which then
    comes back with the time constant ``1/λ`` samples.  A run's NIS grows as the prediction
    drifts (a UR5 stopping within one 10 ms sample: 304, then 1247 at a limit of 40), a
    spike's jumps (0.1 rad on one joint: 1e6): Huber 1964's ε-contaminated Gaussian, the ε
    part's sample.  Before, a 1 rad glitch forced in after a gated maneuver (UR10e log
    ur-20_02_10-30sec_12harm, row 498: NIS 3e9) raised the level from 6.5 to 4e8, the gate's
    limit over 10× the clean run's for the next 1576 samples (any glitch passed); now it is
    rejected and the next sample, the maneuver's, forced in.  Two or three spikes in a row
    after a rejection: the second was forced in (the UR5 stop, 1 rad glitches: velocity off by
    69 and 153 rad/s, the limit 1e8); now each is a spike (past ``A`` limits, then ``A`` times
    the stop's NIS, 304) and the stop's next sample, its drift grown from 304, is forced in
    (the error the stop's own 0.1 rad/s, the limit 7.5e3).  After a spike the reference is
    the run's drift, not the limit: a maneuver past ``A`` limits at its second sample (TIAGo,
    NIS 228, 5.3e3, then 1.35e4 at a limit of 44) goes on growing from its opening NIS, so the
    sample after is forced in as before; against ``A`` limits it was rejected too (17 more
    samples gated on TIAGo).  A jump of the signal that lasts (the robot re-zeroed, a log
    spliced) is rejected for ``M`` samples, then forced in with the level raised to it (the
    gate off a while, as any forced sample past the limit), or, where its velocity goes past
    the log reader's bound, re-initialised there (:mod:`pinobs.io.stream`); a 1 rad jump of
    the UR5's joint 0 while it moves: 11 samples gated, the velocity off by 20 rad/s for 12
    samples (before: 2 gated, 67 rad/s for 6).  A glitch between the limit and ``A`` limits
    is not a spike: two in a row (0.01 rad on the UR5's stop) the second forced in, as
    before (0.49 rad/s).  The model-based families keep
    ``A = ∞`` (every sample after a run forced in): where their model does not explain a real
    log the sample after a rejection is past ``A`` limits because the prediction is off, not
    the sample (UR10e ``ur-19_10_01-14_04_13``, nominal model: ``adaptive`` diverged with
    ``A`` = 100, velocity RMS 0.315 against 0.0053 rad/s; ``ekf``, ``riemannian``, ``kalman``
    re-initialised 7309–7585 times over the UR10e logs against 5581–5957).
    """
    gate = _new_tuple(GateState, (None, False, run, level, None)).measured(
        nis, threshold, dof, spike
    )
    return gate.gated, cast(float, gate.level)


class GateState(NamedTuple):
    """The outlier gate's bookkeeping, carried in the state of every family with an innovation.

    One definition for every filter (``ekf``, ``kf``, ``kalman``, ``riemannian``,
    ``liegroup``, ``ii``; ``adaptive`` through its ``ekf``): a family computes its NIS
    ``eᵀ S⁻¹ e`` (its own ``e`` and ``S``) and calls :meth:`measured`, or :meth:`predicted`
    at a step without a sample; the base reads ``nis`` and ``gated`` of the committed
    state (:meth:`Observer.innovation`: :attr:`Estimate.nis`, :meth:`Observer.consistency`).

    Attributes:
        nis: normalized innovation squared of the last measurement (``None``: none).
        gated: that measurement was rejected as an outlier (the state is the prediction;
            ``kf``'s ``"auto"`` bank: down-weighted, the soft gate of :mod:`pinobs.observers.kf`).
        run: measurements rejected in a row.
        level: running mean of accepted NIS (scales the gate; ``None``: none yet, ``dof``).
        drift: NIS of the run's last rejected sample that was not a spike (``None``: none;
            ``kf``'s spike rule, :func:`outlier_gate`).
    """

    nis: float | None = None
    gated: bool = False
    run: int = 0
    level: float | None = None
    drift: float | None = None

    def measured(
        self, nis: float, threshold: float, dof: int, spike: float = math.inf
    ) -> GateState:
        """After a measurement of normalized innovation squared ``nis``: the gate's decision
        (:func:`outlier_gate`, ``threshold`` from :func:`gate_threshold`, ``dof`` degrees of
        freedom, ``spike`` its ``A``: ``kf``'s :data:`SPIKE_ALPHA`, the model-based families'
        ∞) and its bookkeeping.  ``gated``: the family must not use the measurement.

        :func:`outlier_gate`'s rule is written here, where every filter calls it at every
        sample (issue 39: a call less), and that function calls this; the new state by
        ``tuple.__new__`` directly (the NamedTuple's own ``__new__`` is a Python call more)."""
        run, drift = self.run, self.drift
        lvl = float(dof) if self.level is None else self.level
        scale = lvl / dof  # gate_nis's max(1, NIS̄ / dof), inline
        limit = threshold * (scale if scale > 1.0 else 1.0)
        # (a spike is the ε part's: Huber 1964, not forced in; after a spike, past A times
        # the run's drift: a maneuver's NIS grows from it, a glitch's jumps)
        ref = limit if run <= MAX_GATE_RUN or drift is None else max(limit, drift)
        if nis > limit and (
            run < MAX_GATE_RUN or (run < MAX_GATE_RUN + MAX_SPIKE_RUN and nis > spike * ref)
        ):
            if nis <= spike * limit:
                drift = nis
            return _new_tuple(GateState, (nis, True, run + 1, lvl, drift))
        if run >= MAX_GATE_RUN:  # the prediction was off, not the sample: adapt the gate
            lvl = max(lvl, nis * dof / threshold)
        lvl += NIS_AVERAGING * (min(nis, 100.0 * lvl) - lvl)
        return _new_tuple(GateState, (nis, False, 0, lvl, None))

    def predicted(self) -> GateState:
        """After a step without a measurement: no NIS, not gated, the run, level and drift
        kept."""
        return _new_tuple(GateState, (None, False, self.run, self.level, self.drift))

    def limit(self, threshold: float, dof: int) -> float:
        """The NIS above which the gate rejects at this level (:func:`gate_nis`)."""
        return gate_nis(threshold, self.level, dof)


def gate_loops(
    nis: float, run: int, level: float, level_none: bool, drift: float, drift_none: bool,
    threshold: float, dof: int,
) -> tuple[bool, int, float, float, bool]:  # fmt: skip
    """:meth:`GateState.measured` with ``spike = ∞`` (the model-based families'), its
    operations in its order (for the compiled fused updates: ``riemannian_fused``,
    ``ekf_fused``; tested against that method): ``(gated, run, level, drift,
    drift is None)`` after a measurement of NIS ``nis`` (``level_none``, ``drift_none``: the
    state's ``None``)."""
    lvl = float(dof) if level_none else level
    scale = lvl / dof
    limit = threshold * (scale if scale > 1.0 else 1.0)
    if nis > limit and run < MAX_GATE_RUN:  # (spike ∞: no spike past the run)
        return True, run + 1, lvl, nis, False  # (drift = nis: nis ≤ ∞ · limit)
    if run >= MAX_GATE_RUN:  # the prediction was off, not the sample: adapt the gate
        lvl = max(lvl, nis * dof / threshold)
    lvl += NIS_AVERAGING * (min(nis, 100.0 * lvl) - lvl)
    return False, 0, lvl, drift, True


@functools.lru_cache(maxsize=64)
def steady_innovation_variance(k1: float, k2: float, h: float, meas_var: float) -> float:
    """Innovation variance of a fixed-gain observer of a double integrator, noise-driven, at steady state.

    One tangent direction, error ``e = (δq, δv)``, a sample every ``h`` [s] with
    noise of variance ``meas_var`` [rad²], the correction ``e⁺ = e⁻ − K (δq⁻ − n)``
    with the observer's own gains ``K = (k1, k2)`` [1, 1/s], the prediction
    ``e⁻ = D e``, ``D = [[1, h], [0, 1]]`` (no process noise: an exact model)::

        P = A P Aᵀ + meas_var K Kᵀ,   A = (I − K H) D,   H = [1 0]      (discrete Lyapunov)
        S = (D P Dᵀ)₀₀ + meas_var

    (solved as ``(I − A ⊗ A) vec P = meas_var vec(K Kᵀ)``).  The innovation
    ``δq⁻ − n`` is then Gaussian with variance ``S``, so ``|e|²/S`` over ``nv``
    such directions is χ²(nv).  ``inf`` if ``A`` is not stable (no steady state).
    """
    D = np.array([[1.0, h], [0.0, 1.0]])
    K = np.array([[k1], [k2]])
    A = (np.eye(2) - K @ np.array([[1.0, 0.0]])) @ D
    if not float(np.max(np.abs(np.linalg.eigvals(A)))) < 1.0:
        return math.inf
    vec_p = np.linalg.solve(np.eye(4) - np.kron(A, A), meas_var * (K @ K.T).ravel())
    P = vec_p.reshape(2, 2)
    return float((D @ P @ D.T)[0, 0] + meas_var)

"""``adaptive``'s learning replay: its causal pass over the log, with the models it learned
frozen per window (:func:`learned_models`; :mod:`pinobs.smoothing`, "adaptive")."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import (
    ObserverDiverged,
    OptionError,
)
from pinobs.model import Robot
from pinobs.observers.adaptive import AdaptiveEKF, ModelSnapshot
from pinobs.observers.base import (
    Vector,
    make_observer,
    positive,
)
from pinobs.observers.ekf import ExtendedKalmanFilter
from pinobs.smoothing.constants import AUTO_WHITE_SCALE
from pinobs.tolerances import TIME_EPS

__all__ = ["learned_models"]


class _FrozenModels:
    """``adaptive``'s model-based filter replayed with its learned model frozen per window.

    ``snapshots[j]`` is the model (:class:`~pinobs.observers.adaptive.ModelSnapshot`)
    the causal pass held at the end of window ``j``; the prediction from sample
    ``k`` uses ``snapshots[which[k]]``: its dynamics, its torque offset (added to
    ``tau``) and its regime's densities (``accel_psd`` replaced by the smoother's
    when given, the offset's scaled with it; with ``offset_scale``, the white
    acceleration at :data:`AUTO_WHITE_SCALE` of the regime's and the offset's
    at ``offset_scale`` times the regime's: :func:`consistent_offset_scale`).
    The torque-offset state ``d`` carries over a model switch (it is a random
    walk, so the backward pass sees the switch as a step it absorbs).
    """

    def __init__(
        self,
        ekf: ExtendedKalmanFilter,
        snapshots: Sequence[ModelSnapshot],
        which: Vector,
        accel_psd: float | None,
        offset_scale: float | None = None,
    ) -> None:
        self._ekf, self._snaps, self._which, self._accel = ekf, snapshots, which, accel_psd
        self._offset_scale = offset_scale
        self._k, self._j = 0, -1
        self.robot = ekf.robot

    @property
    def gains(self) -> Any:
        return self._ekf.gains

    @property
    def options(self) -> dict[str, Any]:
        return self._ekf.options

    @property
    def disturbance_psd(self) -> float | None:
        """The offset density given at construction (each window's regime sets its own)."""
        return self._ekf.disturbance_psd

    def _use(self, state: Any, j: int) -> Any:
        snap = self._snaps[j]
        self._ekf.replace_robot(snap.robot)
        scale = 1.0 if self._accel is None else self._accel / snap.accel_psd
        d_scale = scale
        if self._offset_scale is not None:
            scale, d_scale = AUTO_WHITE_SCALE, self._offset_scale
        self._ekf.gains = replace(self._ekf.gains, accel_psd=scale * snap.accel_psd)
        self._j, self.robot = j, snap.robot
        return state._replace(d_psd=d_scale * snap.disturbance_psd)

    def initial_state(self, q0: Vector, v0: Vector) -> Any:
        self._k, self._j = 0, -1
        state = self._ekf.initial_state(q0, v0)
        return self._use(state, int(self._which[0]))

    def predict(self, state: Any, dt: float, tau: Vector) -> tuple[Any, Vector]:
        j = int(self._which[self._k])
        if j != self._j:
            state = self._use(state, j)
        self._k += 1
        return self._ekf.predict(state, dt, tau + self._snaps[j].offset)

    def predict_flow(self, state: Any, dt: float, tau: Vector) -> tuple[Any, Vector, Vector]:
        """:meth:`predict` with ``Φ`` as the mean's Jacobian: the noise band propagates the
        error with ``Φ`` here (:mod:`pinobs.smoothing`, "Two bands")."""
        pred, Phi = self.predict(state, dt, tau)
        return pred, Phi, Phi

    def correct(self, state: Any, q_meas: Vector) -> Any:
        return self._ekf.correct(state, q_meas)

    def gate_limit(self, state: Any) -> float:
        return self._ekf.gate_limit(state)


def learned_models(
    robot: Robot,
    t: Vector,
    q: Vector,
    tau: Vector,
    good: Vector,
    noise_std: float | None,
    options: Mapping[str, Any],
    model_window: float | None,
    frozen_t: Vector | None = None,
) -> tuple[Callable[..., _FrozenModels], dict[str, Any]]:
    """The causal ``adaptive`` over the log (from its first good sample), its model kept per window.

    ``frozen_t``: the times of the rows the frozen-model filter runs over, when they are not
    ``t`` (a known latency: :func:`retimed`); each row takes the window of the latest ``t``
    at or before it.

    Returns a maker of the frozen-model filter (given an ``accel_psd`` or ``None``:
    each window's regime density; and optionally an ``offset_scale``) and the
    options to report.
    """
    dt = float(np.median(np.diff(t)))

    def observer(blend: bool) -> AdaptiveEKF:
        opts = {**options, "blend": blend}
        obs = make_observer("adaptive", robot, noise_std=noise_std, rate=1.0 / dt, **opts)
        return cast(AdaptiveEKF, obs)

    # The snapshots depend on the model-based filter alone (its innovations decide the
    # regimes; the learner takes the committed samples), not on the blend's model-free bank,
    # except through a restart of a lost filter, which needs the bank: the pass runs without
    # it and, should the filter be lost, again with it (tested: the same snapshots).  It
    # costs about 10 % less.
    obs = observer(False)
    window = float(obs.options["horizon"] if model_window is None else model_window)
    positive("model_window", window)
    if window < dt:
        raise OptionError(
            f"model_window={window!r} s is shorter than the log's sample interval ({dt:.3g} s): "
            f"give at least one interval (default the learner's horizon, "
            f"{obs.options['horizon']:g} s)"
        )
    # windows (t₀ + jW, t₀ + (j+1)W]: each ends on the sample where the learner's solve
    # falls when W is a multiple of its resolve_every (both count from the reset at t₀), so
    # the window's model includes it.  Half-open the other way, a solve landing on a window's
    # first sample was left out of the window before it: a payload log smoothed with its
    # first window frozen in the nominal regime, ρ = 72.
    which, frozen = _window_numbers(t, window, frozen_t)
    snapshots = _snapshots(obs, t, q, tau, good, which, options)
    if snapshots is None:  # lost: the pass with the bank, which restarts the filter
        obs = observer(True)
        snapshots = cast(list[ModelSnapshot], _snapshots(obs, t, q, tau, good, which, options))
    ekf, report = _frozen_filter(obs, snapshots, options, noise_std, window)

    def make(accel_psd: float | None, offset_scale: float | None = None) -> _FrozenModels:
        return _FrozenModels(ekf, snapshots, frozen, accel_psd, offset_scale)

    return make, report


def _window_numbers(
    t: Vector, window: float, frozen_t: Vector | None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Each sample's window (numbered from 0, empty ones dropped), and each frozen-model row's
    (:func:`learned_models`' ``frozen_t``; the samples' own when ``None``)."""
    # windows (t₀ + jW, t₀ + (j+1)W]: each ends on the sample where the learner's solve
    # falls when W is a multiple of its resolve_every (both count from the reset at t₀), so
    # the window's model includes it.  Half-open the other way, a solve landing on a window's
    # first sample was left out of the window before it: a payload log smoothed with its
    # first window frozen in the nominal regime, ρ = 72.
    which = np.maximum(np.ceil((t - t[0]) / window - 1e-6).astype(int) - 1, 0)
    which[0] = which[1]  # sample 0 is never a window of its own (nothing learned before it)
    which = np.unique(which, return_inverse=True)[1].astype(float)  # empty windows (gaps) dropped
    frozen = which
    if frozen_t is not None:
        latest = np.searchsorted(t, frozen_t + TIME_EPS, side="right") - 1
        frozen = which[np.maximum(latest, 0)]
    return which, frozen


def _snapshots(
    obs: AdaptiveEKF,
    t: Vector,
    q: Vector,
    tau: Vector,
    good: Vector,
    which: NDArray[np.float64],
    options: Mapping[str, Any],
) -> list[ModelSnapshot] | None:
    """The learning pass: the snapshots at the windows' ends (``which``: each sample's
    window); ``None`` if a filter run without the bank the user asked for is lost."""
    give_up = not obs.blend and bool(options.get("blend", True))
    snapshots: list[ModelSnapshot] = []
    obs.reset(float(t[0]), q[0], None, tau[0])
    for k in range(1, t.size):
        try:
            obs.update(float(t[k]), q[k] if good[k] else None, tau[k])
        except ObserverDiverged:
            if give_up:
                return None
            raise
        if give_up and obs.lost():
            return None
        if k == t.size - 1 or which[k + 1] != which[k]:
            snapshots.append(obs.snapshot())  # the model held at the window's last sample
    return snapshots


def _frozen_filter(
    obs: AdaptiveEKF,
    snapshots: list[ModelSnapshot],
    options: Mapping[str, Any],
    noise_std: float | None,
    window: float,
) -> tuple[ExtendedKalmanFilter, dict[str, Any]]:
    """The EKF the frozen models run in (each window's model and densities set on it by
    :class:`_FrozenModels`), and the options to report: ``obs``'s, the window, and each
    window's regime and densities."""
    opts = {**obs.options, "blend": options.get("blend", True)}
    ekf = ExtendedKalmanFilter(
        snapshots[0].robot,
        accel_psd=snapshots[0].accel_psd,
        q0_std=opts["q0_std"],
        v0_std=opts["v0_std"],
        disturbance_psd=1.0,  # the state gets each window's own density (_FrozenModels._use)
        d0_std=obs.core.d0_std,
        outlier_probability=opts["outlier_probability"],
        noise_std=noise_std,
    )
    densities = {
        "warmup": opts["disturbance_psd"],
        "nominal": opts["validated_disturbance_psd"],
        "learned": opts["learned_disturbance_psd"],
    }
    report = {
        **opts,
        "model_window": window,
        "model_regimes": [s.regime for s in snapshots],
        "model_accel_psd": [s.accel_psd for s in snapshots],
        # (accel_psd [rad²/s³], offset density [rad²/s⁵]) of each window's regime
        "model_densities": [(s.accel_psd, densities[s.regime]) for s in snapshots],
    }
    return ekf, report

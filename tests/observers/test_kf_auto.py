"""``kf`` with ``jerk_psd="auto"``: a bank of white-jerk filters, each joint's density from
its innovations' profile likelihood (``pinobs/observers/kf.py``, module docstring)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

import pinobs
from pinobs.observers.kf import AUTO_LAMBDAS, SMOOTHING_JERK_PSD, transition


def _white_jerk_log(
    rng: np.random.Generator, jerk: np.ndarray, n: int, h: float, sigma: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, x, q_meas)``: each coordinate an integrated white jerk of density ``jerk[i]``
    (the filter's own model, exactly: ``x ← F x + w``, ``w ~ N(0, Q(h))``), measured with
    noise σ; ``x[k] = (q, v, a)`` per coordinate."""
    F, Q = transition(h, 1.0)
    L = np.linalg.cholesky(Q)
    x = np.zeros((3, jerk.size))
    xs = np.empty((n, 3, jerk.size))
    for k in range(n):
        x = F @ x + (L @ rng.standard_normal((3, jerk.size))) * np.sqrt(jerk)
        xs[k] = x
    return np.arange(n) * h, xs, xs[:, 0] + sigma * rng.standard_normal((n, jerk.size))


def _ramp(robot: pinobs.Robot, v: np.ndarray, n: int, h: float) -> tuple[np.ndarray, list]:
    q0 = robot.neutral()
    return np.arange(n) * h, [robot.integrate(q0, k * h * v) for k in range(n)]


@pytest.mark.parametrize("robot_name", ["ur5", "top", "go1", "kinova"])
def test_auto_started_on_the_truth_noise_free_stays_there(robot_name: str) -> None:
    robot = pinobs.load(robot_name)
    v = np.linspace(-1.0, 1.0, robot.nv)
    t, qs = _ramp(robot, v, 300, 1e-3)
    ob = pinobs.make_observer("kf", robot, jerk_psd="auto", noise_std=0.0)
    ob.reset(0.0, qs[0], v)
    for k in range(1, t.size):
        est = ob.update(t[k], qs[k])
        np.testing.assert_allclose(est.v, v, atol=1e-9)
        assert np.max(np.abs(robot.difference(est.q, qs[k]))) < 1e-9


@pytest.mark.parametrize("robot_name", ["ur5", "top", "go1", "kinova"])
def test_auto_converges_from_a_perturbed_start(robot_name: str) -> None:
    robot = pinobs.load(robot_name)
    v = np.linspace(-1.0, 1.0, robot.nv)
    t, qs = _ramp(robot, v, 2000, 1e-3)
    ob = pinobs.make_observer("kf", robot, jerk_psd="auto", noise_std=0.0)
    ob.reset(0.0, qs[0], v + 0.5)  # 0.5 rad/s off on every coordinate
    err = []
    for k in range(1, t.size):
        err.append(float(np.max(np.abs(ob.update(t[k], qs[k]).v - v))))
    assert err[9] < 0.5 and err[99] < 1e-2 * err[0] and err[-1] < 1e-6


def test_auto_lands_near_each_joints_own_density_on_a_white_jerk_log(
    rng: np.random.Generator,
) -> None:
    """On the filter's own model with a different density per joint (1e1, 1e3, 1e5
    rad²/s⁵, 1 kHz, σ = 1e-4 rad): the median density ``"auto"`` reports (after 1 s) is
    within 1.5× of each joint's truth (measured: 1.27, 1.01, 1.02×), and its velocity
    error within 1.1× of the best fixed density's on each joint (measured: 1.02, 1.00,
    1.00×); over the joints 0.74× the best single number's (1e4 or 1e5)."""
    robot = pinobs.load("planar_3r")
    jerk, h, sigma = np.array([1e1, 1e3, 1e5]), 1e-3, 1e-4
    t, x, qm = _white_jerk_log(rng, jerk, 5000, h, sigma)

    def run(j: float | str) -> tuple[np.ndarray, np.ndarray]:
        ob = pinobs.make_observer("kf", robot, jerk_psd=j, noise_std=sigma, rate=1 / h)
        ob.reset(0.0, qm[0], x[0, 1])
        v, d = [], []
        for k in range(1, t.size):
            v.append(ob.update(t[k], qm[k]).v)
            d.append(ob.densities)
        err = np.array(v)[1000:] - x[1001:, 1]
        return np.sqrt(np.mean(err**2, axis=0)), np.median(np.array(d)[1000:], axis=0)

    fixed = np.array([run(j)[0] for j in (1e1, 1e2, 1e3, 1e4, 1e5)])
    rms, density = run("auto")
    assert np.all(np.abs(np.log(density / jerk)) < np.log(1.5))
    assert np.all(rms < 1.1 * fixed.min(axis=0))
    total = np.sqrt(np.mean(rms**2))  # over the joints: no single number does as well
    assert total < 0.85 * np.min(np.sqrt(np.mean(fixed**2, axis=1)))


def test_auto_learns_each_joints_noise_level(rng: np.random.Generator) -> None:
    robot = pinobs.load("planar_3r")
    sigma = np.array([1e-5, 1e-4, 1e-3])
    t, x, _ = _white_jerk_log(rng, np.full(3, 1e3), 3000, 1e-3, 0.0)
    qm = x[:, 0] + sigma * rng.standard_normal((t.size, 3))
    ob = pinobs.make_observer("kf", robot, jerk_psd="auto", noise_std=1e-4)
    ob.reset(0.0, qm[0])
    for k in range(1, t.size):
        ob.update(t[k], qm[k])
    assert np.all(np.abs(np.log(ob.noise_stds / sigma)) < np.log(1.5))


def test_fixed_density_reports_itself_and_auto_reports_its_options() -> None:
    robot = pinobs.load("ur5")
    fixed = pinobs.make_observer("kf", robot, jerk_psd=12.0, noise_std=1e-4)
    fixed.reset(0.0, robot.neutral())
    np.testing.assert_array_equal(fixed.densities, np.full(robot.nv, 12.0))
    np.testing.assert_array_equal(fixed.noise_stds, np.full(robot.nv, 1e-4))
    auto = pinobs.make_observer("kf", robot, jerk_psd="auto", auto_memory=50)
    assert auto.options["jerk_psd"] == "auto" and auto.options["auto_memory"] == 50
    with pytest.raises(pinobs.NotResetError):
        _ = auto.densities
    auto.reset(0.0, robot.neutral())
    assert np.all(np.isnan(auto.densities))  # nothing measured yet


@pytest.mark.parametrize("bad", ["fast", "Auto"])
def test_a_density_that_is_neither_a_number_nor_auto_is_refused(bad: str) -> None:
    with pytest.raises(pinobs.GainError, match="auto"):
        pinobs.make_observer("kf", pinobs.load("ur5"), jerk_psd=bad)


def test_auto_memory_must_be_positive() -> None:
    with pytest.raises(pinobs.GainError, match="auto_memory"):
        pinobs.make_observer("kf", pinobs.load("ur5"), jerk_psd="auto", auto_memory=0.0)


def test_the_smoother_over_auto_runs_the_fixed_smoothing_density() -> None:
    ob = pinobs.make_observer("kf", pinobs.load("ur5"), noise_std=1e-4)
    assert ob.auto and ob.smoothing_filter().gains.jerk_psd == SMOOTHING_JERK_PSD


def test_auto_gates_an_outlier_once_it_has_a_noise_scale(rng: np.random.Generator) -> None:
    robot = pinobs.load("planar_3r")
    t, x, clean = _white_jerk_log(rng, np.full(3, 1e2), 400, 1e-3, 1e-4)
    spiked = clean.copy()
    spiked[300, 1] += 0.5  # a spike 5000 σ high
    runs = []
    for qm in (clean, spiked):
        ob = pinobs.make_observer("kf", robot, jerk_psd="auto", noise_std=1e-4)
        ob.reset(0.0, qm[0], x[0, 1])
        runs.append([ob.update(t[k], qm[k]) for k in range(1, t.size)])
    assert [k + 1 for k, e in enumerate(runs[1]) if e.gated] == [300]
    assert not any(e.gated for e in runs[0])
    gap = max(float(np.max(np.abs(a.v - b.v))) for a, b in zip(*runs, strict=True))
    assert gap < 1e-2  # without the gate the spike moves v by 2e2 rad/s (measured)


@pytest.mark.parametrize("compiled", [True, False])
def test_a_stop_the_gate_fires_on_keeps_part_of_its_correction(
    compiled: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Three joints at 0.1 rad/s stop within one 10 ms sample (σ = 1e-4 rad): the gate fires
    there (NIS 304, measured), and the soft gate moves the estimate from the prediction (the
    sample dropped) toward the ungated filter's, part of the way (1/α of the gain)."""
    from pinobs.observers import kf_kernels

    if not compiled:
        monkeypatch.setattr(kf_kernels.auto_kernel, "compiled", None)
        monkeypatch.setattr(kf_kernels.auto_kernel, "load", lambda: None)
    robot, h, sigma, stop = pinobs.load("ur5"), 1e-2, 1e-4, 200
    t = np.arange(stop + 1) * h
    x = np.minimum(t, t[stop - 1])[:, None] * np.array([0.1, -0.1, 0.1, 0.0, 0.0, 0.0])
    q = x + sigma * np.random.default_rng(0).standard_normal(x.shape)
    last = {}
    for label, p, q_stop in (
        ("soft", 1e-6, q[stop]),
        ("none", None, q[stop]),
        ("pred", None, None),
    ):
        ob = pinobs.make_observer("kf", robot, noise_std=sigma, rate=1 / h, outlier_probability=p)
        ob.reset(t[0], q[0])
        gated = [ob.update(t[k], q[k]).gated for k in range(1, stop)]
        last[label] = ob.update(t[stop], q_stop)
        assert not any(gated)
    assert last["soft"].gated and not last["none"].gated
    part = (last["soft"].v - last["pred"].v)[:3] / (last["none"].v - last["pred"].v)[:3]
    assert np.all((part > 0.0) & (part < 1.0)), part
    # what it tells: down-weighted, not rejected (the fixed density's gate rejects)
    soft = pinobs.make_observer("kf", robot, noise_std=sigma, rate=1 / h)
    soft.reset(t[0], q[0])
    for k in range(1, stop + 1):
        soft.update(t[k], q[k])
    assert "note: kf down-weighted 1 outlier sample(s)" in soft.consistency().messages("kf")[-1]


def _compiled_then_numpy(monkeypatch: pytest.MonkeyPatch) -> Iterator[bool]:
    """``True`` (the compiled step), then ``False`` with the kernel switched off (NumPy)."""
    from pinobs.observers import kf_kernels

    yield True
    monkeypatch.setattr(kf_kernels.auto_kernel, "compiled", None)
    monkeypatch.setattr(kf_kernels.auto_kernel, "load", lambda: None)
    yield False


def _stop_then_glitch(compiled: bool, glitches: dict[int, tuple[int, float]]) -> tuple:
    """A UR5's joints 0-2 at ±0.1 rad/s stop within one 10 ms sample (σ = 1e-4 rad; the gate
    fires there, as in the test above), ``glitches`` ``{row: (joint, size)}`` added:
    ``(true velocities, estimates' v, rows gated, the gate's limit after each row)`` of the
    default ``kf``."""
    robot, h, sigma, stop, n = pinobs.load("ur5"), 1e-2, 1e-4, 200, 400
    t = np.arange(n) * h
    speed = np.array([0.1, -0.1, 0.1, 0.0, 0.0, 0.0])
    x = np.minimum(t, t[stop - 1])[:, None] * speed
    v = np.where(np.arange(n) < stop, 1.0, 0.0)[:, None] * speed
    q = x + sigma * np.random.default_rng(0).standard_normal(x.shape)
    for row, (joint, size) in glitches.items():
        q[row, joint] += size
    ob = pinobs.make_observer("kf", robot, noise_std=sigma, rate=1 / h)
    ob.reset(t[0], q[0])
    out, limits = [], []
    for k in range(1, n):
        out.append(ob.update(t[k], q[k]))
        limits.append(ob._state.gate.limit(ob._gate, robot.nv))  # the gate's limit after row k
    gated = [k + 1 for k, e in enumerate(out) if e.gated]
    return v[1:], np.array([e.v for e in out]), gated, np.array(limits)


def test_a_glitch_right_after_a_gated_stop_is_rejected_and_the_gate_stays_on(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A 0.1 rad glitch on the sample after the gated stop (row 201), another of 0.01 rad at
    row 260: both are rejected (a spike is not forced in by the gate's run), and from the
    sample after the glitch on the velocity error against the truth stays within 1.5× the clean
    log's (the stop's own; measured 1.18×).  Before, the first was forced in (its NIS 1e6 raised the gate's level to 2e4: the
    error 4× the clean log's, 0.2 rad/s) and the second passed.  The compiled and the NumPy
    step agree (1e-12 of the largest velocity)."""
    stop = 200
    runs = {}
    for compiled in _compiled_then_numpy(monkeypatch):
        clean = _stop_then_glitch(compiled, {})
        truth, v, gated, _ = runs[compiled] = _stop_then_glitch(
            compiled, {stop + 1: (0, 0.1), stop + 60: (4, -0.01)}
        )
        assert clean[2] == [stop] and gated == [stop, stop + 1, stop + 60], gated
        err = np.max(np.abs(v - truth)[stop + 1 :], axis=1)  # (row k: index k − 1)
        err_clean = np.max(np.abs(clean[1] - truth)[stop + 1 :], axis=1)
        assert np.max(err) < 1.5 * np.max(err_clean), (np.max(err), np.max(err_clean))
    a, b = runs[True][1], runs[False][1]
    assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(b))


@pytest.mark.parametrize("count", [2, 3])
def test_consecutive_glitches_right_after_a_gated_stop_are_all_rejected(
    count: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``count`` glitches of 1 rad in a row on the samples after the gated stop (rows 201…):
    each is rejected (a spike does not end the gate's run: past ``SPIKE_ALPHA`` limits, then
    past ``SPIKE_ALPHA`` times the NIS of the stop the run opened with), the stop's sample
    after them forced in; the velocity error against the truth stays within the stop's own
    0.1 rad/s (measured 0.1001) and the gate's limit within ``SPIKE_ALPHA``× the clean log's
    largest (measured 3.7× and 5.7×).  Before, the second glitch was forced in: the error
    69 (2 glitches) and 153 rad/s (3), the limit 1e8 (8e4× the clean log's).  The compiled
    and the NumPy step agree (1e-12)."""
    from pinobs.observers.gating import SPIKE_ALPHA

    stop = 200
    runs = {}
    for compiled in _compiled_then_numpy(monkeypatch):
        clean = _stop_then_glitch(compiled, {})
        glitches = {stop + 1 + i: (0, 1.0) for i in range(count)}
        truth, v, gated, limits = runs[compiled] = _stop_then_glitch(compiled, glitches)
        assert gated == list(range(stop, stop + count + 1)), gated
        assert np.max(np.abs(v - truth)[stop:]) < 1.01 * 0.1  # (row k: index k − 1)
        assert np.max(limits) < SPIKE_ALPHA * np.max(clean[3]), np.max(limits)
    a, b = runs[True][1], runs[False][1]
    assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(b))


@pytest.mark.parametrize("compiled", [True, False])
def test_a_quantised_joint_at_rest_that_starts_to_move_is_not_an_outlier(
    compiled: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Encoders quantised to 1e-4 rad (as the UR10e logs), joint 1 at rest for 1 s (its
    readings repeat exactly: the scale ``ĉ`` → 0; 0.8 s on the NumPy path), then moving at
    0.02 rad/s: its first
    steps of one quantum were 1e300-NIS outliers (a UR10e validation log: 28 of 918
    samples rejected, mean NIS 1e299; here samples 101 and 1003 were gated); with the scale
    floored at σ₀² none is gated and the NIS stays near that of a quantum (largest 13.9,
    measured)."""
    from pinobs.observers import kf_kernels

    if not compiled:
        monkeypatch.setattr(kf_kernels.auto_kernel, "compiled", None)
        monkeypatch.setattr(kf_kernels.auto_kernel, "load", lambda: None)
    robot = pinobs.load("planar_3r")
    h, step = 1e-3, 1e-4
    rest = 1.0 if compiled else 0.8  # (the NumPy path, ~10 ms a step: a shorter log)
    t = np.arange(1600 if compiled else 1100) * h
    x = np.stack([0.3 * np.sin(t), np.where(t < rest, 0.0, 0.02 * (t - rest)), 0.1 * t], axis=1)
    q = np.round(x / step) * step
    ob = pinobs.make_observer("kf", robot, noise_std=step / np.sqrt(12.0), rate=1 / h)
    ob.reset(t[0], q[0])
    out = [ob.update(t[k], q[k]) for k in range(1, t.size)]
    assert not [k + 1 for k, e in enumerate(out) if e.gated]
    nis = np.array([e.nis for e in out], dtype=float)
    assert np.max(nis) < 100.0, np.max(nis)
    v = np.array([e.v[1] for e in out])
    assert abs(np.mean(v[-200:]) - 0.02) < 2e-3  # (the joint's speed, from its quanta)


def test_auto_keeps_its_likelihoods_through_a_pause_and_runs_with_a_latency(
    rng: np.random.Generator,
) -> None:
    robot = pinobs.load("planar_3r")
    t, x, qm = _white_jerk_log(rng, np.full(3, 1e3), 2000, 1e-3, 1e-4)
    ob = pinobs.make_observer("kf", robot, jerk_psd="auto", noise_std=1e-4)
    ob.reset(0.0, qm[0])
    for k in range(1, 1000):
        ob.update(t[k], qm[k])
    before = ob.densities
    ob.update(t[1000] + 1.0, qm[1000])  # a 1 s pause: the state restarts at the sample
    assert ob.pauses and np.allclose(ob.densities, before, rtol=0.1)
    lagged = pinobs.make_observer("kf", robot, jerk_psd="auto", noise_std=1e-4, latency=2e-3)
    lagged.reset(0.0, qm[0])
    for k in range(1, t.size):
        est = lagged.update(t[k], qm[k])
    assert np.max(np.abs(est.v - x[-1, 1])) < 0.1


def test_the_grid_spans_from_heavy_smoothing_to_the_raw_difference() -> None:
    assert min(AUTO_LAMBDAS) <= 1e-12 and max(AUTO_LAMBDAS) >= 1e1
    ratios = np.diff(np.log10(AUTO_LAMBDAS))
    np.testing.assert_allclose(ratios, 1.0)  # log-spaced, a decade apart


@pytest.mark.parametrize("rate", [1000.0, None])
def test_auto_compiled_step_equals_the_numpy_step(
    rate: float | None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The compiled ``"auto"`` step (``kf_kernels.auto_step_loops``, vector joints) against the NumPy
    one: a UR5 log with missing samples, single and paired jumps (the second a spike after
    the gate's run, rejected once more) and a pause; the same samples gated, the estimates, NIS and learnt
    densities equal to 1e-12 relative (measured: 2e-15 of each signal's largest value; the
    kernel sums in another order, and its ``S = P⁻₀₀ + σ²`` is the correction's)."""
    from pinobs.observers import kf_kernels

    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=1.0, sensor=pinobs.Sensor(1000.0, 1e-4), seed=3)
    rng = np.random.default_rng(5)
    q = np.array(res.q_meas)
    q[0] = res.q[0]
    for k in (300, 500, 501, 800):
        q[k] = q[k] + 0.05 * rng.choice([-1.0, 1.0], size=robot.nv)
    missing = rng.random(q.shape[0]) < 0.05
    t = np.array(res.t)
    t[600:] += 1.0  # a pause: the state restarts, the likelihoods kept

    def run() -> tuple[np.ndarray, ...]:
        ob = pinobs.make_observer("kf", robot, noise_std=1e-4, rate=rate)
        ob.reset(t[0], q[0])
        out = [ob.update(t[k], None if missing[k] else q[k]) for k in range(1, t.size)]
        nis = np.array([np.nan if e.nis is None else e.nis for e in out])
        gated = np.array([e.gated for e in out])
        est = np.array([np.concatenate([e.q, e.v]) for e in out])
        return est, nis, gated, ob.densities, ob.noise_stds

    compiled = run()
    assert kf_kernels.auto_kernel.compiled is not None  # loaded by make_observer
    monkeypatch.setattr(kf_kernels.auto_kernel, "compiled", None)
    monkeypatch.setattr(kf_kernels.auto_kernel, "load", lambda: None)  # (run() would reload it)
    numpy = run()
    assert np.array_equal(compiled[2], numpy[2]) and 3 <= int(np.sum(numpy[2])) <= 5
    np.testing.assert_array_equal(np.isnan(compiled[1]), np.isnan(numpy[1]))
    est, nis = compiled[0], compiled[1]
    assert np.all(np.abs(est - numpy[0]) <= 1e-12 * np.max(np.abs(numpy[0]), axis=0))
    ok = np.isfinite(numpy[1])
    assert np.all(np.abs(nis[ok] - numpy[1][ok]) <= 1e-12 * np.max(numpy[1][ok]))
    for a, b in zip(compiled[3:], numpy[3:], strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12)


def test_auto_kernel_is_loaded_when_made_and_never_compiled_in_the_loop() -> None:
    """Issue 39: the compiled step is there once ``make_observer`` returns, and the updates
    (missing samples, a read-only sample) run its one signature, the one loaded at
    construction: nothing is compiled inside an update."""
    from pinobs.observers import kf_kernels

    robot = pinobs.load("ur5")
    ob = pinobs.make_observer("kf", robot, noise_std=1e-4, rate=1000.0)
    kernel = kf_kernels.auto_kernel.compiled
    assert kernel is not None
    signatures = list(kernel.signatures)
    q = robot.neutral()
    ob.reset(0.0, q)
    frozen = q.copy()
    frozen.setflags(write=False)
    for k in range(1, 50):
        ob.update(k * 1e-3, None if k % 7 == 0 else (frozen if k % 5 == 0 else q))
    assert list(kernel.signatures) == signatures and len(signatures) == 1


def test_a_never_behind_blend_over_the_auto_kf_compiles_nothing_in_its_updates(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The ``"auto"`` kf's output (copied out of its state's buffer, ``fresh_output``) is
    writable, as the blend's kernels take their arrays: a read-only one was a second
    signature of ``neverbehind.score_kernel``, loaded in the first update (11 ms).  Checked on
    the arrays the updates pass (a spy on each kernel): another test of the same process may
    have compiled the read-only signature already (``test_purity`` steps read-only states)."""
    from pinobs.observers import neverbehind

    robot = pinobs.load("ur5")
    ob = pinobs.make_observer("ekf", robot, noise_std=1e-4, rate=1000.0, never_behind=True)
    kernels = (neverbehind.score_kernel, neverbehind.log_odds_kernel)
    before = [list(k.compiled.signatures) for k in kernels if k.compiled is not None]
    read_only: list[str] = []
    calls = [0]

    def spy(kernel: Any) -> Any:
        compiled = kernel.compiled

        def call(*args: Any) -> Any:
            calls[0] += 1
            read_only.extend(
                f"{kernel.fn.__name__} argument {i}"
                for i, a in enumerate(args)
                if isinstance(a, np.ndarray) and not a.flags.writeable
            )
            return compiled(*args)

        return call

    for kernel in kernels:
        monkeypatch.setattr(kernel, "compiled", spy(kernel))
    ob.reset(0.0, robot.neutral())
    for k in range(1, 30):
        ob.update(k * 1e-3, None if k % 7 == 0 else robot.neutral())
    monkeypatch.undo()
    after = [list(k.compiled.signatures) for k in kernels if k.compiled is not None]
    assert calls[0] >= 29 and read_only == []
    assert len(after) == 2 and after == before


def test_the_auto_state_is_one_buffer_read_through_read_only_views() -> None:
    """Issue 39: ``"auto"``'s state lies in one float64 buffer (``AutoState.x``, laid out by
    ``kf_kernels.auto_layout``); its fields are read-only views of it, a step writes a new
    buffer and leaves the one it read as it was; the estimate is a copy of the mixture of
    its own (``fresh_output``, and the fused update's array of ``q̂``, ``v̂`` and the held
    torque: it keeps nothing of the state's buffer alive)."""
    robot = pinobs.load("ur5")
    ob = pinobs.make_observer("kf", robot, noise_std=1e-4, rate=1000.0)
    ob.reset(0.0, robot.neutral())
    rng = np.random.default_rng(0)
    for k in range(1, 40):
        ob.update(k * 1e-3, robot.neutral() + 1e-4 * rng.standard_normal(robot.nv))
    state = ob._state
    before = state.x.copy()
    nf, nv = len(AUTO_LAMBDAS), robot.nv
    bank = state.bank
    parts = (bank.q, bank.v, bank.a, bank.P, state.A, state.B, state.w, state.mix)
    shapes = [(nf, nv), (nf, nv), (nf, nv), (nf, 3, 3), (nf, nv), (nf,), (nf, nv), (2 * nv,)]
    assert [p.shape for p in parts] == shapes and bank.innovation is not None
    for part in parts:
        assert np.shares_memory(part, state.x) and not part.flags.writeable
    assert np.allclose(state.w.sum(axis=0), 1.0)
    e = ob.update(40e-3, robot.neutral())
    assert ob._state.x is not state.x and np.array_equal(state.x, before)
    assert np.array_equal(np.concatenate([e.q, e.v]), ob._state.mix)
    assert not np.shares_memory(e.q, ob._state.x) and not e.q.flags.writeable
    # the mixture's copy (kf_fused: one new read-only array; the torque held in the filter's)
    assert e.q.base is not None and e.q.base.size == robot.nq + nv and e.v.base is e.q.base
    predicted = ob.step(ob._state, 1e-3, None, np.zeros(nv))
    assert predicted.bank.innovation is None and np.array_equal(predicted.w, ob._state.w)


def test_the_auto_kernels_covariance_prediction_is_the_general_one() -> None:
    """``_predict_covariance_ca`` (``F`` written out: its products by 1 and 0 and its sums of
    0 left out) gives the bits of ``_predict_covariance`` (``F P Fᵀ + j Q₁``) on covariances
    of every scale, and zeros in them."""
    from pinobs.observers import kf_kernels

    def plain(f):  # the Python function (numba's compiled one once loaded: the same arithmetic)
        return getattr(f, "py_func", f)

    general, written = (
        plain(kf_kernels.predict_covariance),
        plain(kf_kernels._predict_covariance_ca),
    )
    rng = np.random.default_rng(1)
    for trial in range(300):
        h = float(10.0 ** rng.uniform(-4, -1))
        F, Q1 = np.eye(3), np.zeros((3, 3))
        plain(kf_kernels.transition_into)(h, F, Q1)
        L = rng.standard_normal((3, 3)) * 10.0 ** rng.uniform(-8, 2, size=(3, 1))
        P = L @ L.T
        if trial % 3 == 0:
            P[0, 1] = P[1, 0] = P[1, 2] = P[2, 1] = 0.0  # (the start's diagonal)
        jerk = float(10.0 ** rng.uniform(-6, 6))
        a, b = np.empty((3, 3)), np.empty((3, 3))
        general(F, Q1, jerk, P, np.empty((3, 3)), a)
        written(h, F[0, 2], jerk, Q1, P, b)
        assert np.array_equal(a, b), (trial, a - b)


@pytest.mark.filterwarnings("ignore::pinobs.errors.NoiseWarning")  # σ learnt from the data
@pytest.mark.parametrize("robot_name", ["planar_3r", "ur5"])
def test_update_rows_gives_the_bits_of_the_updates(
    rng: np.random.Generator, robot_name: str
) -> None:
    """``update_rows`` (the compiled loop over rows a whole log's run takes) after σ was learnt
    from the first second and replayed: the same velocities, last estimate, consistency and
    next update as ``update`` row by row, an outlier the gate rejects included."""
    robot = pinobs.load(robot_name)
    t, _, qm = _white_jerk_log(rng, np.full(robot.nv, 1e3), 3000, 1e-3, 1e-4)
    qm[2000, 0] += 0.05  # rejected by the outlier gate
    one, rows = (pinobs.make_observer("kf", robot) for _ in range(2))  # σ from the data
    for ob in (one, rows):
        ob.reset(t[0], qm[0])
    v_one = np.array([one.update(t[k], qm[k]).v for k in range(1, t.size - 1)])
    m = 1200  # after the first second: σ learnt, replayed
    v_rows = [rows.update(t[k], qm[k]).v for k in range(1, m)]
    q_r, v_r = rows.update_rows(t[m:-1], qm[m:-1], np.full(robot.nv, np.inf))
    assert q_r.shape == (t.size - 1 - m, robot.nq)
    np.testing.assert_array_equal(np.vstack([v_rows, v_r]), v_one)
    np.testing.assert_array_equal(q_r[-1], one.estimate.q)
    assert rows.consistency() == one.consistency() and one.consistency().gated >= 1
    np.testing.assert_array_equal(rows.update(t[-1], qm[-1]).v, one.update(t[-1], qm[-1]).v)


@pytest.mark.filterwarnings("ignore::pinobs.errors.NoiseWarning")  # σ learnt from the data
def test_update_rows_stops_before_a_velocity_past_its_bound(rng: np.random.Generator) -> None:
    """The first row whose ``|v̂_i|`` passes ``v_max`` is left (the state before it kept): its
    ``update`` then gives the estimate the rows one by one give."""
    robot = pinobs.load("planar_3r")
    t, _, qm = _white_jerk_log(rng, np.full(robot.nv, 1e3), 2000, 1e-3, 1e-4)
    one, rows = (pinobs.make_observer("kf", robot) for _ in range(2))
    for ob in (one, rows):
        ob.reset(t[0], qm[0])
    v_one = np.array([one.update(t[k], qm[k]).v for k in range(1, t.size)])
    for k in range(1, 1200):
        rows.update(t[k], qm[k])
    v_max = np.full(robot.nv, np.inf)
    v_max[1] = float(np.median(np.abs(v_one[1199:, 1])))
    first = int(np.argmax(np.abs(v_one[1199:, 1]) > v_max[1]))  # the first row past it
    q_r, v_r = rows.update_rows(t[1200:], qm[1200:], v_max)
    assert q_r.shape[0] == first > 0
    np.testing.assert_array_equal(v_r, v_one[1199 : 1199 + first])
    np.testing.assert_array_equal(
        rows.update(t[1200 + first], qm[1200 + first]).v, v_one[1199 + first]
    )


def test_update_rows_takes_nothing_while_sigma_is_learnt_or_on_unit_blocks() -> None:
    """Before σ is learnt (the updates kept for the replay), and on a free-flyer (``update``
    normalises its quaternion), ``update_rows`` takes no row: ``update`` does."""
    for name in ("planar_3r", "go1"):
        robot = pinobs.load(name)
        t, qs = _ramp(robot, np.linspace(-1.0, 1.0, robot.nv), 1500, 1e-3)
        ob = pinobs.make_observer("kf", robot, noise_std=None if name == "planar_3r" else 1e-4)
        ob.reset(t[0], qs[0])
        for k in range(1, 10 if name == "planar_3r" else 1200):
            ob.update(t[k], qs[k])
        q_r, _ = ob.update_rows(t[1300:], np.array(qs[1300:]), np.full(robot.nv, np.inf))
        assert q_r.shape[0] == 0

"""The lab logger: a run recorded with drops, a second clock, stale rows and printed digits."""

from __future__ import annotations

import warnings
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import pinobs
from pinobs.errors import ConsistencyWarning, DimensionError, GainError, TimestampWarning
from pinobs.io import read_log
from pinobs.simulation import Logger, RecordedLog, Result

RATE = 500.0
P = 1.0 / RATE


def synthetic(n: int, *, nq: int = 3, seed: int = 0, lost: float = 0.0) -> Result:
    """A run of ``n`` ticks without dynamics (fast, any length): smooth q, random tau,
    the sensor's q_meas NaN at tick 0 and at a fraction ``lost`` of the others."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * P
    q = np.sin(np.outer(t, np.arange(1, nq + 1))) + 0.1
    q_meas = q + rng.normal(0.0, 1e-4, q.shape)
    q_meas[0] = np.nan
    q_meas[1:][rng.random(n - 1) < lost] = np.nan
    tau = rng.normal(0.0, 20.0, (n, nq))
    return Result(
        robot="synthetic",
        t=t,
        q=q,
        v=np.cos(q),
        tau=tau,
        q_meas=q_meas,
        traces=(),
        meta={"rate": RATE},
    )


@cache
def ur5_run() -> tuple[pinobs.Robot, Result]:
    robot = pinobs.load("ur5")
    sensor = pinobs.Sensor(RATE, 1e-4, dropout=0.02)
    return robot, pinobs.simulate(robot, [], duration=1.0, sensor=sensor, seed=4)


def runs(mask: np.ndarray) -> np.ndarray:
    """Lengths of the runs of True in a boolean array."""
    padded = np.concatenate([[False], mask, [False]]).astype(int)
    edges = np.flatnonzero(np.diff(padded))
    return edges[1::2] - edges[::2]


def lost_ticks(log: RecordedLog, n: int) -> np.ndarray:
    lost = np.ones(n, dtype=bool)
    lost[log.tick] = False
    return lost


# ------------------------------------------------------------------ the defaults
def test_default_logger_reproduces_the_runs_samples_exactly() -> None:
    res = synthetic(2001, lost=0.05)
    log = Logger().record(res, np.random.default_rng(1))
    np.testing.assert_array_equal(log.t, res.t)
    np.testing.assert_array_equal(log.q, res.q_meas)  # NaN rows included, equal as NaN
    np.testing.assert_array_equal(log.tau, res.tau)
    np.testing.assert_array_equal(log.tick, np.arange(res.t.size))
    assert not log.stale.any()
    assert log.period == P
    assert log.robot == "synthetic"


def test_recording_is_reproducible_from_the_seed() -> None:
    res = synthetic(3001)
    logger = Logger(drop=0.1, burst=3.0, jitter=4e-4, stale=0.1, digits=5, resolution=1e-4)
    a = logger.record(res, np.random.default_rng(7))
    b = logger.record(res, 7)
    for k in ("t", "q", "tau", "tick", "stale"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))


def test_recorded_arrays_are_read_only() -> None:
    log = Logger(stale=0.2).record(synthetic(101), 0)
    for k in ("t", "q", "tau", "tick", "stale"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(log, k)[0] = 0


# ------------------------------------------------------------------ drops
def test_single_drops_have_the_given_rate_within_binomial_tolerance() -> None:
    n, drop = 50_001, 0.05
    log = Logger(drop=drop).record(synthetic(n), np.random.default_rng(11))
    lost = lost_ticks(log, n)
    # the chain's count is no more spread than a binomial's (lost ticks never touch)
    assert abs(lost.mean() - drop) <= 4.0 * np.sqrt(drop * (1 - drop) / n)
    assert set(runs(lost).tolist()) == {1}


@pytest.mark.parametrize(("drop", "burst"), [(0.02, 5.0), (0.1, 3.0)])
def test_bursts_have_the_given_mean_length_and_rate(drop: float, burst: float) -> None:
    n = 200_001
    log = Logger(drop=drop, burst=burst).record(synthetic(n, nq=1), np.random.default_rng(3))
    lost = lost_ticks(log, n)
    lengths = runs(lost)
    # lost runs: geometric, mean burst, variance burst (burst - 1)
    assert abs(lengths.mean() - burst) <= 5.0 * np.sqrt(burst * (burst - 1) / lengths.size)
    # alternating renewal CLT: Var(f) ≈ Var((1-f) L - f K) / (N E[C])
    a = drop / (burst * (1 - drop))
    var_cycle = (1 - drop) ** 2 * burst * (burst - 1) + drop**2 * (1 - a) / a**2
    sigma = np.sqrt(var_cycle / (n * (burst + 1 / a)))
    assert abs(lost.mean() - drop) <= 5.0 * sigma
    assert lengths.max() > 3  # bursts, not single drops


def test_rows_record_the_kept_ticks_in_order() -> None:
    res = synthetic(5001)
    log = Logger(drop=0.2, burst=2.0, stale=0.1).record(res, 5)
    fresh = log.tick[~log.stale]
    assert np.all(np.diff(fresh) > 0)
    np.testing.assert_array_equal(log.q[~log.stale], res.q_meas[fresh])
    np.testing.assert_array_equal(log.tau[~log.stale], res.tau[fresh])


# ------------------------------------------------------------------ stamps
CLOCKS = [
    {"jitter": 3e-4, "offset": 12.5, "drift": 50e-6},
    {"jitter": P / 2, "offset": -3.0, "drift": -80e-6},
    {"jitter": 2.5 * P, "offset": 0.0, "drift": 1e-3},  # jitter over half the spacing
    {"jitter": 0.9 * P, "drop": 0.3, "burst": 2.0, "stale": 0.2},
]


@pytest.mark.parametrize("clock", CLOCKS)
def test_stamps_strictly_increase(clock: dict[str, float]) -> None:
    log = Logger(**clock).record(synthetic(20_001, nq=1), np.random.default_rng(2))
    assert np.all(np.diff(log.t) > 0)


@pytest.mark.parametrize("clock", CLOCKS)
def test_fresh_stamps_are_within_jitter_of_the_drifting_clock(clock: dict[str, float]) -> None:
    res = synthetic(20_001, nq=1)
    logger = Logger(**clock)
    log = logger.record(res, np.random.default_rng(8))
    fresh = ~log.stale
    nominal = logger.offset + (1 + logger.drift) * res.t[log.tick[fresh]]
    err = log.t[fresh] - nominal
    eps = 1e-9  # float rounding of stamps of ~1e1 s
    assert np.all(np.abs(err) <= logger.jitter + eps)
    # and the errors fill the band: uniform, not squeezed to zero
    assert np.abs(err).max() > 0.9 * logger.jitter


def test_without_jitter_stamps_are_the_drifting_clock_exactly() -> None:
    res = synthetic(1001)
    log = Logger(offset=7.25, drift=50e-6).record(res, 0)
    np.testing.assert_array_equal(log.t, 7.25 + (1 + 50e-6) * res.t)


def test_stamps_on_a_resolution_grid_keep_within_half_a_step_of_the_clock() -> None:
    res = synthetic(20_001, nq=1)
    logger = Logger(jitter=2e-4, offset=100.0, drift=50e-6, resolution=1e-4)
    log = logger.record(res, np.random.default_rng(4))
    steps = log.t / 1e-4
    np.testing.assert_allclose(steps, np.rint(steps), rtol=0, atol=1e-6)
    nominal = logger.offset + (1 + logger.drift) * res.t[log.tick]
    assert np.all(np.abs(log.t - nominal) <= 2e-4 + 0.5e-4 + 1e-9)
    assert np.all(np.diff(log.t) > 0)


def test_stale_rows_on_a_coarse_grid_take_the_free_step_between_their_neighbours() -> None:
    # 1 ms stamps at 500 Hz: the one free millisecond between two rows
    res = synthetic(10_001, nq=1)
    log = Logger(stale=0.5, resolution=1e-3).record(res, np.random.default_rng(6))
    k = np.flatnonzero(log.stale)
    np.testing.assert_allclose(log.t[k] - log.t[k - 1], 1e-3, rtol=0, atol=1e-9)
    fresh = int((~log.stale).sum())
    assert abs(k.size - 0.5 * fresh) <= 4.0 * np.sqrt(fresh * 0.25)  # none left out


def test_stale_rows_without_a_free_step_are_not_written() -> None:
    # 1.5 ms stamps at 500 Hz: consecutive rows are one or two steps apart
    res = synthetic(10_001, nq=1)
    log = Logger(stale=0.5, resolution=1.5e-3).record(res, np.random.default_rng(6))
    assert np.all(np.diff(log.t) > 0)
    np.testing.assert_array_equal(log.tick[~log.stale], np.arange(res.t.size))  # all kept
    k = np.flatnonzero(log.stale)
    np.testing.assert_allclose(log.t[k] - log.t[k - 1], 1.5e-3, rtol=0, atol=1e-9)
    fresh_gaps = np.diff(log.t[~log.stale])
    assert 0 < k.size < 0.5 * np.sum(fresh_gaps > 2e-3) + 4.0 * np.sqrt(fresh_gaps.size)


def test_fresh_stamps_rounded_together_are_moved_apart() -> None:
    res = synthetic(20_001, nq=1)
    logger = Logger(jitter=0.9 * P, resolution=P / 4)
    log = logger.record(res, np.random.default_rng(13))
    assert np.all(np.diff(log.t) > 0)
    steps = log.t / (P / 4)
    np.testing.assert_allclose(steps, np.rint(steps), rtol=0, atol=1e-6)
    err = np.abs(log.t - res.t[log.tick])
    assert np.mean(err <= logger.jitter + P / 8 + 1e-12) > 0.99  # rounded, rarely moved


def test_stamps_rounded_together_are_moved_to_the_next_free_step() -> None:
    from pinobs.simulation.logger import _grid_steps

    t = np.array([0.0, 0.4, 0.45, 2.0, 2.1, 7.6])
    np.testing.assert_array_equal(_grid_steps(t, 1.0), [0, 1, 2, 3, 4, 8])


# ------------------------------------------------------------------ stale rows
def test_stale_rows_repeat_their_predecessor_exactly() -> None:
    res = synthetic(10_001, lost=0.05)
    log = Logger(stale=0.2, jitter=2e-4, digits=6).record(res, np.random.default_rng(9))
    k = np.flatnonzero(log.stale)
    assert k.size > 0 and k[0] > 0
    assert not np.any(log.stale[k - 1])  # one stale copy at most, after a fresh row
    np.testing.assert_array_equal(log.q[k], log.q[k - 1])
    np.testing.assert_array_equal(log.tau[k], log.tau[k - 1])
    np.testing.assert_array_equal(log.tick[k], log.tick[k - 1])
    assert np.all(log.t[k] > log.t[k - 1])
    inner = k[k + 1 < len(log)]
    assert np.all(log.t[inner] < log.t[inner + 1])


def test_stale_rows_have_the_given_rate_within_binomial_tolerance() -> None:
    stale = 0.04
    log = Logger(stale=stale, drop=0.1).record(synthetic(50_001, nq=1), np.random.default_rng(12))
    fresh = int((~log.stale).sum())
    count = int(log.stale.sum())
    assert abs(count - stale * fresh) <= 4.0 * np.sqrt(fresh * stale * (1 - stale))


# ------------------------------------------------------------------ digits
@pytest.mark.parametrize("digits", [1, 3, 4, 8, 15, 16])
def test_values_are_rounded_to_the_given_significant_digits(digits: int) -> None:
    res = synthetic(2001, lost=0.05)
    # tau over many magnitudes, including large and tiny ones
    log = Logger(digits=digits).record(res, 0)
    for got, raw in ((log.q, res.q_meas), (log.tau, res.tau)):
        np.testing.assert_array_equal(np.isnan(got), np.isnan(raw))
        ok = np.isfinite(raw) & (raw != 0)
        for y, x in zip(got[ok][:3000], raw[ok][:3000], strict=True):
            assert float(f"{y:.{digits}g}") == y  # a decimal of `digits` digits
            unit = 10.0 ** (np.floor(np.log10(abs(x))) - digits + 1)
            # half a unit of the last digit, up to the float rounding of x·10^k
            assert abs(y - x) <= 0.5 * unit + 4 * np.spacing(abs(x))


def test_rounding_keeps_values_of_any_magnitude_and_their_sign() -> None:
    from pinobs.simulation.logger import _significant

    x = np.array([0.0, -0.0, 1e-300, -123456.789, 9.9996, 2.5e20, np.nan, np.inf, -5e-324])
    y = _significant(x, 4)
    expect = [float(f"{v:.4g}") if np.isfinite(v) else v for v in x]
    np.testing.assert_array_equal(y, expect)
    assert np.signbit(y[1])


def test_seventeen_digits_leave_values_unchanged() -> None:
    res = synthetic(501)
    log = Logger(digits=17).record(res, 0)
    np.testing.assert_array_equal(log.q, res.q_meas)
    np.testing.assert_array_equal(log.tau, res.tau)


def test_a_lost_sensor_sample_stays_nan() -> None:
    _, res = ur5_run()
    log = Logger(drop=0.1, stale=0.1, digits=4).record(res, 3)
    np.testing.assert_array_equal(
        np.isnan(log.q).all(axis=1), np.isnan(res.q_meas[log.tick]).all(axis=1)
    )
    assert np.isnan(log.q).all(axis=1).sum() > 1  # tick 0 and the sensor's dropouts


# ------------------------------------------------------------------ files
@pytest.mark.parametrize("named", [True, False])
def test_csv_reads_back_the_same_arrays(tmp_path: Path, named: bool) -> None:
    robot, res = ur5_run()
    logger = Logger(drop=0.05, burst=3, jitter=3e-4, offset=50.0, drift=50e-6, stale=0.05)
    log = logger.record(res, np.random.default_rng(10))
    path = log.to_csv(tmp_path / "sub" / "log.csv", robot if named else None)
    back = read_log(path, robot)
    np.testing.assert_array_equal(back.t, log.t)
    np.testing.assert_array_equal(back.q, log.q)
    assert back.tau is not None
    np.testing.assert_array_equal(back.tau, log.tau)
    header = path.read_text().splitlines()[0].split(",")
    assert header == log.columns(robot if named else None)


def test_frame_has_the_readers_named_columns_and_reads_back() -> None:
    robot, res = ur5_run()
    log = Logger(digits=6, resolution=1e-3).record(res, 1)
    frame = log.to_frame(robot)
    assert list(frame.columns) == [
        "t",
        *(f"q.{j}" for j in robot.joint_names),
        *(f"tau.{j}" for j in robot.joint_names),
    ]
    back = read_log(frame, robot)
    np.testing.assert_array_equal(back.t, log.t)
    np.testing.assert_array_equal(back.q, log.q)


def test_frame_refuses_a_robot_of_other_dimensions() -> None:
    log = Logger().record(synthetic(11, nq=3), 0)
    with pytest.raises(DimensionError, match=r"nq = 6.*nq = 3"):
        log.to_frame(pinobs.load("ur5"))


# ------------------------------------------------------------------ errors
@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"drop": -0.1}, r"drop=-0\.1 .*\[0, 1\)"),
        ({"drop": 1.0}, r"drop=1\.0 .*\[0, 1\)"),
        ({"stale": 1.0}, r"stale=1\.0 .*\[0, 1\)"),
        ({"stale": -1e-3}, r"stale=-0\.001"),
        ({"drop": "0.1"}, r"drop='0\.1' is not a number"),
        ({"drop": 0.6}, r"drop=0\.6 with burst=1\.0.*0\.5"),
        ({"burst": 0.5}, r"burst=0\.5 .*>= 1"),
        ({"burst": float("inf")}, r"burst=inf is not finite"),
        ({"jitter": -1e-3}, r"jitter=-0\.001 is negative"),
        ({"jitter": float("nan")}, r"jitter=nan is not finite"),
        ({"offset": float("inf")}, r"offset=inf"),
        ({"drift": -1.0}, r"drift=-1\.0 .*> -1"),
        ({"digits": 0}, r"digits=0: .*1\.\.17"),
        ({"digits": 18}, r"digits=18"),
        ({"digits": 2.5}, r"digits=2\.5"),
        ({"digits": True}, r"digits=True"),
        ({"resolution": 0.0}, r"resolution=0\.0 .*> 0"),
        ({"resolution": -1e-3}, r"resolution=-0\.001"),
    ],
)
def test_bad_options_are_refused_by_name(options: dict[str, object], match: str) -> None:
    with pytest.raises(GainError, match=match):
        Logger(**options)  # type: ignore[arg-type]


def test_a_resolution_not_finer_than_the_rows_is_refused_at_recording() -> None:
    with pytest.raises(GainError, match=r"resolution=0\.002 s is not finer .* 0\.002"):
        Logger(resolution=2e-3).record(synthetic(11), 0)


def test_gain_errors_are_value_errors() -> None:
    with pytest.raises(ValueError, match="jitter"):
        Logger(jitter=-1.0)


def test_a_run_whose_every_tick_is_lost_gives_an_empty_log() -> None:
    log = Logger(drop=0.9, burst=10.0).record(synthetic(3, nq=2), 0)  # seed 0: all 3 lost
    assert len(log) == 0
    assert log.q.shape == (0, 2) and log.tau.shape == (0, 2) and log.tick.shape == (0,)


# ------------------------------------------------------------------ any options
@st.composite
def loggers(draw: st.DrawFn) -> Logger:
    burst = draw(st.floats(1.0, 8.0))
    return Logger(
        drop=draw(st.floats(0.0, 0.9 * burst / (1 + burst))),
        burst=burst,
        jitter=draw(st.sampled_from([0.0, 1e-5, 0.3 * P, 0.5 * P, 0.7 * P, 3 * P])),
        offset=draw(st.floats(-1e3, 1e3)),
        drift=draw(st.floats(-1e-3, 1e-3)),
        stale=draw(st.floats(0.0, 0.9)),
        digits=draw(st.none() | st.integers(1, 17)),
        resolution=draw(st.sampled_from([None, 1e-6, 1e-4, 1e-3, 0.9 * P])),
    )


@settings(max_examples=60, deadline=None)
@given(logger=loggers(), seed=st.integers(0, 2**32 - 1))
def test_any_logger_writes_increasing_stamps_and_exact_stale_copies(
    logger: Logger, seed: int
) -> None:
    res = synthetic(400, nq=2, lost=0.1)
    log = logger.record(res, seed)
    assert np.all(np.diff(log.t) > 0)
    k = np.flatnonzero(log.stale)
    assert not np.any(log.stale[k - 1])
    np.testing.assert_array_equal(log.q[k], log.q[k - 1])
    np.testing.assert_array_equal(log.tau[k], log.tau[k - 1])
    np.testing.assert_array_equal(log.tick[k], log.tick[k - 1])
    fresh = log.tick[~log.stale]
    assert np.all(np.diff(fresh) > 0)
    np.testing.assert_array_equal(np.isnan(log.q), np.isnan(res.q_meas[log.tick]))


def test_a_recorded_log_runs_through_the_estimator_row_for_row() -> None:
    robot, res = ur5_run()
    logger = Logger(drop=0.05, burst=3.0, jitter=5e-5, drift=50e-6, offset=10.0, stale=0.05)
    log = logger.record(res, 2)
    frame = log.to_frame(robot)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        as_stamped = pinobs.estimate("kf", frame, robot=robot, noise_std=1e-4, clock="stamps")
    # as stamped, the stale rows are said and kf finds the data inconsistent
    said = {w.category for w in seen}
    assert {TimestampWarning, ConsistencyWarning} <= said, said
    assert len(as_stamped) == len(log)
    np.testing.assert_array_equal(as_stamped["t"].to_numpy(), log.t)
    v = as_stamped[[f"v{i}" for i in range(robot.nv)]].to_numpy()
    late = (res.t[log.tick] > 0.5) & ~log.stale
    rms = np.sqrt(np.mean((v[late] - res.v[log.tick[late]]) ** 2))
    assert rms < 0.05, rms  # rad/s
    # the default repairs the clock: every row at the logger-clock time of its tick
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        df = pinobs.estimate("kf", frame, robot=robot, noise_std=1e-4)
    told = [str(w.message) for w in seen if w.category is TimestampWarning]
    assert len(told) == 1 and told[0].startswith("log clock repaired"), told
    assert not [w for w in seen if w.category is ConsistencyWarning]  # consistent again
    assert len(df) == len(log)
    expected = 10.0 + (1 + 50e-6) * res.t[log.tick]
    placed = np.isfinite(log.q).all(axis=1)  # (a row without a position keeps its stamp)
    assert np.max(np.abs(df["t"].to_numpy()[placed] - expected[placed])) < 2e-6
    assert df.attrs["clock"].stale == int(log.stale.sum())


def test_a_tiny_drop_rate_keeps_every_tick() -> None:
    # geometric run lengths of 2**63 - 1 once crashed numpy (found by the property test)
    res = synthetic(1001)
    log = Logger(drop=1e-300).record(res, 0)
    np.testing.assert_array_equal(log.tick, np.arange(res.t.size))

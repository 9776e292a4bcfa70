"""The noise level from the data: σ per joint from the log, and estimates as good as with the true σ."""

from __future__ import annotations

import numpy as np
import pytest

import pinobs
from pinobs.io import estimate_noise_std, process_log

pd = pytest.importorskip("pandas")


@pytest.mark.parametrize("sigma", [1e-2, 1e-3, 1e-5])
def test_sigma_is_recovered_per_joint_on_a_moving_robot(sigma) -> None:
    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=1.0, sensor=pinobs.Sensor(1000.0, sigma), seed=4)
    est = estimate_noise_std(res.t[1:], res.q_meas[1:], robot)
    assert est is not None and est.shape == (6,)
    # 1000 samples: the robust estimate's relative spread is about 4 %
    np.testing.assert_allclose(est, sigma, rtol=0.15)


def test_sigma_on_a_lie_group_robot_counts_quaternions_as_angles() -> None:
    robot = pinobs.load("rigid_body")
    res = pinobs.simulate(robot, [], duration=1.0, sensor=pinobs.Sensor(1000.0, 1e-3), seed=4)
    est = estimate_noise_std(res.t[1:], res.q_meas[1:], robot)
    assert est is not None and est.shape == (robot.nv,)
    assert np.all(est > 0.3e-3) and np.all(est < 3e-3)  # same order as σ in every tangent direction


def test_glitches_do_not_inflate_sigma() -> None:
    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=1.0, sensor=pinobs.Sensor(1000.0, 1e-3), seed=4)
    q = res.q_meas[1:].copy()
    q[::50, 2] += 0.5  # 2 % of the rows are 0.5 rad glitches
    est = estimate_noise_std(res.t[1:], q, robot)
    assert est is not None and est[2] < 1.3e-3


@pytest.mark.parametrize("dropped", [0.05, 0.3])
@pytest.mark.parametrize("removed", [False, True])
def test_dropped_samples_do_not_inflate_sigma(dropped: float, removed: bool) -> None:
    """A dropped sample (a NaN row, or a row absent with its time) broke the third difference:
    differences across it are not third ones.  UR5, σ = 1e-4, 1 kHz, samples dropped at random
    (seed 0).  Measured σ̂/σ: 1.12 (5 %) and 1.94 (30 %) before, 1.06 and 1.05 now (1.04 with
    none dropped)."""
    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=1.5, sensor=pinobs.Sensor(1000.0, 1e-4), seed=1)
    t, q = res.t, res.q_meas.copy()
    q[np.random.default_rng(0).random(len(q)) < dropped] = np.nan
    if removed:
        keep = np.isfinite(q).all(axis=1)
        t, q = t[keep], q[keep]
    est = estimate_noise_std(t, q, robot)
    assert est is not None
    assert 0.9 < np.median(est) / 1e-4 < 1.1


def test_the_report_names_the_rows_it_used_when_the_log_starts_with_nan() -> None:
    """The sentence said "the log's first second" of a log whose first second was NaN; it
    now gives the rows' times."""
    from pinobs.observers.noise import noise_from_log

    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=2.5, sensor=pinobs.Sensor(1000.0, 1e-3), seed=4)
    q = res.q_meas.copy()
    q[: int(np.searchsorted(res.t, 1.0))] = np.nan
    found = noise_from_log(res.t, q, robot)
    assert found is not None
    sigma, _, said = found
    assert abs(sigma - 1e-3) < 0.2e-3
    assert "first second of finite rows (1001 rows, t = 1 to 2 s)" in said


def test_the_report_says_it_took_more_than_the_first_second_of_a_slow_log() -> None:
    """At 100 Hz the first second has 100 rows and the estimate takes 200 (TIAGo's log:
    "the log's first second ... (200 rows, t = 0.0004 to 2.0004 s)"): it says so."""
    from pinobs.observers.noise import noise_from_log

    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=3.0, sensor=pinobs.Sensor(100.0, 1e-3), seed=4)
    found = noise_from_log(res.t[1:], res.q_meas[1:], robot)
    assert found is not None
    assert (
        "first 200 finite rows (its first second has fewer) (200 rows, t = 0.01 to 2 s)"
        in (found[2])
    )


def test_too_short_a_log_gives_no_estimate() -> None:
    robot = pinobs.load("ur5")
    assert estimate_noise_std(np.arange(5) * 1e-3, np.zeros((5, 6)), robot) is None


@pytest.mark.parametrize("name", ["kf", pytest.param("ekf", marks=pytest.mark.slow)])
def test_without_a_noise_level_estimates_are_within_1_3x_of_those_with_the_true_sigma(name) -> None:
    # before: σ = 1e-6 assumed, 16-57x worse on σ = 1e-3 data, silently
    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=2.0, sensor=pinobs.Sensor(1000.0, 1e-3), seed=5)
    t, q, tau, v = res.t[1:], res.q_meas[1:], res.tau[1:], res.v[1:]
    df = pd.DataFrame({"t": t, **{f"q{i}": q[:, i] for i in range(6)}})
    df = df.assign(**{f"tau{i}": tau[:, i] for i in range(6)})
    k0 = t.size // 4
    estimated = process_log(df, robot, name)
    given = process_log(df, robot, name, noise_std=1e-3)
    rms_est = np.sqrt(np.mean((estimated.v[k0:] - v[k0:]) ** 2))
    rms_true = np.sqrt(np.mean((given.v[k0:] - v[k0:]) ** 2))
    assert rms_est <= 1.3 * rms_true  # measured ratios 0.98 (kf) and 1.00 (ekf) on 4 s
    assert estimated.noise_std == pytest.approx(1e-3, rel=0.15)
    assert any("estimated σ = " in w for w in estimated.warnings)


def test_a_log_at_rest_in_its_first_second_takes_the_rounding_of_its_printed_positions() -> None:
    """Real logs start at rest with positions printed to a few decimals (the UR10e's 4):
    their third differences are 0 there, and σ̂ was ~1e-17, which make_observer refused."""
    from pinobs.observers.noise import noise_from_log

    robot = pinobs.load("ur5")
    t = np.arange(3000) * 1e-3
    q = np.tile(np.round(np.linspace(0.1, 0.6, robot.nq), 4), (t.size, 1))
    q[1500:, :2] += np.round(0.2 * np.sin(np.linspace(0, 3, 1500))[:, None], 4)  # then moves
    sigma, per_joint, said = noise_from_log(t, q, robot)
    assert sigma == pytest.approx(1e-4 / np.sqrt(12))  # two joints move: their step/√12
    assert per_joint[0] == per_joint[1] == pytest.approx(1e-4 / np.sqrt(12))
    assert "the joints that move (2 of 6)" in said and "printed" in said
    pinobs.make_observer("kf", robot, noise_std=sigma)  # accepted


def test_the_log_sigma_is_the_median_over_the_joints_that_move() -> None:
    from pinobs.observers.noise import STILL_STD, moving_median

    sigma, told = moving_median(np.array([1e-17, 3e-4, 1e-4, 2e-4, 0.0]))
    assert sigma == 2e-4  # the median of the three that move
    assert told.tolist() == [False, True, True, True, False]
    still = np.array([1e-17, 0.5 * STILL_STD, 0.0])
    assert moving_median(still)[0] == np.median(still)  # none moves: over all of them


def test_a_joint_at_rest_in_the_first_second_is_measured_over_all_rows_when_asked() -> None:
    """pinobs.identify's σ (rest_over_all_rows): a joint still in the first second (its
    printed positions repeat: only the rounding there) is measured over the whole log."""
    from pinobs.observers.noise import joint_noise_std, quantisation_std

    robot = pinobs.load("ur5")
    rng = np.random.default_rng(7)
    t = np.arange(4000) * 1e-3
    q = np.tile(np.linspace(0.1, 0.6, robot.nq), (t.size, 1))
    q += 0.2 * np.sin(t)[:, None] + 1e-3 * rng.standard_normal(q.shape)
    q[:1200, 0] = 0.1  # joint 0 still for its first 1.2 s
    q = np.round(q, 6)
    quantum = quantisation_std(q, robot)
    first = joint_noise_std(t, q, robot)
    whole = joint_noise_std(t, q, robot, rest_over_all_rows=True)
    assert first is not None and whole is not None
    assert first[0][0] == quantum[0] and first[1][0]  # floored to the rounding, and said so
    assert 0.5e-3 < whole[0][0] < 1.5e-3  # over all rows: the noise (70 % of them move)
    np.testing.assert_array_equal(whole[0][1:], first[0][1:])  # the moving joints unchanged

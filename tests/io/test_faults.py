"""Every fault a real log has, with its outcome: no row lost silently, each reported once."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import pinobs
from pinobs.cli import main
from pinobs.io import Log, estimate_log, read_log, write_log

pytest.importorskip("pandas")

N = 300


@pytest.fixture(scope="module")
def sim() -> pinobs.Result:
    robot = pinobs.load("ur5")
    return pinobs.simulate(robot, [], duration=2.0, sensor=pinobs.Sensor(1000.0, 1e-4), seed=1)


@pytest.fixture(scope="module")
def ur5() -> pinobs.Robot:
    return pinobs.load("ur5")


def _lines(tmp_path: Path, sim: pinobs.Result, n: int = N) -> tuple[Path, list[str]]:
    path = write_log(
        tmp_path / "log.csv", sim.t[1 : n + 1], sim.q_meas[1 : n + 1], sim.tau[1 : n + 1]
    )
    return path, path.read_text().splitlines()


def _kf(robot: pinobs.Robot) -> pinobs.Observer:
    return pinobs.make_observer("kf", robot, rate=1000.0, noise_std=1e-4)


def _estimate_kf(path: Path, out: Path) -> int:
    """``pinobs estimate`` with ``kf`` on the UR5 over ``path`` (σ given): the exit code."""
    args = ["--robot", "ur5", "--observer", "kf", "--log", str(path), "--out", str(out)]
    return main(["estimate", *args, "--no-progress", "--noise", "1e-4"])


def _set(lines: list[str], line: int, col: int, value: str) -> None:
    """Set column ``col`` of file line ``line`` (1-based, the header is line 1)."""
    cells = lines[line - 1].split(",")
    cells[col] = value
    lines[line - 1] = ",".join(cells)


def test_stray_quote_costs_its_row_only_and_names_the_line(tmp_path, sim, ur5) -> None:
    # before: the rest of the file vanished (200 rows in, 50 out, exit 0)
    path, lines = _lines(tmp_path, sim)
    _set(lines, 52, 3, '"' + lines[51].split(",")[3])
    path.write_text("\n".join(lines) + "\n")
    log = read_log(path, ur5)
    assert len(log) == N
    assert [line for line, _ in log.problems] == [52]
    run = estimate_log(_kf(ur5), log)
    assert run.v.shape == (N, 6) and np.isfinite(run.v).all()
    assert [line for line, _ in run.bad_rows] == [52]
    assert "'q2' unreadable" in run.bad_rows[0][1] and "dropped sample" in run.bad_rows[0][1]


def test_utf8_byte_order_mark_is_accepted(tmp_path, sim, ur5) -> None:
    path, _ = _lines(tmp_path, sim, n=20)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    log = read_log(path, ur5)
    assert len(log) == 20 and not log.problems
    np.testing.assert_allclose(log.q, sim.q_meas[1:21], rtol=1e-15)


def test_utf16_and_binary_files_are_errors_naming_the_line(tmp_path, sim, ur5) -> None:
    _, lines = _lines(tmp_path, sim, n=20)
    utf16 = tmp_path / "u16.csv"
    utf16.write_bytes("\n".join(lines).encode("utf-16"))
    with pytest.raises(pinobs.LogFormatError, match=r"line 1 is not UTF-8 text.*UTF-16"):
        read_log(utf16, ur5)
    broken = tmp_path / "latin1.csv"
    lines[9] = lines[9] + "\xe9"
    broken.write_bytes("\n".join(lines).encode("latin-1"))
    with pytest.raises(pinobs.LogFormatError, match=r"line 10 is not UTF-8"):
        read_log(broken, ur5)
    npy = tmp_path / "arr.csv"
    np.save(tmp_path / "arr.npy", np.zeros((3, 13)))
    npy.write_bytes((tmp_path / "arr.npy").read_bytes())
    with pytest.raises(pinobs.LogFormatError, match=r"\.npy array"):
        read_log(npy, ur5)


def test_blank_lines_are_not_rows_whichever_reader_takes_them(tmp_path, sim, ur5) -> None:
    """A blank line was a NaN row, unreported, in the fast (Arrow) reader, and not a row
    after a fallback to pandas: one log read two ways.  Now never a row, in either."""
    path, lines = _lines(tmp_path, sim, n=40)
    blank = tmp_path / "blank.csv"
    blank.write_text("\n".join([*lines[:10], "", *lines[10:30], "", *lines[30:]]) + "\n\n")
    log = read_log(blank, ur5)
    assert len(log) == 40 and not log.problems
    np.testing.assert_array_equal(log.q, read_log(path, ur5).q)
    assert log.lines[8:10].tolist() == [10, 12]  # the lines they are on (11 is blank)
    bad = lines[20].split(",")
    bad[2] = "abc"  # a bad cell between the blank lines: the careful reader from there on
    mixed = tmp_path / "mixed.csv"
    mixed.write_text(
        "\n".join([*lines[:10], "", *lines[10:20], ",".join(bad), *lines[21:30], "", *lines[30:]])
    )
    log = read_log(mixed, ur5)
    assert len(log) == 40 and [line for line, _ in log.problems] == [22]
    assert np.isnan(log.q).any(axis=1).sum() == 1


@pytest.mark.parametrize("kind", ["gzip", "bz2", "lzma"])
def test_a_compressed_log_is_an_error_saying_so(tmp_path, sim, ur5, kind) -> None:
    """A .csv.gz was refused as "line 1 is not UTF-8 text" with no word of why."""
    import importlib

    path, _ = _lines(tmp_path, sim, n=20)
    packed = tmp_path / f"log.csv.{kind}"
    packed.write_bytes(importlib.import_module(kind).compress(path.read_bytes()))
    tool = {"gzip": "gunzip -k", "bz2": "bunzip2 -k", "lzma": "unxz -k"}[kind]
    name = {"gzip": "gzip", "bz2": "bzip2", "lzma": "xz"}[kind]
    with pytest.raises(pinobs.LogFormatError, match=rf"it is {name}-compressed: .*`{tool} "):
        read_log(packed, ur5)


def test_truncated_npz_and_renamed_npy_are_clear_errors(tmp_path, sim, ur5) -> None:
    good = tmp_path / "log.npz"
    np.savez(good, t=sim.t[1:50], q=sim.q_meas[1:50], tau=sim.tau[1:50])
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[:700])
    with pytest.raises(pinobs.LogFormatError, match="truncated"):
        read_log(cut, ur5)
    np.save(tmp_path / "q.npy", sim.q_meas[1:50])
    renamed = tmp_path / "q.npz"
    (tmp_path / "q.npy").rename(renamed)
    with pytest.raises(pinobs.LogFormatError, match=r"one \.npy array of shape \(49, 6\)"):
        read_log(renamed, ur5)


def test_a_row_with_too_many_cells_is_an_error_naming_its_line(tmp_path, sim, ur5) -> None:
    path, lines = _lines(tmp_path, sim, n=50)
    lines[30] += ",1.0"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(pinobs.LogFormatError, match="line 31"):
        read_log(path, ur5)


def test_absurd_position_is_rejected_alone(tmp_path, sim, ur5) -> None:
    # before: one 1e300 poisoned every later row (kf wrote 1e266-1e299, "0 bad")
    path, lines = _lines(tmp_path, sim)
    _set(lines, 101, 2, "1e300")
    path.write_text("\n".join(lines) + "\n")
    run = estimate_log(_kf(ur5), read_log(path, ur5))
    assert [line for line, _ in run.bad_rows] == [101]
    assert "absurd" in run.bad_rows[0][1] and "dropped sample" in run.bad_rows[0][1]
    assert run.measured == N - 1 and run.estimated == N
    assert np.abs(run.v).max() < 10.0  # the truth stays below 3 rad/s


def test_absurd_torque_is_rejected_and_never_stored(tmp_path, sim, ur5) -> None:
    path, lines = _lines(tmp_path, sim)
    _set(lines, 101, 8, "1e300")  # tau1 of line 101
    path.write_text("\n".join(lines) + "\n")
    log = read_log(path, ur5)
    ekf = pinobs.make_observer("ekf", ur5, rate=1000.0, noise_std=1e-4)
    run = estimate_log(ekf, log)
    assert [line for line, _ in run.bad_rows] == [101]
    assert "torque" in run.bad_rows[0][1] and "previous torque held" in run.bad_rows[0][1]
    assert run.measured == N
    clean = estimate_log(
        pinobs.make_observer("ekf", ur5, rate=1000.0, noise_std=1e-4),
        Log(sim.t[1 : N + 1], sim.q_meas[1 : N + 1], sim.tau[1 : N + 1]),
    )
    # holding the previous torque for one period: the estimates after it stay close
    assert np.abs(run.v[120:] - clean.v[120:]).max() < 1e-2


def test_one_timestamp_far_ahead_is_rejected_alone(tmp_path, sim, ur5) -> None:
    # before: t = 51 instead of 0.050 made the 150 good rows after it NaN and blamed them
    path, lines = _lines(tmp_path, sim, n=200)
    _set(lines, 51, 0, "51")
    path.write_text("\n".join(lines) + "\n")
    run = estimate_log(_kf(ur5), read_log(path, ur5))
    assert [line for line, _ in run.bad_rows] == [51]
    assert "far ahead of the next line" in run.bad_rows[0][1]
    finite = np.isfinite(run.v).all(axis=1)
    assert finite.sum() == 199 and not finite[49]


def test_one_timestamp_out_of_order_is_rejected_alone(tmp_path, sim, ur5) -> None:
    path, lines = _lines(tmp_path, sim, n=200)
    _set(lines, 51, 0, "0.0001")
    path.write_text("\n".join(lines) + "\n")
    run = estimate_log(_kf(ur5), read_log(path, ur5))
    assert [line for line, _ in run.bad_rows] == [51]
    assert "not after the previous sample" in run.bad_rows[0][1]
    assert np.isfinite(run.v).all(axis=1).sum() == 199


@pytest.mark.parametrize("name", ["kf", "ekf", "riemannian"])
def test_a_one_second_gap_reinitialises_instead_of_one_giant_step(sim, ur5, name) -> None:
    # before: one RK4 step over 1 s, ekf 523 rad/s and riemannian 3e6 rad/s (truth 1.6)
    t, q, tau, v = sim.t[1:], sim.q_meas[1:], sim.tau[1:], sim.v[1:]
    keep = (t < 0.5) | (t >= 1.5)
    ob = pinobs.make_observer(name, ur5, rate=1000.0, noise_std=1e-4)
    run = estimate_log(ob, Log(t[keep], q[keep], tau[keep]))
    assert len(run.bad_rows) == 1
    line, reason = run.bad_rows[0]
    assert line == 499 and "gap of 1.001 s" in reason and "re-initialised" in reason
    after = np.flatnonzero(t[keep] >= 1.5)
    err = np.abs(run.v - v[keep]).max(axis=1)
    assert err[after[0]] < 2.0  # restarted at rest: the error is the true speed (1.3 rad/s)
    # measured 50 ms later: kf 0.023, ekf 0.0023, riemannian 0.0023 rad/s
    assert err[after[50] :].max() < (0.05 if name == "kf" else 0.005)


def test_a_short_gap_is_propagated_in_sub_steps_of_one_period(sim, ur5) -> None:
    t, q, tau, v = sim.t[1:], sim.q_meas[1:], sim.tau[1:], sim.v[1:]
    keep = (t < 0.5) | (t >= 0.507)
    calls: list[float] = []
    ob = pinobs.make_observer("ekf", ur5, rate=1000.0, noise_std=1e-4)

    class Spy:
        robot, name, uses_torque = ob.robot, ob.name, ob.uses_torque

        def reset(self, *a):
            return ob.reset(*a)

        def update(self, t, q, tau=None):
            calls.append(t)
            return ob.update(t, q, tau)

    run = estimate_log(Spy(), Log(t[keep], q[keep], tau[keep]))
    ((line, reason),) = run.bad_rows
    assert "propagated in 8 steps" in reason
    assert np.diff(calls).max() <= 1e-3 + 1e-12
    assert run.v.shape[0] == keep.sum()  # the sub-steps are not output
    assert np.abs(run.v - v[keep]).max(axis=1)[line:].max() < 0.05


def test_log_in_degrees_warns_naming_the_joints(tmp_path, sim, ur5) -> None:
    q = sim.q_meas[1:201].copy()
    q[:, 1] = np.degrees(q[:, 1]) + 90.0  # shoulder_lift_joint in degrees, around 90°
    run = estimate_log(_kf(ur5), Log(sim.t[1:201], q, sim.tau[1:201]))
    assert any("shoulder_lift_joint" in w and "degrees" in w for w in run.warnings)
    assert not any("elbow_joint" in w for w in run.warnings)


def test_every_row_bad_exits_1(tmp_path, sim, capsys) -> None:
    path, lines = _lines(tmp_path, sim, n=20)
    lines = [lines[0]] + [",".join(["x"] * 13) for _ in lines[1:]]
    path.write_text("\n".join(lines) + "\n")
    code = _estimate_kf(path, tmp_path / "o.csv")
    said = capsys.readouterr()
    assert code == 1 and "no row of the log could be estimated" in said.err
    assert "(every row NaN)" in said.out  # the row-aligned file is written, and said to be empty


def test_summary_counts_rows_not_reports(tmp_path, sim, capsys) -> None:
    path, lines = _lines(tmp_path, sim, n=100)
    _set(lines, 11, 1, "abc")
    _set(lines, 11, 2, "abc")  # two bad cells, one row
    _set(lines, 21, 0, lines[19].split(",")[0])  # duplicated time
    path.write_text("\n".join(lines) + "\n")
    code = _estimate_kf(path, tmp_path / "o.csv")
    out = capsys.readouterr()
    assert code == 0
    assert (
        "100 rows: 99 estimated (98 with their measurement, 1 propagated only), 1 without an estimate; 2 rows reported"
        in out.out
    )
    assert f"{path}:11: 'q0' unreadable: 'abc'; 'q1' unreadable: 'abc'" in out.err


def test_make_observer_rejects_a_non_numeric_option_at_construction(ur5) -> None:
    with pytest.raises(pinobs.GainError, match=r"accel_psd='10' is not a number"):
        pinobs.make_observer("ekf", ur5, accel_psd="10")


def test_planar_root_cos_sin_pair_is_validated_like_a_continuous_joint() -> None:
    robot = pinobs.load("cartpole", root_joint="planar", check=False)  # dynamics not used
    q = robot.neutral()
    q[2:4] = [2.0, 0.0]  # (cos θ, sin θ) of the planar root, off the unit circle
    with pytest.raises(pinobs.ConfigurationError, match=r"q\[2:4\] = \[2.0, 0.0\] has norm 2"):
        robot.check_configuration(q)
    q[2:4] = np.array([np.cos(0.3), np.sin(0.3)]) * (1 + 1e-6)  # within tolerance: renormalised
    np.testing.assert_allclose(np.linalg.norm(robot.check_configuration(q)[2:4]), 1.0, rtol=1e-15)


def test_an_observer_failing_on_a_row_is_reinitialised_there_not_aborted(sim, ur5) -> None:
    # before: on go1 a raw LinAlgError aborted the command
    ob = _kf(ur5)
    calls = {"n": 0}

    class Failing:
        robot, name, uses_torque = ob.robot, ob.name, ob.uses_torque

        def reset(self, *a):
            return ob.reset(*a)

        def update(self, *a):
            calls["n"] += 1
            if calls["n"] == 100:
                raise np.linalg.LinAlgError("Singular matrix")
            return ob.update(*a)

    run = estimate_log(Failing(), Log(sim.t[1:201], sim.q_meas[1:201], sim.tau[1:201]))
    ((row, reason),) = run.bad_rows
    assert row == 100 and "LinAlgError: Singular matrix" in reason and "re-initialised" in reason
    assert run.estimated == 200 and np.isfinite(run.v).all()
    # said once for the run too, not only row by row (real UR10e logs: 299 restarts, no word)
    (said,) = [w for w in run.warnings if "failed or diverged" in w]
    assert "on 1 rows" in said and f"t = {sim.t[101]:.6g} s" in said


def test_a_floating_base_log_with_a_gap_runs_without_overflow_or_abort() -> None:
    # go1: a free-flyer whose translation has no limits (±1.8e308 in Pinocchio)
    robot = pinobs.load("go1")
    res = pinobs.simulate(robot, [], duration=0.25, sensor=pinobs.Sensor(1000.0, 1e-4), seed=1)
    t, q, tau = res.t[1:], res.q_meas[1:], res.tau[1:]
    keep = (t < 0.1) | (t >= 0.2)
    ob = pinobs.make_observer("ekf", robot, rate=1000.0, noise_std=1e-4)
    run = estimate_log(ob, Log(t[keep], q[keep], tau[keep]))
    ((row, reason),) = run.bad_rows
    assert row == 99 and "re-initialised" in reason
    assert run.estimated == keep.sum() and run.warnings == []


def test_two_timestamps_far_ahead_cost_a_few_rows_not_the_rest(tmp_path, sim, ur5) -> None:
    path, lines = _lines(tmp_path, sim, n=200)
    _set(lines, 51, 0, "51")
    _set(lines, 52, 0, "51.001")  # the look-ahead cannot see past two
    path.write_text("\n".join(lines) + "\n")
    run = estimate_log(_kf(ur5), read_log(path, ur5))
    reported = [line for line, _ in run.bad_rows]
    # 51: a 51 s gap (re-initialised), 52 kept, 53-57 behind it (skipped), 58 restarts
    assert reported == [51, *range(53, 59)]
    assert "re-initialised" in dict(run.bad_rows)[58] and "time went back" in dict(run.bad_rows)[58]
    assert np.isfinite(run.v).all(axis=1).sum() == 200 - 5
    assert np.isfinite(run.v[58 - 2 :]).all()


def test_a_header_only_log_exits_1_and_an_empty_file_is_an_error(tmp_path, sim, capsys) -> None:
    path, lines = _lines(tmp_path, sim, n=3)
    path.write_text(lines[0] + "\n\n")
    args = ["estimate", "--robot", "ur5", "--observer", "kf", "--log", str(path), "--no-progress"]
    assert main([*args, "--out", str(tmp_path / "o.csv")]) == 1
    assert "0 rows: 0 estimated" in capsys.readouterr().out
    path.write_text("")
    assert main([*args, "--out", str(tmp_path / "o2.csv")]) == 2
    assert "is empty" in capsys.readouterr().err


def test_an_absurd_velocity_estimate_restarts_the_observer_and_is_reported(sim, ur5) -> None:
    """Found by a sweep: an EKF diverging on torques ×50 stayed finite for a while, up to
    3.8e203 rad/s on a UR5 (limit 3.15), and every row counted as estimated.  A velocity
    beyond ``ABSURD_LIMIT_FACTOR`` × the URDF limit now restarts it, reported."""
    from pinobs.tolerances import ABSURD_LIMIT_FACTOR

    log = Log(t=sim.t[1:], q=sim.q_meas[1:], tau=50.0 * np.array(sim.tau[1:]))
    run = estimate_log(pinobs.make_observer("ekf", ur5, noise_std=1e-4), log)
    limit = np.array(ur5.model.velocityLimit)
    assert np.all(np.abs(run.v) <= ABSURD_LIMIT_FACTOR * limit * (1 + 1e-9))
    assert any("beyond 100× the velocity limit" in why for _, why in run.bad_rows)
    clean = estimate_log(
        pinobs.make_observer("ekf", ur5, noise_std=1e-4),
        Log(t=sim.t[1:], q=sim.q_meas[1:], tau=sim.tau[1:]),
    )
    assert not clean.bad_rows


@pytest.mark.parametrize(("scale", "unit"), [(1e3, "milliseconds"), (1e9, "nanoseconds")])
def test_time_in_another_unit_warns_to_give_seconds(sim, ur5, scale, unit) -> None:
    # before: accepted silently, velocities 1000x (1e9x) too small
    t, q, tau = sim.t[1:201], sim.q_meas[1:201], sim.tau[1:201]
    run = estimate_log(_kf(ur5), Log(t * scale, q, tau))
    assert sum(unit in w and "give t in seconds" in w for w in run.warnings) == 1
    assert not any("sample period" in w for w in estimate_log(_kf(ur5), Log(t, q, tau)).warnings)


def test_time_in_a_larger_unit_warns(sim, ur5) -> None:
    t, q, tau = sim.t[1:201], sim.q_meas[1:201], sim.tau[1:201]
    run = estimate_log(_kf(ur5), Log(t * 1e-4, q, tau))
    assert any("larger than seconds" in w for w in run.warnings)


def test_smoothing_a_log_in_milliseconds_fails_naming_the_unit(tmp_path, sim, ur5) -> None:
    # before: "the filter is lost" alone
    from pinobs.errors import PinobsError
    from pinobs.io.smoothing import smooth_log

    path = write_log(tmp_path / "ms.csv", sim.t[1:401] * 1e3, sim.q_meas[1:401], sim.tau[1:401])
    with pytest.raises(PinobsError, match="is t in milliseconds"):
        smooth_log(path, ur5, tmp_path / "o.csv", observer="ekf", noise_std=1e-4)


def test_duplicated_rows_do_not_change_the_noise_estimate(tmp_path, sim, ur5) -> None:
    # before: σ 3.71e-4 for 9.77e-5 (the estimate ran on unscreened rows)
    from pinobs.io.smoothing import smooth_log

    t, q, tau = sim.t[1:1501], sim.q_meas[1:1501], sim.tau[1:1501]
    clean = write_log(tmp_path / "clean.csv", t, q, tau)
    dup = write_log(tmp_path / "dup.csv", *(np.repeat(x, 2, axis=0) for x in (t, q, tau)))
    a = pinobs.io.process_log(clean, ur5, "kf", keep=False)
    b = pinobs.io.process_log(dup, ur5, "kf", keep=False)
    assert b.noise_std == a.noise_std
    sa, _ = smooth_log(clean, ur5, tmp_path / "a.csv", observer="kf")
    sb, _ = smooth_log(dup, ur5, tmp_path / "b.csv", observer="kf")
    assert sb.noise_std == sa.noise_std


def test_rows_before_the_first_torque_are_said_once_whatever_the_chunks(sim, ur5) -> None:
    # before: each such row "previous torque held" (none was: zero used), no warning; a bag's
    # reports depended on whether its first chunk had any effort
    from pinobs.io import LogEstimator

    t, q, tau = sim.t[1:201], sim.q_meas[1:201], sim.tau[1:201].copy()
    tau[:50] = np.nan
    whole = estimate_log(pinobs.make_observer("ekf", ur5, rate=1e3, noise_std=1e-4), Log(t, q, tau))
    est = LogEstimator(pinobs.make_observer("ekf", ur5, rate=1e3, noise_std=1e-4))
    est.feed(Log(t[:30], q[:30], None))  # a bag chunk before any effort
    est.feed(Log(t[30:], q[30:], tau[30:], lines=np.arange(30, 200)))
    est.finish()
    for bad_rows, warnings in ((whole.bad_rows, whole.warnings), (est.bad_rows, est.warnings)):
        assert not any("torque" in reason for _, reason in bad_rows)
        (said,) = [w for w in warnings if "torque" in w]
        assert said.startswith("50 rows before the first usable torque (row 0 to 49)")


@pytest.mark.parametrize("cell", ["inf", "1e9"])
def test_a_bad_cell_or_a_row_skipped_for_time_does_not_make_the_degrees_warning(
    sim, ur5, cell
) -> None:
    # before: "|q| up to inf: a log in degrees?" from one inf cell
    t, q, tau = sim.t[1:201].copy(), sim.q_meas[1:201].copy(), sim.tau[1:201]
    q[50, 2] = float(cell)  # a non-finite or absurd position: a dropped sample
    q[80, 1], t[80] = 50.0, t[79]  # far outside, on a row skipped for its time
    run = estimate_log(_kf(ur5), Log(t, q, tau))
    assert len(run.bad_rows) == 2
    assert not any("URDF limits" in w for w in run.warnings)


def test_a_reversed_log_warns_to_sort_it(sim, ur5) -> None:
    # before: 1 row of 200 estimated, no word of why but 199 row reports
    t, q, tau = sim.t[1:201], sim.q_meas[1:201], sim.tau[1:201]
    run = estimate_log(_kf(ur5), Log(t[::-1], q[::-1], tau[::-1]))
    assert run.estimated == 1
    assert any(
        w.startswith("199 of 200 rows were skipped") and "Sort it" in w for w in run.warnings
    )
    assert not any("skipped" in w for w in estimate_log(_kf(ur5), Log(t, q, tau)).warnings)


def test_smoothing_a_log_of_no_rows_says_so_not_to_give_noise_std(tmp_path, ur5, capsys) -> None:
    # before: "the log has too few finite rows to estimate its noise; give noise_std"
    path = tmp_path / "h.csv"
    path.write_text("t," + ",".join(f"q{i}" for i in range(6)) + "\n")
    args = ["estimate", "--robot", "ur5", "--observer", "kf", "--smooth", "--log", str(path)]
    assert main([*args, "--out", str(tmp_path / "o.csv"), "--no-progress"]) == 1
    assert "no row of the log could be smoothed" in capsys.readouterr().err


def test_two_stray_quotes_cost_their_two_rows_only(tmp_path, sim, ur5) -> None:
    # quoting now read as standard CSV: the text between two stray quotes is no field
    path, lines = _lines(tmp_path, sim)
    _set(lines, 52, 3, '"' + lines[51].split(",")[3])
    _set(lines, 80, 5, lines[79].split(",")[5] + '"')
    path.write_text("\n".join(lines) + "\n")
    log = read_log(path, ur5)
    assert len(log) == N
    assert [line for line, _ in log.problems] == [52, 80]
    assert np.isnan(log.q[[50, 78]]).any(axis=1).all() and np.isfinite(log.q[51:78]).all()

"""Streaming: chunk boundaries change nothing; the output is written atomically and never clobbers."""

from __future__ import annotations

import numpy as np
import pytest

import pinobs
from pinobs.cli import main
from pinobs.io import estimate_log, process_log, read_log, write_log
from pinobs.io.runs import log_options

pd = pytest.importorskip("pandas")


@pytest.fixture(scope="module")
def log_path(tmp_path_factory):
    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=0.3, sensor=pinobs.Sensor(1000.0, 1e-4), seed=2)
    path = tmp_path_factory.mktemp("logs") / "log.csv"
    lines = write_log(path, res.t[1:], res.q_meas[1:], res.tau[1:]).read_text().splitlines()
    cells = lines[50].split(",")
    cells[0] = "51"  # a timestamp far ahead, right at a chunk boundary (rows 49/50/51)
    lines[50] = ",".join(cells)
    cells = lines[120].split(",")
    cells[3] = "nan"
    lines[120] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("chunk_rows", [7, 49, 50, 1000])
def test_chunk_boundaries_change_nothing(log_path, chunk_rows) -> None:
    robot = pinobs.load("ur5")
    ekf = pinobs.make_observer("ekf", robot, rate=1000.0, noise_std=1e-4, **log_options("ekf", {}))
    whole = estimate_log(ekf, read_log(log_path, robot))
    streamed = process_log(
        log_path, robot, "ekf", rate=1000.0, noise_std=1e-4, chunk_rows=chunk_rows
    )
    np.testing.assert_array_equal(streamed.v, whole.v)
    assert streamed.bad_rows == whole.bad_rows
    assert [line for line, _ in whole.bad_rows] == [51, 121]
    assert streamed.rows == 300 and streamed.estimated == 299


def _args(log, out, *extra):
    return [
        "estimate",
        "--robot",
        "ur5",
        "--observer",
        "kf",
        "--log",
        str(log),
        "--out",
        str(out),
        "--no-progress",
        "--noise",
        "1e-4",
        *extra,
    ]


def test_out_equal_to_the_log_is_refused_and_the_log_kept(log_path, capsys) -> None:
    before = log_path.read_bytes()
    assert main(_args(log_path, log_path)) == 2
    assert "is the input log" in capsys.readouterr().err
    assert log_path.read_bytes() == before


def test_an_existing_output_needs_force(tmp_path, log_path, capsys) -> None:
    out = tmp_path / "est.csv"
    out.write_text("keep me\n")
    assert main(_args(log_path, out)) == 2
    assert "exists; pass --force" in capsys.readouterr().err
    assert out.read_text() == "keep me\n"
    assert main(_args(log_path, out, "--force")) == 0
    assert len(pd.read_csv(out)) == 300


def test_a_failed_run_leaves_no_partial_output(tmp_path, log_path) -> None:
    robot = pinobs.load("ur5")
    ob = pinobs.make_observer("kf", robot, rate=1000.0, noise_std=1e-4)

    class Crashing:
        robot, name, uses_torque = ob.robot, ob.name, ob.uses_torque
        calls = 0

        def reset(self, *a):
            return ob.reset(*a)

        def update(self, *a):
            Crashing.calls += 1
            if Crashing.calls > 120:
                raise RuntimeError("disk full (simulated)")
            return ob.update(*a)

    out = tmp_path / "est.csv"
    with pytest.raises(RuntimeError, match="disk full"):
        process_log(log_path, robot, Crashing(), out=out, chunk_rows=50)
    assert list(tmp_path.iterdir()) == []  # neither est.csv nor its temporary file


def test_an_output_inside_the_input_bag_folder_is_refused_and_the_bag_kept(tmp_path) -> None:
    # before: --out bag/bag.db3 overwrote the bag being read
    from pinobs.errors import OutputExistsError
    from pinobs.io import EstimateWriter

    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (bag / "bag.db3").write_bytes(b"SQLite format 3\x00")
    for out in (bag / "bag.db3", bag / "new.csv"):
        with pytest.raises(OutputExistsError, match="inside the input bag folder"):
            EstimateWriter(out, pinobs.load("ur5"), force=True, inputs=[bag])
    assert sorted(p.name for p in bag.iterdir()) == ["bag.db3", "metadata.yaml"]


def test_an_unwritable_or_non_csv_output_is_a_pinobs_error_before_the_work(
    tmp_path, log_path, capsys
) -> None:
    # before: a raw FileExistsError traceback; x.parquet got CSV text silently
    assert main(_args(log_path, log_path / "x.csv", "--force")) == 2
    assert "cannot be written (FileExistsError" in capsys.readouterr().err
    assert main(_args(log_path, tmp_path / "x.parquet")) == 2
    assert "written as CSV text, not .parquet" in capsys.readouterr().err
    assert not (tmp_path / "x.parquet").exists()


@pytest.mark.filterwarnings("ignore::pinobs.errors.NoiseWarning")  # σ learnt from the data
def test_estimate_log_gives_kf_its_plain_rows_at_once_with_the_same_results(log_path) -> None:
    """``estimate_log`` hands ``kf`` (``update_rows``) the log's leading plain rows at once
    (``LogEstimator.feed_log``): the same estimates, reports, warnings, counts and consistency
    as ``feed`` row by row, on the plain log, and with a NaN row, a repeated time, a gap of 5
    and of 20 periods and an absurd position further on (the rows from there one by one)."""
    from dataclasses import replace

    from pinobs.io import LogEstimator

    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=3.0, sensor=pinobs.Sensor(500.0, 1e-4), seed=4)
    plain = read_log(
        pd.DataFrame({"t": res.t, **{f"q{i}": res.q_meas[:, i] for i in range(6)}}), robot
    )
    logs = [plain]
    for k, what in (
        (900, "nan"),
        (1000, "repeat"),
        (1100, "gap5"),
        (1200, "gap20"),
        (1300, "absurd"),
    ):
        t, q = plain.t.copy(), plain.q.copy()
        if what == "nan":
            q[k, 2] = np.nan
        elif what == "repeat":
            t[k] = t[k - 1]
        elif what.startswith("gap"):
            t[k:] += int(what[3:]) * 2e-3
        else:
            q[k, 1] = 1e4
        logs.append(replace(plain, t=t, q=q))
    for log in logs:
        new = estimate_log(pinobs.make_observer("kf", robot), log)
        ob = pinobs.make_observer("kf", robot)
        est = LogEstimator(ob)
        (_, q_a, v_a), (_, q_b, v_b) = est.feed(log), est.finish()
        np.testing.assert_array_equal(new.q, np.concatenate([q_a, q_b]))
        np.testing.assert_array_equal(new.v, np.concatenate([v_a, v_b]))
        assert new.bad_rows == est.bad_rows and new.warnings == est.warnings
        assert (new.rows, new.estimated, new.measured) == (est.rows, est.estimated, est.measured)
        assert new.consistency == ob.consistency()

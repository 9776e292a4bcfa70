"""A table log without a ``t`` column, its rows at a known fixed rate (issue 36): read with
``rate=R`` as ``t = k / R`` for its row ``k``, in every table format and across chunks."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import pinobs
from pinobs.cli import main
from pinobs.io import Drives, iter_log, read_log
from pinobs.io.writers import write_log

pd = pytest.importorskip("pandas")

N = 120
RATE = 1000.0
NOTE = "no t column: rows taken as sampled at 1000 Hz, t = k/1000"


@pytest.fixture(scope="module")
def ur5() -> pinobs.Robot:
    return pinobs.load("ur5")


@pytest.fixture(scope="module")
def data(ur5) -> tuple[np.ndarray, np.ndarray]:
    res = pinobs.simulate(ur5, [], duration=N / RATE, sensor=pinobs.Sensor(RATE, 1e-4), seed=5)
    return res.q_meas[1:], res.tau[1:]


def _frame(q: np.ndarray, tau: np.ndarray) -> pd.DataFrame:
    """Positional ``q0.., tau0..`` columns, no ``t``."""
    return pd.DataFrame(
        {**{f"q{i}": q[:, i] for i in range(6)}, **{f"tau{i}": tau[:, i] for i in range(6)}}
    )


def _rows(n: int, rate: float = RATE) -> np.ndarray:
    return np.array([k / rate for k in range(n)])  # t = k/R, each row on its own


def test_a_csv_without_t_is_timed_by_the_rate_fast_and_careful(tmp_path, ur5, data) -> None:
    """Every row timed ``k / R`` and read as written (the fast reader); after a bad cell (the
    careful reader) that row still counts, a blank line does not, and the rows after it keep
    their times."""
    q, tau = data
    path = tmp_path / "log.csv"
    _frame(q, tau).to_csv(path, index=False)
    log = read_log(path, ur5, rate=RATE)
    np.testing.assert_array_equal(log.t, _rows(N))
    np.testing.assert_array_equal(log.q, q)
    np.testing.assert_array_equal(log.tau, tau)
    assert log.notes == (NOTE,) and not log.problems
    np.testing.assert_array_equal(log.lines, np.arange(N) + 2)
    lines = path.read_text().splitlines()
    lines[10] = "x" + lines[10]  # line 11 (row 9): a cell that is not a number
    lines.insert(40, "")  # a blank line before row 39: not a row
    path.write_text("\n".join(lines) + "\n")
    log = read_log(path, ur5, rate=RATE)
    assert len(log) == N and [line for line, _ in log.problems] == [11]
    np.testing.assert_array_equal(log.t, _rows(N))
    assert np.isnan(log.q[9, 0]) and log.lines[9] == 11 and log.lines[39] == 42
    np.testing.assert_array_equal(log.q[10:], q[10:])
    assert log.notes == (NOTE,)


def test_parquet_and_a_dataframe_without_t_read_the_csv_s_rows(tmp_path, ur5, data) -> None:
    pytest.importorskip("pyarrow")
    q, tau = data
    frame = _frame(q, tau)
    frame.to_parquet(tmp_path / "log.parquet")
    for source in (tmp_path / "log.parquet", frame):
        log = read_log(source, ur5, rate=RATE)
        np.testing.assert_array_equal(log.t, _rows(N))
        np.testing.assert_array_equal(log.q, q)
        np.testing.assert_array_equal(log.tau, tau)
        assert log.notes == (NOTE,) and log.unit == "row"


def test_a_headerless_csv_without_t_is_mapped_by_position_and_timed(tmp_path, ur5, data) -> None:
    q, tau = data
    path = tmp_path / "bare.csv"
    np.savetxt(path, np.column_stack([q, tau]), delimiter=",", fmt="%.17g")
    cols = {str(i): f"q{i}" for i in range(6)} | {str(6 + i): f"tau{i}" for i in range(6)}
    log = read_log(path, ur5, columns=cols, rate=250.0)
    np.testing.assert_array_equal(log.t, _rows(N, 250.0))
    np.testing.assert_array_equal(log.q, q)
    assert log.lines[0] == 1 and log.lines[-1] == N
    assert log.notes[0] == "no t column: rows taken as sampled at 250 Hz, t = k/250"
    assert log.notes[1].startswith("no header row: line 1 read as data")


@pytest.mark.parametrize("bad_row", [None, 3, 30])
def test_chunks_continue_the_row_count(tmp_path, ur5, data, bad_row) -> None:
    """Chunks of 7 rows: ``t`` continues across them, the note is in the first only; the same
    with a bad cell in the first or a later chunk (the careful reader, here from row 0: the
    file is one of Arrow's blocks)."""
    q, tau = data
    path = tmp_path / "log.csv"
    _frame(q, tau).to_csv(path, index=False)
    if bad_row is not None:
        lines = path.read_text().splitlines()
        lines[bad_row + 1] = lines[bad_row + 1].replace(",", ",?", 1)
        path.write_text("\n".join(lines) + "\n")
    chunks = list(iter_log(path, ur5, chunk_rows=7, rate=RATE))
    assert [len(c) for c in chunks] == [7] * (N // 7) + [N % 7]
    np.testing.assert_array_equal(np.concatenate([c.t for c in chunks]), _rows(N))
    assert chunks[0].notes == (NOTE,) and not any(c.notes for c in chunks[1:])
    problems = [line for c in chunks for line, _ in c.problems]
    assert problems == ([] if bad_row is None else [bad_row + 2])


def test_the_careful_reader_counts_on_from_the_fast_reader_s_rows(
    tmp_path, ur5, monkeypatch
) -> None:
    """A log longer than the fast reader's first blocks, a bad cell near its end: the fast
    reader yields its rows, the careful one takes the rest from there, the times run on."""
    import pinobs.io.readers.csv_log as csv_log

    n = 6000  # ~1.6 MB: several of Arrow's 256 kB blocks
    q = np.random.default_rng(1).normal(size=(n, 12))
    path = tmp_path / "long.csv"
    pd.DataFrame(q, columns=[*(f"q{i}" for i in range(6)), *(f"tau{i}" for i in range(6))]).to_csv(
        path, index=False
    )
    lines = path.read_text().splitlines()
    lines[n - 100] = "x" + lines[n - 100]  # row n - 101
    path.write_text("\n".join(lines) + "\n")
    starts = []

    def spy(*args, **kwargs):
        starts.append(args[5])  # careful_chunks(path, header, layout, robot, sep, start, ...)
        return careful(*args, **kwargs)

    careful = csv_log.careful_chunks
    monkeypatch.setattr(csv_log, "careful_chunks", spy)
    chunks = list(iter_log(path, ur5, chunk_rows=1000, rate=RATE))
    assert len(starts) == 1 and 0 < starts[0] < n - 101
    np.testing.assert_array_equal(np.concatenate([c.t for c in chunks]), _rows(n))
    assert [line for c in chunks for line, _ in c.problems] == [n - 99]
    assert chunks[0].notes == (NOTE,) and not any(c.notes for c in chunks[1:])


def test_parquet_chunks_continue_the_row_count(tmp_path, ur5, data) -> None:
    pytest.importorskip("pyarrow")
    q, tau = data
    _frame(q, tau).to_parquet(tmp_path / "log.parquet")
    chunks = list(iter_log(tmp_path / "log.parquet", ur5, chunk_rows=7, rate=RATE))
    assert len(chunks) == -(-N // 7)
    np.testing.assert_array_equal(np.concatenate([c.t for c in chunks]), _rows(N))
    assert chunks[0].notes == (NOTE,) and not any(c.notes for c in chunks[1:])


def test_without_t_or_rate_the_error_says_to_give_the_rate(tmp_path, ur5, data) -> None:
    q, tau = data
    path = tmp_path / "log.csv"
    _frame(q, tau).to_csv(path, index=False)
    hint = r"lack \['t'\];.* or give the sample rate \(rate=\.\.\., --rate R\) if the rows"
    for source in (path, _frame(q, tau)):
        with pytest.raises(pinobs.DimensionError, match=hint):
            read_log(source, ur5)
    for bad in (0.0, -5.0, np.nan, np.inf):
        with pytest.raises(pinobs.GainError, match=f"rate={bad!r} is out of range"):
            read_log(path, ur5, rate=bad)
    # a joint missing too: both said, the rate's hint only while t is lacking
    with pytest.raises(pinobs.DimensionError, match=r"lack \['q5 or q.wrist_3_joint'\]; ") as exc:
        read_log(_frame(q, tau).drop(columns="q5"), ur5, rate=RATE)
    assert "sample rate" not in str(exc.value)


def test_a_log_with_its_own_times_keeps_them_given_a_rate(tmp_path, ur5, data) -> None:
    """A ``t`` column (irregular here), an NPZ's ``t``: used as they are, nothing said."""
    q, tau = data
    t = np.cumsum(np.random.default_rng(0).uniform(0.5e-3, 1.5e-3, N))
    frame = _frame(q, tau)
    frame.insert(3, "t", t)
    frame.to_csv(tmp_path / "log.csv", index=False)
    np.savez(tmp_path / "log.npz", t=t, q=q, tau=tau)
    for source in (tmp_path / "log.csv", frame, tmp_path / "log.npz"):
        log = read_log(source, ur5, rate=RATE)
        np.testing.assert_array_equal(log.t, t)
        assert not log.notes


@pytest.mark.parametrize("how", ["filtered", "smoothed"])
def test_estimate_reads_a_log_without_t_at_its_rate(tmp_path, ur5, data, capsys, how) -> None:
    """``pinobs estimate --rate`` (filtered, smoothed, ``--out-dir``; and
    ``pinobs.estimate(rate=...)``) on the log without ``t`` gives the estimates of the same
    log written with ``t = k / R``, bit for bit; without ``--rate`` it is refused, saying it."""
    q, tau = data
    (tmp_path / "bare").mkdir()
    _frame(q, tau).to_csv(tmp_path / "bare" / "log.csv", index=False)
    write_log(tmp_path / "timed.csv", _rows(N), q, tau)
    base = ["estimate", "--robot", "ur5", "--observer", "kf", "--noise", "1e-4", "--no-progress"]
    base += ["--smooth"] if how == "smoothed" else []
    for log, out in (("bare/log.csv", "bare_v.csv"), ("timed.csv", "timed_v.csv")):
        args = [*base, "--log", str(tmp_path / log), "--out", str(tmp_path / out)]
        assert main([*args, "--rate", "1000"]) == 0
    assert f"warning: {NOTE}" in capsys.readouterr().err
    bare, timed = (pd.read_csv(tmp_path / f"{n}_v.csv") for n in ("bare", "timed"))
    assert len(bare) == N
    pd.testing.assert_frame_equal(bare, timed, check_exact=True)
    many = [*base, "--log", str(tmp_path / "bare"), "--out-dir", str(tmp_path / "many")]
    assert main([*many, "--workers", "0", "--rate", "1000"]) == 0
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "many" / "log.csv"), bare)
    if how == "filtered":
        with pytest.warns(pinobs.PinobsWarning, match="no t column"):
            df = pinobs.estimate(
                "kf", tmp_path / "bare" / "log.csv", robot=ur5, rate=RATE, noise_std=1e-4
            )
        np.testing.assert_array_equal(df.to_numpy(), bare.to_numpy())
    capsys.readouterr()
    args = [*base, "--log", str(tmp_path / "bare" / "log.csv"), "--out", str(tmp_path / "no.csv")]
    assert main(args) == 2
    assert "or give the sample rate (rate=..., --rate R)" in capsys.readouterr().err
    assert not (tmp_path / "no.csv").exists()


def test_identify_reads_a_log_without_t_at_its_rate(tmp_path, capsys) -> None:
    """``pinobs identify --rate`` on a log without ``t``: the URDF of the same log written
    with ``t = k / R``; ``--rate`` on a log with its own times: said not used."""
    robot = pinobs.load("double_pendulum")
    rate = 500.0
    res = pinobs.simulate(robot, [], duration=2.0, sensor=pinobs.Sensor(rate, 1e-5), seed=2)
    q, tau = res.q_meas[1:], res.tau[1:]
    frame = pd.DataFrame(
        {**{f"q{i}": q[:, i] for i in range(2)}, **{f"tau{i}": tau[:, i] for i in range(2)}}
    )
    frame.to_csv(tmp_path / "bare.csv", index=False)
    write_log(tmp_path / "timed.csv", _rows(len(q), rate), q, tau)
    base = ["identify", "--robot", "double_pendulum", "--no-refine", "--rate", "500"]
    for name in ("bare", "timed"):
        args = [
            *base,
            "--log",
            str(tmp_path / f"{name}.csv"),
            "--out",
            str(tmp_path / f"{name}.urdf"),
        ]
        assert main(args) == 0
        err = capsys.readouterr().err
        said = "warning: --rate 500 not used: the log has its own times"
        assert (said in err) == (name == "timed")
    assert (tmp_path / "bare.urdf").read_text() == (tmp_path / "timed.urdf").read_text()
    bad = [*base[:-1], "0", "--log", str(tmp_path / "bare.csv"), "--out", str(tmp_path / "x.urdf")]
    assert main(bad) == 2
    assert "rate=0.0 is out of range" in capsys.readouterr().err


def _figaroh_tx40() -> Path:
    """FIGAROH's Stäubli TX40 example in the shared data folder; skipped where it is absent."""
    from tests.io.test_real_data import real_data

    root = real_data.data_root()
    path = None if root is None else root / "figaroh" / "examples" / "staubli_TX40"
    if path is None or not (path / "data" / "pos_read_data.csv").is_file():
        pytest.skip("no shared data folder with FIGAROH's staubli_TX40")
    return path


def test_the_real_tx40_log_reads_as_recorded_at_its_rate() -> None:
    """FIGAROH's TX40 motor encoders, ``Joint_1..Joint_6`` with no time, 5 kHz (its config's
    ``ts``): read as recorded through the drives, the log built by hand from the same numbers
    (:mod:`tests.io.test_drives`), row for row, ``t = k / 5000``."""
    from tests.io.test_drives import tx40_transmission

    root = _figaroh_tx40()
    config = (root / "config" / "TX40_config.yaml").read_text()
    ts = float(next(ln for ln in config.splitlines() if ln.strip().startswith("ts ")).split(":")[1])
    assert ts == 2e-4
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its meshes are not in the data
        robot = pinobs.load(str(root / "urdf" / "tx40_mdh_modified.urdf"), check=False)
    drives = Drives(
        transmission=tx40_transmission(), position_offset=[0, -np.pi / 2, np.pi / 2, 0, 0, 0]
    )
    names = {f"Joint_{k + 1}": f"qm.{j}" for k, j in enumerate(robot.joint_names)}
    path = root / "data" / "pos_read_data.csv"
    log = read_log(path, robot, columns=names, drives=drives, rate=5000.0)
    motor = pd.read_csv(path).to_numpy(dtype=float)
    assert len(log) == len(motor) == 45000 and not log.problems
    np.testing.assert_array_equal(log.t, _rows(len(motor), 5000.0))
    np.testing.assert_array_equal(log.q, drives.joint_positions(motor))
    assert log.notes == ("no t column: rows taken as sampled at 5000 Hz, t = k/5000",)

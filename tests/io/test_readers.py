"""Readers: named columns, TSV, Parquet, DataFrames and ROS bags all give the same rows."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import pinobs
from pinobs.cli import main
from pinobs.io import iter_log, read_log

pd = pytest.importorskip("pandas")

N = 120


@pytest.fixture(scope="module")
def ur5() -> pinobs.Robot:
    return pinobs.load("ur5")


@pytest.fixture(scope="module")
def data(ur5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    res = pinobs.simulate(ur5, [], duration=N / 1000, sensor=pinobs.Sensor(1000.0, 1e-4), seed=3)
    return res.t[1:], res.q_meas[1:], res.tau[1:]


def _named_frame(robot: pinobs.Robot, t, q, tau, order: np.ndarray) -> pd.DataFrame:
    cols = {"t": t}
    for i in order:
        name = robot.joint_names[i]
        cols[f"tau.{name}"] = tau[:, i]
        cols[f"q.{name}"] = q[:, i]
    cols["comment"] = ["x"] * len(t)  # extra columns are ignored
    return pd.DataFrame(cols)


def test_named_columns_in_any_order_read_as_the_positional_format(tmp_path, ur5, data) -> None:
    t, q, tau = data
    frame = _named_frame(ur5, t, q, tau, np.random.default_rng(0).permutation(6))
    frame.to_csv(tmp_path / "named.csv", index=False)
    frame.to_csv(tmp_path / "named.tsv", index=False, sep="\t")
    for path in ("named.csv", "named.tsv"):
        log = read_log(tmp_path / path, ur5)
        np.testing.assert_array_equal(log.t, t)
        np.testing.assert_array_equal(log.q, q)  # shortest round-trip floats: exact
        np.testing.assert_array_equal(log.tau, tau)
        assert not log.problems and log.unit == "line"


def test_a_column_map_renames_columns_to_joints(tmp_path, ur5, data) -> None:
    t, q, _ = data
    frame = pd.DataFrame({"stamp": t, **{f"pos_{i}": q[:, i] for i in range(6)}})
    frame.to_csv(tmp_path / "m.csv", index=False)
    mapping = {"stamp": "t", **{f"pos_{i}": f"q.{ur5.joint_names[i]}" for i in range(6)}}
    log = read_log(tmp_path / "m.csv", ur5, columns=mapping)
    np.testing.assert_array_equal(log.q, q)
    assert log.tau is None
    with pytest.raises(pinobs.DimensionError, match=r"lack \['t'"):
        read_log(tmp_path / "m.csv", ur5)
    out = tmp_path / "est.csv"
    args = ["estimate", "--robot", "ur5", "--observer", "kf", "--log", str(tmp_path / "m.csv")]
    args += ["--out", str(out), "--no-progress", "--map", "stamp=t"]
    args += ["--map", ",".join(f"pos_{i}=q{i}" for i in range(6))]
    assert main(args) == 0
    assert len(pd.read_csv(out)) == N


def test_a_csv_without_a_header_names_its_columns_by_position(tmp_path, ur5, data) -> None:
    """A log written without a header row (the UR10e logs: 31 numbers a line): line 1 is
    data, its columns are ``0, 1, ...``; mapped, every row is read, line numbers counted
    from 1 (the fast reader, and the careful one from a bad cell); unmapped, the error says
    how to name them."""
    t, q, tau = data
    rows = np.column_stack([t, q, np.zeros((len(t), 2)), tau])  # (two columns not used)
    path = tmp_path / "bare.csv"
    np.savetxt(path, rows, delimiter=",", fmt="%.17g")
    cols = {"0": "t", **{str(1 + i): f"q{i}" for i in range(6)}}
    cols |= {str(9 + i): f"tau{i}" for i in range(6)}
    log = read_log(path, ur5, columns=cols)
    np.testing.assert_array_equal(log.t, t)
    np.testing.assert_array_equal(log.q, q)
    np.testing.assert_array_equal(log.tau, tau)
    assert log.lines[0] == 1 and log.lines[-1] == len(t) and not log.problems
    assert any(n.startswith("no header row: line 1 read as data") for n in log.notes)
    lines = path.read_text().splitlines()
    lines[9] = "x" + lines[9]  # line 10: a cell that is not a number (the careful reader)
    path.write_text("\n".join(lines) + "\n")
    log = read_log(path, ur5, columns=cols)
    assert len(log) == len(t) and [line for line, _ in log.problems] == [10]
    assert np.isnan(log.t[9]) and log.lines[9] == 10
    np.testing.assert_array_equal(log.q[10:], q[10:])
    with pytest.raises(pinobs.DimensionError, match=r"no header: .* named by position, 0 to 14"):
        read_log(path, ur5)


def test_a_column_named_twice_or_beyond_the_robot_is_refused(tmp_path, ur5, data) -> None:
    """Found by a sweep: two ``t`` columns, or ``--map enc1=q1`` on a log that has ``q1``, read
    the first silently; positional columns beyond the robot's were ignored (another robot's
    log ran on its first columns)."""
    t, q, _ = data
    frame = pd.DataFrame({"t": t, **{f"q{i}": q[:, i] for i in range(6)}, "enc1": q[:, 1]})
    frame.to_csv(tmp_path / "a.csv", index=False)
    with pytest.raises(pinobs.DimensionError, match="2 columns are named 'q1'"):
        read_log(tmp_path / "a.csv", ur5, columns={"enc1": "q1"})
    text = (tmp_path / "a.csv").read_text().replace("enc1", "t", 1)
    (tmp_path / "b.csv").write_text(text)
    with pytest.raises(pinobs.DimensionError, match="2 columns are named 't'"):
        read_log(tmp_path / "b.csv", ur5)
    frame["q6"] = 0.0
    frame.drop(columns="enc1").to_csv(tmp_path / "c.csv", index=False)
    with pytest.raises(pinobs.DimensionError, match=r"\['q6'\] are beyond robot"):
        read_log(tmp_path / "c.csv", ur5)


def test_continuous_joint_given_as_one_angle_column() -> None:
    robot = pinobs.load("double_pendulum_continuous")
    names = robot.joint_names
    angles = np.array([[0.1, -0.2], [0.2, -0.3]])
    frame = pd.DataFrame(
        {"t": [0.0, 0.001], **{f"q.{n}": angles[:, i] for i, n in enumerate(names)}}
    )
    log = read_log(frame, robot)
    np.testing.assert_allclose(
        log.q[:, :2], np.column_stack([np.cos(angles[:, 0]), np.sin(angles[:, 0])])
    )


def test_parquet_dataframe_and_npz_read_the_same_rows(tmp_path, ur5, data) -> None:
    pytest.importorskip("pyarrow")
    t, q, tau = data
    frame = _named_frame(ur5, t, q, tau, np.arange(6)[::-1])
    frame.to_parquet(tmp_path / "log.parquet")
    np.savez(tmp_path / "log.npz", t=t, q=q, tau=tau)
    logs = [
        read_log(tmp_path / "log.parquet", ur5),
        read_log(frame, ur5),
        read_log(tmp_path / "log.npz", ur5),
    ]
    for log in logs:
        np.testing.assert_array_equal(log.q, q)
        np.testing.assert_array_equal(log.tau, tau)
        assert log.unit == "row"


def test_chunked_reading_gives_the_same_rows_and_line_numbers(tmp_path, ur5, data) -> None:
    t, q, tau = data
    _named_frame(ur5, t, q, tau, np.arange(6)).to_csv(tmp_path / "log.csv", index=False)
    chunks = list(iter_log(tmp_path / "log.csv", ur5, chunk_rows=50))
    assert [len(c) for c in chunks] == [50, 50, 20]
    np.testing.assert_array_equal(np.concatenate([c.q for c in chunks]), q)
    np.testing.assert_array_equal(np.concatenate([c.lines for c in chunks]), np.arange(N) + 2)


def test_estimate_api_returns_a_dataframe_with_one_row_per_log_row(ur5, data) -> None:
    t, q, tau = data
    frame = _named_frame(ur5, t, q, tau, np.arange(6))
    df = pinobs.estimate("kf", frame, robot="ur5", noise_std=1e-4)
    assert list(df.columns) == ["t", *(f"q{i}" for i in range(6)), *(f"v{i}" for i in range(6))]
    assert len(df) == N and np.isfinite(df.to_numpy()).all()
    assert df.attrs["bad_rows"] == [] and df.attrs["noise_std"] == 1e-4
    ob = pinobs.make_observer("kf", ur5, rate=1000.0, noise_std=1e-4)
    again = pinobs.estimate(ob, frame)  # the observer brings its robot
    np.testing.assert_allclose(again.to_numpy(), df.to_numpy(), rtol=1e-12, atol=1e-12)
    with pytest.raises(pinobs.DimensionError, match="needs robot="):
        pinobs.estimate("kf", frame)


# ------------------------------------------------------------------ ROS bags
def _write_bag(
    path: Path,
    robot: pinobs.Robot,
    t,
    q,
    tau,
    *,
    kind: str,
    rng,
    short_at: int = -1,
    unstamped: bool = False,
    gripper: str = "",
) -> None:
    """``gripper``: a second publisher on the topic, a one-joint JointState ``"before"`` or
    ``"after"`` each of the robot's."""
    pytest.importorskip("rosbags")
    from rosbags.typesys import Stores, get_typestore

    store = Stores.ROS1_NOETIC if kind == "ros1" else Stores.ROS2_HUMBLE
    ts = get_typestore(store)
    js = ts.types["sensor_msgs/msg/JointState"]
    header = ts.types["std_msgs/msg/Header"]
    stamp = ts.types["builtin_interfaces/msg/Time"]
    names = list(robot.joint_names)

    def messages():
        for k in range(len(t)):
            order = rng.permutation(len(names))  # shuffled joint order, per message
            if k == short_at:
                order = order[:-1]  # this message lacks one joint
            sec, nsec = 1_700_000_000 + int(t[k]), round((t[k] % 1) * 1e9)
            extra = {"seq": k} if kind == "ros1" else {}
            at = stamp(sec=0, nanosec=0) if unstamped else stamp(sec=sec, nanosec=nsec)
            msg = js(
                header=header(**extra, stamp=at, frame_id=""),
                name=[names[i] for i in order],
                position=q[k, order],
                velocity=np.empty(0),
                effort=tau[k, order],
            )
            grip = js(
                header=header(**extra, stamp=at, frame_id=""),
                name=["gripper_finger"],
                position=np.zeros(1),
                velocity=np.empty(0),
                effort=np.zeros(1),
            )
            if gripper == "before":
                yield (sec * 10**9 + nsec), grip
            yield (sec * 10**9 + nsec), msg
            if gripper == "after":
                yield (sec * 10**9 + nsec), grip

    if kind == "ros1":
        from rosbags.rosbag1 import Writer as Writer1

        with Writer1(path) as w:
            conn = w.add_connection("/joint_states", js.__msgtype__, typestore=ts)
            for ns, msg in messages():
                w.write(conn, ns, ts.serialize_ros1(msg, js.__msgtype__))
        return
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as w:
        conn = w.add_connection("/joint_states", js.__msgtype__, typestore=ts)
        other = w.add_connection("/other", "std_msgs/msg/Header", typestore=ts)
        for ns, msg in messages():
            w.write(conn, ns, ts.serialize_cdr(msg, js.__msgtype__))
            w.write(other, ns, ts.serialize_cdr(msg.header, "std_msgs/msg/Header"))


@pytest.mark.parametrize("kind", ["sqlite3", "mcap", "ros1"])
def test_ros_bag_round_trips_through_pinobs_estimate_one_row_per_message(
    tmp_path, ur5, data, kind, capsys
) -> None:
    t, q, tau = data
    bag = tmp_path / ("log.bag" if kind == "ros1" else "log_bag")
    _write_bag(bag, ur5, t, q, tau, kind=kind, rng=np.random.default_rng(1))
    log = read_log(bag, ur5)
    assert log.unit == "message" and not log.problems
    if kind == "ros1":  # header.seq is the sample counter (the clock repair's ticks)
        np.testing.assert_array_equal(log.tick, np.arange(len(t)))
    else:
        assert log.tick is None
    np.testing.assert_array_equal(log.q, q)  # matched by name, whatever the order
    np.testing.assert_array_equal(log.tau, tau)
    np.testing.assert_allclose(log.t - 1_700_000_000, t, atol=1e-6)  # header stamps, ns
    out = tmp_path / "est.csv"
    args = ["estimate", "--robot", "ur5", "--observer", "ekf", "--log", str(bag), "--out", str(out)]
    assert main([*args, "--no-progress", "--noise", "1e-4"]) == 0
    est = pd.read_csv(out)
    assert len(est) == N and np.isfinite(est.to_numpy()).all()
    assert f"{N} rows: {N} estimated ({N} with their measurement" in capsys.readouterr().out


def test_bag_topic_is_chosen_and_a_missing_joint_is_reported(tmp_path, ur5, data) -> None:
    t, q, tau = data
    bag = tmp_path / "b"
    _write_bag(bag, ur5, t[:5], q[:5], tau[:5], kind="mcap", rng=np.random.default_rng(2))
    with pytest.raises(
        pinobs.DimensionError, match=r"no sensor_msgs/JointState topic '/nope'.*\['/joint_states'\]"
    ):
        read_log(bag, ur5, topic="/nope")
    with pytest.raises(pinobs.DimensionError, match="panda_joint1"):
        read_log(bag, pinobs.load("panda"))  # the bag lacks the panda's joints: every row says so


def test_a_bag_message_lacking_a_joint_is_reported_with_its_stamp(tmp_path, ur5, data) -> None:
    t, q, tau = data
    bag = tmp_path / "b"
    _write_bag(
        bag,
        ur5,
        t[:40],
        q[:40],
        tau[:40],
        kind="sqlite3",
        rng=np.random.default_rng(2),
        short_at=20,
    )
    log = read_log(bag, ur5)
    ((number, reason),) = log.problems
    assert number == 20 and reason.startswith("no position for joints [")
    assert reason.endswith("]; effort lacks some joints")
    run = pinobs.io.estimate_log(pinobs.make_observer("kf", ur5, rate=1000.0, noise_std=1e-4), log)
    ((number, reason),) = run.bad_rows
    assert number == 20 and reason.startswith(f"stamp {1_700_000_000 + t[20]:.9f} s; no position")
    assert "dropped sample" in reason and run.estimated == 40


@pytest.mark.parametrize("kind", ["mcap", "ros1"])
def test_a_bag_whose_header_stamps_are_unset_is_timed_by_its_receive_times(
    tmp_path, ur5, data, kind
) -> None:
    """Header stamps all 0 (a publisher that does not stamp): read as one row at t = 0 and
    repeats of it, without a hint; now the bag's receive times, said on message 0."""
    t, q, tau = data
    bag = tmp_path / ("log.bag" if kind == "ros1" else "log_bag")
    _write_bag(
        bag, ur5, t[:50], q[:50], tau[:50], kind=kind, rng=np.random.default_rng(3), unstamped=True
    )
    log = read_log(bag, ur5)
    np.testing.assert_allclose(log.t - 1_700_000_000, t[:50], atol=1e-6)  # receive times
    ((number, reason),) = log.problems
    assert number == 0 and "header stamps unset (0): the bag's receive times are used" in reason
    run = pinobs.io.estimate_log(pinobs.make_observer("kf", ur5, rate=1000.0, noise_std=1e-4), log)
    assert run.estimated == 50


def test_find_logs_takes_a_file_a_folder_or_a_pattern(tmp_path) -> None:
    from pinobs.io import find_logs

    for name in ("b.csv", "a.parquet", "c.npz", "notes.md"):
        (tmp_path / name).write_text("")
    bag = tmp_path / "bag2"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "d.tsv").write_text("")
    assert [p.name for p in find_logs(tmp_path)] == ["a.parquet", "b.csv", "bag2", "c.npz"]
    assert [p.name for p in find_logs(str(tmp_path / "*.csv"))] == ["b.csv"]
    assert [p.name for p in find_logs(str(tmp_path / "**" / "*.tsv"))] == ["d.tsv"]
    assert find_logs(bag) == [bag] and find_logs(tmp_path / "notes.md") == [tmp_path / "notes.md"]
    with pytest.raises(pinobs.ModelFileError, match=r"no log in .*\.bag, \.csv"):
        find_logs(str(tmp_path / "*.md"))
    with pytest.raises(pinobs.ModelFileError, match="does not exist"):
        find_logs(tmp_path / "missing")


@pytest.mark.parametrize("dress", [" {} ", '"{}"'])
def test_parquet_with_padded_or_quoted_column_names_reads_as_clean(
    tmp_path, ur5, data, dress
) -> None:
    # before: KeyError (renamed from the raw names, looked up by the cleaned ones)
    pytest.importorskip("pyarrow")
    t, q, tau = data
    frame = _named_frame(ur5, t, q, tau, np.arange(6))
    frame.columns = [dress.format(c) for c in frame.columns]
    frame.to_parquet(tmp_path / "log.parquet")
    log = read_log(tmp_path / "log.parquet", ur5)
    np.testing.assert_array_equal(log.q, q)
    np.testing.assert_array_equal(log.tau, tau)


@pytest.mark.parametrize("name", ["t", "time"])
def test_parquet_written_with_t_as_the_pandas_index_reads_t(tmp_path, ur5, data, name) -> None:
    # before: KeyError "['t'] not in index" (pandas' metadata made the column an index)
    pytest.importorskip("pyarrow")
    t, q, tau = data
    frame = _named_frame(ur5, t, q, tau, np.arange(6)).rename(columns={"t": name})
    frame.set_index(name).to_parquet(tmp_path / "log.parquet")
    log = read_log(tmp_path / "log.parquet", ur5, columns={"time": "t"} if name == "time" else None)
    np.testing.assert_array_equal(log.t, t)
    np.testing.assert_array_equal(log.q, q)


@pytest.mark.parametrize("kind", ["datetime", "timedelta"])
def test_datetime_or_timedelta_t_reads_as_seconds_and_says_so(tmp_path, ur5, data, kind) -> None:
    # before: every row reported "'t' unreadable", exit 1
    pytest.importorskip("pyarrow")
    t, q, tau = data
    frame = _named_frame(ur5, t, q, tau, np.arange(6))
    start = pd.Timestamp("2026-12-01 12:00:00") if kind == "datetime" else pd.Timedelta(0)
    frame["t"] = start + pd.to_timedelta(np.round(t * 1e9).astype("int64"), unit="ns")
    frame.to_parquet(tmp_path / "log.parquet")
    for source in (tmp_path / "log.parquet", frame):
        log = read_log(source, ur5)
        offset = start.timestamp() if kind == "datetime" else 0.0
        np.testing.assert_allclose(log.t - offset, t, atol=1e-6)
        ((row, said),) = log.problems
        assert row == 0 and "read as seconds" in said


@pytest.mark.parametrize("bad", [False, True])
def test_cr_only_line_ends_read_the_rows_of_the_lf_file(tmp_path, ur5, data, bad) -> None:
    # before: the header parsed, then "0 rows" (every row lost silently)
    t, q, tau = data
    lf = tmp_path / "lf.csv"
    _named_frame(ur5, t, q, tau, np.arange(6)).to_csv(lf, index=False)
    lines = lf.read_text().splitlines()
    if bad:  # a bad cell: the careful reader (pandas) takes over
        lines[10] = "x" + lines[10][lines[10].index(",") :]
    lf.write_text("\n".join(lines) + "\n")
    cr = tmp_path / "cr.csv"
    cr.write_bytes(lf.read_bytes().replace(b"\n", b"\r"))
    a, b = read_log(lf, ur5), read_log(cr, ur5)
    assert len(b) == N
    np.testing.assert_array_equal(b.q, a.q)
    np.testing.assert_array_equal(b.lines, a.lines)
    assert b.problems == a.problems and len(a.problems) == bad


def test_an_option_the_format_would_ignore_is_refused(tmp_path, ur5, data) -> None:
    # before: --map ignored for bags and NPZ, --topic for CSV/Parquet/NPZ, silently
    t, q, tau = data
    np.savez(tmp_path / "log.npz", t=t, q=q, tau=tau)
    _named_frame(ur5, t, q, tau, np.arange(6)).to_csv(tmp_path / "log.csv", index=False)
    with pytest.raises(pinobs.OptionError, match="--map"):
        read_log(tmp_path / "log.npz", ur5, columns={"time": "t"})
    with pytest.raises(pinobs.OptionError, match="not a bag"):
        read_log(tmp_path / "log.csv", ur5, topic="/joint_states")
    with pytest.raises(pinobs.OptionError, match="not a bag"):
        read_log(_named_frame(ur5, t, q, tau, np.arange(6)), ur5, topic="/joint_states")
    bag = tmp_path / "b"
    _write_bag(bag, ur5, t[:5], q[:5], tau[:5], kind="mcap", rng=np.random.default_rng(2))
    with pytest.raises(pinobs.OptionError, match="--map"):
        read_log(bag, ur5, columns={"time": "t"})


@pytest.mark.parametrize("gripper", ["before", "after"])
def test_messages_of_another_publisher_on_the_topic_are_skipped_and_said_once(
    tmp_path, ur5, data, gripper
) -> None:
    # before: refused when the gripper's came first; otherwise 2N rows, N "dropped samples"
    t, q, tau = data
    bag = tmp_path / "b"
    _write_bag(bag, ur5, t, q, tau, kind="mcap", rng=np.random.default_rng(4), gripper=gripper)
    log = read_log(bag, ur5)
    assert len(log) == N and not log.problems
    np.testing.assert_array_equal(log.q, q)
    np.testing.assert_array_equal(log.lines, 2 * np.arange(N) + (gripper == "before"))
    (note,) = log.notes
    assert f"{N} messages" in note and "gripper_finger" in note and "skipped" in note
    for chunk_rows in (7, N):
        run = pinobs.io.process_log(
            bag, ur5, "kf", rate=1000.0, noise_std=1e-4, chunk_rows=chunk_rows
        )
        assert run.rows == run.estimated == N and not run.bad_rows
        assert run.warnings == [note]


def test_a_file_of_another_kind_is_named_with_what_to_do(tmp_path, ur5, data) -> None:
    # before: a zipped CSV "an .npz must be named .npz", Feather "not UTF-8" alone, an NPZ's
    # q_meas called q, a bag without JointState "0 topics []"
    import zipfile

    t, q, tau = data
    _named_frame(ur5, t, q, tau, np.arange(6)).to_csv(tmp_path / "log.csv", index=False)
    with zipfile.ZipFile(tmp_path / "log.csv.zip", "w") as z:
        z.write(tmp_path / "log.csv", "log.csv")
    with pytest.raises(pinobs.LogFormatError, match=r"zip archive of \['log.csv'\]: unzip it"):
        read_log(tmp_path / "log.csv.zip", ur5)
    pytest.importorskip("pyarrow")
    from pyarrow import feather

    feather.write_feather(pd.DataFrame({"t": t}), str(tmp_path / "log.feather"))
    with pytest.raises(pinobs.LogFormatError, match=r"Feather / Arrow IPC.*Parquet"):
        read_log(tmp_path / "log.feather", ur5)
    np.savez(tmp_path / "res.npz", t=t, q=q, q_meas=q[:, :3])
    with pytest.raises(pinobs.DimensionError, match=r"q_meas \(120, 3\)"):
        read_log(tmp_path / "res.npz", ur5)


def test_a_bag_without_joint_states_lists_its_topics(tmp_path) -> None:
    pytest.importorskip("rosbags")
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    text = ts.types["std_msgs/msg/String"]
    with Writer(tmp_path / "b", version=9) as w:
        conn = w.add_connection("/chatter", text.__msgtype__, typestore=ts)
        w.write(conn, 1, ts.serialize_cdr(text(data="hi"), text.__msgtype__))
    with pytest.raises(pinobs.DimensionError, match=r"its topics: \['/chatter \(std_msgs"):
        read_log(tmp_path / "b", pinobs.load("ur5"))


def test_quoted_fields_read_as_standard_csv_with_their_lines(tmp_path, ur5, data) -> None:
    # before: a quoted comma failed the whole log; a quoted line break made an extra row
    # and shifted the cells of the next
    t, q, tau = data
    frame = _named_frame(ur5, t, q, tau, np.arange(6))
    frame["comment"] = ["still"] * N
    frame.loc[30, "comment"] = "moving, fast"
    frame.loc[60, "comment"] = 'a "quoted" word'
    frame.loc[90, "comment"] = "two\nlines"
    frame.to_csv(tmp_path / "log.csv", index=False)  # pandas quotes the three as needed
    log = read_log(tmp_path / "log.csv", ur5)
    assert len(log) == N and not log.problems
    np.testing.assert_array_equal(log.q, q)
    np.testing.assert_array_equal(log.t, t)
    want = np.arange(N) + 2
    want[91:] += 1  # the row after the two-line field starts a line later
    np.testing.assert_array_equal(log.lines, want)


def test_a_short_row_is_said_as_such(tmp_path, ur5, data) -> None:
    # before: "non-finite position [..., nan, nan]"
    t, q, tau = data
    _named_frame(ur5, t, q, tau, np.arange(6)).to_csv(tmp_path / "log.csv", index=False)
    lines = (tmp_path / "log.csv").read_text().splitlines()
    lines[20] = ",".join(lines[20].split(",")[:5])
    (tmp_path / "log.csv").write_text("\n".join(lines) + "\n")
    log = read_log(tmp_path / "log.csv", ur5)
    assert len(log) == N and log.problems == ((21, "row has 5 of 14 cells"),)

"""Many runs on Dask: results in task order, a bad task fails alone, the sweep table."""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import pytest

pytest.importorskip("dask.distributed")
pd = pytest.importorskip("pandas")

from pinobs.evaluation.distributed import (  # noqa: E402
    TaskOutcome,
    run_sweep_task,
    run_tasks,
    sweep,
    sweep_tasks,
    write_sweep,
)
from pinobs.evaluation.many_logs import run_log_task  # noqa: E402


def _inverse(x: float) -> float:
    return 1.0 / x


def test_tasks_come_back_in_order_and_a_bad_one_fails_alone() -> None:
    seen = []
    out = run_tasks(
        _inverse,
        [1.0, 0.0, 4.0],
        workers=2,
        processes=False,
        progress=lambda k, n: seen.append((k, n)),
    )
    assert [o.task for o in out] == [1.0, 0.0, 4.0]
    assert out[0].value == 1.0 and out[2].value == 0.25
    assert out[1].value is None and "ZeroDivisionError" in (out[1].error or "")
    assert seen[-1] == (3, 3)


def test_a_local_cluster_starts_beside_another_dask_on_port_8787() -> None:
    """Its scheduler's HTTP server took 8787 and, that taken, warned (an error here): the
    tests failed beside any other Dask on the machine."""
    import socket

    taken = socket.socket()
    try:
        try:
            taken.bind(("0.0.0.0", 8787))
            taken.listen()
        except OSError:
            pass  # taken already: the same condition
        out = run_tasks(_inverse, [2.0], workers=1, processes=False)
        assert out[0].value == 0.5
    finally:
        taken.close()


def test_sweep_gives_one_row_per_run_and_observer_and_reports_a_bad_run(tmp_path) -> None:
    tasks = sweep_tasks(
        ["pendulum", "no_such_robot"],
        ["exact"],
        [0, 1],
        {"kf": ("kf", {}), "ekf": ("ekf", {"accel_psd": 1e-6})},
        duration=0.2,
    )
    table = sweep(tasks, workers=2, processes=False)
    assert len(table) == 2 * 2 * 2
    good = table[table["robot"] == "pendulum"]
    assert good["error"].isna().all() and (good["rms_v_error"] < 0.1).all()
    bad = table[table["robot"] == "no_such_robot"]
    assert bad["error"].str.contains("UnknownNameError").all()
    assert bad["rms_v_error"].map(math.isnan).all()
    assert bad["diverged"].isna().all() and (~good["diverged"]).all()  # was False: not known
    # the same run in this process gives the same numbers (a seeded, deterministic task)
    direct = {r["observer"]: r["rms_v_error"] for r in run_sweep_task(tasks[0])}
    first = good[good["seed"] == 0].set_index("observer")["rms_v_error"].to_dict()
    assert first == direct
    paths = write_sweep(table, tmp_path)
    assert paths[0].exists() and paths[0].stat().st_size > 0


def test_sweep_an_observer_that_cannot_be_built_fails_alone_and_the_others_run() -> None:
    tasks = sweep_tasks(
        ["pendulum"],
        ["exact"],
        [0],
        {"lg": ("liegroup", {}), "kf": ("kf", {}), "h": ("highgain", {"no_such": 1})},
        duration=0.2,
    )
    table = sweep(tasks, workers=0)
    assert list(table["observer"]) == ["lg", "kf", "h"]
    rows = table.set_index("observer")
    assert rows.loc["kf", "rms_v_error"] < 0.1 and pd.isna(rows.loc["kf", "error"])  # was NaN
    assert "UnsupportedRobotError" in rows.loc["lg", "error"]
    assert "no_such" in rows.loc["h", "error"]
    assert rows.loc[["lg", "h"], "diverged"].isna().all()
    assert rows.loc[["lg", "h"], "rms_v_error"].map(math.isnan).all()


def test_write_sweep_refuses_a_previous_sweep_and_with_force_leaves_no_stale_plot(
    tmp_path,
) -> None:
    from pinobs.errors import OutputExistsError

    pytest.importorskip("matplotlib")
    ok = sweep(
        sweep_tasks(["pendulum"], ["exact"], [0], {"kf": ("kf", {})}, duration=0.1), workers=0
    )
    failed = ok.assign(rms_v_error=math.nan, error="RuntimeError: x")
    assert [p.name for p in write_sweep(ok, tmp_path)][1:] == ["sweep.png"]
    with pytest.raises(OutputExistsError, match=r"sweep\.parquet' exists; pass --force"):
        write_sweep(failed, tmp_path)
    assert (tmp_path / "sweep.png").exists()
    written = write_sweep(failed, tmp_path, force=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == [written[0].name]  # was: the old png


# ------------------------------------------------------------------ many logs
def _logs(folder, n: int = 200) -> list:
    """Two good logs of the pendulum (CSV, NPZ) and, with ``pandas``, a Parquet one; plus a
    corrupt CSV (a header without the position column)."""
    import numpy as np

    import pinobs
    from pinobs.io import write_log

    robot = pinobs.load("pendulum")
    folder.mkdir()
    paths = []
    for seed, suffix in enumerate((".csv", ".npz", ".parquet")):
        res = pinobs.simulate(
            robot, [], duration=n / 1000, sensor=pinobs.Sensor(1000.0, 1e-4), seed=seed
        )
        t, q, tau = res.t[1:], res.q_meas[1:], res.tau[1:]
        path = folder / f"run{seed}{suffix}"
        if suffix == ".csv":
            write_log(path, t, q, tau)
        elif suffix == ".npz":
            np.savez(path, t=t, q=q, tau=tau)
        else:
            pd.DataFrame({"t": t, "q0": q[:, 0], "tau0": tau[:, 0]}).to_parquet(path)
        paths.append(path)
    bad = folder / "broken.csv"
    bad.write_text("t,tau0\n0.001,0.5\n")
    return [*paths, bad]


def test_many_logs_one_estimates_file_each_equal_to_the_single_log_path_and_a_bad_log_fails_alone(
    tmp_path, capsys
) -> None:
    from pinobs.cli import main

    logs = _logs(tmp_path / "logs")
    out = tmp_path / "out"
    common = ["--robot", "pendulum", "--observer", "kf", "--noise", "1e-4", "--no-progress"]
    many = ["--log", str(tmp_path / "logs"), "--out-dir", str(out), "--workers", "0"]
    code = main(["estimate", *common, *many])
    captured = capsys.readouterr()
    assert code == 1  # one log failed, and only that one
    assert "failed: " in captured.err and "broken.csv" in captured.err
    assert "1 of 4 logs failed" in captured.err
    assert "wrote 3 estimates files" in captured.out  # the files there are (not 4 - failed)
    summary = pd.read_parquet(out / "summary.parquet")
    assert list(summary["log"]) == [str(p) for p in sorted(logs)]
    by = summary.set_index(summary["log"].map(lambda s: s.rsplit("/", 1)[-1]))
    assert "DimensionError" in by.loc["broken.csv", "error"] and pd.isna(
        by.loc["broken.csv", "rows"]
    )
    assert not (out / "broken.csv").exists()
    for good in logs[:3]:
        row = by.loc[good.name]
        assert pd.isna(row["error"]) and row["rows"] == row["estimated"] == 200
        assert row["bad_rows"] == 0 and row["sigma"] == 1e-4 and row["seconds"] > 0
        single = tmp_path / f"single_{good.stem}.csv"
        assert main(["estimate", *common, "--log", str(good), "--out", str(single)]) == 0
        assert (out / f"{good.stem}.csv").read_bytes() == single.read_bytes()
    # the outputs exist: refused without --force, before any work
    again = ["estimate", *common, "--log", str(tmp_path / "logs" / "run*")]
    assert main([*again, "--out-dir", str(out), "--workers", "0"]) == 2
    assert "exists; pass --force" in capsys.readouterr().err
    assert main([*again, "--out-dir", str(out), "--workers", "0", "--force"]) == 0
    assert len(pd.read_parquet(out / "summary.parquet")) == 3


@pytest.mark.parametrize("smooth", [None, {"accel_psd": 1e-4}], ids=["filtered", "smoothed"])
def test_many_logs_on_a_dask_cluster_give_the_serial_results(tmp_path, smooth) -> None:
    from pinobs.evaluation.many_logs import estimate_logs, log_tasks

    logs = _logs(tmp_path / "logs", n=100)
    kw = {"robot": "pendulum", "observer": "ekf", "noise_std": 1e-4, "smooth": smooth}
    serial = estimate_logs(log_tasks(logs, tmp_path / "a", **kw), workers=0)
    dask = estimate_logs(log_tasks(logs, tmp_path / "b", **kw), workers=2, processes=False)
    same = ["log", "rows", "estimated", "bad_rows", "sigma", "consistency", "rho", "error"]
    pd.testing.assert_frame_equal(serial[same], dask[same])
    for p in logs[:3]:
        name = p.with_suffix(".csv").name
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


def test_many_logs_smoothed_each_equal_to_the_single_log_smoother_with_its_rho(
    tmp_path, capsys
) -> None:
    """``estimate --smooth --out-dir``: one file per log, byte-equal to ``--smooth --out``
    on that log; the summary gives ρ (the smoother's check) and its verdict (inconsistent
    where pinobs.smooth would warn) instead of the NIS test's."""
    import numpy as np

    from pinobs.cli import main
    from pinobs.evaluation.many_logs import estimate_logs, log_tasks
    from pinobs.io import write_log
    from pinobs.io.smoothing import smooth_log
    from pinobs.model import load

    logs = _logs(tmp_path / "logs")
    out = tmp_path / "out"
    common = ["--robot", "pendulum", "--observer", "ekf", "--noise", "1e-4", "--no-progress"]
    smooth = ["--smooth", "--accel-psd", "1e-4", "--lag", "0.05"]
    many = ["--log", str(tmp_path / "logs"), "--out-dir", str(out), "--workers", "0"]
    assert main(["estimate", *common, *smooth, *many]) == 1  # broken.csv fails alone
    captured = capsys.readouterr()
    assert "ekf smoothed on" in captured.out and "broken.csv" in captured.err
    summary = pd.read_parquet(out / "summary.parquet")
    by = summary.set_index(summary["log"].map(lambda s: s.rsplit("/", 1)[-1]))
    for good in logs[:3]:
        row = by.loc[good.name]
        assert pd.isna(row["error"]) and row["rows"] == row["estimated"] == 200
        assert row["consistency"] == "consistent"
        _, stretches = smooth_log(
            good, load("pendulum"), tmp_path / f"api_{good.stem}.csv", noise_std=1e-4,
            accel_psd=1e-4, lag=0.05,
        )  # fmt: skip
        assert row["rho"] == stretches[0]["consistency"] and 0.1 < row["rho"] < 10
        single = tmp_path / f"single_{good.stem}.csv"
        argv = ["estimate", *common, *smooth, "--log", str(good), "--out", str(single)]
        assert main(argv) == 0
        written = (out / f"{good.stem}.csv").read_bytes()
        assert written == single.read_bytes()
        assert written.splitlines()[0].decode().endswith("v0,v_std0")
    # a log the model does not explain: the first one's torques off by 1 N·m (ρ ≈ 1e5)
    t, q, tau = np.loadtxt(logs[0], delimiter=",", skiprows=1).T
    off = write_log(tmp_path / "off.csv", t, q[:, None], tau[:, None] + 1.0)
    off_task = log_tasks([off], tmp_path / "off_out", robot="pendulum", observer="ekf",
                         noise_std=1e-4, smooth={"accel_psd": 1e-4, "lag": 0.05})  # fmt: skip
    (row,) = estimate_logs(off_task, workers=0).to_dict("records")
    assert row["consistency"] == "inconsistent" and row["rho"] > 1e3, row


def test_smoother_options_without_smooth_are_refused(tmp_path, capsys) -> None:
    from pinobs.cli import main

    logs = _logs(tmp_path / "logs")
    argv = ["estimate", "--robot", "pendulum", "--observer", "ekf", "--log", str(logs[0])]
    assert main([*argv, "--out", str(tmp_path / "e.csv"), "--lag", "0.1", "--band", "noise"]) == 2
    assert "--lag, --band: options of the smoother; add --smooth" in capsys.readouterr().err
    assert not (tmp_path / "e.csv").exists()


def test_log_tasks_mirror_subfolders_and_refuse_two_logs_for_one_file(tmp_path) -> None:
    from pinobs.errors import OptionError
    from pinobs.evaluation.many_logs import log_tasks

    a, b = tmp_path / "r1" / "run.csv", tmp_path / "r2" / "run.csv"
    tasks = log_tasks([a, b], tmp_path / "out", robot="pendulum", observer="kf")
    assert [t.out for t in tasks] == [
        str((tmp_path / "out" / "r1" / "run.csv").resolve()),
        str((tmp_path / "out" / "r2" / "run.csv").resolve()),
    ]
    with pytest.raises(OptionError, match="would both write"):
        log_tasks([a, a.with_suffix(".npz")], tmp_path / "out", robot="pendulum", observer="kf")
    with pytest.raises(OptionError, match="no logs given"):
        log_tasks([], tmp_path / "out", robot="pendulum", observer="kf")


def test_many_logs_smoothed_with_latency_auto_each_equal_to_the_single_log_run(
    tmp_path,
) -> None:
    """``estimate --out-dir --smooth --latency auto``: the latency found per log (as on one
    log), not an error on every log."""
    from pinobs.cli import main

    logs = _logs(tmp_path / "logs")[:2]
    common = ["--robot", "pendulum", "--observer", "ekf", "--noise", "1e-4", "--no-progress"]
    common += ["--smooth", "--accel-psd", "1e-4", "--lag", "0.05", "--latency", "auto"]
    out = tmp_path / "out"
    argv = [
        "estimate",
        *common,
        "--log",
        str(tmp_path / "logs" / "run[01]*"),
        "--out-dir",
        str(out),
    ]
    assert main([*argv, "--workers", "0"]) == 0
    summary = pd.read_parquet(out / "summary.parquet")
    assert summary["error"].isna().all() and (summary["estimated"] == 200).all()
    assert summary["latency"].map(math.isfinite).all()
    single = tmp_path / "single.csv"
    assert main(["estimate", *common, "--log", str(logs[0]), "--out", str(single)]) == 0
    assert (out / "run0.csv").read_bytes() == single.read_bytes()


def _exit_on_two(task: tuple[Path, int]) -> int:
    folder, x = task
    with open(folder / f"ran{x}", "a") as f:
        f.write("ran\n")
    if x == 2:
        os._exit(1)  # the worker process dies, as when killed for lack of memory
    return x * x


def test_a_task_that_kills_its_worker_fails_alone_and_runs_once(tmp_path) -> None:
    """Its worker dies (KilledWorker): its outcome says so, the others come back, and it
    is not run again (Dask's default: on 3 more workers)."""
    seen: list[TaskOutcome] = []
    tasks = [(tmp_path, k) for k in range(5)]
    out = run_tasks(_exit_on_two, tasks, workers=1, on_result=seen.append)
    assert [o.value for o in out] == [0, 1, None, 9, 16]
    assert "worker process died while running it" in (out[2].error or "")
    assert "out of memory" in (out[2].error or "")
    assert len(seen) == 5
    assert (tmp_path / "ran2").read_text() == "ran\n"


def _slow_square(x: int) -> int:
    time.sleep(0.2)
    return x * x


def test_a_lost_scheduler_leaves_the_tasks_not_done_failed_and_keeps_those_done() -> None:
    import dask.distributed as dd

    cluster = dd.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0"
    )

    def lose_it(outcome: TaskOutcome) -> None:
        if outcome.task == 1:
            cluster.close()

    out = run_tasks(
        _slow_square, list(range(5)), scheduler=cluster.scheduler_address, on_result=lose_it
    )
    assert [o.value for o in out[:2]] == [0, 1] and out[0].error is out[1].error is None
    for o in out[2:]:
        assert (
            o.value is None and o.error == "not done: the connection to the Dask scheduler was lost"
        )


def test_many_logs_say_each_logs_warnings_once_naming_it_and_keep_them_in_the_summary(
    tmp_path, capsys
) -> None:
    """The warnings a log alone gives (σ from the log, or too short for it: the observer's
    default σ; outlier samples rejected) are printed once with the log's name, and are the
    summary's ``warnings``; a σ of NaN there is not silent."""
    import numpy as np

    from pinobs.cli import main

    logs = _logs(tmp_path / "logs")
    t, q, tau = np.loadtxt(logs[0], delimiter=",", skiprows=1).T
    q[150] += 0.1  # an outlier
    np.savetxt(logs[0], np.c_[t, q, tau], delimiter=",", header="t,q0,tau0", comments="")
    short = tmp_path / "logs" / "short.csv"
    short.write_text("".join(logs[0].read_text().splitlines(keepends=True)[:11]))
    common = ["--robot", "pendulum", "--observer", "ekf", "--no-progress"]
    alone = {}
    for log in (logs[0], short):
        assert main(["estimate", *common, "--log", str(log), "--out", str(tmp_path / "a.csv"),
                     "--force"]) == 0  # fmt: skip
        err = capsys.readouterr().err.splitlines()
        alone[log.name] = [x for x in err if x.startswith(("warning: ", "note: "))]
    assert any("too short to estimate it" in x for x in alone["short.csv"])
    assert any("rejected 1 outlier sample" in x for x in alone["run0.csv"])
    argv = ["estimate", *common, "--log", str(tmp_path / "logs" / "*.csv")]
    assert main([*argv, "--out-dir", str(tmp_path / "out"), "--workers", "0"]) == 1  # broken
    err = capsys.readouterr().err.splitlines()
    summary = pd.read_parquet(tmp_path / "out" / "summary.parquet")
    by = summary.set_index(summary["log"].map(lambda s: s.rsplit("/", 1)[-1]))
    for name, said in alone.items():
        log = by.loc[name, "log"]
        assert [x for x in err if x.startswith(f"{log}: ")] == [f"{log}: {x}" for x in said]
        assert by.loc[name, "warnings"].splitlines() == said
    assert math.isnan(by.loc["short.csv", "sigma"])
    assert pd.isna(by.loc["broken.csv", "warnings"])


def test_a_rerun_does_not_take_the_batchs_own_outputs_for_logs(tmp_path, capsys) -> None:
    """``--log 'fleet/**/*.csv' --out-dir fleet/est`` twice: the second run estimates the same
    two logs (not the first run's estimates), saying it left 2 files out; ``--log 'pq/*'
    --out-dir pq``: the summary found there is not a log."""
    import shutil

    from pinobs.cli import main
    from pinobs.errors import OptionError
    from pinobs.evaluation.many_logs import log_tasks

    logs = _logs(tmp_path / "logs")
    for k in (1, 2):
        (tmp_path / "fleet" / f"r{k}").mkdir(parents=True)
        shutil.copy(logs[0], tmp_path / "fleet" / f"r{k}" / "run.csv")
    argv = ["estimate", "--robot", "pendulum", "--observer", "kf", "--noise", "1e-4"]
    argv += [
        "--no-progress",
        "--workers",
        "0",
        "--force",
        "--log",
        str(tmp_path / "fleet/**/*.csv"),
    ]
    argv += ["--out-dir", str(tmp_path / "fleet" / "est")]
    for _ in range(2):
        assert main(argv) == 0
        summary = pd.read_parquet(tmp_path / "fleet" / "est" / "summary.parquet")
        assert [s.rsplit("fleet/", 1)[1] for s in summary["log"]] == ["r1/run.csv", "r2/run.csv"]
    assert "note: 2 of the 4 logs found left out" in capsys.readouterr().err
    pq = tmp_path / "logs"  # a Parquet log and the summary in the same folder
    kw = {"robot": "pendulum", "observer": "kf", "force": True}
    (pq / "summary.parquet").write_bytes(b"")
    tasks = log_tasks([pq / "run2.parquet", pq / "summary.parquet"], pq, **kw)
    assert [t.log for t in tasks] == [str(pq / "run2.parquet")]
    with pytest.raises(OptionError, match="outputs of an earlier run"):
        log_tasks([pq / "summary.parquet"], pq, **kw)


def test_an_out_dir_that_is_a_file_is_refused_before_any_log(tmp_path, capsys) -> None:
    from pinobs.cli import main

    _logs(tmp_path / "logs")
    afile = tmp_path / "afile"
    afile.write_text("")
    argv = ["estimate", "--robot", "pendulum", "--observer", "kf", "--no-progress"]
    argv += ["--log", str(tmp_path / "logs"), "--out-dir", str(afile), "--workers", "0"]
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert f"--out-dir {str(afile)!r} is a file; give a folder" in captured.err
    assert "pinobs estimate:" not in captured.out  # no log attempted


def _interrupt_on_run1(task):  # Ctrl-C while the second log runs
    if "run1" in task.log:
        raise KeyboardInterrupt
    return run_log_task(task)


def test_an_interrupted_batch_writes_the_summary_of_the_logs_done(
    tmp_path, capsys, monkeypatch
) -> None:
    import pinobs.evaluation.many_logs as many_logs
    from pinobs.cli import main

    _logs(tmp_path / "logs")
    monkeypatch.setattr(many_logs, "run_log_task", _interrupt_on_run1)
    out = tmp_path / "out"
    argv = ["estimate", "--robot", "pendulum", "--observer", "kf", "--noise", "1e-4"]
    argv += ["--no-progress", "--log", str(tmp_path / "logs" / "run*"), "--out-dir", str(out)]
    assert main([*argv, "--workers", "0"]) == 130
    assert "interrupted: 1 of 3 logs done" in capsys.readouterr().err
    summary = pd.read_parquet(out / "summary.parquet")
    assert summary["error"].isna().tolist() == [True, False, False]
    assert summary["error"][1] == summary["error"][2] == "not done: interrupted"
    assert summary["estimated"][0] == 200 and (out / "run0.csv").exists()
    assert not (out / "run1.csv").exists()


@pytest.mark.parametrize("address", ["garbage", "http://127.0.0.1:9999"])
def test_a_malformed_scheduler_address_is_an_option_error_naming_the_flag(address) -> None:
    from pinobs.errors import OptionError

    with pytest.raises(OptionError, match=r"--scheduler \(scheduler=\) .* is not a Dask"):
        run_tasks(_inverse, [1.0], scheduler=address)

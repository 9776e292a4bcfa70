"""The command line, called as ``main([...])``."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from pinobs.cli import DEMO_GHOSTS, main
from pinobs.observers import observer_names


def test_list_prints_robots_and_observers(capsys) -> None:
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "cartpole" in out and "ur5" in out and "kf" in out and "fd" in out


def test_run_prints_a_table_and_writes_json_with_rms_v_error(tmp_path: Path, capsys) -> None:
    path = tmp_path / "r.json"
    code = main(
        [
            "run",
            "--robot",
            "cartpole",
            "--observer",
            "fd,kf",
            "--duration",
            "0.5",
            "--json",
            str(path),
            "--save",
            str(tmp_path / "r.npz"),
        ]
    )
    assert code == 0
    out = capsys.readouterr().out
    assert "rms v err" in out and "x aba" in out
    report = json.loads(path.read_text())
    assert set(report["rms_v_error"]) == {"fd", "kf"}
    assert all(0 < v < 1 for v in report["rms_v_error"].values())
    assert report["observers"][0]["cost_in_aba"] > 0
    assert (tmp_path / "r.npz").is_file()


def test_unknown_robot_is_an_error_message_not_a_traceback(capsys) -> None:
    assert main(["run", "--robot", "nosuchbot", "--observer", "kf", "--duration", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "unknown robot 'nosuchbot'" in err and "ur5" in err


def test_unknown_observer_is_an_error_message(capsys) -> None:
    assert main(["run", "--robot", "cartpole", "--observer", "nosuchobs", "--duration", "0.1"]) == 2
    assert "unknown observer 'nosuchobs'" in capsys.readouterr().err


def test_bad_option_value_is_an_error_message(capsys) -> None:
    assert main(["run", "--robot", "cartpole", "--observer", "kf", "--rate", "-5"]) == 2
    assert "rate=-5" in capsys.readouterr().err


def test_demo_prints_tables_for_cartpole_and_ur5_and_writes_json(tmp_path: Path, capsys) -> None:
    assert main(["demo", "--duration", "0.3", "--out", str(tmp_path), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "cartpole (nv = 2)" in out and "ur5 (nv = 6)" in out
    runs = json.loads((tmp_path / "demo.json").read_text())["runs"]
    assert [r["robot"] for r in runs] == ["cartpole", "ur5"]
    for name in ("cartpole", "ur5"):
        assert (tmp_path / f"{name}_playback.html").stat().st_size > 10_000
    assert "playback: open" in out
    # the UR5 carries a payload its observers lack; its page shows the demo's ghosts
    assert "the truth is the inertia20_payload model" in out
    page = (tmp_path / "ur5_playback.html").read_text(encoding="utf-8")
    legend = page[page.index('id="pinobs-legend"') : page.index('id="pinobs-time"')]
    assert re.findall(r'data-label="([^"]+)"', legend) == ["truth", *DEMO_GHOSTS]
    assert "adaptive" not in observer_names() or "adaptive" in DEMO_GHOSTS


def test_missing_subcommand_exits_with_usage() -> None:
    with pytest.raises(SystemExit):
        main([])


def test_check_ii_reports_the_working_ordering_on_the_cartpole_and_fails_on_a_panda(capsys) -> None:
    assert main(["check", "ii", "--robot", "cartpole"]) == 0
    out = capsys.readouterr().out
    assert "HOLDS" in out and "(pole_theta, cart_x)" in out
    assert main(["check", "ii", "--robot", "panda"]) == 1
    assert "FAILS" in capsys.readouterr().out


def test_run_writes_a_playback_page_and_a_plot_and_play_rereads_a_saved_run(
    tmp_path: Path, capsys
) -> None:
    html, png, npz = tmp_path / "p.html", tmp_path / "p.png", tmp_path / "sub" / "r.npz"
    args = ["run", "--robot", "top", "--observer", "kf", "--duration", "0.3", "--no-progress"]
    assert main([*args, "--html", str(html), "--plot", str(png), "--save", str(npz)]) == 0
    assert html.stat().st_size > 10_000 and png.stat().st_size > 10_000
    assert (
        main(["play", str(npz), "--no-progress"]) == 0
    )  # robot and root joint read from the result
    assert (tmp_path / "sub" / "r.html").is_file()
    assert "wrote" in capsys.readouterr().out


def test_meshcat_flag_serves_and_stops_on_end_of_input(monkeypatch, tmp_path: Path, capsys) -> None:
    import pinobs.visualization

    served = []

    class FakeViewer:
        def __enter__(self):
            return self

        def __exit__(self, *exc):
            served.append("closed")

    monkeypatch.setattr(
        pinobs.visualization,
        "serve",
        lambda result, robot: served.append(robot.name) or FakeViewer(),
    )
    monkeypatch.setattr("builtins.input", lambda prompt="": (_ for _ in ()).throw(EOFError))
    assert (
        main(
            [
                "run",
                "--robot",
                "pendulum",
                "--observer",
                "kf",
                "--duration",
                "0.1",
                "--no-progress",
                "--meshcat",
            ]
        )
        == 0
    )
    assert served == ["pendulum", "closed"]


def test_sweep_writes_a_table_and_reports_a_failed_run(tmp_path, capsys) -> None:
    pytest.importorskip("dask.distributed")
    pytest.importorskip("pandas")
    code = main(
        [
            "sweep",
            "--robots",
            "pendulum,cartpole",
            "--scenarios",
            "exact",
            "--seeds",
            "0-1",
            "--observers",
            "kf,ekf+d=ekf:disturbance_psd=1,lg=liegroup",
            "--duration",
            "0.2",
            "--workers",
            "1",
            "--no-progress",
            "--out",
            str(tmp_path),
        ]
    )
    captured = capsys.readouterr()
    assert code == 1  # liegroup refuses both robots: its rows fail alone and are reported
    # named before the runs, listed once per robot with its seeds, on stderr
    assert captured.err.index("warning: lg refuses pendulum") < captured.err.index("failed:")
    assert "failed: lg on pendulum exact, seeds 0-1: " in captured.err
    assert "failed: lg on cartpole exact, seeds 0-1: " in captured.err
    assert "ekf+d" not in captured.err and "failed:" not in captured.out
    assert "pinobs: error: 4 of 12 observer runs failed" in captured.err
    assert any(p.name.startswith("sweep.") for p in tmp_path.iterdir())


def test_sweep_an_observer_that_refuses_a_robot_fails_alone(tmp_path, capsys) -> None:
    """Found by a sweep: liegroup refusing the UR5 made every UR5 row NaN (kf's too),
    marked them not diverged, and dropped the UR5 from the median table."""
    pd = pytest.importorskip("pandas")
    argv = ["sweep", "--robots", "pendulum,rigid_body", "--seeds", "0", "--workers", "0"]
    code = main(
        [*argv, "--observers", "kf,lg=liegroup", "--duration", "0.2", "--out", str(tmp_path)]
    )
    assert code == 1
    table = pd.read_parquet(tmp_path / "sweep.parquet").set_index(["robot", "observer"])
    assert table.loc[("pendulum", "kf"), "rms_v_error"] < 0.1  # was NaN
    assert pd.isna(table.loc[("pendulum", "kf"), "error"])
    assert "UnsupportedRobotError" in table.loc[("pendulum", "lg"), "error"]
    assert pd.isna(table.loc[("pendulum", "lg"), "diverged"])  # was False
    assert table.loc[("rigid_body", "lg"), "rms_v_error"] < 0.1
    medians = capsys.readouterr().out.split("over seeds")[1]
    assert re.search(r"pendulum\s+exact\s+\S+\s+NaN", medians)  # was missing


def test_sweep_refuses_an_existing_sweep_without_force_before_running(tmp_path, capsys) -> None:
    pytest.importorskip("pandas")
    argv = ["sweep", "--robots", "pendulum", "--seeds", "0", "--observers", "kf", "--workers", "0"]
    argv += ["--duration", "0.1", "--no-progress", "--out", str(tmp_path)]
    assert main(argv) == 0
    before = (tmp_path / "sweep.parquet").read_bytes()
    capsys.readouterr()
    assert main(argv) == 2  # was: overwritten
    captured = capsys.readouterr()
    assert "sweep.parquet' exists; pass --force" in captured.err and captured.out == ""
    assert (tmp_path / "sweep.parquet").read_bytes() == before
    assert main([*argv, "--force"]) == 0


# ------------------------------------------------------- excite (sweep findings)
def test_excite_writes_a_trajectory_for_a_one_dof_robot(tmp_path: Path, capsys) -> None:
    # Pinocchio's joint-torque regressor is a 1-D row when nv = 1: hstack used to raise
    out = tmp_path / "e.csv"
    assert main(["excite", "--robot", "pendulum", "--duration", "2", "--out", str(out)]) == 0
    lines = out.read_text().splitlines()
    assert lines[0] == "t,q.theta,v.theta,a.theta,tau.theta"
    assert len(lines) == 1 + 201


def test_excite_of_joints_without_limits_warns_nothing(tmp_path: Path) -> None:
    """double_pendulum's joints have no position limits (Pinocchio's ±1.8e308 since a URDF's
    lower = upper = 0 reads as none): hi − lo overflowed, a numpy RuntimeWarning (an error in
    this suite); each joint now swings about ±π/2 about its neutral position (measured
    −0.881 to 0.692 and 0 to 1.5712 rad)."""
    out = tmp_path / "e.csv"
    assert main(["excite", "--robot", "double_pendulum", "--duration", "2", "--out", str(out)]) == 0
    q = np.loadtxt(out, delimiter=",", skiprows=1)[:, 1:3]
    assert np.all(np.abs(q) <= 1.01 * np.pi / 2) and np.ptp(q, axis=0).min() > 0.5


@pytest.mark.parametrize(
    ("option", "value", "match"),
    [
        ("--rate", "0", "rate=0.0 is out of range"),
        ("--rate", "-100", "rate=-100.0 is out of range"),
        ("--rate", "1", "cannot sample the trajectory's highest harmonic"),
        ("--duration", "-1", "duration=-1.0 is out of range"),
        ("--duration", "0", "duration=0.0 is out of range"),
        ("--duration", "inf", "duration=inf is out of range"),
        ("--seed", "-1", "seed=-1: give an integer >= 0"),
    ],
)
def test_excite_refuses_bad_values_before_writing_anything(
    tmp_path: Path, capsys, option: str, value: str, match: str
) -> None:
    out = tmp_path / "e.csv"
    argv = ["excite", "--robot", "pendulum", "--duration", "2", "--out", str(out)]
    assert main([*argv, option, value]) == 2
    assert match in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_excite_refuses_a_directory_and_creates_missing_parents(tmp_path: Path, capsys) -> None:
    argv = ["excite", "--robot", "pendulum", "--duration", "2", "--out"]
    assert main([*argv, str(tmp_path), "--force"]) == 2
    assert "is a directory; give a file name" in capsys.readouterr().err
    (tmp_path / "afile").write_text("x")
    assert main([*argv, str(tmp_path / "afile" / "e.csv")]) == 2
    assert "is a file, not a folder" in capsys.readouterr().err
    out = tmp_path / "missing" / "parent" / "e.csv"
    assert main([*argv, str(out)]) == 0
    assert out.exists()


# ------------------------------------------------------- sweep options (sweep findings)
def test_sweep_observer_options_are_typed_ints_floats_and_booleans() -> None:
    from pinobs.cli.sweep import _parse_sweep_observers

    parsed = _parse_sweep_observers(
        "a=adaptive:friction=False,h=highgain:order=3,ekf:disturbance_psd=1e-2,r=riemannian:x=true"
    )
    assert parsed["a"] == ("adaptive", {"friction": False})  # was the string 'False', read as True
    assert parsed["h"] == ("highgain", {"order": 3}) and type(parsed["h"][1]["order"]) is int
    assert parsed["ekf"] == ("ekf", {"disturbance_psd": 0.01})  # was "unknown observer '1'"
    assert parsed["r"] == ("riemannian", {"x": True})


@pytest.mark.parametrize(
    ("spec", "match"),
    [
        ("e=ekf:rate=10", "rate is the same for every observer of a sweep; give --rate"),
        ("e=ekf:noise_std=0.1", "give --noise"),
        ("a=kf,a=fd", "the label 'a' is used twice"),
        ("kf,,fd", "an empty entry"),
        ("e=ekf:disturbance_psd", "is not key=value"),
        ("=kf", "give NAME, NAME:key=value or LABEL=NAME:key=value"),
    ],
)
def test_sweep_refuses_bad_observer_specs_before_running(
    tmp_path: Path, capsys, spec: str, match: str
) -> None:
    code = main(
        ["sweep", "--robots", "pendulum", "--observers", spec, "--out", str(tmp_path / "s")]
    )
    assert code == 2
    assert match in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize(
    ("option", "value", "match"),
    [
        ("--seeds", "3-1", "the range '3-1' is empty"),
        ("--seeds", "0--2", "is not a seed or a range"),
        ("--seeds", "5-", "is not a seed or a range"),
        ("--seeds", "0-2,1", "names 1 more than once"),
        ("--robots", "pendulum,pendulum", "names pendulum more than once"),
        ("--robots", "no_such_robot", "no_such_robot"),
        ("--scenarios", "exact,nope", "unknown 'nope'"),
        ("--scenarios", "exact,exact", "names exact more than once"),
        ("--duration", "0", "--duration=0.0 is out of range"),
        ("--duration", "1e-4", "shorter than one sample at 1000 Hz"),
        ("--rate", "nan", "--rate=nan is out of range"),
        ("--observers", "h=highgain:no_such_option=1", "no_such_option"),
    ],
)
def test_sweep_refuses_bad_options_up_front(
    tmp_path: Path, capsys, option: str, value: str, match: str
) -> None:
    code = main(["sweep", "--robots", "pendulum", option, value, "--out", str(tmp_path / "s")])
    assert code == 2
    captured = capsys.readouterr()
    assert match in captured.err and captured.out == ""
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize(
    "command",
    [
        ["sweep", "--robots", "pendulum"],
        ["bench", "--quick"],
        ["estimate", "--robot", "pendulum", "--observer", "kf", "--log", "logs", "--out-dir", "o"],
    ],
)
@pytest.mark.parametrize(
    ("flags", "match"),
    [
        (["--workers", "-1"], "--workers -1: give 0 (the tasks one after the other"),
        (
            ["--workers", "2", "--scheduler", "tcp://h:1"],
            "--workers 2 with --scheduler tcp://h:1: the scheduler's cluster has its own workers",
        ),
    ],
)
def test_cluster_flags_are_refused_by_name_before_any_output(
    tmp_path: Path, capsys, monkeypatch, command: list[str], flags: list[str], match: str
) -> None:
    """Found by a sweep: refused after "N runs on a local Dask cluster (-1)" was printed, in
    Python names (workers=2 with scheduler=...); bench ignored --workers with --scheduler."""
    monkeypatch.chdir(tmp_path)
    assert main([*command, *flags]) == 2
    captured = capsys.readouterr()
    assert f"pinobs: error: {match}" in captured.err and captured.out == ""
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("flags", [["--workers", "2"], ["--scheduler", "tcp://h:1"]])
def test_one_log_refuses_the_cluster_flags_it_would_ignore(
    tmp_path: Path, capsys, flags: list[str]
) -> None:
    """Found by a sweep: ``estimate --out`` (one log, run here) ignored them silently."""
    out = tmp_path / "est.csv"
    argv = ["estimate", "--robot", "pendulum", "--observer", "kf", "--log", "log.csv"]
    argv += ["--out", str(out), *flags]
    assert main(argv) == 2
    assert f"pinobs: error: {flags[0]}: many logs run on Dask" in capsys.readouterr().err
    assert not out.exists()


def test_sweep_where_no_run_succeeds_says_so_and_writes_the_table(tmp_path, capsys) -> None:
    pytest.importorskip("pandas")
    argv = ["sweep", "--robots", "pendulum", "--seeds", "0", "--observers", "liegroup"]
    code = main([*argv, "--duration", "0.1", "--workers", "0", "--out", str(tmp_path)])
    assert code == 1  # was: ValueError: Data cannot be log-scaled, from the plot
    captured = capsys.readouterr()
    assert "pinobs: error: 0 of 1 run succeeded" in captured.err
    assert "pinobs sweep: 1 run on this process" in captured.out
    assert [p.name for p in tmp_path.iterdir() if p.suffix == ".png"] == []


def test_sweep_tasks_make_robot_file_paths_absolute(tmp_path, monkeypatch) -> None:
    from pinobs.evaluation.distributed import sweep_tasks

    (tmp_path / "arm.urdf").write_text("<robot/>")
    monkeypatch.chdir(tmp_path)
    tasks = sweep_tasks(["arm.urdf", "pendulum"], ["exact"], [0], {"kf": ("kf", {})})
    assert [t.robot for t in tasks] == [str(tmp_path / "arm.urdf"), "pendulum"]


# ------------------------------------------------- run / demo values (sweep findings)
@pytest.mark.parametrize(
    ("option", "match"),
    [
        ("--duration=-1", "duration=-1.0 is out of range"),
        ("--duration=inf", "duration=inf is out of range"),
        ("--duration=nan", "duration=nan is out of range"),
        ("--duration=0", "duration=0.0 is out of range"),
        ("--seed=-1", "--seed -1: give an integer >= 0"),
        ("--perturb-q=nan", "perturb_q=nan is out of range"),
        ("--perturb-q=inf", "perturb_q=inf is out of range"),
        ("--perturb-q=-0.1", "perturb_q=-0.1 is out of range"),
    ],
)
def test_run_refuses_bad_simulation_values_with_one_line(capsys, option: str, match: str) -> None:
    assert main(["run", "--robot", "pendulum", "--observer", "kf", option]) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err


def test_demo_refuses_a_negative_seed_before_simulating(tmp_path: Path, capsys) -> None:
    assert main(["demo", "--seed=-1", "--out", str(tmp_path / "d")]) == 2
    assert "--seed -1: give an integer >= 0" in capsys.readouterr().err


# ------------------------------------------------------- outputs (sweep findings)
@pytest.mark.parametrize(
    ("flag", "target", "match"),
    [
        ("--json", "adir", "--json '{}' is a directory; give a file name"),
        ("--save", "afile/x.npz", "'{}' is a file, not a folder"),
        ("--html", "adir", "--html '{}' is a directory"),
        ("--plot", "r/p.txt", "matplotlib cannot write '.txt' files"),
    ],
)
def test_run_refuses_unwritable_outputs_before_simulating(
    tmp_path: Path, capsys, monkeypatch, flag: str, target: str, match: str
) -> None:
    import pinobs.cli.run

    (tmp_path / "adir").mkdir()
    (tmp_path / "afile").write_text("x")
    monkeypatch.setattr(pinobs.cli.run, "simulate", None)  # calling it would raise TypeError
    path = tmp_path / target
    shown = path.parent if target.startswith("afile") else path
    code = main(["run", "--robot", "pendulum", "--observer", "kf", flag, str(path)])
    assert code == 2
    assert match.format(shown) in capsys.readouterr().err


def test_run_refuses_the_same_file_for_json_and_save(tmp_path: Path, capsys) -> None:
    same = str(tmp_path / "x")
    assert (
        main(["run", "--robot", "pendulum", "--observer", "kf", "--json", same, "--save", same])
        == 2
    )
    assert "--json and --save are the same file" in capsys.readouterr().err


@pytest.mark.parametrize("command", [["demo"], ["sweep", "--robots", "pendulum"]])
def test_demo_and_sweep_refuse_a_file_as_their_output_folder(
    tmp_path: Path, capsys, command: list[str]
) -> None:
    (tmp_path / "afile").write_text("x")
    assert main([*command, "--out", str(tmp_path / "afile")]) == 2
    assert "is a file; give a folder" in capsys.readouterr().err


def test_an_os_error_while_writing_is_one_line_and_exit_1(
    tmp_path: Path, capsys, monkeypatch
) -> None:
    from pinobs.simulation import Result

    def full(self, path):
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(Result, "save", full)
    argv = ["run", "--robot", "pendulum", "--observer", "kf", "--duration", "0.1"]
    assert main([*argv, "--save", str(tmp_path / "r.npz")]) == 1
    err = capsys.readouterr().err
    assert (
        err.startswith("pinobs: error: [Errno 28] No space left on device")
        and "Traceback" not in err
    )


def test_run_plot_reports_the_file_it_wrote(tmp_path: Path, capsys) -> None:
    pytest.importorskip("matplotlib")
    argv = ["run", "--robot", "pendulum", "--observer", "kf", "--duration", "0.2"]
    assert main([*argv, "--plot", str(tmp_path / "p")]) == 0
    assert f"wrote {tmp_path / 'p.png'}" in capsys.readouterr().out


def test_play_refuses_a_result_of_another_robot_unless_forced(tmp_path: Path, capsys) -> None:
    pytest.importorskip("matplotlib")
    saved = tmp_path / "cp.npz"
    argv = ["run", "--robot", "cartpole", "--observer", "kf", "--duration", "0.2"]
    assert main([*argv, "--save", str(saved)]) == 0
    play = ["play", str(saved), "--robot", "double_pendulum", "--plot", str(tmp_path / "p.png")]
    assert main(play) == 2  # was: cart-pole data drawn on a double pendulum (same nq)
    assert "is a run of 'cartpole', not of 'double_pendulum'" in capsys.readouterr().err
    assert main([*play, "--force"]) == 0
    assert main(["play", str(saved), "--robot", "pendulum", "--force"]) == 2
    assert "has nq = 2, nv = 2; robot 'pendulum' has nq = 1" in capsys.readouterr().err


def test_play_of_a_file_that_is_not_a_result_is_one_line(tmp_path: Path, capsys) -> None:
    (tmp_path / "notes.txt").write_text("x\n")
    assert main(["play", str(tmp_path / "notes.txt")]) == 2
    err = capsys.readouterr().err
    assert "is not a result saved by pinobs" in err and "Traceback" not in err


def test_play_of_a_run_whose_robot_file_moved_gives_the_command_with_its_new_path(
    tmp_path: Path, capsys, monkeypatch
) -> None:
    """The message was the loader's "does not exist; give an existing URDF/MJCF file or one of
    the robot names: a1, ..." (78 names); now the command to rerun, with the file's new path
    when one of that name is next to the result or here, else a placeholder."""
    import shlex

    monkeypatch.chdir(tmp_path)
    (tmp_path / "arm").mkdir()
    urdf = tmp_path / "arm" / "arm.urdf"
    urdf.write_text(
        """<?xml version="1.0"?><robot name="arm"><link name="world"/>
  <joint name="j" type="revolute"><parent link="world"/><child link="rod"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="100" velocity="10"/></joint>
  <link name="rod"><inertial><origin xyz="0 0 0.5"/><mass value="1"/>
    <inertia ixx="0.08" ixy="0" ixz="0" iyy="0.08" iyz="0" izz="0.001"/></inertial></link>
</robot>"""
    )
    saved = tmp_path / "runs" / "arm run.npz"
    run = ["run", "--robot", str(urdf), "--observer", "kf", "--duration", "0.1"]
    assert main([*run, "--save", str(saved)]) == 0
    (tmp_path / "models").mkdir()
    urdf.rename(tmp_path / "models" / "arm.urdf")
    capsys.readouterr()
    page = str(tmp_path / "p.html")
    assert main(["play", str(saved), "--html", page, "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"robot file {str(urdf)!r}, which no longer exists" in err and "a1, " not in err
    command = err.strip().splitlines()[-1]
    assert shlex.split(command) == [
        "pinobs",
        "play",
        str(saved),
        "--robot",
        str(tmp_path / "models" / "arm.urdf"),
        "--html",
        page,
        "--no-progress",
    ]
    assert main(shlex.split(command)[1:]) == 0  # the command given works
    (tmp_path / "models" / "arm.urdf").rename(tmp_path / "elsewhere.urdf")
    assert main(["play", str(saved), "--meshcat"]) == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert shlex.split(last)[3:] == ["--robot", "NEW/PATH/TO/arm.urdf", "--meshcat"]


@pytest.mark.parametrize("spec", ["", ",,", " , "])
def test_run_refuses_an_observer_list_without_a_name(capsys, monkeypatch, spec: str) -> None:
    import pinobs.cli.run

    monkeypatch.setattr(pinobs.cli.run, "simulate", None)  # was: the whole run, then a TypeError
    assert main(["run", "--robot", "pendulum", "--observer", spec]) == 2
    assert "names no observer; give names (pinobs list) or 'all'" in capsys.readouterr().err


def test_run_all_in_a_list_skips_observers_that_refuse_the_robot(capsys) -> None:
    argv = ["run", "--robot", "pendulum", "--duration", "0.2", "--observer", "all,kf"]
    assert main(argv) == 0  # was: UnsupportedRobotError from liegroup, which 'all' alone skips
    assert "skipped liegroup:" in capsys.readouterr().out


def test_run_prints_why_an_observer_failed(capsys, monkeypatch) -> None:
    import dataclasses

    import pinobs.cli.run

    real = pinobs.cli.run.simulate

    def failing(*args, **kwargs):
        res = real(*args, **kwargs)
        tr = dataclasses.replace(res.traces[0], diverged_at=0.0)
        meta = {**res.meta, "failures": {"kf": "NonFiniteError at t = 0 s: q is nan"}}
        return dataclasses.replace(res, traces=(tr,), meta=meta)

    monkeypatch.setattr(pinobs.cli.run, "simulate", failing)
    assert main(["run", "--robot", "pendulum", "--observer", "kf", "--duration", "0.1"]) == 0
    assert "failed kf: NonFiniteError at t = 0 s: q is nan" in capsys.readouterr().out


# ------------------------------------------------------------------ --lock
FINGERS = ["panda_finger_joint1", "panda_finger_joint2"]


@pytest.fixture(scope="module")
def franka_log(tmp_path_factory) -> tuple[Path, np.ndarray]:
    """A 7-joint Franka log (columns t, q0..q6, tau0..tau6): the panda simulated with its
    fingers locked, and its true velocities."""
    import pinobs
    from pinobs.io import write_log

    arm = pinobs.load("panda", lock=FINGERS)
    res = pinobs.simulate(arm, [], duration=0.5, sensor=pinobs.Sensor(1000.0, 1e-4), seed=3)
    path = tmp_path_factory.mktemp("franka") / "franka.csv"
    write_log(path, res.t[1:], res.q_meas[1:], res.tau[1:], digits=12)
    return path, np.asarray(res.v[1:])


def test_estimate_runs_a_seven_joint_franka_log_on_the_panda_with_its_fingers_locked(
    franka_log, tmp_path: Path, capsys
) -> None:
    log, v_true = franka_log
    out = tmp_path / "est.csv"
    base = ["estimate", "--robot", "panda", "--observer", "ekf", "--log", str(log)]
    base += ["--noise", "1e-4", "--no-progress", "--out", str(out)]
    assert main(base) == 2  # the nine-joint panda: the log lacks its fingers
    err = capsys.readouterr().err
    assert "--lock panda_finger_joint1 --lock panda_finger_joint2" in err and not out.exists()
    assert main([*base, "--lock", FINGERS[0], "--lock", FINGERS[1]]) == 0
    header = out.read_text().splitlines()[0].split(",")
    assert header == ["t", *(f"q{i}" for i in range(7)), *(f"v{i}" for i in range(7))]
    est = np.loadtxt(out, delimiter=",", skiprows=1)
    settled = slice(100, None)  # after 0.1 s
    rms = np.sqrt(np.mean((est[settled, 8:] - v_true[settled]) ** 2))
    assert rms < 1e-3 * np.sqrt(np.mean(v_true[settled] ** 2))  # (2e-4 of it measured)


def test_estimate_of_many_logs_locks_the_joints_in_every_task(franka_log, tmp_path: Path) -> None:
    import pandas as pd

    log, _ = franka_log
    argv = ["estimate", "--robot", "panda", "--observer", "kf", "--log", str(log.parent)]
    argv += ["--lock", FINGERS[0], "--lock", f"{FINGERS[1]}=0.01", "--noise", "1e-4"]
    assert main([*argv, "--out-dir", str(tmp_path / "out"), "--workers", "0", "--no-progress"]) == 0
    table = pd.read_parquet(tmp_path / "out" / "summary.parquet")
    assert len(table) == 1 and table["error"].isna().all()


def test_bad_lock_values_are_errors_naming_the_flag(capsys) -> None:
    base = ["check", "ii", "--robot", "panda"]
    for lock, said in (
        (f"{FINGERS[0]}=wide", f"--lock '{FINGERS[0]}=wide': VALUE 'wide' is not a number"),
        ("=0.01", "--lock '=0.01': give JOINT or JOINT=VALUE"),
        (f"{FINGERS[0]}=inf", "is not finite"),
        ("finger", "lock (--lock) names ['finger'], which robot 'panda' does not have"),
        (f"{FINGERS[0]}=0.5", "outside the position limits [0, 0.04]"),
    ):
        assert main([*base, "--lock", lock]) == 2, lock
        err = capsys.readouterr().err
        assert said in err and "Traceback" not in err, err
    assert main([*base, "--lock", FINGERS[0], "--lock", f"{FINGERS[0]}=0.01"]) == 2
    assert f"--lock names joint '{FINGERS[0]}' twice" in capsys.readouterr().err


def test_every_command_that_takes_robot_takes_lock() -> None:
    import argparse

    from pinobs.cli import _parser

    sub = next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction)).choices
    with_robot = {name for name, p in sub.items() if "--robot" in p._option_string_actions}
    assert with_robot == {"run", "play", "estimate", "check", "identify", "excite"}
    for name in with_robot:
        assert "--lock" in sub[name]._option_string_actions, name


def test_a_locked_run_is_played_back_on_the_locked_robot(tmp_path: Path, capsys) -> None:
    pytest.importorskip("matplotlib")
    saved = tmp_path / "r.npz"
    run = ["run", "--robot", "panda", "--observer", "kf", "--duration", "0.05", "--no-progress"]
    assert (
        main([*run, "--lock", f"{FINGERS[0]}=0.02", "--lock", FINGERS[1], "--save", str(saved)])
        == 0
    )
    from pinobs.simulation import Result

    result = Result.load(saved)
    assert result.q.shape[1] == 7 and result.meta["lock"] == {FINGERS[0]: 0.02, FINGERS[1]: 0.0}
    # play reloads the run's robot with its joints locked (nine joints would not fit)
    assert main(["play", str(saved), "--plot", str(tmp_path / "p.png"), "--no-progress"]) == 0
    assert (tmp_path / "p.png").stat().st_size > 10_000
    # the robot given anew: its locks given anew
    given = ["play", str(saved), "--robot", "panda", "--plot", str(tmp_path / "q.png")]
    assert main(given) == 2
    assert "nq = 7, nv = 7; robot 'panda' has nq = 9" in capsys.readouterr().err
    assert main([*given, "--lock", FINGERS[0], "--lock", FINGERS[1]]) == 0


def test_excite_and_identify_take_lock_and_the_calibrated_urdf_has_the_joint_fixed(
    tmp_path: Path, capsys
) -> None:
    import xml.etree.ElementTree as ET

    import pinobs

    out = tmp_path / "exc.csv"
    argv = ["excite", "--robot", "planar_3r", "--lock", "joint3=0.4", "--duration", "4"]
    assert main([*argv, "--out", str(out)]) == 0
    assert out.read_text().splitlines()[0].split(",")[:3] == ["t", "q.joint1", "q.joint2"]
    robot = pinobs.load("planar_3r", lock={"joint3": 0.4})
    truth = robot.perturbed(inertia_scale=[1.2, 0.8], damping=[0.2, 0.1])
    res = pinobs.simulate(
        robot, [], duration=6.0, sensor=pinobs.Sensor(1000.0, 1e-5), seed=1, plant=truth
    )
    from pinobs.io import write_log

    log = write_log(tmp_path / "log.csv", res.t[1:], res.q_meas[1:], res.tau[1:])
    urdf = tmp_path / "calibrated.urdf"
    argv = ["identify", "--robot", "planar_3r", "--lock", "joint3=0.4", "--log", str(log)]
    assert main([*argv, "--out", str(urdf)]) == 0
    types = {j.get("name"): j.get("type") for j in ET.parse(urdf).getroot().findall("joint")}
    assert types["joint3"] == "fixed"
    calibrated = pinobs.load(urdf, friction=True)  # no --lock needed: the file has it fixed
    assert calibrated.joint_names == ("joint1", "joint2")
    rng = np.random.default_rng(0)
    for _ in range(10):  # closer to the truth than the nominal model
        q = robot.random_configuration(rng)
        m = truth.mass_matrix(q)
        assert (
            np.abs(calibrated.mass_matrix(q) - m).max()
            < 0.2 * np.abs(robot.mass_matrix(q) - m).max()
        )


def test_play_of_a_locked_run_whose_robot_file_moved_gives_the_command_with_its_locks(
    tmp_path: Path, capsys, monkeypatch
) -> None:
    import shlex

    from pinobs.model.loading import _models_dir

    monkeypatch.chdir(tmp_path)
    urdf = tmp_path / "arm.urdf"
    urdf.write_text((_models_dir() / "planar_3r.urdf").read_text())
    saved = tmp_path / "run.npz"
    run = ["run", "--robot", str(urdf), "--lock", "joint3=0.25", "--observer", "kf"]
    assert main([*run, "--duration", "0.05", "--no-progress", "--save", str(saved)]) == 0
    (tmp_path / "models").mkdir()
    urdf.rename(tmp_path / "models" / "arm.urdf")
    capsys.readouterr()
    png = str(tmp_path / "p.png")
    assert main(["play", str(saved), "--plot", png]) == 2
    command = shlex.split(capsys.readouterr().err.strip().splitlines()[-1])
    assert command[3:] == [
        "--robot",
        str(tmp_path / "models" / "arm.urdf"),
        "--plot",
        png,
        "--lock",
        "joint3=0.25",
    ]
    pytest.importorskip("matplotlib")
    assert main(command[1:]) == 0  # the command given works: the locked two-joint arm


# ------------------------------------------------ the package (issue 37, item 3)
def _subcommands() -> dict[str, object]:
    import argparse

    from pinobs.cli import _parser

    return next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction)).choices


def test_help_synopsis_lists_every_subcommand_generated_from_its_parser(capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    head, sep, synopsis = text.partition("synopsis (pinobs COMMAND --help")
    assert sep, text
    lines = synopsis.splitlines()[1:]
    assert [line.split()[:2] for line in lines] == [["pinobs", name] for name in _subcommands()]
    for name in _subcommands():  # and each in the list argparse writes above it
        assert re.search(rf"^    {name} ", head, re.M), name
    assert "identify" in synopsis and "excite" in synopsis  # the hand-written one lacked them
    # the required arguments come from the parsers: a mutually exclusive group, a positional
    assert (
        "  pinobs estimate --robot ROBOT --observer OBSERVER --log LOG (--out OUT | --out-dir "
        "OUT_DIR) [options]"
    ) in lines
    assert "  pinobs check {ii} --robot ROBOT [options]" in lines
    assert "  pinobs list" in lines


def test_every_command_module_is_registered_once() -> None:
    import pinobs.cli
    from pinobs.cli import COMMANDS

    shared = {"__init__", "__main__", "options", "output"}
    files = {p.stem for p in Path(pinobs.cli.__file__).parent.glob("*.py")} - shared
    modules = [getattr(c, "__name__", "").rsplit(".", 1)[-1] for c in COMMANDS]
    assert sorted(modules) == sorted(files)
    assert len(_subcommands()) == len(COMMANDS)


def test_python_m_pinobs_cli_is_the_pinobs_command() -> None:
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-m", "pinobs.cli", "--help"], capture_output=True, text=True, check=False
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("usage: pinobs ") and "  pinobs demo" in out.stdout


def test_estimate_blends_a_model_based_observer_unless_alone(franka_log, tmp_path: Path) -> None:
    """``pinobs estimate`` runs ``ekf`` never behind kf (``pinobs.estimate``'s default);
    ``--alone`` runs the family alone; both equal the Python API's."""
    import pinobs

    log, _ = franka_log
    arm = pinobs.load("panda", lock=FINGERS)
    base = ["estimate", "--robot", "panda", "--observer", "ekf", "--log", str(log)]
    base += ["--lock", FINGERS[0], "--lock", FINGERS[1], "--noise", "1e-4", "--no-progress"]
    for alone in (False, True):
        out = tmp_path / f"est{alone}.csv"
        assert main([*base, "--out", str(out), *(["--alone"] if alone else [])]) == 0
        est = np.loadtxt(out, delimiter=",", skiprows=1)[:, 8:]
        df = pinobs.estimate(
            "ekf", log, robot=arm, noise_std=1e-4, options={"never_behind": not alone}
        )
        np.testing.assert_allclose(est, df[[f"v{i}" for i in range(7)]].to_numpy(), atol=1e-9)
    blended = np.loadtxt(tmp_path / "estFalse.csv", delimiter=",", skiprows=1)
    assert not np.array_equal(
        blended, np.loadtxt(tmp_path / "estTrue.csv", delimiter=",", skiprows=1)
    )


@pytest.mark.parametrize(
    ("flags", "said"),
    [
        (["--observer", "ekf", "--smooth"], "--alone: the smoother runs its observer alone"),
        (["--observer", "inekf"], "--alone: inekf runs its observer alone"),
    ],
)
def test_alone_is_refused_where_nothing_is_blended(tmp_path: Path, capsys, flags, said) -> None:
    argv = ["estimate", "--robot", "pendulum", "--log", "log.csv", "--alone"]
    assert main([*argv, *flags, "--out", str(tmp_path / "o.csv")]) == 2
    assert f"pinobs: error: {said}" in capsys.readouterr().err

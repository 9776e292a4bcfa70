"""The benchmark harness on a tiny configuration (the full run is `pinobs bench`)."""

from __future__ import annotations

import math
import re

import pytest

from pinobs.cli import main
from pinobs.evaluation.bench import BenchConfig, format_bench, run_bench, scaling_exponent
from pinobs.simulation import MISMATCH_SCENARIOS


def test_scaling_exponent_recovers_a_power_law() -> None:
    nv = [2, 6, 9, 18, 38]
    assert scaling_exponent(nv, [3e-6 * n**1.5 for n in nv]) == pytest.approx(1.5)
    assert math.isnan(scaling_exponent([2, 6], [1.0, 2.0]))


def test_bench_reports_every_observer_and_the_tuned_baselines(capsys) -> None:
    cfg = BenchConfig(
        robots=("cartpole",),
        mismatch_robots=("cartpole",),
        cost_robots=("pendulum", "planar_3r"),
        duration=0.4,
        timing_updates=20,
    )
    report = run_bench(cfg, log=lambda _: None)
    rows = report["rows"]
    names = {r["observer"] for r in rows}
    assert {"diff", "fd*", "kf*", "fd", "kf"} <= names
    assert {r["sensor"] for r in rows} == {"gauss 0.0001", "16-bit"}
    best_fd = next(r for r in rows if r["observer"] == "fd*" and r["sensor"] == "gauss 0.0001")
    raw = next(r for r in rows if r["observer"] == "diff" and r["sensor"] == "gauss 0.0001")
    assert best_fd["rms_v_error"] < raw["rms_v_error"]
    assert all(r["cost_in_aba"] > 0 for r in rows)
    assert {g["robot"] for g in report["geometry"]} == {"cartpole", "pendulum", "planar_3r"}
    assert report["scaling"]["kf"]["points"] and math.isfinite(report["scaling"]["kf"]["exponent"])
    mism = {(r["observer"], r["scenario"]): r for r in report["mismatch"]}
    assert {s for _, s in mism} == {"exact", "inertia5", "inertia20_payload", "friction"}
    assert {"ekf+d", "ekf~", "kf*", "fd*"} <= {o for o, _ in mism}
    # a model-free filter does not use the model: its error barely moves with the truth's model
    assert mism[("kf*", "friction")]["rms_v_error"] < 3 * mism[("kf*", "exact")]["rms_v_error"]
    text = format_bench(report)
    assert "**cartpole** (nv = 2), gauss 0.0001" in text and "Cost scaling" in text
    assert "**Model mismatch, cartpole**" in text


def test_bench_command_is_registered(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["bench", "--help"])
    assert "--quick" in capsys.readouterr().out


def test_bench_on_a_dask_cluster_gives_the_serial_accuracy_numbers() -> None:
    pytest.importorskip("dask.distributed")
    cfg = BenchConfig(
        robots=("pendulum",),
        mismatch_robots=("pendulum",),
        cost_robots=(),
        duration=0.05,
        timing_updates=20,
    )
    serial = run_bench(cfg, log=lambda _: None)
    lines: list[str] = []
    dask = run_bench(cfg, log=lines.append, workers=2, processes=False)
    timing = ("time_per_update", "cost_in_aba", "time_in_loop")

    def accuracy(report):
        return [{k: v for k, v in r.items() if k not in timing} for r in report["rows"]]

    assert accuracy(dask) == accuracy(serial) and len(serial["rows"]) > 10
    assert dask["mismatch"] == serial["mismatch"] and len(serial["mismatch"]) == 4 * (
        len({r["observer"] for r in serial["mismatch"]})
    )
    assert dask["scaling"].keys() == serial["scaling"].keys()
    assert all(r["cost_in_aba"] > 0 for r in dask["rows"])
    assert len(lines) == 1 + 2 + 4 + 1  # timed, two sensors, four scenarios, geometry


def test_a_failed_bench_task_fails_alone_and_is_reported(monkeypatch) -> None:
    """Found by a sweep: the README says a task that raises fails alone, but one failed
    task made run_bench raise and discard every other result."""
    import pinobs.evaluation.bench as bench

    real = bench.run_bench_task

    def flaky(task):
        if (task.kind, task.robot, task.variant) == ("mismatch", "pendulum", "friction"):
            raise RuntimeError("a worker lost its node")
        return real(task)

    monkeypatch.setattr(bench, "run_bench_task", flaky)
    cfg = BenchConfig(
        robots=("pendulum",),
        mismatch_robots=("pendulum", "cartpole"),
        cost_robots=(),
        duration=0.05,
        timing_updates=20,
    )
    lines: list[str] = []
    report = run_bench(cfg, log=lines.append)
    assert report["failed"] == [
        {
            "kind": "mismatch",
            "robot": "pendulum",
            "variant": "friction",
            "error": "RuntimeError: a worker lost its node",
        }
    ]
    assert "  failed: mismatch on pendulum friction: RuntimeError: a worker lost its node" in lines
    assert len(report["rows"]) > 10 and report["geometry"]
    ran = {(r["robot"], r["scenario"]) for r in report["mismatch"]}
    assert ran == {(r, s) for r in ("pendulum", "cartpole") for s in MISMATCH_SCENARIOS} - {
        ("pendulum", "friction")
    }
    text = format_bench(report)  # was (had it got here): KeyError on the missing cell
    assert "**Failed tasks**" in text and "- mismatch on pendulum friction: RuntimeError" in text
    pendulum = text.split("**Model mismatch, pendulum**")[1].split("**Model mismatch")[0]
    assert re.search(r"\| `kf\*` \| [^|]+ \| [^|]+ \| [^|]+ \| - \|", pendulum)  # friction: -


def test_bench_command_exits_1_when_a_task_failed(tmp_path, capsys, monkeypatch) -> None:
    import pinobs.evaluation.bench as bench

    failed = [{"kind": "geometry", "robot": "ur5", "variant": "", "error": "RuntimeError: x"}]
    report = {"rows": [], "mismatch": [], "scaling": {}, "geometry": [], "failed": failed}
    report |= {"seconds": 1.0, "machine": {"processor": "p", "system": "s"}}
    monkeypatch.setattr(bench, "run_bench", lambda cfg, **kw: report)
    assert main(["bench", "--quick", "--json", str(tmp_path / "b.json")]) == 1  # was: raised
    captured = capsys.readouterr()
    assert "- geometry on ur5: RuntimeError: x" in captured.out
    assert "pinobs: error: 1 of " in captured.err and (tmp_path / "b.json").exists()

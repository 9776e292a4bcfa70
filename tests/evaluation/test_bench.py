"""The benchmark harness on a tiny configuration (the full run is `pinobs bench`)."""

from __future__ import annotations

import math

import pytest

from pinobs.cli import main
from pinobs.evaluation.bench import BenchConfig, format_bench, run_bench, scaling_exponent


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

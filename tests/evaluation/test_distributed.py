"""Many runs on Dask: results in task order, a bad task fails alone, the sweep table."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("dask.distributed")
pd = pytest.importorskip("pandas")

from pinobs.evaluation.distributed import (  # noqa: E402
    run_sweep_task,
    run_tasks,
    sweep,
    sweep_tasks,
    write_sweep,
)


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
    # the same run in this process gives the same numbers (a seeded, deterministic task)
    direct = {r["observer"]: r["rms_v_error"] for r in run_sweep_task(tasks[0])}
    first = good[good["seed"] == 0].set_index("observer")["rms_v_error"].to_dict()
    assert first == direct
    paths = write_sweep(table, tmp_path)
    assert paths[0].exists() and paths[0].stat().st_size > 0

"""``adaptive``'s synchronous learning: its windows and solves on one BLAS thread, the rest of
the update on the caller's threads (issue 39: the limit cost every update 11–12 µs)."""

from __future__ import annotations

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import pinobs
from pinobs.observers import adaptive_fused, adaptive_learner, make_observer
from pinobs.simulation import Sensor
from tests.conftest import cached_robot


def _threads() -> set[int]:
    return {d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas"}


def test_synchronous_learning_runs_its_jobs_on_one_blas_thread_and_the_update_on_the_callers(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    robot = cached_robot("ur5")
    res = pinobs.simulate(robot, [], duration=0.7, sensor=Sensor(1000.0, 1e-4), seed=5)
    ob = make_observer("adaptive", robot, rate=1000.0, noise_std=1e-4)
    assert not ob.uses_blas  # compiled filter, bank and blend: no BLAS call of their own
    seen: dict[str, list[set[int]]] = {"add_window": [], "solve": [], "step": []}
    identifier = adaptive_learner._Identifier
    for job in ("add_window", "solve"):
        original = getattr(identifier, job)

        def spy(self, *args, job=job, original=original):
            seen[job].append(_threads())
            return original(self, *args)

        monkeypatch.setattr(identifier, job, spy)

    def spied(step):  # type: ignore[no-untyped-def]
        def spy(*args):  # type: ignore[no-untyped-def]
            if len(seen["step"]) < 3:  # (threadpool_info scans the libraries: a few suffice)
                seen["step"].append(_threads())
            return step(*args)

        return spy

    monkeypatch.setattr(type(ob), "step", spied(type(ob).step))
    # (a plain update's step: the fused update's, pinobs.observers.adaptive_fused)
    monkeypatch.setattr(adaptive_fused, "fused_step", spied(adaptive_fused.fused_step))
    with threadpool_limits(2, user_api="blas"):
        ob.reset(res.t[0], res.q[0], None, res.tau[0])
        seen["step"].clear()  # (reset's own step, thrown away, runs under reset's limit)
        for k in range(1, res.t.size):
            ob.update(res.t[k], res.q_meas[k], res.tau[k])
        assert _threads() == {2}  # the caller's count, back after every job
    assert ob.consistency().details["solves"] >= 1
    assert len(seen["add_window"]) >= 2 and len(seen["solve"]) >= 1
    assert all(s == {1} for job in ("add_window", "solve") for s in seen[job])
    assert seen["step"] == [{2}] * 3

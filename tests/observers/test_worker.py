"""The worker process behind ``adaptive``'s background learning (:mod:`pinobs.observers.worker`)."""

from __future__ import annotations

import gc
import time

import numpy as np
import pytest

from pinobs.observers.adaptive_learner import PRELOAD
from pinobs.observers.worker import Worker as _Worker


def Worker(*args):  # the fork server started as adaptive starts it (whichever test is first)
    return _Worker(*args, preload=PRELOAD)


def _start(offset: float) -> dict:
    return {"offset": offset, "seen": []}


def _add(state: dict, x: float) -> float:
    state["seen"].append(x)
    return x + state["offset"]


def _seen(state: dict) -> list:
    return list(state["seen"])


def _fail(state: dict, message: str) -> None:
    raise ValueError(message)


def _sleep(state: dict, seconds: float) -> float:
    time.sleep(seconds)
    return seconds


def _size(state: dict, a: np.ndarray) -> int:
    return int(a.size)


def _bad_start() -> None:
    raise RuntimeError("no regressor here")


def _slow_start(seconds: float) -> dict:
    time.sleep(seconds)
    return {"offset": 0.0, "seen": []}


def test_jobs_run_in_order_on_the_state_init_made() -> None:
    w = Worker(_start, 10.0)
    jobs = [w.submit(_add, float(i)) for i in range(5)]
    assert [j.result() for j in jobs] == [10.0, 11.0, 12.0, 13.0, 14.0]
    assert w.submit(_seen).result() == [0.0, 1.0, 2.0, 3.0, 4.0]
    w.close()


def test_a_jobs_exception_is_raised_by_its_result_and_the_worker_goes_on() -> None:
    w = Worker(_start, 0.0)
    bad, good = w.submit(_fail, "rows not finite"), w.submit(_add, 2.0)
    with pytest.raises(ValueError, match="rows not finite"):
        bad.result()
    assert good.result() == 2.0
    w.close()


def test_submit_never_waits_for_a_worker_that_is_behind() -> None:
    """Jobs beyond what the pipe holds wait in the outbox, written as the worker catches up."""
    w = Worker(_start, 0.0)
    slow = w.submit(_sleep, 0.5)
    big = np.zeros(w.capacity * 4096 // 8 // 3)  # a third of the pipe each
    t0 = time.perf_counter()
    jobs = [w.submit(_size, big) for _ in range(8)]
    assert time.perf_counter() - t0 < 0.25  # (writing 8 × 1/3 of the pipe would block)
    assert w.outbox and not slow.done()
    assert slow.result() == 0.5
    assert [j.result() for j in jobs] == [big.size] * 8
    assert not w.outbox
    w.close()


def test_done_never_waits() -> None:
    w = Worker(_start, 0.0)
    job = w.submit(_sleep, 0.3)
    t0 = time.perf_counter()
    assert not job.done()
    assert time.perf_counter() - t0 < 0.1
    assert job.result() == 0.3 and job.done()
    w.close()


def test_the_process_ends_when_the_worker_is_dropped() -> None:
    w = Worker(_start, 0.0)
    assert w.started()
    process = w.process
    assert process.is_alive()
    del w
    gc.collect()
    process.join(timeout=5.0)
    assert not process.is_alive()


def test_the_constructor_does_not_wait_for_the_start_and_jobs_wait_in_the_pipe() -> None:
    """Issue 39: the worker starts (its init here takes 0.5 s) while the caller goes on; a
    job submitted meanwhile is written at once and run when the worker is ready, its
    result read only then (``done`` never waits)."""
    Worker(_start, 0.0).close()  # (the fork server up: what is timed is the worker's start)
    t0 = time.perf_counter()
    w = Worker(_slow_start, 0.5)
    job = w.submit(_add, 3.0)
    assert time.perf_counter() - t0 < 0.25
    assert not w.started(wait=False) and not job.done() and not w.outbox
    assert job.result() == 3.0 and w.started()
    assert time.perf_counter() - t0 >= 0.5
    w.close()


def test_a_worker_dropped_while_it_starts_ends() -> None:
    w = Worker(_slow_start, 0.3)
    process = w.process
    del w
    gc.collect()
    process.join(timeout=5.0)
    assert process.exitcode is not None and not process.is_alive()


def test_an_init_error_is_raised_by_started_and_by_the_next_submit_or_result() -> None:
    w = Worker(_bad_start)  # (not waited for: raised later)
    with pytest.raises(RuntimeError, match="no regressor here"):
        w.started()
    with pytest.raises(RuntimeError, match="no regressor here"):
        w.submit(_add, 1.0)
    w = Worker(_bad_start)
    job = w.submit(_add, 1.0)
    with pytest.raises(RuntimeError, match="no regressor here"):
        job.result()

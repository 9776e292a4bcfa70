"""BLAS on one thread inside ``update`` and ``reset``, the caller's thread counts untouched (issue 39)."""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import pinobs
from pinobs.errors import TimestampError, UnsupportedRobotError
from pinobs.observers import Observer, make_observer, observer_names
from pinobs.observers.blas import blas_libraries, one_blas_thread
from pinobs.simulation import Sensor
from tests.conftest import cached_robot


def _blas_threads() -> list[tuple[str, int]]:
    return sorted((d["filepath"], d["num_threads"]) for d in threadpool_info())


@pytest.fixture(scope="module")
def ur5_run():
    robot = cached_robot("ur5")
    res = pinobs.simulate(robot, [], duration=0.3, sensor=Sensor(1000.0, 1e-4), seed=5)
    return robot, res


def _feed(ob: Observer, res, limited: bool = True) -> np.ndarray:
    ob.uses_blas = limited  # (on the instance: the limit on or off)
    ob.reset(res.t[0], res.q[0], None, res.tau[0])
    rows = []
    for k in range(1, res.t.size):
        e = ob.update(res.t[k], res.q_meas[k], res.tau[k])
        rows.append(np.concatenate([e.q, e.v]))
    return np.array(rows)


@pytest.mark.parametrize("threads", [1, 2, 3])
@pytest.mark.parametrize("name", ["kf", "ekf", "riemannian", "adaptive"])
def test_update_leaves_the_callers_blas_thread_counts_as_they_were(
    ur5_run, name: str, threads: int
) -> None:
    robot, res = ur5_run
    ob = make_observer(name, robot, rate=1000.0, noise_std=1e-4)
    with threadpool_limits(threads, user_api="blas"):
        before = _blas_threads()
        ob.reset(res.t[0], res.q[0], None, res.tau[0])
        assert _blas_threads() == before
        for k in range(1, 30):
            ob.update(res.t[k], res.q_meas[k], res.tau[k])
            assert _blas_threads() == before
    direct = {p.filepath for p in blas_libraries().openblas}
    assert {n for path, n in before if path in direct} == {threads}  # the caller's, kept


def test_make_observer_leaves_the_callers_blas_thread_counts_as_they_were(ur5_run) -> None:
    robot, _ = ur5_run
    with threadpool_limits(2, user_api="blas"):
        before = _blas_threads()
        for name in ("riemannian", "ekf", "adaptive"):
            make_observer(name, robot, rate=1000.0, noise_std=1e-4)
            assert _blas_threads() == before


def test_update_leaves_the_counts_as_they_were_when_it_raises(ur5_run) -> None:
    robot, res = ur5_run
    ob = make_observer("ekf", robot, rate=1000.0, noise_std=1e-4)
    with threadpool_limits(2, user_api="blas"):
        before = _blas_threads()
        ob.reset(res.t[0], res.q[0], None, res.tau[0])
        with pytest.raises(TimestampError, match="not after the previous"):
            ob.update(res.t[0], res.q_meas[1], res.tau[1])
        assert _blas_threads() == before


def test_blas_runs_on_one_thread_inside_update(ur5_run, monkeypatch) -> None:
    robot, res = ur5_run
    # kalman's paper form may call a BLAS (its NumPy step); ekf's, riemannian's and the default
    # kalman's compiled steps on a UR5 do not
    ob = make_observer("kalman", robot, rate=1000.0, noise_std=1e-4, form="paper")
    seen: list[set[int]] = []
    step = type(ob).step

    def spy(self, *args, **kwargs):
        seen.append({d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas"})
        return step(self, *args, **kwargs)

    monkeypatch.setattr(type(ob), "step", spy)
    with threadpool_limits(2, user_api="blas"):
        ob.reset(res.t[0], res.q[0], None, res.tau[0])
        for k in range(1, 4):
            ob.update(res.t[k], res.q_meas[k], res.tau[k])
        assert {d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas"} == {2}
    assert seen == [{1}] * 3


def test_a_family_without_blas_calls_updates_on_the_callers_threads(ur5_run, monkeypatch) -> None:
    """``uses_blas = False`` (``fd``): the limit is not entered, so it costs nothing per update;
    ``ekf``'s, ``riemannian``'s, ``kalman``'s, ``highgain``'s (its gain steady: from the
    start with ``gain_ramp=1``) and ``sliding``'s compiled steps on a UR5 neither; a family
    that may call a BLAS (``kalman``'s paper form: its NumPy step) runs its step on one
    thread.  ``ekf``'s and ``kalman``'s plain updates are done whole by their fused paths
    (``_update_fused``, before the limit; the step where it leaves an update): spied too."""
    robot, res = ur5_run
    cases = [(name, {}, {2}) for name in ("fd", "ekf", "riemannian", "kalman", "sliding")]
    cases += [("highgain", {"gain_ramp": 1.0}, {2}), ("kalman", {"form": "paper"}, {1})]
    for name, options, inside in cases:
        ob = make_observer(name, robot, rate=1000.0, noise_std=1e-4, **options)
        assert ob.uses_blas is (inside == {1})
        seen: list[set[int]] = []
        spied = ("step", "_update_fused") if ob._fused_path else ("step",)
        for method in spied:
            original = getattr(type(ob), method)

            def spy(self, *args, original=original, seen=seen, **kwargs):
                seen.append(
                    {d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas"}
                )
                return original(self, *args, **kwargs)

            monkeypatch.setattr(type(ob), method, spy)
        with threadpool_limits(2, user_api="blas"):
            ob.reset(res.t[0], res.q[0], None, res.tau[0])
            for k in range(1, 4):
                ob.update(res.t[k], res.q_meas[k], res.tau[k])
        # one a step (two where the fused path leaves an update to the base's), each inside
        assert 3 <= len(seen) <= 3 * len(spied) and set(map(frozenset, seen)) == {
            frozenset(inside)
        }, (name, options, seen)


@pytest.mark.parametrize("name", observer_names())
def test_estimates_are_bit_identical_with_and_without_the_limit(ur5_run, name: str) -> None:
    robot, res = ur5_run
    try:
        make_observer(name, robot, rate=1000.0)
    except UnsupportedRobotError:
        pytest.skip(f"{name} does not run on a UR5")
    with threadpool_limits(2, user_api="blas"):
        limited = _feed(make_observer(name, robot, rate=1000.0, noise_std=1e-4), res)
        free = _feed(make_observer(name, robot, rate=1000.0, noise_std=1e-4), res, limited=False)
    assert np.isfinite(limited).all()
    np.testing.assert_array_equal(limited, free)


@pytest.mark.slow
def test_talos_ekf_is_bit_identical_where_two_threads_would_split_its_products() -> None:
    """talos ``ekf``'s 76² covariance products cross OpenBLAS's threading thresholds: measured
    21× slower with two threads on a loaded 2-core machine, and bit-identical."""
    robot = cached_robot("talos")
    res = pinobs.simulate(robot, [], duration=0.05, sensor=Sensor(1000.0, 1e-4), seed=1)
    with threadpool_limits(2, user_api="blas"):
        limited = _feed(make_observer("ekf", robot, rate=1000.0, noise_std=1e-4), res)
        free = _feed(make_observer("ekf", robot, rate=1000.0, noise_std=1e-4), res, limited=False)
    np.testing.assert_array_equal(limited, free)


def test_a_nested_limited_call_leaves_the_outer_limit_in_place() -> None:
    inner_counts: list[list[int]] = []

    @one_blas_thread
    def inner() -> None:
        inner_counts.append([p.get_threads() for p in blas_libraries().openblas])

    @one_blas_thread
    def outer() -> list[int]:
        inner()
        return [p.get_threads() for p in blas_libraries().openblas]

    with threadpool_limits(2, user_api="blas"):
        assert outer() == [1] * len(blas_libraries().openblas)
        assert [p.get_threads() for p in blas_libraries().openblas] == [2] * len(
            blas_libraries().openblas
        )
    assert inner_counts == [[1] * len(blas_libraries().openblas)]


def test_every_loaded_blas_library_is_limited_one_way_or_the_other() -> None:
    libs = blas_libraries()
    direct = {p.filepath for p in libs.openblas}
    others = set() if libs.others is None else {d["filepath"] for d in libs.others.info()}
    loaded = {d["filepath"] for d in threadpool_info() if d["user_api"] == "blas"}
    assert loaded <= direct | others
    assert direct  # numpy's wheels ship OpenBLAS on pthreads: the direct path

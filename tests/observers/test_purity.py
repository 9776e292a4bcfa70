"""``step`` is pure for every family (issue 37): everything an observer learns lives in its state.

The protocol (:mod:`pinobs.observers.base`) promises ``step(state, dt, q, tau)`` returns a new
state and changes nothing else: stepping twice from the same state with the same inputs gives
identical states, and the observer object (every attribute, followed into the objects it
holds) is the same after as before.  Only working memory may change: Pinocchio's ``pin.Data``,
buffers named ``_scratch*`` and memo caches named ``*cache*`` (their content is overwritten by
every call that uses them, never read across calls).  Checked for every registered family, every
model-based one wrapped ``never_behind=True``, and ``adaptive`` in each learning mode, on a
committed state after 0.6 s of motion (``adaptive`` has solved by then), with a sample, without
one, and from a lost model-based filter (``adaptive`` restarts it, ``never_behind`` re-seeds it:
both were counted on the observer inside ``step`` before).
"""

from __future__ import annotations

from collections import deque
from functools import cache
from typing import Any

import numpy as np
import pinocchio as pin
import pytest

import pinobs
from pinobs.observers import make_observer, observer_class, observer_names
from pinobs.simulation import Sensor
from tests.conftest import cached_robot

CANDIDATE_ROBOTS = ("cartpole", "top", "rigid_body")
DURATION = 0.6  # [s]: adaptive's first solve is at 0.5 s


#: Working memory named otherwise: ``KFBank``'s compiled step writes its likelihood and gate
#: level into these and never reads them back (its gate is off, ``inf``: kf_bank.py, "step's
#: scratch (its likelihood and gate are not kept)").
def _working_memory(name: str) -> bool:
    return name.startswith("_scratch") or "cache" in name


def _leaf(x: Any) -> Any:
    """The image of a value with no parts (``None`` for anything else)."""
    if isinstance(x, (bool, int, str, bytes)):
        return x
    if isinstance(x, (float, np.generic)):
        return repr(x)
    if isinstance(x, np.ndarray):
        return ("array", x.shape, x.dtype.str, x.tobytes())
    if isinstance(x, pin.Data):
        return "pin.Data"
    return None


def _fingerprint(x: Any, seen: set[int]) -> Any:
    """A comparable image of ``x``: arrays by their bytes, pinobs objects by their attributes
    (working memory left out), containers item by item, anything else by identity."""
    leaf = _leaf(x)
    if leaf is not None or x is None:
        return leaf
    if id(x) in seen:
        return ("seen", type(x).__name__, id(x))
    seen.add(id(x))
    if isinstance(x, (tuple, list, deque)):
        return (type(x).__name__, [_fingerprint(y, seen) for y in x])
    if isinstance(x, dict):  # (vars(observer): its attributes)
        items = [(k, v) for k, v in x.items() if not _working_memory(str(k))]
        return ("dict", [(repr(k), _fingerprint(v, seen)) for k, v in items])
    if type(x).__module__.startswith("pinobs"):
        attrs = dict(getattr(x, "__dict__", {}))
        for slot in getattr(type(x), "__slots__", ()):
            if hasattr(x, slot):
                attrs[slot] = getattr(x, slot)
        kept = {k: v for k, v in attrs.items() if not _working_memory(k)}
        return (type(x).__name__, [(k, _fingerprint(v, seen)) for k, v in sorted(kept.items())])
    return ("object", type(x).__name__, id(x))


def fingerprint(x: Any) -> Any:
    return _fingerprint(x, set())


def _cases() -> list[tuple[str, dict[str, Any]]]:
    cases: list[tuple[str, dict[str, Any]]] = []
    for name in observer_names():
        cases.append((name, {}))
        if observer_class(name).uses_torque:
            cases.append((name, {"never_behind": True}))
    cases.append(("adaptive", {"learning": "background"}))
    cases.append(("adaptive", {"blend": False}))
    cases.append(("ekf", {"disturbance_psd": "auto"}))
    return cases


def _case_id(case: tuple[str, dict[str, Any]]) -> str:
    name, opts = case
    return "-".join([name, *(f"{k}={v}" for k, v in opts.items())])


@cache
def _motion(robot_name: str) -> pinobs.Result:
    robot = cached_robot(robot_name)
    return pinobs.simulate(
        robot, [], duration=DURATION, sensor=Sensor(rate=1000.0, noise_std=1e-4), seed=3
    )


def _committed(name: str, opts: dict[str, Any]) -> tuple[pinobs.Robot, Any, pinobs.Result]:
    """The observer built on the first candidate robot it accepts, run over the motion."""
    for robot_name in CANDIDATE_ROBOTS:
        robot = cached_robot(robot_name)
        try:
            ob = make_observer(name, robot, rate=1000.0, noise_std=1e-4, **opts)
        except pinobs.UnsupportedRobotError:
            continue
        res = _motion(robot_name)
        ob.reset(res.t[0], res.q[0], res.v[0], res.tau[0])
        for k in range(1, res.t.size - 1):
            ob.update(res.t[k], res.q_meas[k], res.tau[k])
        return robot, ob, res
    raise AssertionError(f"{name} accepts none of {CANDIDATE_ROBOTS}")


def _assert_pure_step(ob: Any, state: Any, dt: float, q: Any, tau: Any) -> Any:
    before = fingerprint(vars(ob))
    given = fingerprint(state)
    first = ob.step(state, dt, q, tau)
    after_first = fingerprint(vars(ob))
    second = ob.step(state, dt, q, tau)
    assert fingerprint(state) == given, "step changed the state it was given"
    assert after_first == before, "step changed the observer"
    assert fingerprint(vars(ob)) == before, "step changed the observer"
    assert fingerprint(first) == fingerprint(second), "two steps from one state differ"
    return first


@pytest.fixture(params=_cases(), ids=_case_id)
def committed(request) -> tuple[pinobs.Robot, Any, pinobs.Result]:
    name, opts = request.param
    return _committed(name, opts)


def test_step_is_pure_and_changes_nothing_of_the_observer(committed) -> None:
    _, ob, res = committed
    state, k = ob._state, res.t.size - 1
    dt = res.t[k] - res.t[k - 1]
    with np.errstate(all="ignore"):
        _assert_pure_step(ob, state, dt, res.q_meas[k], res.tau[k])
        _assert_pure_step(ob, state, dt, None, res.tau[k])
        _assert_pure_step(ob, state, 5 * dt, res.q_meas[k], res.tau[k])


def test_adaptive_has_learned_before_the_purity_check() -> None:
    """The states checked above carry a learned model or a validated nominal one: the check
    covers a learner past its first solve, not only the warm-up."""
    _, ob, _ = _committed("adaptive", {})
    assert ob.consistency().details["solves"] >= 1
    assert ob.regime != "warmup"


def _nan_v(filt: Any) -> Any:
    return filt._replace(v=np.full_like(filt.v, np.nan))


LOST = {  # (the family, its options): (the state with its model-based filter lost, the count)
    "adaptive": (
        ("adaptive", {}),
        lambda s: s._replace(ekf=_nan_v(s.ekf)),
        lambda ob: ob.restarts,
    ),
    "adaptive-never_behind": (
        ("adaptive", {"never_behind": True}),
        lambda s: s._replace(model=s.model._replace(ekf=_nan_v(s.model.ekf))),
        lambda ob: ob.model.restarts,
    ),
    "ekf-never_behind": (
        ("ekf", {"never_behind": True}),
        lambda s: s._replace(model=_nan_v(s.model)),
        lambda ob: ob.reseeds,
    ),
}


@pytest.mark.parametrize("case", list(LOST))
def test_restarting_a_lost_filter_in_step_is_pure_and_counted_only_once_committed(
    case: str,
) -> None:
    """A lost model-based filter (NaN velocity): ``adaptive`` restarts it on its bank,
    ``never_behind`` re-seeds it from the kf, inside ``step``.  Twice from the same state:
    the same new state, the observer unchanged; the counts (``restarts``, ``reseeds``) say
    it once the update that made it is committed, not before."""
    (name, opts), make_lost, counted = LOST[case]
    _, ob, res = _committed(name, opts)
    k = res.t.size - 1
    dt = res.t[k] - res.t[k - 1]
    lost = make_lost(ob._state)
    before = counted(ob)
    with np.errstate(all="ignore"):
        new = _assert_pure_step(ob, lost, dt, res.q_meas[k], res.tau[k])
    assert counted(ob) == before
    assert np.all(np.isfinite(ob.output(new)[1]))
    ob._state = lost  # the same step through update: committed, counted
    with np.errstate(all="ignore"):
        ob.update(res.t[k], res.q_meas[k], res.tau[k])
    assert counted(ob) == before + 1

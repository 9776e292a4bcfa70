"""The contract every registered observer keeps, through the public API only.

One suite, parametrised over the registry: input validation that names the
bad value and leaves the state untouched, dropped samples, the sampled-data
torque convention's bookkeeping, option validation.
"""

from __future__ import annotations

import numpy as np
import pytest

import pinobs
from pinobs.observers import observer_names
from pinobs.observers.registry import FAMILY_MODULES

# Each observer on the first of these robots it accepts.
CANDIDATE_ROBOTS = ("cartpole", "top", "rigid_body")


def _build(name: str, **options):
    last = None
    for robot_name in CANDIDATE_ROBOTS:
        robot = pinobs.load(robot_name)
        try:
            return robot, pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-4, **options)
        except pinobs.UnsupportedRobotError as exc:
            last = exc
    raise AssertionError(f"{name} accepts none of {CANDIDATE_ROBOTS}: {last}")


def _started(name: str):
    robot, ob = _build(name)
    rng = np.random.default_rng(0)
    q0 = robot.random_configuration(rng, scale=0.2)
    ob.reset(0.0, q0, np.zeros(robot.nv))
    for k in range(1, 6):
        ob.update(k * 1e-3, robot.integrate(q0, 1e-3 * k * np.ones(robot.nv)), np.zeros(robot.nv))
    return robot, ob, q0


def _snapshot(ob) -> tuple:
    e = ob.estimate
    return e.t, e.q.copy(), e.v.copy()


@pytest.fixture(params=observer_names())
def name(request) -> str:
    return request.param


def test_estimate_has_fixed_shapes_and_is_read_only(name: str) -> None:
    robot, ob, _ = _started(name)
    est = ob.estimate
    assert est.q.shape == (robot.nq,) and est.v.shape == (robot.nv,)
    with pytest.raises(ValueError, match="read-only"):
        est.v[0] = 1.0


def test_update_before_reset_raises(name: str) -> None:
    robot, ob = _build(name)
    with pytest.raises(pinobs.NotResetError, match="reset"):
        ob.update(0.001, robot.neutral())


@pytest.mark.parametrize(
    ("bad", "error", "match"),
    [
        ("short_q", pinobs.DimensionError, "q_meas must have shape"),
        ("nan_q", pinobs.NonFiniteError, "q_meas has non-finite entries"),
        ("short_tau", pinobs.DimensionError, "tau must have shape"),
        ("inf_tau", pinobs.NonFiniteError, "tau has non-finite entries"),
        ("same_time", pinobs.TimestampError, "not after the previous sample"),
        ("earlier_time", pinobs.TimestampError, "not after the previous sample"),
        ("nan_time", pinobs.TimestampError, "not finite"),
        ("text_q", pinobs.DimensionError, "numeric array"),
    ],
)
def test_bad_input_raises_a_valueerror_naming_it_and_changes_nothing(
    name: str, bad: str, error, match: str
) -> None:
    robot, ob, q0 = _started(name)
    _, twin, _ = _started(name)
    before = _snapshot(ob)
    t, q, tau = 0.006, robot.integrate(q0, 6e-3 * np.ones(robot.nv)), np.zeros(robot.nv)
    args = {
        "short_q": (t, q[:-1], tau),
        "nan_q": (t, np.where(np.arange(robot.nq) == 0, np.nan, q), tau),
        "short_tau": (t, q, tau[:-1]),
        "inf_tau": (t, q, np.full(robot.nv, np.inf)),
        "same_time": (0.005, q, tau),
        "earlier_time": (0.001, q, tau),
        "nan_time": (float("nan"), q, tau),
        "text_q": (t, "q", tau),
    }[bad]
    with pytest.raises(error, match=match) as info:
        ob.update(*args)
    assert isinstance(info.value, ValueError) and isinstance(info.value, pinobs.PinobsError)
    after = _snapshot(ob)
    assert after[0] == before[0]
    np.testing.assert_array_equal(after[1], before[1])
    np.testing.assert_array_equal(after[2], before[2])
    # the next valid sample continues exactly as if the bad one never came
    a = ob.update(t, q, tau)
    b = twin.update(t, q, tau)
    np.testing.assert_array_equal(a.q, b.q)
    np.testing.assert_array_equal(a.v, b.v)


def test_dropped_sample_propagates_and_keeps_going(name: str) -> None:
    robot, ob, q0 = _started(name)
    est = ob.update(0.006, None, np.zeros(robot.nv))
    assert est.t == 0.006 and np.all(np.isfinite(est.v))
    est = ob.update(0.007, robot.integrate(q0, 7e-3 * np.ones(robot.nv)), np.zeros(robot.nv))
    assert np.all(np.isfinite(est.q)) and np.all(np.isfinite(est.v))


def test_unknown_option_is_rejected_listing_the_accepted_ones(name: str) -> None:
    with pytest.raises(
        pinobs.OptionError, match=r"does not accept option.*'gain_typo'.*accepted"
    ) as info:
        _build(name, gain_typo=1.0)
    assert isinstance(info.value, TypeError)


@pytest.mark.parametrize(
    ("option", "value"),
    [("rate", -1.0), ("rate", 0.0), ("noise_std", -1e-3), ("rate", float("nan"))],
)
def test_sensor_hints_out_of_range_are_rejected(name: str, option: str, value: float) -> None:
    robot = pinobs.load("cartpole")
    kwargs = {"rate": 1000.0, "noise_std": 1e-4, option: value}
    with pytest.raises(pinobs.GainError, match=option):
        try:
            pinobs.make_observer(name, robot, **kwargs)
        except pinobs.UnsupportedRobotError:
            pinobs.make_observer(name, pinobs.load("top"), **kwargs)


def test_reset_validates_its_inputs(name: str) -> None:
    robot, ob = _build(name)
    with pytest.raises(pinobs.DimensionError, match="q0 must have shape"):
        ob.reset(0.0, np.zeros(robot.nq + 1))
    with pytest.raises(pinobs.DimensionError, match="v0 must have shape"):
        ob.reset(0.0, robot.neutral(), np.zeros(robot.nv + 1))


def test_unknown_observer_name_lists_the_registry() -> None:
    with pytest.raises(pinobs.UnknownNameError, match=r"unknown observer 'ekff'.*fd.*kf"):
        pinobs.make_observer("ekff", pinobs.load("cartpole"))


def test_registry_is_sorted_and_every_observer_has_a_summary() -> None:
    names = observer_names()
    assert names == sorted(names) and {"fd", "kf"} <= set(names)
    for n in names:
        assert pinobs.observers.observer_class(n).summary


def test_family_modules_lists_exactly_what_the_modules_register() -> None:
    """``make_observer`` imports a family's module on first use (``FAMILY_MODULES``): every
    module of the layer imported, the registry holds those names and no others, each
    registered by the module the table names."""
    import importlib
    import pkgutil

    for info in pkgutil.iter_modules(pinobs.observers.__path__):
        importlib.import_module(f"pinobs.observers.{info.name}")
    assert observer_names() == sorted(FAMILY_MODULES)
    for name, module in FAMILY_MODULES.items():
        assert pinobs.observers.observer_class(name).__module__ == module

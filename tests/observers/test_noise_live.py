"""σ from the data, live: an observer built without ``noise_std`` learns it, rebuilds, warns once.

The independent check: after the rebuild its estimates are exactly those of
the same observer built with the σ it found (the kept updates are replayed),
and that σ is the true one to a few percent.
"""

from __future__ import annotations

import pickle
import warnings

import numpy as np
import pytest

import pinobs
from pinobs.errors import NoiseWarning
from pinobs.observers.base import NOISE_WINDOW, observer_class

SIGMA = 1e-3
NOISE_DEPENDENT = ["kf", "ekf", "riemannian", "fd", "highgain", "sliding", "kalman"]


@pytest.fixture(scope="module")
def robot() -> pinobs.Robot:
    return pinobs.load("planar_3r")


@pytest.fixture(scope="module")
def run(robot: pinobs.Robot) -> pinobs.Result:
    return pinobs.simulate(robot, [], duration=1.6, sensor=pinobs.Sensor(1000.0, SIGMA), seed=3)


def _feed(ob: pinobs.Observer, res: pinobs.Result) -> np.ndarray:
    """Velocity estimates at ``res.t[2:]`` (the first sample, ``t[1]``, starts the observer)."""
    ob.reset(res.t[1], res.q_meas[1], tau0=res.tau[1])
    return np.array(
        [
            ob.update(t, q, tau).v
            for t, q, tau in zip(res.t[2:], res.q_meas[2:], res.tau[2:], strict=True)
        ]
    )


@pytest.mark.parametrize("name", NOISE_DEPENDENT)
def test_learns_sigma_warns_once_and_equals_the_given_sigma(
    robot: pinobs.Robot, run: pinobs.Result, name: str
) -> None:
    ob = pinobs.make_observer(name, robot, rate=1000.0)
    with pytest.warns(NoiseWarning, match="estimated σ") as caught:
        v_live = _feed(ob, run)
    assert len([w for w in caught if issubclass(w.category, NoiseWarning)]) == 1
    sigma = ob.noise_std
    assert sigma is not None and abs(sigma / SIGMA - 1.0) < 0.1
    given = pinobs.make_observer(name, robot, rate=1000.0, noise_std=sigma)
    v_given = _feed(given, run)
    k = int(np.searchsorted(run.t[2:], run.t[2] + NOISE_WINDOW - 1e-9))  # the rebuild's sample
    np.testing.assert_array_equal(v_live[k:], v_given[k:])
    assert not np.array_equal(v_live[: k - 1], v_given[: k - 1])  # the default σ before it


def test_noise_free_data_change_nothing(robot: pinobs.Robot) -> None:
    res = pinobs.simulate(robot, [], duration=1.3, sensor=pinobs.Sensor(1000.0, 0.0), seed=3)
    ob = pinobs.make_observer("ekf", robot, rate=1000.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _feed(ob, res)
    assert ob.noise_std is None


def test_explicit_gains_are_kept(robot: pinobs.Robot, run: pinobs.Result) -> None:
    ob = pinobs.make_observer("fd", robot, rate=1000.0, cutoff=20.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _feed(ob, run)
    assert ob.noise_std is None and ob.options["cutoff"] == 20.0


def test_given_sigma_and_sigma_free_families_keep_nothing(
    robot: pinobs.Robot, run: pinobs.Result
) -> None:
    given = pinobs.make_observer("ekf", robot, rate=1000.0, noise_std=SIGMA)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _feed(given, run)
    assert given._noise_samples is None
    # every family uses σ (in its gains, or in its NIS and outlier gate)
    assert all(observer_class(n).uses_noise_std for n in pinobs.observer_names())


@pytest.mark.parametrize("name", ["ii", "liegroup"])
def test_nis_only_families_learn_sigma_for_their_gate(name: str) -> None:
    """σ enters only their NIS: with the default 1e-6 on σ = 1e-3 data the gate would reject
    every other sample; after the first second they are the observer built with σ̂."""
    robot = pinobs.load("cartpole" if name == "ii" else "top")
    res = pinobs.simulate(robot, [], duration=1.6, sensor=pinobs.Sensor(1000.0, SIGMA), seed=3)
    ob = pinobs.make_observer(name, robot, rate=1000.0)
    with pytest.warns(NoiseWarning):
        v_live = _feed(ob, res)
    assert ob.noise_std is not None and abs(ob.noise_std / SIGMA - 1.0) < 0.15
    given = pinobs.make_observer(name, robot, rate=1000.0, noise_std=ob.noise_std)
    v_given = _feed(given, res)
    k = int(np.searchsorted(res.t[2:], res.t[2] + NOISE_WINDOW - 1e-9))
    np.testing.assert_array_equal(v_live[k:], v_given[k:])
    assert ob.consistency().gated == given.consistency().gated


def test_pickled_mid_window_resumes_identically(robot: pinobs.Robot, run: pinobs.Result) -> None:
    ob = pinobs.make_observer("kf", robot, rate=1000.0)
    ob.reset(run.t[1], run.q_meas[1], tau0=run.tau[1])
    half = 400
    for t, q, tau in zip(run.t[2:half], run.q_meas[2:half], run.tau[2:half], strict=True):
        ob.update(t, q, tau)
    clone = pickle.loads(pickle.dumps(ob))
    rest = list(zip(run.t[half:], run.q_meas[half:], run.tau[half:], strict=True))
    with pytest.warns(NoiseWarning):
        a = np.array([ob.update(*x).v for x in rest])
    with pytest.warns(NoiseWarning):
        b = np.array([clone.update(*x).v for x in rest])
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
    ("name", "robot_name"),
    [("ii", "cartpole"), ("liegroup", "top"), ("riemannian", "top")]
    + [(name, "cartpole") for name in ("ekf", "kf", "kalman")],
)
def test_the_sigma_a_family_uses_is_the_base_one(name: str, robot_name: str) -> None:
    """σ (``noise_std``, or the floor when none or 0 is given) and the NIS variance σ² are
    defined once, in the base, for every family."""
    from pinobs.observers.base import NOISE_FLOOR

    robot = pinobs.load(robot_name)  # one the family accepts
    for given, used in ((None, NOISE_FLOOR), (0.0, NOISE_FLOOR), (2e-4, 2e-4)):
        ob = pinobs.make_observer(name, robot, rate=1000.0, noise_std=given)
        assert ob.noise_std_used == used
        assert ob._sigma2 == used**2
        meas_std = getattr(getattr(ob, "gains", None), "meas_std", None)  # ekf, kf
        assert meas_std is None or meas_std == used

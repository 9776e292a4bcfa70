"""Random shapes, values and timestamps thrown at every registered observer (hypothesis).

The property: every call either returns a finite estimate of the right shape,
or raises a ``PinobsError`` (a ``ValueError`` for bad input, ``ObserverDiverged``
for a numerical failure) and leaves the observer's estimate exactly as it was.
No other exception escapes.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import pinobs
from pinobs.observers import observer_names

ROBOT_FOR = {}


def _observer(name: str):
    for robot_name in ("cartpole", "top", "rigid_body"):
        robot = pinobs.load(robot_name)
        try:
            return robot, pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-3)
        except pinobs.UnsupportedRobotError:
            continue
    raise AssertionError(name)


Q_KINDS = [
    "valid",
    "valid",
    "valid",
    "none",
    "short",
    "long",
    "nan",
    "inf",
    "huge",
    "off_manifold",
    "matrix",
]
TAU_KINDS = ["zero", "random", "none", "short", "nan", "huge"]
DT_KINDS = ["normal", "normal", "normal", "tiny", "gap", "zero", "negative", "nan"]

call = st.tuples(
    st.sampled_from(DT_KINDS),
    st.sampled_from(Q_KINDS),
    st.sampled_from(TAU_KINDS),
    st.integers(0, 2**31 - 1),
)


def _args(robot, t_prev: float, q_true: np.ndarray, kinds) -> tuple:
    dt_kind, q_kind, tau_kind, seed = kinds
    rng = np.random.default_rng(seed)
    dt = {"normal": 1e-3, "tiny": 1e-9, "gap": 0.05, "zero": 0.0, "negative": -1e-3, "nan": np.nan}[
        dt_kind
    ]
    q_ok = robot.integrate(q_true, rng.normal(0, 1e-3, robot.nv))
    q = {
        "valid": q_ok,
        "none": None,
        "short": q_ok[:-1],
        "long": np.append(q_ok, 0.0),
        "nan": np.where(rng.random(robot.nq) < 0.5, np.nan, q_ok),
        "inf": np.full(robot.nq, np.inf),
        "huge": q_ok + (1e300 if robot.is_vector_space else 0.0),
        "off_manifold": q_ok * (1.0 if robot.is_vector_space else 3.0)
        + (0.0 if not robot.is_vector_space else 0.5),
        "matrix": np.tile(q_ok, (2, 1)),
    }[q_kind]
    tau = {
        "zero": np.zeros(robot.nv),
        "random": rng.normal(0, 1.0, robot.nv),
        "none": None,
        "short": np.zeros(robot.nv - 1),
        "nan": np.full(robot.nv, np.nan),
        "huge": np.full(robot.nv, 1e200),
    }[tau_kind]
    return t_prev + dt, q, tau


@pytest.mark.parametrize("name", observer_names())
@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(calls=st.lists(call, min_size=1, max_size=12))
def test_every_call_returns_a_finite_estimate_or_raises_a_pinobs_error_and_changes_nothing(
    name: str, calls
) -> None:
    robot, ob = _observer(name)
    q_true = robot.neutral()
    ob.reset(0.0, q_true)
    for kinds in calls:
        before = ob.estimate
        t, q, tau = _args(robot, before.t, q_true, kinds)
        try:
            with np.errstate(all="ignore"):
                est = ob.update(t, q, tau)
        except pinobs.PinobsError as exc:
            assert isinstance(exc, ValueError | pinobs.ObserverDiverged)
            after = ob.estimate
            assert after.t == before.t
            np.testing.assert_array_equal(after.q, before.q)
            np.testing.assert_array_equal(after.v, before.v)
            continue
        assert est.q.shape == (robot.nq,) and est.v.shape == (robot.nv,)
        assert np.all(np.isfinite(est.q)) and np.all(np.isfinite(est.v))
        assert est.t == t

"""``kf``'s plain ``"auto"`` update in one compiled call (``pinobs.observers.kf_fused``, issue
39): the same bits and the same errors as the base's own path, which it leaves every update
it does not take."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import pinobs
from pinobs.errors import NonFiniteError, TimestampError
from pinobs.observers.kf_fused import _SPAN, _SPLIT
from tests.conftest import varied_samples


def _pair(robot: pinobs.Robot) -> tuple[pinobs.Observer, pinobs.Observer]:
    fused, base = (pinobs.make_observer("kf", robot, rate=1000.0, noise_std=1e-4) for _ in "ab")
    base._fused_path = False  # the base's own path
    assert fused._fused_path
    return fused, base


def _same(a: pinobs.Observer, b: pinobs.Observer) -> bool:
    return (
        a._state.x.tobytes() == b._state.x.tobytes()
        and a._state.jerk.tobytes() == b._state.jerk.tobytes()
        and (a._state.shape, a._state.n, a._state.gate)
        == (b._state.shape, b._state.n, b._state.gate)
        and a._tau.tobytes() == b._tau.tobytes()
        and list(a._nis) == list(b._nis)
        and a._gated == b._gated
        and a._t == b._t
    )


def test_the_fused_update_gives_the_base_paths_bits() -> None:
    """Over a run with dropped samples, an outlier, no torque now and then, float and NumPy
    times, strided and read-only samples: the same estimates, state, held torque and NIS."""
    robot = pinobs.load("ur5")
    sim = pinobs.simulate(
        robot, [], duration=0.6, sensor=pinobs.Sensor(rate=1000.0, noise_std=1e-4), seed=1
    )
    fused, base = _pair(robot)
    for ob in (fused, base):
        ob.reset(sim.t[0], sim.q[0], None, sim.tau[0])
    for _, t, q, tau in varied_samples(sim, outlier_at=300, outlier=lambda q: q + 0.3):
        a, b = fused.update(t, q, tau), base.update(t, q, tau)
        assert a.q.tobytes() == b.q.tobytes() and a.v.tobytes() == b.v.tobytes()
        assert (a.t, a.nis, a.gated) == (b.t, b.nis, b.gated)
        assert not a.q.flags.writeable and not a.v.flags.writeable
    assert _same(fused, base) and fused._gated >= 1


@pytest.mark.parametrize(
    ("change", "error"),
    [
        (lambda t, q, tau: (t, np.where(np.arange(q.size) == 2, np.nan, q), tau), NonFiniteError),
        (lambda t, q, tau: (t, q, 1e12 * np.ones_like(tau)), NonFiniteError),
        (lambda t, q, tau: (t - 5e-3, q, tau), TimestampError),
        (lambda t, q, tau: (np.nan, q, tau), TimestampError),
    ],
)
def test_what_the_fused_update_does_not_take_the_base_refuses_as_before(
    change: object, error: type[Exception]
) -> None:
    """A non-finite sample, an absurd torque, a time not after the last: the base's error,
    the observer as it was (then the same updates as the base's path)."""
    robot = pinobs.load("ur5")
    fused, base = _pair(robot)
    q0 = robot.neutral()
    for ob in (fused, base):
        ob.reset(0.0, q0)
        for k in range(1, 30):
            ob.update(k * 1e-3, q0 + 1e-4 * np.sin(k + np.arange(robot.nq)), np.ones(robot.nv))
    before = pickle.dumps(fused._state)
    for ob in (fused, base):
        with pytest.raises(error):
            ob.update(*change(30e-3, q0.copy(), np.ones(robot.nv)))  # type: ignore[operator]
    assert pickle.dumps(fused._state) == before and _same(fused, base)
    a, b = fused.update(30e-3, q0, None), base.update(30e-3, q0, None)
    assert a.v.tobytes() == b.v.tobytes() and _same(fused, base)


def test_a_pickled_kf_resumes_with_its_fused_update() -> None:
    """Pickled mid-run (the compiled code is not pickled: loaded again), the copy goes on as
    the original, by the fused path."""
    robot = pinobs.load("ur5")
    ob = pinobs.make_observer("kf", robot, rate=1000.0, noise_std=1e-4)
    q0 = robot.neutral()
    ob.reset(0.0, q0)
    for k in range(1, 30):
        ob.update(k * 1e-3, q0 + 1e-4 * np.cos(k + np.arange(robot.nq)))
    clone = pickle.loads(pickle.dumps(ob))
    assert clone.auto_bank.fused is not None and clone._fused_path
    for k in range(30, 60):
        q = q0 + 1e-4 * np.cos(k + np.arange(robot.nq))
        a, b = ob.update(k * 1e-3, q), clone.update(k * 1e-3, q)
        assert a.v.tobytes() == b.v.tobytes() and a.nis == b.nis


def test_the_fused_update_follows_a_period_learnt_from_the_intervals() -> None:
    """No ``rate``: the base learns the period from the first intervals, and the fused update's
    copy of its sub-step and pause limits follows (``ConstantAccelerationKF._set_period``);
    over a gap of five periods and a pause of 1.5 s, with dropped samples, the base's bits,
    and some updates taken by the fused path."""
    robot = pinobs.load("ur5")
    sim = pinobs.simulate(
        robot, [], duration=1.0, sensor=pinobs.Sensor(rate=1000.0, noise_std=1e-4), seed=4
    )
    t = sim.t.copy()
    t[500:] += 4e-3  # a gap: sub-steps
    t[800:] += 1.5  # a pause: a restart
    fused, base = (pinobs.make_observer("kf", robot, noise_std=1e-4) for _ in "ab")
    base._fused_path = False
    taken: list[bool] = []
    own = fused._update_fused

    def counted(*args: object) -> object:
        estimate = own(*args)  # type: ignore[arg-type]
        taken.append(estimate is not None)
        return estimate

    fused._update_fused = counted  # type: ignore[method-assign]
    for ob in (fused, base):
        ob.reset(t[0], sim.q[0])
    for k in range(1, t.size):
        q = None if k % 9 == 0 else sim.q_meas[k]
        a, b = fused.update(float(t[k]), q, sim.tau[k]), base.update(float(t[k]), q, sim.tau[k])
        assert a.v.tobytes() == b.v.tobytes() and (a.nis, a.gated) == (b.nis, b.gated)
    assert _same(fused, base)
    assert 0.9 * len(taken) < sum(taken) < len(taken)  # (not while the period is learnt, a gap)
    assert (fused._work[_SPLIT], fused._work[_SPAN]) == (fused._split, fused._span)
    assert fused._split == pytest.approx(3e-3) and fused._span == pytest.approx(0.1)


def test_the_fused_update_works_in_place_and_its_estimates_and_states_stay_as_given() -> None:
    """The fused update writes the state, count, gate and torque held into the filter's own
    array (no AutoState built per update: one only when the state is read); an estimate or a
    state read between updates is not written by the updates after it."""
    robot = pinobs.load("ur5")
    sim = pinobs.simulate(
        robot, [], duration=0.2, sensor=pinobs.Sensor(rate=1000.0, noise_std=1e-4), seed=2
    )
    fused, base = _pair(robot)
    for ob in (fused, base):
        ob.reset(sim.t[0], sim.q[0], None, sim.tau[0])
    kept: list[tuple[pinobs.Estimate, bytes, bytes]] = []
    states = []
    work = fused._work
    for k in range(1, sim.t.size):
        q = None if k % 17 == 0 else sim.q_meas[k]
        a, b = fused.update(sim.t[k], q, sim.tau[k]), base.update(sim.t[k], q, sim.tau[k])
        assert fused._work is work and fused._live and fused._stale  # (the state in _work)
        assert a.v.tobytes() == b.v.tobytes() and a.nis == b.nis
        kept.append((a, a.q.tobytes(), a.v.tobytes()))
        if k % 50 == 0:  # read: built once, then kept as it is
            state = fused._state
            assert fused._state is state and not fused._stale
            states.append((state, state.x.tobytes(), state.n, state.gate))
    assert all(e.q.tobytes() == q and e.v.tobytes() == v for e, q, v in kept)
    assert all(not e.q.flags.writeable and not e.v.flags.writeable for e, _, _ in kept)
    assert len({id(e.q.base) for e, _, _ in kept}) == len(kept)  # (a new array each)
    assert all(s.x.tobytes() == x and (s.n, s.gate) == (n, g) for s, x, n, g in states)
    assert _same(fused, base)

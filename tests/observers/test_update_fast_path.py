"""``Observer.update``'s fast input path (issue 39) against its full checks.

A float time and float64 arrays of the right shape are checked by a cheaper path
(a Python sum for finiteness, ``±`` the smallest joint's torque bound or each joint's
own, unit-norm blocks of ``q`` normalised); anything else goes through the full checks.  Both must give the same estimates bit for
bit, the same errors, and no aliasing of the caller's buffers or of an estimate
the caller kept.
"""

from __future__ import annotations

import numpy as np
import pytest

import pinobs
from pinobs.observers import observer_names


def _pair(name: str, *robot_names: str):
    """Two observers started alike on a slow motion, on the first of ``robot_names`` the
    family accepts, and the samples that continue it."""
    for robot_name in robot_names:
        robot = pinobs.load(robot_name)
        try:
            pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-4)
            break
        except pinobs.UnsupportedRobotError:
            continue
    obs = []
    for _ in range(2):
        ob = pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-4)
        ob.reset(0.0, robot.neutral(), np.zeros(robot.nv), robot.gravity(robot.neutral()))
        obs.append(ob)
    ts = [1e-3 * k for k in range(1, 40)]
    qs = [robot.integrate(robot.neutral(), 0.3 * t * np.ones(robot.nv)) for t in ts]
    return robot, obs, ts, qs


@pytest.mark.parametrize("name", observer_names())
def test_fast_and_full_checks_give_the_same_bits(name: str) -> None:
    """Arrays and floats (fast path) against lists, ints-as-float64 scalars (full checks)."""
    robot, (fast, full), ts, qs = _pair(name, "cartpole", "top")  # top: a quaternion
    tau = robot.gravity(robot.neutral()) + 0.5
    for k, (t, q) in enumerate(zip(ts, qs, strict=True)):
        q_in = None if k % 7 == 3 else q
        a = fast.update(t, q_in, tau)
        b = full.update(np.float64(t), None if q_in is None else q.tolist(), tau.tolist())
        assert a.t == b.t and type(a.t) is float and type(b.t) is float
        assert a.q.tobytes() == b.q.tobytes() and a.v.tobytes() == b.v.tobytes()
        assert a.nis == b.nis and a.gated == b.gated


@pytest.mark.parametrize("name", ["kf", "ekf", "riemannian"])
def test_torque_between_the_smallest_and_its_own_bound_is_accepted(name: str) -> None:
    """UR5: joint 0's bound is 15000 N·m, the wrist's 2800 (the fast path's floor): 5000 N·m
    on joint 0 leaves the fast path and is accepted as before; 20000 is refused; so is any
    non-finite entry, first or last, named as the full check names it."""
    robot, (ob, twin), ts, qs = _pair(name, "ur5")
    tau = np.zeros(robot.nv)
    tau[0] = 5000.0
    a = ob.update(ts[0], qs[0], tau)
    b = twin.update(ts[0], qs[0].tolist(), tau.tolist())
    assert a.v.tobytes() == b.v.tobytes()
    tau[0] = 20000.0
    with pytest.raises(pinobs.NonFiniteError, match=r"tau\[0\] = 20000 is beyond"):
        ob.update(ts[1], qs[1], tau)
    for i in (0, robot.nv - 1):
        for bad in (np.nan, np.inf, -np.inf):
            x = np.zeros(robot.nv)
            x[i] = bad
            with pytest.raises(pinobs.NonFiniteError, match=rf"tau has non-finite .*\[{i}\]"):
                ob.update(ts[1], qs[1], x)
            y = qs[1].copy()
            y[i] = bad
            with pytest.raises(pinobs.NonFiniteError, match=rf"q_meas has non-finite .*\[{i}\]"):
                ob.update(ts[1], y, np.zeros(robot.nv))
    with pytest.raises(pinobs.DimensionError, match=r"q_meas must have shape \(6,\)"):
        ob.update(ts[1], qs[1][None, :], np.zeros(robot.nv))
    with pytest.raises(pinobs.DimensionError, match=r"tau must have shape \(6,\)"):
        ob.update(ts[1], qs[1], np.zeros((robot.nv, 1)))
    with pytest.raises(pinobs.TimestampError, match="not after the previous sample"):
        ob.update(ts[0], qs[1], np.zeros(robot.nv))
    with pytest.raises(pinobs.TimestampError, match="not finite"):
        ob.update(np.inf, qs[1], np.zeros(robot.nv))
    a = ob.update(ts[1], qs[1], np.zeros(robot.nv))  # the refusals changed nothing
    b = twin.update(ts[1], qs[1], np.zeros(robot.nv))
    assert a.q.tobytes() == b.q.tobytes() and a.v.tobytes() == b.v.tobytes()


@pytest.mark.parametrize("name", ["kf", "ekf", "riemannian", "adaptive"])
def test_reused_input_buffers_and_kept_estimates_are_not_aliased(name: str) -> None:
    """A loop that writes each sample into the same buffers, and keeps every estimate: the
    estimates are those of fresh arrays, and none changes once returned."""
    robot, (ob, twin), ts, qs = _pair(name, "ur5")
    q_buf, tau_buf = np.empty(robot.nq), np.empty(robot.nv)
    kept, copies = [], []
    for t, q in zip(ts, qs, strict=True):
        q_buf[:] = q
        tau_buf[:] = robot.gravity(q)
        e = ob.update(t, q_buf, tau_buf)
        f = twin.update(t, q.copy(), robot.gravity(q))
        q_buf[:] = np.nan  # the caller's buffers scribbled on after the call
        tau_buf[:] = 1e3
        assert e.q.tobytes() == f.q.tobytes() and e.v.tobytes() == f.v.tobytes()
        kept.append(e)
        copies.append((e.q.copy(), e.v.copy()))
    for e, (q, v) in zip(kept, copies, strict=True):
        assert e.q.tobytes() == q.tobytes() and e.v.tobytes() == v.tobytes()
        assert not e.q.flags.writeable and not e.v.flags.writeable


@pytest.mark.parametrize("name", ["ekf", "riemannian"])
def test_a_quaternion_off_unit_norm_is_normalised_or_refused_as_by_the_full_check(
    name: str,
) -> None:
    """go1 (free-flyer): a quaternion 1e-9 off unit norm is normalised by the fast path to the
    bits of ``check_configuration`` (the same estimates as from a list); one 1e-2 off is
    refused with its message, and leaves the observer as it was."""
    robot, (fast, full), ts, qs = _pair(name, "go1")
    for k, (t, q) in enumerate(zip(ts[:10], qs[:10], strict=True)):
        q = q.copy()
        q[3:7] *= 1.0 + 1e-9 * (k % 3)
        a = fast.update(t, q, np.zeros(robot.nv))
        b = full.update(t, q.tolist(), np.zeros(robot.nv).tolist())
        assert a.q.tobytes() == b.q.tobytes() and a.v.tobytes() == b.v.tobytes()
    bad = qs[10].copy()
    bad[3:7] *= 1.01
    with pytest.raises(pinobs.ConfigurationError, match=r"q_meas\[3:7\] = .* has norm 1\.01"):
        fast.update(ts[10], bad, np.zeros(robot.nv))
    a = fast.update(ts[10], qs[10], np.zeros(robot.nv))
    b = full.update(ts[10], qs[10], np.zeros(robot.nv))
    assert a.q.tobytes() == b.q.tobytes() and a.v.tobytes() == b.v.tobytes()


def test_finite_inputs_whose_sum_overflows_and_none_are_accepted_as_by_the_full_checks() -> None:
    """The one test of the usual call sums the time, ``q`` and ``τ``: finite entries whose sum
    overflows leave it for the full checks, which accept them (no ``NonFiniteError``: ``kf``
    then diverges, as from a list); a ``None`` sample and torque take it, as lists would."""
    robot, (ob, twin), ts, qs = _pair("kf", "ur5")
    a = ob.update(ts[0], None, None)
    b = twin.update(ts[0], None, np.zeros(robot.nv).tolist())
    assert a.q.tobytes() == b.q.tobytes() and a.v.tobytes() == b.v.tobytes()
    q = qs[1].copy()
    q[:2] = 1e308  # each finite, their sum is not
    outcomes: list[object] = []
    for o, x in ((ob, q), (twin, q.tolist())):
        try:
            e = o.update(ts[1], x, None)
            outcomes.append((e.q.tobytes(), e.v.tobytes(), e.gated))
        except pinobs.ObserverDiverged as exc:
            outcomes.append(str(exc))
    assert outcomes[0] == outcomes[1]
    assert isinstance(outcomes[0], str) and "diverged at t = 0.002 s" in outcomes[0]

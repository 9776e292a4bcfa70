"""Compiled kernels called without numba's dispatcher (``LazyKernel.unchecked``, issue 39): the
same machine code, so the same bits as through the dispatcher."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import pinobs
from pinobs.model import dynamics_rk4
from pinobs.observers.blockstep import joseph_kernels, transition_kernels
from pinobs.observers.fused import ekf_coast_kernel, loaded, rk4_stage_kernel, rkmk4_stage_kernel
from pinobs.observers.fused_lie import rkmk4_solve_kernel
from pinobs.observers.kf_kernels import auto_kernel as kf_kernel


def test_unchecked_is_the_loaded_signatures_code_not_the_dispatcher() -> None:
    """The entry point of the float64 signature the warm arguments load, called as the
    dispatcher is, with the same result."""
    kernel = joseph_kernels[0]  # (P += Q_d, S = P_qq + r I)
    direct = kernel.unchecked()
    assert direct is not loaded(kernel) and callable(direct)
    P1, P2 = np.eye(4) * 0.3, np.eye(4) * 0.3
    S1, S2 = np.empty((2, 2)), np.empty((2, 2))
    direct(P1, 1e-9, 2e-6, 1e-3, 1e-8, S1)
    loaded(kernel)(P2, 1e-9, 2e-6, 1e-3, 1e-8, S2)
    assert P1.tobytes() == P2.tobytes() and S1.tobytes() == S2.tobytes()


@pytest.mark.parametrize("robot_name", ["talos", "go1"])
def test_block_step_gives_the_dispatchers_bits(robot_name: str) -> None:
    """``ekf``'s block step (``BlockStep``, ``LieRK4``) with its kernels called directly and
    through numba's dispatcher: equal estimates, bit for bit, over 60 updates."""
    robot = pinobs.load(robot_name)
    rng = np.random.default_rng(3)
    q0 = robot.random_configuration(rng, scale=0.5)
    v0 = 0.3 * rng.standard_normal(robot.nv)
    tau = robot.gravity(q0)
    obs = [pinobs.make_observer("ekf", robot, rate=1000.0, noise_std=1e-4) for _ in range(2)]
    b, rk = obs[1]._lie_fast.blocks, obs[1]._lie_fast.blocks.rk4
    b.start, b.square, b.phi = (loaded(k) for k in transition_kernels)
    b.noise, b._own_update = loaded(joseph_kernels[0]), loaded(joseph_kernels[2])
    b._own_factor = loaded(joseph_kernels[1])
    rk.solve_stage, rk._first_stage = loaded(rkmk4_solve_kernel), loaded(rkmk4_stage_kernel)
    for ob in obs:
        ob.reset(0.0, robot.integrate(q0, 1e-3 * np.ones(robot.nv)), v0, tau)
    q, v = q0, v0
    for k in range(1, 61):
        q, v = dynamics_rk4(robot, q, v, tau, 1e-3)
        sample = None if k % 17 == 0 else robot.integrate(q, 1e-4 * rng.standard_normal(robot.nv))
        a, c = (ob.update(k * 1e-3, sample, tau) for ob in obs)
        assert a.q.tobytes() == c.q.tobytes() and a.v.tobytes() == c.v.tobytes()
        assert a.nis == c.nis
    assert obs[0]._state.P.tobytes() == obs[1]._state.P.tobytes()


def test_kf_auto_step_takes_any_sample_array() -> None:
    """``kf``'s ``"auto"`` step calls its kernel without numba's dispatcher; a sample that is
    not a writable C-contiguous float64 array (read-only, strided, float32) is copied to one
    first: the same bits as the same values in a fresh float64 array."""
    robot = pinobs.load("ur5")
    obs = pinobs.make_observer("kf", robot, rate=1000.0, noise_std=1e-4)
    assert obs.auto_bank is not None and obs.auto_bank._direct is not loaded(kf_kernel)
    rng = np.random.default_rng(5)
    q0 = robot.random_configuration(rng, scale=0.5)
    obs.reset(0.0, q0)
    state = obs._state
    sample = q0 + 1e-3 * rng.standard_normal(robot.nv)
    read_only = sample.copy()
    read_only.setflags(write=False)
    strided = np.repeat(sample, 2)[::2]
    single = sample.astype(np.float32)
    for q in (sample.copy(), read_only, strided, single):
        a = obs.step(state, 1e-3, np.array(q, dtype=float), None)
        b = obs.step(state, 1e-3, q, None)
        assert a.x.tobytes() == b.x.tobytes() and a.gate == b.gate


def _samples(robot: pinobs.Robot, rng: np.random.Generator, q: np.ndarray, k: int) -> Any:
    """A sample of ``q`` as a caller may hand it: none, fresh, read-only or strided (every
    fifth update), the unchecked kernels' arguments checked by their step."""
    if k % 17 == 0:
        return None
    x = robot.integrate(q, 1e-4 * rng.standard_normal(robot.nv))
    if k % 5 == 1:
        x.setflags(write=False)
    elif k % 5 == 3:
        x = np.repeat(x, 2)[::2]
    return x


@pytest.mark.parametrize("name", ["ekf", "kalman"])
def test_vector_space_steps_give_the_dispatchers_bits(name: str) -> None:
    """``ekf``'s and ``kalman``'s compiled steps on a UR5 call their kernels without numba's
    dispatcher where the state is the one they returned last and the sample a float64 array
    of unit stride (issue 39): the same bits as through the dispatcher, over 80 ``step``
    calls from a state and samples of every kind (fresh, read-only, strided, none)."""
    robot = pinobs.load("ur5")
    rng = np.random.default_rng(4)
    q0 = robot.random_configuration(rng, scale=0.5)
    v0 = 0.3 * rng.standard_normal(robot.nv)
    tau = robot.gravity(q0)
    obs = [pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-4) for _ in range(2)]
    fast = obs[1]._fast
    if name == "ekf":
        assert fast._own_predict is not fast.predict and fast.stage is not loaded(rk4_stage_kernel)
        fast._own_predict, fast._own_finish = fast.predict, fast.finish
        fast.stage, fast.coast = loaded(rk4_stage_kernel), loaded(ekf_coast_kernel)
    else:
        assert fast._own is not fast._checked
        fast._own, fast.stage = fast._checked, loaded(rk4_stage_kernel)
    for ob in obs:
        ob.reset(0.0, robot.integrate(q0, 1e-3 * np.ones(robot.nv)), v0, tau)
    states = [ob._state for ob in obs]
    q, v = q0, v0
    for k in range(1, 81):
        q, v = dynamics_rk4(robot, q, v, tau, 1e-3)
        sample = _samples(robot, rng, q, k)
        states = [ob.step(s, 1e-3, sample, tau) for ob, s in zip(obs, states, strict=True)]
        a, c = states
        assert a.q.tobytes() == c.q.tobytes() and a.v.tobytes() == c.v.tobytes()
        assert a.P.tobytes() == c.P.tobytes() and a.gate == c.gate

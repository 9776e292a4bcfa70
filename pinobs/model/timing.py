"""The Pinocchio reference call every cost is quoted against.

Machines are noisy, so pinobs never quotes a bare time: it quotes the ratio
to one ``pin.aba`` call on the same robot, measured in the same run.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial

import numpy as np
import pinocchio as pin

from pinobs.model.robot import Robot

__all__ = ["aba_call", "aba_time", "pinocchio_version"]


def aba_call(robot: Robot, *, seed: int = 0) -> Callable[[], object]:
    """The reference call: ``pin.aba`` on ``robot`` at a seeded random state, ready to time."""
    rng = np.random.default_rng(seed)
    q = robot.random_configuration(rng)
    v = rng.standard_normal(robot.nv)
    tau = rng.standard_normal(robot.nv)
    return partial(pin.aba, robot.model, robot.model.createData(), q, v, tau)


def aba_time(robot: Robot, *, repeats: int = 2000, rounds: int = 5, seed: int = 0) -> float:
    """Median wall time [s] of one ``pin.aba`` call from Python on ``robot``.

    Python call overhead is included, as it is in every observer update it is
    compared with.  The median over ``rounds`` rounds of ``repeats`` calls.
    """
    call = aba_call(robot, seed=seed)
    samples = []
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(repeats):
            call()
        samples.append((time.perf_counter() - start) / repeats)
    return float(np.median(samples))


def pinocchio_version() -> str:
    """The installed Pinocchio's version, for benchmark reports."""
    return str(pin.__version__)

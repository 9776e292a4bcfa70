"""Every model-based observer uses the model's joint friction: started on the truth, it stays there."""

from __future__ import annotations

import numpy as np
import pytest

import pinobs
from pinobs.model.friction import FrictionLaw
from pinobs.observers import observer_class, observer_names

MODEL_BASED = [n for n in observer_names() if observer_class(n).uses_torque]


def _robots() -> list[pinobs.Robot]:
    cartpole = pinobs.load("cartpole").perturbed(
        name="cartpole+friction", damping=[0.5, 0.02], coulomb=[0.3, 0.01]
    )
    top = pinobs.load("top").perturbed(
        name="top+friction", damping=[0.01, 0.01, 0.005], coulomb=[0.0, 0.0, 0.0]
    )
    # every term of pinobs.model.friction at once: asymmetric Coulomb, Stribeck, offset
    law = FrictionLaw(
        viscous=[0.5, 0.02],
        coulomb_pos=[0.3, 0.01],
        coulomb_neg=[0.2, 0.015],
        static=[0.6, 0.03],
        offset=[0.05, -0.002],
        smoothing=[0.02, 0.05],
        stribeck_velocity=[0.1, 0.2],
        law="mixed",
    )
    laws = cartpole.with_model(
        cartpole.model, name="cartpole+friction-law", friction=True, friction_law=law
    )
    return [cartpole, top, laws]


@pytest.mark.parametrize("name", MODEL_BASED)
def test_started_on_the_truth_with_modelled_friction_the_estimate_stays_there(name: str) -> None:
    for robot in _robots():
        assert robot.has_friction
        try:
            ob = pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-6)
        except pinobs.UnsupportedRobotError:
            continue
        res = pinobs.simulate(
            robot, {name: ob}, duration=1.0, sensor=pinobs.Sensor(1000.0, 0.0), seed=0
        )
        err = np.abs(res.trace(name).v - res.v).max()
        # measured: with the friction left out of the observer the same run ends 6e-2 to 9e-2 rad/s off
        assert err < 1e-5, f"{name} on {robot.name}: {err:.2e}"

"""The model-based observers' default model-error density: the robot's own
(:attr:`pinobs.Robot.model_error_psd`, measured by ``pinobs.identify``) for ``ekf``,
``kalman`` and ``riemannian``, else 1e-8; an explicit ``accel_psd`` always wins."""

from __future__ import annotations

import numpy as np
import pytest

import pinobs
from pinobs.observers import make_observer
from pinobs.simulation import Sensor, simulate

FAMILIES = ("ekf", "kalman", "riemannian")


@pytest.mark.parametrize("name", FAMILIES)
def test_the_robots_own_density_is_the_default_and_an_explicit_one_wins(name: str) -> None:
    robot = pinobs.load("ur5")
    opts = {"rate": 1000.0, "noise_std": 1e-4}
    assert make_observer(name, robot, **opts).options["accel_psd"] == 1e-8
    robot.model_error_psd = 2e-3
    assert make_observer(name, robot, **opts).options["accel_psd"] == 2e-3
    given = make_observer(name, robot, accel_psd=1e-5, **opts)
    assert given.options["accel_psd"] == 1e-5


def test_riemannian_takes_a_density_its_gain_form_cannot_reach_without_an_error() -> None:
    """TIAGo's identified density (28.1 rad²/s³ at σ 5.2e-6, 100 Hz): the Kalman gain's
    error poles are negative reals, out of the paper form's (alpha, beta) (it used to raise);
    the Riccati schedule runs the Kalman gains, the reported (alpha, beta) are clipped."""
    robot = pinobs.load("ur5")
    robot.model_error_psd = 28.1
    opts = {"rate": 100.0, "noise_std": 5.24e-6}
    ob = make_observer("riemannian", robot, **opts)
    assert ob.options["accel_psd"] == 28.1 and ob.options["gain_rule"] == "kalman-clipped"
    assert ob.options["gain_schedule"] == "riccati"
    given = make_observer("riemannian", robot, accel_psd=1e-5, **opts)
    assert given.options["accel_psd"] == 1e-5 and given.options["gain_rule"] == "kalman"


def test_adaptive_keeps_its_own_densities_on_an_identified_robot() -> None:
    robot = pinobs.load("planar_3r")
    before = make_observer("adaptive", robot).options
    robot.model_error_psd = 2e-3
    after = make_observer("adaptive", robot).options
    keys = ("accel_psd", "warmup_accel_psd", "validated_accel_psd")
    assert [after[k] for k in keys] == [before[k] for k in keys]


def test_ekf_on_an_exact_model_with_its_measured_density_stays_on_the_truth() -> None:
    """Invariance: started on the truth, noise-free, exact model; the density an
    identification would store (here 1e-3) changes the gain, not the fixed point."""
    robot = pinobs.load("ur5")
    robot.model_error_psd = 1e-3
    ekf = make_observer("ekf", robot, rate=1000.0)
    assert ekf.options["accel_psd"] == 1e-3
    res = simulate(robot, {"ekf": ekf}, sensor=Sensor(1000, 0.0), inputs="pd", duration=0.5, seed=1)
    err = np.abs(res.trace("ekf").v - res.v).max()
    assert err < 1e-10  # (1e-8: measured 5e-14, test_ekf.py)

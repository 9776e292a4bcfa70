"""Does ``pinobs.identify``'s refinement judge a friction law on velocities the law shaped?

Its passes after the first fit on velocities from a smoother built on the model identified
so far, friction law included (:mod:`pinobs.calibration`).  The truth here: planar_3r with
an asymmetric Coulomb law whose smoothing velocity, 0.0056 rad/s, is below the search's
default 0.01, on a PD-tracked multisine that stops every 1.5 s (many zero crossings and
rests), torques exact (issue 36; the measurements are in the module docstring of
:mod:`pinobs.calibration`, "The friction law's smoothing velocity").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

import pinobs
from pinobs.calibration import identify
from pinobs.model.friction import FrictionLaw
from pinobs.model.friction_fit import SMOOTHING_GRID
from pinobs.simulation import Sensor
from pinobs.simulation.inputs import InputProfile, PDTracking, make_input

TRUE_VS = SMOOTHING_GRID[3]  # 0.0056 rad/s
LAW = FrictionLaw(
    viscous=np.array([0.2, 0.1, 0.05]),
    coulomb_pos=np.array([0.6, 0.3, 0.1]),
    coulomb_neg=np.array([0.3, 0.4, 0.06]),
    static=np.zeros(3),
    offset=np.zeros(3),
    smoothing=np.full(3, TRUE_VS),
    stribeck_velocity=np.zeros(3),
    law="asymmetric",
)


@dataclass(frozen=True)
class _Dwell(InputProfile):
    """``pd``'s reference in a time that stalls: ``move`` s of motion (its speed ramped up
    and down by half cosines of ``ramp`` s), then ``rest`` s held."""

    pd: PDTracking
    move: float = 1.5
    rest: float = 0.6
    ramp: float = 0.3
    name = "pd-dwell"

    def _warp(self, t: float) -> tuple[float, float]:
        """The stalled time and its rate at ``t``."""
        k, r = divmod(t, self.move + self.rest)
        a, full = self.ramp, self.move - self.ramp

        def up(x: float) -> tuple[float, float]:  # ∫ and value of (1 − cos(πx/a))/2
            return 0.5 * (x - a / math.pi * math.sin(math.pi * x / a)), 0.5 * (
                1.0 - math.cos(math.pi * x / a)
            )

        if r < a:
            s, g = up(r)
        elif r < self.move - a:
            s, g = a / 2 + (r - a), 1.0
        elif r < self.move:
            s, g = up(self.move - r)
            s = full - s
        else:
            s, g = full, 0.0
        return k * full + s, g

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        p = self.pd
        tw, g = self._warp(t)
        arg = 2.0 * np.pi * p.freqs * tw + p.phases
        xi = p.amplitude * (p.weights * np.sin(arg)).sum(axis=1)
        xi_dot = p.amplitude * (p.weights * 2.0 * np.pi * p.freqs * np.cos(arg)).sum(axis=1)
        return p.robot.integrate(p.center, xi), xi_dot * g

    def torque(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        p = self.pd
        q_ref, v_ref = self.reference(t)
        kp, kd = p.bandwidth**2, 2.0 * p.damping * p.bandwidth
        e = p.robot.difference(q, q_ref)
        return p.robot.gravity(q) + p.robot.mass_matrix(p.center) @ (kp * e + kd * (v_ref - v))


def _log(sigma: float, bits: int | None, seed: int) -> tuple[pinobs.Robot, tuple]:
    robot = pinobs.load("planar_3r")
    plant = robot.perturbed(inertia_scale=[1.2, 0.8, 1.1])
    plant = plant.with_model(plant.model, friction=True, friction_law=LAW)
    rng = np.random.default_rng(seed)
    q0 = plant.random_configuration(rng, scale=0.3)
    pd = make_input("pd", plant, rng=rng, center=q0, f_hi=1.5, amplitude=0.6)
    assert isinstance(pd, PDTracking)
    sensor = Sensor(rate=1000.0, noise_std=sigma, bits=bits)
    res = pinobs.simulate(
        robot, [], duration=8.0, sensor=sensor, seed=seed, plant=plant, inputs=_Dwell(pd), q0=q0
    )
    q = np.array(res.q_meas)
    q[0] = res.q[0]
    return robot, (res.t, q, np.array(res.tau))


def _error(ident: pinobs.model.identification.Identification) -> float:
    """The largest relative error of the nine coefficients (``F_v``, ``F_c⁺``, ``F_c⁻``)."""
    got = ident.robot.friction_law
    return max(
        float(np.max(np.abs(getattr(got, k) / getattr(LAW, k) - 1.0)))
        for k in ("viscous", "coulomb_pos", "coulomb_neg")
    )


@pytest.mark.slow
def test_the_refinement_leaves_the_first_pass_s_smoothing_velocity_for_the_truth() -> None:
    """σ = 3e-5 rad, 16 bits per turn, seed 1: the first pass (Savitzky–Golay) chose 0.01 on
    joints 1 and 3, the law the first smoother ran on; the refined fit chose the truth's
    0.0056 on every joint, its coefficients within 0.25 % of the truth (measured) where the
    first pass's were 18 % off: the smoother's law did not confirm itself."""
    robot, log = _log(3e-5, 16, seed=1)
    first = identify(robot, log, friction="asymmetric", refine=())
    refined = identify(robot, log, friction="asymmetric")
    assert np.any(first.robot.friction_law.smoothing != TRUE_VS)  # the smoother started off
    np.testing.assert_array_equal(refined.robot.friction_law.smoothing, TRUE_VS)
    assert _error(refined) < 4e-3  # measured 2.5e-3 (1.5x)
    assert _error(refined) < 0.05 * _error(first)  # measured 0.014x


#: Measured on this log (σ = 1e-4, seed 1): the first pass chose 0.01 on joints 1 and 3 and
#: so did both refinement passes, on velocities smoothed with that law; joint 1's F_c⁻ 21 %
#: high.  One pass from the same first fit with the truth's v_s in the smoother chose 0.0056
#: on every joint (F_c⁻ 4.9 %), as did a fit on the true velocities (0.07 %).  Left failing,
#: strictly.
_STICKS = pytest.mark.xfail(
    strict=True, reason="σ = 1e-4: the refinement keeps the first pass's v_s = 0.01 (issue 36)"
)


@pytest.mark.slow
@_STICKS
def test_the_refinement_finds_the_truth_s_smoothing_velocity_at_a_noisier_sensor() -> None:
    robot, log = _log(1e-4, None, seed=1)
    refined = identify(robot, log, friction="asymmetric")
    np.testing.assert_array_equal(refined.robot.friction_law.smoothing, TRUE_VS)

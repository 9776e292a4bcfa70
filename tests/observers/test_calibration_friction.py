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
@pytest.mark.parametrize(
    ("sigma", "bits", "bound", "share"),
    # measured: 0.18 % and 0.010x the first pass's; 1.15 % and 0.12x (bounds 1.5x those)
    [(3e-5, 16, 2.7e-3, 0.015), (1e-4, None, 1.7e-2, 0.18)],
)
def test_the_refinement_leaves_the_first_pass_s_smoothing_velocity_for_the_truth(
    sigma: float, bits: int | None, bound: float, share: float
) -> None:
    """Seed 1: the first pass (Savitzky–Golay, the one-standard-error rule) chose 0.01 on
    joints 1 and 3; the refined fit the truth's 0.0056 on every joint.  Before the first
    pass's law (the smoother's) took the cross-validation's minimum, σ = 1e-4 kept 0.01
    there through both refinements, the coefficients 21 % off (0.25 % at σ = 3e-5)."""
    robot, log = _log(sigma, bits, seed=1)
    first = identify(robot, log, friction="asymmetric", refine=())
    refined = identify(robot, log, friction="asymmetric")
    assert np.any(first.robot.friction_law.smoothing != TRUE_VS)  # the rule's choice
    np.testing.assert_array_equal(refined.robot.friction_law.smoothing, TRUE_VS)
    assert _error(refined) < bound
    assert _error(refined) < share * _error(first)

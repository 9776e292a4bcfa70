"""The invariant EKF's ``adapt_noise`` (eq. 12; :mod:`pinobs.observers.legged_adapt`): the
feet's density scaled per IMU axis, matched to their innovations."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest

from pinobs.errors import GainError
from pinobs.observers.inekf import InEKFGains, InEKFPrior, InvariantEKF
from pinobs.observers.legged_adapt import ADAPT_BOUNDS, match_foot_scale, scaled_densities
from pinobs.observers.legs import noise_densities
from tests.observers.test_inekf import SyntheticLegs, run, synthetic_truth, truth

RATE = 200.0
#: the filter's densities; the feet's true random walk is ``TRUE_SCALE`` times its per axis
GAINS = InEKFGains(
    gyro=1e-4, accel=1e-3, gyro_bias=1e-7, accel_bias=1e-6, contact=1e-4, joint=1e-6,
    kinematics=0.0,
)  # fmt: skip
TRUE_SCALE = np.array([4.0, 1.0, 0.25])  # variance ratios per world axis (the base barely turns)


@cache
def slipping_feet(seed: int = 3, duration: float = 24.0):
    """Three feet standing still but for a random walk of density ``√TRUE_SCALE σ_c`` per
    world axis, under a base that barely turns, and IMU and encoder noise at ``GAINS``'.
    The joint angles by Newton's method on every sample at once (``SyntheticLegs.inverse``'s,
    vectorised: the base from :func:`truth`, its own angles not computed)."""
    rng = np.random.default_rng(seed)
    legs = SyntheticLegs(3)
    base = truth(legs, RATE, duration, wobble=0.1, inverse=lambda h: np.zeros(legs.nq_joints))
    R = np.array([b[1] for b in base])
    p = np.array([b[3] for b in base])
    d = np.array(legs.c)  # truth's feet: h_j(0) = c_j, at z = −0.4 m
    steps = rng.normal(size=(len(base), 3, 3)) * (GAINS.contact * np.sqrt(TRUE_SCALE / RATE))
    feet = d + np.cumsum(steps, axis=0) - steps[0]  # (n, foot, world axis)
    h = np.einsum("nia,nfi->nfa", R, feet - p[:, None, :])  # h_j = Rᵀ(d_j + δd_j − p)
    q = np.empty((len(base), 3, 3))
    for j in range(3):  # u + 0.1 sin u = M_jᵀ(h_j − c_j)
        y = (h[:, j] - legs.c[j]) @ legs.M[j]
        u = y.copy()
        for _ in range(50):
            u -= (u + 0.1 * np.sin(u) - y) / (1 + 0.1 * np.cos(u))
        q[:, j] = u
    noise = rng.normal(size=(len(base), 3 + 3 + 9))
    return [
        (
            t,
            Rk,
            v,
            pk,
            qk.reshape(-1) + GAINS.joint * nk[6:],
            omega + GAINS.gyro * math.sqrt(RATE) * nk[:3],
            acc + GAINS.accel * math.sqrt(RATE) * nk[3:6],
            contacts,
        )
        for (t, Rk, v, pk, _, omega, acc, contacts), qk, nk in zip(base, q, noise, strict=True)
    ]


def test_the_learned_scale_converges_to_the_feet_true_density_per_axis() -> None:
    """Feet walking at 4, 1 and 0.25 times the filter's contact variance along x, y, z: the
    scale ``α`` (window 2 s) averaged over the last 6 s of 24 is each within 15 % of it (seed 3:
    4.01 / 0.98 / 0.26, its spread over those 6 s 2-4 %); off, it stays 1."""
    samples = slipping_feet()
    prior = InEKFPrior(attitude=1e-3, velocity=1e-3)
    ekf = InvariantEKF(SyntheticLegs(3), gains=GAINS, adapt_noise=2.0)
    scales = [ekf.noise_scale.copy() for _ in run(ekf, samples, prior=prior)]
    late = np.mean(scales[-round(6 * RATE) :], axis=0)
    np.testing.assert_allclose(late, TRUE_SCALE, rtol=0.15)
    off = InvariantEKF(SyntheticLegs(3), gains=GAINS)
    for _ in run(off, samples[:50], prior=prior):
        pass
    np.testing.assert_array_equal(off.noise_scale, np.ones(3))


def test_started_on_the_truth_it_stays_there_with_adapt_noise() -> None:
    """Noise-free, started on the truth, through a foot's lift-off and landing: the estimate
    stays on the truth whatever the scale does (it is in Q, not in the mean)."""
    ekf = InvariantEKF(SyntheticLegs(3), adapt_noise=0.5)
    worst = 0.0
    for est, (R, v, _p) in run(ekf, synthetic_truth()):
        worst = max(worst, float(np.abs(est.velocity_world - v).max()))
        worst = max(worst, float(np.abs(est.rotation - R).max()))
    assert worst < 1e-9
    assert np.all(ekf.noise_scale >= ADAPT_BOUNDS[0])


def test_scaled_densities_scale_only_the_feet_blocks_per_axis() -> None:
    qc = noise_densities(InEKFGains(), 2)
    out = scaled_densities(qc, np.array([2.0, 3.0, 4.0]), 2)
    np.testing.assert_array_equal(out[9:15], qc[9:15] * [2, 3, 4, 2, 3, 4])
    np.testing.assert_array_equal(np.delete(out, range(9, 15)), np.delete(qc, range(9, 15)))
    assert not out.flags.writeable


def test_a_foot_without_a_share_of_s_leaves_the_scale() -> None:
    """``f = 0`` (the foot's density none of ``S``): the innovations, however small, do not
    move ``α``; a full share moves it down for innovations below their prediction."""
    scale = np.array([1.0, 2.0, 0.5])
    e, s = np.full((2, 3), 1e-6), np.ones((2, 3))
    kept = match_foot_scale(scale, e, s, np.zeros((2, 3)), 0.01, 1.0)
    np.testing.assert_array_equal(kept, scale)
    moved = match_foot_scale(scale, e, s, np.ones((2, 3)), 0.01, 1.0)
    assert np.all(moved < scale)


@pytest.mark.parametrize("window", [0.0, -1.0, math.nan])
def test_a_bad_window_is_refused(window: float) -> None:
    with pytest.raises(GainError, match="adapt_noise"):
        InvariantEKF(SyntheticLegs(3), adapt_noise=window)

"""The contact-aided filters' landing term (``InEKFGains.landing``, ``landing_time``): a foot's
contact density raised over its first ``landing_time`` of contact
(:func:`pinobs.observers.legged_filter.landing_densities`)."""

from __future__ import annotations

import numpy as np
import pytest

import pinobs
from pinobs.observers.inekf import InEKFGains, InvariantEKF
from pinobs.observers.legged_filter import landing_densities
from pinobs.observers.legs import noise_densities
from pinobs.observers.qekf import QuaternionEKF
from tests.observers.test_inekf import GO1_FEET, Go1Legs, truth
from tests.observers.test_inekf_foot_noise import _run


@pytest.fixture(scope="module")
def go1_truth():
    legs = Go1Legs("imu_link")
    return truth(legs, 200.0, 0.5, wobble=0.5, feet_z=None, inverse=legs.inverse)


def test_landing_densities_add_the_share_of_the_step_inside_the_window() -> None:
    """Two feet, landed at 0 and at −1 s, window 20 ms: a step [15, 25] ms is half inside the
    first's window (``landing²/2`` added), none of the second's; a step inside it all of it."""
    gains = InEKFGains(contact=1e-3, landing=1e-2, landing_time=0.02)
    qc = noise_densities(gains, 2)
    landed = np.array([0.0, -1.0])
    half = landing_densities(qc, gains, landed, 0.015, 0.01)
    np.testing.assert_allclose(half[9:12], 1e-6 + 0.5e-4, rtol=1e-12)
    np.testing.assert_array_equal(half[12:15], 1e-6)
    np.testing.assert_array_equal(np.delete(half, range(9, 12)), np.delete(qc, range(9, 12)))
    whole = landing_densities(qc, gains, landed, 0.002, 0.002)
    np.testing.assert_allclose(whole[9:12], 1e-6 + 1e-4, rtol=1e-12)
    assert not half.flags.writeable and not whole.flags.writeable
    assert landing_densities(qc, gains, landed, 0.03, 0.002) is qc  # past every window
    for off in (InEKFGains(landing=1e-2), InEKFGains(landing_time=0.02)):
        assert landing_densities(qc, off, landed, 0.0, 0.002) is qc


@pytest.mark.parametrize("family", [InvariantEKF, QuaternionEKF])
def test_a_landing_term_that_is_off_leaves_the_filters_bit_identical(go1_truth, family) -> None:
    """``landing`` 0 (whatever ``landing_time``) or ``landing_time`` 0: the estimates and
    covariances of the gains without them, bit for bit."""
    go1 = pinobs.load("go1")
    runs = [
        _run(family(go1, GO1_FEET, imu_frame="imu_link", gains=g), go1_truth, speeds=False)[0]
        for g in (InEKFGains(), InEKFGains(landing_time=0.05), InEKFGains(landing=0.05))
    ]
    for a, b, c in zip(*runs, strict=True):
        assert np.array_equal(a.covariance, b.covariance) and np.array_equal(a.q, b.q)
        assert np.array_equal(a.covariance, c.covariance) and np.array_equal(
            a.v, c.v, equal_nan=True
        )


@pytest.mark.parametrize("family", [InvariantEKF, QuaternionEKF])
def test_the_landing_term_widens_the_filter_and_leaves_its_mean(go1_truth, family) -> None:
    """Feet down at ``reset`` land then: with ``landing`` 0.05 m/s/√Hz over 20 ms the
    velocity's variance is larger than without at the window's end, and the mean, started on
    the truth with exact measurements, stays on it (the term is in Q, not in the mean; the
    root's velocity with the raw gyro in the lever arm, ``lever_tau`` 0: imu_link.py's M3)."""
    go1 = pinobs.load("go1")
    base = InEKFGains(contact=1e-3, lever_tau=0.0)
    landing = InEKFGains(contact=1e-3, landing=0.05, landing_time=0.02, lever_tau=0.0)
    plain, _ = _run(family(go1, GO1_FEET, imu_frame="imu_link", gains=base), go1_truth)
    wide, worst = _run(family(go1, GO1_FEET, imu_frame="imu_link", gains=landing), go1_truth)
    assert worst < 1e-9
    k = 3  # the update at 20 ms (200 Hz): the window's last step
    assert np.trace(wide[k].covariance[3:6, 3:6]) > 1.5 * np.trace(plain[k].covariance[3:6, 3:6])

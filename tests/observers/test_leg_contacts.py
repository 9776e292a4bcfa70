"""Issue 38: the feet's NIS over stance rows (legs.stance_consistency) and SEROW's contact
probability (contacts.ContactProbability)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2, norm

import pinobs
from pinobs.errors import DimensionError, GainError
from pinobs.observers.contacts import (
    ContactProbability,
    contact_flags,
    contacts_from_probability,
)
from pinobs.observers.legs import quaternion_to_rotation, stance_consistency


def test_chi2_innovations_are_consistent_and_fall_in_their_interval_95_percent(rng) -> None:
    dof = rng.choice([3, 6, 9, 12], 20000)
    nis = chi2.rvs(dof, random_state=rng)
    c = stance_consistency(nis, dof)
    assert c.verdict == "consistent" and c.samples == 20000
    assert c.mean_nis == pytest.approx(1.0, abs=0.03)
    assert c.details["inside"] == pytest.approx(0.95, abs=0.01)
    assert c.details["below"] == pytest.approx(0.025, abs=0.005)


def test_too_small_or_too_large_innovations_are_inconsistent_and_rows_without_feet_skipped(
    rng,
) -> None:
    dof = np.full(2000, 6)
    nis = chi2.rvs(dof, random_state=rng)
    small = stance_consistency(0.05 * nis, dof)  # noise levels 4.5x too large
    assert small.verdict == "inconsistent" and small.details["below"] > 0.9
    large = stance_consistency(20.0 * nis, dof)
    assert large.verdict == "inconsistent" and large.details["above"] > 0.9
    with_air = stance_consistency(np.r_[nis, np.nan, 5.0], np.r_[dof, 0, 0])
    assert with_air.samples == 2000 and with_air.mean_nis == pytest.approx(
        stance_consistency(nis, dof).mean_nis
    )
    assert stance_consistency([], []).verdict == "unknown"
    with pytest.raises(DimensionError, match="one row each"):
        stance_consistency([1.0, 2.0], [3])


def test_contact_probability_is_the_product_of_the_force_and_speed_normal_cdfs() -> None:
    p = ContactProbability(force_min=20.0, force_sigma=5.0, speed_max=0.5, speed_sigma=0.1)
    assert p(20.0, 0.5) == pytest.approx(0.25)
    f, v = np.array([10.0, 30.0, 60.0]), np.array([0.0, 0.45, 0.9])
    expected = norm.cdf((f - 20.0) / 5.0) * norm.cdf((0.5 - v) / 0.1)
    np.testing.assert_allclose(p(f, v), expected, rtol=1e-12)
    assert math.isnan(float(p(np.nan, 0.0)))
    flags = contacts_from_probability([0.9, 0.1, np.nan, np.nan], [False, True, True, False])
    assert flags.tolist() == [True, False, True, False]


def test_a_row_s_flags_are_contact_flags_of_the_probability_to_the_bit(rng) -> None:
    """``row_flags`` (legged_run's row, z in Python floats) is :func:`contact_flags` of
    ``force_factor · speed_factor`` (the arrays' NumPy), a NaN force keeping the flag; and
    ``speed_factor`` is ``erfc(−z_v/√2)`` as written, bit for bit."""
    from scipy.special import erfc

    p = ContactProbability(20.0, 5.0)
    force = np.r_[rng.uniform(0.0, 40.0, 4000), np.nan, p.force_min]
    speed = np.r_[rng.uniform(0.0, 0.6, 4000), 0.1, p.speed_max]
    z_v = (p.speed_max - speed) / p.speed_sigma
    np.testing.assert_array_equal(p.speed_factor(speed), erfc(-z_v / math.sqrt(2.0)))
    ff, sf = p.force_factor(force), p.speed_factor(speed)
    previous = (rng.uniform(size=force.size) < 0.5).tolist()
    want = contact_flags((ff * sf).tolist(), previous)
    got: list[bool] = []
    for i in range(0, force.size, 4):  # rows of four feet
        got += p.row_flags(ff[i : i + 4].tolist(), speed[i : i + 4], previous[i : i + 4])
    assert got == want
    assert 0 < sum(got) < len(got) and got[-2] == previous[-2]  # (the NaN force kept)


def test_contact_probability_defaults_scale_with_weight_and_bad_values_are_named() -> None:
    go1 = ContactProbability.for_robot(pinobs.load("go1"))
    weight = 9.80665 * pinobs.load("go1").total_mass()
    # the Schmitt trigger's on/off (0.15 W, 0.075 W) are f_min ± σ_f
    assert go1.force_min + go1.force_sigma == pytest.approx(0.15 * weight)
    assert go1.force_min - go1.force_sigma == pytest.approx(0.075 * weight)
    with pytest.raises(GainError, match="speed_max"):
        ContactProbability(10.0, 2.0, speed_max=-1.0)
    with pytest.raises(GainError, match="force_sigma and speed_sigma"):
        ContactProbability(10.0, 0.0)


def test_quaternion_to_rotation_is_scipy_s_to_the_bit_and_a_rotation(rng) -> None:
    """Issue 39: ``inekf``'s reset no longer imports ``scipy.spatial`` (0.1–0.4 s CPU); its
    rotation is the same bits as SciPy's (unit and non-unit quaternions, near identity),
    orthonormal with determinant 1, and Pinocchio's for the same quaternion."""
    import pinocchio as pin
    from scipy.spatial.transform import Rotation

    for k in range(3000):
        quat = rng.normal(size=4) * 10.0 ** rng.uniform(-3, 3)
        if k % 5 == 0:
            quat = np.array([0.0, 0.0, 0.0, 1.0]) + 1e-9 * rng.normal(size=4)
        R = quaternion_to_rotation(quat)
        assert np.array_equal(R, Rotation.from_quat(quat).as_matrix())
        np.testing.assert_allclose(R @ R.T, np.eye(3), rtol=0, atol=1e-14)
        assert abs(np.linalg.det(R) - 1.0) < 1e-14
        unit = quat / np.linalg.norm(quat)
        expected = pin.Quaternion(unit[3], *unit[:3]).toRotationMatrix()
        np.testing.assert_allclose(R, expected, rtol=0, atol=1e-14)

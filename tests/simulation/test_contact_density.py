"""benchmarks/legged_truth.py's ``stance_density``: the contact density a foot's true motion
amounts to (``GO1_GAINS``, ``GO1_WHITE_GAINS``, ``TALOS_GAINS``), against closed forms; and
the gains measured with it on short held-out simulations."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

pytest.importorskip("mujoco")

from tests.io.test_real_data import bench_module

RADIUS, DT = 0.02, 0.002


def rolling_foot(phi_dot: float, samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A sphere of radius ``RADIUS`` rolling without slipping about the world's y at
    ``phi_dot`` [rad/s] (rolling.py's (R1): ``ċ = ω × r n``): times, centres (N, 1, 3),
    orientations (N, 1, 3, 3)."""
    t = np.arange(samples) * DT
    phi = phi_dot * t
    centres = np.zeros((samples, 1, 3))
    centres[:, 0, 0] = RADIUS * phi  # r φ (u × n), u = y, n = z
    centres[:, 0, 2] = RADIUS
    rotations = Rotation.from_rotvec(np.outer(phi, [0.0, 1.0, 0.0])).as_matrix()[:, None]
    return t, centres, rotations


def test_a_rolling_foots_touch_point_moves_as_the_cycloid_its_centre_as_r_phi() -> None:
    """One stance of 0.1 s rolling 1 rad/s: the centre moves r φ, the touch point rolling.py's
    (R3), ``r (φ − sin φ)`` along and ``r (1 − cos φ)`` up; σ_c = |Δa| / sqrt(3 τ)."""
    bench = bench_module("legged_truth")
    t, centres, rotations = rolling_foot(1.0, 51)
    flags = np.ones((t.size, 1), dtype=bool)
    tau, phi = t[-1], t[-1] * 1.0
    centre = bench.stance_density(t, centres, rotations, flags, 0.0)
    touch = bench.stance_density(t, centres, rotations, flags, RADIUS)
    assert centre["density"] == pytest.approx(RADIUS * phi / np.sqrt(3 * tau), rel=1e-12)
    cycloid = RADIUS * np.hypot(phi - np.sin(phi), 1 - np.cos(phi))
    assert touch["density"] == pytest.approx(cycloid / np.sqrt(3 * tau), rel=1e-9)
    assert touch["density"] < 0.06 * centre["density"]
    assert centre["stances"] == touch["stances"] == 1 and centre["stance_s"] == pytest.approx(tau)


def test_a_white_random_walk_gives_its_density_and_a_flat_spectrum() -> None:
    """A foot walking randomly with density 0.01 m/s/√Hz over 100 stances of 0.2 s (flags off
    between them): σ_c and every band of the spectrum within 10 % of 0.01."""
    bench = bench_module("legged_truth")
    rng = np.random.default_rng(0)
    n = 20_000
    t = np.arange(n) * DT
    centres = np.cumsum(rng.normal(size=(n, 1, 3)) * 0.01 * np.sqrt(DT), axis=0)
    rotations = np.broadcast_to(np.eye(3), (n, 1, 3, 3))
    flags = ((np.arange(n) // 100) % 2 == 0)[:, None]
    out = bench.stance_density(t, centres, rotations, flags, RADIUS)
    assert out["stances"] == 100
    assert out["density"] == pytest.approx(0.01, rel=0.1)
    assert np.allclose(out["psd"], 0.01, rtol=0.1), out["psd"]


def test_no_stance_is_an_error() -> None:
    bench = bench_module("legged_truth")
    t, centres, rotations = rolling_foot(1.0, 10)
    flags = np.zeros((t.size, 1), dtype=bool)
    flags[3] = True  # one sample: no duration
    with pytest.raises(ValueError, match="no stance"):
        bench.stance_density(t, centres, rotations, flags, RADIUS)


def test_a_landing_is_split_from_the_rest_of_its_stance() -> None:
    """A foot that moves 1 mm in z over its first 10 ms then stays, over a stance of 0.1 s:
    the first ``LANDING_TIME`` (20 ms) carries it all, ``landing`` = 1 mm / sqrt(3 · 20 ms)
    (z alone: 1 mm / sqrt(20 ms)), ``after`` 0; the whole stance's σ_c = 1 mm / sqrt(0.3 s)."""
    bench = bench_module("legged_truth")
    t = np.arange(51) * DT
    centres = np.zeros((t.size, 1, 3))
    centres[:, 0, 2] = -1e-3 * np.minimum(t / 0.01, 1.0)
    rotations = np.broadcast_to(np.eye(3), (t.size, 1, 3, 3))
    out = bench.stance_density(t, centres, rotations, np.ones((t.size, 1), bool), 0.0)
    window = bench.LANDING_TIME
    assert out["landing"] == pytest.approx(1e-3 / np.sqrt(3 * window), rel=1e-9)
    np.testing.assert_allclose(out["landing_per_axis"], [0, 0, 1e-3 / np.sqrt(window)], rtol=1e-9)
    assert out["after"] == 0.0
    assert out["density"] == pytest.approx(1e-3 / np.sqrt(3 * 0.1), rel=1e-9)


def _inekf_pair(scenario: str, seed: int, *gains: object) -> list[dict]:
    """legged_truth's inekf rows (rolling feet, from the truth) on one 3 s go1 run, one per
    set of ``gains``."""
    import pinobs
    from pinobs.simulation.legged import simulate_legged

    bench = bench_module("legged_truth")
    go1 = pinobs.load("go1")
    run = simulate_legged(scenario, 3.0, seed=seed, noise=bench.NOISE, robot=go1)
    return [bench.run_filter("inekf", run, go1, "truth", g, bench.FOOT_RADIUS) for g in gains]


def test_the_landing_term_makes_a_held_out_trot_seed_consistent() -> None:
    """``GO1_GAINS`` (the contact density after the landing and the landing term, measured on
    the trot's truth, seed 0) against ``GO1_WHITE_GAINS`` (one white density), rolling feet,
    the trot, seed 1 (the motion is the measuring one, the sensor noise held out), 3 s, from
    the truth: NEES/3 in 0.7-1.3 where it was below 0.5, and the velocity not worse than 1.1×
    (measured: NEES/3 0.35 → 0.95, 0.0080 → 0.0085 m/s, z inside ±2σ 100 → 89 %; the
    benchmark's trot, 10 s, seeds 0-2: 0.42 → 0.84, 0.0079 → 0.0076 m/s)."""
    bench = bench_module("legged_truth")
    new, old = _inekf_pair("trot", 1, bench.GO1_GAINS, bench.GO1_WHITE_GAINS)
    assert old["nees"] < 0.5 and 0.7 <= new["nees"] <= 1.3, (old["nees"], new["nees"])
    assert new["v_rms"] <= 1.1 * old["v_rms"], (new["v_rms"], old["v_rms"])
    assert 0.7 <= new["nees_body"] <= 1.3, new["nees_body"]  # in the IMU frame: 1.00


def test_the_measured_go1_density_makes_the_held_out_sway_more_consistent() -> None:
    """``GO1_WHITE_GAINS`` (the density measured at the touch point on the trot's truth) against
    ``GAINS`` (0.007, the foot centre's), both with rolling feet, on the sway (held out), seed
    2, 3 s, from the truth: NEES/3 closer to 1 and the velocity no worse (measured: NEES/3
    0.79 → 0.94, 0.0114 → 0.0109 m/s, x inside ±2σ 95.2 → 94.9 %; the benchmark's sway, 10 s,
    seeds 0-2: 0.52 → 0.62, 0.0090 → 0.0087 m/s, ≥ 98.9 % on every axis)."""
    bench = bench_module("legged_truth")
    new, old = _inekf_pair("sway", 2, bench.GO1_WHITE_GAINS, bench.GAINS)
    assert old["nees"] < new["nees"] < 1.0, (old["nees"], new["nees"])
    assert new["v_rms"] <= old["v_rms"] * 1.01, (new["v_rms"], old["v_rms"])
    assert min(new["in_2sigma_xyz"]) >= 0.9, new["in_2sigma_xyz"]  # 3 s: 0.949 on x

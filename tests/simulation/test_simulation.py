"""Ground truth, sensors, inputs and the result type."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import pinobs
from pinobs.model import dynamics_rk4, lie_rk4
from pinobs.simulation import PDTracking, Sensor, make_input, simulate


@pytest.mark.parametrize("name", ["ur5", "top", "rigid_body"])
def test_plant_integrator_is_fourth_order_on_every_joint_group(name: str) -> None:
    robot = pinobs.load(name)
    rng = np.random.default_rng(1)
    q0, v0 = robot.random_configuration(rng), 2 * rng.standard_normal(robot.nv)

    def rhs(q, v):
        return v, robot.forward_dynamics(q, v, np.zeros(robot.nv))

    def run(h: float):
        q, v = q0, v0
        for _ in range(round(0.5 / h)):
            q, v = lie_rk4(robot, q, v, h, rhs)
        return q, v

    qr, vr = run(2.5e-4)
    errs = []
    for h in (1e-2, 5e-3):
        q, v = run(h)
        errs.append(np.linalg.norm(robot.difference(qr, q)) + np.linalg.norm(v - vr))
    assert 3.5 < np.log2(errs[0] / errs[1]) < 4.6


@pytest.mark.parametrize(
    "name", ["ur5", "panda", "top", "rigid_body", "double_pendulum_continuous"]
)
@pytest.mark.parametrize("friction", [False, True])
def test_dynamics_step_is_the_generic_rkmk4_step(name: str, friction: bool) -> None:
    """The stacked vector-space form of ``dynamics_rk4`` is classical RK4, to rounding."""
    robot = pinobs.load(name, friction=friction)
    rng = np.random.default_rng(2)
    q, v = robot.random_configuration(rng), rng.standard_normal(robot.nv)
    tau = rng.standard_normal(robot.nv)
    for h in (1e-3, 0.05):
        q1, v1 = dynamics_rk4(robot, q, v, tau, h)
        q2, v2 = lie_rk4(robot, q, v, h, lambda qq, vv: (vv, robot.forward_dynamics(qq, vv, tau)))
        assert np.abs(robot.difference(q2, q1)).max() <= 1e-14 * max(1.0, np.abs(v).max())
        assert np.abs(v1 - v2).max() <= 1e-13 * max(1.0, np.abs(v2).max())


@pytest.mark.parametrize(("name", "root"), [("go1", None), ("top", None), ("planar_3r", "planar")])
def test_lie_group_dynamics_step_is_lie_rk4_bit_for_bit(name: str, root: str | None) -> None:
    """Where there are Lie-group joints ``dynamics_rk4`` writes out ``lie_rk4``'s stages:
    the same bits, at rest too (``J_r(0) = I``) and with the first stage given (``acc0``)."""
    robot = pinobs.load(name, root_joint=root)
    rng = np.random.default_rng(4)
    for speed in (0.0, 1.0, 30.0):
        q, v = robot.random_configuration(rng), speed * rng.standard_normal(robot.nv)
        tau = rng.standard_normal(robot.nv)
        q2, v2 = lie_rk4(
            robot, q, v, 1e-3, lambda qq, vv, tau=tau: (vv, robot.forward_dynamics(qq, vv, tau))
        )
        for acc0 in (None, robot.forward_dynamics(q, v, tau)):
            q1, v1 = dynamics_rk4(robot, q, v, tau, 1e-3, acc0=acc0)
            assert np.array_equal(q1, q2) and np.array_equal(v1, v2)


def test_free_motion_conserves_energy_on_a_ur5() -> None:
    robot = pinobs.load("ur5")
    res = simulate(robot, [], duration=2.0, inputs="zero", v0=np.full(6, 1.0), seed=0)
    energy = [
        robot.kinetic_energy(q, v) + robot.potential_energy(q)
        for q, v in zip(res.q, res.v, strict=True)
    ]
    # measured: 9.6e-8 J drift on 33.4 J (2.9e-9 relative) over 2 s at 1 kHz
    assert np.ptp(energy) / np.mean(energy) < 1e-8


def test_sensor_noise_has_the_requested_standard_deviation() -> None:
    robot = pinobs.load("planar_3r")
    rng = np.random.default_rng(0)
    s = Sensor(rate=100.0, noise_std=1e-3)
    q = robot.neutral()
    samples = np.array([robot.difference(q, s.measure(robot, q, rng)) for _ in range(4000)])
    assert np.std(samples) == pytest.approx(1e-3, rel=0.05)
    assert abs(np.mean(samples)) < 1e-4


def test_quantization_rounds_vector_joints_to_the_encoder_grid() -> None:
    robot = pinobs.load("planar_3r")
    s = Sensor(bits=12)
    res = 2 * np.pi / 4096
    q = np.array([0.1234, -0.5, 2.0])
    m = s.measure(robot, q, np.random.default_rng(0))
    np.testing.assert_allclose(m / res, np.round(q / res), atol=1e-9)
    assert np.abs(m - q).max() <= res / 2


def test_quaternion_stays_unit_under_noise() -> None:
    robot = pinobs.load("top")
    m = Sensor(noise_std=0.1).measure(robot, robot.neutral(), np.random.default_rng(0))
    assert np.linalg.norm(m) == pytest.approx(1.0, abs=1e-14)


def test_dropouts_and_delay_are_applied() -> None:
    robot = pinobs.load("pendulum")
    res = simulate(
        robot,
        ["kf"],
        duration=1.0,
        sensor=Sensor(rate=1000.0, dropout=0.3, delay=2),
        inputs="pd",
        seed=2,
    )
    dropped = np.isnan(res.q_meas[1:, 0])
    assert 0.25 < dropped.mean() < 0.35
    k = np.flatnonzero(~dropped)[10] + 1
    np.testing.assert_allclose(res.q_meas[k], res.q[k - 2])
    assert np.all(np.isfinite(res.trace("kf").v))


def test_pd_tracking_follows_its_reference() -> None:
    robot = pinobs.load("ur5")
    res = simulate(robot, [], duration=3.0, inputs="pd", seed=0)
    profile = make_input("pd", robot, rng=np.random.default_rng(0), center=res.q[0])
    assert isinstance(profile, PDTracking)
    # the run's own reference: rebuild it with the run's generator state is not possible; check tracking
    # of a freshly made profile instead
    res2 = simulate(
        robot,
        [],
        duration=3.0,
        inputs=profile,
        q0=profile.reference(0.0)[0],
        v0=profile.reference(0.0)[1],
    )
    err = [
        np.linalg.norm(robot.difference(q, profile.reference(t)[0]))
        for t, q in zip(res2.t, res2.q, strict=True)
    ]
    assert max(err[1000:]) < 0.05


def test_result_round_trips_through_a_file_and_is_read_only(tmp_path: Path) -> None:
    robot = pinobs.load("cartpole")
    res = simulate(
        robot, ["fd", "kf"], duration=0.3, sensor=Sensor(noise_std=1e-4, dropout=0.1), seed=4
    )
    back = pinobs.Result.load(res.save(tmp_path / "r.npz"))
    for k in ("t", "q", "v", "tau", "q_meas"):
        np.testing.assert_array_equal(getattr(back, k), getattr(res, k))
    assert back.observer_names == ["fd", "kf"]
    np.testing.assert_array_equal(back.trace("kf").v, res.trace("kf").v)
    assert back.meta == res.meta and back.trace("fd").options == res.trace("fd").options
    with pytest.raises(ValueError, match="read-only"):
        res.v[0, 0] = 1.0
    assert res.t.shape == (301,) and res.q.shape == (301, 2) and res.trace("kf").v.shape == (301, 2)


def test_same_seed_same_run_other_seed_other_run() -> None:
    robot = pinobs.load("cartpole")
    kw = dict(duration=0.2, sensor=Sensor(noise_std=1e-3), perturb_v=0.5)
    a, b, c = (simulate(robot, ["kf"], seed=s, **kw) for s in (1, 1, 2))
    np.testing.assert_array_equal(a.trace("kf").v, b.trace("kf").v)
    assert not np.array_equal(a.q_meas[1:], c.q_meas[1:])


def test_observers_own_their_data_and_do_not_disturb_the_truth() -> None:
    robot = pinobs.load("ur5")
    alone = simulate(robot, [], duration=0.2, seed=5)
    with_obs = simulate(robot, ["fd", "kf"], duration=0.2, seed=5)
    np.testing.assert_array_equal(alone.q, with_obs.q)


# ------------------------------------------------ arguments refused before any work
@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"duration": -1.0}, pinobs.errors.GainError, "duration=-1.0 is out of range"),
        ({"duration": math.inf}, pinobs.errors.GainError, "duration=inf is out of range"),
        ({"duration": math.nan}, pinobs.errors.GainError, "duration=nan is out of range"),
        ({"duration": 1e-4}, pinobs.errors.GainError, "shorter than one sample period"),
        ({"perturb_q": math.nan}, pinobs.errors.GainError, "perturb_q=nan is out of range"),
        ({"perturb_q": -0.1}, pinobs.errors.GainError, "perturb_q=-0.1 is out of range"),
        ({"perturb_v": math.inf}, pinobs.errors.GainError, "perturb_v=inf is out of range"),
        ({"seed": -1}, pinobs.errors.GainError, "seed=-1: give an integer >= 0"),
        ({"substeps": 0}, pinobs.errors.GainError, "substeps=0: give an integer >= 1"),
        ({"observers": "kf"}, pinobs.errors.OptionError, r"give a list of names \(\['kf'\]\)"),
        ({"observers": {"a": "kf"}}, pinobs.errors.OptionError, "are not observers"),
        ({"plant": "double_pendulum"}, pinobs.errors.DimensionError, "has nq = 2, nv = 2"),
    ],
)
def test_simulate_refuses_bad_arguments_with_a_pinobs_error(kwargs, error, match) -> None:
    robot = pinobs.load("pendulum")
    kwargs = {"observers": ["kf"], "duration": 0.1, **kwargs}
    if kwargs.get("plant") == "double_pendulum":
        kwargs["plant"] = pinobs.load("double_pendulum")
    observers = kwargs.pop("observers")
    with pytest.raises(error, match=match):
        simulate(robot, observers, **kwargs)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"delay": 1.5}, r"delay=1.5: give a whole number of samples >= 0"),
        ({"delay": -1}, r"delay=-1: give a whole number"),
        ({"bits": 12.5}, r"bits=12.5: give an integer >= 1"),
    ],
)
def test_sensor_refuses_fractional_delays_and_bits(kwargs, match) -> None:
    with pytest.raises(pinobs.errors.GainError, match=match):
        Sensor(**kwargs)


# ------------------------------------------------------------ saved results
def test_result_load_refuses_files_that_are_not_saved_results(tmp_path: Path) -> None:
    import json

    from pinobs.errors import LogFormatError

    (tmp_path / "text.npz").write_text("not a result\n")
    np.savez(tmp_path / "other.npz", a=np.zeros(2))
    np.savez(tmp_path / "list.npz", header=np.array("[1, 2]"))
    np.savez(tmp_path / "short.npz", header=np.array(json.dumps({"robot": "x", "traces": []})))
    for name, match in [
        ("text.npz", "it is not an .npz archive"),
        ("other.npz", "it has no header"),
        ("list.npz", "its header is not a result's"),
        ("short.npz", "KeyError"),
    ]:
        with pytest.raises(LogFormatError, match="is not a result saved by pinobs.*" + match):
            pinobs.Result.load(tmp_path / name)


def test_result_saves_its_format_version_and_refuses_a_newer_one(tmp_path: Path) -> None:
    import json

    from pinobs.errors import LogFormatError
    from pinobs.simulation.result import RESULT_FORMAT

    res = simulate(pinobs.load("pendulum"), ["kf"], duration=0.05)
    path = res.save(tmp_path / "r.npz")
    with np.load(path) as z:
        header = json.loads(str(z["header"]))
        arrays = {k: z[k] for k in z.files}
    assert header["format"] == RESULT_FORMAT == 1
    assert pinobs.Result.load(path).meta == res.meta
    header["format"] = RESULT_FORMAT + 1
    np.savez(tmp_path / "new.npz", **{**arrays, "header": np.array(json.dumps(header))})
    with pytest.raises(LogFormatError, match="saved in result format 2; this pinobs reads"):
        pinobs.Result.load(tmp_path / "new.npz")


def test_the_observers_noise_hint_includes_the_quantization() -> None:
    """A noise-free 12-bit encoder was hinted as σ = 0 (the observers then trust each rounded
    sample: kf 0.436 rad/s, adaptive 0.155, ekf 3.6e-3 over 3-6 s on a UR5, seed 0); the hint is
    now √(σ² + Δ²/12), Δ = 2π/2¹²: 0.025, 1.2e-4, 1.0e-4 measured."""
    sensor = Sensor(1000.0, 0.0, bits=12)
    assert sensor.effective_std == pytest.approx(2 * np.pi / 4096 / np.sqrt(12), rel=1e-12)
    assert Sensor(1000.0, 3e-4).effective_std == 3e-4
    robot = pinobs.load("ur5")
    res = simulate(robot, ["kf", "ekf"], duration=6.0, sensor=sensor, seed=0)
    late = res.t > 3.0
    rms = {tr.name: np.sqrt(np.mean((tr.v[late] - res.v[late]) ** 2)) for tr in res.traces}
    assert rms["kf"] < 0.05 and rms["ekf"] < 5e-4, rms


@pytest.mark.slow  # 100k RK4 steps at 50 substeps, and the friction splits: 30-60 s
def test_the_plant_splits_its_steps_where_coulomb_friction_is_stiff() -> None:
    """Fixed RK4 steps are unstable on the smoothed Coulomb slope: a double pendulum with
    3 N·m of it chattered to |v| = 3.57 rad/s at one step per sample (0.071 at 50), silently,
    from t = 0.16 s on (measured on the plant before the split, 041a0dd~1).
    The plant now takes the EKF's friction substeps: max |v| 0.01513 at one step per sample,
    0.01512 at 20, 50 and 200 (and with 1000 fixed steps before), at t = 0.955 s, seed 0.
    Two seconds at 50 substeps hold both (the test ran 4 s at 200 before: 205 s of a CI run)."""
    robot = pinobs.load("double_pendulum")
    plant = robot.perturbed(name="coulomb", coulomb=np.full(robot.nv, 3.0))
    peak = []
    for substeps in (1, 50):
        res = simulate(robot, [], duration=2.0, sensor=Sensor(1000.0, 1e-4), plant=plant,
                       seed=0, substeps=substeps)  # fmt: skip
        peak.append(np.abs(res.v).max())
    assert peak[0] < 0.02 and peak[0] == pytest.approx(peak[1], rel=0.01), peak

"""The adaptive observer: learns its model online, never far behind the model-free filter."""

from __future__ import annotations

import numpy as np
import pytest

import pinobs
from pinobs.errors import IdentificationError
from pinobs.observers import make_observer
from pinobs.simulation import Sensor
from pinobs.simulation.mismatch import mismatched_plant


def _rms_after(res, trace, t0: float) -> float:
    k = int(np.searchsorted(res.t, t0))
    return float(np.sqrt(np.mean((trace.v[k:] - res.v[k:]) ** 2)))


def test_started_on_the_truth_noise_free_it_stays_there() -> None:
    """Exact model, no noise: the first solve ends the warm-up, the filter's innovations then
    say the nominal model explains the data, so no fitted model replaces it (before that
    rule, models fitted to Savitzky-Golay velocities moved the estimate by 3.5e-4 rad/s)."""
    robot = pinobs.load("cartpole")
    obs = {"a": make_observer("adaptive", robot, rate=1000.0)}
    res = pinobs.simulate(robot, obs, duration=3.0, sensor=Sensor(rate=1000.0), seed=2)
    err = np.abs(res.trace("a").v - res.v).max(axis=1)
    assert err.max() < 1e-8
    details = obs["a"].consistency().details
    assert details["solves"] >= 4 and details["installs"] == 0 and details["regime"] == "nominal"


@pytest.mark.parametrize("name", ["cartpole", "planar_3r"])
def test_learns_a_payload_and_beats_the_best_model_free_filter(name: str) -> None:
    """Truth: links ±20 % and a payload; 8 s at 1 kHz, σ = 1e-4, from a wrong start.

    Measured (seed 2): cart-pole adaptive 7.7e-4 rad/s against the best kf 5.2e-3
    (0.15×), planar_3r 2.0e-3 against 4.1e-3 (0.47×); the plain ekf 0.36 and 5.9.
    """
    robot = pinobs.load(name)
    plant = mismatched_plant(robot, "inertia20_payload", seed=0)
    obs = {
        "adaptive": make_observer("adaptive", robot, rate=1000.0, noise_std=1e-4),
        "ekf": make_observer("ekf", robot, rate=1000.0, noise_std=1e-4),
    }
    for j in (1e1, 1e2, 1e3, 1e4):
        obs[f"kf{j:g}"] = make_observer("kf", robot, rate=1000.0, noise_std=1e-4, jerk_psd=j)
    res = pinobs.simulate(
        robot,
        obs,
        duration=8.0,
        sensor=Sensor(rate=1000.0, noise_std=1e-4),
        seed=2,
        plant=plant,
        perturb_q=0.05,
        perturb_v=0.5,
    )
    best_kf = min(_rms_after(res, res.trace(k), 5.0) for k in obs if k.startswith("kf"))
    adaptive = _rms_after(res, res.trace("adaptive"), 5.0)
    assert adaptive < 0.6 * best_kf
    assert _rms_after(res, res.trace("ekf"), 5.0) > 10 * best_kf  # the problem is real
    learner = obs["adaptive"]
    assert learner.consistency().details["installs"] >= 1
    # what it learned is closer to the truth than the nominal model
    learned = learner.learned_robot()
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = robot.random_configuration(rng, scale=0.5)
        m_true = plant.mass_matrix(q)
        assert (
            np.abs(learned.mass_matrix(q) - m_true).max()
            < np.abs(robot.mass_matrix(q) - m_true).max()
        )
    params = learner.parameters()
    assert len(params.names) == len(params.values) == len(params.std)
    assert np.all(params.std > 0)


def test_a_failed_solve_keeps_the_last_model_and_says_so(monkeypatch) -> None:
    import pinobs.observers.adaptive_learner as adaptive_learner

    def fail(*args, **kwargs):
        raise IdentificationError("simulated failure")

    monkeypatch.setattr(adaptive_learner, "solve", fail)
    robot = pinobs.load("cartpole")
    ob = make_observer("adaptive", robot, rate=1000.0, noise_std=1e-4)
    res = pinobs.simulate(
        robot, {"a": ob}, duration=2.0, sensor=Sensor(rate=1000.0, noise_std=1e-4), seed=1
    )
    assert np.all(np.isfinite(res.trace("a").v))
    details = ob.consistency().details
    assert details["solves"] == 0 and details["warming_up"]
    assert any("simulated failure" in r for r in details["rejected"])
    np.testing.assert_array_equal(ob.parameters().values, ob.parameters().nominal)


@pytest.mark.parametrize(
    "option, value",
    [
        ("window", 0.0),
        ("horizon", 0.1),
        ("resolve_every", -1.0),
        ("accel_psd", "x"),
        ("blend_time", float("nan")),
        ("learned_disturbance_psd", 0.0),
    ],
)
def test_out_of_range_options_raise_gain_error(option: str, value: object) -> None:
    with pytest.raises(pinobs.GainError):
        make_observer("adaptive", pinobs.load("cartpole"), rate=1000.0, **{option: value})


@pytest.mark.parametrize("name", ["ur5", "top"])
def test_the_kf_bank_equals_separate_kf_filters(name: str) -> None:
    from pinobs.observers.kf import KFBank

    robot = pinobs.load(name)
    res = pinobs.simulate(
        robot, [], duration=0.5, sensor=Sensor(rate=1000.0, noise_std=1e-4, dropout=0.1), seed=0
    )
    jerks = (1e1, 1e3, 1e5)
    bank = KFBank(robot, jerks, 1e-4)
    state = bank.initial(res.q[0], res.v[0], 1.0)
    singles = [  # without their outlier gate: the bank steps what adaptive's gate keeps
        make_observer("kf", robot, jerk_psd=j, noise_std=1e-4, outlier_probability=None)
        for j in jerks
    ]
    for ob in singles:
        ob.reset(0.0, res.q[0], res.v[0])
    for k in range(1, len(res.t)):
        qm = None if np.isnan(res.q_meas[k]).any() else res.q_meas[k]
        state = bank.step(state, res.t[k] - res.t[k - 1], qm)
        for i, ob in enumerate(singles):
            est = ob.update(res.t[k], qm)
            np.testing.assert_allclose(state.v[i], est.v, rtol=0, atol=1e-12)
            np.testing.assert_allclose(state.q[i], est.q, rtol=0, atol=1e-12)


def test_a_lost_model_based_filter_restarts_instead_of_failing() -> None:
    """Learning without friction columns on a truth with strong friction: the learned model
    cannot hold, and its EKF diverged (ObserverDiverged at 4.2 s on the UR5, seed 1) before
    the restart rule; now it restarts on the kf bank and the estimate stays finite.  After a
    restart the blend follows the kf until a solve replaces the model: before that rule the
    estimate reached 1.1 rad/s of error at the restart at 4.19 s, and with the compiled bank's
    different rounding the blend itself overflowed (5.5 s); now 0.04 rad/s at most after 1 s."""
    robot = pinobs.load("ur5")
    plant = mismatched_plant(robot, "friction", seed=0)
    ob = make_observer("adaptive", robot, rate=1000.0, noise_std=1e-4, friction=False)
    res = pinobs.simulate(
        robot,
        {"a": ob},
        duration=6.0,
        sensor=Sensor(rate=1000.0, noise_std=1e-4),
        seed=1,
        plant=plant,
    )
    trace = res.trace("a")
    assert trace.diverged_at is None and np.all(np.isfinite(trace.v))
    assert ob.consistency().details["restarts"] >= 1
    assert _rms_after(res, trace, 1.0) < 0.05
    k = int(np.searchsorted(res.t, 1.0))
    assert np.abs(trace.v[k:] - res.v[k:]).max() < 0.1


def _ur5_at_rest_for_4_ms():
    """``adaptive`` on a UR5 held at its neutral pose against gravity, 4 updates in."""
    robot = pinobs.load("ur5")
    ob = make_observer("adaptive", robot, rate=1000.0, noise_std=1e-4)
    q0 = robot.neutral()
    ob.reset(0.0, q0, np.zeros(robot.nv))
    tau = robot.gravity(q0)
    for k in range(1, 5):
        ob.update(k * 1e-3, q0, tau)
    return ob, q0, tau


def test_a_filter_step_that_raises_is_a_lost_filter_restarted(monkeypatch) -> None:
    """A model-based step that raises (``LinAlgError`` from a singular innovation covariance:
    on a UR10e log at 95 Hz the warm-up filter's velocity variance reached 6e10 first) is a
    lost filter: restarted on the kf bank, the update returns a finite estimate, as for a
    step that returns NaN.  Before, the error escaped ``update``."""
    from pinobs.observers.ekf import ExtendedKalmanFilter

    ob, q0, tau = _ur5_at_rest_for_4_ms()
    step = ExtendedKalmanFilter.step
    calls = {"n": 0}

    def raising_once(self, *args):
        calls["n"] += 1
        if calls["n"] == 1:
            raise np.linalg.LinAlgError("Singular matrix")
        return step(self, *args)

    monkeypatch.setattr(ExtendedKalmanFilter, "step", raising_once)
    ob._fused_path = False  # (the patched step: the fused update never calls it)
    est = ob.update(5e-3, q0, tau)
    assert calls["n"] == 2  # the raising step, then the restarted filter's
    assert ob.restarts == 1 and np.all(np.isfinite(est.v))
    assert np.abs(est.v).max() < 1e-2  # at rest: the restart is on the bank's estimate


def _sines(robot, h: float, seconds: float, rng):
    """A known truth at ``1/h`` Hz: a sine per joint (0.3 rad), positions as a real logger
    prints them (σ = 3e-5 rad, rounded to 1e-4 rad: the UR10e logs of benchmarks/real_logs.py)."""
    t = np.arange(int(seconds / h)) * h
    w, ph = rng.uniform(0.5, 2.0, robot.nv), rng.uniform(0.0, 6.0, robot.nv)
    q = 0.3 * np.sin(w * t[:, None] + ph)
    q_meas = np.round(q + 3e-5 * rng.standard_normal(q.shape), 4)
    return t, q_meas, 0.3 * w * np.cos(w * t[:, None] + ph)


def _run(ob, t, q_meas, tau) -> np.ndarray:
    ob.reset(t[0], q_meas[0])
    v = np.zeros((t.size, ob.robot.nv))
    for k in range(1, t.size):
        v[k] = ob.update(t[k], q_meas[k], tau).v
    return v


def test_a_model_that_does_not_hold_does_not_starve_the_kf_bank(monkeypatch, rng) -> None:
    """A model that does not hold (the UR10e logs of ``benchmarks/real_logs.py``: a learned
    model lost the model-based filter every 2-4 steps): restarted on the bank's estimate and
    wrong again at once, that filter's gate rejected the samples for the bank too (240 of 706
    on ur-19_09_27-15_11_06), whose variance then grew and gave the lost filter weight in the
    blend: adaptive 3.4x kf there.  Here the filter is broken on purpose (20 rad/s off at each
    step, lost at every third): the blend stays near the kf (measured: 1.05x; 1.35x before)."""
    from pinobs.observers.ekf import ExtendedKalmanFilter

    step = ExtendedKalmanFilter.step
    calls = {"n": 0}

    def broken(self, state, dt, q, tau):
        calls["n"] += 1
        new = step(self, state, dt, q, tau)
        if calls["n"] % 3 == 0:
            return new._replace(v=np.full_like(new.v, np.nan))
        return new._replace(v=new.v + 20.0)

    robot = pinobs.load("ur5")
    t, q_meas, v = _sines(robot, 0.01, 4.0, rng)
    tau = np.zeros(robot.nv)
    kf = _run(make_observer("kf", robot, rate=100.0, noise_std=3e-5), t, q_meas, tau)
    monkeypatch.setattr(ExtendedKalmanFilter, "step", broken)
    ob = make_observer("adaptive", robot, rate=100.0, noise_std=3e-5)
    ad = _run(ob, t, q_meas, tau)
    after = t >= 1.0
    rms = {k: float(np.sqrt(np.mean((x - v)[after] ** 2))) for k, x in (("kf", kf), ("ad", ad))}
    assert ob.restarts > 100  # lost all along, as on the UR10e logs
    assert rms["ad"] <= 1.2 * rms["kf"]  # issue 36's bound


def test_a_filter_whose_velocity_squared_overflows_is_lost(monkeypatch) -> None:
    """A model-based filter at 1e200 rad/s is finite, but the blend squares its disagreement
    with the bank: ``inf − inf`` made the estimate NaN (a UR10e log: ``pinobs.estimate`` then
    re-initialised the whole observer mid-log, 0.67 rad/s against the kf's 0.005).  It is a
    lost filter: restarted, the estimate stays finite and on the bank's."""
    from pinobs.observers.ekf import ExtendedKalmanFilter

    ob, q0, tau = _ur5_at_rest_for_4_ms()
    step = ExtendedKalmanFilter.step
    calls = {"n": 0}

    def overflowing_once(self, *args):
        calls["n"] += 1
        new = step(self, *args)
        return new._replace(v=np.full_like(new.v, 1e200)) if calls["n"] == 1 else new

    monkeypatch.setattr(ExtendedKalmanFilter, "step", overflowing_once)
    ob._fused_path = False  # (the patched step: the fused update never calls it)
    est = ob.update(5e-3, q0, tau)
    assert ob.restarts == 1 and np.all(np.isfinite(est.v))
    assert np.abs(est.v).max() < 1e-2  # at rest: the restart is on the bank's estimate


def test_a_filter_lost_at_once_on_the_nominal_model_leaves_the_estimate_on_the_bank(
    monkeypatch,
) -> None:
    """A model-based filter lost at every step, also when restarted on the nominal model:
    it stays at its restart (the bank's estimate, finite) and the update's estimate is the
    bank's; before, its NaN reached the blend and the update raised ``ObserverDiverged``."""
    from pinobs.observers.ekf import ExtendedKalmanFilter

    robot = pinobs.load("ur5")
    ob = make_observer("adaptive", robot, rate=1000.0, noise_std=1e-4)
    q0 = robot.neutral()
    ob.reset(0.0, q0, np.zeros(robot.nv))
    tau = robot.gravity(q0)
    step = ExtendedKalmanFilter.step

    def lost(self, *args):
        new = step(self, *args)
        return new._replace(v=np.full_like(new.v, np.nan))

    monkeypatch.setattr(ExtendedKalmanFilter, "step", lost)
    for k in range(1, 20):
        est = ob.update(k * 1e-3, q0, tau)
        assert np.all(np.isfinite(est.v)) and np.abs(est.v).max() < 1e-2  # at rest
    assert ob.restarts == 19


def _massless_tip():
    """planar_3r with a massless tip: ``M(q)`` singular along joint3 at every ``q``."""
    import pinocchio as pin

    nominal = pinobs.load("planar_3r")
    model = nominal.model.copy()
    model.inertias[3] = pin.Inertia.Zero()
    model.armature = np.zeros(model.nv)
    robot = nominal.with_model(model, name="planar_3r_massless_tip")
    assert np.linalg.eigvalsh(robot.mass_matrix(robot.neutral()))[0] == 0.0
    return robot


def test_a_singular_mass_matrix_is_named_as_why_the_learner_has_no_rows(rng) -> None:
    """Every window left out for the singular nominal ``M(q)``: the solves fail for want of
    rows, and ``consistency()`` says so (the joint and the URDF's inertias), not "check the
    torques" (it did: the TX40 of ``benchmarks/real_logs.py``, its link 6 massless)."""
    robot = _massless_tip()
    t, q_meas, _ = _sines(robot, 1e-3, 3.0, rng)  # (five solves: four in a row say it)
    ob = make_observer("adaptive", robot, rate=1000.0, noise_std=3e-5)
    _run(ob, t, q_meas, np.zeros(robot.nv))
    c = ob.consistency()
    assert c.verdict == "inconsistent" and c.details["rows"] == 0
    assert c.details["solves"] == 0
    (cause,) = c.causes
    assert cause.startswith("no rows to learn from")
    assert "M(q) is singular" in cause and "along joint 'joint3'" in cause
    assert "URDF's inertias" in cause and "signs, scales" not in cause


def test_a_nominal_model_with_a_singular_mass_matrix_leaves_the_estimate_on_the_bank(
    rng,
) -> None:
    """planar_3r with a massless tip (``M(q)`` singular, as the TX40's URDF loaded with
    ``check=False`` in ``benchmarks/real_logs.py``): the model-based filter is lost at every
    step and its restart kept (the update raised ``ObserverDiverged``), the identification
    windows, weighted by ``M(q)⁻¹``, are left out and said (their ``LinAlgError`` escaped the
    update): the estimate is the bank's, near the kf's (TX40: 1.02x kf, 110x before)."""
    robot = _massless_tip()
    t, q_meas, v = _sines(robot, 1e-3, 2.0, rng)
    tau = np.zeros(robot.nv)
    kf = _run(make_observer("kf", robot, rate=1000.0, noise_std=3e-5), t, q_meas, tau)
    ob = make_observer("adaptive", robot, rate=1000.0, noise_std=3e-5)
    ad = _run(ob, t, q_meas, tau)
    after = t >= 1.0
    rms = {k: float(np.sqrt(np.mean((x - v)[after] ** 2))) for k, x in (("kf", kf), ("ad", ad))}
    assert rms["ad"] <= 1.2 * rms["kf"]
    assert any("left out: Singular matrix" in r for r in ob.consistency().details["rejected"])


def test_adaptive_runs_inside_never_behind() -> None:
    """``make_observer("adaptive", never_behind=True)``: the wrapped observer is never reset
    itself (the blend is), so its learner starts at the first committed sample (it raised
    IndexError before).  Exact model, σ = 1e-4, 2 s at 1 kHz: the blend keeps adaptive's
    accuracy, far below the kf's (measured: 6.2e-5, 6.2e-5 and 5.0e-3 rad/s after 1 s)."""
    robot = pinobs.load("ur5")
    obs = {
        "nb": make_observer("adaptive", robot, rate=1000.0, noise_std=1e-4, never_behind=True),
        "alone": make_observer("adaptive", robot, rate=1000.0, noise_std=1e-4),
        "kf": make_observer("kf", robot, rate=1000.0, noise_std=1e-4),
    }
    res = pinobs.simulate(
        robot, obs, duration=2.0, sensor=Sensor(rate=1000.0, noise_std=1e-4), inputs="pd", seed=0
    )
    rms = {k: _rms_after(res, res.trace(k), 1.0) for k in obs}
    assert rms["nb"] <= 1.1 * rms["alone"]
    assert rms["alone"] < 0.1 * rms["kf"]
    assert obs["nb"].model.consistency().details["solves"] >= 2  # type: ignore[attr-defined]


def test_the_compiled_bank_and_blend_equal_the_numpy_ones(monkeypatch) -> None:
    """On vector joints the bank and the blend are compiled loops; the NumPy path (Lie-group
    robots) gives the same estimates on the same run, a payload error and sample dropouts."""
    import pinobs.observers.adaptive_blend as adaptive_blend
    import pinobs.observers.kf_kernels as kf_kernels

    robot = pinobs.load("planar_3r")
    plant = mismatched_plant(robot, "inertia20_payload", seed=0)
    sensor = Sensor(rate=1000.0, noise_std=1e-4, dropout=0.05)
    res = pinobs.simulate(robot, [], duration=1.5, sensor=sensor, seed=3, plant=plant)

    def run() -> np.ndarray:
        ob = make_observer("adaptive", robot, rate=1000.0, noise_std=1e-4)
        ob.reset(0.0, res.q[0], res.v[0], res.tau[0])
        out = [
            ob.update(res.t[k], None if np.isnan(qm).any() else qm, res.tau[k]).v
            for k, qm in enumerate(res.q_meas[1:], start=1)
        ]
        return np.array(out)

    compiled = run()
    assert adaptive_blend.bank_blend_kernel.compiled is not None
    assert kf_kernels.bank_kernel.compiled is not None
    monkeypatch.setattr(adaptive_blend.bank_blend_kernel, "compiled", None)
    monkeypatch.setattr(kf_kernels.bank_kernel, "compiled", None)
    for kernel in (adaptive_blend.bank_blend_kernel, kf_kernels.bank_kernel):
        monkeypatch.setattr(kernel, "load", lambda: None)  # (run() would reload it)
    np.testing.assert_allclose(compiled, run(), rtol=0, atol=1e-12)


def test_the_learners_edgeless_smoothing_equals_the_full_one_inside() -> None:
    """The learner keeps only samples ``half_window`` from both ends of what it smooths, so it
    skips the edge polynomial fits (``edges=False``); inside, the results are the same."""
    from pinobs.model.identification import smooth_path

    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=0.2, sensor=Sensor(rate=1000.0), seed=0)
    q = res.q + 1e-4 * np.random.default_rng(0).standard_normal(res.q.shape)
    full = smooth_path(robot, res.t, q, half_window=50)
    inner = smooth_path(robot, res.t, q, half_window=50, edges=False)
    for a, b in zip(full, inner, strict=True):
        np.testing.assert_allclose(a[50:-50], b[50:-50], rtol=0, atol=1e-12)
        assert not np.allclose(a[:50], b[:50])  # the edges differ: the option does something


def test_friction_too_weak_to_be_stiff_is_a_held_input_and_started_on_the_truth_stays_there() -> (
    None
):
    """A learned friction whose slope cannot make the prediction stiff (λh ≤ 0.1) is given to
    the filter as a torque held over each step, not put in its model (whose stiff-friction
    path costs substeps): the filter's model has none, ``learned_robot()`` has all of it, and
    on a noise-free truth that *is* the learned robot the filter started there stays there.

    Measured (UR5, seed 4): 1.7e-5 rad/s at most after the tenth step with the friction at
    the extrapolated mid-step velocity; held at the step's start velocity, above 3e-4.  The first
    step has no previous one to extrapolate from (7e-4)."""
    robot = pinobs.load("ur5")
    ob = make_observer("adaptive", robot, rate=1000.0, blend=False)
    lr = ob._learner
    n, nj = lr.reg.n_inertial, lr.reg.n_joint
    theta = lr.nominal.copy()
    theta[n : n + nj] = 0.05  # viscous [N·m·s/rad]
    theta[n + nj : n + 2 * nj] = 0.01  # Coulomb [N·m]: slope 1 N·m·s/rad at v = 0
    truth = lr.reg.with_parameters(theta)
    res = pinobs.simulate(truth, [], duration=0.45, sensor=Sensor(rate=1000.0), seed=4)
    ob.reset(0.0, res.q[0], res.v[0], res.tau[0])
    lr = ob._state.learner  # a reset starts a new learner
    lr.theta = theta
    lr.minv_max = np.diag(np.linalg.inv(truth.mass_matrix(res.q[0])))
    model, ekf = ob._install(ob._state.model, lr, ob._state.ekf)
    ob._state = ob._state._replace(model=model, ekf=ekf)
    assert model.held is not None and np.all(model.held == 1.0)
    assert not model.core.robot.has_friction and ob.learned_robot().has_friction
    v = np.array([1.0, -0.5, 0.003, 0.0, -0.01, 2.0])
    np.testing.assert_allclose(
        ob.learned_robot().friction_torque(v), truth.friction_torque(v), rtol=0, atol=1e-15
    )
    err = np.array(
        [
            np.abs(ob.update(res.t[k], res.q[k], res.tau[k]).v - res.v[k]).max()
            for k in range(1, 450)
        ]
    )  # before the first solve (0.5 s)
    assert err[0] < 1e-3
    assert err[9:].max() < 5e-5


def _learn_over(robot, t, q, tau, v, rate):
    """The adaptive observer over a stream: (RMS after its first 2 s, its consistency)."""
    ob = make_observer("adaptive", robot, rate=rate, noise_std=1e-4)
    ob.reset(t[0], q[0], v[0], tau[0])
    out = np.array([ob.update(t[k], q[k], tau[k]).v for k in range(1, t.size)])
    late = t[1:] - t[0] > 2.0
    return float(np.sqrt(np.mean((out[late] - v[1:][late]) ** 2))), ob.consistency()


@pytest.fixture(scope="module")
def payload_stream():
    robot = pinobs.load("planar_3r")
    plant = mismatched_plant(robot, "inertia20_payload", seed=1)
    res = pinobs.simulate(robot, [], duration=3.5, sensor=Sensor(1000.0, 1e-4), seed=2, plant=plant)
    return robot, res.t[1:], res.q_meas[1:], np.array(res.tau[1:]), res.v[1:]


def test_learning_does_not_depend_on_where_the_clock_starts(payload_stream) -> None:
    """The first solve was at t = resolve_every, not after the reset: a clock 100 s behind
    never solved (RMS 12× worse on the UR5, 'consistent' all the same)."""
    robot, t, q, tau, v = payload_stream
    ref, c_ref = _learn_over(robot, t, q, tau, v, 1000.0)
    assert c_ref.details["solves"] >= 5
    for shift in (-100.0, 1.7e9):
        rms, c = _learn_over(robot, t + shift, q, tau, v, 1000.0)
        assert c.details["solves"] == c_ref.details["solves"], shift
        assert abs(rms / ref - 1.0) < 0.05, (shift, rms, ref)


def test_timestamp_jitter_and_another_rate_do_not_stop_the_learning(payload_stream) -> None:
    """Jitter of ±10 % of the interval cleared the learner's windows at every other sample
    (0 solves, silently); so did a 500 Hz stream without ``rate`` (1 kHz assumed).  The
    learner now takes jitter within ±h/2, the first interval when no rate is given, and the
    samples' own interval when ten in a row disagree with ``rate`` (said)."""
    robot, t, q, tau, v = payload_stream
    ref, c_ref = _learn_over(robot, t, q, tau, v, 1000.0)
    jitter = np.random.default_rng(0).uniform(-1e-4, 1e-4, t.size)
    rms, c = _learn_over(robot, t + jitter, q, tau, v, 1000.0)
    assert c.details["solves"] == c_ref.details["solves"] and rms < 3.0 * ref, (rms, ref)
    slow = slice(None, None, 2)  # the same motion sampled at 500 Hz
    ref500, c500 = _learn_over(robot, t[slow], q[slow], tau[slow], v[slow], 500.0)
    assert c500.details["solves"] >= 5 and not c500.details["rejected"]
    for rate in (None, 1000.0):
        rms, c = _learn_over(robot, t[slow], q[slow], tau[slow], v[slow], rate)
        assert c.details["solves"] == c500.details["solves"], rate
        # rate=1000 given: its windows start ten samples later, once the interval is known
        assert abs(rms / ref500 - 1.0) < (0.05 if rate is None else 0.5), (rate, rms, ref500)
        said = [r for r in c.details["rejected"] if "the samples come every 0.002 s" in r]
        assert len(said) == (rate is not None), c.details["rejected"]
    # every other sample lost (or gated) is not a slower stream: the interval stays 1/rate
    ob = make_observer("adaptive", robot, rate=1000.0, noise_std=1e-4)
    ob.reset(t[0], q[0], v[0], tau[0])
    for k in range(1, 1500):
        ob.update(t[k], q[k] if k % 2 or k > 1000 else None, tau[k])
    assert not [r for r in ob.consistency().details["rejected"] if "samples come" in r]
    assert ob._state.learner.h == 1e-3


@pytest.mark.parametrize("lost", [0.05, 0.2])
def test_lost_samples_do_not_stop_the_learning(payload_stream, lost: float) -> None:
    """A lost sample cleared the learner's buffer, whose windows need ~200 consecutive
    samples: with 2 % or more lost at random it never solved, stayed in its warm-up and fell
    behind kf (UR5 with a payload, 5 % lost: 0 solves in 12 s, 1.19× kf, 'consistent').  Up to
    three lost in a row are now interpolated.  Measured on that UR5 log: 23 solves, 0.049×
    kf (5 %), 0.053× (20 %).  Here (planar 3R, 3.5 s), against the log with none lost: 6
    solves each, RMS 1.54e-3 (none lost), 1.61e-3 (5 %), 1.68e-3 (20 %); 0 solves before."""
    robot, t, q, tau, v = payload_stream
    ref, c_ref = _learn_over(robot, t, q, tau, v, 1000.0)
    drop = np.random.default_rng(0).random(t.size) < lost
    drop[0] = False
    ob = make_observer("adaptive", robot, rate=1000.0, noise_std=1e-4)
    ob.reset(t[0], q[0], v[0], tau[0])
    out = np.array([ob.update(t[k], None if drop[k] else q[k], tau[k]).v for k in range(1, t.size)])
    late = t[1:] - t[0] > 2.0
    rms = float(np.sqrt(np.mean((out[late] - v[1:][late]) ** 2)))
    c = ob.consistency()
    assert c.details["solves"] >= c_ref.details["solves"] - 1, (c.details, c_ref.details)
    assert rms < 2.0 * ref, (rms, ref)


def test_a_learned_model_lost_again_at_its_restart_falls_back_to_the_nominal_one(
    payload_stream, monkeypatch
) -> None:
    """A restart kept the learned model; when that model itself could not be stepped (solo12
    with friction, a Panda at hard stops: a mass matrix not positive definite away from the
    configurations its solve checked), the restarted filter was lost at once and ObserverDiverged
    was raised.  Now the learned model is dropped for the nominal one, said, and the estimate
    goes on.  Here the filter on a learned model returns a NaN velocity from 2 s on (its
    torque was made non-finite, through ``_torque``, before the step took ``τ + b̂`` inline)."""
    from pinobs.observers.ekf import ExtendedKalmanFilter

    robot, t, q, tau, v = payload_stream
    ob = make_observer("adaptive", robot, rate=1000.0, noise_std=1e-4)
    ob.reset(t[0], q[0], v[0], tau[0])
    step, clock = ExtendedKalmanFilter.step, {"t": 0.0}

    def broken(self, state, dt, q_, tau_):  # type: ignore[no-untyped-def]
        new = step(self, state, dt, q_, tau_)
        lost = self.robot.name.endswith("~learned") and clock["t"] >= 2.0
        return new._replace(v=np.full_like(new.v, np.nan)) if lost else new

    monkeypatch.setattr(ExtendedKalmanFilter, "step", broken)
    ob._fused_path = False  # (the patched step: the fused update never calls it)
    out = []
    for k in range(1, t.size):
        clock["t"] = t[k - 1] - t[0]  # the state's time, since the reset
        out.append(ob.update(t[k], q[k], tau[k]).v)
    out = np.array(out)
    details = ob.consistency().details
    assert np.all(np.isfinite(out))
    assert any("learned model dropped" in r for r in details["rejected"]), details["rejected"]
    assert ob.restarts >= 1
    late = t[1:] - t[0] > 3.0
    assert np.sqrt(np.mean((out[late] - v[1:][late]) ** 2)) < 0.05


def test_when_no_physical_model_fits_the_model_is_blamed_and_the_verdict_says_so() -> None:
    """A UR5 whose wrist_2 torque is logged with the wrong sign: every solve gives a mass
    matrix that is not positive definite and is rejected, so the learner never left its
    warm-up; the offset state absorbed the wrong torque below the NIS bound, the blend trusted
    the model, and adaptive was 1.02x kf over 5-12 s (1.26-1.48x per second), reading
    'consistent' (seed 1).  After four rejected solves in a row the model is now blamed (the
    blend goes to the kf where they disagree) and the verdict is 'inconsistent', naming it.
    Measured on that log: 0.49x kf.  Here (6 s, RMS after 3 s): 5.2e-3 against kf 1.16e-2."""
    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=6.0, sensor=Sensor(1000.0, 1e-4), seed=1)
    flip = np.ones(6)
    flip[4] = -1.0
    t, q, v = res.t[1:], res.q_meas[1:], res.v[1:]
    tau = np.array(res.tau[1:]) * flip
    out = {}
    # kf at the fixed density of the numbers above (its default, "auto", scores 5.3e-3
    # here, as adaptive does)
    for name, opts in (("adaptive", {}), ("kf", {"jerk_psd": 1e3})):
        ob = make_observer(name, robot, rate=1000.0, noise_std=1e-4, **opts)
        ob.reset(t[0], q[0], v[0], tau[0])
        est = np.array([ob.update(t[k], q[k], tau[k]).v for k in range(1, t.size)])
        late = t[1:] > 3.0
        out[name] = (float(np.sqrt(np.mean((est[late] - v[1:][late]) ** 2))), ob.consistency())
    rms, c = out["adaptive"]
    assert c.details["solves"] == 0 and len(c.details["rejected"]) >= 4
    assert c.verdict == "inconsistent" and "no physical model fits" in c.causes[0]
    # the solves' own reason, not the latest entry of `rejected` (a filter restart, on the
    # UR10e logs of benchmarks/real_logs.py); and the torques blamed, as they should be here
    assert "not positive definite in solve" in c.causes[0] and "signs, scales" in c.causes[0]
    assert rms < 0.75 * out["kf"][0], (rms, out["kf"][0])


def test_the_warm_up_ends_at_the_first_solve_whatever_the_last_bit_of_the_positions() -> None:
    """``benchmarks/run_bench.py``'s UR5 16-bit cell read 2.65e-5 rad/s on one CPU and 2.93e-4
    on another (11×): the first solve (0.5 s, 18 rows of rank 18, fitted exactly: its residual
    scale is rounding) came out unphysical on one, so the warm-up waited for the next solve
    and its transient fell in the scored window.  With the positions moved by one ulp (random
    signs) that solve was unphysical in 6 of 19 draws.  An unphysical solve that fits its rows
    exactly only validates now (``Learner._inconclusive``): the warm-up ends at 0.5 s in every
    draw, and the velocity error over 0.6-1.2 s stays within 1.5x of the unperturbed run's.
    Before, here: 4 of the 8 draws waited, 3.1e-3 against 1.2e-4 rad/s (26x)."""
    robot = pinobs.load("ur5")
    sensor = Sensor(1000.0, 0.0, bits=16)
    noise = 2.0 * np.pi / 2**16 / np.sqrt(12.0)  # (the bench's: quantization res/√12)
    res = pinobs.simulate(robot, [], duration=1.2, sensor=sensor, inputs="pd", seed=0)
    t, q, v, tau = res.t, res.q_meas, res.v, res.tau
    rng = np.random.default_rng(0)
    scored = t >= 0.6
    regimes, rms = [], []
    for draw in range(8):
        qd = q if draw == 0 else q + rng.integers(-1, 2, q.shape) * np.spacing(q)
        ob = make_observer("adaptive", robot, rate=1000.0, noise_std=noise)
        ob.reset(t[0], q[1], np.zeros(robot.nv), tau[0])
        est = [np.zeros(robot.nv)]
        for k in range(1, t.size):
            est.append(ob.update(t[k], qd[k], tau[k]).v)
            if abs(t[k] - 0.55) < 1e-9:
                regimes.append((ob.regime, ob.consistency().details["rejected"]))
        est_v = np.array(est)
        rms.append(float(np.sqrt(np.mean((est_v[scored] - v[scored]) ** 2))))
    assert all(regime == "nominal" for regime, _ in regimes), regimes
    assert max(rms) < 1.5 * rms[0] and min(rms) > rms[0] / 1.5, rms

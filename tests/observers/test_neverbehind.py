"""The never-behind blend (pinobs.observers.neverbehind): a model-based family and kf per joint."""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import pytest

import pinobs
from pinobs.errors import GainError, ObserverDiverged, OptionError
from pinobs.evaluation import evaluate
from pinobs.model.sampling import UNIFORM_TOL
from pinobs.observers import make_observer
from pinobs.observers.ekf import ExtendedKalmanFilter
from pinobs.observers.neverbehind import (
    CONSISTENT,
    FAR_GATE,
    LOG_BOUNDS,
    LOG_CHI2_MEAN,
    PRIOR,
    TRUSTED_PRIOR,
    NeverBehind,
    claims_within_kf,
    clipped_log_chi2_mean,
    kf_velocity_variance,
    match_density,
    model_velocity_variance,
)
from pinobs.simulation import Sensor, simulate

FAMILIES = ["ekf", "riemannian", "kalman"]


def _rms(res: pinobs.simulation.Result, robot: pinobs.Robot) -> dict[str, float]:
    return {m.observer: m.rms_v_error for m in evaluate(res, robot)}


@pytest.mark.parametrize("family", FAMILIES)
def test_blend_started_on_the_truth_stays_on_it(family: str) -> None:
    """Noise-free, on the truth, exact model: the blend is the family's own estimate (which
    its own tests hold on the truth: kalman's practical form is 2e-6 off at 1 kHz)."""
    robot = pinobs.load("ur5")
    ob = make_observer(family, robot, never_behind=True, noise_std=0.0)
    alone = make_observer(family, robot, noise_std=0.0)
    res = simulate(
        robot,
        {"nb": ob, "alone": alone},
        sensor=Sensor(1000, 0.0),
        inputs="pd",
        duration=0.5,
        seed=1,
    )
    assert isinstance(ob, NeverBehind)
    assert np.abs(res.trace("nb").v - res.trace("alone").v).max() < 1e-10
    assert np.abs(res.trace("nb").v - res.v).max() < 1e-5  # measured 3e-14, 3e-14, 2.2e-6
    assert ob.reseeds == 0
    assert np.all(ob.weights > 1.0 - 1e-12)


def test_blend_converges_from_a_perturbed_start() -> None:
    robot = pinobs.load("ur5")
    ob = make_observer("ekf", robot, never_behind=True, noise_std=0.0)
    res = simulate(
        robot,
        {"nb": ob},
        sensor=Sensor(1000, 0.0),
        inputs="pd",
        duration=0.5,
        perturb_q=0.1,
        perturb_v=0.5,
        seed=2,
    )
    err = np.abs(res.trace("nb").v - res.v)
    assert err[0].max() > 0.1
    assert err[res.t > 0.3].max() < 1e-8


def test_blend_keeps_the_exact_model_accuracy() -> None:
    robot = pinobs.load("ur5")
    obs = {
        "ekf": make_observer("ekf", robot, rate=1000, noise_std=1e-4),
        "nb": make_observer("ekf", robot, rate=1000, noise_std=1e-4, never_behind=True),
        "kf": make_observer("kf", robot, rate=1000, noise_std=1e-4),
    }
    res = simulate(robot, obs, sensor=Sensor(1000, 1e-4), inputs="pd", duration=2.0, seed=0)
    rms = _rms(res, robot)
    assert rms["nb"] <= 1.1 * rms["ekf"]  # measured 3.9e-5 both; kf 1.2e-2
    assert rms["ekf"] < 0.01 * rms["kf"]


def test_a_consistent_model_earns_the_prior_at_high_noise() -> None:
    """UR5, exact model, 1 kHz, σ = 1e-3 rad, seed 5 (``benchmarks/never_behind_exact.py``'s
    run, the observers fed the samples from ``q₀`` without a velocity): the one-step evidence
    for the model is weak (~7 nats a window) and dipped to ℓ = −0.6 at t = 1.55 s, where the
    kf's velocity is 440× worse.  With the data alone (``prior_log_odds=PRIOR``, the default
    before) the blend is 4.0× the ekf alone there, yet never behind the kf; by default the
    ekf's windowed NIS passes its test, the model earns ``TRUSTED_PRIOR`` and the blend keeps
    the ekf's accuracy, as that prior given (measured 1.001× both)."""
    robot = pinobs.load("ur5")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(robot, {}, duration=3.0, sensor=Sensor(1000, 1e-3), seed=5)
    t, q, tau, truth = res.t[1:], res.q_meas[1:], res.tau[1:], res.v[1:]
    rms = {}
    runs = {
        "alone": ("ekf", {}),
        "default": ("ekf", {"never_behind": True}),
        "data": ("ekf", {"never_behind": True, "prior_log_odds": PRIOR}),
        "trusted": ("ekf", {"never_behind": True, "prior_log_odds": TRUSTED_PRIOR}),
        "kf": ("kf", {}),
    }
    for label, (name, opts) in runs.items():
        ob = make_observer(name, robot, rate=1000, noise_std=1e-3, **opts)
        ob.reset(t[0], q[0], None, tau[0])
        v = np.array([ob.update(t[k], q[k], tau[k]).v for k in range(1, t.size)])
        rms[label] = float(np.sqrt(np.mean((v - truth[1:])[t[1:] > 1.0] ** 2)))
    assert rms["default"] <= 1.1 * rms["alone"]
    assert rms["trusted"] <= 1.1 * rms["alone"]
    assert rms["data"] > 2.0 * rms["alone"]  # the data alone: 4.5e-4 against 1.1e-4
    assert rms["data"] < rms["kf"]  # never behind it


def test_an_inconsistent_model_earns_no_prior() -> None:
    """Masses and inertias ×1.5 in the truth (UR5, 1 kHz, σ = 1e-4): the ekf's windowed NIS
    leaves its band and the prior is 0, as with the data alone: the same estimates."""
    robot = pinobs.load("ur5")
    truth = robot.perturbed(name="x1.5", inertia_scale=np.full(len(robot.joints), 1.5))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(robot, {}, duration=1.5, sensor=Sensor(1000, 1e-4), seed=2, plant=truth)
    t, q, tau = res.t[1:], res.q_meas[1:], res.tau[1:]
    runs = {}
    for label, p in (("default", CONSISTENT), ("data", PRIOR)):
        ob = make_observer("ekf", robot, rate=1000, noise_std=1e-4, never_behind=True,
                           prior_log_odds=p)  # fmt: skip
        ob.reset(t[0], q[0], None, tau[0])
        runs[label] = np.array([ob.update(t[k], q[k], tau[k]).v for k in range(1, t.size)])
        if label == "default":
            assert ob._state.nis > 10.0  # (measured: the band's top is ~1.1)
    late = t[1:] > 0.5
    np.testing.assert_array_equal(runs["default"][late], runs["data"][late])


def _blend_after(family: str, seconds: float, **options: Any) -> NeverBehind:
    """A blend of ``family`` fed ``seconds`` of an exact UR5 at 1 kHz, σ = 1e-4 (seed 3)."""
    robot = pinobs.load("ur5")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(robot, {}, duration=seconds, sensor=Sensor(1000, 1e-4), seed=3)
    t, q, tau = res.t[1:], res.q_meas[1:], res.tau[1:]
    ob = make_observer(family, robot, rate=1000, noise_std=1e-4, never_behind=True, **options)
    assert isinstance(ob, NeverBehind)
    ob.reset(t[0], q[0], None, tau[0])
    for k in range(1, t.size):
        ob.update(t[k], q[k], tau[k])
    return ob


@pytest.mark.parametrize("jerk_psd", ["auto", 10.0])
def test_kf_velocity_variance_is_its_own_covariance(jerk_psd: str | float) -> None:
    """The kf's velocity variance read by the blend (module docstring, **Prior**): the
    mixture's ``Σ_f w_fi (ĉ_fi P_f,vv + (v̂_fi − v̂ᵢ)²)`` of the auto bank (compiled, against
    NumPy on the bank's views: the same to rounding), a fixed density's ``P_vv``."""
    ob = _blend_after("ekf", 0.3, reference_options={"jerk_psd": jerk_psd})
    kf = ob._state.kf
    got = kf_velocity_variance(kf)
    assert got is not None and got.shape == (ob.robot.nv,)
    if jerk_psd == "auto":
        b, w = kf.bank, kf.w
        c = np.maximum(kf.A / kf.n, 1e-300)
        mean = np.sum(w * b.v, axis=0)
        want = np.sum(w * (c * b.P[:, 1, 1][:, None] + (b.v - mean) ** 2), axis=0)
    else:
        want = np.full(ob.robot.nv, kf.P[1, 1])
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0.0)
    assert np.all(got > 0.0)
    p_m = model_velocity_variance(ob._state.model, ob.robot.nv)
    assert p_m is not None
    for scale in (1.0, 1e9):  # (an exact ekf claims ~1e-3 of the kf's; ×1e9, more)
        m = ob._state.model._replace(P=ob._state.model.P * scale)
        assert claims_within_kf(m, kf, ob.robot.nv) == bool(np.all(scale * p_m <= got))
        assert claims_within_kf(m, kf, ob.robot.nv) == (scale == 1.0)


def test_a_consistent_model_claiming_worse_velocities_than_the_kf_earns_no_prior() -> None:
    """The prior is earned by a consistent model whose own velocity variance is at most the
    kf's on every joint (module docstring, **Prior**): an exact ekf claims ~1e-3 of the kf's
    (it earns it); the same state claiming 1e6 × its ``P`` does not (the identified UR10e
    model claims 3–19× the kf's, consistent: ``benchmarks/never_behind_weights.md``);
    riemannian under its Riccati schedule claims the schedule's ``P₁₁`` in every direction
    (the same rule, against the kf's smallest); without a schedule (constant gains) it keeps
    no covariance and is judged by its NIS alone."""
    ob = _blend_after("ekf", 0.3)
    st = ob._state
    nv = ob.robot.nv
    p_m = model_velocity_variance(st.model, nv)
    p_kf = kf_velocity_variance(st.kf)
    assert p_m is not None and p_kf is not None
    assert np.all(p_m < 0.01 * p_kf)
    h = 1e-3
    nis, prior = ob._earned_prior(1.0, st.model, st.kf, h)  # (ν̄ = 1: inside the band)
    assert prior == TRUSTED_PRIOR
    wide = st.model._replace(P=st.model.P * 1e6)
    assert np.all(model_velocity_variance(wide, nv) > p_kf)  # type: ignore[operator]
    assert ob._earned_prior(1.0, wide, st.kf, h) == (nis, PRIOR)
    rm = _blend_after("riemannian", 0.05)
    m = rm._state.model
    assert model_velocity_variance(m, nv) is None and m.P is not None  # (its schedule's)
    p_kf = kf_velocity_variance(rm._state.kf)
    assert p_kf is not None and m.P[2] < p_kf.min()  # (an exact model: ~1e-8 rad²/s³)
    assert rm._earned_prior(1.0, m, rm._state.kf, h)[1] == TRUSTED_PRIOR
    wide = m._replace(P=(m.P[0], m.P[1], 2.0 * float(p_kf.min())))
    assert rm._earned_prior(1.0, wide, rm._state.kf, h)[1] == PRIOR
    steady = _blend_after("riemannian", 0.05, alpha=60.0, beta=900.0)
    assert steady._state.model.P is None  # (given gains: no schedule, no covariance)
    assert steady._earned_prior(1.0, steady._state.model, steady._state.kf, h)[1] == TRUSTED_PRIOR


@pytest.mark.slow
@pytest.mark.parametrize("family", FAMILIES)
def test_blend_degrades_to_kf_with_a_grossly_wrong_model(family: str) -> None:
    """Masses and inertias ×3 in the truth: the family alone is lost, the blend is the kf."""
    robot = pinobs.load("ur5")
    truth = robot.perturbed(name="ur5x3", inertia_scale=np.full(len(robot.joints), 3.0))
    obs = {
        "alone": make_observer(family, robot, rate=1000, noise_std=1e-4),
        "nb": make_observer(family, robot, rate=1000, noise_std=1e-4, never_behind=True),
        "kf": make_observer("kf", robot, rate=1000, noise_std=1e-4),
    }
    res = simulate(
        robot, obs, sensor=Sensor(1000, 1e-4), inputs="pd", duration=2.0, seed=0, plant=truth
    )
    rms = _rms(res, robot)
    assert rms["alone"] > 10 * rms["kf"]
    assert rms["nb"] <= 1.2 * rms["kf"]


def test_a_sample_the_kf_rejects_and_the_next_are_not_scored() -> None:
    """An outlier of 0.05 rad on joint 1 (UR5, exact model, 1 kHz, σ = 1e-4): the kf rejects
    it and keeps its prediction, so at the next sample its one-step error is a two-step one:
    neither sample is scored (module docstring, **Gated**), the one after is."""
    robot = pinobs.load("ur5")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(robot, {}, duration=0.5, sensor=Sensor(1000, 1e-4), inputs="pd", seed=4)
    t, q, tau = res.t[1:], res.q_meas[1:].copy(), res.tau[1:]
    bad = 300
    q[bad, 1] += 0.05
    ob = make_observer("ekf", robot, rate=1000, noise_std=1e-4, never_behind=True)
    assert isinstance(ob, NeverBehind)
    ob.reset(t[0], q[0], None, tau[0])
    scores, gated = [], []
    for k in range(1, bad + 3):
        ob.update(t[k], q[k], tau[k])
        scores.append(np.array(ob._state.s))
        gated.append(ob.reference.innovation(ob._state.kf)[1])
    assert gated[bad - 1] and not gated[bad] and not any(gated[: bad - 1])
    assert np.array_equal(scores[bad - 1], scores[bad - 2])  # the rejected sample
    assert np.array_equal(scores[bad], scores[bad - 2])  # the next: the kf two steps ahead
    assert not np.array_equal(scores[bad + 1], scores[bad])  # the one after: scored


def test_blend_options_are_checked() -> None:
    robot = pinobs.load("ur5")
    with pytest.raises(OptionError, match="model-free"):
        make_observer("kf", robot, never_behind=True)
    with pytest.raises(OptionError, match="does not accept"):
        make_observer("ekf", robot, never_behind=True, jerk=1.0)
    with pytest.raises(OptionError, match="latency"):
        make_observer("ekf", robot, never_behind=True, latency=0.01)
    ob = make_observer("ekf", robot, never_behind=True, window=0.1, accel_psd=1e-6)
    assert isinstance(ob, NeverBehind)
    assert ob.options["window"] == 0.1
    assert ob.options["model_options"]["accel_psd"] == 1e-6
    assert ob.options["prior_log_odds"] == CONSISTENT
    with pytest.raises(GainError, match="prior_log_odds"):
        make_observer("ekf", robot, never_behind=True, prior_log_odds=-1.0)
    with pytest.raises(GainError, match="prior_log_odds"):
        make_observer("ekf", robot, never_behind=True, prior_log_odds="trusted")
    assert make_observer("ekf", robot, never_behind=True, prior_log_odds=PRIOR).prior == 0.0


def test_match_density_moves_toward_consistent_innovations(rng: np.random.Generator) -> None:
    """Innovations drawn with variance 100 S raise ψ, with 0.01 S lower it, with S keep it
    (in the mean of log: the fixed point), all within the bounds."""
    bounds = np.array([1e-6, 1e6])
    s = np.ones(3)
    scale = np.array([10.0, 0.1, 1.0])  # the innovations' std over √S
    psd: np.ndarray = np.ones(3)
    logs = []
    for _ in range(20000):
        e = scale * rng.standard_normal(3)
        psd = match_density(psd, e, s, 1e-3, window=0.1, bounds=bounds)
        logs.append(np.log(psd))
    assert psd[0] > 1e3 and psd[1] < 1e-3
    assert np.all((psd >= 1e-6) & (psd <= 1e6))
    assert abs(np.mean(np.array(logs)[:, 2])) < 1.0  # log ψ wanders about 0 (measured 0.2)


def test_learned_disturbance_ekf_started_on_the_truth_stays_on_it() -> None:
    robot = pinobs.load("ur5")
    ob = make_observer("ekf", robot, noise_std=0.0, disturbance_psd="auto")
    res = simulate(robot, {"auto": ob}, sensor=Sensor(1000, 0.0), inputs="pd", duration=0.5, seed=1)
    assert isinstance(ob, ExtendedKalmanFilter)
    assert np.abs(res.trace("auto").v - res.v).max() < 1e-8
    d = ob.disturbance
    assert d is not None
    np.testing.assert_allclose(d, 0.0, atol=1e-6)


@pytest.mark.slow
def test_learned_disturbance_ekf_absorbs_a_grossly_wrong_model() -> None:
    """Masses ×3 in the truth: the plain ekf is lost, the learned density follows the model's
    error (alone near the kf's level, blended at it); on the exact model it stays close to the
    plain ekf."""
    robot = pinobs.load("ur5")
    truth = robot.perturbed(name="ur5x3", inertia_scale=np.full(len(robot.joints), 3.0))
    rms = {}
    for label, plant in (("exact", None), ("x3", truth)):
        obs = {
            "ekf": make_observer("ekf", robot, rate=1000, noise_std=1e-4),
            "auto": make_observer("ekf", robot, rate=1000, noise_std=1e-4, disturbance_psd="auto"),
            "kf": make_observer("kf", robot, rate=1000, noise_std=1e-4),
            "auto+nb": make_observer(
                "ekf", robot, rate=1000, noise_std=1e-4, disturbance_psd="auto", never_behind=True
            ),
        }
        res = simulate(
            robot, obs, sensor=Sensor(1000, 1e-4), inputs="pd", duration=3.0, seed=0, plant=plant
        )
        rms[label] = _rms(res, robot)
    assert rms["x3"]["ekf"] > 10 * rms["x3"]["kf"]
    # alone the learned density absorbs the error (1.6e-2 against the plain ekf's 14) but is
    # 3.0× the kf (jerk_psd="auto", 5.2e-3; 1.3× the former fixed-density kf); blended, 1.0×
    assert rms["x3"]["auto"] <= 1e-2 * rms["x3"]["ekf"]
    assert rms["x3"]["auto+nb"] <= 1.1 * rms["x3"]["kf"]
    assert rms["exact"]["auto"] <= 1.5 * rms["exact"]["ekf"]  # measured 1.28× (5.1e-5)
    assert rms["exact"]["auto+nb"] <= 1.5 * rms["exact"]["ekf"]


def test_log_chi2_mean_constant_is_the_clipped_integral() -> None:
    """The written-out fixed point is the integral it stands for (recomputed here), and that
    integral is right: unclipped, ``E[log u] = −(γ + log 2)`` for ``u ~ χ²₁``; clipped, the
    same expectation by adaptive quadrature (scipy) of the density of ``y = log u``."""
    from scipy.integrate import quad

    assert LOG_CHI2_MEAN == pytest.approx(clipped_log_chi2_mean(*LOG_BOUNDS), rel=0, abs=1e-14)
    assert clipped_log_chi2_mean(-np.inf, np.inf) == pytest.approx(
        -(np.euler_gamma + np.log(2.0)), abs=1e-9
    )
    lo, hi = LOG_BOUNDS

    def density(y: float) -> float:
        return float(np.exp(0.5 * y - 0.5 * np.exp(y)) / np.sqrt(2.0 * np.pi))

    below = quad(density, -np.inf, lo)[0]
    inside = quad(lambda y: y * density(y), lo, hi)[0]
    above = quad(density, hi, np.inf)[0]
    assert lo * below + inside + hi * above == pytest.approx(LOG_CHI2_MEAN, abs=1e-9)


class NumpyBlend(NeverBehind):
    """The blend's step as NumPy computed it before the compiled kernels (issue 39): the
    reference the compiled step must equal bit for bit (its ``exp`` is NumPy's there too)."""

    def step(self, state: Any, dt: float, q_meas: Any, tau: Any) -> Any:
        r = self.robot
        flat = r.is_vector_space
        kf = self.reference.step(state.kf, dt, q_meas, tau)
        q_kf, v_kf = self.reference.output(kf)
        try:
            m = self.model.step(state.model, dt, q_meas, tau)
            q_m, v_m = self.model.output(m)
            lost = raised = not math.isfinite(sum(q_m.tolist()) + sum(v_m.tolist()))
            raised = False
        except (ObserverDiverged, np.linalg.LinAlgError, ArithmeticError):
            lost = raised = True
        s_m, s_k, c, d = state.s[0], state.s[1], state.c, state.d
        prior, nis = self.prior, state.nis
        if self._self_test and not raised:  # (the NIS test: NeverBehind's own, shared)
            nis, prior = self._earned_prior(nis, m, kf, dt)
        gated = self.reference.innovation(kf)[1] or self.reference.innovation(state.kf)[1]
        if not lost and q_meas is not None and not gated:  # (**Gated**: nor the next one)
            ahead = 0.0 if state.dt_prev <= 0 else 0.5 * dt * dt / state.dt_prev
            step_a = ahead * (state.v - state.v_prev)
            qm0, vm0 = self.model.output(state.model)
            qk0, vk0 = self.reference.output(state.kf)
            if flat:
                e_m = q_meas - (qm0 + dt * vm0 + step_a)
                e_k = q_meas - (qk0 + dt * vk0 + step_a)
            else:
                e_m = r.difference(r.integrate(qm0, dt * vm0 + step_a), q_meas)
                e_k = r.difference(r.integrate(qk0, dt * vk0 + step_a), q_meas)
            lam = min(1.0, dt / self.window)
            s_m = s_m + lam * (e_m * e_m - s_m)
            s_k = s_k + lam * (e_k * e_k - s_k)
            d = (1.0 - lam) * d + (e_k * e_k - e_m * e_m)
            c = c + lam * (1.0 - c)
            lost = c > 0.5 and bool(np.any(s_m > self.lost_ratio**2 * s_k))
        if not lost and c > 0.5 and q_meas is not None:
            lost = bool(np.any(dt * np.abs(v_m - v_kf) > FAR_GATE * np.sqrt(s_k / c)))
        reseeds = state.reseeds
        if lost:
            reseeds += 1
            m = self.model.initial_state(q_kf, v_kf)
            q_m, v_m = self.model.output(m)
            s_m = self.lost_ratio * s_k
            d = (s_k - s_m) / min(1.0, dt / self.window)
        w = self.weights_of(c, dt, s_m, s_k, d, float(prior)) if c > 0.0 else np.ones(r.nv)
        v = v_kf + w * (v_m - v_kf)
        q = q_kf + w * (q_m - q_kf) if flat else r.integrate(q_kf, w * r.difference(q_kf, q_m))
        return state._replace(
            model=m, kf=kf, s=np.array([s_m, s_k]), c=c, w=w, q=q, v=v, v_prev=state.v,
            dt_prev=dt, reseeds=reseeds, d=d, nis=nis,
        )  # fmt: skip

    def weights_of(self, c: float, dt: float, s_m: Any, s_k: Any, d: Any, p: float) -> Any:
        """The weights from the scores (module docstring, with **Irregular steps**)."""
        bound = 50.0  # the log-odds' bound and start-up prior (module docstring)
        floor = max(c * (self.noise_std or 0.0) ** 2, 1e-300)
        n = c * self.window / dt
        den = np.maximum(np.minimum(s_m, s_k), floor)
        ell = (self.sharpness * 0.5 * n) * (s_k - s_m) / den
        period = self._period_s  # a step off the grid: each innovation counted once
        if period is not None and abs(dt - period) > UNIFORM_TOL * period:
            ell = self.sharpness * 0.5 * c * d / den
        prior = p + (1.0 - c) * (bound - p)  # persistent (ℓ_p = p), then start-up
        ell = np.clip(ell + prior, -bound, bound)
        w = 1.0 / (1.0 + np.exp(-ell))
        w[ell <= -bound] = 0.0
        return w


def _run_blend(ob: NeverBehind, res: pinobs.simulation.Result) -> dict[str, np.ndarray]:
    """``ob`` fed ``res``'s samples (a dropped one as ``None``) with a stretch stamped off the
    grid (steps of 0.4 and 1.6 periods: the blend's **Irregular steps**), a pause sub-stepped
    (30 ms at 500 Hz) and one it restarts after (2 s, :meth:`~pinobs.observers.base.Observer.update`)."""
    t = np.array(res.t)
    off = np.arange(len(t) // 8, len(t) // 4)
    t[off] += 0.3 * (t[1] - t[0]) * (-1.0) ** off
    t[len(t) // 2 :] += 0.03
    t[3 * len(t) // 4 :] += 2.0
    ob.reset(t[0], res.q[0], res.v[0], res.tau[0])
    rows: dict[str, list[Any]] = {"q": [], "v": [], "w": [], "reseeds": []}
    for k in range(1, len(t)):
        qm = res.q_meas[k]
        est = ob.update(t[k], None if np.isnan(qm).any() else qm, res.tau[k])
        for key, x in (("q", est.q), ("v", est.v), ("w", ob.weights), ("reseeds", ob.reseeds)):
            rows[key].append(x)
    return {k: np.array(x) for k, x in rows.items()}


_IDENTITY_CASES = [
    ("ur5", "exact", "ekf", 1e-3),
    ("ur5", "exact", "riemannian", None),
    ("ur5", "x3", "ekf", 1e-3),
    ("ur5", "exact", "ekf", None),
    ("ur5", "exact", "kalman", 1e-3),
    ("ur5", "exact", "adaptive", None),
    ("ur5", "x3", "riemannian", None),
    ("ur5", "x3", "kalman", 1e-3),
    ("go1", "exact", "ekf", 1e-3),
    ("go1", "exact", "riemannian", None),
    ("go1", "exact", "kalman", 1e-3),
    ("go1", "exact", "adaptive", 1e-3),
]


@pytest.mark.parametrize(("robot_name", "plant", "family", "noise_std"), _IDENTITY_CASES)
def test_compiled_blend_equals_the_numpy_form_bit_for_bit(
    robot_name: str, plant: str, family: str, noise_std: float | None
) -> None:
    """The compiled step (score, log-odds and blend kernels) against :class:`NumpyBlend`:
    the same bits for every estimate, weight and re-seed count, noise given or learned, with
    dropped samples, a sub-stepped pause, a restart and (``x3``: masses ×3 in the truth) the
    re-seeding path."""
    robot = pinobs.load(robot_name)
    truth = None
    if plant == "x3":
        truth = robot.perturbed(name="x3", inertia_scale=np.full(len(robot.joints), 3.0))
    res = simulate(
        robot,
        {"kf": make_observer("kf", robot, noise_std=1e-3)},
        sensor=Sensor(500, 1e-3, dropout=0.05),
        inputs="pd",
        duration=1.5 if noise_std is None else 0.6,  # learned: σ̂ after 1 s of samples
        seed=3,
        plant=truth,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pinobs.errors.NoiseWarning)
        fast = _run_blend(NeverBehind(robot, observer=family, noise_std=noise_std), res)
        slow = _run_blend(NumpyBlend(robot, observer=family, noise_std=noise_std), res)
    if plant == "x3":
        assert fast["reseeds"][-1] > 0  # the path is taken (measured 7 ekf, 6 kalman)
    assert 0.0 < fast["w"].mean() < 1.0  # both sides weigh
    for key in fast:
        assert np.array_equal(fast[key], slow[key]), key

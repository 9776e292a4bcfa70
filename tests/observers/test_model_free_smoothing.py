"""The model-free smoother: the RTS smoother over ``kf`` (white jerk, no model)."""

from __future__ import annotations

import numpy as np
import pytest

from pinobs.errors import ConsistencyWarning, OptionError
from pinobs.io import Log, estimate_log
from pinobs.observers import kf_kernels, make_observer
from pinobs.observers.kf import KFBank, transition
from pinobs.simulation import Sensor, simulate
from pinobs.simulation.mismatch import mismatched_plant
from pinobs.smoothing import (
    JERK_GRID,
    Smoother,
    default_overlap,
    select_accel_psd,
    smooth,
    streaming_smoother,
)
from pinobs.smoothing.densities import forward_log_likelihood
from pinobs.smoothing.filters import prepare_log
from pinobs.smoothing.jerk import white_jerk_smooth
from pinobs.smoothing.logs import first_good, smoothing_arrays
from pinobs.smoothing.rts import log_rows
from tests.conftest import cached_robot


def _half_decade(x: float) -> bool:
    """``x`` is on the jerk grid or halfway between two of its decades (``select_density``'s refine)."""
    e = 2 * np.log10(x)
    return bool(abs(e - round(e)) < 1e-9)


def _white_jerk_batch(
    t: np.ndarray, y: np.ndarray, jerk: float, sigma: float, v0_std: float
) -> tuple[np.ndarray, np.ndarray]:
    """One direction's smoothed ``(v, var v)`` by conditioning the joint Gaussian of all states
    on all measurements (no recursion): ``x_k = (q, v, a)``, ``x_{k+1} = F x_k + w_k``
    (:func:`pinobs.observers.kf.transition`), prior ``x_0 ~ N((y_0, 0, 0), diag(σ², v0², (10
    v0)²))`` (the filter's start), ``y_k = q_k + n_k`` for ``k ≥ 1`` (NaN: dropped)."""
    n = t.size
    A = np.zeros((3 * n, 3 * n))  # x = A z, z = (x_0, w_1 .. w_{n-1})
    cov_z = np.zeros((3 * n, 3 * n))
    cov_z[:3, :3] = np.diag([sigma**2, v0_std**2, (10 * v0_std) ** 2])
    A[:3, :3] = np.eye(3)
    for k in range(1, n):
        F, Q = transition(t[k] - t[k - 1], jerk)
        A[3 * k : 3 * k + 3] = F @ A[3 * k - 3 : 3 * k]
        A[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] += np.eye(3)
        cov_z[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] = Q
    mean_x = A[:, :3] @ np.array([y[0], 0.0, 0.0])
    cov_x = A @ cov_z @ A.T
    rows = [3 * k for k in range(1, n) if np.isfinite(y[k])]
    C = np.zeros((len(rows), 3 * n))
    C[np.arange(len(rows)), rows] = 1.0
    S = C @ cov_x @ C.T + sigma**2 * np.eye(len(rows))
    gain = cov_x @ C.T @ np.linalg.inv(S)
    post = mean_x + gain @ (y[[r // 3 for r in rows]] - C @ mean_x)
    post_cov = cov_x - gain @ C @ cov_x
    return post[1::3], np.diag(post_cov)[1::3]


def test_model_free_smoother_is_the_batch_estimate_of_the_white_jerk_model(rng) -> None:
    """On a UR5 (``q ⊕ δ = q + δ``) every joint's smoothed velocity and its model band are
    those of the white-jerk model's joint Gaussian conditioned on all the samples, computed
    directly per joint (the smoother runs one ``3 nv`` state with ``P = P₃ ⊗ I``).  Uneven
    sample intervals; sample 4 dropped."""
    robot = cached_robot("ur5")
    t = np.cumsum(np.r_[0.0, rng.uniform(0.5e-3, 1.5e-3, 11)])
    q = rng.standard_normal((t.size, robot.nv)) * 1e-3
    q[4] = np.nan
    jerk, sigma = 1e4, 1e-3
    s = smooth(
        robot, (t, q), observer="kf", noise_std=sigma, band="model",
        filter_options={"jerk_psd": jerk, "v0_std": 0.5},
    )  # fmt: skip
    for i in range(robot.nv):
        v, var = _white_jerk_batch(t, q[:, i], jerk, sigma, 0.5)
        np.testing.assert_allclose(s.v[:, i], v, rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(s.v_std[:, i] ** 2, var, rtol=1e-8)
    assert s.options["jerk_psd"] == jerk and s.options["accel_psd"] is None


def test_model_free_smoother_ends_on_the_causal_kf_and_keeps_exact_motions() -> None:
    """The last sample is the causal ``kf``'s estimate; a noise-free motion the model holds
    exactly (constant acceleration on a UR5, a constant spin of the top on SO(3)) is
    smoothed to it from the first sample (the filter starts at v = 0)."""
    robot = cached_robot("ur5")
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 0.5, 1e-3)
    q0, v0, a = rng.standard_normal((3, robot.nv))
    q = q0 + np.outer(t, v0) + 0.5 * np.outer(t**2, a)
    noisy = q + 1e-4 * rng.standard_normal(q.shape)
    kf = make_observer("kf", robot, noise_std=1e-4, jerk_psd=10.0)
    causal = estimate_log(kf, Log(t=t, q=noisy, tau=np.zeros_like(q)))
    s = smooth(robot, (t, noisy), observer="kf", noise_std=1e-4, filter_options={"jerk_psd": 10.0})
    np.testing.assert_allclose(s.v[-1], causal.v[-1], rtol=0, atol=1e-12)
    assert np.abs(s.v[0] - causal.v[0]).max() > 0.5  # the filter's start, the smoother's use
    opts = {"filter_options": {"jerk_psd": 1e-2}, "noise_std": 1e-6}
    s = smooth(robot, (t, q), observer="kf", **opts)  # type: ignore[arg-type]
    assert np.abs(s.v - (v0 + np.outer(t, a))).max() < 1e-7  # measured 3.1e-8
    top = cached_robot("top")
    w = np.array([0.3, -0.2, 0.5])
    spin = np.array([top.integrate(top.neutral(), w * tk) for tk in t])
    s = smooth(top, (t, spin), observer="kf", **opts)  # type: ignore[arg-type]
    assert np.abs(s.v - w).max() < 1e-7  # measured 4.3e-9


def test_model_free_smoother_chunks_and_streams_like_the_whole_log() -> None:
    """Chunks with the default overlap (the white-jerk filter's memory: the triple
    integrator's, :func:`default_overlap`) agree with the whole log to 1e-5 of ``v_std``, and
    the streamed smoother is the chunked one."""
    robot = cached_robot("ur5")
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=2.0, seed=4)
    log = Log(t=res.t, q=res.q_meas, tau=res.tau)
    opts = {"observer": "kf", "noise_std": 1e-4, "filter_options": {"jerk_psd": 1e2}}
    whole = smooth(robot, log, band="model", **opts)  # type: ignore[arg-type]
    chunked = smooth(robot, log, band="model", chunk=0.4, **opts)  # type: ignore[arg-type]
    over = chunked.options["overlap"]
    assert over == pytest.approx(default_overlap(0.0, 1e-4, 1e-3, disturbance_psd=1e2), abs=1e-3)
    dv = np.abs(chunked.v - whole.v)[1:] / whole.v_std[1:]
    assert dv.max() < 1e-5
    make, _ = streaming_smoother(
        robot, dt=1e-3, observer="kf", noise_std=1e-4, chunk=0.4,
        filter_options={"jerk_psd": 1e2},
    )  # fmt: skip
    smoother, got = make(), {}
    for k in range(1, res.t.size):
        for i, _, v, _ in smoother.push(res.t[k], res.q_meas[k], res.tau[k]):
            got[i + 1] = v
    for i, _, v, _ in smoother.close():
        got[i + 1] = v
    np.testing.assert_allclose(np.array([got[k] for k in sorted(got)]), chunked.v[1:], atol=1e-12)


@pytest.mark.parametrize(("chunk", "overlap"), [(None, 0), (400, 5), (250, 250)])
@pytest.mark.parametrize("band", ["model", "noise"])
def test_compiled_model_free_smoother_is_the_smoother(chunk, overlap, band, monkeypatch) -> None:
    """On vector joints :func:`smooth` runs ``kf``'s smoother in compiled passes
    (:func:`white_jerk_smooth`: 3×3 factors of ``P₃ ⊗ I``); it gives what :class:`Smoother`
    gives over the same filter: estimates, band, likelihood and ``ρ``, whole or in windows (a
    short overlap, so that the windows show), with uneven intervals and dropped samples (three
    in a row).  The bank's NumPy pass stores the same states as its compiled one."""
    robot = cached_robot("ur5")
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=1.2, seed=1)
    rng = np.random.default_rng(0)
    t = res.t + np.r_[0.0, rng.uniform(-2e-4, 2e-4, res.t.size - 1)]
    q = np.array(res.q_meas)
    q[[5, 300, 301, 302, 900]] = np.nan
    k0, good = first_good(q)
    arrays = (t[k0:], q[k0:], np.zeros((t.size - k0, robot.nv)), good)
    filt = make_observer("kf", robot, noise_std=1e-4, jerk_psd=300.0).smoothing_filter()
    smoother, n = Smoother(filt, chunk, overlap, band), t.size - k0
    want = np.full((3, n, robot.nv), np.nan)
    for row in log_rows(*arrays):
        for k, qs, vs, var in smoother.push(*row):
            want[:, k] = qs, vs, var
    for k, qs, vs, var in smoother.close():
        want[:, k] = qs, vs, var
    q_s, v_s, var_s, ll, rho_sum, terms = white_jerk_smooth(filt, arrays, chunk, overlap, band)
    np.testing.assert_allclose(q_s, want[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(v_s, want[1], rtol=0, atol=1e-11 * np.abs(want[1]).max())
    np.testing.assert_allclose(var_s, want[2], rtol=1e-10)
    assert ll == pytest.approx(smoother.log_likelihood, rel=1e-12)
    assert terms == smoother.consistency_terms
    assert rho_sum / terms == pytest.approx(smoother.consistency, rel=1e-10)
    bank = KFBank(robot, (300.0,), 1e-4)
    compiled = bank.run(arrays[0], arrays[1], good, 1.0)
    monkeypatch.setattr(kf_kernels.bank_kernel, "compiled", None)
    numpy = bank.run(arrays[0], arrays[1], good, 1.0)
    for a, b in zip(compiled, numpy, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-10)  # (q + v h) + a h²/2, or q + (…)


def test_kf_gates_a_glitch_causal_and_smoothed() -> None:
    """``kf`` has the outlier gate of the EKF family (``outlier_probability``): one sample
    1 rad off is skipped.  Smoothed, the estimate moves by 5e-4 rad/s at most (6.8 rad/s
    without the gate) and ρ, so the inflated band, is the clean log's (4.3e3 without: every
    ``v_std`` 65× wider); causal, with ``jerk_psd`` = 1e3, 8e-3 rad/s (75 rad/s without;
    ``"auto"``'s own gate: ``tests/observers/test_kf_auto.py``)."""
    robot = cached_robot("ur5")
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=2.0, seed=0)
    q = np.array(res.q_meas)
    bad = q.copy()
    bad[500, 2] += 1.0
    clean = smooth(robot, (res.t, q), observer="kf", noise_std=1e-4)
    got = smooth(robot, (res.t, bad), observer="kf", noise_std=1e-4)
    assert np.nanmax(np.abs(got.v - clean.v)) < 1e-3  # measured 4.95e-4
    assert got.consistency == pytest.approx(clean.consistency, rel=1e-3)
    ratio = (got.v_std / clean.v_std)[1:]  # the same but around the skipped sample
    assert np.median(ratio) == pytest.approx(1.0, abs=1e-9) and np.abs(ratio - 1).max() < 0.05
    log = {"t": res.t[1:], "tau": None}
    for p, bound in ((1e-6, 1e-2), (None, 10.0)):  # measured 7.9e-3 and 75
        a, b = (
            estimate_log(
                make_observer("kf", robot, noise_std=1e-4, jerk_psd=1e3, outlier_probability=p),
                Log(q=x[1:], **log),  # type: ignore[arg-type]
            )
            for x in (q, bad)
        )
        assert (np.abs(b.v - a.v).max() < bound) == (p is not None)


@pytest.mark.slow  # 6-8 s on a 2-core machine: the default run stays under 10 min
def test_model_free_smoother_is_the_floor_where_the_model_is_wrong() -> None:
    """Under a payload the model does not have, the smoother over ``ekf`` with ``auto`` ends at
    its grid's top (warned: model-free, pointing to ``kf``); over ``kf`` with its jerk chosen
    from the log it is well below the causal ``kf`` at its best jerk on the truth, and its
    default band (inflated noise band) covers the truth."""
    robot = cached_robot("ur5")
    plant = mismatched_plant(robot, "inertia20_payload", seed=0)
    res = simulate(
        robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=4.0, seed=1, plant=plant
    )
    log = Log(t=res.t, q=res.q_meas, tau=res.tau)
    late = res.t > 1.0

    def rms(v: np.ndarray) -> float:
        return float(np.sqrt(np.mean((v - res.v)[late] ** 2)))

    with pytest.warns(ConsistencyWarning, match="observer='kf'"):
        over_ekf = smooth(robot, log, noise_std=1e-4, accel_psd="auto")
    s = smooth(robot, log, observer="kf", noise_std=1e-4, accel_psd="auto")
    assert s.options["band"] == "inflated" and s.options["accel_psd_from_log"]
    assert _half_decade(s.options["jerk_psd"])
    causal = min(
        rms(estimate_log(make_observer("kf", robot, noise_std=1e-4, jerk_psd=j), log).v)
        for j in (1e1, 1e2, 1e3, 1e4)
    )
    # measured: 2.16e-3 (jerk_psd 316) against 5.39e-3 and 1.22e-2 (2.5× and 5.7×)
    assert rms(s.v) < causal / 2.0
    assert rms(s.v) < rms(over_ekf.v) / 2.0
    cover = np.mean(np.abs(s.v - res.v)[late] <= 2 * s.v_std[late])
    assert 0.9 <= cover <= 0.98  # measured 97.3 %


@pytest.mark.parametrize("name", ["ur5", "top"])
def test_one_bank_pass_gives_each_jerk_densitys_likelihood(name: str) -> None:
    """``"auto"`` over ``kf`` scores its candidates with one pass of a bank of filters
    (:meth:`KFBank.log_likelihoods`): the likelihood :func:`select_accel_psd` sums filter by
    filter, on a vector-joint robot (compiled bank) and on SO(3) (NumPy bank), a sample
    dropped."""
    robot = cached_robot(name)
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=0.5, seed=1)
    q = np.array(res.q_meas)
    q[50] = np.nan
    arrays, k0, _, make, _ = prepare_log(
        robot,
        *smoothing_arrays(robot, Log(t=res.t, q=q, tau=res.tau)),
        "kf",
        1e-4,
        None,
        None,
        None,
    )
    jerks = (1.0, 1e2, 1e4)
    each = [forward_log_likelihood(make(j), arrays, k0) for j in jerks]
    bank = KFBank(robot, jerks, 1e-4, 1e-6).log_likelihoods(arrays[0], arrays[1], arrays[3], 1.0)
    np.testing.assert_allclose(bank, each, rtol=1e-12)


def test_model_free_smoother_takes_its_jerk_density_not_an_acceleration_one() -> None:
    """``kf`` has no white acceleration: a number for ``accel_psd`` is refused with what to give
    instead; ``select_accel_psd`` searches its jerk grid; options it does not take are refused."""
    robot = cached_robot("ur5")
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=0.6, seed=4)
    log = Log(t=res.t, q=res.q_meas, tau=res.tau)
    with pytest.raises(OptionError, match=r"filter_options=\{'jerk_psd': 0.001\}"):
        smooth(robot, log, observer="kf", noise_std=1e-4, accel_psd=1e-3)
    with pytest.raises(OptionError, match="does not accept option"):
        smooth(robot, log, observer="kf", noise_std=1e-4, disturbance_psd=1.0)
    with pytest.raises(OptionError, match="model_window"):
        smooth(robot, log, observer="kf", noise_std=1e-4, model_window=1.0)
    chosen = select_accel_psd(robot, log, noise_std=1e-4, observer="kf")
    assert JERK_GRID[0] <= chosen <= JERK_GRID[-1]
    assert _half_decade(chosen)


def test_cli_estimate_smooths_over_kf_and_says_the_jerk_it_chose(tmp_path, capsys) -> None:
    """``estimate --observer kf --smooth --accel-psd auto`` writes what :func:`smooth` gives and
    says the jerk density chosen; a number for ``--accel-psd`` is refused."""
    from pinobs.cli import main
    from pinobs.io import write_log

    robot = cached_robot("ur5")
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=0.4, seed=4)
    log = write_log(tmp_path / "log.csv", res.t[1:], res.q_meas[1:], res.tau[1:])
    out = tmp_path / "est.csv"
    argv = ["estimate", "--robot", "ur5", "--observer", "kf", "--log", str(log), "--out", str(out)]
    assert main([*argv, "--smooth", "--noise", "1e-4", "--accel-psd", "auto"]) == 0
    want = smooth(
        robot, (res.t[1:], res.q_meas[1:], res.tau[1:]), observer="kf", noise_std=1e-4,
        accel_psd="auto",
    )  # fmt: skip
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    np.testing.assert_allclose(data[:, 7:13], want.v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(data[:, 13:], want.v_std, rtol=0, atol=1e-15)
    assert f"jerk_psd = {want.options['jerk_psd']:.3g} rad²/s⁵" in capsys.readouterr().err
    assert main([*argv, "--smooth", "--noise", "1e-4", "--accel-psd", "1e3", "--force"]) == 2
    assert "kf has no white acceleration" in capsys.readouterr().err


def test_a_log_without_torques_is_smoothed_over_kf_without_the_torque_warning(tmp_path) -> None:
    """``kf`` takes no torque: a log with no torque columns gets no warning that the model
    now assumes zero torque (which ``ekf`` does get, and which used to be said for ``kf``
    too); the estimate is the one from arrays without torques."""
    from pinobs.io import write_log
    from pinobs.io.smoothing import smooth_log

    robot = cached_robot("ur5")
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=0.3, seed=4)
    log = write_log(tmp_path / "log.csv", res.t[1:], res.q_meas[1:], None)
    run, _ = smooth_log(log, robot, tmp_path / "kf.csv", observer="kf", noise_std=1e-4)
    assert not any("torque" in w for w in run.warnings)
    want = smooth(robot, (res.t[1:], res.q_meas[1:]), observer="kf", noise_std=1e-4)
    data = np.loadtxt(tmp_path / "kf.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(data[:, 7:13], want.v, rtol=0, atol=1e-12)
    run, _ = smooth_log(log, robot, tmp_path / "ekf.csv", observer="ekf", noise_std=1e-4)
    assert any("no torque columns: 'ekf'" in w for w in run.warnings)


def test_kf_refuses_to_find_a_latency() -> None:
    """Without a model a late log is as likely as one on time: latency='auto' over kf chose
    3.5 ms on a log on time (0.5 s UR5); refused, a latency in seconds still taken."""
    robot = cached_robot("ur5")
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=0.5, seed=4)
    log = (res.t, res.q_meas, res.tau)
    with pytest.raises(OptionError, match="cannot tell its latency"):
        smooth(robot, log, observer="kf", noise_std=1e-4, filter_options={"latency": "auto"})
    given = smooth(robot, log, observer="kf", noise_std=1e-4, filter_options={"latency": 1e-3})
    assert given.options["latency"] == 1e-3

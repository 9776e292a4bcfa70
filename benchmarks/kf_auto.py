# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[io]", "scipy"]
# ///
"""``kf``'s density from the data (``jerk_psd="auto"``, issue 36 item 1) against the fixed
1e3 rad²/s⁵ it replaced and the best fixed density chosen on the reference (``kf*``).

- **Real logs** (``real_logs.py``'s protocol and functions; skipped without the data): the
  velocity RMS of ``pinobs.estimate("kf", ...)`` against the robot's own velocity, on every
  moving UR10e log and on TIAGo's held-out 20 %, and on the TX40 log decimated to 1 kHz
  against its full-rate Savitzky–Golay velocity; ``kf*`` over ``real_logs.JERK_GRID``.
- **Simulated** (``pinobs bench``'s accuracy runs, :class:`BenchConfig` defaults: 4 s,
  1 kHz, PD tracking, start error 0.05 rad / 0.5 rad/s, Gaussian and 16-bit sensors);
  ``kf*`` over ``pinobs.evaluation.bench.KF_JERKS``.
- **Cost** per update, as a ratio to ``pin.aba`` timed in the same run (interleaved
  chunks of 400 updates and 400 ``pin.aba`` calls, 20 rounds, process CPU time: the
  machine may be shared); median and interquartile range.

    python benchmarks/kf_auto.py            # writes benchmarks/kf_auto.{md,json}
    python benchmarks/kf_auto.py --quick    # two UR10e logs, one robot, printed only
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import real_data as rd
import real_logs as rl

import pinobs
from pinobs.evaluation import evaluate
from pinobs.evaluation.bench import KF_JERKS, BenchConfig
from pinobs.model import aba_call
from pinobs.observers import make_observer
from pinobs.simulation import Sensor

HERE = Path(__file__).resolve().parent
VARIANTS = {"kf 1e3": {"jerk_psd": 1e3}, "kf auto": {"jerk_psd": "auto"}}


def _velocity_rms(frame, robot, ref, rows, joints, options) -> float:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        df = pinobs.estimate("kf", frame, robot=robot, options=options)
    v = df[[f"v{i}" for i in range(robot.nv)]].to_numpy()
    return float(rl.rms(((v - ref)[rows][:, joints]).ravel()))


def _row(frame, robot, ref, rows, joints) -> dict[str, Any]:
    out = {k: _velocity_rms(frame, robot, ref, rows, joints, o) for k, o in VARIANTS.items()}
    grid = {
        j: _velocity_rms(frame, robot, ref, rows, joints, {"jerk_psd": j}) for j in rl.JERK_GRID
    }
    best = min(grid, key=grid.__getitem__)
    out["kf*"], out["kf*_jerk_psd"] = grid[best], best
    return out


def real(quick: bool) -> dict[str, dict[str, Any]]:
    if rd.data_root() is None:
        print("no real data: skipped", flush=True)
        return {}
    logs: dict[str, dict[str, Any]] = {}
    robot = rd.ur10e_robot()
    unloaded = [
        n
        for n in rl.ur10e_names("identification_data")
        if n not in rl.UR10E_FIT and not re.search(r"(?<!un)load", n, re.IGNORECASE)
    ]
    names = ["ur-20_01_17-ptp_10_points", *unloaded]
    for n in names[:2] if quick else names:
        folder = "validation_data" if n.startswith("ur-20_01_17") else "identification_data"
        log = rd.load_log(f"ur10e/{folder}/{n}")
        t = log.frame["t"].to_numpy(dtype=float)
        rows = t >= t[0] + rl.SETTLE
        logs[f"ur10e {n}"] = _row(log.frame, robot, log.velocity, rows, list(range(6)))
        print(f"ur10e {n}: {logs[f'ur10e {n}']}", flush=True)
    if quick:
        return logs
    frame, robot, ref, rows, joints = tiago_held_out()
    logs["tiago (held-out 20 %)"] = _row(frame, robot, ref, rows, joints)
    print(f"tiago: {logs['tiago (held-out 20 %)']}", flush=True)
    logs["tx40 (1 kHz)"] = tx40()
    print(f"tx40: {logs['tx40 (1 kHz)']}", flush=True)
    return logs


def tiago_held_out() -> tuple[Any, pinobs.Robot, np.ndarray, np.ndarray, list[int]]:
    """TIAGo as ``real_logs.py`` scores its velocities: the log on its loop's clock without
    its stale rows (a DataFrame), the robot, the reference velocity, the held-out 20 %
    (after ``identify``'s ``fit_end``) and the arm_1..4 and torso joints' indices."""
    tlog, _, keep, t, q, tau = rl.tiago_rows()
    frame = tlog.frame[keep].copy()
    frame["t"] = t
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ident = pinobs.identify(  # (for its fit_end; as real_logs.py fits TIAGo)
            tlog.robot, (t, q, tau), holdout=0.2, exclude=rd.TIAGO_JOINTS[5:],
            max_condition=1e8,
        )  # fmt: skip
    joints = [rd.TIAGO_JOINTS.index(j) for j in rl.TIAGO_TORQUE_JOINTS]
    return frame, tlog.robot, tlog.velocity[keep], t > ident.report["fit_end"], joints


def tx40() -> dict[str, Any]:
    """``real_logs.tx40``'s log and reference (its module docstring)."""
    import pandas as pd

    d = rd.data_root() / "figaroh" / "examples" / "staubli_TX40"
    motor = pd.read_csv(d / "data" / "pos_read_data.csv").to_numpy(dtype=float)
    R = np.diag(rl.TX40_RATIO)
    R[5, 4] = rl.TX40_RATIO[5]
    q = np.linalg.solve(R, motor.T).T
    q[:, 1] -= np.pi / 2
    q[:, 2] += np.pi / 2
    t = np.arange(len(q)) / rl.TX40_RATE
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = pinobs.load(str(d / "urdf" / "tx40_mdh_modified.urdf"), check=False)
    _, ref_full, _ = rl.sg_fit(t, q, rl.TX40_SG_WINDOW, rl.SG_ORDER)
    sl = slice(0, None, rl.TX40_DECIMATE)
    td, qd = t[sl], q[sl]
    frame = pd.DataFrame({"t": td, **{f"q.{j}": qd[:, i] for i, j in enumerate(robot.joint_names)}})
    return _row(frame, robot, ref_full[sl], td >= td[0] + rl.SETTLE, list(range(robot.nv)))


def sensors(cfg: BenchConfig) -> dict[str, tuple[Sensor, float]]:
    """``pinobs bench``'s two sensors and the σ told to the observers (16-bit: res/√12)."""
    res = 2.0 * np.pi / 2**cfg.bits
    return {
        f"gauss {cfg.noise_std:g}": (Sensor(cfg.rate, cfg.noise_std), cfg.noise_std),
        f"{cfg.bits}-bit": (Sensor(cfg.rate, 0.0, bits=cfg.bits), res / np.sqrt(12.0)),
    }


def simulated(quick: bool) -> list[dict[str, Any]]:
    cfg = BenchConfig()
    out = []
    for name in ("ur5",) if quick else cfg.robots:
        robot = pinobs.load(name)
        for label, (sensor, noise) in sensors(cfg).items():
            hints = {"rate": cfg.rate, "noise_std": noise}
            obs = {k: make_observer("kf", robot, **hints, **o) for k, o in VARIANTS.items()}
            for j in KF_JERKS:
                obs[f"kf@{j:g}"] = make_observer("kf", robot, jerk_psd=j, **hints)
            res = pinobs.simulate(
                robot, obs, duration=cfg.duration, sensor=sensor, inputs="pd",
                perturb_q=cfg.perturb_q, perturb_v=cfg.perturb_v, seed=cfg.seed,
            )  # fmt: skip
            m = {x.observer: x.rms_v_error for x in evaluate(res, robot)}
            best = min((k for k in m if "@" in k), key=m.__getitem__)
            row = {"robot": name, "sensor": label, **{k: m[k] for k in VARIANTS}}
            row.update({"kf*": m[best], "kf*_jerk_psd": float(best.split("@")[1])})
            row["densities"] = obs["kf auto"].densities.tolist()
            out.append(row)
            print(row, flush=True)
    return out


def cost(quick: bool, rounds: int = 20, chunk: int = 400) -> list[dict[str, Any]]:
    out = []
    for name in ("ur5",) if quick else ("ur5", "panda", "go1"):
        robot = pinobs.load(name)
        aba = aba_call(robot)
        rng = np.random.default_rng(0)
        ramp = np.linspace(-1.0, 1.0, robot.nv)
        qs = [
            robot.integrate(robot.neutral(), 1e-3 * k * ramp + 1e-4 * rng.standard_normal(robot.nv))
            for k in range(chunk * rounds + 1)
        ]
        row: dict[str, Any] = {"robot": name, "nv": robot.nv}
        for label, o in VARIANTS.items():
            ob = make_observer("kf", robot, noise_std=1e-4, rate=1000.0, **o)
            ob.reset(0.0, qs[0])
            ratios, times = [], []
            k = 1
            for _ in range(rounds):
                t0 = time.process_time()
                for _ in range(chunk):
                    ob.update(k * 1e-3, qs[k])
                    k += 1
                tu = (time.process_time() - t0) / chunk
                t0 = time.process_time()
                for _ in range(chunk):
                    aba()
                ratios.append(tu / ((time.process_time() - t0) / chunk))
                times.append(tu)
            row[label] = {
                "seconds": float(np.median(times)),
                "x_aba": float(np.median(ratios)),
                "x_aba_iqr": [float(np.percentile(ratios, 25)), float(np.percentile(ratios, 75))],
            }
        out.append(row)
        print(row, flush=True)
    return out


def _g(x: float) -> str:
    return f"{x:.3g}"


def markdown(res: dict[str, Any]) -> str:
    L = [
        '# `kf` with `jerk_psd="auto"` (`benchmarks/kf_auto.py`)',
        "",
        f"Made by `python benchmarks/kf_auto.py` on {res['date']} in {res['seconds']:.0f} s. "
        "Velocity RMS [rad/s]; `kf 1e3`: the fixed density that was the default; `kf*`: the "
        "best fixed density chosen on the reference itself (optimistic).",
        "",
        "## Real logs",
        "",
        "| log | kf 1e3 | kf auto | kf* | kf* jerk_psd | kf 1e3 / kf* | kf auto / kf* |",
        "|---|---|---|---|---|---|---|",
    ]
    for k, r in res["real"].items():
        L.append(
            f"| {k} | {_g(r['kf 1e3'])} | {_g(r['kf auto'])} | {_g(r['kf*'])} | "
            f"{r['kf*_jerk_psd']:g} | {r['kf 1e3'] / r['kf*']:.2f} | "
            f"**{r['kf auto'] / r['kf*']:.2f}** |"
        )
    L += [
        "",
        "## Simulated (`pinobs bench`'s accuracy runs)",
        "",
        "| robot | sensor | kf 1e3 | kf auto | kf* | kf* jerk_psd | kf auto / kf 1e3 | "
        "kf auto / kf* | auto's densities at the end [rad²/s⁵] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in res["simulated"]:
        dens = ", ".join(f"{x:.2g}" for x in r["densities"])
        L.append(
            f"| {r['robot']} | {r['sensor']} | {_g(r['kf 1e3'])} | {_g(r['kf auto'])} | "
            f"{_g(r['kf*'])} | {r['kf*_jerk_psd']:g} | {r['kf auto'] / r['kf 1e3']:.2f} | "
            f"**{r['kf auto'] / r['kf*']:.2f}** | {dens} |"
        )
    L += [
        "",
        "## Cost per update (process CPU time; ratio to `pin.aba` in the same run)",
        "",
        "| robot | nv | kf 1e3 [µs] | × aba (IQR) | kf auto [µs] | × aba (IQR) |",
        "|---|---|---|---|---|---|",
    ]
    for r in res["cost"]:
        a, b = r["kf 1e3"], r["kf auto"]
        L.append(
            f"| {r['robot']} | {r['nv']} | {a['seconds'] * 1e6:.1f} | {a['x_aba']:.1f} "
            f"({a['x_aba_iqr'][0]:.1f}–{a['x_aba_iqr'][1]:.1f}) | {b['seconds'] * 1e6:.1f} | "
            f"{b['x_aba']:.1f} ({b['x_aba_iqr'][0]:.1f}–{b['x_aba_iqr'][1]:.1f}) |"
        )
    return "\n".join(L) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    a = p.parse_args(argv)
    t0 = time.perf_counter()
    res: dict[str, Any] = {"date": time.strftime("%Y-%m-%d"), "quick": a.quick}
    res["real"] = real(a.quick)
    res["simulated"] = simulated(a.quick)
    res["cost"] = cost(a.quick)
    res["seconds"] = time.perf_counter() - t0
    text = markdown(res)
    print(text)
    if not a.quick:
        (HERE / "kf_auto.json").write_text(json.dumps(res, indent=1) + "\n")
        (HERE / "kf_auto.md").write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

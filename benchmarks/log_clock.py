# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[io]"]
# ///
"""Logs as they are recorded: each observer on the clean log and on the same log as a
lab logger records it, the clock repair's cost, and what it finds on the real logs.

Simulated (known truth): a run at 1 kHz with σ = 1e-4 rad, recorded by
``pinobs.simulation.Logger(drop=0.08, jitter=4e-4, stale=0.06, digits=6)`` (issue 35's
numbers: 8 % of the loop's samples lost, stamps jittered uniformly ±0.4 ms, 6 % stale
rows, 6 significant digits).  The *clean* log holds the same recorded samples (drops
and digits included) at their true times, without the stale rows; *recorded* is the
log as written, estimated with the default ``clock="auto"``; *stamps* the same with
``clock="stamps"``.  RMS velocity error over the last two thirds of the run, against
the truth at every output row.

Cost: ``fit_clock`` on the recorded log over one ``kf`` pass over it
(``process_log(..., clock="stamps")``), medians of ``REPEATS`` runs each, one ratio per
log, paired in the same process.

The clock's rule on loggers with known truth (UR5, 12 s at 500 Hz: a 2 ms loop; q printed
to 4 decimals): *UR e-series*, rows every 5 or 6 ticks stamped to the ms, 5 % 1 ms late
(the UR10e's 2020 logs); *sleep-paced*, a logger sleeping 10 ms and working 0.3–0.9 ms
between reads of the loop's latest sample, stamped to the ms (its 2019 logs); *glitched*,
the UR e-series log with five rows stamped ±1 s off.  Per log: the stamps' von Neumann
ratio ``η`` about the loop found, what ``auto`` did, the RMS distance of the stamps and of
the loop's clock (``clock="loop"``) to the samples' true times once an offset and a rate
are fitted, and ``kf``'s RMS velocity error against the truth (from 1.2 s) with each clock.

Real (``../shared/data``, skipped when absent; :mod:`real_data`): the clock report of
every UR10e and TIAGo log (``η`` too), and ``kf``'s RMS difference to the robot's own
recorded velocity with ``clock="auto"`` and ``clock="stamps"``; and
``ur-20_02_19_14harm50sec`` with five rows stamped ±1 s off (rows seeded, 0).

    python benchmarks/log_clock.py            # writes benchmarks/log_clock.{md,json}
    python benchmarks/log_clock.py --quick    # one seed, short runs (a smoke test)
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import pinobs
from pinobs.io import fit_clock, process_log
from pinobs.simulation import Logger, Sensor

HERE = Path(__file__).resolve().parent
ROBOTS = ("ur5", "panda", "z1")
OBSERVERS = ("fd", "kf", "ekf", "riemannian", "adaptive")
ALONE = {name: {"never_behind": False} for name in ("ekf", "riemannian", "adaptive")}
LOGGER = Logger(drop=0.08, jitter=4e-4, stale=0.06, digits=6)
SIGMA = 1e-4
REPEATS = 5


def _frame(robot, t, q, tau):
    import pandas as pd

    names = robot.joint_names
    return pd.DataFrame(
        {
            "t": t,
            **{f"q.{n}": q[:, i] for i, n in enumerate(names)},
            **{f"tau.{n}": tau[:, i] for i, n in enumerate(names)},
        }
    )


def _rms(df, v_true, nv):
    v = df[[f"v{i}" for i in range(nv)]].to_numpy()
    tail = slice(len(v) // 3, None)
    return float(np.sqrt(np.nanmean((v[tail] - v_true[tail]) ** 2)))


def _quiet_estimate(name, frame, robot, clock):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return pinobs.estimate(  # each family alone (pinobs.estimate's default blends it)
            name, frame, robot=robot, noise_std=SIGMA, clock=clock, options=ALONE.get(name)
        )


def simulated(seeds, duration):
    rows = []
    for robot_name in ROBOTS:
        robot = pinobs.load(robot_name)
        for seed in seeds:
            res = pinobs.simulate(
                robot, [], duration=duration, sensor=Sensor(rate=1000.0, noise_std=SIGMA), seed=seed
            )
            rec = LOGGER.record(res, seed)
            fresh = ~rec.stale
            recorded = rec.to_frame(robot)
            clean = _frame(robot, res.t[rec.tick[fresh]], rec.q[fresh], rec.tau[fresh])
            fit = fit_clock(rec.t, rec.q)
            cost = _cost(recorded, rec, robot)
            for name in OBSERVERS:
                e_clean = _rms(
                    _quiet_estimate(name, clean, robot, "stamps"), res.v[rec.tick[fresh]], robot.nv
                )
                e_rec = _rms(
                    _quiet_estimate(name, recorded, robot, "auto"), res.v[rec.tick], robot.nv
                )
                e_raw = _rms(
                    _quiet_estimate(name, recorded, robot, "stamps"), res.v[rec.tick], robot.nv
                )
                rows.append(
                    {
                        "robot": robot_name,
                        "seed": seed,
                        "observer": name,
                        "clean": e_clean,
                        "recorded": e_rec,
                        "stamps": e_raw,
                        "ratio": e_rec / e_clean,
                        "stamps_ratio": e_raw / e_clean,
                        "repaired": fit.report.repaired,
                        "stale_found": fit.report.stale,
                        "stale_true": int(rec.stale.sum()),
                        "eta": fit.report.wander,
                        "cost_over_kf": cost,
                    }
                )
                print(
                    f"{robot_name} seed {seed} {name:10s} clean {e_clean:.3g} recorded "
                    f"{e_rec:.3g} ({e_rec / e_clean:.2f}x) stamps {e_raw:.3g} "
                    f"({e_raw / e_clean:.1f}x)",
                    flush=True,
                )
    return rows


def _ur_e_series(res, rng):
    ticks = np.cumsum(np.where(rng.random(1200) < 0.75, 5, 6))
    ticks = ticks[ticks < res.t.size - 1]
    late = rng.random(ticks.size) < 0.05
    return 1e-3 * np.round(1e3 * res.t[ticks]) + 1e-3 * late, ticks


def _sleep_paced(res, rng):
    read = 0.05 + np.cumsum(10e-3 + rng.uniform(0.3e-3, 0.9e-3, 1300))
    read = read[read < res.t[-1] - 0.01]
    return 1e-3 * np.round(1e3 * read), np.floor(read / 2e-3 + 1e-9).astype(int)


def _glitched(res, rng):
    t, ticks = _ur_e_series(res, rng)
    rows = np.sort(rng.choice(np.arange(10, t.size - 10), 5, replace=False))
    t[rows] += np.array([1.0, -1.0, 1.0, -1.0, 1.0])
    return t, ticks


LOGGERS = {"UR e-series": _ur_e_series, "sleep-paced": _sleep_paced, "glitched": _glitched}


def _line_error(t, truth):
    a = np.vstack([np.ones_like(truth), truth]).T
    coef, *_ = np.linalg.lstsq(a, t, rcond=None)
    return float(np.sqrt(np.mean((t - a @ coef) ** 2)))


def loggers(seeds):
    """The clock's rule against the truth (module docstring)."""
    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=12.0, sensor=Sensor(rate=500.0))
    rows = []
    for name, make in LOGGERS.items():
        for seed in seeds:
            t, ticks = make(res, np.random.default_rng(seed))
            q = np.round(res.q[ticks], 4)
            frame = _frame(robot, t, q, np.zeros_like(q))
            fit = fit_clock(t, q)
            loop = fit_clock(t, q, mode="loop")
            row = {
                "logger": name,
                "seed": seed,
                "wander": fit.report.wander,
                "repaired": fit.report.repaired,
                "outliers": fit.report.outliers,
                "reason": fit.report.reason,
                "stamps_ms": 1e3 * _line_error(t, res.t[ticks]),
                "loop_ms": 1e3 * _line_error(loop.t, res.t[ticks]),
            }
            for clock in ("auto", "stamps", "loop"):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    df = pinobs.estimate("kf", frame, robot=robot, clock=clock)
                v = df[[f"v{i}" for i in range(robot.nv)]].to_numpy()
                ok = np.isfinite(v).all(axis=1) & (res.t[ticks] > 1.2)
                row[f"kf_{clock}"] = float(np.sqrt(np.mean((v[ok] - res.v[ticks][ok]) ** 2)))
            print(row, flush=True)
            rows.append(row)
    return rows


def _cost(recorded, rec, robot):
    """fit_clock over one kf pass on the same log, median of REPEATS paired runs."""
    ratios = []
    for _ in range(REPEATS):
        a = time.perf_counter()
        fit_clock(rec.t, rec.q)
        b = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            process_log(recorded, robot, "kf", noise_std=SIGMA, keep=False, clock="stamps")
        c = time.perf_counter()
        ratios.append((b - a) / (c - b))
    return float(np.median(ratios))


def _clock_row(name, frame, fit):
    """A real log's row: its clock's report."""
    r = fit.report
    return {
        "log": name,
        "rows": len(frame),
        "report": r.message(),
        "repaired": r.repaired,
        "period_ms": None if r.period is None else 1e3 * r.period,
        "jitter_ms": 1e3 * r.jitter,
        "stale": r.stale,
        "drops": r.drops,
        "wander": r.wander,
    }


def _kf_by_clock(frame, robot, ref):
    """``kf``'s RMS against ``ref`` with each clock (``kf_auto``, ``kf_stamps``)."""
    out = {}
    for clock in ("auto", "stamps"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            df = pinobs.estimate("kf", frame, robot=robot, clock=clock)
        v = df[[f"v{i}" for i in range(robot.nv)]].to_numpy()
        ok = np.isfinite(v).all(axis=1) & np.isfinite(ref).all(axis=1)
        out[f"kf_{clock}"] = float(np.sqrt(np.mean((v[ok] - ref[ok]) ** 2)))
    return out


def real():
    sys.path.insert(0, str(HERE))
    try:
        import real_data
    except ImportError:
        return []
    out = []
    for name in real_data.list_logs():
        log = real_data.load_log(name)
        frame, robot, ref = log.frame, log.robot, log.velocity
        q = frame[[f"q.{j}" for j in robot.joint_names]].to_numpy()
        row = _clock_row(name, frame, fit_clock(frame["t"].to_numpy(), q))
        if ref is not None:
            row.update(_kf_by_clock(frame, robot, ref))
        print(name, row.get("kf_auto"), row.get("kf_stamps"), row["report"], flush=True)
        out.append(row)
        if name.endswith("ur-20_02_19_14harm50sec"):
            out.append(_glitched_real(log, q))
    return out


def _glitched_real(log, q):
    """``log`` with five rows stamped ±1 s off (seeded rows), ``kf`` with each clock."""
    frame, robot, ref = log.frame.copy(), log.robot, log.velocity
    t = frame["t"].to_numpy().copy()
    rows = np.sort(np.random.default_rng(0).choice(np.arange(200, t.size - 200), 5, replace=False))
    t[rows] += np.array([1.0, -1.0, 1.0, -1.0, 1.0])
    frame["t"] = t
    row = _clock_row(log.name + " + 5 glitches", frame, fit_clock(t, q))
    row.update(glitch_rows=rows.tolist(), **_kf_by_clock(frame, robot, ref))
    print(row["log"], row["kf_auto"], row["kf_stamps"], row["report"], flush=True)
    return row


def _markdown(sim, rl, lg=()):
    lines = [
        "# Logs as recorded (`benchmarks/log_clock.py`)",
        "",
        f"Simulated: 1 kHz, σ = {SIGMA:g} rad, recorded by `{LOGGER!r}`; RMS velocity "
        "error [rad/s] over the last two thirds, against the truth at every output row. "
        '*recorded*: the log as written, `clock="auto"`; *stamps*: `clock="stamps"`; '
        "*clean*: the same samples at their true times without the stale rows.",
        "",
        "| robot | seed | observer | clean | recorded | × clean | stamps | × clean |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in sim:
        lines.append(
            f"| {r['robot']} | {r['seed']} | {r['observer']} | {r['clean']:.3g} | "
            f"{r['recorded']:.3g} | {r['ratio']:.2f} | {r['stamps']:.3g} | "
            f"{r['stamps_ratio']:.1f} |"
        )
    if sim:
        ratios = np.array([r["ratio"] for r in sim])
        costs = sorted({(r["robot"], r["seed"]): r["cost_over_kf"] for r in sim}.values())
        lines += [
            "",
            f"Recorded over clean: {ratios.min():.2f}–{ratios.max():.2f} (median "
            f"{np.median(ratios):.2f}) over {len(ratios)} runs. Stale rows found exactly on "
            f"{sum(r['stale_found'] == r['stale_true'] for r in sim) // len(OBSERVERS)} of "
            f"{len(sim) // len(OBSERVERS)} logs.",
            "",
            f"Cost of the clock repair over one `kf` pass on the same log (median of "
            f"{REPEATS} paired runs per log): {costs[0]:.3f}–{costs[-1]:.3f}.",
        ]
    if sim:
        eta = [r["eta"] for r in sim if "eta" in r]
        if eta:
            lines += [
                "",
                f"Von Neumann ratio η of the recorded logs' stamps about the loop: "
                f"{min(eta):.2f}–{max(eta):.2f}.",
            ]
    if lg:
        lines += [
            "",
            "## The clock's rule on loggers with known truth",
            "",
            "UR5, 12 s at 500 Hz (a 2 ms loop), q printed to 4 decimals. *stamps*, *loop*: "
            'RMS distance [ms] of the stamps and of the loop\'s clock (`clock="loop"`) to '
            "the samples' true times, an offset and a rate fitted; `kf` RMS velocity error "
            "[rad/s] against the truth from 1.2 s with `clock=` auto, stamps, loop.",
            "",
            "| logger | seed | η | auto | outliers | stamps [ms] | loop [ms] | kf auto | "
            "kf stamps | kf loop |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in lg:
            lines.append(
                f"| {r['logger']} | {r['seed']} | {r['wander']:.3g} | "
                f"{'repaired' if r['repaired'] else 'stamps'} | {r['outliers']} | "
                f"{r['stamps_ms']:.3g} | {r['loop_ms']:.3g} | {r['kf_auto']:.4g} | "
                f"{r['kf_stamps']:.4g} | {r['kf_loop']:.4g} |"
            )
    if rl:
        lines += [
            "",
            "## Real logs (`../shared/data`)",
            "",
            "`kf` against the robot's own recorded velocity, RMS [rad/s], with the clock "
            "repair (`auto`) and with the stamps as they are.",
            "",
            "| log | rows | repaired | loop [ms] | jitter [ms] | η | stale | drops | kf auto | "
            "kf stamps |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in rl:
            per = "–" if r["period_ms"] is None else f"{r['period_ms']:.4g}"
            lines.append(
                f"| {r['log']} | {r['rows']} | {'yes' if r['repaired'] else 'no'} | {per} | "
                f"{r['jitter_ms']:.3g} | {r.get('wander', float('nan')):.3g} | {r['stale']} | "
                f"{r['drops']} | "
                f"{r.get('kf_auto', float('nan')):.3g} | {r.get('kf_stamps', float('nan')):.3g} |"
            )
        lines += ["", "What the repair said of each log:", ""]
        lines += [f"- {r['log']}: {r['report']}" for r in rl]
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--duration", type=float, default=2.0, help="simulated run [s]")
    p.add_argument("--out", default=str(HERE / "log_clock"))
    a = p.parse_args(argv)
    seeds = (1,) if a.quick else (1, 2, 3)
    sim = simulated(seeds, 1.5 if a.quick else a.duration)
    lg = loggers(seeds)
    out = {"simulated": sim, "loggers": lg}
    Path(a.out).with_suffix(".json").write_text(json.dumps(out, indent=1))
    rl = [] if a.quick else real()
    out["real"] = rl
    Path(a.out).with_suffix(".json").write_text(json.dumps(out, indent=1))
    Path(a.out).with_suffix(".md").write_text(_markdown(sim, rl, lg))
    print(_markdown(sim, rl, lg))


if __name__ == "__main__":
    main()

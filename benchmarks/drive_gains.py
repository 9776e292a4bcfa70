# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[io]", "scipy"]
# ///
"""Drive gains from a known payload on the real UR10e (issue 36, "Drives"), held out.

Mamedov et al. 2020 recorded the same excitation unloaded and with a 2.805 kg load on the
flange, twice (``ur-20_02_19_14harm50sec*`` and ``..._15harm50sec*``).  Their
``estimate_drive_gains.m`` identifies the drive gains (current → torque) from the 14harm
pair, rows 195..4966 (unloaded) and 308..5071 (loaded).  Here:

1. the gains by :func:`pinobs.model.identification.identify_drive_gains` on one pair (the
   14harm rows theirs; the 15harm rows by the same rule: 150 rows after the first moving
   row to 14 before the last, which is what their 14harm rows are), against the published
   ``drvGains`` (``UR10E_parameters.txt``);
2. held out: the *other* pair's torques taken as those gains × its currents, the robot
   calibrated on its unloaded run (``pinobs.identify``, nothing held out) and the load
   identified on its loaded run (``pinobs.identify(..., payload="tool0")``, its last 20 %
   held out): the load's mass against 2.805 kg, and the held-out torque residual per joint
   [N·m] with the load (after) and without (before); the same with the published gains
   beside it, and (not ``--quick``) with the gains of ``method="ols"`` (their ``'OLS'``).

Rows that repeat the previous position exactly (the logger's stale reads, ~5 %) are left
out, as in ``tests/model/test_identification_real_data.py``.  Writes
``benchmarks/drive_gains.json`` and ``benchmarks/drive_gains.md``.

    python benchmarks/drive_gains.py            # both directions (about 10 min on 2 cores)
    python benchmarks/drive_gains.py --quick    # 14harm → 15harm only, printed (no files)
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import real_data as rd

import pinobs
from pinobs.model.identification import identify_drive_gains

HERE = Path(__file__).resolve().parent
LOAD_KG = 2.805  # estimate_drive_gains.m's m_load
BODY = "tool0"
#: Their rows (1-based, inclusive, of the raw CSV) of the 14harm pair; the 15harm pair's by
#: the same offsets from its moving rows (:func:`rows_by_rule`).
THEIR_ROWS = {"ur-20_02_19_14harm50sec": (195, 4966), "ur-20_02_19_14harm50secLoad": (308, 5071)}
START_AFTER_MOVING, END_BEFORE_MOVING = 150, 14
PAIRS = {
    "14harm": ("ur-20_02_19_14harm50sec", "ur-20_02_19_14harm50secLoad"),
    "15harm": ("ur-20_02_19_15harm50sec", "ur-20_02_19_15harm50secLoad"),
}


def _raw(name: str) -> pd.DataFrame:
    path = rd.data_root() / "ur10e" / "dataset_ur10e" / "identification_data" / f"{name}.csv"
    return pd.read_csv(path, header=None, usecols=list(range(13)), dtype=float)


def rows_by_rule(name: str) -> tuple[int, int]:
    """Their rows for the 14harm files; otherwise 150 rows after the first row with a joint
    moving (|dq| > 1e-3 rad/s) to 14 rows before the last (their 14harm offsets)."""
    if name in THEIR_ROWS:
        return THEIR_ROWS[name]
    dq = _raw(name).to_numpy()[:, 7:13]
    sane = np.isfinite(dq).all(axis=1) & (np.abs(dq) < 10.0).all(axis=1)  # not garbled
    moving = np.flatnonzero((np.abs(dq) > 1e-3).any(axis=1) & sane)
    return int(moving[0]) + 1 + START_AFTER_MOVING, int(moving[-1]) + 1 - END_BEFORE_MOVING


def run(name: str) -> dict[str, np.ndarray]:
    """``t, q, current`` of the rows of ``name`` (:func:`rows_by_rule`), stale rows out."""
    first, last = rows_by_rule(name)
    stamps = _raw(name).to_numpy()[:, 0]
    frame = rd.load_log(f"ur10e/identification_data/{name}").frame
    t = frame["t"].to_numpy(float)
    q = frame[[c for c in frame.columns if c.startswith("q.")]].to_numpy(float)
    tau = frame[[c for c in frame.columns if c.startswith("tau.")]].to_numpy(float)
    keep = (t >= stamps[first - 1]) & (t <= stamps[last - 1])
    keep[1:] &= ~(q[1:] == q[:-1]).all(axis=1)
    current = tau[keep] / rd.ur10e_drive_gains()  # the loader's τ = drvGains × current
    return {"t": t[keep] - t[keep][0], "q": q[keep], "current": current, "rows": [first, last]}


def gains_on(robot: pinobs.Robot, pair: str, method: str = "current") -> dict:
    """The gains ``identify_drive_gains`` finds on ``pair`` by ``method``, and its report."""
    unloaded, loaded = (run(n) for n in PAIRS[pair])
    start = time.perf_counter()
    out = identify_drive_gains(robot, unloaded, loaded, body=BODY, load_mass=LOAD_KG, method=method)
    rep = out.report
    return {
        "pair": pair,
        "rows": {"unloaded": unloaded["rows"], "loaded": loaded["rows"]},
        "gains": out.gains.tolist(),
        "std": out.std.tolist(),
        "load_com": rep["load"]["com"],
        "rank": rep["rank"],
        "n_parameters": rep["n_parameters"],
        "condition": rep["condition"],
        "residual_unloaded": rep["residual_unloaded"],
        "residual_loaded": rep["residual_loaded"],
        "seconds": time.perf_counter() - start,
    }


def payload_on(robot: pinobs.Robot, pair: str, gains: np.ndarray) -> dict:
    """The load identified on ``pair`` with torques ``gains`` × current."""
    logs = []
    for name in PAIRS[pair]:
        r = run(name)
        logs.append((r["t"], r["q"], r["current"] * gains))
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fits' warnings on real data
        calibrated = pinobs.identify(robot, logs[0], holdout=0.0).robot
        ident = pinobs.identify(calibrated, logs[1], payload=BODY)
    rep = ident.report
    return {
        "pair": pair,
        "mass": rep["payload"]["mass"],
        "mass_error": rep["payload"]["mass"] / LOAD_KG - 1.0,
        "com": rep["payload"]["com"],
        "holdout_torque_before": list(rep["holdout_torque_before"]),
        "holdout_torque_after": list(rep["holdout_torque_after"]),
        "seconds": time.perf_counter() - start,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="14harm → 15harm only")
    args = parser.parse_args(argv)
    if rd.data_root() is None:
        print("no shared data folder (../shared/data): nothing to run")
        return 0
    robot = rd.ur10e_robot()
    published = rd.ur10e_drive_gains()
    directions = [("14harm", "15harm")] + ([] if args.quick else [("15harm", "14harm")])
    results = {"published_gains": published.tolist(), "load_kg": LOAD_KG, "directions": []}
    for fit, held in directions:
        g = gains_on(robot, fit)
        print(f"gains on {fit}: {np.round(g['gains'], 3)} ± {np.round(g['std'], 3)}")
        ours = payload_on(robot, held, np.array(g["gains"]))
        theirs = payload_on(robot, held, published)
        print(
            f"  held out on {held}: mass {ours['mass']:.3f} kg ({100 * ours['mass_error']:+.1f} %)"
            f", published gains {theirs['mass']:.3f} kg ({100 * theirs['mass_error']:+.1f} %)"
        )
        entry = {"fit": fit, "held_out": held, "gains": g, "payload": ours}
        entry["payload_published"] = theirs
        if not args.quick:  # Mamedov et al.'s 'OLS' (method="ols") beside it
            g_ols = gains_on(robot, fit, "ols")
            entry["gains_ols"] = g_ols
            entry["payload_ols"] = payload_on(robot, held, np.array(g_ols["gains"]))
            print(f"  ols: {np.round(g_ols['gains'], 3)}: {entry['payload_ols']['mass']:.3f} kg")
        results["directions"].append(entry)
    if args.quick:  # one direction: printed, the full run's files kept
        return 0
    (HERE / "drive_gains.json").write_text(json.dumps(results, indent=1) + "\n", encoding="utf-8")
    (HERE / "drive_gains.md").write_text(markdown(results), encoding="utf-8")
    return 0


def _row(label: str, values, fmt: str = ".3f") -> str:  # type: ignore[no-untyped-def]
    """One markdown table row: ``| label | v₁ | v₂ | … |``."""
    return f"| {label} | " + " | ".join(format(float(x), fmt) for x in values) + " |"


def markdown(results: dict) -> str:
    joints = ("pan", "lift", "elbow", "wrist 1", "wrist 2", "wrist 3")
    pub = results["published_gains"]
    lines = [
        "# Drive gains from a known payload: the real UR10e, held out",
        "",
        "`python benchmarks/drive_gains.py` (its docstring says what it does). Gains "
        "[N·m/A] by `identify_drive_gains` on one pair (2.805 kg on tool0), the load then "
        "identified on the other pair with those gains (`pinobs.identify(..., "
        'payload="tool0")`, after calibrating on its unloaded run), against the published '
        "gains (Mamedov et al. 2020, `UR10E_parameters.txt`).",
        "",
    ]
    for d in results["directions"]:
        g, p, pp = d["gains"], d["payload"], d["payload_published"]
        lines += [
            f"## Gains on {d['fit']} (rows {g['rows']['unloaded']} unloaded, "
            f"{g['rows']['loaded']} loaded), load held out on {d['held_out']}",
            "",
            "| joint | " + " | ".join(joints) + " |",
            "|---|" + "---|" * 6,
            _row("gain", g["gains"]),
            _row("± (1σ)", g["std"]),
            _row("published", pub, ".4f"),
            _row("ratio", (a / b for a, b in zip(g["gains"], pub, strict=True))),
            _row("fit residual unloaded [N·m]", g["residual_unloaded"]),
            _row("fit residual loaded [N·m]", g["residual_loaded"]),
            "",
            f"Rank {g['rank']} of {g['n_parameters']} columns, condition {g['condition']:.3g}, "
            f"{g['seconds']:.1f} s (wall, a shared 2-core machine); the load's centre of mass "
            f"{np.round(g['load_com'], 4).tolist()} m (tool0).",
            "",
            *_ols_lines(d),
            f"Held out on {d['held_out']}: load mass **{p['mass']:.3f} kg "
            f"({100 * p['mass_error']:+.1f} %)** with these gains, {pp['mass']:.3f} kg "
            f"({100 * pp['mass_error']:+.1f} %) with the published ones (target: within 5 %).",
            "",
            "| held-out torque RMS [N·m] | " + " | ".join(joints) + " |",
            "|---|" + "---|" * 6,
            _row("without the load, these gains", p["holdout_torque_before"]),
            _row("with it, these gains", p["holdout_torque_after"]),
            _row("without the load, published", pp["holdout_torque_before"]),
            _row("with it, published", pp["holdout_torque_after"]),
            _row(
                "with it, these gains, in A (÷ gain)",
                (x / k for x, k in zip(p["holdout_torque_after"], g["gains"], strict=True)),
                ".4f",
            ),
            _row(
                "with it, published, in A (÷ gain)",
                (x / k for x, k in zip(pp["holdout_torque_after"], pub, strict=True)),
                ".4f",
            ),
            "",
            "Each row is in its own gains' torque (gain × current): the rows in A compare the "
            "two fits on the measured currents.",
            "",
        ]
    return "\n".join(lines)


def _ols_lines(d: dict) -> list[str]:
    """The ``method="ols"`` gains and the load they give, when run (not ``--quick``)."""
    if "gains_ols" not in d:
        return []
    g, p = d["gains_ols"], d["payload_ols"]
    return [
        "By `method=\"ols\"` (their 'OLS', least squares in torque): gains "
        + ", ".join(f"{x:.3f}" for x in g["gains"])
        + f"; the load held out on {d['held_out']} with them: {p['mass']:.3f} kg "
        f"({100 * p['mass_error']:+.1f} %).",
        "",
    ]


if __name__ == "__main__":
    raise SystemExit(main())

# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[io]", "scipy"]
# ///
"""Presliding hysteresis (Dahl) friction on the real arms (issue 36): how much of the held-out
torque residual at rest a friction state explains.  A diagnosis: nothing here is in pinobs.

Every law of :data:`pinobs.model.friction.FRICTION_LAWS` is a function of ``v`` alone, so at
rest it predicts (nearly) no friction, while a joint at rest holds any torque in its stiction
band, set by its history.  The Dahl model (Dahl 1968; Olsson et al. 1998, "Friction models
and friction compensation", §3.1) ``F = F_h·h``, ``dh/dx = (1 − h·sgn(ẋ))/x_s``, is rate
independent: integrated exactly over each step ``Δx``, ``h ← s − (s − h)·exp(−|Δx|/x_s)``,
``s = sgn(Δx)`` (:func:`dahl`), ``h`` is a function of the position history alone, and at rest
it holds the value of the last motion (``±1`` after a slide longer than a few ``x_s``).  Once
``x_s`` is chosen, ``F_h·h`` is one more linear column per joint.

- **Models.** *pinobs*: ``pinobs.identify`` with its defaults (viscous + Coulomb·tanh(v/0.01),
  armature), as ``real_logs.py`` runs it (TX40: the motor log through ``real_logs.tx40_drives``,
  decimated to 1 kHz, last 20 % held out; UR10e: ``real_logs.UR10E_FIT``, every other
  unloaded moving log and the static poses p1..p10 held out; TIAGo: last 20 % held out,
  arm_5..7 excluded).  Its residual ``r = τ − τ̂`` is then fitted per joint on the fitted
  rows by ordinary least squares on ``[tanh(v/0.01), 1]`` (*+ Coulomb refit, offset*: the
  control, which shows what a refit and a constant alone do) and on
  ``[tanh(v/0.01), 1, h]`` (*+ Dahl*), each joint's ``x_s`` from :data:`XS_GRID` by the least
  sum of squares over :data:`FOLDS` contiguous blocks of the fitted rows, each predicted by
  the fit on the others (``pinobs.model.friction_fit.search_smoothing``'s blocks, the
  minimum taken).  TX40 also: *lsq FIGAROH columns* (``real_logs.lsq_figaroh_columns``,
  FIGAROH's TX40 columns with its coupled wrist, weighted least squares) and the same with the
  ``h`` columns, at the ``x_s`` the *+ Dahl* search chose.
- **h's input.** The zero-phase Savitzky–Golay ``q`` of the derivatives (TX40: 101 rows at
  5 kHz; UR10e and TIAGo: 21 rows), not the raw ``q``: raw encoder noise at rest walks ``h``
  toward 0 when ``x_s`` is small (offline: an online ``h`` would need a causal filter or a
  dead band).  ``h = 0`` at each log's first row.
- **Correlation check.** On the held-out rows at rest (every joint ``|v| ≤ 0.01`` rad/s),
  ``corr²`` of *pinobs*'s residual with the sign of the last motion (``|v| > 0.01``) and with
  ``h`` at each ``x_s`` of the grid: the share of its variance a straight line in that
  feature explains, fitted on those very rows (an upper bound, not a prediction; 0 where
  the feature is constant on them, as after a single stop).
- **Scores.** RMS per joint [N·m] over the held-out rows, those moving and those at rest
  (TX40: at 5 kHz, as ``tx40_friction.py``), and those at rest after a motion in their log.
  Nothing is chosen on the held-out rows.

    python benchmarks/friction_hysteresis.py     # about 3 min on 2 cores; writes friction_hysteresis.md
"""

from __future__ import annotations

import re
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

sys.path.insert(0, str(Path(__file__).resolve().parent))
import real_data as rd
import real_logs as rl

import pinobs
from pinobs.tolerances import COULOMB_SMOOTHING_VELOCITY

#: Presliding displacements searched [rad or m].
XS_GRID = (3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2)
#: Contiguous blocks of the fitted rows for the x_s search.
FOLDS = 5
#: A row is at rest when every joint's speed is at most this [rad/s]; the last motion's
#: sign is that of the last row above it.
REST = 0.01
#: A rest episode counts when it lasts at least this [s].
EPISODE = 0.05
#: Scored rows: every held-out row, the moving ones, those at rest, and those at rest after a
#: motion in their log (the UR10e's static poses p1..p10 never move: ``h = 0`` on them).
PARTS = ("held_out", "moving", "at_rest", "at_rest_after_motion")


def dahl(q: np.ndarray, xs: float) -> np.ndarray:
    """``h`` of Dahl's model along ``q`` (rows × joints), ``h = 0`` at the first row:
    ``dh/dx = (1 − h·sgn(ẋ))/x_s`` (Dahl 1968; Olsson et al. 1998 eq. 4 with ``σ₀ = F_c/x_s``)
    integrated exactly over each step: ``h ← s − (s − h)·exp(−|Δx|/x_s)``, ``s = sgn(Δx)``."""
    dq = np.diff(q, axis=0, prepend=q[:1])
    decay, s = np.exp(-np.abs(dq) / xs), np.sign(dq)
    h = np.empty_like(q)
    cur = np.zeros(q.shape[1])
    for k in range(len(q)):
        cur = s[k] - (s[k] - cur) * decay[k]
        h[k] = cur
    return h


def last_sign(v: np.ndarray) -> np.ndarray:
    """The sign of each joint's last row with ``|v| > REST`` (0 before any)."""
    out = np.empty_like(v)
    cur = np.zeros(v.shape[1])
    for k in range(len(v)):
        cur = np.where(np.abs(v[k]) > REST, np.sign(v[k]), cur)
        out[k] = cur
    return out


class Case:
    """One robot's rows: ``τ``, the default identification's prediction, SG ``q, v, a``, the
    fitted/held-out masks, the torque channels scored, and ``h`` per ``x_s``."""

    def __init__(self, name, logs, channels, step=1):
        cat = lambda k: np.concatenate([d[k] for d in logs])  # noqa: E731
        self.name, self.channels, self.step = name, channels, step
        self.tau, self.pred, self.q, self.v, self.a = (
            cat(k) for k in ("tau", "pred", "q", "v", "a")
        )
        self.q_raw, self.t = cat("q_raw"), cat("t")
        self.log = np.concatenate([np.full(len(d["t"]), i) for i, d in enumerate(logs)])
        self.fit, self.held = cat("fit"), cat("held")
        self.rest = np.abs(self.v).max(axis=1) <= REST
        self.last = np.concatenate([last_sign(d["v"]) for d in logs])
        self.h = {xs: np.concatenate([dahl(d["q"], xs) for d in logs]) for xs in XS_GRID}
        moved = (self.last[:, channels] != 0).any(axis=1)
        still = self.held & self.rest
        self.masks = dict(
            zip(PARTS, (self.held, self.held & ~self.rest, still, still & moved), strict=True)
        )


def rows_of(t, q, tau, pred, window, fit_end=None, fitted=None):
    """A log's rows: SG ``q, v, a`` and the fitted/held-out masks (inner rows only)."""
    qs, v, a = rl.sg_fit(t, q, window, rl.SG_ORDER)
    inner = np.zeros(len(t), bool)
    inner[window // 2 : len(t) - window // 2] = True
    if fit_end is not None:
        fit, held = inner & (t <= fit_end), inner & (t > fit_end)
    else:
        fit, held = inner & fitted, inner & ~fitted
    return {
        **{"tau": tau, "pred": pred(qs, v, a), "q": qs, "q_raw": q, "v": v, "a": a},
        **{"fit": fit, "held": held, "t": t},
    }


def quiet_identify(robot, data, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # identify's notes are in its report
        return pinobs.identify(robot, data, **options)


def tx40_case() -> tuple[Case, pinobs.Robot]:
    robot, log = rl.tx40_rows()
    t, q, tau = log.t, log.q, log.tau
    sl = slice(0, None, rl.TX40_DECIMATE)
    ident = quiet_identify(robot, (t[sl], q[sl], tau[sl]), holdout=0.2)
    split = rl.checked_split(ident, t[sl])
    d = rows_of(
        t, q, tau, lambda qs, v, a: rl.predict_identified(ident, q, v, a), rl.TX40_SG_WINDOW, split
    )
    return Case("TX40", [d], list(range(6)), step=rl.TX40_DECIMATE), robot


def ur10e_case() -> Case:
    robot = rd.ur10e_robot()
    ident, _, _ = rl.ur10e_identify(rl.UR10E_FIT, robot)
    unloaded = [
        n
        for n in rl.ur10e_names("identification_data")
        if n not in rl.UR10E_FIT and not re.search(r"(?<!un)load", n, re.IGNORECASE)
    ]
    static = [n for n in rl.ur10e_names("validation_data") if re.search(r"-p\d+$", n)]
    logs = []
    for n in [*rl.UR10E_FIT, "ur-20_01_17-ptp_10_points", *unloaded, *static]:
        folder = "validation_data" if n.startswith("ur-20_01_17") else "identification_data"
        t, q, tau = rl.arrays(rd.load_log(f"ur10e/{folder}/{n}").frame)
        keep = rl.fresh(q)
        t, q, tau = t[keep], q[keep], tau[keep]
        pred = lambda qs, v, a, q=q: rl.predict_robot(ident.robot, q, v, a)  # noqa: E731
        logs.append(
            rows_of(t, q, tau, pred, rl.SG_WINDOW, fitted=np.full(len(t), n in rl.UR10E_FIT))
        )
    return Case("UR10e", logs, list(range(6)))


def tiago_case() -> Case:
    log, _, _, t, q, tau = rl.tiago_rows()
    common = {"holdout": 0.2, "exclude": list(rd.TIAGO_JOINTS[5:]), "max_condition": 1e8}
    ident = quiet_identify(log.robot, (t, q, tau), **common)
    split = rl.checked_split(ident, t)
    pred = lambda qs, v, a: rl.predict_identified(ident, q, v, a)  # noqa: E731
    return Case("TIAGo", [rows_of(t, q, tau, pred, rl.SG_WINDOW, split)], list(range(5)))


# ------------------------------------------------------------------ step 1: correlation
def correlations(c: Case) -> dict[str, list[float]]:
    """``corr²`` on the held-out rows at rest of the residual with the last motion's sign and
    with ``h`` per ``x_s`` (module docstring), per channel."""
    rows = c.masks["at_rest"]
    r = (c.tau - c.pred)[rows]

    def corr2(z: np.ndarray) -> list[float]:
        return [
            float(np.corrcoef(z[rows, j], r[:, j])[0, 1] ** 2) if z[rows, j].std() > 0 else 0.0
            for j in c.channels
        ]

    return {
        "last motion sign": corr2(c.last),
        **{f"h, x_s = {xs:g}": corr2(c.h[xs]) for xs in XS_GRID},
    }


def episodes(c: Case, mask: np.ndarray) -> list[np.ndarray]:
    """The rest episodes within ``mask``: runs of consecutive rows of one log at rest, at
    least :data:`EPISODE` long."""
    idx = np.flatnonzero(mask & c.rest)
    cut = np.flatnonzero((np.diff(idx) > 1) | (np.diff(c.log[idx]) != 0)) + 1
    runs = np.split(idx, cut) if len(idx) else []
    return [e for e in runs if c.t[e[-1]] - c.t[e[0]] >= EPISODE]


def episode_signs(c: Case) -> dict[str, Any]:
    """Per joint, over the rest episodes (fitted and held-out apart): how many there are, the
    share of the held-out rest rows in the longest, and in how many the sign of the mean
    residual is the last motion's (episodes after a motion of that joint only)."""
    r = c.tau - c.pred
    out: dict[str, Any] = {}
    for part, mask in (("fitted", c.fit), ("held_out", c.held)):
        eps = episodes(c, mask)
        agree = []
        for j in c.channels:
            pairs = [
                (np.sign(r[e, j].mean()), c.last[e[0], j]) for e in eps if c.last[e[0], j] != 0
            ]
            agree.append(f"{sum(a == b for a, b in pairs)}/{len(pairs)}")
        out[part] = {
            "episodes": len(eps),
            "rows": int(sum(len(e) for e in eps)),
            "longest": int(max((len(e) for e in eps), default=0)),
            "agree": agree,
        }
    return out


# ------------------------------------------------------------------ step 2: fits
def block_cv(A: np.ndarray, y: np.ndarray) -> float:
    """Sum over :data:`FOLDS` contiguous blocks of each block's squared error predicted by the
    least-squares fit on the others."""
    total = 0.0
    for idx in np.array_split(np.arange(len(y)), FOLDS):
        keep = np.ones(len(y), bool)
        keep[idx] = False
        th = np.linalg.lstsq(A[keep], y[keep], rcond=None)[0]
        total += float(np.sum((A[idx] @ th - y[idx]) ** 2))
    return total


def stage_fits(c: Case) -> tuple[dict[str, np.ndarray], list[float]]:
    """The residual's per-joint fits on the fitted rows (module docstring): predictions of
    *+ Coulomb refit, offset* and *+ Dahl* on every row, and each joint's ``x_s``."""
    fit = np.flatnonzero(c.fit)[:: c.step]
    r = c.tau - c.pred
    base_pred, dahl_pred, chosen = c.pred.copy(), c.pred.copy(), []
    for j in c.channels:
        base = np.c_[np.tanh(c.v[:, j] / COULOMB_SMOOTHING_VELOCITY), np.ones(len(r))]
        th = np.linalg.lstsq(base[fit], r[fit, j], rcond=None)[0]
        base_pred[:, j] += base @ th
        cv = {xs: block_cv(np.c_[base, c.h[xs][:, j]][fit], r[fit, j]) for xs in XS_GRID}
        xs = min(cv, key=cv.__getitem__)
        A = np.c_[base, c.h[xs][:, j]]
        th = np.linalg.lstsq(A[fit], r[fit, j], rcond=None)[0]
        dahl_pred[:, j] += A @ th
        chosen.append(xs)
    return {"pinobs + Coulomb refit, offset": base_pred, "pinobs + Dahl": dahl_pred}, chosen


def tx40_lsq(c: Case, robot: pinobs.Robot, xs: list[float]) -> dict[str, np.ndarray]:
    """``real_logs.lsq_figaroh_columns`` (coupled) and the same with ``diag(h)`` at ``xs``:
    their predictions on the fitted and held-out rows (others 0)."""
    model, data = robot.model, robot.model.createData()
    vs = COULOMB_SMOOTHING_VELOCITY
    h = np.stack([c.h[x][:, j] for j, x in enumerate(xs)], axis=1)

    def columns(k: int, hyst: bool) -> np.ndarray:
        v, a = c.v[k], c.a[k]
        y = pin.computeJointTorqueRegressor(model, data, c.q_raw[k], v, a)
        cols = [y, np.diag(v), np.diag(np.tanh(v / vs)), np.diag(a), np.eye(6)]
        m6 = np.zeros((6, 3))
        sign = np.tanh((v[4] + v[5]) / vs)
        m6[4] = [a[5], v[5], sign]
        m6[5] = [a[4], v[4], sign]
        cols.append(m6)
        if hyst:
            cols.append(np.diag(h[k]))
        return np.hstack(cols)

    fit = np.flatnonzero(c.fit)[:: c.step]
    score = np.flatnonzero(c.held)
    out = {}
    for label, hyst in (("lsq FIGAROH columns", False), ("lsq FIGAROH columns + Dahl", True)):
        A = np.vstack([columns(k, hyst) for k in fit])
        y = c.tau[fit].ravel()
        th = np.linalg.lstsq(A, y, rcond=None)[0]
        w = np.tile(1.0 / (A @ th - y).reshape(-1, 6).std(axis=0), len(fit))
        th = np.linalg.lstsq(A * w[:, None], y * w, rcond=None)[0]
        p = np.zeros_like(c.tau)
        p[score] = np.array([columns(k, hyst) @ th for k in score])
        out[label] = p
    return out


def scores(c: Case, preds: dict[str, np.ndarray]) -> dict[str, dict[str, list[float]]]:
    return {
        k: {part: rl.rms((c.tau - p)[m][:, c.channels]).tolist() for part, m in c.masks.items()}
        for k, p in preds.items()
    }


def run() -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, make in (("TX40", tx40_case), ("UR10e", ur10e_case), ("TIAGo", tiago_case)):
        t0 = time.perf_counter()
        made = make()
        c, robot = made if isinstance(made, tuple) else (made, None)
        preds, xs = stage_fits(c)
        preds = {"pinobs (default)": c.pred, **preds}
        if robot is not None:
            preds.update(tx40_lsq(c, robot, xs))
        out[name] = {
            "rows": {k: int(m.sum()) for k, m in c.masks.items()},
            "fitted_rows": int(c.fit.sum()),
            "fitted_at_rest": int((c.fit & c.rest).sum()),
            "corr2": correlations(c),
            "episodes": episode_signs(c),
            "xs": xs,
            "scores": scores(c, preds),
            "seconds": time.perf_counter() - t0,
        }
        print(f"{name}: {out[name]['seconds']:.0f} s", flush=True)
    return out


# ------------------------------------------------------------------ report
JOINTS = {
    "TX40": [f"j{k + 1}" for k in range(6)],
    "UR10e": [f"j{k + 1}" for k in range(6)],
    "TIAGo": ["torso", "arm_1", "arm_2", "arm_3", "arm_4"],
}


def markdown(res: dict[str, Any], seconds: float) -> str:
    refs = rl.tx40_references(rl.figaroh_measured(), str(rl.TX40_SG_WINDOW))
    lines = [
        f"Made by `python benchmarks/friction_hysteresis.py` on {time.strftime('%Y-%m-%d')} in "
        f"{seconds:.0f} s (pinobs {pinobs.__version__}); conditions in its docstring.",
        "",
    ]
    for name, r in res.items():
        j = JOINTS[name]
        lines += [
            f"### {name}: held-out rows {r['rows']['held_out']} ({r['rows']['moving']} moving, "
            f"{r['rows']['at_rest']} at rest, {r['rows']['at_rest_after_motion']} of them after "
            f"a motion); fitted rows {r['fitted_rows']} "
            f"({r['fitted_at_rest']} at rest)",
            "",
            "corr² on the held-out rows at rest of *pinobs (default)*'s residual with:",
            "",
            "| feature | " + " | ".join(j) + " |",
            "|---|" + "---|" * len(j),
            *(
                f"| {k} | " + " | ".join(f"{x:.2f}" for x in v) + " |"
                for k, v in r["corr2"].items()
            ),
            "",
            "Rest episodes (≥ 0.05 s; the rows at rest they hold; the longest) and, per joint, in "
            "how many the mean residual has the sign of that joint's last motion:",
            "",
            "| rows | episodes | rows in them | longest | " + " | ".join(j) + " |",
            "|---|---|---|---|" + "---|" * len(j),
            *(
                f"| {k} | {e['episodes']} | {e['rows']} | {e['longest']} | "
                + " | ".join(e["agree"])
                + " |"
                for k, e in r["episodes"].items()
            ),
            "",
            "Held-out torque residual RMS [N·m; N for the torso]; x_s chosen on the fitted rows: "
            + ", ".join(f"{x:g}" for x in r["xs"])
            + ".",
            "",
        ]
        extra = list(refs) if name == "TX40" else []
        lines += [
            "| model | rows | "
            + " | ".join(j)
            + "".join(f" | worst j1–j4 / FIGAROH {k}" for k in extra)
            + " |",
            "|---|---|" + "---|" * (len(j) + len(extra)),
        ]
        for model, s in r["scores"].items():
            for part in PARTS:
                ratios = (
                    [
                        f"{max(x / y for x, y in zip(s[part][:4], ref[:4], strict=True)):.3g}"
                        if part == "held_out"
                        else "—"
                        for ref in refs.values()
                    ]
                    if extra
                    else []
                )
                cells = [f"{x:.3g}" for x in s[part]] + ratios
                lines.append(f"| {model} | {part} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def main() -> int:
    return rd.report(__file__, run, markdown)


if __name__ == "__main__":
    raise SystemExit(main())

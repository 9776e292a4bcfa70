# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[io,peers]", "scipy"]
# ///
"""Where pinobs's TIAGo fit trails FIGAROH-tanh on the held-out rows (issue 36, a diagnosis).

``real_logs.md``'s TIAGo table has *pinobs N·m offset* (``pinobs.identify``,
``weighting="torque"``, ``offset=True``, arm_5..7 left out) at 1.06× FIGAROH-tanh's held-out
residual on arm_1 (*fed tanh*: FIGAROH 1.0.2 on the same rows and Savitzky–Golay derivatives,
``figaroh_peer.py``).  The two models have the same columns (rigid body, viscous, Coulomb
``tanh(v/0.01)``, rotor inertia and an offset per joint): the gap is not a missing term.  What
this script measures, nothing chosen on the held-out rows:

- **Held out, moving and at rest.**  RMS per joint of each fit's held-out residual
  ``τ̂ − τ`` over the rows where the joint moves (``|v_j| >`` :data:`MOVING` rad/s) and the
  others, and its mean at rest (a bias an offset would carry).
- **The acceleration the fits leave.**  Per joint, the least-squares coefficient of ``a_j``
  in the residual with ``[1, v_j, tanh(v_j/0.01), a_j]`` (the joint's own offset, viscous,
  Coulomb and rotor-inertia columns) on the fitted rows: an effective inertia about the joint
  the fit lacks [kg·m²; kg for the torso] where the per-sample least squares would have it.
  FIGAROH (a per-sample least squares with these columns among its own) is fitted to that; it
  predicts only the held-out rows here, where the same coefficient is given for every fit.
- **How sure the held-out ratio is.**  pinobs's held-out RMS over FIGAROH's per joint, with
  a 90 % moving-block bootstrap interval (:data:`BOOT_BLOCK` s blocks, :data:`BOOT_DRAWS`
  draws, seed :data:`SEED`): the held-out 20 % holds few motions.
- **Blocked cross-validation on the fitted 80 % only.**  The fitted span cut into
  :data:`FOLDS` contiguous blocks; each block predicted by the fits on the other blocks
  (pinobs: the other rows joined with a NaN row, ``holdout=0``, as ``real_logs.py`` joins the
  UR10e logs; FIGAROH: the other rows less :data:`real_logs.SG_WINDOW` // 2 at each block
  edge, whose derivatives see the block's positions).  The rule a cross-validation on the fitted
  rows would choose among *pinobs N·m offset*, its ``refine=()`` and FIGAROH-tanh, and whether
  it says what the held-out rows say.

    python benchmarks/figaroh_gap.py   # about 20 min on a loaded 2-core machine; writes figaroh_gap.{md,json}
"""

from __future__ import annotations

import argparse
import itertools
import json
import logging
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

sys.path.insert(0, str(Path(__file__).resolve().parent))
import figaroh_peer as fp
import real_data as rd
import real_logs as rl

import pinobs

#: pinobs's fits compared (options of ``pinobs.identify`` beside real_logs.py's TIAGo ones).
PINOBS = {k: rl.TIAGO_VARIANTS[k] for k in ("pinobs N·m offset", "pinobs N·m offset refine=()")}
FIGAROH = "FIGAROH fed tanh"
MODELS = (*PINOBS, FIGAROH)
#: A joint moves on a row when its Savitzky–Golay speed exceeds this [rad/s; m/s].
MOVING = 0.01
#: Contiguous blocks of the fitted 80 % for the cross-validation.
FOLDS = 5
#: The per-joint terms compared (:func:`joint_parameters`).
TERMS = ("viscous", "Coulomb", "rotor inertia", "offset")
#: Moving-average lengths [rows] of :func:`inertia_by_band` (1: the rows themselves).
BANDS = (1, 5, 10, 20, 40)
#: Pauses shorter than this [s] join two runs of motion; shorter runs are dropped (:func:`motions`).
PAUSE = 0.1
#: Moving-block bootstrap of the held-out ratio: block length [s], draws, seed.
BOOT_BLOCK, BOOT_DRAWS, SEED = 1.0, 2000, 0
JOINTS = list(rl.TIAGO_TORQUE_JOINTS)
OUT = Path(__file__).with_suffix("")


# ------------------------------------------------------------------ the fits
def tiago() -> dict[str, Any]:
    """real_logs.py's TIAGo rows, derivatives and split (``fit``, ``held``: inner rows)."""
    log, _, _, t, q, tau = rl.tiago_rows()
    _, v, a = rl.sg_fit(t, q)
    inner = np.zeros(len(t), bool)
    inner[rl.SG_WINDOW // 2 : len(t) - rl.SG_WINDOW // 2] = True
    split = rl.held_out_split(t)
    return {
        "robot": log.robot,
        "t": t,
        "q": q,
        "v": v,
        "a": a,
        "tau": tau,
        "fit": inner & (t <= split),
        "held": inner & (t > split),
    }


def joined(keep: np.ndarray, t: np.ndarray, *series: np.ndarray) -> tuple[np.ndarray, ...]:
    """The rows ``keep`` of ``(t, *series)``, a NaN row (at the time of the last row left
    out) in each gap between kept pieces: ``pinobs.identify`` integrates over no NaN row."""
    rows = np.flatnonzero(keep)
    resume = np.flatnonzero(np.diff(keep.astype(int)) == 1) + 1  # first row of a later piece
    resume = resume[resume > rows[0]]
    at = np.searchsorted(rows, resume)  # where each NaN row goes among the kept rows
    T = np.insert(t[rows], at, t[resume - 1])
    return (T, *(np.insert(x[rows], at, np.nan, axis=0) for x in series))


def pinobs_fit(d: dict[str, Any], opts: dict[str, Any], block: np.ndarray | None):
    """``pinobs.identify``'s prediction on every row: fitted as real_logs.py does
    (``holdout=0.2``) when ``block`` is None, else on the fitted rows less ``block``, the
    pieces joined by a NaN row (``holdout=0``); and the identification."""
    t, q, tau = d["t"], d["q"], d["tau"]
    common = {"exclude": list(rd.TIAGO_JOINTS[5:]), "max_condition": 1e8, **opts}
    if block is None:
        log = (t, q, tau)
        common["holdout"] = 0.2
    else:
        log = joined((t <= t[d["fit"]].max()) & ~block, t, q, tau)
        common["holdout"] = 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ident = pinobs.identify(d["robot"], log, **common)
    return rl.predict_identified(ident, q, d["v"], d["a"]), ident


def figaroh_fit(d: dict[str, Any], config: str, train: np.ndarray, test: np.ndarray):
    """FIGAROH-tanh fitted on ``train`` rows (``figaroh_peer.py``'s *fed tanh*), its
    prediction on every row (NaN outside ``test``), and FIGAROH's identification."""
    sets = {
        m: (d["t"][r], d["q"][r], d["v"][r], d["a"][r], d["tau"][r])
        for m, r in ((None, train), ("held_out", test))
    }
    robot = pin.RobotWrapper(d["robot"].model.copy())
    with fp.coulomb_model("tanh"):
        iden = fp.fed_identification(robot, config, sets, list(rd.TIAGO_JOINTS), JOINTS)
        fp.quiet_solve(iden, decimate=False)
    pred, _, _ = fp.validation(iden, JOINTS)
    out = np.full((len(d["t"]), len(rd.TIAGO_JOINTS)), np.nan)
    out[np.ix_(test, range(len(JOINTS)))] = pred
    return out, iden


def joint_parameters(fits: dict[str, Any]) -> dict[str, dict[str, list[float]]]:
    """Per model, each scored joint's viscous, Coulomb, rotor inertia and offset, the offset
    as FIGAROH writes it (``τ = … + off``; pinobs's ``b`` is ``τ + b = …``: ``off = −b``);
    FIGAROH's values where its base parameter is that one standard parameter alone, else
    NaN (a combination)."""
    out: dict[str, dict[str, list[float]]] = {}
    for name, (_, fit) in fits.items():
        if name == FIGAROH:
            base = dict(zip(fit.params_base, np.asarray(fit.phi_base, float), strict=True))
            get = {
                k: [base.get(f"{p}_{j}", np.nan) for j in JOINTS]
                for k, p in zip(TERMS, ("fv", "fs", "Ia", "off"), strict=True)
            }
        else:
            par = dict(zip(fit.parameters.names, fit.parameters.values, strict=True))
            get = {
                k: [sign * par.get(f"{j}.{p}", 0.0) for j in JOINTS]
                for k, p, sign in zip(
                    TERMS, ("damping", "coulomb", "armature", "offset"), (1, 1, 1, -1), strict=True
                )
            }
        out[name] = {k: [float(x) for x in v] for k, v in get.items()}
    return out


# ------------------------------------------------------------------ what is measured
def residual(d: dict[str, Any], pred: np.ndarray) -> np.ndarray:
    """``τ̂ − τ`` on the scored channels (torso, arm_1..4)."""
    return (pred - d["tau"])[:, : len(JOINTS)]


def split_scores(d: dict[str, Any], r: np.ndarray) -> dict[str, list[float]]:
    """Held-out RMS per joint over its moving rows and its rows at rest, and the mean at rest."""
    h = d["held"]
    out: dict[str, list[float]] = {"all": [], "moving": [], "rest": [], "rest_mean": []}
    for j in range(len(JOINTS)):
        rj, mv = r[h, j], np.abs(d["v"][h, j]) > MOVING
        out["all"].append(float(rl.rms(rj)))
        out["moving"].append(float(rl.rms(rj[mv])))
        out["rest"].append(float(rl.rms(rj[~mv])))
        out["rest_mean"].append(float(rj[~mv].mean()))
    return out


def inertia_left(d: dict[str, Any], r: np.ndarray, rows: np.ndarray) -> list[float]:
    """Per joint, the coefficient of ``a_j`` in ``r_j`` fitted on ``[1, v_j, tanh(v_j/0.01),
    a_j]`` over ``rows``: the effective inertia the fit lacks, ``τ̂ − τ ≈ −ΔI a``, so ``−coef``."""
    out = []
    for j in range(len(JOINTS)):
        vj, aj = d["v"][rows, j], d["a"][rows, j]
        X = np.column_stack([np.ones_like(vj), vj, np.tanh(vj / 0.01), aj])
        out.append(float(-np.linalg.lstsq(X, r[rows, j], rcond=None)[0][3]))
    return out


def inertia_by_band(d: dict[str, Any], r: np.ndarray) -> list[list[float]]:
    """:func:`inertia_left` on the fitted rows after a centred moving average of ``n`` rows of
    the residual and of every column, for each ``n`` of :data:`BANDS`: per joint, the
    effective inertia left at slower and slower content of the log."""
    rows, out = d["fit"], []
    for n in BANDS:
        k = np.ones(n) / n
        smooth = {
            "v": np.apply_along_axis(np.convolve, 0, d["v"], k, mode="same"),
            "a": np.apply_along_axis(np.convolve, 0, d["a"], k, mode="same"),
        }
        rs = np.apply_along_axis(np.convolve, 0, r, k, mode="same")
        out.append([])
        for j in range(len(JOINTS)):
            tanh = np.convolve(np.tanh(d["v"][:, j] / 0.01), k, mode="same")
            ones = np.convolve(np.ones(len(rs)), k, mode="same")  # the offset, averaged alike
            X = np.column_stack([ones, smooth["v"][:, j], tanh, smooth["a"][:, j]])
            out[-1].append(float(-np.linalg.lstsq(X[rows], rs[rows, j], rcond=None)[0][3]))
    return out


def boot_ratio(d: dict[str, Any], num: np.ndarray, den: np.ndarray) -> list[list[float]]:
    """Per joint ``[ratio, 5 %, 95 %]`` of RMS(num)/RMS(den) on the held-out rows, the interval
    by a moving-block bootstrap (circular blocks of :data:`BOOT_BLOCK` s)."""
    h = np.flatnonzero(d["held"])
    n = len(h)
    step = float(np.median(np.diff(d["t"][h])))
    L = max(1, round(BOOT_BLOCK / step))
    rng = np.random.default_rng(SEED)
    starts = rng.integers(0, n, size=(BOOT_DRAWS, -(-n // L)))
    idx = ((starts[:, :, None] + np.arange(L)) % n).reshape(BOOT_DRAWS, -1)[:, :n]
    out = []
    for j in range(len(JOINTS)):
        a2, b2 = num[h, j] ** 2, den[h, j] ** 2
        ratios = np.sqrt(a2[idx].mean(axis=1) / b2[idx].mean(axis=1))
        lo, hi = np.quantile(ratios, [0.05, 0.95])
        out.append([float(np.sqrt(a2.mean() / b2.mean())), float(lo), float(hi)])
    return out


def folds(d: dict[str, Any]) -> list[np.ndarray]:
    """:data:`FOLDS` contiguous blocks of equal time over the fitted rows (masks on every row)."""
    t, fit = d["t"], d["fit"]
    edges = np.linspace(t[fit].min(), t[fit].max(), FOLDS + 1)
    edges[-1] += 1.0
    return [fit & (t >= lo) & (t < hi) for lo, hi in itertools.pairwise(edges)]


def cross_validation(d: dict[str, Any], config: str) -> dict[str, Any]:
    """Each model's per-joint RMS on each block predicted by its fit on the other blocks, and
    pooled over the blocks."""
    m = rl.SG_WINDOW // 2
    sq = {k: np.zeros(len(JOINTS)) for k in MODELS}
    per: dict[str, list[list[float]]] = {k: [] for k in MODELS}
    count = 0
    for k, block in enumerate(folds(d)):
        near = np.convolve(block, np.ones(2 * m + 1), mode="same") > 0
        preds = {name: pinobs_fit(d, o, block)[0] for name, o in PINOBS.items()}
        preds[FIGAROH] = figaroh_fit(d, config, d["fit"] & ~near, block)[0]
        for name, p in preds.items():
            r = residual(d, p)[block]
            sq[name] += np.sum(r**2, axis=0)
            per[name].append(rl.rms(r).tolist())
        count += int(block.sum())
        print(f"fold {k + 1}/{FOLDS} done", flush=True)
    pooled = {k: np.sqrt(s / count).tolist() for k, s in sq.items()}
    return {"pooled": pooled, "per_fold": per}


def run() -> dict[str, Any]:
    """Every measurement of the module docstring."""
    t0 = time.perf_counter()
    logging.getLogger("figaroh").setLevel(logging.ERROR)
    d = tiago()
    res: dict[str, Any] = {"date": time.strftime("%Y-%m-%d", time.gmtime())}
    res |= {"figaroh": fp.figaroh_version(), "joints": JOINTS, "held_rows": int(d["held"].sum())}
    with tempfile.TemporaryDirectory() as tmp:
        legacy = fp.examples() / "tiago" / "config" / "tiago_config.yaml"
        config = fp.unified_config(legacy, "tiago", Path(tmp))
        fits = {name: pinobs_fit(d, o, None) for name, o in PINOBS.items()}
        fits[FIGAROH] = figaroh_fit(d, config, d["fit"], d["held"])
        preds = {k: f[0] for k, f in fits.items()}
        res["parameters"] = joint_parameters(fits)
        print("held-out fits done", flush=True)
        r = {k: residual(d, p) for k, p in preds.items()}
        fitted_r = {k: r[k] for k in PINOBS}  # FIGAROH predicted the held-out rows only
        res["held_out"] = {k: split_scores(d, x) for k, x in r.items()}
        res["inertia_left_fitted"] = {k: inertia_left(d, x, d["fit"]) for k, x in fitted_r.items()}
        res["inertia_by_band"] = {k: inertia_by_band(d, x) for k, x in fitted_r.items()}
        mv = d["held"] & (np.abs(d["v"][:, 1]) > MOVING)
        res["inertia_left_held_moving_arm_1"] = {k: inertia_left(d, x, mv)[1] for k, x in r.items()}
        res["arm_1_held_motions"] = motions(d)
        res["ratio"] = {k: boot_ratio(d, r[k], r[FIGAROH]) for k in PINOBS}
        res["cv"] = cross_validation(d, config)
    res["seconds"] = time.perf_counter() - t0
    return res


# ------------------------------------------------------------------ the page
def _f(x: float) -> str:
    return "—" if x != x else f"{x:.3g}"


def _table(head: str, rows: dict[str, list[float]]) -> list[str]:
    j = [n.replace("_joint", "") for n in JOINTS]
    L = [f"| {head} | " + " | ".join(j) + " |", "|---|" + "---|" * len(j)]
    return L + [f"| {k} | " + " | ".join(_f(x) for x in v) + " |" for k, v in rows.items()]


def held_out_section(res: dict[str, Any]) -> list[str]:
    h = res["held_out"]
    rows = {f"{k}, {part}": h[k][part] for k in MODELS for part in ("all", "moving", "rest")}
    rows |= {f"{k}, mean at rest": h[k]["rest_mean"] for k in MODELS}
    L = ["### Held out: moving and at rest [N·m; torso N]", ""]
    L += _table("model, rows", rows)
    L += [
        "",
        f"pinobs over FIGAROH-tanh, held out, with a 90 % moving-block bootstrap interval "
        f"({BOOT_BLOCK:g} s blocks, {BOOT_DRAWS} draws, seed {SEED}):",
        "",
    ]
    cells = {
        k: [f"{x:.3f} [{lo:.2f}, {hi:.2f}]" for x, lo, hi in v] for k, v in res["ratio"].items()
    }
    j = [n.replace("_joint", "") for n in JOINTS]
    L += ["| model | " + " | ".join(j) + " |", "|---|" + "---|" * len(j)]
    L += [f"| {k} / FIGAROH | " + " | ".join(v) + " |" for k, v in cells.items()]
    return L


def parameter_section(res: dict[str, Any]) -> list[str]:
    L = ["", "### The joints' own terms, held-out fits", ""]
    L += [
        "Viscous [N·m·s/rad], Coulomb [N·m], rotor inertia [kg·m²] and offset [N·m] (as "
        "FIGAROH writes it, `τ = … + off`); the torso's in N and kg. FIGAROH's: its base "
        "parameter where it is that parameter alone, — where it is a combination.",
        "",
    ]
    rows = {f"{m}, {k}": v for m, p in res["parameters"].items() for k, v in p.items()}
    return L + _table("model, term", rows)


def inertia_section(res: dict[str, Any]) -> list[str]:
    L = ["", "### The acceleration the fits leave [kg·m²; torso kg]", ""]
    L += [
        "Per joint, minus the coefficient of `a_j` in the fit's residual regressed on "
        "`[1, v_j, tanh(v_j/0.01), a_j]` over the fitted rows: the effective inertia about the "
        "joint that the per-sample least squares on these derivatives would add (FIGAROH-tanh, "
        "such a least squares, is fitted to these rows; the held-out value is given below).",
        "",
    ]
    L += _table("model", res["inertia_left_fitted"])
    L += [
        "",
        "The same after a centred moving average of n rows of the residual and of each column "
        "(the log's slower content), arm_1..4:",
        "",
        "| model | n [rows] | " + " | ".join(n.replace("_joint", "") for n in JOINTS[1:]) + " |",
        "|---|---|" + "---|" * (len(JOINTS) - 1),
    ]
    for k, by in res["inertia_by_band"].items():
        L += [
            f"| {k} | {n} | " + " | ".join(_f(x) for x in v[1:]) + " |"
            for n, v in zip(BANDS, by, strict=True)
        ]
    held = res["inertia_left_held_moving_arm_1"]
    L += [
        "",
        "The same on arm_1's held-out moving rows, arm_1: "
        + ", ".join(f"{k} {_f(v)}" for k, v in held.items())
        + ".",
    ]
    return L


def cv_section(res: dict[str, Any]) -> list[str]:
    cv = res["cv"]
    L = ["", f"### Blocked cross-validation on the fitted 80 % ({FOLDS} blocks) [N·m; torso N]", ""]
    L += _table("model, pooled over the blocks", cv["pooled"])
    pin_, fig = cv["pooled"], cv["pooled"][FIGAROH]
    L += [
        "",
        "Pooled over FIGAROH-tanh's: "
        + "; ".join(
            f"{k} " + " ".join(f"{a / b:.3f}" for a, b in zip(v, fig, strict=True))
            for k, v in pin_.items()
            if k != FIGAROH
        )
        + ".",
    ]
    wins = {
        k: sum(
            a[1] <= b[1] for a, b in zip(cv["per_fold"][k], cv["per_fold"][FIGAROH], strict=True)
        )
        for k in PINOBS
    }
    L += [
        "",
        "Blocks where arm_1's pinobs residual is at or below FIGAROH-tanh's: "
        + ", ".join(f"{k} {n} of {FOLDS}" for k, n in wins.items())
        + ".",
    ]
    return L


def motions(d: dict[str, Any], j: int = 1) -> list[list[float]]:
    """``[start, end]`` [s] of each motion of joint ``j`` in the held-out rows: runs of rows
    moving (``|v_j| >`` :data:`MOVING`) joined across pauses under :data:`PAUSE` s, runs
    shorter than :data:`PAUSE` dropped."""
    t = d["t"][d["held"]]
    moving = np.abs(d["v"][d["held"], j]) > MOVING
    runs: list[list[float]] = []
    for k in np.flatnonzero(moving):
        if runs and t[k] - runs[-1][1] <= PAUSE:
            runs[-1][1] = float(t[k])
        else:
            runs.append([float(t[k]), float(t[k])])
    return [r for r in runs if r[1] - r[0] >= PAUSE]


def above(res: dict[str, Any], k: str) -> list[str]:
    """The joints whose held-out ratio to FIGAROH-tanh has its whole interval above 1."""
    return [JOINTS[j] for j, (_, lo, _) in enumerate(res["ratio"][k]) if lo > 1.0]


def findings(res: dict[str, Any]) -> list[str]:
    """The diagnosis in sentences, every number read from ``res``."""
    k = "pinobs N·m offset"
    h, f = res["held_out"][k], res["held_out"][FIGAROH]
    x, lo, hi = res["ratio"][k][1]
    cv = res["cv"]["pooled"]
    cvr = [a / b for a, b in zip(cv[k], cv[FIGAROH], strict=True)]
    band = res["inertia_by_band"][k]
    runs = res["arm_1_held_motions"]
    L = ["", "### Diagnosis (arm_1)", ""]
    L.append(
        f"- At rest the two fits agree on arm_1 ({_f(h['rest'][1])} against {_f(f['rest'][1])} "
        f"N·m; means at rest {_f(h['rest_mean'][1])} and {_f(f['rest_mean'][1])}); the gap is on "
        f"its moving rows ({_f(h['moving'][1])} against {_f(f['moving'][1])}). The two have the "
        "same columns (rigid body, viscous, Coulomb tanh, rotor inertia, offset) and close "
        f"friction (viscous {_f(res['parameters'][k]['viscous'][1])} against "
        f"{_f(res['parameters'][FIGAROH]['viscous'][1])}, Coulomb "
        f"{_f(res['parameters'][k]['Coulomb'][1])} against "
        f"{_f(res['parameters'][FIGAROH]['Coulomb'][1])}): no missing term, offset or bias at "
        "rest explains it."
    )
    L.append(
        f"- The moving difference follows the acceleration: on the fitted rows *{k}* leaves an "
        f"effective inertia of {_f(band[0][1])} kg·m² about arm_1 that a per-sample least "
        f"squares on these derivatives would add ({_f(res['inertia_left_fitted'][k + ' refine=()'][1])} "
        "with `refine=()`), and on the held-out motion "
        f"{_f(res['inertia_left_held_moving_arm_1'][k])} (FIGAROH-tanh "
        f"{_f(res['inertia_left_held_moving_arm_1'][FIGAROH])})."
    )
    if band[0][1] * band[-1][1] < 0:
        L.append(
            f"- That inertia depends on how fast the content is: after a moving average of "
            f"{BANDS[-2]} rows it is {_f(band[-2][1])}, of {BANDS[-1]} rows {_f(band[-1][1])} "
            "kg·m², of the other sign. No one constant inertia fits arm_1's fast and slow torque "
            "at once (a drive's compliance or torque filtering would be a dynamic term, in "
            "neither model); pinobs's momentum windows weigh the slower content, FIGAROH's "
            "per-sample rows the faster, which the per-sample score on the same derivatives "
            "rewards."
        )
    L.append(
        f"- The held-out ratio on arm_1 is {x:.3f}, 90 % interval [{lo:.2f}, {hi:.2f}], from "
        f"{len(runs)} motion(s) of arm_1 in the held-out rows ("
        + ", ".join(f"{a:.1f}–{b:.1f} s" for a, b in runs)
        + "). Joints whose interval lies above 1: "
        + (", ".join(j.replace("_joint", "") for j in above(res, k)) or "none")
        + "."
    )
    L.append(
        f"- Cross-validated on the fitted 80 % only ({FOLDS} blocks), *{k}* over FIGAROH-tanh, "
        "pooled: "
        + ", ".join(f"{j.replace('_joint', '')} {r:.3f}" for j, r in zip(JOINTS, cvr, strict=True))
        + ". "
        + (
            "On the fitted rows pinobs is not behind on arm_1: nothing chosen there (a friction "
            "law, an offset, a weighting) has a gap to close, so no model-structure change is "
            "made; the held-out gap is in those held-out motions alone."
            if cvr[1] <= 1.0
            else "The fitted rows show the arm_1 gap too."
        )
    )
    held = [r[0] for r in res["ratio"][k]]
    swing = max(abs(a - b) for a, b in zip(cvr, held, strict=True))
    L.append(
        "- The same ratio held out: "
        + ", ".join(f"{j.replace('_joint', '')} {r:.3f}" for j, r in zip(JOINTS, held, strict=True))
        + f": per joint, held out and cross-validated differ by up to {swing:.2f}, more than "
        "arm_1's gap; a target of 1.0 per joint on one held-out stretch is within that spread."
    )
    return L


def markdown(res: dict[str, Any]) -> str:
    L = [
        f"Made by `python benchmarks/figaroh_gap.py` on {res['date']} in {res['seconds']:.0f} s "
        f"(FIGAROH {res['figaroh']}); the conditions are in the script's docstring. TIAGo, "
        f"real_logs.py's rows, split and derivatives ({res['held_rows']} held-out rows); "
        f"*{FIGAROH}*: figaroh_peer.py's *fed tanh*.",
        "",
    ]
    L += (
        held_out_section(res)
        + parameter_section(res)
        + inertia_section(res)
        + cv_section(res)
        + findings(res)
    )
    return "\n".join(L) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--render", action="store_true", help="the .md again from the .json")
    a = p.parse_args(argv)
    if rd.data_root() is None:
        print(f"no shared data: set {rd.ENV} or use ../shared/data; nothing run")
        return 0
    if a.render:
        res = json.loads(OUT.with_suffix(".json").read_text())
    else:
        res = run()
        OUT.with_suffix(".json").write_text(json.dumps(res, indent=1) + "\n")
    OUT.with_suffix(".md").write_text(markdown(res))
    print(markdown(res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

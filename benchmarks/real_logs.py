# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[io]", "scipy"]
# ///
"""Real-data benchmark (issue 36): held-out torque residuals [N·m] and velocity RMS on the
recorded UR10e and TIAGo logs of ``../shared/data`` (:mod:`real_data`; skipped when absent).

**Torque residual, held out.**  The inverse-dynamics prediction
``τ̂ = M(q) a + c(q, v) + g(q) + friction(v)`` against the measured torque (drive gain ×
current), RMS per joint [N·m; N for TIAGo's prismatic torso].  ``v`` and ``a`` come from
one zero-phase Savitzky–Golay fit of the logged ``q`` (a least-squares polynomial of
order :data:`SG_ORDER` over :data:`SG_WINDOW` consecutive rows, fitted on the rows'
times, so irregular stamps are honoured), the same for every model; rows that repeat
the previous position exactly (the logger's stale reads) are left out of the fit and
of the residual, and so are the first and last half-window of each log.

- UR10e: ``pinobs.identify`` (``friction=True``, its defaults otherwise) on
  :data:`UR10E_FIT`, validated on ``validation_data/ptp_10_points`` and on every
  unloaded ``identification_data`` log not used for the fit (the loaded ones carry a
  2.8 kg payload the models lack; the static poses p1..p10 are reported apart).
  ``pinobs.identify`` takes the logs at their own stamps (steps of 8-16 ms; it
  refused them before main's ``idgrid`` merge), the repeated rows left out, the two
  logs joined with a NaN row and a 1 s gap between them.  *published*: ``UR10E_parameters.txt``
  (Mamedov et al.): ``pi_rgd`` read per link as ``[Ixx Ixy Ixz Iyy Iyz Izz hx hy hz
  m]`` at the URDF joint frame's origin (their ``parse_urdf.m``,
  ``base_params_qr.m``, ``generate_rb_regressor.m``), ``pi_drvs`` as rotor inertias
  added to ``M``'s diagonal (``regressorWithMotorDynamics.m``), ``pi_frcn`` per joint
  as ``Fv·v + Fc·sign(v) + F0`` (``frictionRegressor.m``; ``sign`` is 0 below
  :data:`SIGN_DEADBAND`, as their filtered dq is at rest).  Their ``main.m`` fits
  ``ur-20_02_10-30sec_12harm``: on that log *published* is not held out.
  *pinobs+rotor*: ``pinobs.identify`` the same way, started from the URDF with the
  published rotor inertias as ``armature`` (the prior of pinobs's own rotor-inertia
  fit); *pinobs N·m*: ``weighting="torque"`` (each torque channel by its own residual
  scale; the default weighs the rows by ``M⁻¹``).
- TIAGo: the log on the loop's clock (:func:`pinobs.io.fit_clock`, stale rows
  dropped); ``pinobs.identify(holdout=0.2)`` with arm_5..7's torque channels left out
  (zero on most rows), and with ``weighting="torque"`` (*pinobs N·m*), also with
  ``offset=True`` (*pinobs N·m offset*: a constant torque per joint, FIGAROH's joint
  offset; every identified model's prediction is less its offset,
  :func:`predict_identified`), and that without the smoother's passes (``refine=()``): the first 80 % fits, the last 20 % is held out.  FIGAROH:
  measured by ``figaroh_peer.py`` (FIGAROH 1.0.2 on these rows and derivatives, and by its
  own protocol; read from ``figaroh_peer.json`` when it is there,
  :func:`figaroh_measured`), the numbers quoted in ``shared/data/README.md`` beside them.
  For reference (not ``pinobs.identify``), pinobs's own columns fitted at each sample on
  FIGAROH's *same rows* (:func:`pinobs_columns`, :func:`lsq_pinobs_columns`,
  :data:`TIAGO_LSQ`): plain weighted least squares (no prior, no physical consistency),
  and pinobs's ``solve`` with a wide prior without and with physical consistency, and with
  its own prior: what consistency, the prior and the momentum form each cost there.

**Velocity RMS** [rad/s, m/s for the torso] of ``pinobs.estimate`` (default
``clock="auto"``, σ from the log) against the robot's own velocity (UR10e ``dq``,
TIAGo ``tiago_velocity.csv``), from 1 s after the start (TIAGo: over the held-out 20 %
only), over the joints whose torques are measured (TIAGo: torso and arm_1..4):
``kf`` (default), ``kf*`` (the best ``jerk_psd`` of :data:`JERK_GRID`, chosen on the
reference itself: optimistic), ``ekf``, ``riemannian``, ``kalman`` on the nominal
model and on the identified one (``+id``), each also blended per joint with ``kf``
(``+nb``: ``never_behind=True``, :mod:`pinobs.observers.neverbehind`), ``ekf`` on the
identified model with its learned torque offset and the blend (``ekf+auto+nb+id``:
``disturbance_psd="auto"``), and ``adaptive`` (nominal start), alone and blended with
``kf`` (``adaptive+nb``), and started from the identified model (``adaptive+id``, not in
``--quick``); on the
UR10e also ``ekf`` and ``riemannian`` on the *pinobs+rotor* model (``+rotor``) and on
the published one (``+pub``: rotor inertias as armature, ``Fv`` as damping, ``Fc`` as
pinobs's tanh-smoothed Coulomb friction, no offset).  The reference's own noise floor:
its RMS difference to the non-causal Savitzky–Golay velocity above and to the central
difference of ``q``.  Re-initialisations after a divergence (``df.attrs["bad_rows"]``)
are counted.

**TX40** (FIGAROH's ``staubli_TX40`` example): motor encoder positions and currents
read as joint positions and torques by ``pinobs.io.read_log(..., drives=...)``
(:func:`tx40_drives`: FIGAROH's reduction matrix, ratios 32, 32, 45, −48, 45, 32 and
the coupled wrist's ``T[5, 4]``, ``q = T⁻¹ θ_m`` with offsets −π/2, +π/2 on joints 2,
3, ``τ = Tᵀ i``).  ``pinobs.load`` refuses the URDF (singular mass matrix along joint
6); loaded with ``check=False``, ``pinobs.identify(holdout=0.2)`` (armature on: the
rotors make ``M`` regular) on the log decimated to 1 kHz, by default and with
``refine=()``; held-out torque residuals on the full-rate log with Savitzky–Golay
derivatives over :data:`TX40_SG_WINDOW` and :data:`SG_WINDOW` rows (FIGAROH measured
by ``figaroh_peer.py`` as for TIAGo, the README's quote beside it), over all the held-out rows
and apart over its moving ones and those at rest (:data:`TX40_REST_SPEED`), with
``offset=True`` too, and for reference a weighted least-squares fit with FIGAROH's
model's columns, coupled wrist included (:func:`lsq_figaroh_columns`).  Observers (``kf``,
``kf*``, ``ekf``, ``riemannian``, nominal and ``+id``) on the log decimated to 1 kHz
against the Savitzky–Golay velocity of the full 5 kHz log (:data:`TX40_SG_WINDOW`
rows, order :data:`SG_ORDER`), from 1 s on and over the held-out 20 %; the
reference's spread, its RMS difference to the same fit over twice the window, is given.

    python benchmarks/real_logs.py            # writes benchmarks/real_logs.{md,json}
    python benchmarks/real_logs.py --quick    # 3 UR10e logs, fewer observers, printed
    python benchmarks/real_logs.py --render   # the .md again from the .json
    python benchmarks/real_logs.py --sections tiago tx40 --torque-only
        # those sections' torque residuals only (no observers), merged into the .json
"""

from __future__ import annotations

import argparse
import json
import math
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

import pinobs
import pinobs.io
from pinobs.model.friction import friction_basis
from pinobs.model.identification.leastsquares import pseudo_inertia, solve
from pinobs.model.identification.regressor import MomentumRegressor
from pinobs.tolerances import COULOMB_SMOOTHING_VELOCITY

#: Savitzky–Golay window [rows] and polynomial order of the derivatives of q.
SG_WINDOW, SG_ORDER = 21, 3
#: UR10e logs pinobs identifies on (unloaded, multi-harmonic, 40 s and 50 s).
UR10E_FIT = ("ur-20_02_12-40sec_12harm", "ur-20_02_12-50sec_12harm")
#: The log the published parameters were fitted on (their main.m).
UR10E_PUBLISHED_FIT = "ur-20_02_10-30sec_12harm"
#: Grid of kf's jerk_psd [rad²/s⁵] for the tuned kf*.
JERK_GRID = tuple(10.0**k for k in range(-6, 6))
#: |v| [rad/s] below which the published model's sign(v) Coulomb term is 0.
SIGN_DEADBAND = 1e-6
#: Gap [s] between two UR10e logs joined for pinobs.identify.
UR10E_JOIN_GAP = 1.0
#: Seconds at the start of a log left out of the velocity RMS (the observers' start).
SETTLE = 1.0
#: FIGAROH on TIAGo arm_1..4 [N·m], 20 % held out (shared/data/README.md).
FIGAROH_README = {"sign": (1.77, 4.59, 1.96, 1.57), "tanh": (0.87, 2.70, 1.40, 0.86)}
#: FIGAROH run side by side by ``figaroh_peer.py``: its results, beside this script.
FIGAROH_PEER = Path(__file__).with_name("figaroh_peer.json")
#: figaroh_peer.py's runs: label here → its key (*fed*: these rows and derivatives; *own*:
#: FIGAROH's example's own filtering and derivatives, scored on the same held-out rows).
FIGAROH_RUNS = {
    "same rows, sign": "fed sign",
    "same rows, tanh": "fed tanh",
    "own protocol, sign": "own sign",
    "own protocol, tanh": "own tanh",
}
#: The measured FIGAROH runs the issue's targets are computed against (tanh Coulomb).
FIGAROH_TARGET_RUNS = ("same rows, tanh", "own protocol, tanh")
#: ``--quick``: the moving UR10e logs run (ptp_10_points and the first two unloaded ones).
QUICK_UR10E_LOGS = 3
UR10E_MODELS = ("nominal", "pinobs", "pinobs N·m", "pinobs+rotor", "published")
TIAGO_TORQUE_JOINTS = rd.TIAGO_JOINTS[:5]  # torso, arm_1..4 (arm_5..7 efforts mostly 0)
#: TIAGo's identifications beside the default ``pinobs`` (options of ``pinobs.identify``):
#: each torque channel by its own residual scale in N·m, and with a torque offset per joint.
TIAGO_VARIANTS: dict[str, dict[str, Any]] = {
    "pinobs N·m": {"weighting": "torque"},
    "pinobs N·m offset": {"weighting": "torque", "offset": True},
    "pinobs N·m offset refine=()": {"weighting": "torque", "offset": True, "refine": ()},
}
#: TIAGo's reference fits of pinobs's own columns at each sample (:func:`lsq_pinobs_columns`,
#: not ``pinobs.identify``): label → ``(prior, physically consistent)``; ``prior``: ``None``
#: plain least squares, or the factor on pinobs's prior widths with ``solve`` (no Huber),
#: :data:`TIAGO_WIDE_PRIOR` (*wide prior*) or 1 (pinobs's own prior, with its Huber loss).
TIAGO_LSQ: dict[str, tuple[float | None, bool]] = {
    "lsq pinobs columns": (None, False),
    "lsq pinobs columns, wide prior": (1e3, False),
    "lsq pinobs columns, wide prior, consistent": (1e3, True),
    "pinobs solve, per-sample rows": (1.0, True),
}
#: Factor on pinobs's prior widths that leaves TIAGo's fit to the data (at 1e6 ``solve``
#: lost precision, fitted residual 60-160 N·m on arm_1..4 against 2, until its steps took a
#: truncated SVD there: now within 0.3 % of 1e3, ``tests/io/test_real_logs_lsq.py``).
TIAGO_WIDE_PRIOR = 1e3


# ------------------------------------------------------------------ helpers
def figaroh_measured(path: Path = FIGAROH_PEER) -> dict[str, Any] | None:
    """FIGAROH's held-out RMS per joint measured by ``figaroh_peer.py``, or None when its
    ``.json`` is not there: ``{"label": "FIGAROH <version> (measured)", "tiago": {run:
    [torso, arm_1..4]}, "tx40": {window: {run: [j1..j6]}}}``, ``run`` a key of
    :data:`FIGAROH_RUNS`; the *own protocol* runs have their own derivatives, the same for
    every window."""
    if not path.exists():
        return None
    r = json.loads(path.read_text())
    x = r["tx40"]
    windows = [w for w in x if w.isdigit()]
    return {
        "label": f"FIGAROH {r['figaroh']} (measured)",
        "tiago": {k: r["tiago"][v]["held_out"] for k, v in FIGAROH_RUNS.items()},
        "tx40": {
            w: {
                k: (x[w] if v.startswith("fed") else x)[v]["held_out"]
                for k, v in FIGAROH_RUNS.items()
            }
            for w in windows
        },
    }


def worst_ratio(values, reference) -> float:
    """The largest ``values[i] / reference[i]`` over the joints both give."""
    return max(a / b for a, b in zip(values, reference, strict=False))


def sg_fit(t: np.ndarray, q: np.ndarray, window: int = SG_WINDOW, order: int = SG_ORDER):
    """Zero-phase Savitzky–Golay ``(q, v, a)`` on the rows' own times (window shifted inward at
    the ends)."""
    n = len(t)
    start = np.clip(np.arange(n) - window // 2, 0, n - window)
    idx = start[:, None] + np.arange(window)[None, :]
    dt = t[idx] - t[:, None]
    s = float(np.median(np.abs(dt[:, -1] - dt[:, 0]))) or 1.0
    V = (dt / s)[..., None] ** np.arange(order + 1)
    c = np.linalg.pinv(V) @ q[idx]  # (n, order+1, nq)
    return c[:, 0], c[:, 1] / s, 2.0 * c[:, 2] / s**2


def arrays(frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = frame["t"].to_numpy(dtype=float)
    q = frame[[c for c in frame.columns if c.startswith("q.")]].to_numpy(dtype=float)
    tau = frame[[c for c in frame.columns if c.startswith("tau.")]].to_numpy(dtype=float)
    return t, q, tau


def fresh(q: np.ndarray) -> np.ndarray:
    """Rows that do not repeat the previous row's position exactly."""
    keep = np.ones(len(q), bool)
    keep[1:] = ~(q[1:] == q[:-1]).all(axis=1)
    return keep


def rms(x: np.ndarray, axis=0) -> np.ndarray:
    return np.sqrt(np.mean(np.square(x), axis=axis))


def predict_robot(robot: pinobs.Robot, q, v, a) -> np.ndarray:
    """``M a + c + g − τ_f(v)`` of a pinobs robot (its friction when on)."""
    out = np.empty_like(v)
    for k in range(len(q)):
        out[k] = robot.inverse_dynamics(q[k], v[k], a[k]) - robot.friction_torque(v[k])
    return out


def predict_identified(ident, q, v, a) -> np.ndarray:
    """:func:`predict_robot` of ``pinobs.identify``'s model less its torque offset ``b``
    (zero unless ``offset=True``): its dynamics are ``τ + b = M a + c + g + f(v)``
    (:mod:`pinobs.model.identification`), and a :class:`pinobs.Robot` has no offset."""
    return predict_robot(ident.robot, q, v, a) - ident.offset


# ------------------------------------------------------------------ UR10e published model
def _vector(text: str, name: str) -> np.ndarray:
    m = re.search(rf"{name}\s*=\s*\[([^\]]*)\]", text)
    if m is None:
        raise ValueError(f"UR10E_parameters.txt has no {name}")
    return np.array(m.group(1).split(), dtype=float)


class Published:
    """Mamedov et al.'s identified UR10e (module docstring for the ordering)."""

    def __init__(self, robot: pinobs.Robot) -> None:
        text = (rd.data_root() / "ur10e" / "UR10E_parameters.txt").read_text(encoding="utf-8")
        rgd, self.rotor, frcn = (_vector(text, n) for n in ("pi_rgd", "pi_drvs", "pi_frcn"))
        if rgd.shape != (60,) or self.rotor.shape != (6,) or frcn.shape != (18,):
            raise ValueError("UR10E_parameters.txt: unexpected sizes")
        self.fv, self.fc, self.f0 = frcn.reshape(6, 3).T
        model = robot.model.copy()
        for i in range(6):
            ixx, ixy, ixz, iyy, iyz, izz, hx, hy, hz, m = rgd[10 * i : 10 * i + 10]
            # Pinocchio's order: m, h, Ixx, Ixy, Iyy, Ixz, Iyz, Izz (inertia at the frame origin)
            pi = np.array([m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz])
            model.inertias[i + 1] = pin.Inertia.FromDynamicParameters(pi)
        model.armature = np.zeros(model.nv)  # the rotor inertias are added below, explicitly
        self.model, self.data = model, model.createData()
        # the same as a pinobs Robot for the observers: rotor inertias as armature, Fv as
        # damping, Fc as (tanh-smoothed) Coulomb friction; the offset F0 has no place there
        as_robot = model.copy()
        as_robot.armature = self.rotor.copy()
        as_robot.damping = self.fv.copy()
        as_robot.friction = self.fc.copy()
        self.robot = robot.with_model(as_robot, name="ur10e-published", friction=True)

    def predict(self, q, v, a) -> np.ndarray:
        out = np.empty_like(v)
        for k in range(len(q)):
            out[k] = pin.rnea(self.model, self.data, q[k], v[k], a[k])
        # sign(v) with |v| below SIGN_DEADBAND read as 0: the fit's round-off on constant
        # positions (about 1e-16) would otherwise switch the full Coulomb torque at rest
        sign = np.where(np.abs(v) > SIGN_DEADBAND, np.sign(v), 0.0)
        return out + self.rotor * a + self.fv * v + self.fc * sign + self.f0


# ------------------------------------------------------------------ observers
def velocity_runs(
    frame, robot, identified, ref, rows, joints, quick: bool, extra=()
) -> dict[str, Any]:
    """RMS [rad/s] over ``rows`` and ``joints`` of each observer against ``ref``."""
    out: dict[str, Any] = {}
    seconds: dict[str, float] = {}
    said: dict[str, list[str]] = {}
    restarts: dict[str, int] = {}

    def run(label: str, name: str, rob, options=None) -> None:
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                df = pinobs.estimate(name, frame, robot=rob, options=options or {})
            restarts[label] = sum("re-initialised" in str(b[1]) for b in df.attrs["bad_rows"])
            if name != "kf":
                said[label] = [
                    w[:300]
                    for w in df.attrs["warnings"]
                    if not w.startswith(("log clock", "no noise"))
                ]
            v = df[[f"v{i}" for i in range(rob.nv)]].to_numpy()
            err = (v - ref)[rows][:, joints]
            out[label] = float(rms(err.ravel())) if np.isfinite(err).all() else math.inf
        except Exception as e:  # report, do not hide: a refusal is a result here
            out[label] = math.nan
            out.setdefault("errors", {})[label] = f"{type(e).__name__}: {e}"  # type: ignore[index]
        seconds[label] = time.perf_counter() - t0

    run("kf", "kf", robot)
    # the full grid in --quick too: its every third density made kf* 1.2-1.6x the full grid's
    # on UR10e logs (0.0146 against 0.0102 rad/s), flattering every ratio to kf*
    grid = JERK_GRID
    best = (math.inf, math.nan)
    for j in grid:
        run(f"kf(jerk_psd={j:g})", "kf", robot, {"jerk_psd": j})
        best = min(best, (out.pop(f"kf(jerk_psd={j:g})"), j))
    out["kf*"], out["kf*_jerk_psd"] = best
    names = ("ekf", "riemannian") if quick else ("ekf", "riemannian", "kalman")
    nb = {"never_behind": True}
    alone = {"never_behind": False}  # (pinobs.estimate's default for a model-based family: nb)
    for name in names:
        run(name, name, robot, alone)
        run(f"{name}+nb", name, robot, nb)
        if identified is not None:
            run(f"{name}+id", name, identified, alone)
            run(f"{name}+nb+id", name, identified, nb)
    if identified is not None:
        run("ekf+auto+nb+id", "ekf", identified, {**nb, "disturbance_psd": "auto"})
    for suffix, rob in extra:
        for name in ("ekf", "riemannian"):
            run(f"{name}+{suffix}", name, rob, alone)
    run("adaptive", "adaptive", robot, alone)
    run("adaptive+nb", "adaptive", robot, nb)
    if identified is not None and not quick:
        run("adaptive+id", "adaptive", identified, alone)  # learning on from the identified model
    out["seconds"] = float(sum(seconds.values()))
    out["seconds_by_run"] = seconds
    out["warnings"] = said
    out["restarts"] = {k: n for k, n in restarts.items() if n}
    return out


def reference_floor(t, q, ref, rows, joints) -> dict[str, float]:
    _, v_sg, _ = sg_fit(t, q)
    cd = np.full_like(ref, np.nan)
    cd[1:-1] = (q[2:] - q[:-2]) / (t[2:] - t[:-2])[:, None]
    ok = rows.copy()
    ok[[0, -1]] = False
    return {
        "ref_vs_savgol": float(rms((ref - v_sg)[ok][:, joints].ravel())),
        "ref_vs_central_difference": float(rms((ref - cd)[ok][:, joints].ravel())),
    }


# ------------------------------------------------------------------ UR10e
def ur10e_names(folder: str) -> list[str]:
    return [n.split("/")[-1] for n in rd.list_logs() if n.startswith(f"ur10e/{folder}/")]


def ur10e_identify(names: tuple[str, ...], robot: pinobs.Robot, **options: Any):
    """pinobs.identify on the named logs at their stamps (repeated rows left out), joined
    with a NaN row and :data:`UR10E_JOIN_GAP` between them, nothing held out; ``options``
    for :func:`pinobs.identify`."""
    parts_t, parts_q, parts_tau, off = [], [], [], 0.0
    for n in names:
        t, q, tau = arrays(rd.load_log(f"ur10e/identification_data/{n}").frame)
        keep = fresh(q)
        t, q, tau = t[keep] - t[keep][0] + off, q[keep], tau[keep]
        parts_t += [t, [t[-1] + UR10E_JOIN_GAP / 2]]
        parts_q += [q, np.full((1, 6), np.nan)]
        parts_tau += [tau, np.full((1, 6), np.nan)]
        off = t[-1] + UR10E_JOIN_GAP
    T, Q, TAU = (np.concatenate(p[:-1]) for p in (parts_t, parts_q, parts_tau))
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ident = pinobs.identify(robot, (T, Q, TAU), holdout=0.0, **options)
    return ident, time.perf_counter() - t0, [str(w.message) for w in caught]


def ur10e(quick: bool) -> dict[str, Any]:
    robot = rd.ur10e_robot()
    fit = UR10E_FIT[1:] if quick else UR10E_FIT
    ident, secs, said = ur10e_identify(fit, robot)
    published = Published(robot)
    # the nominal URDF with the published rotor inertias (armature, not identified by pinobs)
    with_rotor = robot.model.copy()
    with_rotor.armature = published.rotor.copy()
    ident_r, secs_r, _ = ur10e_identify(fit, robot.with_model(with_rotor))
    # each torque channel weighted by its own residual scale in N·m (not the default)
    ident_t, _, _ = ur10e_identify(fit, robot, weighting="torque")
    unloaded = [
        n
        for n in ur10e_names("identification_data")
        if n not in fit and not re.search(r"(?<!un)load", n, re.IGNORECASE)
    ]
    moving = ["ur-20_01_17-ptp_10_points", *unloaded]
    static = [n for n in ur10e_names("validation_data") if re.search(r"-p\d+$", n)]
    if quick:
        moving, static = moving[:QUICK_UR10E_LOGS], static[:1]
    torque: dict[str, Any] = {}
    velocity: dict[str, Any] = {}
    pooled: dict[str, list[np.ndarray]] = {m: [] for m in UR10E_MODELS}
    for group, names in (("moving", moving), ("static", static)):
        for n in names:
            folder = "validation_data" if n.startswith("ur-20_01_17") else "identification_data"
            log = rd.load_log(f"ur10e/{folder}/{n}")
            t, q, tau = arrays(log.frame)
            keep = fresh(q)
            tk, qk, tauk = t[keep], q[keep], tau[keep]
            _, v, a = sg_fit(tk, qk)
            inner = np.zeros(len(tk), bool)
            inner[SG_WINDOW // 2 : len(tk) - SG_WINDOW // 2] = True
            preds = {
                "nominal": predict_robot(robot, qk, v, a),
                "pinobs": predict_robot(ident.robot, qk, v, a),
                "pinobs N·m": predict_robot(ident_t.robot, qk, v, a),
                "pinobs+rotor": predict_robot(ident_r.robot, qk, v, a),
                "published": published.predict(qk, v, a),
            }
            row = {"group": group, "rows": int(inner.sum()), "seconds": float(tk[-1] - tk[0])}
            for k, p in preds.items():
                res = (p - tauk)[inner]
                row[k] = rms(res).tolist()
                if group == "moving" and n != UR10E_PUBLISHED_FIT:
                    pooled[k].append(res)
            row["published_held_out"] = n != UR10E_PUBLISHED_FIT
            torque[n] = row
            if group == "moving":
                rows = t >= t[0] + SETTLE
                extra = () if quick else (("rotor", ident_r.robot), ("pub", published.robot))
                vel = velocity_runs(
                    log.frame, robot, ident.robot, log.velocity, rows, list(range(6)), quick, extra
                )
                vel.update(reference_floor(t, q, log.velocity, rows, list(range(6))))
                velocity[n] = vel
                print(f"  ur10e {n}: velocity done in {vel['seconds']:.0f} s", flush=True)
    pooled_rms = {k: rms(np.vstack(v)).tolist() for k, v in pooled.items() if v}
    return {
        "joints": list(rd.UR10E_JOINTS),
        "fit_logs": list(fit),
        "identify_seconds": secs,
        "identify_warnings": said,
        "identify_report": {
            k: ident.report[k]
            for k in ("rank", "condition", "rows", "noise_std", "smoother_consistency", "warnings")
        },
        "identify_rotor_seconds": secs_r,
        "identify_rotor_report": {
            k: ident_r.report[k]
            for k in ("rank", "condition", "rows", "noise_std", "smoother_consistency", "warnings")
        },
        "torque": torque,
        "torque_pooled_moving_held_out": pooled_rms,
        "velocity": velocity,
    }


# ------------------------------------------------------------------ TIAGo
def held_out_split(t: np.ndarray, holdout: float = 0.2) -> float:
    """``pinobs.identify``'s split [s]: ``fit_end = t_end − holdout·(t_end − t_start)``, the
    rows at or before it fitted, the last ``holdout`` of the span held out (its report's
    ``fit_end``; :func:`tiago` and :func:`tx40` check that the two agree)."""
    return float(t.max() - holdout * (t.max() - t.min()))


def checked_split(ident, t: np.ndarray) -> float:
    """``ident``'s ``fit_end``, refused unless it is :func:`held_out_split` of ``t``."""
    split = float(ident.report["fit_end"])
    if not math.isclose(split, held_out_split(t), rel_tol=0.0, abs_tol=1e-9):
        raise RuntimeError(f"identify's fit_end {split} is not held_out_split {held_out_split(t)}")
    return split


def tiago_rows():
    """The TIAGo log as :func:`tiago` uses it: ``(log, clock, keep, t, q, tau)``, ``keep``
    the log's rows that are not stale (:func:`pinobs.io.fit_clock`), ``t`` the loop's clock
    on them, ``q`` and ``tau`` those rows."""
    log = rd.tiago_log()
    t_raw, q, tau = arrays(log.frame)
    clock = pinobs.io.fit_clock(t_raw, q)
    t = np.asarray(clock.t, float)
    keep = ~np.asarray(clock.stale) & np.isfinite(t)
    return log, clock, keep, t[keep], q[keep], tau[keep]


def tiago(quick: bool, velocity: bool = True) -> dict[str, Any]:
    """TIAGo: held-out torque residuals of the identified models; the observers' velocity
    RMS unless ``velocity`` is False (``--torque-only``)."""
    log, clock, keep, t, q, tau = tiago_rows()
    robot = log.robot
    ref = log.velocity[keep]
    frame = log.frame[keep].copy()
    frame["t"] = t
    # arm_5..7's efforts are zero on most rows: their channels are left out (identify
    # refuses them); the wrist bodies, then seen through arm_1..4's torques alone, make
    # the condition 2e6 (M⁻¹ weighting) to 4e7 (torque weighting): hence max_condition
    common = {"holdout": 0.2, "exclude": list(rd.TIAGO_JOINTS[5:]), "max_condition": 1e8}
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ident = pinobs.identify(robot, (t, q, tau), **common)
    secs = time.perf_counter() - t0
    idents = {"pinobs": ident}
    for label, opts in TIAGO_VARIANTS.items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            idents[label] = pinobs.identify(robot, (t, q, tau), **common, **opts)
    split = checked_split(ident, t)
    _, v, a = sg_fit(t, q)
    inner = np.zeros(len(t), bool)
    inner[SG_WINDOW // 2 : len(t) - SG_WINDOW // 2] = True
    held = inner & (t > split)
    fitted = inner & (t <= split)
    preds = {"nominal": predict_robot(robot, q, v, a)}
    preds.update({k: predict_identified(i, q, v, a) for k, i in idents.items()})
    lsq, lsq_said = tiago_lsq(robot, common["exclude"], q, v, a, tau, fitted)
    preds.update(lsq)
    torque = {
        k: {"held_out": rms((p - tau)[held]).tolist(), "fitted": rms((p - tau)[fitted]).tolist()}
        for k, p in preds.items()
    }
    joints = [rd.TIAGO_JOINTS.index(j) for j in TIAGO_TORQUE_JOINTS]
    moving = np.abs(ref[held][:, joints]).max(axis=1) > 0.01
    out = {
        "joints": list(rd.TIAGO_JOINTS),
        "clock": str(clock.report.describe())
        if hasattr(clock.report, "describe")
        else str(clock.report),
        "rows_dropped_stale": int((~keep).sum()),
        "fit_end": split,
        "held_out_rows": int(held.sum()),
        "held_out_moving_share": float(moving.mean()),
        "identify_seconds": secs,
        "identify_warnings": [str(w.message) for w in caught],
        "identify_report": {
            k: ident.report[k]
            for k in ("rank", "condition", "rows", "noise_std", "smoother_consistency", "warnings")
        },
        "torque": torque,
        "lsq_inconsistent": lsq_said,
    }
    if velocity:
        rows = t > split
        vel = velocity_runs(frame, robot, ident.robot, ref, rows, joints, quick)
        vel.update(reference_floor(t, q, ref, rows, joints))
        out["velocity"] = vel
    return out


def pinobs_columns(robot: pinobs.Robot, exclude, q, v, a) -> tuple[Any, np.ndarray, np.ndarray]:
    """pinobs's own columns at each sample (acceleration form, not the momentum windows of
    ``pinobs.identify``): ``τ − I_known a = Y(q, v, a) π + Σ_f diag(φ_f(v)) F_f + diag(a) I_a
    − b``, the columns of :class:`MomentumRegressor` (rigid body, its friction law's terms
    ``φ_f``: viscous ``v`` and Coulomb ``tanh(v/v_s)``, rotor inertia on every actuated joint,
    offset ``b``; the signs of its ``system``).  Returns ``(regressor, C, I_known a)``: ``C``
    ``(N, nv, p)`` and the torque of the armature not identified (``(N, nv)``; zero when
    every rotor is), the fit being ``τ − I_known a ≈ C θ``."""
    reg = MomentumRegressor(robot, armature=True, weighting="torque", exclude=exclude)
    model = robot.model
    data = model.createData()
    act = list(reg.actuated)
    sel = np.zeros((model.nv, reg.n_joint))
    sel[act, range(reg.n_joint)] = 1.0
    arm = [reg.actuated_names.index(j) for j in reg.armature_joints]
    known = np.array(model.armature, dtype=float)
    known[reg.armature_coordinates] = 0.0

    def columns(k: int) -> np.ndarray:
        va = v[k, act]
        phi = [
            sel * friction_basis(f, va, reg.smoothing, reg.stribeck_velocity)
            for f in reg.friction_terms
        ]
        rigid = pin.computeJointTorqueRegressor(model, data, q[k], v[k], a[k])
        return np.hstack([rigid, *phi, sel[:, arm] * a[k, act][arm], -sel])

    return reg, np.array([columns(k) for k in range(len(q))]), known * a


def lsq_pinobs_columns(
    reg, C, known, tau, fit, channels, *, prior, consistent
) -> tuple[np.ndarray, np.ndarray]:
    """A reference fit of :func:`pinobs_columns` (not ``pinobs.identify``) on ``fit``'s rows
    of the torque ``channels``, each channel weighted by its residual's spread; returns the
    prediction ``C θ + I_known a`` on every row and ``θ``.  ``prior`` ``None``: ordinary
    least squares, then again weighted (:func:`lsq_figaroh_columns`'s recipe; no prior, no consistency);
    else ``pinobs``'s ``solve`` with its prior widths times ``prior`` (its channel weights:
    ``1.4826 · median |r|`` per channel, re-estimated at each pass), Huber's loss only at
    ``prior == 1`` (as ``identify``), and physical consistency when ``consistent``
    (every body's pseudo-inertia ⪰ 0, friction and armature ≥ 0: Wensing et al. 2017)."""
    rows = np.flatnonzero(fit)
    A = C[rows][:, channels].reshape(-1, C.shape[2])
    y = (tau - known)[rows][:, channels].ravel()
    if prior is None:
        theta = np.linalg.lstsq(A, y, rcond=None)[0]
        w = np.tile(1.0 / (A @ theta - y).reshape(-1, len(channels)).std(axis=0), len(rows))
        theta = np.linalg.lstsq(A * w[:, None], y * w, rcond=None)[0]
    else:
        channel = np.tile(np.arange(len(channels)), len(rows))
        loss = {} if prior == 1.0 else {"huber": np.inf}
        s = prior * reg.prior_std()
        theta = solve(reg, A, y, prior_std=s, consistent=consistent, channel=channel, **loss).theta
    return C @ theta + known, theta


def inconsistent(reg, theta) -> list[str]:
    """What in ``θ`` (:func:`pinobs_columns`'s order) is not physically consistent: the
    bodies whose pseudo-inertia is not ⪰ 0 (or mass ≤ 0), and the friction or armature
    below 0 by more than 1e-9 of the largest (the solver's barrier stops that close)."""
    out = []
    for k, body in enumerate(reg.bodies):
        J = pseudo_inertia(theta[10 * k : 10 * k + 10])
        if np.linalg.eigvalsh(J)[0] < -1e-12 * np.abs(J).max() or J[3, 3] <= 0:
            out.append(f"{body} (mass {J[3, 3]:.3g} kg)")
    n0, n = reg.n_inertial, reg.n_joint
    lo = slice(n0, n0 + len(reg.friction_terms) * n + len(reg.armature_joints))
    scale = 1e-9 * np.abs(theta[lo]).max()
    out += [f"{reg.names[i]} {theta[i]:.3g}" for i in range(lo.start, lo.stop) if theta[i] < -scale]
    return out


def tiago_lsq(robot, exclude, q, v, a, tau, fitted) -> tuple[dict[str, Any], dict[str, Any]]:
    """TIAGo's :data:`TIAGO_LSQ` reference fits: their predictions on every row and, per fit,
    what in it is not physically consistent (:func:`inconsistent`)."""
    reg, C, known = pinobs_columns(robot, exclude, q, v, a)
    channels = [robot.model.joints[robot.model.getJointId(j)].idx_v for j in TIAGO_TORQUE_JOINTS]
    preds, said = {}, {}
    for label, (prior, consistent) in TIAGO_LSQ.items():
        preds[label], theta = lsq_pinobs_columns(
            reg, C, known, tau, fitted, channels, prior=prior, consistent=consistent
        )
        said[label] = inconsistent(reg, theta)
    return preds, said


# ------------------------------------------------------------------ TX40
#: FIGAROH's TX40 example: motor → joint (config/TX40_config.yaml, utils/staubli_tx40_tools.py).
TX40_RATIO = (32.0, 32.0, 45.0, -48.0, 45.0, 32.0)
#: Joint-side offsets FIGAROH adds after the reduction (joints 2 and 3) [rad].
TX40_OFFSET = (0.0, -np.pi / 2, np.pi / 2, 0.0, 0.0, 0.0)
TX40_RATE, TX40_DECIMATE = 5000.0, 5
#: Savitzky–Golay window [rows at 5 kHz] and order of the TX40 reference velocity.
TX40_SG_WINDOW = 101
#: FIGAROH with tanh Coulomb on the TX40, j1..j6 [N·m], 20 % held out (shared/data/README.md).
TX40_FIGAROH_TANH = (2.09, 4.91, 1.44, 0.61, 3.33, 1.48)
#: ``pinobs.identify``'s runs on the TX40 (its options beside ``holdout=0.2``).
TX40_IDENTIFY: dict[str, dict[str, Any]] = {
    "pinobs": {},
    "pinobs refine=()": {"refine": ()},
    "pinobs offset": {"offset": True},
}
#: Reference least-squares fits with FIGAROH's columns (:func:`lsq_figaroh_columns`):
#: label → with the coupled wrist's motor-6 columns.
TX40_LSQ = {"lsq FIGAROH columns": True, "lsq FIGAROH columns, uncoupled": False}
TX40_MODELS = ("nominal", *TX40_IDENTIFY, *TX40_LSQ)
#: A held-out row is at rest when every joint's Savitzky–Golay speed is at most this [rad/s].
TX40_REST_SPEED = 0.01


def tx40_drives() -> pinobs.io.Drives:
    """FIGAROH's reduction matrix (ratios on the diagonal, the coupled wrist's ``T[5, 4]``)
    as pinobs drives; its ``curr_data`` times the reduction is its joint torque (motor
    constant 1: FIGAROH's ``process_torque_data``)."""
    T = np.diag(TX40_RATIO)
    T[5, 4] = TX40_RATIO[5]  # motor 6 turns with joints 5 and 6
    return pinobs.io.Drives(transmission=T, motor_constant=np.ones(6), position_offset=TX40_OFFSET)


def tx40_log(robot: pinobs.Robot):
    """The TX40's motor log read through :func:`tx40_drives` (``qm.``/``i.`` columns)."""
    import pandas as pd

    d = rd.data_root() / "figaroh" / "examples" / "staubli_TX40" / "data"
    motor = pd.read_csv(d / "pos_read_data.csv").to_numpy(dtype=float)
    current = pd.read_csv(d / "curr_data.csv").to_numpy(dtype=float)
    names = robot.joint_names
    frame = pd.DataFrame(
        {
            "t": np.arange(len(motor)) / TX40_RATE,
            **{f"qm.{j}": motor[:, i] for i, j in enumerate(names)},
            **{f"i.{j}": current[:, i] for i, j in enumerate(names)},
        }
    )
    return pinobs.io.read_log(frame, robot, drives=tx40_drives())


def tx40_urdf() -> Path:
    """FIGAROH's TX40 URDF in the shared data."""
    return (
        rd.data_root() / "figaroh" / "examples" / "staubli_TX40" / "urdf" / "tx40_mdh_modified.urdf"
    )


def tx40_rows():
    """``(robot, log)``: the TX40 URDF loaded with ``check=False`` (its ``M`` is singular as
    shipped) and its full-rate log through :func:`tx40_drives`; :func:`tx40` splits it at
    :func:`held_out_split` of the 1 kHz rows ``pinobs.identify`` fits."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its meshes are not in the data
        robot = pinobs.load(str(tx40_urdf()), check=False)
    return robot, tx40_log(robot)


def tx40_identify(robot: pinobs.Robot, t, q, tau) -> tuple[dict[str, Any], dict[str, Any]]:
    """``pinobs.identify(holdout=0.2)`` of each of :data:`TX40_IDENTIFY` on the log decimated
    to 1 kHz: the identifications and what each reported."""
    sl = slice(0, None, TX40_DECIMATE)
    idents: dict[str, Any] = {}
    said: dict[str, Any] = {}
    for label, opts in TX40_IDENTIFY.items():
        t0 = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            ident = pinobs.identify(robot, (t[sl], q[sl], tau[sl]), holdout=0.2, **opts)
        idents[label] = ident
        said[f"identify[{label}]"] = {
            "seconds": time.perf_counter() - t0,
            "warnings": [str(w.message) for w in caught],
            "armature": ident.robot.model.armature.tolist(),
            "damping": ident.robot.model.damping.tolist(),
            "coulomb": ident.robot.model.friction.tolist(),
            "offset": ident.offset.tolist(),
            **{
                k: ident.report[k]
                for k in (
                    "rank",
                    "condition",
                    "rows",
                    "fit_end",
                    "smoother_consistency",
                    "warnings",
                )
            },
        }
    return idents, said


def lsq_figaroh_columns(robot: pinobs.Robot, t, q, v, a, tau, fit, *, coupled: bool) -> np.ndarray:
    """A reference fit with FIGAROH's TX40 columns (not FIGAROH): ``τ = Y(q, v, a) π + F_v v
    + F_c tanh(v/0.01) + I_a a + b`` per joint, plus with ``coupled`` the shared motor 6's
    three (FIGAROH's ``_add_coupling``: its rotor inertia, viscous and Coulomb friction on
    joints 5 and 6, ``Tᵀ I_m T`` and ``Tᵀ f_m(T v)`` off the diagonal); ordinary least
    squares on every :data:`TX40_DECIMATE`-th row of ``fit``, then again with each channel
    weighted by its residual's spread (FIGAROH's weighted least squares).  No prior, no
    physical consistency.  Returns the prediction on every row."""
    model = robot.model
    data = model.createData()
    vs = COULOMB_SMOOTHING_VELOCITY  # pinobs's smoothing of the Coulomb sign

    def columns(k: int) -> np.ndarray:
        y = pin.computeJointTorqueRegressor(model, data, q[k], v[k], a[k])
        cols = [y, np.diag(v[k]), np.diag(np.tanh(v[k] / vs)), np.diag(a[k]), np.eye(6)]
        if coupled:
            c = np.zeros((6, 3))
            sign = np.tanh((v[k, 4] + v[k, 5]) / vs)
            c[4] = [a[k, 5], v[k, 5], sign]
            c[5] = [a[k, 4], v[k, 4], sign]
            cols.append(c)
        return np.hstack(cols)

    rows = np.flatnonzero(fit)[::TX40_DECIMATE]
    A = np.vstack([columns(k) for k in rows])
    y = tau[rows].ravel()
    theta = np.linalg.lstsq(A, y, rcond=None)[0]
    w = np.tile(1.0 / (A @ theta - y).reshape(-1, 6).std(axis=0), len(rows))
    theta = np.linalg.lstsq(A * w[:, None], y * w, rcond=None)[0]
    return np.array([columns(k) @ theta for k in range(len(t))])


def tx40(quick: bool, velocity: bool = True) -> dict[str, Any]:
    """The TX40 through pinobs's drives: identified with armature (1 kHz, last 20 % held
    out), held-out torque residuals (all held-out rows, moving ones, at-rest ones); the
    observers on the log decimated to 1 kHz against the full-rate non-causal
    Savitzky–Golay velocity unless ``velocity`` is False (module docstring)."""
    urdf = tx40_urdf()
    out: dict[str, Any] = {}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # its meshes are not in the data
            pinobs.load(str(urdf))
        out["load"] = "loaded"
    except Exception as e:
        out["load"] = f"{type(e).__name__}: {str(e).splitlines()[0][:300]}"
    robot, log = tx40_rows()
    t, q, tau = log.t, log.q, log.tau
    out.update(rows_full_rate=len(q), seconds=float(t[-1]), joints=list(robot.joint_names))
    idents, said = tx40_identify(robot, t, q, tau)
    out.update(said)
    split = checked_split(idents["pinobs"], t[::TX40_DECIMATE])
    out["fit_end"] = split
    torque: dict[str, Any] = {}
    for window in (TX40_SG_WINDOW, SG_WINDOW):
        _, v, a = sg_fit(t, q, window, SG_ORDER)
        inner = np.zeros(len(t), bool)
        inner[window // 2 : len(t) - window // 2] = True
        held = inner & (t > split)
        still = np.abs(v).max(axis=1) <= TX40_REST_SPEED
        parts = {"held_out": held, "moving": held & ~still, "at_rest": held & still}
        rows: dict[str, Any] = {f"{k}_rows": int(m.sum()) for k, m in parts.items()}
        preds = {"nominal": predict_robot(robot, q, v, a)}
        preds.update({k: predict_identified(i, q, v, a) for k, i in idents.items()})
        for label, coupled in TX40_LSQ.items():
            fit = inner & (t <= split)
            preds[label] = lsq_figaroh_columns(robot, t, q, v, a, tau, fit, coupled=coupled)
        for k, p in preds.items():
            rows[k] = rms((p - tau)[held]).tolist()
            for part in ("moving", "at_rest"):
                rows[f"{k} [{part}]"] = rms((p - tau)[parts[part]]).tolist()
        torque[str(window)] = rows
    out["torque"] = torque
    if velocity:
        out.update(tx40_velocity(robot, t, q, tau, split, idents["pinobs"].robot, quick))
    return out


def tx40_velocity(robot, t, q, tau, split, identified, quick) -> dict[str, Any]:
    """Observers at 1 kHz against the full-rate Savitzky–Golay velocity, from 1 s on and
    over the held-out 20 % (the identified model did not see it)."""
    import pandas as pd

    sl = slice(0, None, TX40_DECIMATE)
    _, ref_full, _ = sg_fit(t, q, TX40_SG_WINDOW, SG_ORDER)
    _, ref_wide, _ = sg_fit(t, q, 2 * TX40_SG_WINDOW + 1, SG_ORDER)
    td, qd, taud, ref = t[sl], q[sl], tau[sl], ref_full[sl]
    names = robot.joint_names
    frame = pd.DataFrame(
        {
            "t": td,
            **{f"q.{j}": qd[:, i] for i, j in enumerate(names)},
            **{f"tau.{j}": taud[:, i] for i, j in enumerate(names)},
        }
    )
    rows_v = td >= td[0] + SETTLE
    vel = velocity_runs(frame, robot, identified, ref, rows_v, list(range(6)), quick)
    held_v = td > split
    inner = slice(TX40_SG_WINDOW, -TX40_SG_WINDOW)
    vel["ref_window_spread"] = float(rms((ref_full - ref_wide)[inner].ravel()))
    vel_held = velocity_runs(frame, robot, identified, ref, held_v, list(range(6)), True)
    return {"velocity": vel, "velocity_held_out": vel_held}


# ------------------------------------------------------------------ tables
def _f(x: float, d: int = 3) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "—"
    if math.isinf(x):
        return "inf"
    return f"{x:.{d}g}"


OBS_COLS = (
    "kf",
    "kf*",
    "ekf",
    "ekf+id",
    "riemannian",
    "riemannian+id",
    "kalman",
    "kalman+id",
    "ekf+nb",
    "riemannian+nb",
    "kalman+nb",
    "ekf+nb+id",
    "riemannian+nb+id",
    "kalman+nb+id",
    "ekf+auto+nb+id",
    "adaptive",
    "adaptive+nb",
    "adaptive+id",
    "ekf+rotor",
    "riemannian+rotor",
    "ekf+pub",
    "riemannian+pub",
)


def tx40_rest_split(rows: dict[str, Any], j: list[str]) -> list[str]:
    """The TX40's held-out residuals over its moving rows and its rows at rest."""
    L: list[str] = []
    if "moving_rows" in rows:
        L.append("")
        L.append(
            f"Held-out rows split (SG window {TX40_SG_WINDOW}): {rows['moving_rows']} moving, "
            f"{rows['at_rest_rows']} at rest (every joint's speed ≤ {TX40_REST_SPEED:g} rad/s); "
            "the fitted 80 % has no row at rest. At rest the measured current is not a "
            "function of the pose: at the one held-out pose it drifts by several N·m while "
            "nothing moves (the drives' hold, stiction), which no model of `(q, v, a)` follows."
        )
        L.append("")
        L.append("| model | rows | " + " | ".join(j) + " |")
        L.append("|---|---|" + "---|" * len(j))
        for k in (k for k in TX40_MODELS if k in rows):
            for part in ("moving", "at_rest"):
                vals = rows[f"{k} [{part}]"]
                L.append(f"| {k} | {part} | " + " | ".join(_f(v) for v in vals) + " |")
    return L


def quote_gap(measured: dict[str, Any], run: str) -> float:
    """The largest relative difference over j1..j6 between the README's TX40 FIGAROH-tanh
    quote and the measured ``run`` at :data:`TX40_SG_WINDOW`."""
    got = np.asarray(measured["tx40"][str(TX40_SG_WINDOW)][run])
    quote = np.asarray(TX40_FIGAROH_TANH)
    return float(np.max(np.abs(got - quote) / quote))


def tx40_references(measured: dict[str, Any] | None, window: str) -> dict[str, list[float]]:
    """FIGAROH-tanh per joint for issue 36's TX40 target: the measured tanh runs at
    ``window`` (when figaroh_peer.json is there), and the README's quote."""
    refs = {} if measured is None else {k: measured["tx40"][window][k] for k in FIGAROH_TARGET_RUNS}
    return refs | {"README tanh": list(TX40_FIGAROH_TANH)}


def tx40_torque_table(
    x: dict[str, Any], measured: dict[str, Any] | None, j: list[str]
) -> list[str]:
    """The TX40's held-out residuals per window and model, FIGAROH's measured and quoted
    rows, and issue 36's target (j1–j4 ≤ 0.8 × FIGAROH-tanh) against each FIGAROH-tanh."""
    window0 = next(iter(x["torque"]))
    names = list(tx40_references(measured, window0))
    L = [
        "| SG window [rows] | model | "
        + " | ".join(j)
        + " | "
        + " | ".join(f"worst j1–j4 / FIGAROH {k}" for k in names)
        + " |",
        "|---|---|" + "---|" * (len(j) + len(names)),
    ]
    for window, rows in x["torque"].items():
        refs = tx40_references(measured, window)
        models = [(k, rows[k]) for k in TX40_MODELS if k in rows]
        models += [
            (f"{measured['label']}, {k}", v)
            for k, v in (measured or {}).get("tx40", {}).get(window, {}).items()
        ]
        for k, vals in models:
            ratios = [worst_ratio(vals[:4], r[:4]) for r in refs.values()]
            L.append(
                f"| {window} | {k} | "
                + " | ".join(_f(v) for v in vals)
                + " | "
                + " | ".join(_f(r) for r in ratios)
                + " |"
            )
    L.append(
        "| — | FIGAROH-tanh (README quote) | "
        + " | ".join(_f(v) for v in TX40_FIGAROH_TANH)
        + " | "
        + " | ".join("—" for _ in names)
        + " |"
    )
    L.append("")
    L.append(
        "The last columns: the largest over j1–j4 of the row's held-out residual over "
        "FIGAROH-tanh's, each FIGAROH-tanh at the row's window (issue 36's target: ≤ 0.8). "
        "*own protocol* rows: the same FIGAROH run in both windows (its own derivatives). "
        "*pinobs offset*: "
        "`offset=True` (a constant torque per joint, FIGAROH's joint offset; the prediction "
        "is the model's less it). *lsq FIGAROH columns*: not FIGAROH but its TX40 model's "
        "columns (rigid body, viscous, tanh Coulomb, rotor inertia, offset per joint, and the "
        "coupled wrist's motor 6: its inertia, viscous and Coulomb friction on j5 and j6), "
        "fitted by per-channel weighted least squares on the same derivatives and rows, no "
        "prior, no physical consistency (`lsq_figaroh_columns`); *uncoupled*: without "
        "motor 6's columns. j5 and j6 share motor 6: its rotor inertia and friction act on "
        "both joints (`Tᵀ I_m T`, `Tᵀ f_m(T v)`, off the diagonal), which pinobs's per-joint "
        "armature and friction cannot express. FIGAROH 1.0.2's `initialize` never calls its "
        "example's coupled-wrist columns (`add_additional_parameters`): its measured runs "
        "have none."
    )
    lsq = next(iter(TX40_LSQ))
    above = [
        name
        for i, name in enumerate(j)
        if all(lsq in r and r[lsq][i] > TX40_FIGAROH_TANH[i] for r in x["torque"].values())
    ]
    if above:
        L.append("")
        L.append(
            "The README's FIGAROH-tanh quote does not state its derivatives' window or rows: "
            f"on these rows and derivatives, with either window, the least squares with "
            f"FIGAROH's own columns (*{lsq}*) is above it on {', '.join(above)}"
            + (
                f"; the quote differs by up to {quote_gap(measured, 'own protocol, tanh'):.0%} "
                "per joint from FIGAROH's own protocol measured (its filtering and derivatives), "
                f"by up to {quote_gap(measured, 'same rows, tanh'):.0%} from FIGAROH on "
                f"these rows and derivatives ({TX40_SG_WINDOW} rows; figaroh_peer.md)."
                if measured is not None
                else ", so its column compares unlike protocols there."
            )
        )
    return L


def tx40_markdown(x: dict[str, Any]) -> list[str]:
    """The TX40's block: held-out torque residuals and velocity RMS."""
    measured = figaroh_measured()
    L = ["", "### TX40: torque residual RMS, last 20 % held out [N·m]", ""]
    ident = x["identify[pinobs]"]
    L.append(
        f"Motor encoders and currents read through `pinobs.io.Drives` (FIGAROH's reduction "
        f"matrix, ratios {', '.join(f'{r:g}' for r in TX40_RATIO)}, coupled wrist "
        f"`T[5, 4]`; offsets −π/2, +π/2 on joints 2, 3; motor constant 1 as FIGAROH). "
        f"`pinobs.load` refuses the URDF as shipped ({x['load'].split(':')[0]}); loaded with "
        f"`check=False`, `pinobs.identify(holdout=0.2)` with armature on the log decimated "
        f"to 1 kHz fits t ≤ {x['fit_end']:.2f} s ({ident['seconds']:.0f} s; rank "
        f"{ident['rank']}, condition {ident['condition']:.3g}); identified armature "
        + ", ".join(f"{a:.3g}" for a in ident["armature"])
        + " kg·m². Residuals on the full 5 kHz log, derivatives: Savitzky–Golay order "
        f"{SG_ORDER} over the window given. "
        + (
            "FIGAROH-tanh: quoted from shared/data/README.md (figaroh_peer.py has not been "
            "run: no figaroh_peer.json)."
            if measured is None
            else f"{measured['label']}: run by `benchmarks/figaroh_peer.py` on these rows, "
            "split and derivatives (*same rows*, each window) and by its example's own "
            "protocol (*own protocol*: its filtering and derivatives, whatever the window), "
            "Coulomb as shipped (*sign*) and as tanh (*tanh*); the README's quote below them."
        )
    )
    L.append("")
    j = [n.replace("joint_", "j") for n in x["joints"]]
    L += tx40_torque_table(x, measured, j)
    L += tx40_rest_split(x["torque"].get(str(TX40_SG_WINDOW), {}), j)
    if "velocity" not in x:  # (a --torque-only run not merged into a stored one)
        return L
    L.append("")
    L.append(
        "### TX40: velocity RMS at 1 kHz against the full-rate Savitzky–Golay velocity [rad/s]"
    )
    L.append("")
    v = x["velocity"]
    L.append(
        f"Reference: Savitzky–Golay {TX40_SG_WINDOW} rows, order {SG_ORDER}, of the 5 kHz "
        f"log; against the same fit over {2 * TX40_SG_WINDOW + 1} rows it differs by "
        f"{_f(v['ref_window_spread'])} rad/s. `+id`: the model `pinobs.identify` fitted "
        "(with armature: the nominal `M` is singular)."
    )
    L.append("")
    cols = [c for c in OBS_COLS if c in v or c in v.get("errors", {})]
    L.append("| rows | " + " | ".join(cols) + " | kf* jerk_psd |")
    L.append("|---|" + "---|" * (len(cols) + 1))
    for label, vv in (("from 1 s", v), ("held-out 20 %", x["velocity_held_out"])):
        L.append(
            f"| {label} | "
            + " | ".join(_f(vv.get(c, math.nan)) for c in cols)
            + f" | {_f(vv['kf*_jerk_psd'], 2)} |"
        )
    restarts = {k: n for k, n in v.get("restarts", {}).items() if n}
    if restarts:
        L.append("")
        L.append(
            "Re-initialised after a divergence (rows, whole log): "
            + ", ".join(f"`{k}` {n}" for k, n in restarts.items())
            + " (the nominal model's `M` is singular: those observers restart at every row)."
        )
    errs = {**v.get("errors", {})}
    if errs:
        L.append("")
        for k, msg in errs.items():
            L.append(f"- {k} refused: {msg.splitlines()[0][:300]}")
    return L


def tiago_figaroh_said(measured: dict[str, Any] | None) -> str:
    """The TIAGo block's sentence on where its FIGAROH rows come from."""
    if measured is None:
        return (
            "FIGAROH: quoted from shared/data/README.md (figaroh_peer.py has not been run: "
            "no figaroh_peer.json)."
        )
    return (
        f"{measured['label']}: run by `benchmarks/figaroh_peer.py` (figaroh_peer.md), on "
        "these rows, split and derivatives (*same rows*: torso and arm_1..4's torques fitted) "
        "and by its example's own protocol (*own protocol*: its filtering and derivatives, "
        "fitted before the split, scored on these held-out rows), with its Coulomb column as "
        "shipped (*sign*) and as tanh (*tanh*); the README's quote below them."
    )


def tiago_torque_table(t: dict[str, Any], measured: dict[str, Any] | None) -> list[str]:
    """TIAGo's held-out and fitted residuals per model, FIGAROH's measured and quoted rows,
    and issue 36's target (arm_1..4 ≤ FIGAROH-tanh) against each measured tanh run."""
    j = [x.replace("_joint", "") for x in t["joints"]]
    L = ["| model | part | " + " | ".join(j) + " |", "|---|---|" + "---|" * len(j)]
    for k, d in t["torque"].items():
        for part in ("held_out", "fitted"):
            L.append(f"| {k} | {part} | " + " | ".join(_f(x) for x in d[part]) + " |")
    for k, vals in (measured or {}).get("tiago", {}).items():
        cells = [_f(x) for x in vals] + ["—"] * (len(j) - len(vals))
        L.append(f"| {measured['label']}, {k} | held_out | " + " | ".join(cells) + " |")
    for k, vals in FIGAROH_README.items():
        cells = ["—"] + [_f(x) for x in vals] + ["—"] * (len(j) - 5)
        L.append(f"| FIGAROH ({k} Coulomb, README quote) | held_out | " + " | ".join(cells) + " |")
    refs = {f"README {k}": list(v) for k, v in FIGAROH_README.items() if k == "tanh"}
    if measured is not None:
        refs = {k: measured["tiago"][k][1:5] for k in FIGAROH_TARGET_RUNS} | refs
    L += [
        "",
        "Issue 36's target, arm_1..4 ≤ FIGAROH-tanh: the worst over arm_1..4 of the model's "
        "held-out residual over FIGAROH-tanh's (met when ≤ 1).",
        "",
        "| model | " + " | ".join(f"/ FIGAROH {k}" for k in refs) + " |",
        "|---|" + "---|" * len(refs),
    ]
    for k, d in t["torque"].items():
        ratios = [worst_ratio(d["held_out"][1:5], r) for r in refs.values()]
        L.append(f"| {k} | " + " | ".join(_f(x) for x in ratios) + " |")
    return L


def _price(what: str, over: str, num: list[float], den: list[float]) -> str:
    """``num`` over ``den`` on the held-out arm_1..4 (channels 1..4), as a sentence."""
    ratios = (f"×{a / b:.3f}" for a, b in zip(num[1:5], den[1:5], strict=True))
    return f"{what} price on the held-out arm_1..4 ({over}): " + ", ".join(ratios)


def tiago_lsq_said(t: dict[str, Any]) -> list[str]:
    """What TIAGo's reference rows (:data:`TIAGO_LSQ`) are, and what in each is not
    physically consistent."""
    said = t.get("lsq_inconsistent")
    if not said:
        return []
    L = [
        "",
        "Reference rows, not `pinobs.identify` (`lsq_pinobs_columns`): pinobs's own columns "
        "(rigid body, viscous, Coulomb `tanh(v/0.01)`, rotor inertia and offset on every "
        "joint: `MomentumRegressor`'s) at each sample, on the same Savitzky–Golay "
        "derivatives and fitted rows as FIGAROH's *same rows* runs, torso and arm_1..4's "
        "torques, each channel weighted by its residual's spread; FIGAROH's acceleration "
        "form, not identify's momentum windows. *lsq pinobs columns*: ordinary then weighted "
        "least squares, no prior, no physical consistency (as the TX40's "
        "`lsq_figaroh_columns`); *wide prior*: pinobs's `solve` with its prior widths × "
        f"{TIAGO_WIDE_PRIOR:g} and no Huber loss, without and with physical consistency "
        "(*consistent*: pseudo-inertias ⪰ 0, friction and armature ≥ 0); *pinobs solve, "
        "per-sample rows*: its prior and Huber loss as `identify` has them, consistent. "
        "Not physically consistent in each fit:",
        "",
    ]
    for k, bad in said.items():
        L.append(f"- {k}: " + ("; ".join(bad) if bad else "nothing (consistent)"))
    free, cons = (t["torque"].get(k, {}).get("held_out") for k in list(TIAGO_LSQ)[1:3])
    if free and cons:
        L += [
            "",
            _price(
                "Physical consistency's", "*wide prior, consistent* over *wide prior*", cons, free
            )
            + ". arm_5..7's torques are not fitted: with the wide prior nothing holds the "
            "wrist's parameters that arm_1..4's torques do not see, and the consistent fit's "
            "prediction of those three channels is meaningless (their columns above).",
        ]
    refined, plain = (t["torque"].get(k, {}).get("held_out") for k in list(TIAGO_VARIANTS)[1:3])
    if refined and plain:
        over = "*pinobs N·m offset* over *pinobs N·m offset refine=()*"
        L += ["", _price("The smoother's passes'", over, refined, plain) + "."]
    return L


def header(res: dict[str, Any]) -> list[str]:
    """The table's first lines: how, when and on what it was made, and any rerun since."""
    L: list[str] = [
        f"Made by `python benchmarks/real_logs.py{' --quick' if res['quick'] else ''}` on "
        f"{res['date']} in {res['seconds']:.0f} s (pinobs {pinobs.__version__}, Pinocchio "
        f"{pin.__version__}, on a shared, loaded machine); the conditions are in the script's "
        "docstring. Data: `../shared/data` (UR10e: Mamedov et al. 2020; TIAGo and TX40: "
        "FIGAROH's examples; sources in its README).",
        "",
    ]
    for r in res.get("reruns", []):
        L += [
            f"Rerun since: `python benchmarks/real_logs.py {r['options']}` on {r['date']} in "
            f"{r['seconds']:.0f} s (those sections' results replace the run's above).",
            "",
        ]
    return L


def markdown(res: dict[str, Any]) -> str:
    L = header(res)
    u = res.get("ur10e")
    if u:
        L.append("### UR10e: held-out torque residual RMS [N·m]")
        L.append("")
        L.append(
            f"Identified by `pinobs.identify` on {', '.join(u['fit_logs'])} "
            f"(at their stamps, {u['identify_seconds']:.0f} s); "
            f"derivatives: Savitzky–Golay {SG_WINDOW} rows, order {SG_ORDER}, on the stamps. "
            f"*published*: UR10E_parameters.txt († its own fitting log, not held out); "
            '*pinobs N·m*: `weighting="torque"` (each torque channel by its own residual '
            "scale; the default weighs the rows by M⁻¹)."
        )
        L.append("")
        j = [x.replace("_joint", "") for x in u["joints"]]
        L.append("| log | rows | model | " + " | ".join(j) + " |")
        L.append("|---|---|---|" + "---|" * len(j))
        for n, row in u["torque"].items():
            for k in UR10E_MODELS:
                mark = " †" if k == "published" and not row["published_held_out"] else ""
                tag = " (static)" if row["group"] == "static" else ""
                L.append(
                    f"| {n}{tag} | {row['rows']} | {k}{mark} | "
                    + " | ".join(_f(x) for x in row[k])
                    + " |"
                )
        L.append("")
        L.append("Pooled over the moving held-out logs (published's fitting log excluded):")
        L.append("")
        L.append("| model | " + " | ".join(j) + " |")
        L.append("|---|" + "---|" * len(j))
        for k, vals in u["torque_pooled_moving_held_out"].items():
            L.append(f"| {k} | " + " | ".join(_f(x) for x in vals) + " |")
        L.append("")
    t = res.get("tiago")
    if t:
        L.append("### TIAGo: torque residual RMS, last 20 % held out [N·m; torso N]")
        L.append("")
        L.append(
            f"Loop's clock (`fit_clock`), {t['rows_dropped_stale']} stale rows dropped; "
            f"`pinobs.identify(holdout=0.2)` fits t ≤ {t['fit_end']:.1f} s "
            f"({t['identify_seconds']:.0f} s); {t['held_out_rows']} held-out rows, "
            f"{100 * t['held_out_moving_share']:.0f} % of them moving (|v| > 0.01). "
            "arm_5..7's torque channels left out (zero on most rows); *pinobs N·m*: "
            '`weighting="torque"`; *pinobs N·m offset*: also `offset=True` (a constant torque '
            "per joint; the prediction is the model's less it); *refine=()*: the "
            "Savitzky–Golay velocities only, without the model-based smoother's passes "
            f"(their consistency ρ = {t['identify_report']['smoother_consistency']:.3g} on "
            "this log for the default run, against about 1 when model and torques explain "
            "the positions: `pinobs.identify`'s docstring). "
            + tiago_figaroh_said(figaroh_measured())
        )
        L.append("")
        L += tiago_torque_table(t, figaroh_measured())
        L += tiago_lsq_said(t)
        L.append("")
    L.append("### Velocity RMS against the robot's own velocity [rad/s]")
    L.append("")
    L.append(
        "`kf*`: best `jerk_psd` on the reference (optimistic); `+id`: the pinobs-identified "
        "model; floor: the reference against the non-causal Savitzky–Golay velocity / "
        "central difference."
    )
    L.append("")
    L.append("| log | " + " | ".join(OBS_COLS) + " | kf* jerk_psd | floor SG / CD |")
    L.append("|---|" + "---|" * (len(OBS_COLS) + 2))
    logs = []
    if u:
        logs += [(f"ur10e {n}", v) for n, v in u["velocity"].items()]
    if t and "velocity" in t:
        logs.append(("tiago (held-out 20 %)", t["velocity"]))
    for n, v in logs:
        L.append(
            f"| {n} | "
            + " | ".join(_f(v.get(c, math.nan)) for c in OBS_COLS)
            + f" | {_f(v['kf*_jerk_psd'], 2)} | {_f(v['ref_vs_savgol'])} / "
            f"{_f(v['ref_vs_central_difference'])} |"
        )
    L.append("")
    L.append(
        "Against issue 36's targets (ratios of the RMS above): default `kf` over `kf*` "
        "(target ≤ 1.3); the worst of `ekf`, `riemannian`, `kalman` on the nominal model over "
        "`kf` (≤ 1.2), alone (`never_behind=False`) and blended with `kf` (`+nb`: "
        "`never_behind=True`, what `pinobs.estimate` runs on a log by default); `ekf+id` and "
        "`riemannian+id` over `kf` (≤ 0.7), alone, blended, and `ekf` with the learned "
        'disturbance (`+auto`: `disturbance_psd="auto"`); `adaptive` over `kf*` (≤ 0.5), '
        "alone and blended with `kf` (`adaptive+nb`); "
        "with the `+rotor` model, `ekf+rotor` over `kf`."
    )
    L.append("")
    L.append(
        "| log | kf / kf* | nominal model-based / kf | nominal +nb / kf | ekf+id / kf "
        "| riemannian+id / kf | ekf+nb+id / kf | riemannian+nb+id / kf | ekf+auto+nb+id / kf "
        "| adaptive / kf* | adaptive+nb / kf* | ekf+rotor / kf |"
    )
    L.append("|---|" + "---|" * 11)
    for n, v in logs:
        worst = max(v.get(c, math.nan) for c in ("ekf", "riemannian", "kalman"))
        worst_nb = max(v.get(c, math.nan) for c in ("ekf+nb", "riemannian+nb", "kalman+nb"))
        cells = (
            v["kf"] / v["kf*"],
            worst / v["kf"],
            worst_nb / v["kf"],
            v.get("ekf+id", math.nan) / v["kf"],
            v.get("riemannian+id", math.nan) / v["kf"],
            v.get("ekf+nb+id", math.nan) / v["kf"],
            v.get("riemannian+nb+id", math.nan) / v["kf"],
            v.get("ekf+auto+nb+id", math.nan) / v["kf"],
            v.get("adaptive", math.nan) / v["kf*"],
            v.get("adaptive+nb", math.nan) / v["kf*"],
            v.get("ekf+rotor", math.nan) / v["kf"],
        )
        L.append(f"| {n} | " + " | ".join(_f(c, 2) for c in cells) + " |")
    x = res.get("tx40")
    if x:
        L += tx40_markdown(x)
    L.append("")
    L.append(
        "Re-initialisations after a divergence (`ObserverDiverged`, rows in "
        "`df.attrs['bad_rows']`), total over the logs above: "
        + ", ".join(
            f"`{k}` {sum(v['restarts'].get(k, 0) for _, v in logs)}"
            for k in OBS_COLS
            if k != "kf*" and any(v["restarts"].get(k) for _, v in logs)
        )
        + "."
    )
    errs = [(n, v["errors"]) for n, v in logs if v.get("errors")]
    if errs:
        L.append("")
        L.append("Refusals and failures:")
        L.append("")
        for n, e in errs:
            for k, msg in e.items():
                L.append(f"- {n}, {k}: {msg.splitlines()[0][:300]}")
    return "\n".join(L) + "\n"


#: The benchmark's sections, in the order they run.
SECTIONS = ("ur10e", "tiago", "tx40")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="3 UR10e logs, fewer observers")
    p.add_argument("--out", default=str(Path(__file__).with_name("real_logs.md")))
    p.add_argument("--render", action="store_true", help="rewrite the .md from the .json (no runs)")
    p.add_argument(
        "--sections",
        nargs="+",
        choices=SECTIONS,
        default=list(SECTIONS),
        help="run these only; the others' results are kept from the existing .json",
    )
    p.add_argument(
        "--torque-only",
        action="store_true",
        help="tiago and tx40: the torque residuals only (no observers), merged into the "
        "existing .json, whose velocity results are kept",
    )
    a = p.parse_args(argv)
    if a.render:
        res = json.loads(Path(a.out).with_suffix(".json").read_text())
        Path(a.out).with_suffix(".md").write_text(markdown(res))
        return 0
    sections = [x for x in SECTIONS if x in a.sections]
    if a.torque_only and "ur10e" in sections:
        if a.sections != list(SECTIONS):
            p.error("--torque-only runs tiago and tx40 only: the UR10e's has no such mode")
        sections.remove("ur10e")
    partial = a.torque_only or sections != list(SECTIONS)
    stored = Path(a.out).with_suffix(".json")
    if partial and not (a.quick or stored.exists()):
        p.error(f"--sections/--torque-only merge into {stored}, which does not exist: run all")
    if rd.data_root() is None:
        print(f"no data: set {rd.ENV} or put the shared data at ../shared/data; skipped")
        return 0
    t0 = time.perf_counter()
    date = time.strftime("%Y-%m-%d", time.gmtime())
    res: dict[str, Any] = {"quick": a.quick, "date": date}
    merged = partial and not a.quick  # into the stored run (a --quick run is printed only)
    if merged:
        res = json.loads(stored.read_text())
    runs = {
        "ur10e": lambda: ur10e(a.quick),
        "tiago": lambda: tiago(a.quick, velocity=not a.torque_only),
        "tx40": lambda: tx40(a.quick, velocity=not a.torque_only),
    }
    for name in sections:
        print(f"{name} ...", flush=True)
        new = runs[name]()
        res[name] = {**res.get(name, {}), **new} if merged else new
    seconds = time.perf_counter() - t0
    if merged:
        command = " ".join(["--sections", *sections] + (["--torque-only"] if a.torque_only else []))
        res.setdefault("reruns", []).append({"options": command, "date": date, "seconds": seconds})
    else:
        res["seconds"] = seconds
    md = markdown(res)
    print(md)
    if not a.quick:
        stored.write_text(json.dumps(res, indent=1, default=float))
        Path(a.out).with_suffix(".md").write_text(md)
    print(f"done in {seconds:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[io,peers]", "scipy"]
# ///
"""FIGAROH run side by side (issue 36): its identification on the TIAGo and Stäubli TX40
logs of ``../shared/data`` (FIGAROH's own examples), held-out torque residual RMS per
joint [N·m; N for TIAGo's torso], on the held-out rows of :mod:`real_logs`.

FIGAROH (``pip install figaroh``, ``pinobs[peers]``) is driven through its own API:
``figaroh.identification.base_identification.BaseIdentification`` (``initialize``,
``solve``, and its held-out validation, ``identif_config["validation_data_file"]``,
whose per-joint ``rmse_identified`` is reported), its examples' classes imported from
the data folder by path at run time (``TiagoIdentification``, ``TX40Identification``),
their legacy configs turned into FIGAROH 1.0's format by FIGAROH's own
``figaroh.utils.config_migration.convert_legacy_to_unified`` (its ``extends:`` template
and the calibration section dropped: the wheel ships no templates, the examples'
calibration sections are empty).  Robots: ``pinocchio.RobotWrapper`` on the URDF's
model (``figaroh.tools.load_robot`` needs the meshes, which the data lack).  TIAGo's
``identification.py`` names ``config/tiago_unified_config.yaml`` and
``urdf/tiago_48_schunk.urdf``, which the data do not hold: ``config/tiago_config.yaml``
and ``urdf/tiago.urdf`` are used (the script sets the drive constants, active joints and
data files itself, as ``identification.py`` does; the filter is the class's default).

**(a) Same rows** (``fed``): the rows, split and Savitzky–Golay derivatives of
:mod:`real_logs` (:func:`real_logs.tiago_rows`, :func:`real_logs.tx40_rows`,
:func:`real_logs.held_out_split`, :func:`real_logs.sg_fit`: first 80 % fitted, the
last 20 % held out, the first and last half-window of the log left out), fed to a
``BaseIdentification`` whose ``load_trajectory_data`` returns them and whose
``process_kinematics_data`` keeps them as given (FIGAROH would low-pass them again);
torques as :mod:`real_logs` reads them; ``solve(decimate=False)`` (every fitted row).
FIGAROH's model columns: rigid body, viscous ``v``, Coulomb, rotor inertia ``a``,
offset ``1`` per joint (the examples' configs).  TIAGo: the same 8-joint model as
pinobs, torso and arm_1..4's torques fitted (``torque_fit_joints``; arm_5..7's are zero
on most rows, pinobs leaves them out too).  TX40: the model pinobs loads.

**(b) FIGAROH's protocol** (``own``): the example's class as shipped, its own filtering
and derivatives (TIAGo: median 5 and 4th-order 2 Hz Butterworth on the logged
positions and velocities, acceleration by ``np.gradient``, rows 921..6791 of the log,
``decimate`` by 10; TX40: motor to joint, median 5 and 100 Hz Butterworth at 5 kHz,
``np.gradient`` twice, 20 torque rows cut at each end, ``decimate`` by 10), fitted
only on rows before the split (its window cut there), then its model predicts the
whole log through its own pipeline (its validation set: the whole log) and the
prediction is scored on :mod:`real_logs`'s held-out rows against the same torques.

**Coulomb.** FIGAROH's regressor fills its Coulomb column with ``np.sign(v)``
(``figaroh.tools.regressor.RegressorBuilder._fill_joint_regressor_sample``) and has no
option for another; *tanh*: the one change made, that column replaced by
``tanh(v / 0.01)`` (pinobs's ``COULOMB_SMOOTHING_VELOCITY`` [rad/s]) after
``build_regressor_basic`` (wrapped where ``base_identification`` calls it, so fit and
validation both use it; the column is checked to hold ``sign(v)`` before).

**Physical consistency.** FIGAROH's least squares has no constraint; its base parameters
that stand for one mass, rotor inertia or friction coefficient alone are checked for sign
(:func:`negative_alone`; a pseudo-inertia is not readable from its base combinations).

    python benchmarks/figaroh_peer.py   # writes benchmarks/figaroh_peer.{md,json}
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import json
import logging
import math
import os
import sys
import tempfile
import time
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

sys.path.insert(0, str(Path(__file__).resolve().parent))
import real_data as rd
import real_logs as rl

from pinobs.tolerances import COULOMB_SMOOTHING_VELOCITY

COULOMB = ("sign", "tanh")
#: TIAGo's joints whose torques are fitted and scored (torso, arm_1..4).
TIAGO_FIT = rl.TIAGO_TORQUE_JOINTS
#: FIGAROH's TIAGo example: rows it identifies on, and its drive constants (identification.py).
TIAGO_TRUNCATE = (921, 6791)
TIAGO_REDUCTION = dict(zip(rd.TIAGO_JOINTS, rd.TIAGO_REDUCTION, strict=True))
TIAGO_KMOTOR = dict(zip(rd.TIAGO_JOINTS, rd.TIAGO_KMOTOR, strict=True))
#: TX40: the torque rows FIGAROH's example cuts at each end (5 × its Butterworth order).
TX40_BORDER = 20
#: A quote within this relative difference on every joint is said to match a run.
PROTOCOL_MATCH = 0.10


def examples() -> Path:
    """FIGAROH's examples in the shared data.

    Raises:
        FileNotFoundError: no shared data folder.
    """
    root = rd.data_root()
    if root is None:
        raise FileNotFoundError(f"no shared data folder: set {rd.ENV} or use ../shared/data")
    return root / "figaroh" / "examples"


def figaroh_version() -> str:
    from importlib.metadata import version

    return version("figaroh")


# ------------------------------------------------------------------ FIGAROH's pieces
def example_module(robot: str, tools: str):
    """An example's tools module, imported from the data folder by path."""
    path = examples() / robot / "utils" / tools
    spec = importlib.util.spec_from_file_location(f"figaroh_example_{robot}", path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def unified_config(legacy: Path, name: str, folder: Path) -> str:
    """The example's legacy config in FIGAROH 1.0's format (FIGAROH's own migration), its
    ``extends:`` template and calibration section dropped (module docstring)."""
    import yaml
    from figaroh.utils.config_migration import convert_legacy_to_unified

    doc = yaml.safe_load(legacy.read_text(encoding="utf-8"))
    doc.pop("calibration", None)
    unified = convert_legacy_to_unified(doc)
    unified.pop("extends")
    unified["robot"]["name"] = name
    out = folder / f"{name}.yaml"
    out.write_text(yaml.safe_dump(unified), encoding="utf-8")
    return str(out)


@contextlib.contextmanager
def coulomb_model(kind: str) -> Iterator[None]:
    """FIGAROH's regressor as shipped (``sign``) or with its Coulomb column
    ``sign(v)`` replaced by ``tanh(v / COULOMB_SMOOTHING_VELOCITY)`` (``tanh``)."""
    import figaroh.identification.base_identification as bi

    shipped = bi.build_regressor_basic
    if kind == "sign":
        yield
        return

    def smoothed(robot, q, v, a, identif_config, tau=None):
        W = shipped(robot, q, v, a, identif_config, tau)
        nv, n = robot.model.nv, len(q)
        V = np.asarray(v, float).reshape(n, nv)
        for j in identif_config["act_idxv"]:
            col = 11 * nv + j  # 10 inertial columns per joint, then fv, then fs (regressor.py)
            rows = slice(j * n, (j + 1) * n)
            if not np.array_equal(W[rows, col], np.sign(V[:, j])):
                raise RuntimeError(f"FIGAROH's column {col} is not sign(v) of joint {j}")
            W[rows, col] = np.tanh(V[:, j] / COULOMB_SMOOTHING_VELOCITY)
        return W

    bi.build_regressor_basic = smoothed
    try:
        yield
    finally:
        bi.build_regressor_basic = shipped


@contextlib.contextmanager
def working_directory(folder: Path) -> Iterator[None]:
    """Run in ``folder`` (the TX40 example reads ``data/*.csv`` relative to it)."""
    before = Path.cwd()
    os.chdir(folder)
    try:
        yield
    finally:
        os.chdir(before)


def set_active(iden, joints: list[str]) -> None:
    """The examples' active-joint entries of ``identif_config`` (identification.py)."""
    ps, model = iden.identif_config, iden.model
    ps["active_joints"] = list(joints)
    ps["act_Jid"] = [model.getJointId(j) for j in joints]
    ps["act_J"] = [model.joints[i] for i in ps["act_Jid"]]
    ps["act_idxq"] = [J.idx_q for J in ps["act_J"]]
    ps["act_idxv"] = [J.idx_v for J in ps["act_J"]]


def quiet_solve(iden, *, decimate: bool, truncate=None) -> str:
    """``initialize`` and ``solve`` without plots; FIGAROH's printed report returned."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        iden.initialize(truncate=truncate)
        iden.solve(decimate=decimate, plotting=False, save_results=False)
    return out.getvalue()


def validation(iden, joints: list[str]) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """FIGAROH's validation: its predicted and measured torque series per joint
    (samples × joints) and its per-joint ``rmse_identified``."""
    vm = iden.result.get("validation_metrics") or {}
    if vm.get("validation_source") != "validation_data":
        raise RuntimeError(f"FIGAROH did not validate on the held-out set: {vm.keys()}")
    pred = np.column_stack([vm["tau_identified_per_joint"][j] for j in joints])
    meas = np.column_stack([vm["tau_measured_per_joint"][j] for j in joints])
    return pred, meas, [vm["per_joint"][j]["rmse_identified"] for j in joints]


# ------------------------------------------------------------------ (a) the same rows
def fed_identification(robot, config: str, sets: dict[Any, tuple], joints, fit_joints):
    """A FIGAROH ``BaseIdentification`` fed ``sets`` (``None``: the fitted rows,
    ``"held_out"``: the held-out ones; each ``(t, q, v, a, tau)``), derivatives as given."""
    from figaroh.identification.base_identification import BaseIdentification

    class Fed(BaseIdentification):
        def load_trajectory_data(self, data_source=None):
            t, q, v, a, tau = sets[data_source]
            return {
                "timestamps": t[:, None],
                "positions": q,
                "velocities": v,
                "accelerations": a,
                "torques": tau,
            }

        def process_kinematics_data(self, filter_config=None):
            # the derivatives as given (FIGAROH's filter_kinematics_data would filter them)
            keys = ("timestamps", "positions", "velocities", "accelerations")
            self.processed_data = {k: self.raw_data[k] for k in keys}

    iden = Fed(robot, config)
    set_active(iden, joints)
    iden.identif_config["torque_fit_joints"] = list(fit_joints)
    iden.identif_config["validation_data_file"] = "held_out"
    return iden


#: FIGAROH's names of the standard parameters that physics wants ≥ 0: mass, rotor inertia,
#: viscous and Coulomb friction (its ``m_``, ``Ia_``, ``fv_``, ``fs_`` prefixes).
NONNEGATIVE = ("m_", "Ia_", "fv_", "fs_")


def negative_alone(iden) -> dict[str, float]:
    """FIGAROH's base parameters that are one standard parameter alone (no combination: a
    name without spaces) of :data:`NONNEGATIVE` and negative: a physical inconsistency its
    base parameters show without mapping back (a pseudo-inertia's is not readable from
    the combinations)."""
    return {
        n: float(p)
        for n, p in zip(iden.params_base, iden.phi_base, strict=True)
        if " " not in n and n.startswith(NONNEGATIVE) and p < 0
    }


def run_fed(robot, config, sets, joints, fit_joints, kind: str) -> dict[str, Any]:
    """(a): FIGAROH fitted on ``sets[None]``, its held-out RMS per fitted joint."""
    t0 = time.perf_counter()
    with coulomb_model(kind):
        iden = fed_identification(robot, config, sets, joints, fit_joints)
        report = quiet_solve(iden, decimate=False)
    pred, meas, figaroh_rms = validation(iden, list(fit_joints))
    held_tau = sets["held_out"][4][:, [joints.index(j) for j in fit_joints]]
    if not np.allclose(meas, held_tau):
        raise RuntimeError("FIGAROH's held-out torques are not the rows fed to it")
    return {
        "held_out": rl.rms(pred - held_tau).tolist(),
        "figaroh_rmse_identified": figaroh_rms,
        "base_parameters": len(iden.phi_base),
        "negative_alone": negative_alone(iden),
        "fit_rmse_stacked": float(iden.rms_error),
        "seconds": time.perf_counter() - t0,
        "report_tail": report.strip().splitlines()[-12:],
    }


def tiago_same_rows(config: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """(a) on TIAGo; also returns what (b) needs: the held-out rows in the log's numbering,
    the split and the torques."""
    log, _, keep, t, q, tau = rl.tiago_rows()
    split = rl.held_out_split(t)
    _, v, a = rl.sg_fit(t, q)
    inner = np.zeros(len(t), bool)
    inner[rl.SG_WINDOW // 2 : len(t) - rl.SG_WINDOW // 2] = True
    fit, held = inner & (t <= split), inner & (t > split)
    sets = {m: (t[r], q[r], v[r], a[r], tau[r]) for m, r in ((None, fit), ("held_out", held))}
    robot = pin.RobotWrapper(log.robot.model.copy())
    out: dict[str, Any] = {"split": split, "fit_rows": int(fit.sum()), "held_rows": int(held.sum())}
    for kind in COULOMB:
        out[f"fed {kind}"] = run_fed(robot, config, sets, list(rd.TIAGO_JOINTS), TIAGO_FIT, kind)
    rows = np.flatnonzero(keep)  # the log's row of each kept row
    return out, {
        "held_rows": rows[held],
        "fit_end_row": int(rows[t <= split][-1]) + 1,
        "tau": log.frame[[f"tau.{j}" for j in rd.TIAGO_JOINTS]].to_numpy(),
    }


# ------------------------------------------------------------------ (b) FIGAROH's protocol
def scored(pred: np.ndarray, tau: np.ndarray, rows: np.ndarray) -> list[float]:
    """RMS per joint of ``pred − tau`` over ``rows`` (both in the log's numbering)."""
    return rl.rms((pred - tau)[rows]).tolist()


def tiago_own(config: str, same: dict[str, Any], kind: str) -> dict[str, Any]:
    """(b) on TIAGo: FIGAROH's ``TiagoIdentification`` as identification.py drives it, its
    window ``TIAGO_TRUNCATE`` cut at the split; validated on the whole log."""
    tools = example_module("tiago", "tiago_tools.py")

    class Own(tools.TiagoIdentification):  # type: ignore[name-defined]
        def load_trajectory_data(self, data_source=None):  # validation: the whole log again
            return super().load_trajectory_data()

    data = examples() / "tiago" / "data" / "identification" / "dynamic"
    robot = pin.RobotWrapper(
        pin.buildModelFromUrdf(str(examples() / "tiago" / "urdf" / "tiago.urdf"))
    )
    t0 = time.perf_counter()
    with coulomb_model(kind):
        iden = Own(robot, config)
        ps = iden.identif_config
        ps["reduction_ratio"], ps["kmotor"] = TIAGO_REDUCTION, TIAGO_KMOTOR
        set_active(iden, list(rd.TIAGO_JOINTS))
        ps["pos_data"] = str(data / "tiago_position.csv")
        ps["vel_data"] = str(data / "tiago_velocity.csv")
        ps["torque_data"] = str(data / "tiago_effort.csv")
        ps["validation_data_file"] = "the whole log"
        end = min(TIAGO_TRUNCATE[1], same["fit_end_row"])
        report = quiet_solve(iden, decimate=True, truncate=(TIAGO_TRUNCATE[0], end))
    pred, meas, _ = validation(iden, list(rd.TIAGO_JOINTS))
    fit = [rd.TIAGO_JOINTS.index(j) for j in TIAGO_FIT]
    held = same["held_rows"]
    return {
        "held_out": scored(pred, same["tau"], held)[: len(fit)],
        "torque_vs_real_logs_max": np.abs(meas - same["tau"]).max(axis=0)[fit].tolist(),
        "truncate": [TIAGO_TRUNCATE[0], end],
        "base_parameters": len(iden.phi_base),
        "seconds": time.perf_counter() - t0,
        "report_tail": report.strip().splitlines()[-12:],
    }


def tx40_same_rows(config: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """(a) on the TX40, with :mod:`real_logs`'s two Savitzky–Golay windows; also returns
    what (b) needs (held-out rows, split row, torques)."""
    robot_, log = rl.tx40_rows()
    t, q, tau = log.t, log.q, log.tau
    split = rl.held_out_split(t[:: rl.TX40_DECIMATE])
    robot = pin.RobotWrapper(robot_.model.copy())
    joints = list(robot_.joint_names)
    out: dict[str, Any] = {"split": split, "joints": joints}
    held101 = None
    for window in (rl.TX40_SG_WINDOW, rl.SG_WINDOW):
        _, v, a = rl.sg_fit(t, q, window, rl.SG_ORDER)
        inner = np.zeros(len(t), bool)
        inner[window // 2 : len(t) - window // 2] = True
        fit, held = inner & (t <= split), inner & (t > split)
        sets = {m: (t[r], q[r], v[r], a[r], tau[r]) for m, r in ((None, fit), ("held_out", held))}
        rows: dict[str, Any] = {"fit_rows": int(fit.sum()), "held_rows": int(held.sum())}
        for kind in COULOMB:
            rows[f"fed {kind}"] = run_fed(robot, config, sets, joints, joints, kind)
        out[str(window)] = rows
        if window == rl.TX40_SG_WINDOW:
            held101 = np.flatnonzero(held)
    return out, {"held_rows": held101, "fit_end_row": int((t <= split).sum()), "tau": tau}


def tx40_own(config: str, same: dict[str, Any], kind: str) -> dict[str, Any]:
    """(b) on the TX40: FIGAROH's ``TX40Identification`` as identification.py drives it,
    the log cut at the split; validated on the whole log.  Its ``process_torque_data``
    cuts :data:`TX40_BORDER` torque rows at each end and then the kinematics' last rows to
    the same length, so its torque row ``k`` is the log's ``k + 20`` (4 ms later) beside
    kinematics row ``k``: it fits that way, as shipped; its prediction at row ``k`` is
    scored against the log's torque at ``k`` (and, as FIGAROH pairs them, at ``k + 20``)."""
    tools = example_module("staubli_TX40", "staubli_tx40_tools.py")

    class Own(tools.TX40Identification):  # type: ignore[name-defined]
        def load_trajectory_data(self, data_source=None):  # validation: the whole log again
            return super().load_trajectory_data()

    model = pin.buildModelFromUrdf(str(rl.tx40_urdf()))
    t0 = time.perf_counter()
    with coulomb_model(kind), working_directory(examples() / "staubli_TX40"):
        iden = Own(pin.RobotWrapper(model), config)  # reads data/*.csv from its folder
        iden.identif_config["validation_data_file"] = "the whole log"
        report = quiet_solve(iden, decimate=True, truncate=(0, same["fit_end_row"]))
    joints = list(iden.identif_config["active_joints"])
    pred, meas, _ = validation(iden, joints)
    held = same["held_rows"]
    if held.max() >= len(pred):
        raise RuntimeError("FIGAROH's validation set is shorter than the held-out rows")
    return {
        "held_out": scored(pred, same["tau"][: len(pred)], held),
        "held_out_as_figaroh_pairs": rl.rms((pred - meas)[held]).tolist(),
        "torque_shift_rows": TX40_BORDER,
        "shift_check_max": float(
            np.abs(meas - same["tau"][TX40_BORDER : TX40_BORDER + len(meas)]).max()
        ),
        "truncate": [0, same["fit_end_row"]],
        "base_parameters": len(iden.phi_base),
        "seconds": time.perf_counter() - t0,
        "report_tail": report.strip().splitlines()[-10:],
    }


# ------------------------------------------------------------------ run and tables
def run() -> dict[str, Any]:
    """Every measurement of the module docstring (about two minutes)."""
    t0 = time.perf_counter()
    res: dict[str, Any] = {
        "figaroh": figaroh_version(),
        "pinocchio": pin.__version__,
        "date": time.strftime("%Y-%m-%d", time.gmtime()),
        "tanh_velocity": COULOMB_SMOOTHING_VELOCITY,
    }
    logging.getLogger("figaroh").setLevel(logging.ERROR)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        cfg = unified_config(examples() / "tiago" / "config" / "tiago_config.yaml", "tiago", folder)
        tiago, same = tiago_same_rows(cfg)
        for kind in COULOMB:
            tiago[f"own {kind}"] = tiago_own(cfg, same, kind)
        tiago["joints"] = list(TIAGO_FIT)
        res["tiago"] = tiago
        print("tiago done", flush=True)
        legacy = examples() / "staubli_TX40" / "config" / "TX40_config.yaml"
        cfg = unified_config(legacy, "staubli_tx40", folder)
        tx40, same = tx40_same_rows(cfg)
        for kind in COULOMB:
            tx40[f"own {kind}"] = tx40_own(cfg, same, kind)
        res["tx40"] = tx40
    res["seconds"] = time.perf_counter() - t0
    return res


def cell(x: float) -> str:
    """Three significant digits; ``—`` for NaN (nothing to show)."""
    return "—" if math.isnan(x) else f"{x:.3g}"


def _row(label: str, values: list[float]) -> str:
    return f"| {label} | " + " | ".join(cell(v) for v in values) + " |"


def markdown(res: dict[str, Any]) -> str:
    t, x = res["tiago"], res["tx40"]
    L = [
        f"Made by `python benchmarks/figaroh_peer.py` on {res['date']} in "
        f"{res['seconds']:.0f} s (FIGAROH {res['figaroh']}, Pinocchio {res['pinocchio']}); "
        "the conditions are in the script's docstring. *fed*: FIGAROH on real_logs.py's rows, "
        "split and Savitzky–Golay derivatives (`solve(decimate=False)`); *own*: FIGAROH's "
        "example as shipped (its filtering, derivatives, window and decimation), fitted before "
        "the split, scored on the same held-out rows. *sign*: FIGAROH's Coulomb column as "
        f"shipped; *tanh*: that column replaced by tanh(v / {res['tanh_velocity']:g}), the "
        "only change. pinobs against these: `benchmarks/real_logs.md` (its TIAGo and TX40 "
        "tables, issue 36's targets).",
        "",
        "### TIAGo: held-out torque residual RMS [N·m; torso N]",
        "",
        f"Split at t = {t['split']:.2f} s (loop's clock); {t['fit_rows']} fitted rows, "
        f"{t['held_rows']} held out. *fed*: pinobs's 8-joint model, torso and arm_1..4's "
        "torques fitted; *own*: FIGAROH's full URDF, all 8 torques fitted as its example "
        f"does, rows {t['own sign']['truncate'][0]}..{t['own sign']['truncate'][1]} "
        f"(its window {TIAGO_TRUNCATE[0]}..{TIAGO_TRUNCATE[1]} cut at the split); "
        "its identification.py's config and URDF are not in the data: tiago_config.yaml and "
        "tiago.urdf are used.",
        "",
        "| FIGAROH | " + " | ".join(j.replace("_joint", "") for j in t["joints"]) + " |",
        "|---|" + "---|" * len(t["joints"]),
    ]
    for k in ("fed sign", "fed tanh", "own sign", "own tanh"):
        L.append(_row(f"{k} ({t[k]['base_parameters']} base parameters)", t[k]["held_out"]))
    for k, vals in rl.FIGAROH_README.items():
        L.append(_row(f"README quote, {k}", [math.nan, *vals]))
    L += ["", negative_note(t, ("fed sign", "fed tanh"))]
    j = [n.replace("joint_", "j") for n in x["joints"]]
    L += [
        "",
        "### TX40: held-out torque residual RMS [N·m]",
        "",
        f"Split at t = {x['split']:.4f} s (the 1 kHz rows' `held_out_split`). *fed*: every "
        "fitted 5 kHz row, the two Savitzky–Golay windows of real_logs.py; *own*: FIGAROH's "
        f"pipeline, log cut at row {x['own sign']['truncate'][1]}. FIGAROH's example pairs "
        f"torque row k + {TX40_BORDER} with kinematics row k (its `process_torque_data` cuts "
        f"{TX40_BORDER} torque rows at each end, then the kinematics' tail): *own* is scored "
        "against the torque of the same row; as FIGAROH pairs them it is "
        + ", ".join(
            f"{k}: " + " ".join(cell(v) for v in x[f"own {k}"]["held_out_as_figaroh_pairs"])
            for k in COULOMB
        )
        + ". The example's coupled-wrist columns (`TX40Identification.add_additional_"
        "parameters`) are never called by FIGAROH 1.0.2's `initialize`: neither run has them.",
        "",
        "| FIGAROH | SG window [rows] | " + " | ".join(j) + " |",
        "|---|---|" + "---|" * len(j),
    ]
    for w in (str(rl.TX40_SG_WINDOW), str(rl.SG_WINDOW)):
        for k in COULOMB:
            L.append(_row(f"fed {k} | {w}", x[w][f"fed {k}"]["held_out"]))
    for k in COULOMB:
        L.append(_row(f"own {k} | its own", x[f"own {k}"]["held_out"]))
    L.append(_row("README quote, tanh | —", list(rl.TX40_FIGAROH_TANH)))
    L += ["", *protocol_note(res)]
    return "\n".join(L) + "\n"


def negative_note(t: dict[str, Any], runs: tuple[str, ...]) -> str:
    """The base parameters each of ``runs`` identified negative that physics wants ≥ 0
    (:func:`negative_alone`)."""
    said = [
        f"*{k}*: "
        + (
            ", ".join(f"`{n}` {v:.3g}" for n, v in t[k]["negative_alone"].items())
            if t[k]["negative_alone"]
            else "none"
        )
        for k in runs
        if "negative_alone" in t[k]
    ]
    if not said:
        return ""
    return (
        "Physical consistency: FIGAROH's least squares has no constraint. Base parameters "
        "that stand for one mass, rotor inertia or friction coefficient alone and came out "
        "negative: " + "; ".join(said) + " (the pseudo-inertias are not readable from its "
        "base combinations)."
    )


def protocol_note(res: dict[str, Any]) -> list[str]:
    """How far the README's quoted FIGAROH numbers are from each measured run, per robot."""
    out = []
    quotes = [
        ("TIAGo", res["tiago"], "", k, list(v), slice(1, 5)) for k, v in rl.FIGAROH_README.items()
    ]
    quotes.append(
        ("TX40", res["tx40"], str(rl.TX40_SG_WINDOW), "tanh", list(rl.TX40_FIGAROH_TANH), slice(6))
    )
    nearer = []
    for robot, r, w, kind, quote, cols in quotes:
        fed = (r[w] if w else r)[f"fed {kind}"]["held_out"][cols]
        own = r[f"own {kind}"]["held_out"][cols]
        dist = {
            k: float(np.max(np.abs(np.subtract(v, quote)) / np.asarray(quote)))
            for k, v in (("fed", fed), ("own", own))
        }
        nearer.append((f"{robot} {kind}", min(dist, key=dist.__getitem__), min(dist.values())))
        out.append(
            f"- {robot}, {kind}: the README's quote differs from *fed {kind}* by up to "
            f"{100 * dist['fed']:.0f} % on a joint, from *own {kind}* by up to "
            f"{100 * dist['own']:.0f} %."
        )
    own = [n for n, k, d in nearer if k == "own" and d <= PROTOCOL_MATCH]
    other = [f"{n} (nearest: *{k}*, {100 * d:.0f} %)" for n, k, d in nearer if n not in own]
    verdict = (
        "The earlier statement that the quoted numbers likely come from a different protocol "
        + (
            f"holds for the {', '.join(own)} quote{'s' if len(own) > 1 else ''}: within "
            f"{100 * PROTOCOL_MATCH:.0f} % of FIGAROH's own protocol (*own*), not of the same "
            "rows and Savitzky–Golay derivatives (*fed*) the README names"
            if own
            else "is not borne out: no quote is near FIGAROH's own protocol"
        )
        + (f"; it matches no run measured here for {', '.join(other)}." if other else ".")
    )
    return [
        "How far the README's quoted FIGAROH numbers are from each run measured here "
        "(largest relative difference over the joints quoted):",
        "",
        *out,
        "",
        verdict,
    ]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=str(Path(__file__).with_name("figaroh_peer.md")))
    p.add_argument("--render", action="store_true", help="rewrite the .md from the .json")
    a = p.parse_args(argv)
    out = Path(a.out)
    if a.render:
        out.write_text(markdown(json.loads(out.with_suffix(".json").read_text())))
        return 0
    if rd.data_root() is None:
        print(f"no data: set {rd.ENV} or put the shared data at ../shared/data; skipped")
        return 0
    if importlib.util.find_spec("figaroh") is None:
        print("FIGAROH is not installed: pip install 'pinobs[peers]'; skipped")
        return 0
    res = run()
    md = markdown(res)
    print(md)
    out.with_suffix(".json").write_text(json.dumps(res, indent=1, default=float))
    out.write_text(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

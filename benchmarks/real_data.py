# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[io]"]
# ///
"""Real robot logs for benchmarks: the UR10e and TIAGo data under ``../shared/data``.

The data are not shipped with pinobs (see ``shared/data/README.md`` for their
sources and licences); they are found beside the repository, in
``../shared/data``, or in the folder the environment variable
``PINOBS_SHARED_DATA`` names.  Without them :func:`list_logs` returns nothing.

Each log comes as a :class:`RealLog`: a DataFrame in pinobs's log format
(``t``, ``q.<joint>``, ``tau.<joint>``, read by :func:`pinobs.io.read_log`), the
robot to read it with, and the robot's own velocity where it recorded one.

- **UR10e** (Mamedov et al. 2020), ``ur10e/dataset_ur10e/<folder>/<file>.csv``:
  no header; ``t`` [s], ``q`` (6) [rad], ``dq`` (6) [rad/s], motor current (6)
  [A], then (31-column files) desired current (6) and desired torque (6).
  Torque [N·m] = the authors' identified drive gain × current
  (``UR10E_parameters.txt``: ``drvGains``).  The robot: the dataset's
  ``URe/urdf/ur10e.urdf`` (example-robot-data's ``ur10`` is the older UR10).
  Rows the logger garbled are left out (see :func:`ur10e_log`).  The
  ``validation_data`` files ``p1`` .. ``p10`` are static poses (q constant to
  1e-4 rad, dq 0), ``ptp_10_points`` moves.
- **TIAGo** (FIGAROH's example), ``figaroh/examples/tiago/data/identification/dynamic/
  tiago_{position,velocity,effort}.csv``: torso lift and arm joints 1-7, one row
  per stamp in each file.  Efforts are motor currents; as FIGAROH's
  ``identification.py`` does, arm torque [N·m] = reduction ratio × motor constant
  × current, and the torso force [N] = effort + g × the mass the torso lifts
  (from the robot's model).  The robot: the dataset's ``tiago.urdf`` with every
  other joint (head, hand, wheels) locked at its neutral position.

    python benchmarks/real_data.py          # what is there: rows, rates, repeats
"""

from __future__ import annotations

import os
import re
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

import pinobs
from pinobs.errors import ModelWarning

#: Environment variable naming the data folder (default: ``../shared/data`` beside the repo).
ENV = "PINOBS_SHARED_DATA"

UR10E_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
UR10E_FOLDERS = ("identification_data", "validation_data", "jointwise_motion", "collision")
TIAGO_JOINTS = ("torso_lift_joint", *(f"arm_{i}_joint" for i in range(1, 8)))
#: FIGAROH ``examples/tiago/identification.py``: torque = ratio × kmotor × effort.
TIAGO_REDUCTION = (1.0, 100.0, 100.0, 100.0, 100.0, 336.0, 336.0, 336.0)
TIAGO_KMOTOR = (1.0, 0.136, 0.136, -0.087, -0.087, -0.0613, -0.0613, -0.0613)
GRAVITY = 9.81  # [m/s²], FIGAROH's

_TIAGO_DIR = Path("figaroh", "examples", "tiago")
_TIAGO_DATA = _TIAGO_DIR / "data" / "identification" / "dynamic"
_TIAGO_KINDS = ("position", "velocity", "effort")
_UR10E_DIR = Path("ur10e")

# A UR10e row no robot state could be (the logger's garbled rows): limits [rad, rad/s, A]
_Q_MAX = 2 * np.pi + 0.01
_DQ_MAX = 10.0
_CURRENT_MAX = 50.0
#: Garbled rows are searched for among the first rows (the logger's start-up).
_HEAD_ROWS = 50


@dataclass(frozen=True)
class RealLog:
    """One recorded log, ready for :func:`pinobs.io.read_log`.

    Attributes:
        name: ``"<robot>/<folder>/<file stem>"`` (:func:`list_logs`).
        frame: columns ``t`` [s] (the logger's stamps, as recorded), ``q.<joint>`` [rad
            or m], and ``tau.<joint>`` [N·m or N] where the torques are known.
        robot: the robot to read it with (a copy of its own).
        velocity: the robot's own joint velocity [rad/s or m/s], one row per frame row,
            shape ``(N, nv)``, or ``None`` when the log has none.
        sources: the files read.
        notes: what was done to the data (rows left out, units, model warnings).
    """

    name: str
    frame: pd.DataFrame
    robot: pinobs.Robot
    velocity: np.ndarray | None
    sources: tuple[Path, ...]
    notes: tuple[str, ...] = field(default=())


def report(script: str, run: Callable[[], Any], markdown: Callable[[Any, float], str]) -> int:
    """A real-data benchmark's ``main``: ``run()``, its ``markdown(result, seconds)`` printed
    and written beside ``script`` (``.md``); nothing where the data is absent."""
    if data_root() is None:
        print("real data absent: skipped")
        return 0
    t0 = time.perf_counter()
    md = markdown(run(), time.perf_counter() - t0)
    print(md)
    Path(script).with_suffix(".md").write_text(md, encoding="utf-8")
    return 0


def data_root() -> Path | None:
    """The shared data folder (``$PINOBS_SHARED_DATA``, else ``../shared/data`` beside the
    repository), or ``None`` when it does not exist."""
    env = os.environ.get(ENV)
    root = Path(env) if env else Path(__file__).resolve().parents[1].parent / "shared" / "data"
    return root if root.is_dir() else None


def list_logs() -> list[str]:
    """Names of the logs present (sorted; UR10e files, then TIAGo), ``[]`` without the data."""
    root = data_root()
    if root is None:
        return []
    names = []
    for folder in UR10E_FOLDERS:
        d = root / _UR10E_DIR / "dataset_ur10e" / folder
        if d.is_dir():
            names += [f"ur10e/{folder}/{p.stem}" for p in sorted(d.glob("*.csv"))]
    if all((root / _TIAGO_DATA / f"tiago_{k}.csv").is_file() for k in _TIAGO_KINDS):
        names.append("tiago/dynamic/tiago")
    return names


def load_log(name: str) -> RealLog:
    """The log :func:`list_logs` calls ``name``.

    Raises:
        FileNotFoundError: no data folder, or no such log in it.
    """
    root = _root()
    parts = name.split("/")
    if len(parts) == 3 and parts[0] == "ur10e" and parts[1] in UR10E_FOLDERS:
        path = root / _UR10E_DIR / "dataset_ur10e" / parts[1] / f"{parts[2]}.csv"
        if path.is_file():
            return ur10e_log(path)
    if name == "tiago/dynamic/tiago":
        return tiago_log()
    raise FileNotFoundError(f"no log {name!r} in {root}; have {list_logs()}")


def _root() -> Path:
    root = data_root()
    if root is None:
        raise FileNotFoundError(
            f"no shared data folder: set {ENV} or put it at ../shared/data beside the repository"
        )
    return root


# ---------------------------------------------------------------------- UR10e
@cache
def _ur10e_robot() -> pinobs.Robot:
    urdf = _root() / _UR10E_DIR / "URe" / "urdf" / "ur10e.urdf"
    with warnings.catch_warnings():  # its meshes are not in the dataset: dynamics only
        warnings.filterwarnings("ignore", r".*mesh\(es\) not found", ModelWarning)
        return pinobs.load(urdf)


def ur10e_robot() -> pinobs.Robot:
    """The dataset's UR10e (``URe/urdf/ur10e.urdf``, loaded without its absent meshes)."""
    return _ur10e_robot().copy()


@cache
def ur10e_drive_gains() -> np.ndarray:
    """The authors' identified drive gains [N·m/A] (``UR10E_parameters.txt``, ``drvGains``)."""
    text = (_root() / _UR10E_DIR / "UR10E_parameters.txt").read_text(encoding="utf-8")
    m = re.search(r"drvGains\s*=\s*\[([^\]]*)\]", text)
    if m is None:
        raise ValueError("UR10E_parameters.txt has no 'drvGains = [...]'")
    gains = np.array(m.group(1).split(), dtype=float)
    if gains.shape != (6,):
        raise ValueError(f"UR10E_parameters.txt: drvGains has {gains.size} values, not 6")
    return gains


def ur10e_log(path: str | Path) -> RealLog:
    """One UR10e CSV (31 or 19 columns, no header).

    Rows left out, and said in ``notes``: at the start, every row up to the last
    implausible one among the first 50 (some files begin with rows the logger
    garbled: 253.0 in q, numbers of 100+ digits, columns shifted); elsewhere,
    each implausible row.  Implausible: a cell of ``t``, ``q``, ``dq`` or the
    current missing or not finite, ``|q| > 2π``, ``|dq| > 10 rad/s``,
    ``|current| > 50 A``; and a stamp not after the one before.  (A last line cut
    short after the currents, as in ``ur-20_02_19_15harm50secLoad``, is kept.)
    """
    path = Path(path)
    raw = pd.read_csv(path, header=None, dtype=float).to_numpy()
    ncol = raw.shape[1]
    if ncol not in (19, 31):
        raise ValueError(f"{path}: {ncol} columns; a UR10e log has 31 (or 19, older files)")
    t, q, dq, cur = raw[:, 0], raw[:, 1:7], raw[:, 7:13], raw[:, 13:19]
    bad = (
        ~np.isfinite(raw[:, :19]).all(axis=1)
        | (np.abs(q) > _Q_MAX).any(axis=1)
        | (np.abs(dq) > _DQ_MAX).any(axis=1)
        | (np.abs(cur) > _CURRENT_MAX).any(axis=1)
    )
    notes = []
    head = np.flatnonzero(bad[:_HEAD_ROWS])
    keep = ~bad
    if head.size:
        keep[: head[-1] + 1] = False
        notes.append(f"rows 1-{head[-1] + 1} left out (garbled by the logger at its start)")
    tail = np.flatnonzero(bad[_HEAD_ROWS:]) + _HEAD_ROWS
    if tail.size:
        notes.append(f"rows {(tail + 1).tolist()} left out (implausible or cut short)")
    idx = np.flatnonzero(keep)
    back = np.flatnonzero(np.diff(t[idx]) <= 0) + 1
    if back.size:  # a stamp not after the previous kept one
        notes.append(f"rows {(idx[back] + 1).tolist()} left out (stamp not increasing)")
        idx = np.delete(idx, back)
    robot = ur10e_robot()
    tau = cur[idx] * ur10e_drive_gains()
    frame = pd.DataFrame(
        {
            "t": t[idx],
            **{f"q.{j}": q[idx, i] for i, j in enumerate(UR10E_JOINTS)},
            **{f"tau.{j}": tau[:, i] for i, j in enumerate(UR10E_JOINTS)},
        }
    )
    notes.append("tau [N·m] = drvGains × motor current (UR10E_parameters.txt)")
    if not np.any(dq[idx]):
        notes.append("dq is all zero: the robot stood still")
    if ncol == 19:
        notes.append("19-column file: t, q, dq, current (no desired current or torque)")
    return RealLog(
        name=f"ur10e/{path.parent.name}/{path.stem}",
        frame=frame,
        robot=robot,
        velocity=dq[idx],
        sources=(path,),
        notes=tuple(notes),
    )


# ---------------------------------------------------------------------- TIAGo


@cache
def _tiago_robot() -> tuple[pinobs.Robot, float, tuple[str, ...]]:
    """(robot, the mass the torso lifts [kg], the model's warnings)."""
    import pinocchio as pin

    urdf = _root() / _TIAGO_DIR / "urdf" / "tiago.urdf"
    full = pin.buildModelFromUrdf(str(urdf))
    lock = [full.getJointId(n) for n in list(full.names)[1:] if n not in TIAGO_JOINTS]
    model = pin.buildReducedModel(full, lock, pin.neutral(full))
    data = model.createData()
    pin.computeSubtreeMasses(model, data)
    lifted = float(data.mass[model.getJointId("torso_lift_joint")])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ModelWarning)
        robot = pinobs.load(model)
    said = tuple(f"model: {w.message}" for w in caught if issubclass(w.category, ModelWarning))
    if robot.joint_names != TIAGO_JOINTS:
        raise ValueError(f"{urdf}: reduced to {robot.joint_names}, expected {TIAGO_JOINTS}")
    return robot, lifted, said


def tiago_robot() -> pinobs.Robot:
    """The dataset's TIAGo (``tiago.urdf``), torso lift and arm only: head, hand and
    wheels locked at their neutral position; named ``tiago`` as the model is."""
    return _tiago_robot()[0].copy()


def tiago_log() -> RealLog:
    """FIGAROH's TIAGo identification log (position, velocity and effort files).

    Raises:
        ValueError: the three files' stamps differ.
    """
    d = _root() / _TIAGO_DATA
    paths = tuple(d / f"tiago_{k}.csv" for k in _TIAGO_KINDS)
    tables = [pd.read_csv(p) for p in paths]
    t = tables[0]["t"].to_numpy(dtype=float)
    for p, tab in zip(paths[1:], tables[1:], strict=True):
        if not np.array_equal(tab["t"].to_numpy(dtype=float), t):
            raise ValueError(f"{p}: its stamps differ from {paths[0]}'s")

    def columns(tab: pd.DataFrame, kind: str) -> np.ndarray:
        # headers read "- arm_1_joint_position": match each joint by name
        out = []
        for j in TIAGO_JOINTS:
            found = [c for c in tab.columns if c.strip(" -") == f"{j}_{kind}"]
            if len(found) != 1:
                raise ValueError(f"tiago_{kind}.csv: no single column for {j} in {list(tab)}")
            out.append(tab[found[0]].to_numpy(dtype=float))
        return np.column_stack(out)

    q, v, effort = (columns(tab, k) for tab, k in zip(tables, _TIAGO_KINDS, strict=True))
    robot_, lifted, said = _tiago_robot()
    tau = effort * np.multiply(TIAGO_REDUCTION, TIAGO_KMOTOR)
    tau[:, 0] += GRAVITY * lifted  # FIGAROH adds the weight the torso lifts
    frame = pd.DataFrame(
        {
            "t": t,
            **{f"q.{j}": q[:, i] for i, j in enumerate(TIAGO_JOINTS)},
            **{f"tau.{j}": tau[:, i] for i, j in enumerate(TIAGO_JOINTS)},
        }
    )
    notes = (
        "arm tau [N·m] = reduction ratio × kmotor × effort (FIGAROH identification.py)",
        f"torso tau [N] = effort + {GRAVITY} × {lifted:.4g} kg (the model's mass above the "
        "torso joint; FIGAROH's own URDF gives 18.906 kg)",
        "arm_5..7 efforts are 0 most of the time",
        *said,
    )
    return RealLog(
        name="tiago/dynamic/tiago",
        frame=frame,
        robot=robot_.copy(),
        velocity=v,
        sources=paths,
        notes=notes,
    )


# ---------------------------------------------------------------------- summary
def describe(log: RealLog) -> dict[str, float | int | str]:
    """Rows, stamp steps [ms], repeated positions, and the reference velocity's agreement
    with the finite difference of q (RMS [rad/s], against the mean of the two rows' dq)."""
    f = log.frame
    t = f["t"].to_numpy()
    q = f[[c for c in f.columns if c.startswith("q.")]].to_numpy()
    dt = np.diff(t)
    repeated = np.all(q[1:] == q[:-1], axis=1)
    out: dict[str, float | int | str] = {
        "name": log.name,
        "rows": len(f),
        "duration_s": float(t[-1] - t[0]),
        "step_ms_median": float(np.median(dt) * 1e3),
        "step_ms_min": float(dt.min() * 1e3),
        "step_ms_max": float(dt.max() * 1e3),
        "repeated_q": float(repeated.mean()),
        "tau": "yes" if any(c.startswith("tau.") for c in f.columns) else "no",
    }
    if log.velocity is not None:
        v = log.velocity
        fd = np.diff(q, axis=0) / dt[:, None]
        moving = np.abs(v[1:]).max(axis=1) > 0.05
        out["repeated_q_moving"] = float(np.mean(repeated & moving))
        out["fd_vs_velocity_rms"] = float(np.sqrt(np.mean((fd - 0.5 * (v[1:] + v[:-1])) ** 2)))
    return out


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="the first UR10e log and TIAGo")
    args = parser.parse_args()
    names = list_logs()
    if not names:
        print(f"no data: set {ENV} or put the shared data at ../shared/data")
    if args.quick:
        names = names[:1] + [n for n in names if n.startswith("tiago")]
    print(
        "| log | rows | s | step ms (median, min-max) | repeated q | of which moving "
        "| RMS fd − dq [rad/s] |"
    )
    print("|---|---|---|---|---|---|---|")
    for name in names:
        log = load_log(name)
        d = describe(log)
        moving = d.get("repeated_q_moving")
        rms = d.get("fd_vs_velocity_rms")
        print(
            f"| {name} | {d['rows']} | {d['duration_s']:.1f} | {d['step_ms_median']:.1f} "
            f"({d['step_ms_min']:.1f}-{d['step_ms_max']:.1f}) | {d['repeated_q']:.3f} | "
            f"{'—' if moving is None else f'{moving:.3f}'} | "
            f"{'—' if rms is None else f'{rms:.4f}'} |"
        )


# ------------------------------------------------------------------ SEROW's Go1
#: SEROW's Go1 unit-test log under the shared data folder (legged robots, issue 38).
SEROW_GO1 = "serow_go1/evaluation/unit_tests/data/go1.csv"
SEROW_MG = 12 * 9.81  # go1_test.cpp: mass 12 kg, g 9.81 m/s²
SEROW_BIAS = -6.0  # go1_test.cpp: the raw reading of an unloaded foot


def serow_go1_frame(path: Path) -> pd.DataFrame:
    """SEROW's Go1 unit-test CSV in pinobs' table columns.

    ``Time(s)`` -> ``t`` (as recorded); ``BaseWx..z`` -> ``imu.gyro.*`` [rad/s];
    ``BaseAx..z`` -> ``imu.acc.*`` [m/s²]; ``JointPos<LEG>_<part>`` ->
    ``q.<LEG>_<part>_joint``; the raw foot readings ``<LEG>_Force`` (integers, not N)
    -> ``force.<LEG>_foot`` [N] scaled as SEROW's ``go1_test.cpp`` does::

        f = clip((raw − b) · m g / (m g − 4 b), 0, m g),   m = 12 kg, g = 9.81, b = −6
    """
    raw = pd.read_csv(path)
    out = {"t": raw["Time(s)"]}
    for a in "xyz":
        out[f"imu.gyro.{a}"] = raw[f"BaseW{a}"]
        out[f"imu.acc.{a}"] = raw[f"BaseA{a}"]
    for leg in ("FR", "FL", "RR", "RL"):
        force = (raw[f"{leg}_Force"] - SEROW_BIAS) * SEROW_MG / (SEROW_MG - 4 * SEROW_BIAS)
        out[f"force.{leg}_foot"] = force.clip(0.0, SEROW_MG)  # go1_test.cpp, line 72
        for part in ("hip", "thigh", "calf"):
            out[f"q.{leg}_{part}_joint"] = raw[f"JointPos{leg}_{part}"]
    return pd.DataFrame(out)

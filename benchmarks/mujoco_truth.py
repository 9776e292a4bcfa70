# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[mujoco]"]
# ///
"""Observers on data simulated by MuJoCo: a physics engine nobody here wrote as the truth.

Writes `benchmarks/mujoco_truth.json` and `benchmarks/mujoco_truth.md` (the README quotes the
markdown). Per system: MuJoCo's RK4 at 0.1 ms (contacts and joint limits off), the
actuators' controls held between 1 kHz samples, the measured torque `qfrc_actuator`,
positions with Gaussian noise σ = 1e-4 rad; the observers run on the model pinobs builds
from MuJoCo's compiled model (`pinobs.load(file.xml)`, damping included), from rest
estimates while the truth starts at 0.5 rad/s (velocity norm); RMS velocity error after the
first quarter of the run. `kf*`, `fd*` are the model-free filters with their best
parameter from a grid, chosen on the run itself (optimistic); `ekf (pin parser)` is the EKF
on the model Pinocchio's own MJCF parser reads from the same file.

Systems: `models/mjcf_cartpole.xml` and `models/mjcf_acrobot.xml` (dm_control style, written
for pinobs), dm_control's `cartpole.xml`, `acrobot.xml`, `pendulum.xml` and `walker.xml` as
shipped (when dm_control's files are installed: `pip install --no-deps dm_control`; the walker
without its ground contacts, so it falls while its legs are driven), and `models/mjcf_ur5.xml` (the UR5 of
example-robot-data with an armature and damping; `--write-ur5` regenerates it).

    python benchmarks/mujoco_truth.py [--duration 4] [--seed 0]
"""

from __future__ import annotations

import argparse
import importlib.resources
import json
import math
import platform
import time
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pinocchio as pin

import pinobs
from pinobs.model.loading import _models_dir
from pinobs.model.mjcf import build_from_mujoco
from pinobs.observers import make_observer, observer_names

FD_CUTOFFS = (2.0, 5.0, 10.0, 20.0, 40.0, 80.0, 160.0)  # [Hz], as pinobs bench
KF_JERKS = (1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3, 1e4, 1e5)  # [rad²/s⁵], as pinobs bench
UR5_ARMATURE = 0.1  # [kg·m²] reflected rotor inertia, each joint
UR5_DAMPING = 0.5  # [N·m·s/rad]


def write_ur5(path: Path) -> None:
    """An MJCF of example-robot-data's UR5 (its kinematics and inertias), with armature and damping."""
    model = pinobs.load("ur5").model
    lines = [
        "<!-- The UR5 of example-robot-data (kinematics and inertias of ur5_robot.urdf) as MJCF,",
        f"     with armature {UR5_ARMATURE} kg m^2 and damping {UR5_DAMPING} N m s/rad on every joint.",
        "     Written by benchmarks/mujoco_truth.py with the write-ur5 flag; no geometry but the inertias. -->",
        '<mujoco model="ur5">',
        '  <compiler angle="radian" inertiafromgeom="false"/>',
        f'  <default><joint armature="{UR5_ARMATURE}" damping="{UR5_DAMPING}"/>'
        '<motor ctrllimited="false"/></default>',
        "  <worldbody>",
    ]
    indent = "    "
    for j in range(1, model.njoints):
        place = model.jointPlacements[j]
        x, y, z, w = pin.Quaternion(place.rotation).coeffs()
        axis = {"X": "1 0 0", "Y": "0 1 0", "Z": "0 0 1"}[model.joints[j].shortname()[-1]]
        inertia = model.inertias[j]
        i = inertia.inertia
        lines += [
            f'{indent}<body name="{model.names[j]}_link" pos="{" ".join(f"{c:.17g}" for c in place.translation)}" '
            f'quat="{w:.17g} {x:.17g} {y:.17g} {z:.17g}">',
            f'{indent}  <joint name="{model.names[j]}" type="hinge" axis="{axis}"/>',
            f'{indent}  <inertial pos="{" ".join(f"{c:.17g}" for c in inertia.lever)}" mass="{inertia.mass:.17g}" '
            f'fullinertia="{i[0, 0]:.17g} {i[1, 1]:.17g} {i[2, 2]:.17g} {i[0, 1]:.17g} {i[0, 2]:.17g} {i[1, 2]:.17g}"/>',
        ]
        indent += "  "
    for _ in range(model.njoints - 1):
        indent = indent[:-2]
        lines.append(f"{indent}</body>")
    lines += ["  </worldbody>", "  <actuator>"]
    lines += [f'    <motor joint="{model.names[j]}"/>' for j in range(1, model.njoints)]
    lines += ["  </actuator>", "</mujoco>", ""]
    path.write_text("\n".join(lines))


def systems() -> dict[str, Path]:
    out = {
        "cartpole (pinobs MJCF)": _models_dir() / "mjcf_cartpole.xml",
        "acrobot (pinobs MJCF)": _models_dir() / "mjcf_acrobot.xml",
    }
    try:
        suite = Path(str(importlib.resources.files("dm_control") / "suite"))
        for name in ("cartpole", "acrobot", "pendulum", "walker"):
            out[f"{name} (dm_control)"] = suite / f"{name}.xml"
    except ModuleNotFoundError:
        print("dm_control's files are not installed: its rows are skipped")
    out["ur5 (MJCF, armature, damping)"] = _models_dir() / "mjcf_ur5.xml"
    return out


def simulate_mujoco(path: Path, duration: float, seed: int) -> dict[str, Any]:
    """Truth from MuJoCo: RK4 at 0.1 ms, controls held between 1 kHz samples, τ = qfrc_actuator."""
    robot = pinobs.load(path)
    _, mj, mapping, _ = build_from_mujoco(path)
    mj.opt.timestep = 1e-4
    mj.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    mj.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    data = mujoco.MjData(mj)
    rng = np.random.default_rng(seed)
    v0 = rng.normal(size=mj.nv)
    data.qvel[:] = mapping.velocity_jacobian(robot.neutral()) @ (0.5 * v0 / np.linalg.norm(v0))
    mujoco.mj_forward(mj, data)
    substeps, n = 10, round(duration * 1000) + 1
    freqs = rng.uniform(0.2, 1.5, size=(mj.nu, 3))
    phases = rng.uniform(0, 2 * np.pi, size=(mj.nu, 3))
    lo, hi = mj.actuator_ctrlrange[:, 0], mj.actuator_ctrlrange[:, 1]
    limited = mj.actuator_ctrllimited.astype(bool)
    full = mj.nu == mj.nv  # fully actuated (the UR5): PD on a multi-sine reference
    t_s, q_s, v_s, tau_s = [], [], [], []
    for k in range(n):
        t = k * 1e-3
        wave = np.sum(np.sin(2 * np.pi * freqs * t + phases), axis=1) / 3.0
        if full:
            q = mapping.q_from_qpos(data.qpos)
            ref = 0.5 * wave
            data.ctrl[:] = 400.0 * (ref - q) - 40.0 * data.qvel + robot.gravity(q)
        else:
            data.ctrl[:] = np.where(limited, 0.5 * (lo + hi) + 0.5 * (hi - lo) * wave, wave)
        mujoco.mj_forward(mj, data)  # qfrc_actuator of the held control
        q = mapping.q_from_qpos(data.qpos)
        t_s.append(t)
        q_s.append(q)
        v_s.append(mapping.v_from_qvel(q, data.qvel))
        tau_s.append(mapping.velocity_jacobian(q).T @ data.qfrc_actuator)
        for _ in range(substeps):
            mujoco.mj_step(mj, data)
    return {
        "robot": robot,
        "t": np.array(t_s),
        "q": np.array(q_s),
        "v": np.array(v_s),
        "tau": np.array(tau_s),
    }


def run_observers(run: dict[str, Any], path: Path, noise: float, seed: int) -> dict[str, float]:
    robot: pinobs.Robot = run["robot"]
    rng = np.random.default_rng(seed + 1)
    q_meas = np.array([robot.integrate(q, rng.normal(0.0, noise, robot.nv)) for q in run["q"]])
    obs: dict[str, Any] = {}
    for name in observer_names():
        try:
            obs[name] = make_observer(name, robot, rate=1000.0, noise_std=noise)
        except pinobs.PinobsError:
            continue
    for fc in FD_CUTOFFS:
        obs[f"fd@{fc:g}"] = make_observer("fd", robot, cutoff=fc, rate=1000.0, noise_std=noise)
    for j in KF_JERKS:
        obs[f"kf@{j:g}"] = make_observer("kf", robot, jerk_psd=j, rate=1000.0, noise_std=noise)
    parsed = pinobs.load(pin.buildModelFromMJCF(str(path)), friction=True, check=False)
    obs["ekf (pin parser)"] = make_observer("ekf", parsed, rate=1000.0, noise_std=noise)
    t, tau = run["t"], run["tau"]
    after = t >= 0.25 * t[-1]
    out: dict[str, float] = {}
    for name, ob in obs.items():
        est = [ob.reset(t[0], q_meas[0], None, tau[0]).v]
        try:
            for k in range(1, t.size):
                est.append(ob.update(t[k], q_meas[k], tau[k]).v)
            err = np.array(est) - run["v"]
            out[name] = float(np.sqrt(np.mean(err[after] ** 2)))
        except pinobs.PinobsError:
            out[name] = math.inf
    for prefix in ("fd", "kf"):
        grid = {k: v for k, v in out.items() if k.startswith(prefix + "@")}
        best = min(grid, key=lambda k: grid[k])
        out[f"{prefix}* ({best.split('@')[1]})"] = grid[best]
        for k in grid:
            del out[k]
    return out


MODEL_BASED = ("ekf", "riemannian", "kalman", "ii")


def format_report(report: dict[str, Any], duration: float, seed: int) -> str:
    """The markdown: how it was made, a summary table (the README's), one table per system."""
    m = report["machine"]
    md = [
        f"Made by `python benchmarks/mujoco_truth.py --duration {duration:g} --seed {seed}` on "
        f"{m['date']} in {report['seconds']:.0f} s (MuJoCo {m['mujoco']}, Pinocchio "
        f"{m['pinocchio']}, on a shared, loaded machine); the conditions are in the script's "
        "docstring. RMS velocity error [rad/s or m/s]; in brackets, the best tuned model-free "
        "filter's error over the observer's (`-`: the observer does not accept the robot).",
        "",
        "| system | nv | best tuned model-free | "
        + " | ".join(f"`{n}`" for n in MODEL_BASED)
        + " | `ekf` on Pinocchio's MJCF parser |",
        "|---|---:|---:|" + "---:|" * (len(MODEL_BASED) + 1),
    ]
    for label, sysrep in report["systems"].items():
        rms = sysrep["rms_v_error"]
        free_name = min((k for k in rms if k.startswith(("kf*", "fd*"))), key=lambda k: rms[k])
        free = rms[free_name]

        def cell(name: str, rms: dict[str, float] = rms, free: float = free) -> str:
            if name not in rms:
                return "-"
            return f"{rms[name]:.2g} ({free / rms[name]:.3g}x)"

        md.append(
            f"| {label} | {sysrep['nv']} | {free:.2g} (`{free_name}`) | "
            + " | ".join(cell(n) for n in MODEL_BASED)
            + f" | {cell('ekf (pin parser)')} |"
        )
    md.append("")
    for label, sysrep in report["systems"].items():
        rms = sysrep["rms_v_error"]
        free = min(v for k, v in rms.items() if k.startswith(("kf*", "fd*")))
        md += [
            f"**{label}** (nv = {sysrep['nv']})",
            "",
            "| observer | rms v err | ratio |",
            "|---|---:|---:|",
        ]
        for name, value in sorted(rms.items(), key=lambda kv: kv[1]):
            ratio = free / value if value > 0 and math.isfinite(value) else 0.0
            md.append(f"| `{name}` | {value:.3g} | {ratio:.3g} |")
        md.append("")
    return "\n".join(md)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--duration", type=float, default=4.0, help="simulated time per system [s]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--noise", type=float, default=1e-4, help="position noise σ [rad or m]")
    parser.add_argument("--write-ur5", action="store_true", help="regenerate models/mjcf_ur5.xml")
    args = parser.parse_args()
    here = Path(__file__).parent
    if args.write_ur5:
        write_ur5(here.parent / "models" / "mjcf_ur5.xml")
    start = time.time()
    report: dict[str, Any] = {"systems": {}}
    for label, path in systems().items():
        t0 = time.time()
        run = simulate_mujoco(path, args.duration, args.seed)
        rms = run_observers(run, path, args.noise, args.seed)
        robot = run["robot"]
        report["systems"][label] = {"nv": robot.nv, "rms_v_error": rms}
        print(f"{label}: {time.time() - t0:.0f} s", flush=True)
    report["seconds"] = time.time() - start
    report["machine"] = {
        "date": time.strftime("%Y-%m-%d"),
        "python": platform.python_version(),
        "mujoco": mujoco.__version__,
        "pinocchio": pin.__version__,
    }
    (here / "mujoco_truth.json").write_text(json.dumps(report, indent=1) + "\n")
    md = format_report(report, args.duration, args.seed)
    (here / "mujoco_truth.md").write_text(md)
    print(md)


if __name__ == "__main__":
    main()

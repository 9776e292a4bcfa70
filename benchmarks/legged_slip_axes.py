# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[mujoco]"]
# ///
"""The slip term split along and across each foot's predicted velocity (`slip_across`, eq. 12
of `split_slip`: a variant of the invariant EKF in this script, not in the library), measured
and checked on the MuJoCo go1.  Not adopted: it costs base velocity and ±2σ coverage on the
sway and trot (the `check` table) and does not raise the real Go1 log's stance NIS inside share
(`legged_real_innovations.md`).

Writes `benchmarks/legged_slip_axes.md`. go1 simulated by `simulate_legged` (10 s, 500 Hz; its
sensor noise `NOISE` with white encoders, or `QUANTISED`: encoders rounded as the real Go1
log's, `benchmarks/legged_truth.py`), through `pinobs.io.legged_run.legged_run` from the
simulated log (contacts from the forces), the settings of each row.

`measure`: the measuring run, trot seed 0 with white encoders, `imu_noise="log"`, `slip_across`
``κ`` over a grid: every foot measured at mid-stance (more than 20 ms after it landed) gives its
innovation ``r_j`` and the filter's ``S_jj`` (eqs. 4-5) in the frame of the foot's predicted
velocity ``u_j`` (along it, then two axes across it); per axis ``r²/S`` (mean square over mean
predicted variance, 1 for a consistent filter).  ``κ`` is the least of the grid whose across
axes' ``r²/S`` stay ≤ 1 (below it the filter would be overconfident across); the stand and sway,
seeds 1-2 and the quantised encoders are held out, and the real log is not used.

`check`: trot, stand, sway × seeds 0-2 × white / quantised encoders, per setting: the base
velocity RMS after 0.5 s (base frame, `v[0:3]`), the IMU's velocity error inside ±2σ of the
filter's covariance per axis of the IMU frame (``v̂_b − v_b ≈ R̂ᵀ ξ_v``, as `legged_truth.py`'s
IMU-frame columns) and the stance rows inside their 95 % χ² interval
(`pinobs.observers.legs.stance_consistency`); the mean over seeds.  `imu_noise="log"`:
`legged_run`'s option (the IMU's densities from the log's stillest second, and eq. 10).

    python benchmarks/legged_slip_axes.py [--sections measure check] [--seeds 0 1 2]
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import os
import time
import warnings
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pandas as pd

import pinobs
import pinobs.io.legged_run as runner
from pinobs.io import read_log
from pinobs.simulation.legged import LEGGED_MOTIONS, LeggedNoise, simulate_legged

NOISE = LeggedNoise()
#: the real Go1 log's encoder rounding (legged_truth.py's ``QUANTISED``)
QUANTISED = LeggedNoise(encoder=3e-5, encoder_step=(6e-5, 6e-5, 4e-5) * 4)
KAPPAS = (1.0, 0.3, 0.1, 0.03, 0.0)
KAPPA = 0.1  # the measuring run's choice (the table `measure`)
SETTINGS = {
    "defaults": {},
    f"slip_across={KAPPA}": {"slip_across": KAPPA},
    "imu_noise='log'": {"imu_noise": "log"},
    f"imu_noise='log', slip_across={KAPPA}": {"imu_noise": "log", "slip_across": KAPPA},
}
LATE = 0.5  # [s] the velocity error after this
MID = 0.02  # [s] mid-stance: this long after the foot landed


def split_slip(base: type, kappa: float) -> type:
    """``base`` (an :class:`~pinobs.observers.inekf.InvariantEKF`) with its ``slip_speed`` term
    split along and across each foot's predicted velocity ``u_j`` (world frame: eq. 10's
    speed in ``ṗ̂_j``'s direction), ``κ = kappa`` the share across::

        Q_c,dj = (σ_c² + κ |u_j|² h) I + (1 − κ) h u_j u_jᵀ                 (12)

    The model's failure ``ḋ_j ≠ 0`` is the foot's velocity, a vector: over the step the foot
    moves by ``s u_j h`` (``s`` a unit Gaussian; the size uncertain, the direction given by the
    legs), covariance ``u_j u_jᵀ h²``; ``κ`` is the share left across (the direction's own
    error); ``κ = 1`` is eq. (9) of :mod:`pinobs.observers.inekf` (Hartley et al., IJRR 2020,
    the contact noise ``ḋ_j = R h_R w_c`` with a speed-dependent covariance).  The isotropic
    part goes through the filter's ``Q_c``; the rank-one part is added to the foot's block of
    ``P`` after the step: ``ξ_dj`` is the foot's world-frame error and the foot's rows and
    columns of ``A`` (eq. 2) are zero, so noise on it stays in it over the step and
    ``P_djdj += (1 − κ) h² u_j u_jᵀ`` is exact for the density held."""

    class Split(base):  # type: ignore[valid-type, misc]
        _split_along: Any = None

        def _remember(self, u: Any, h: Any, dt: float = 0.0) -> None:
            super()._remember(u, h, dt)
            self._split_along = None
            if self._speed is None or kappa == 1.0:
                return
            v = self.foot_velocities(u.q_joints, u.joint_velocities, u.reading[:3])
            raw = np.sqrt(np.sum(v * v, axis=1))
            scale = np.divide(self._speed, raw, out=np.zeros_like(raw), where=raw > 0.0)
            self._split_along = v * (scale * np.sqrt(1.0 - kappa))[:, None]
            self._speed = self._speed * np.sqrt(kappa)

        def _propagate(self, state: Any, imu: Any, dt: float, t: float) -> Any:
            out = super()._propagate(state, imu, dt, t)
            if self._split_along is not None:
                for i, j in enumerate(state.feet):  # P_djdj += (1 − κ) h² u_j u_jᵀ
                    u = self._split_along[j] * dt
                    out.P[9 + 3 * i : 12 + 3 * i, 9 + 3 * i : 12 + 3 * i] += np.outer(u, u)
            return out

    return Split


@contextlib.contextmanager
def patched(cls: type, options: dict[str, Any]) -> Any:
    """``legged_run`` with ``cls`` as its filter, split by ``options["slip_across"]`` if
    given (:func:`split_slip`); yields the other options."""
    options = dict(options)
    kappa = options.pop("slip_across", None)
    plain = runner.InvariantEKF
    runner.InvariantEKF = cls if kappa is None else split_slip(cls, kappa)
    try:
        yield options
    finally:
        runner.InvariantEKF = plain


class Recorder(runner.InvariantEKF):
    """The invariant EKF recording, per measured foot at mid-stance, its innovation and
    ``S_jj`` in the frame of its predicted velocity, and after each update ``R̂``, ``v̂``,
    ``P_vv``."""

    feet_rows: ClassVar[list[Any]] = []
    states: ClassVar[list[Any]] = []
    velocity: Any = None

    def _remember(self, u: Any, h: Any, dt: float = 0.0) -> None:
        super()._remember(u, h, dt)
        ok = u is not None and u.joint_velocities is not None
        self.velocity = (
            self.foot_velocities(u.q_joints, u.joint_velocities, u.reading[:3]) if ok else None
        )

    def update_checked(self, *args: Any, **kwargs: Any) -> Any:  # (update calls it; the runner too)
        out = super().update_checked(*args, **kwargs)
        s = self.state
        self.states.append((s.t, s.R, s.x[0], s.P[3:6, 3:6]))
        return out

    def _update(self, state: Any, measured: list[int], h: Any, jac: Any) -> Any:
        R, x, P = state.R, state.x, state.P
        blocks = self._foot_noise(R, jac[measured])
        for i, j in enumerate(state.feet):
            if self.velocity is None or state.t - self._landed[j] < MID:
                continue
            E = velocity_frame(self.velocity[j])
            if E is None:
                continue
            r = R @ h[j] - (x[2 + i] - x[1])
            d, p = slice(9 + 3 * i, 12 + 3 * i), slice(6, 9)
            S = P[p, p] - P[p, d] - P[d, p] + P[d, d] + blocks[i]
            self.feet_rows.append((E @ r, np.diag(E @ S @ E.T)))
        return super()._update(state, measured, h, jac)


def velocity_frame(u: Any) -> Any:
    """Rows: ``u/|u|`` and two unit axes across it (``None`` for ``u`` = 0)."""
    s = float(np.linalg.norm(u))
    if s < 1e-12:
        return None
    e = u / s
    a = np.cross(e, [0.0, 0.0, 1.0])
    a = a / np.linalg.norm(a) if np.linalg.norm(a) > 1e-9 else np.array([1.0, 0.0, 0.0])
    return np.array([e, a, np.cross(e, a)])


@functools.cache
def simulated(motion: str, seed: int, encoders: str) -> tuple[Any, Any]:
    go1 = pinobs.load("go1")
    noise = NOISE if encoders == "white" else QUANTISED
    run = simulate_legged(motion, 10.0, seed=seed, noise=noise, robot=go1)
    frame = pd.DataFrame(
        {k: v for k, v in run.columns.items() if not k.startswith(("truth.", "contact."))}
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the note that the log has no base pose
        log = read_log(frame, go1)
    return run, log


def one_run(motion: str, seed: int, encoders: str, options: dict[str, Any]) -> dict[str, Any]:
    """``legged_run`` with the recorder on one simulated log: the metrics of the docstring."""
    go1 = pinobs.load("go1")
    run, log = simulated(motion, seed, encoders)
    Recorder.feet_rows, Recorder.states = [], []
    with patched(Recorder, options) as rest, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        detail = runner.legged_run(go1, log, **rest)
    late = run.t > run.t[0] + LATE
    err = detail.run.v[late, :3] - run.base_v()[late, :3]
    r = np.array([a[0] for a in Recorder.feet_rows])
    S = np.array([a[1] for a in Recorder.feet_rows])
    return {
        "v_rms": float(np.sqrt(np.mean(err**2))),
        "in_2sigma_imu": _coverage(run, go1, late).tolist(),
        "inside": detail.run.consistency.details["inside"],
        "ratio_along_across": (np.mean(r**2, axis=0) / np.mean(S, axis=0)).tolist(),
    }


def _coverage(run: Any, go1: Any, late: Any) -> Any:
    """Per IMU-frame axis, the share of rows after ``LATE`` whose velocity error is inside
    ±2σ: ``e_b = R̂ᵀ v̂ − R_iᵀ v_i`` against ``R̂ᵀ P_vv R̂`` (``R_i = R_b R_bi``, ``v_i`` the
    IMU's true world velocity)."""
    base_q, base_v = run.base_q(), run.base_v()
    imu = go1.model.frames[go1.model.getFrameId("imu_link")].placement
    R_bi, r_bi = imu.rotation, imu.translation
    states = {round(t * 1e6): s for t, *s in Recorder.states}
    inside = []
    for k in np.flatnonzero(late):
        R_hat, v_hat, P = states[round(run.t[k] * 1e6)]
        q = base_q[k, 3:]
        R_b = _rotation(q)
        v_i = R_b @ (base_v[k, :3] + np.cross(base_v[k, 3:], r_bi))
        e = R_hat.T @ v_hat - (R_b @ R_bi).T @ v_i
        sigma = np.sqrt(np.diag(R_hat.T @ P @ R_hat))
        inside.append(np.abs(e) <= 2.0 * sigma)
    return np.mean(inside, axis=0)


def _rotation(q: Any) -> Any:
    from pinobs.observers.legs import quaternion_to_rotation

    return quaternion_to_rotation(q)


def measure() -> list[str]:
    md = [
        "### measure: trot seed 0, white encoders, `imu_noise='log'` (the measuring run)",
        "",
        "| κ (`slip_across`) | r²/S along / across / across | stance inside [%] | v rms [m/s] |",
        "|---:|---|---:|---:|",
    ]
    for kappa in KAPPAS:
        out = one_run("trot", 0, "white", {"imu_noise": "log", "slip_across": kappa})
        md.append(
            f"| {kappa:g} | {' / '.join(f'{x:.2f}' for x in out['ratio_along_across'])} "
            f"| {100 * out['inside']:.1f} | {out['v_rms']:.4f} |"
        )
        print(md[-1], flush=True)
    return [*md, ""]


def check(seeds: list[int]) -> list[str]:
    md = [
        f"### check: mean over seeds {', '.join(map(str, seeds))} (10 s)",
        "",
        "| motion, encoders | setting | v rms [m/s] | in ±2σ x / y / z (IMU frame) [%] "
        "| stance inside [%] | r²/S along / across / across |",
        "|---|---|---:|---|---:|---|",
    ]
    for encoders in ("white", "quantised"):
        for motion in LEGGED_MOTIONS:
            for name, options in SETTINGS.items():
                runs = [one_run(motion, s, encoders, options) for s in seeds]
                mean = {k: np.mean([r[k] for r in runs], axis=0) for k in runs[0]}
                md.append(
                    f"| {motion}, {encoders} | {name} | {mean['v_rms']:.4f} "
                    f"| {' / '.join(f'{100 * x:.1f}' for x in mean['in_2sigma_imu'])} "
                    f"| {100 * mean['inside']:.1f} "
                    f"| {' / '.join(f'{x:.2f}' for x in mean['ratio_along_across'])} |"
                )
                print(md[-1], flush=True)
    return [*md, ""]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument(
        "--sections", nargs="+", choices=["measure", "check"], default=["measure", "check"]
    )
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    args = parser.parse_args()
    start, load = time.time(), os.getloadavg()[0]
    md = [
        "Made by `python benchmarks/legged_slip_axes.py` (its docstring says what each column is).",
        "",
    ]
    if "measure" in args.sections:
        md += measure()
    if "check" in args.sections:
        md += check(args.seeds)
    md.append(
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {time.time() - start:.0f} s, "
        f"load {load:.1f} → {os.getloadavg()[0]:.1f}."
    )
    text = "\n".join(md) + "\n"
    print(text)
    (Path(__file__).parent / "legged_slip_axes.md").write_text(text)


if __name__ == "__main__":
    main()

"""Why ``ekf+nb+id`` was behind ``kf`` on UR10e logs, and the prior's velocity clause (issue 36).

The conditions of ``real_logs.py`` (its identified model, identified on
:data:`real_logs.UR10E_FIT`, the ``@id`` robot; velocity RMS against the robot's own ``dq``
after :data:`real_logs.SETTLE`, all six joints; ``pinobs.estimate`` with its defaults).  Per
log: ``kf``; ``ekf`` on the identified model alone (``never_behind=False``) and blended
(``never_behind=True``), *before* (the consistency prior earned by the NIS test alone: the
velocity clause switched off by making :func:`~pinobs.observers.neverbehind.claims_within_kf`
return True) and *now* (the NIS test and the model's own velocity variance at most the
``kf``'s on every joint: :mod:`pinobs.observers.neverbehind` docstring, **Prior**), and so
``kalman`` and ``ekf`` with ``disturbance_psd="auto"`` (:data:`OTHERS`); and,
from the *before* run's recorded steps: the share of steps its NIS test passed, the
mean model weight and its mean square (a weight that flips between 0 and 1 has ``E[w²]``
near ``E[w]``), the correlation over steps and joints of ``w`` with the model's
instantaneous advantage ``e²_kf − e²_m`` (against the reference), the part of the excess
squared error over ``kf`` while moving (``|dq| > 0.01`` rad/s) and at rest, the blend with
each joint's weight held at its mean, the oracle constant weight per joint (least squares
against the reference: a bound, not causal), and the median ratio of the model's claimed
velocity variance (its ``P``'s ``δv`` block) to the ``kf``'s (its mixture's).

    python benchmarks/never_behind_weights.py            # writes never_behind_weights.md
    python benchmarks/never_behind_weights.py LOG,LOG    # those logs, printed
"""

from __future__ import annotations

import contextlib
import re
import sys
import time
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import real_data as rd
import real_logs as R

import pinobs
from pinobs.observers import neverbehind as nb

#: |dq| [rad/s] above which a joint's row counts as moving.
MOVING = 0.01
#: The other blends on the identified model the prior's clause applies to: label, family, options.
OTHERS = (
    ("kalman+nb+id", "kalman", {}),
    ("ekf+auto+nb+id", "ekf", {"disturbance_psd": "auto"}),
)


@contextlib.contextmanager
def recording(rows: list[tuple[Any, ...]], *, velocity_clause: bool = True) -> Iterator[None]:
    """``NeverBehind.step`` recording ``(q_meas, w, v̂_m, v̂_kf, P_m,vv, P_kf,vv, NIS band, ν̄)``
    per step into ``rows``; without ``velocity_clause`` the prior as before it (the NIS test alone)."""
    step, clause = nb.NeverBehind.step, nb.claims_within_kf

    def recorded(self: nb.NeverBehind, state: Any, dt: float, q: Any, tau: Any) -> Any:
        new = step(self, state, dt, q, tau)
        p_m = nb.model_velocity_variance(new.model, self.robot.nv)
        p_kf = nb.kf_velocity_variance(new.kf)
        rows.append(
            (
                None if q is None else np.array(q),
                np.array(new.w),
                np.array(self.model.output(new.model)[1]),
                np.array(self.reference.output(new.kf)[1]),
                None if p_m is None else np.array(p_m),
                None if p_kf is None else np.array(p_kf),
                nb.nis_band(self.robot.nv, min(1.0, dt / self.window)),
                new.nis,
            )
        )
        return new

    nb.NeverBehind.step = recorded  # type: ignore[method-assign]
    if not velocity_clause:
        nb.claims_within_kf = lambda m, kf, nv: True  # type: ignore[assignment]
    try:
        yield
    finally:
        nb.NeverBehind.step = step  # type: ignore[method-assign]
        nb.claims_within_kf = clause


def velocities(frame: Any, robot: pinobs.Robot, options: dict[str, Any]) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        df = pinobs.estimate(options.pop("name", "ekf"), frame, robot=robot, options=options)
    return df[[f"v{i}" for i in range(robot.nv)]].to_numpy()


def aligned(rows: list[tuple[Any, ...]], q: np.ndarray) -> np.ndarray:
    """For each log row, the index of the recorded step that measured it (-1: none)."""
    idx = np.full(len(q), -1)
    k = 0
    for i, r in enumerate(rows):
        if r[0] is None:
            continue
        while k < len(q) and not np.array_equal(q[k], r[0]):
            k += 1
        if k < len(q):
            idx[k] = i
            k += 1
    return idx


def one_log(name: str, robot: pinobs.Robot, ident: pinobs.Robot) -> dict[str, Any]:
    folder = "validation_data" if name.startswith("ur-20_01_17") else "identification_data"
    log = rd.load_log(f"ur10e/{folder}/{name}")
    t, q, _ = R.arrays(log.frame)
    ref, late = log.velocity, t >= t[0] + R.SETTLE

    def rms(v: np.ndarray) -> float:
        return float(np.sqrt(np.mean((v - ref)[late] ** 2)))

    v_kf = velocities(log.frame, robot, {"name": "kf"})
    v_alone = velocities(log.frame, ident, {"never_behind": False})
    before: list[tuple[Any, ...]] = []
    with recording(before, velocity_clause=False):
        v_before = velocities(log.frame, ident, {"never_behind": True})
    now: list[tuple[Any, ...]] = []
    with recording(now):
        v_now = velocities(log.frame, ident, {"never_behind": True})
    kf = rms(v_kf)
    out: dict[str, Any] = {
        "rows": len(t),
        "kf": kf,
        "alone": rms(v_alone) / kf,
        "before": rms(v_before) / kf,
        "now": rms(v_now) / kf,
    }
    for label, name, opts in OTHERS:  # (the same clause, other families)
        for when, clause in (("before", False), ("now", True)):
            with recording([], velocity_clause=clause):
                v = velocities(log.frame, ident, {"name": name, "never_behind": True, **opts})
            out[f"{label} {when}"] = rms(v) / kf
    idx = aligned(before, q)
    ok = late & (idx >= 0)
    i = idx[ok]
    w = np.array([before[j][1] for j in i])
    vm = np.array([before[j][2] for j in i])
    vk = np.array([before[j][3] for j in i])
    e_k, e_b, d = vk - ref[ok], vk + w * (vm - vk) - ref[ok], vm - vk
    advantage = e_k**2 - (vm - ref[ok]) ** 2
    p_m = np.array([before[j][4] for j in i])
    p_kf = np.array([before[j][5] for j in i])
    passed = np.mean([before[j][6][0] <= before[j][7] <= before[j][6][1] for j in i])
    moving = np.abs(ref[ok]) > MOVING
    excess = e_b**2 - e_k**2
    wc = np.clip(-(e_k * d).sum(0) / (d * d).sum(0), 0.0, 1.0)
    n_kf = float(np.mean(e_k**2))
    with np.errstate(divide="ignore", over="ignore"):  # (a joint at rest: P_kf,vv ~ 0)
        claimed = float(np.median(p_m / p_kf))
    out.update(
        nis_passed=float(passed),
        mean_w=float(w.mean()),
        mean_w2=float((w * w).mean()),
        corr=float(np.corrcoef(w.ravel(), advantage.ravel())[0, 1]),
        excess_moving=float(excess[moving].sum() / excess.size / n_kf),
        excess_rest=float(excess[~moving].sum() / excess.size / n_kf),
        held_mean=float(np.sqrt(np.mean((e_k + w.mean(axis=0) * d) ** 2) / n_kf)),
        oracle=float(np.sqrt(np.mean((e_k + wc * d) ** 2) / n_kf)),
        oracle_w=wc.round(2).tolist(),
        claimed=claimed,
        claimed_below=float(np.mean(np.all(p_m <= p_kf, axis=1))),
    )
    return out


COLUMNS = (
    ("rows", "rows", "{:d}"),
    ("kf", "kf [rad/s]", "{:.4g}"),
    ("alone", "ekf+id / kf", "{:.2f}"),
    ("before", "ekf+nb+id / kf, before", "{:.4f}"),
    ("now", "now", "{:.4f}"),
    ("kalman+nb+id before", "kalman+nb+id / kf, before", "{:.4f}"),
    ("kalman+nb+id now", "now", "{:.4f}"),
    ("ekf+auto+nb+id before", "ekf+auto+nb+id / kf, before", "{:.4f}"),
    ("ekf+auto+nb+id now", "now", "{:.4f}"),
    ("nis_passed", "steps the NIS test passed", "{:.2f}"),
    ("mean_w", "mean w (before)", "{:.3f}"),
    ("mean_w2", "E[w²]", "{:.3f}"),
    ("corr", "corr(w, e²_kf − e²_m)", "{:+.3f}"),
    ("excess_moving", "excess moving / kf²", "{:+.4f}"),
    ("excess_rest", "excess at rest / kf²", "{:+.4f}"),
    ("held_mean", "w held at its mean / kf", "{:.4f}"),
    ("oracle", "oracle constant w / kf", "{:.4f}"),
    ("claimed", "median P_m,vv / P_kf,vv", "{:.2g}"),
    ("claimed_below", "steps P_m,vv ≤ P_kf,vv ∀ joints", "{:.2f}"),
)


def table(res: dict[str, dict[str, Any]]) -> list[str]:
    lines = [
        "| log | " + " | ".join(c[1] for c in COLUMNS) + " |",
        "|---|" + "---:|" * len(COLUMNS),
    ]
    for name, r in res.items():
        mark = " (fit)" if name in R.UR10E_FIT else ""
        cells = [fmt.format(r[key]) for key, _, fmt in COLUMNS]
        lines.append(f"| {name}{mark} | " + " | ".join(cells) + " |")
    return lines


def main(argv: list[str]) -> int:
    if not any(n.startswith("ur10e/") for n in rd.list_logs()):
        print("no UR10e data (real_data.py): nothing to do")
        return 0
    robot = rd.ur10e_robot()
    t0 = time.perf_counter()
    ident, _, _ = R.ur10e_identify(R.UR10E_FIT, robot)
    unloaded = [
        n
        for n in R.ur10e_names("identification_data")
        if not re.search(r"(?<!un)load", n, re.IGNORECASE)
    ]
    names = argv[0].split(",") if argv else ["ur-20_01_17-ptp_10_points", *unloaded]
    res = {}
    for n in names:
        res[n] = one_log(n, robot, ident.robot)
        print(n, {k: res[n][k] for k in ("kf", "alone", "before", "now")}, flush=True)
    lines = table(res)
    print("\n".join(lines))
    if not argv:
        head = Path(__file__).with_suffix(".md").read_text().split("<!-- table -->")[0]
        stamp = f"Made by `python benchmarks/never_behind_weights.py` in {time.perf_counter() - t0:.0f} s."
        Path(__file__).with_suffix(".md").write_text(
            head + "<!-- table -->\n\n" + stamp + "\n\n" + "\n".join(lines) + "\n"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

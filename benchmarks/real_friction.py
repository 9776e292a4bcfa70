# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[io]", "scipy"]
# ///
"""Friction laws on the real UR10e (issue 36, item 3): held-out torque residual per joint.

``pinobs.identify`` on ``real_logs.UR10E_FIT`` (the same join, stamps and defaults as
``real_logs.ur10e_identify``) once per friction law (``friction=True``: today's viscous +
Coulomb·tanh(v/0.01); ``"offset-sigmoid"``, ``"stribeck"``, ``"asymmetric"``: their
smoothing velocity chosen by cross-validation with the one-standard-error rule, and again
with today's ``v_s`` = 0.01 kept: ``@0.01``), then the inverse-dynamics prediction
``M a + c + g − τ_f(v)`` (``real_logs.predict_robot``: the robot's own friction law, its
offset included) against the measured torque, RMS per joint [N·m] pooled over the moving
held-out logs exactly as ``real_logs.ur10e`` pools them; the published model
(Mamedov et al.) beside them.  Prints the table and each law's identified parameters and
writes ``benchmarks/real_friction.json``.

    python benchmarks/real_friction.py            # every law (about 15 min on 2 cores)
    python benchmarks/real_friction.py --quick    # one held-out log
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import real_data as rd
import real_logs as rl

import pinobs

#: (friction, smoothing): each law with its smoothing velocity searched (None), and with
#: today's 0.01 rad/s kept (the search's minimum, 1e-3 at the shoulders, predicted worse;
#: the one-standard-error rule keeps 0.01 on every joint)
LAWS: tuple[tuple[bool | str, float | None], ...] = (
    (True, None),
    ("offset-sigmoid", None),
    ("stribeck", None),
    ("asymmetric", None),
    ("offset-sigmoid", 0.01),
    ("stribeck", 0.01),
    ("asymmetric", 0.01),
)


def identify(
    names: tuple[str, ...], robot: pinobs.Robot, friction: bool | str, smoothing: float | None
):
    """``real_logs.ur10e_identify`` with a friction law (the same join and defaults)."""
    parts_t, parts_q, parts_tau, off = [], [], [], 0.0
    for n in names:
        t, q, tau = rl.arrays(rd.load_log(f"ur10e/identification_data/{n}").frame)
        keep = rl.fresh(q)
        t, q, tau = t[keep] - t[keep][0] + off, q[keep], tau[keep]
        parts_t += [t, [t[-1] + rl.UR10E_JOIN_GAP / 2]]
        parts_q += [q, np.full((1, 6), np.nan)]
        parts_tau += [tau, np.full((1, 6), np.nan)]
        off = t[-1] + rl.UR10E_JOIN_GAP
    T, Q, TAU = (np.concatenate(p[:-1]) for p in (parts_t, parts_q, parts_tau))
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        ident = pinobs.identify(
            robot, (T, Q, TAU), holdout=0.0, friction=friction, smoothing=smoothing
        )
    return ident, time.perf_counter() - t0


def held_out_logs(quick: bool) -> list[str]:
    """The moving held-out logs of ``real_logs.ur10e`` (ptp_10_points and the unloaded
    identification logs not fitted), the published model's own fit log left out."""
    unloaded = [
        n
        for n in rl.ur10e_names("identification_data")
        if n not in rl.UR10E_FIT and not re.search(r"(?<!un)load", n, re.IGNORECASE)
    ]
    moving = ["ur-20_01_17-ptp_10_points", *unloaded]
    moving = [n for n in moving if n != rl.UR10E_PUBLISHED_FIT]
    return moving[:1] if quick else moving


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    if rd.data_root() is None:
        print("real data absent: skipped")
        return 0
    robot = rd.ur10e_robot()
    published = rl.Published(robot)
    models: dict[str, object] = {}
    out: dict[str, dict] = {"laws": {}}
    for law, vs in LAWS:
        name = "pinobs" if law is True else f"pinobs:{law}" + ("" if vs is None else f"@{vs:g}")
        ident, secs = identify(rl.UR10E_FIT, robot, law, vs)
        models[name] = ident.robot
        fl = ident.robot.friction_law
        out["laws"][name] = {
            "seconds": secs,
            "report": ident.report.get("friction_law"),
            **{
                k: getattr(fl, k).tolist()
                for k in (
                    "viscous",
                    "coulomb_pos",
                    "coulomb_neg",
                    "static",
                    "offset",
                    "smoothing",
                    "stribeck_velocity",
                )
            },
            "armature": np.asarray(ident.robot.model.armature).tolist(),
        }
        print(f"{name}: identified in {secs:.0f} s", flush=True)
    pooled: dict[str, list[np.ndarray]] = {k: [] for k in [*models, "published"]}
    logs = held_out_logs(args.quick)
    for n in logs:
        folder = "validation_data" if n.startswith("ur-20_01_17") else "identification_data"
        t, q, tau = rl.arrays(rd.load_log(f"ur10e/{folder}/{n}").frame)
        keep = rl.fresh(q)
        tk, qk, tauk = t[keep], q[keep], tau[keep]
        _, v, a = rl.sg_fit(tk, qk)
        inner = np.zeros(len(tk), bool)
        inner[rl.SG_WINDOW // 2 : len(tk) - rl.SG_WINDOW // 2] = True
        for k, m in models.items():
            pooled[k].append((rl.predict_robot(m, qk, v, a) - tauk)[inner])
        pooled["published"].append((published.predict(qk, v, a) - tauk)[inner])
    out["held_out_logs"] = logs
    out["pooled_rms"] = {k: rl.rms(np.vstack(v)).tolist() for k, v in pooled.items()}
    print(f"held-out torque residual [N·m], pooled over {len(logs)} moving logs")
    print(f"{'model':24s}" + "".join(f"{j[:9]:>10s}" for j in rd.UR10E_JOINTS))
    for k, r in out["pooled_rms"].items():
        print(f"{k:24s}" + "".join(f"{x:10.3f}" for x in r))
    for k, d in out["laws"].items():
        print(f"\n{k}: {json.dumps({x: d[x] for x in d if x not in ('report',)}, indent=None)}")
    if not args.quick:
        path = Path(__file__).with_suffix(".json")
        path.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

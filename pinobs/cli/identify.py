"""``pinobs identify``: inertias, friction and rotor inertias (and a torque offset) from a
log; a report and a calibrated URDF (its armature in a ``.pinobs.json`` sidecar)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pinobs.cli.options import (
    add_clock_option,
    add_drive_options,
    add_log_columns,
    add_robot_options,
    load_robot,
    rate_not_used,
    read_args_log,
)
from pinobs.cli.output import check_output
from pinobs.errors import OutputExistsError
from pinobs.io.clock import without_stale
from pinobs.model.friction import FRICTION_LAWS
from pinobs.model.identification import MAX_CONDITION
from pinobs.model.sidecar import sidecar_path
from pinobs.observers.checks import positive

if TYPE_CHECKING:
    from pinobs.cli.options import Subparsers

__all__ = ["SMOOTHER_RHO_HINT", "add_parser", "handle"]

#: ``pinobs identify`` suggests comparing with ``--no-refine`` at or above this smoother
#: consistency: clean simulated logs gave 0.44–14.8, 1 % torque noise 20–183 (where the
#: refinement still helped a UR5), 5 % 108–4500 (where it did not, on average:
#: :mod:`pinobs.calibration`).
SMOOTHER_RHO_HINT = 100.0


def add_parser(subparsers: Subparsers) -> argparse.ArgumentParser:
    """``pinobs identify``."""
    p = subparsers.add_parser(
        "identify", help="identify inertias and friction from a log; write a calibrated URDF"
    )
    add_robot_options(p, "URDF")
    p.add_argument(
        "--log",
        required=True,
        help="log with t, q and tau columns (CSV, Parquet, NPZ or a ROS bag, as estimate reads; "
        "without t: --rate)",
    )
    add_log_columns(p)
    add_drive_options(p)
    add_clock_option(p)
    p.add_argument(
        "--rate",
        type=float,
        default=None,
        help="sample rate [Hz] of a CSV/TSV or Parquet log without a t column: row k read at "
        "t = k/R (a log with its own times keeps them)",
    )
    p.add_argument("--out", required=True, help="the calibrated URDF to write")
    _add_model_options(p)
    _add_fit_options(p)
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(func=handle)
    return p


def _add_model_options(p: argparse.ArgumentParser) -> None:
    """``pinobs identify``'s options of what is identified (friction, armature, offset)."""
    p.add_argument("--no-friction", action="store_true", help="do not identify joint friction")
    p.add_argument(
        "--friction-law",
        choices=sorted(FRICTION_LAWS),
        default="viscous-coulomb",
        help="the joint friction law to fit (default %(default)s: the URDF's viscous + "
        "Coulomb tanh(v/0.01)); offset-sigmoid, stribeck and asymmetric have their smoothing "
        "velocity identified and are saved in the sidecar (offset-sigmoid has its own offset: "
        "not with --offset)",
    )
    p.add_argument(
        "--smoothing",
        type=float,
        default=None,
        help="the friction law's smoothing velocity v_s [rad/s], every joint, instead of its "
        "cross-validated search (for --friction-law offset-sigmoid, stribeck, asymmetric; "
        "viscous-coulomb's is 0.01 unless given)",
    )
    p.add_argument(
        "--no-armature",
        action="store_true",
        help="do not identify the rotor inertia (armature) per joint (identified by default "
        "where the data determine it: beyond 2 standard deviations and 1 %% of the joint's "
        "inertia from the model's); keep the model's",
    )
    p.add_argument(
        "--offset",
        action="store_true",
        help="also identify a torque offset per joint (a biased torque sensor; not in the URDF)",
    )


def _add_fit_options(p: argparse.ArgumentParser) -> None:
    """``pinobs identify``'s options of the fit (hold-out, conditioning, torques, noise,
    payload)."""
    p.add_argument(
        "--holdout",
        type=float,
        default=0.2,
        help="fraction of the log (its end) kept out of the fit for the report (default %(default)s)",
    )
    p.add_argument(
        "--max-condition",
        type=float,
        default=MAX_CONDITION,
        help="refuse a log whose identifiable combinations are worse conditioned than this "
        "(default %(default)g)",
    )
    p.add_argument(
        "--torque",
        choices=["held", "sampled"],
        default="held",
        help="how the log's torques were taken: held over each sample (zero-order hold: "
        "pinobs run, most controllers; the default) or sampled at the instants (pinobs "
        "excite's trajectory)",
    )
    p.add_argument(
        "--no-refine",
        action="store_true",
        help="fit once, on Savitzky–Golay velocities, without the model-based smoother's "
        "refinement passes (compare when the report's smoother consistency is in the "
        "hundreds: noisy torques)",
    )
    p.add_argument(
        "--weighting",
        choices=["torque", "inertia"],
        default="inertia",
        help="how the fit weighs the joints: the rows by M⁻¹ (acceleration-like, the "
        "default) or each torque channel by its own residual scale in N·m (better on real "
        "arms with noisy light joints, worse on simulated logs)",
    )
    p.add_argument(
        "--exclude-torque",
        action="append",
        default=[],
        metavar="JOINT",
        help="leave this joint's torque channel out of the fit (not measured, or mostly "
        "zero); repeat for several",
    )
    p.add_argument(
        "--noise",
        type=float,
        default=None,
        help="position noise σ [rad or m] of the log (default: estimated from its rows)",
    )
    p.add_argument(
        "--payload",
        metavar="BODY",
        default=None,
        help="identify only a load's ten inertial parameters attached to this body or frame, "
        "the --robot taken as calibrated (its other parameters fixed)",
    )


def handle(args: argparse.Namespace) -> int:
    """The identification's report printed, its URDF written, how to use it said."""
    from pinobs.calibration import REFINE_ACCEL_PSD, identify

    out = Path(args.out)
    positive("rate", args.rate, allow_none=True)
    check_output("--out", out)  # before the work, as the other commands
    robot = load_robot(args)
    if out.exists() and not args.force:
        raise OutputExistsError(f"{str(out)!r} exists; give --force to overwrite it")
    if out.resolve() == Path(args.log).resolve():
        raise OutputExistsError(f"--out {str(out)!r} is the log itself")
    log = read_args_log(args, robot)
    unused = rate_not_used(args.rate, log)
    if unused:
        print(f"warning: {unused}", file=sys.stderr)
    log, clock = without_stale(log, mode=args.clock or "auto")
    if clock.repaired or clock.stale:  # (stale rows left out: one sample per row to fit)
        print(f"warning: {clock.message()}", file=sys.stderr)
    ident = identify(
        robot,
        log,
        friction=False if args.no_friction else args.friction_law,
        offset=args.offset,
        armature=not args.no_armature,
        holdout=args.holdout,
        max_condition=args.max_condition,
        torque=args.torque,
        smoothing=args.smoothing,
        refine=() if args.no_refine else REFINE_ACCEL_PSD,
        noise_std=args.noise,
        weighting=args.weighting,
        exclude=args.exclude_torque,
        payload=args.payload,
    )
    print(_identify_report(ident))
    path = ident.save(str(out))
    opts = ", ".join(f"{k}={v:g}" for k, v in ident.report["observer_options"].items())
    root = robot.root_joint if robot.root_joint not in (None, "fixed") else None
    how = f"{path!r}, friction=True" + ("" if root is None else f", root_joint={root!r}")
    cli = f"--robot {path} --friction" + ("" if root is None else f" --root-joint {root}")
    sidecar = sidecar_path(path)
    beside = f" and its rotor inertias and friction law to {sidecar}" if sidecar.is_file() else ""
    print(f"wrote {path}{beside}: load it with pinobs.load({how}) (pinobs estimate: {cli})")
    print(
        f"run ekf or riemannian on it with {opts or 'their default options'}, or adaptive "
        "starting from it"
    )
    return 0


def _identify_report(ident: Any) -> str:
    """The identification report as text tables (``pinobs identify``)."""
    rep = ident.report
    lines = [
        f"rows {rep['rows']} fitted, {rep['holdout_rows']} held out; "
        f"{rep['rank']} identifiable combinations of {rep['n_parameters']} parameters; "
        f"condition number {rep['condition']:.3g}"
        + ("; physical consistency enforced" if rep["projected"] else ""),
        "",
    ]
    lines += _residual_lines(rep)
    if "payload" in rep:
        pl = rep["payload"]
        com = ", ".join(f"{x:.4g}" for x in pl["com"])
        lines.append(
            f"payload on {pl['frame']}: mass {pl['mass']:.4g} ± {pl['mass_std']:.2g} kg, centre "
            f"of mass ({com}) m in {pl['frame']}"
        )
    lines += _parameter_lines(ident, rep)
    lines += _notes(ident, rep)
    return "\n".join(lines)


def _residual_lines(rep: dict[str, Any]) -> list[str]:
    """The report's table of torque residuals per joint, with its title."""
    lines: list[str] = []
    by_torque = rep.get("weighting") == "torque"
    lines.append(
        "torque residual RMS per joint, windows' mean torque [N·m; N prismatic]"
        if by_torque
        else "torque residual RMS per joint (fit: rows weighted by M⁻¹/Δt, rad/s²-like; "
        "held-out also in N·m [N prismatic])"
    )
    lines.append(
        f"{'joint':24s} {'fit before':>11s} {'fit after':>11s} {'unexplained':>12s} "
        f"{'held-out before':>16s} {'held-out after':>15s}"
        + (f" {'σ [N·m]':>10s}" if by_torque else f" {'N·m before':>11s} {'N·m after':>10s}")
    )
    excluded = set(rep.get("excluded", []))
    for j, name in enumerate(rep["coordinates"]):
        unexplained = rep["unexplained"][j]
        lines.append(
            f"{name:24s} {rep['residual_before'][j]:11.4g} {rep['residual_after'][j]:11.4g} "
            + (
                f"{'excluded':>12s} "
                if name in excluded
                else f"{100 * unexplained:10.3g} % "
                if math.isfinite(unexplained)
                else f"{'—':>12s} "
                if math.isnan(unexplained)
                else f"{'no torque':>12s} "
            )
            + f"{rep['holdout_before'][j]:16.4g} {rep['holdout_after'][j]:15.4g}"
            + (
                f" {rep['torque_sigma'][j]:10.4g}"
                if by_torque
                else f" {rep['holdout_torque_before'][j]:11.4g} "
                f"{rep['holdout_torque_after'][j]:10.4g}"
            )
        )
    return lines


def _parameter_lines(ident: Any, rep: dict[str, Any]) -> list[str]:
    """The report's table of the parameters identified, and those not excited."""
    lines = ["", f"{'parameter':32s} {'nominal':>12s} {'identified':>12s} {'std':>10s}"]
    for name, value, std, nominal, excited in ident.parameters.as_rows():
        if excited:
            lines.append(f"{name:32s} {nominal:12.5g} {value:12.5g} {std:10.2g}")
    n_not = len(rep["not_excited"])
    if n_not:
        moved = rep.get("moved_by_consistency", [])
        values = dict(zip(ident.parameters.names, ident.parameters.values, strict=True))
        nominal = dict(zip(ident.parameters.names, ident.parameters.nominal, strict=True))
        lines.append(
            f"({n_not} parameters not excited by this log: "
            + ", ".join(rep["not_excited"][:6])
            + (", ..." if n_not > 6 else "")
            + "; "
            + (
                f"physical consistency moved {len(moved)} of them: "
                + ", ".join(f"{n} {nominal[n]:.4g} → {values[n]:.4g}" for n in moved[:6])
                + (", ..." if len(moved) > 6 else "")
                + "; the others stay near their nominal values)"
                if moved
                else "they stay near their nominal values)"
            )
        )
    return lines


def _notes(ident: Any, rep: dict[str, Any]) -> list[str]:
    """The report's closing lines: the friction law's velocities, the smoother's
    consistency, the noise level, the warnings and the torque offset."""
    lines: list[str] = []
    law = rep.get("friction_law")
    if law and law["law"] != "viscous-coulomb":  # the velocities the search chose [rad/s]
        lines.append(
            f"friction law {law['law']}: smoothing velocity v_s "
            + ", ".join(
                f"{j} {v:.3g}" for j, v in zip(law["joints"], law["smoothing"], strict=True)
            )
            + " rad/s"
            + (
                "; Stribeck velocity " + ", ".join(f"{v:.3g}" for v in law["stribeck_velocity"])
                if law["law"] == "stribeck"
                else ""
            )
        )
    rho = rep.get("smoother_consistency", math.nan)
    if math.isfinite(rho):  # pinobs.calibration's "Limitation: noisy torques"
        lines.append(
            f"velocities: {rep['velocities']}, smoother consistency ρ = {rho:.3g} (about 1 "
            "when the model and the torques explain the positions"
            + (
                "; this high, the torques are likely noisy and the refined fit may be no "
                "better than --no-refine's: compare the two)"
                if rho >= SMOOTHER_RHO_HINT
                else ")"
            )
        )
    if "noise_std" in rep:
        lines.append(f"position noise σ = {rep['noise_std']:.3g} rad or m (--noise to give it)")
    lines += [f"warning: {w}" for w in rep.get("warnings", [])]
    if np.any(ident.offset):
        lines.append(
            "torque offset b per joint [N·m] (not stored in the URDF; the model is driven by tau + b: add it to the torques "
            "or let the observer estimate it): " + ", ".join(f"{b:.4g}" for b in ident.offset)
        )
    return lines

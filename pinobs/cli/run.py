"""``pinobs run``: simulate a robot and compare observers (a table, JSON, a saved result,
playback); :func:`run_one`, one simulation and its report, is ``demo``'s too."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from pinobs.cli.options import add_robot_options, add_sim_options, load_robot, progress
from pinobs.cli.output import (
    check_outputs,
    consistency_warnings,
    short_reason,
    watch,
    write_json,
)
from pinobs.errors import GainError, OptionError, UnsupportedRobotError
from pinobs.evaluation import evaluate, format_table
from pinobs.model import Robot, aba_time
from pinobs.observers import Observer, make_observer, observer_class, observer_names
from pinobs.simulation import Result, Sensor, mismatched_plant, simulate

if TYPE_CHECKING:
    from pinobs.cli.options import Subparsers

__all__ = ["add_parser", "handle", "run_one"]


def add_parser(subparsers: Subparsers) -> argparse.ArgumentParser:
    """``pinobs run``."""
    p = subparsers.add_parser("run", help="simulate a robot and compare observers")
    add_robot_options(p, "URDF/MJCF")
    p.add_argument(
        "--observer",
        action="append",
        required=True,
        help="observer name, comma list, or 'all' (repeatable)",
    )
    p.add_argument("--json", default=None, help="write the metrics to this JSON file")
    p.add_argument("--save", default=None, help="write the whole result to this .npz file")
    p.add_argument(
        "--html", default=None, help="write a self-contained 3D playback (meshcat) to this file"
    )
    p.add_argument(
        "--meshcat", action="store_true", help="serve the playback on a local meshcat server"
    )
    p.add_argument(
        "--plot", default=None, help="write true vs estimated velocities to this PNG (matplotlib)"
    )
    add_sim_options(p, duration=3.0)
    p.set_defaults(func=handle)
    return p


def handle(args: argparse.Namespace) -> int:
    """One simulation: its table printed, its outputs written."""
    check_outputs(args, ("json", "save", "html", "plot"))
    robot = load_robot(args)
    names = _observer_list(args.observer)
    result, report, table = run_one(robot, names, args, strict=not _asks_all(args.observer))
    print(table)
    if args.json:
        print(f"wrote {write_json(args.json, report)}")
    if args.save:
        print(f"wrote {result.save(args.save)}")
    watch(result, robot, args)
    return 0


def _observer_list(spec: Sequence[str]) -> list[str]:
    """``--observer`` values: names, comma lists, ``all``; at least one name."""
    names: list[str] = []
    for item in spec:
        for name in item.split(","):
            name = name.strip()
            if name == "all":
                names.extend(observer_names())
            elif name:
                observer_class(name)  # raises UnknownNameError listing the names
                names.append(name)
    if not names:
        raise OptionError(
            f"--observer {','.join(spec)!r} names no observer; give names (pinobs list) or 'all'"
        )
    return list(dict.fromkeys(names))


def _asks_all(spec: Sequence[str]) -> bool:
    """``all`` among the ``--observer`` values (then observers that refuse the robot are skipped)."""
    return any(name.strip() == "all" for item in spec for name in item.split(","))


def _build(
    robot: Robot, names: Sequence[str], sensor: Sensor, *, strict: bool
) -> tuple[dict[str, Observer[Any]], dict[str, str]]:
    """Observers by name; with ``strict=False`` those that refuse the robot are skipped with the reason."""
    built: dict[str, Observer[Any]] = {}
    skipped: dict[str, str] = {}
    for name in names:
        try:
            built[name] = make_observer(name, robot, rate=sensor.rate, noise_std=sensor.noise_std)
        except UnsupportedRobotError as exc:
            if strict:
                raise
            skipped[name] = short_reason(exc)
    return built, skipped


def run_one(
    robot: Robot,
    names: Sequence[str],
    args: argparse.Namespace,
    *,
    strict: bool,
    mismatch: str | None = None,
) -> tuple[Result, dict[str, Any], str]:
    """One simulation of the observers ``names`` with the simulation options of ``args``:
    the result, its JSON report, its table (with the skipped, failed and inconsistent)."""
    sensor = Sensor(rate=args.rate, noise_std=args.noise, bits=args.bits)
    if args.seed < 0:  # before the plant draws with it
        raise GainError(f"--seed {args.seed}: give an integer >= 0")
    plant = None if mismatch is None else mismatched_plant(robot, mismatch, seed=args.seed)
    observers, skipped = _build(robot, names, sensor, strict=strict)
    with progress(f"{robot.name}: simulating", not args.no_progress) as step:
        result = simulate(
            robot,
            observers,
            duration=args.duration,
            sensor=sensor,
            inputs=args.input,
            perturb_q=args.perturb_q,
            perturb_v=args.perturb_v,
            seed=args.seed,
            plant=plant,
            progress=step,
        )
    metrics = evaluate(result, robot)
    aba = aba_time(robot)
    title = (
        f"{robot.name} (nv = {robot.nv}): {args.duration:g} s at {args.rate:g} Hz, "
        f"noise {args.noise:g}, input {result.meta['input']}, seed {args.seed}, "
        f"start error |dq| = {args.perturb_q:g}, |dv| = {args.perturb_v:g}; "
        f"one pin.aba = {aba * 1e6:.2f} us"
    )
    if mismatch is not None:
        title += f"; the truth is the {mismatch} model, the observers know the nominal one"
    table = format_table(metrics, aba_seconds=aba, title=title)
    if skipped:
        table += "\n" + "\n".join(f"skipped {k}: {v}" for k, v in skipped.items())
    failures = result.meta.get("failures", {})
    if failures:  # why an observer stopped (the table says only when)
        table += "\n" + "\n".join(f"failed {k}: {v}" for k, v in failures.items())
    warnings = consistency_warnings({k: ob.consistency() for k, ob in observers.items()})
    if warnings:
        table += "\n" + "\n".join(warnings)
    report = {
        "robot": robot.name,
        "nv": robot.nv,
        "meta": result.meta,
        "aba_seconds": aba,
        "skipped": skipped,
        "consistency": {k: ob.consistency().as_dict() for k, ob in observers.items()},
        "rms_v_error": {m.observer: m.rms_v_error for m in metrics},
        "observers": [
            {
                **m.as_dict(),
                "cost_in_aba": m.time_per_update / aba,
                "options": result.trace(m.observer).options,
            }
            for m in metrics
        ],
    }
    return result, report, table

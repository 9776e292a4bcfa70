"""``pinobs sweep``: robots × scenarios × seeds × observer options on Dask: a tidy table
and a plot."""

from __future__ import annotations

import argparse
import itertools
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from pinobs.cli.options import (
    add_cluster_options,
    add_progress_option,
    check_cluster,
    cluster_name,
    task_progress,
)
from pinobs.cli.output import check_output, plural, short_reason
from pinobs.errors import GainError, OptionError, UnsupportedRobotError
from pinobs.model import load
from pinobs.observers import make_observer, observer_class
from pinobs.observers.base import positive
from pinobs.simulation import MISMATCH_SCENARIOS

if TYPE_CHECKING:
    from pinobs.cli.options import Subparsers

__all__ = ["add_parser", "handle"]

#: Options every sweep observer gets from the sweep's own flags.
_SWEEP_SHARED = {"rate": "--rate", "noise_std": "--noise"}


def add_parser(subparsers: Subparsers) -> argparse.ArgumentParser:
    """``pinobs sweep``."""
    p = subparsers.add_parser(
        "sweep",
        help="robots × scenarios × seeds × observer options on Dask: a tidy table and a plot",
    )
    p.add_argument("--robots", default="ur5", help="comma-separated (default %(default)s)")
    p.add_argument(
        "--scenarios",
        default="exact",
        help="mismatch scenarios, comma-separated: " + ", ".join(MISMATCH_SCENARIOS),
    )
    p.add_argument("--seeds", default="0-4", help="'0-9' or '0,3,7' (default %(default)s)")
    p.add_argument(
        "--observers",
        default="ekf,kf",
        help="names, or label=name:key=value;key=value (e.g. 'ekf+d=ekf:disturbance_psd=1')",
    )
    p.add_argument("--out", default="sweep", help="output folder (default %(default)s)")
    p.add_argument("--force", action="store_true", help="overwrite a sweep in --out")
    add_cluster_options(p, "local worker processes (0: this process; default: one per core)")
    p.add_argument("--duration", type=float, default=3.0, help="per run [s] (default %(default)s)")
    p.add_argument(
        "--rate", type=float, default=1000.0, help="sample rate [Hz] (default %(default)s)"
    )
    p.add_argument(
        "--noise", type=float, default=1e-4, help="position noise std (default %(default)s)"
    )
    add_progress_option(p)
    p.set_defaults(func=handle)
    return p


def handle(args: argparse.Namespace) -> int:
    """The sweep's runs on Dask: failures, the median table, the files written."""
    from pinobs.evaluation.distributed import sweep, sweep_tasks, write_sweep

    robots, scenarios, seeds, observers = _checked(args)
    refusals = _refusals(args, robots, observers, len(scenarios) * len(seeds))
    tasks = sweep_tasks(
        robots,
        scenarios,
        seeds,
        observers,
        duration=args.duration,
        rate=args.rate,
        noise_std=args.noise,
    )
    for line in refusals:
        print(line, file=sys.stderr)
    print(f"pinobs sweep: {plural(len(tasks), 'run')} on {cluster_name(args)}")
    with task_progress("sweep", not args.no_progress) as step:
        table = sweep(tasks, scheduler=args.scheduler, workers=args.workers, progress=step)
    failed = table[table["error"].notna()]
    for line in _failed_runs(failed):
        print(line, file=sys.stderr)
    if len(failed) == len(table):  # not one observer ran
        print(f"pinobs: error: 0 of {plural(len(tasks), 'run')} succeeded", file=sys.stderr)
    else:
        # over every run: a robot and scenario where an observer always failed shows NaN
        summary = (
            table.groupby(["robot", "scenario", "observer"], sort=False)["rms_v_error"]
            .median()
            .unstack("observer")
        )
        print("median RMS velocity error [rad/s] over seeds (nan: every run failed):")
        print(summary.to_string(float_format=lambda x: f"{x:.3g}"))
        if len(failed):
            print(
                f"pinobs: error: {len(failed)} of {len(table)} observer runs failed",
                file=sys.stderr,
            )
    for path in write_sweep(table, args.out, force=args.force):
        print(f"wrote {path}")
    return 0 if failed.empty else 1


def _checked(
    args: argparse.Namespace,
) -> tuple[list[str], list[str], list[int], dict[str, tuple[str, dict[str, Any]]]]:
    """Everything a run would refuse, refused here once rather than in every task: the
    robots, scenarios, seeds and observers of the sweep."""
    from pinobs.evaluation.distributed import check_sweep_out

    check_cluster(args)
    positive("--duration", args.duration)
    positive("--rate", args.rate)
    positive("--noise", args.noise, allow_zero=True)
    if args.duration * args.rate < 1.0:
        raise GainError(
            f"--duration {args.duration:g} s is shorter than one sample at {args.rate:g} Hz"
        )
    check_output("--out", args.out, folder=True)
    check_sweep_out(args.out, force=args.force)
    robots = _unique_list("--robots", args.robots)
    scenarios = _unique_list("--scenarios", args.scenarios)
    unknown = [s for s in scenarios if s not in MISMATCH_SCENARIOS]
    if unknown:
        raise OptionError(
            f"--scenarios: unknown {', '.join(map(repr, unknown))}; give some of "
            + ", ".join(MISMATCH_SCENARIOS)
        )
    seeds = _parse_seeds(args.seeds)
    observers = _parse_sweep_observers(args.observers)
    return robots, scenarios, seeds, observers


def _refusals(
    args: argparse.Namespace,
    robots: Sequence[str],
    observers: dict[str, tuple[str, dict[str, Any]]],
    runs: int,
) -> list[str]:
    """A warning per observer that refuses a robot (its ``runs`` runs there fail alone, the
    others run); a bad robot or observer option fails here, not once per task."""
    refusals = []
    for robot_name in robots:
        robot = load(robot_name)
        for label, (name, options) in observers.items():
            try:
                make_observer(name, robot, rate=args.rate, noise_std=args.noise, **options)
            except UnsupportedRobotError as exc:
                refusals.append(
                    f"warning: {label} refuses {robot_name}: {short_reason(exc)}; its "
                    f"{plural(runs, 'run')} there are reported as failed"
                )
    return refusals


def _parse_seeds(spec: str) -> list[int]:
    """``"0-4"`` -> 0..4, ``"0,3,7"`` -> those; seeds >= 0, each once, ranges not empty."""
    seeds: list[int] = []
    for part in spec.split(","):
        part = part.strip()
        lo, dash, hi = part.partition("-")
        if not lo.isdigit() or (dash and not hi.isdigit()):  # '5-', '0--2', '-1', 'x'
            raise OptionError(
                f"--seeds {spec!r}: {part!r} is not a seed or a range; give seeds >= 0 as "
                "'0-9' or '0,3,7'"
            )
        first, last = int(lo), int(hi if dash else lo)
        if first > last:
            raise OptionError(f"--seeds {spec!r}: the range {part!r} is empty; give LOW-HIGH")
        seeds.extend(range(first, last + 1))
    _no_repeats("--seeds", spec, seeds)
    return seeds


def _no_repeats(flag: str, spec: str, items: list[Any]) -> None:
    """Refuse a list that names an entry twice (a repeated run, skewing the medians)."""
    repeated = sorted({x for x in items if items.count(x) > 1})
    if repeated:
        raise OptionError(
            f"{flag} {spec!r} names {', '.join(map(str, repeated))} more than once; each would "
            "run the same simulations again"
        )


def _unique_list(flag: str, spec: str) -> list[str]:
    """A comma list of names; refused when empty or when a name repeats (a repeated run)."""
    items = [x.strip() for x in spec.split(",")]
    if not all(items):
        raise OptionError(f"{flag} {spec!r}: an empty name; give a comma-separated list")
    _no_repeats(flag, spec, items)
    return items


def _option_value(text: str) -> Any:
    """A sweep option's value: an int, a float, true/false, or the string itself."""
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text.strip()


def _parse_sweep_observers(spec: str) -> dict[str, tuple[str, dict[str, Any]]]:
    """``"kf,ekf+d=ekf:disturbance_psd=1"``: a name, or ``label=name:key=value;key=value``.

    Values are ints, floats, ``true``/``false`` or strings; labels are unique.
    """
    out: dict[str, tuple[str, dict[str, Any]]] = {}
    for item in spec.split(","):
        item = item.strip()
        if not item:
            raise OptionError(f"--observers {spec!r}: an empty entry; give a comma-separated list")
        head, _, opts = item.partition(":")
        label, eq, name = head.partition("=")
        if not eq:
            label = name = head
        label, name = label.strip(), name.strip()
        if not label or not name:
            raise OptionError(
                f"--observers {item!r}: give NAME, NAME:key=value or LABEL=NAME:key=value"
            )
        observer_class(name)  # an unknown name: UnknownNameError listing the registered ones
        options: dict[str, Any] = {}
        for kv in filter(None, (x.strip() for x in opts.split(";"))):
            key, sep, value = kv.partition("=")
            key = key.strip()
            if not sep or not key or not value.strip():
                raise OptionError(f"--observers {item!r}: option {kv!r} is not key=value")
            if key in _SWEEP_SHARED:
                raise OptionError(
                    f"--observers {item!r}: {key} is the same for every observer of a sweep; "
                    f"give {_SWEEP_SHARED[key]}"
                )
            options[key] = _option_value(value)
        if label in out:
            raise OptionError(
                f"--observers {spec!r}: the label {label!r} is used twice; give each entry its "
                "own label (LABEL=NAME:key=value)"
            )
        out[label] = (name, options)
    return out


def _failed_runs(failed: Any) -> list[str]:
    """The failed rows of a sweep, one line per robot, scenario, observers and error,
    with the seeds where they failed."""
    runs: dict[tuple[str, str, int, str], list[str]] = {}
    for r in failed.itertuples(index=False):
        runs.setdefault((r.robot, r.scenario, r.seed, r.error), []).append(r.observer)
    lines: dict[tuple[str, str, tuple[str, ...], str], list[int]] = {}
    for (robot, scenario, seed, error), labels in runs.items():
        lines.setdefault((robot, scenario, tuple(labels), error), []).append(int(seed))
    return [
        f"failed: {', '.join(labels)} on {robot} {scenario}, "
        f"seed{'s' if len(seeds) > 1 else ''} {_seed_spec(seeds)}: {error}"
        for (robot, scenario, labels, error), seeds in lines.items()
    ]


def _seed_spec(seeds: Sequence[int]) -> str:
    """Seeds as :func:`_parse_seeds` reads them: ``[0, 1, 2, 5]`` -> ``"0-2,5"``."""
    parts: list[str] = []
    for _, group in itertools.groupby(enumerate(sorted(seeds)), lambda x: x[1] - x[0]):
        run = [s for _, s in group]
        parts.append(str(run[0]) if len(run) == 1 else f"{run[0]}-{run[-1]}")
    return ",".join(parts)

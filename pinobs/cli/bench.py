"""``pinobs bench``: accuracy and cost of every observer against the baselines."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from pinobs.cli.options import add_cluster_options, check_cluster, cluster_name
from pinobs.cli.output import write_json

if TYPE_CHECKING:
    from pinobs.cli.options import Subparsers

__all__ = ["add_parser", "handle"]


def add_parser(subparsers: Subparsers) -> argparse.ArgumentParser:
    """``pinobs bench``."""
    p = subparsers.add_parser(
        "bench", help="accuracy and cost of every observer against the baselines"
    )
    p.add_argument("--quick", action="store_true", help="two robots, short runs: under two minutes")
    p.add_argument("--json", default=None, help="write the full report to this JSON file")
    p.add_argument(
        "--live", action="store_true", help="UR5 observers in a paced 1 kHz loop, 10 s each"
    )
    add_cluster_options(
        p,
        "its independent runs on a local Dask cluster of N processes (default 0: "
        "one after the other in this process; workers load each other's timings)",
    )
    p.set_defaults(func=handle)
    return p


def handle(args: argparse.Namespace) -> int:
    """The bench's table (and JSON); exit code 1 when a task failed."""
    from pinobs.evaluation.bench import BenchConfig, bench_tasks, format_bench, run_bench

    if args.live:  # a user's own paced loop (issue 39): pinobs.evaluation.live
        from pinobs.evaluation.live import print_live

        return print_live(quick=args.quick, json_path=args.json)
    check_cluster(args)
    if args.workers is None and not args.scheduler:
        args.workers = 0  # bench's default: its timings not loaded by each other
    cfg = BenchConfig.quick() if args.quick else BenchConfig()
    print(
        f"pinobs bench ({'quick' if args.quick else 'full'}): robots {', '.join(cfg.robots)}; timing also {', '.join(cfg.cost_robots)}"
    )
    print(f"independent runs on {cluster_name(args)}")
    report = run_bench(
        cfg,
        log=lambda msg: print(msg, flush=True),
        scheduler=args.scheduler,
        workers=args.workers,
    )
    print(format_bench(report))
    print(
        f"\nbench took {report['seconds']:.0f} s on {report['machine']['processor']} ({report['machine']['system']})"
    )
    if args.json:
        print(f"wrote {write_json(args.json, report)}")
    if report["failed"]:
        n = len(bench_tasks(cfg))
        print(f"pinobs: error: {len(report['failed'])} of {n} bench tasks failed", file=sys.stderr)
        return 1
    return 0

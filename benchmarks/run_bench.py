# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs"]
# ///
"""Run the full benchmark and write `benchmarks/results.json` and `benchmarks/results.md`.

The same as `pinobs bench --json benchmarks/results.json`, plus a markdown file
the README quotes (with the command, date, machine and how long it took).

    python benchmarks/run_bench.py            # full run
    python benchmarks/run_bench.py --quick    # under two minutes
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from pinobs.evaluation.bench import BenchConfig, format_bench, run_bench

if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="two robots, short runs")
    parser.add_argument(
        "--out", default=str(Path(__file__).parent), help="folder for results.json / results.md"
    )
    args = parser.parse_args()
    cfg = BenchConfig.quick() if args.quick else BenchConfig()
    report = run_bench(cfg, log=lambda m: print(m, flush=True))
    if report["failed"]:  # the README quotes these results: not with rows missing
        raise SystemExit(f"{len(report['failed'])} bench tasks failed; nothing written")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps(report, indent=1, default=str) + "\n")
    m = report["machine"]
    cmd = "python benchmarks/run_bench.py" + (" --quick" if args.quick else "")
    header = (
        f"Made by `{cmd}` on {m['date']} in {report['seconds']:.0f} s; {m['processor']}, {m['system']}, "
        f"Python {m['python']}, Pinocchio {m['pinocchio']}, NumPy {m['numpy']}. "
        f"{cfg.duration:g} s per run at {cfg.rate:g} Hz, PD tracking of a multi-sine reference (the base "
        f"of a floating robot actuated too), start error |dq| = {cfg.perturb_q:g} rad, |dv| = {cfg.perturb_v:g} rad/s, seed {cfg.seed}; "
        "RMS after the first quarter of the run. `update` and `x aba` are one update's time and its ratio to one "
        "`pin.aba` call on the same robot, both from the cost measurement below (the observer alone, chunks of "
        "updates each followed by as many `pin.aba` calls; `fd*` and `diff` are shown at `fd`'s cost, `kf*` "
        "at the default `kf`'s, whose bank of jerk densities costs more than the one fixed density of `kf*`). "
        "Rows sorted by error; `fd*`, `kf*` are tuned on the run itself (optimistic).\n"
    )
    (out / "results.md").write_text(header + format_bench(report) + "\n")
    print(format_bench(report))
    print(f"wrote {out / 'results.md'} and {out / 'results.json'}")

# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs"]
# ///
"""Issue 39: what the worst updates of a user's 1 kHz loop are made of.

The loop of :func:`pinobs.evaluation.live.live_loop` (σ = 1e-4 simulated samples, the
observer made with ``rate=1000, noise_std=1e-4`` and its live options, paced at 1 kHz:
sleep, then spin to the tick; the set-up frozen for the garbage collector), with, per
update: its wall and thread CPU time; the involuntary context switches in it (``getrusage``
read around it: the OS gave the core to another task) and the minor page faults (the same
read: memory the allocator returned to the OS and took back, which the thread's CPU clock
counts); the garbage collections inside it (``gc.callbacks``: generation, duration); the
CPU time of a fixed piece of work right after it, in the same tick (:func:`_fixed_work`:
eight 6×6 products into a preallocated array and a 300-step Python loop, no allocation that
outlives it: the same work at every tick, so its spread is the machine's); and, for ``adaptive`` (learning in its worker
process), what its learner did in it, read from its state around the update: a window or
a solve sent to the worker, a result taken, a model installed.  Each update after the
first above the p99.9, and each over 1 ms, gets the causes it shows: ``preempted`` (an
involuntary switch, or wall over twice the CPU time), ``fault`` (a minor page fault in it),
``gc<generation>``, the learner's events (``worker busy``: a job was out, not yet taken,
when the update began), ``machine`` (the fixed work in the same tick above its own p99: the
core ran everything slower then, e.g. a virtual machine's stolen or throttled time, another
task's cache traffic), else ``cpu`` (the thread ran, nothing of the above: the work itself,
or the machine slowing it in a way the fixed work did not see).

``--replay``: the same update at every tick (the observer's state and its inputs at sample
1000 put back before each call, outside the timing): identical work, so its spread is the
machine's, not the observer's.  Compare a family's p99.9/median with and without it.

    python benchmarks/live_tail.py --only ur5:kf,ur5:adaptive --seconds 20
    python benchmarks/live_tail.py --only ur5:kf --seconds 20 --replay
    python benchmarks/live_tail.py --only ur5:kf,ur5:ekf --seconds 20 --setting mallopt

``--setting``: a process setting a real-time user might apply, for an A/B against a run
without it: ``mallopt`` (glibc's trim threshold 256 MiB, top pad 64 MiB, mmap threshold
256 MiB: freed memory kept, not returned and faulted back), ``fifo`` (the loop's thread at
``SCHED_FIFO`` priority 10: needs the privilege; processes it starts inherit it unless they
set their own, as ``adaptive``'s worker does).

Prints one markdown table and the tail's causes per run; quote the load average with it
(a shared machine's other processes are in these numbers).
"""

from __future__ import annotations

import argparse
import ctypes
import ctypes.util
import gc
import os
import resource
import time
from collections import Counter
from typing import Any

import numpy as np

from pinobs.evaluation.live import LIVE_OPTIONS, NOISE_STD, SPIN
from pinobs.model import aba_call, load
from pinobs.observers import make_observer
from pinobs.simulation import Sensor, simulate

#: [Hz] The loop's rate.
RATE = 1000.0


def _learner_events(before: tuple[int, ...] | None, after: tuple[int, ...] | None) -> list[str]:
    """What ``adaptive``'s learner did between two reads of :func:`_learner_read`."""
    if before is None or after is None:
        return []
    (pending0, windows0, solving0, installs0), (pending1, windows1, solving1, installs1) = (
        before,
        after,
    )
    events = ["worker busy"] if pending0 else []  # a job out at the update's start
    if windows1 > windows0:
        events.append("window sent")
    if solving1 and not solving0:
        events.append("solve sent")
    sent = int(windows1 > windows0) + int(solving1 and not solving0)
    if pending1 < pending0 + sent:
        events.append("solve applied" if solving0 and not solving1 else "result taken")
    if installs1 > installs0:
        events.append("model installed")
    return events


def _learner_read(observer: Any) -> tuple[int, ...] | None:
    """``adaptive``'s learner as counts (its state read from the observer's internals), or
    None for another family."""
    learner = getattr(getattr(observer, "_state", None), "learner", None)
    if learner is None:
        return None
    return (len(learner.pending), learner.windows, int(learner.solving), learner.installs)


def _apply(setting: str) -> None:
    """Apply ``--setting`` (module docstring) to this process."""
    if setting == "mallopt":
        libc = ctypes.CDLL(ctypes.util.find_library("c"))
        m_trim_threshold, m_top_pad, m_mmap_threshold = -1, -2, -3  # glibc's malloc.h
        for option, value in ((m_trim_threshold, 256), (m_top_pad, 64), (m_mmap_threshold, 256)):
            if libc.mallopt(option, value << 20) != 1:
                raise OSError(f"mallopt({option}) failed")
    elif setting == "fifo":
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))


def _fixed_work() -> Any:
    """A fixed piece of work timed after each update (module docstring): the same at every
    tick, nothing allocated that outlives a call."""
    m, x, y = np.eye(6), np.ones(6), np.empty(6)

    def work() -> None:
        for _ in range(8):
            np.dot(m, x, out=y)
        s = 0
        for i in range(300):
            s += i

    return work


def _setup(
    robot_name: str, observer_name: str, n: int, replay: bool
) -> tuple[Any, Any, list[tuple[Any, ...]], dict[str, Any]]:
    """``(observer reset, one pin.aba call, the n updates' inputs, what a replay puts back)``."""
    robot = load(robot_name)
    sim = simulate(
        robot, [], duration=(n + 1100) / RATE, sensor=Sensor(rate=RATE, noise_std=NOISE_STD),
        seed=0,
    )  # fmt: skip
    options = LIVE_OPTIONS.get(observer_name, {})
    observer = make_observer(observer_name, robot, rate=RATE, noise_std=NOISE_STD, **options)
    observer.reset(sim.t[0], sim.q[0], None, sim.tau[0])
    if not replay:
        return (
            observer,
            aba_call(robot, seed=0),
            list(zip(sim.t[1:], sim.q_meas[1:], sim.tau[1:], strict=True)),
            {},
        )
    for k in range(1, 1001):  # the state and inputs of sample 1000, put back at every tick
        observer.update(sim.t[k], sim.q_meas[k], sim.tau[k])
    snap = {a: getattr(observer, a) for a in ("_state", "_t", "_tau", "_last", "_ts")}
    return (
        observer,
        aba_call(robot, seed=0),
        [(sim.t[1001], sim.q_meas[1001], sim.tau[1001])] * n,
        snap,
    )


def run(robot_name: str, observer_name: str, seconds: float, replay: bool) -> dict[str, Any]:
    """One paced loop, its per-update records (module docstring)."""
    n = round(seconds * RATE)
    observer, aba, samples, snap = _setup(robot_name, observer_name, n, replay)
    update = type(observer).update
    wall, cpu, fixed = np.empty(n), np.empty(n), np.empty(n)
    switches, faults = np.empty(n, dtype=int), np.empty(n, dtype=int)
    work = _fixed_work()
    collections: list[tuple[int, int, float]] = []  # (update, generation, seconds)
    learner: list[list[str]] = [[] for _ in range(n)]
    current, started = [-1], [0.0]

    def on_gc(phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            started[0] = time.perf_counter()
        elif current[0] >= 0:
            collections.append((current[0], info["generation"], time.perf_counter() - started[0]))

    gc.collect()
    gc.freeze()
    gc.callbacks.append(on_gc)
    clock, cpu_clock, usage = time.perf_counter, time.thread_time, resource.getrusage
    try:
        start = clock()
        for k in range(n):
            due = start + (k + 1) / RATE
            while (now := clock()) < due:
                if due - now > SPIN:
                    time.sleep(due - now - SPIN)
            observer.__dict__.update(snap)  # (a replay; nothing otherwise)
            before = _learner_read(observer)
            aba()  # as live_loop: one call just before the update
            r0 = usage(resource.RUSAGE_THREAD)
            current[0] = k
            t0, c0 = clock(), cpu_clock()
            update(observer, *samples[k])
            c1, t1 = cpu_clock(), clock()
            current[0] = -1
            r1 = usage(resource.RUSAGE_THREAD)
            c2 = cpu_clock()
            work()
            fixed[k] = cpu_clock() - c2
            switches[k], faults[k] = r1.ru_nivcsw - r0.ru_nivcsw, r1.ru_minflt - r0.ru_minflt
            wall[k], cpu[k] = t1 - t0, c1 - c0
            learner[k] = _learner_events(before, _learner_read(observer))
    finally:
        gc.callbacks.remove(on_gc)
        gc.unfreeze()
    return {
        "robot": robot_name, "observer": observer_name, "replay": replay, "wall": wall * 1e6,
        "cpu": cpu * 1e6, "switches": switches, "gc": collections, "learner": learner,
        "faults": faults, "fixed": fixed * 1e6,
        "load": os.getloadavg(),
    }  # fmt: skip


def causes(r: dict[str, Any], k: int) -> str:
    """The causes update ``k`` shows (module docstring)."""
    out = []
    if r["switches"][k] > 0 or r["wall"][k] > 2.0 * r["cpu"][k]:
        out.append("preempted")
    if r["faults"][k] > 0:
        out.append("fault")
    out += [f"gc{g}" for kk, g, _ in r["gc"] if kk == k]
    out += r["learner"][k]
    if r["fixed"][k] > np.percentile(r["fixed"][1:], 99.0):
        out.append("machine")
    return " + ".join(out) or "cpu"


def report(r: dict[str, Any]) -> list[str]:
    wall, cpu, fixed = r["wall"][1:], r["cpu"][1:], r["fixed"][1:]  # after the first update
    q = {
        name: (np.median(x), *np.percentile(x, [99.0, 99.9]), x.max())
        for name, x in (("wall", wall), ("cpu", cpu))
    }
    gcs = Counter(g for k, g, _ in r["gc"] if k > 0)
    gc_us = {g: np.median([d for k, gg, d in r["gc"] if k > 0 and gg == g]) * 1e6 for g in gcs}
    label = f"{r['robot']} {r['observer']}{' (replay)' if r['replay'] else ''}"
    row = (
        f"| {label} | {q['wall'][0]:.0f} | {q['wall'][2] / q['wall'][0]:.2f} | "
        f"{q['wall'][3] / 1e3:.2f} | {q['cpu'][0]:.0f} | {q['cpu'][2] / q['cpu'][0]:.2f} | "
        f"{q['cpu'][3] / 1e3:.2f} | {np.percentile(fixed, 99.9) / np.median(fixed):.2f} | "
        f"{int(np.sum(r['faults'][1:]))} | {int(np.sum(wall > 1e3))} | "
        + (", ".join(f"gen{g} {c} ({gc_us[g]:.0f} µs)" for g, c in sorted(gcs.items())) or "none")
        + f" | {r['load'][0]:.1f} |"
    )
    tail = [k + 1 for k in np.flatnonzero(wall > q["wall"][2])]
    over = [k + 1 for k in np.flatnonzero(wall > 1e3)]
    cpu_tail = [k + 1 for k in np.flatnonzero(cpu > q["cpu"][2])]
    lines = [row]
    for what, ks in (("wall > p99.9", tail), ("CPU > p99.9", cpu_tail), ("wall > 1 ms", over)):
        if ks:
            c = Counter(causes(r, k) for k in ks)
            lines.append(
                f"  {label}, {len(ks)} updates {what}: "
                + "; ".join(f"{v} {name}" for name, v in c.most_common())
            )
    p99 = np.flatnonzero(cpu > np.percentile(cpu, 99.0)) + 1
    for period in (500, 100, 10):  # our own work every n samples shows as one residue
        residue, count = Counter(p99 % period).most_common(1)[0]
        if count > 0.5 * p99.size:
            lines.append(
                f"  {label}: {count} of the {p99.size} updates over the CPU p99 at update "
                f"index ≡ {residue} mod {period} (CPU median there "
                f"{np.median(r['cpu'][np.arange(r['cpu'].size) % period == residue]):.0f} µs)"
            )
            break
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="ur5:kf,ur5:riemannian,ur5:adaptive")
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--replay", action="store_true", help="the same update every tick")
    parser.add_argument("--setting", choices=("none", "mallopt", "fifo"), default="none")
    args = parser.parse_args()
    _apply(args.setting)
    print(
        "| run | median µs | p99.9/median | max ms | CPU median µs | CPU p99.9/median "
        "| CPU max ms | fixed work CPU p99.9/median | page faults | > 1 ms | GC in updates | load |"
        "\n|---|---|---|---|---|---|---|---|---|---|---|---|"
    )
    tails = []
    for pair in args.only.split(","):
        robot, observer = pair.split(":", 1)
        lines = report(run(robot, observer, args.seconds, args.replay))
        print(lines[0], flush=True)
        tails += lines[1:]
    print("\n" + "\n".join(tails))


if __name__ == "__main__":
    main()

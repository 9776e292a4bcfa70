"""What a user's own real-time loop sees: per-update times of an observer paced at its rate.

:func:`~pinobs.evaluation.measure_cost` times updates back to back, BLAS on one
thread, each chunk against ``pin.aba`` calls a millisecond later: the
observer's cost with warm caches.  A control loop is not that: it waits for
each tick (the process sleeps, other processes run and evict its data), keeps
the process's own BLAS and thread settings, and cares about the worst update,
not the median.  :func:`live_loop` runs that loop: every ``1/rate`` seconds it
waits for the tick (sleeps, then spins its last 0.2 ms), reads the next sample
of a pre-computed simulation and calls ``observer.update(t, q, tau)``, as
``examples/realtime_loop.py`` does; only the call is timed (until issue 39's fused
``kf`` update the three indexings of the simulation's arrays were timed with it: about
1.5–2 ``pin.aba`` calls of a UR5 ``kf``'s paced update, load 6–7).  Per tick it also times one ``pin.aba``
call just before the update (after the same wait: *cold*) and, after the
update, a burst of :data:`ABA_BURST` calls (*warm*, the reference of
:func:`~pinobs.evaluation.measure_cost`), so every ratio compares times taken
under the same machine load, in the same tick.

**The garbage collector.**  A full (generation-2) collection walks every object the process
tracks: after ``import pinobs`` and one observer about 125 000, 120 ms on the 2-core machine
of ``benchmarks/live_loop.md`` (a UR5 ``ekf`` built, load average 12).  CPython runs one
when enough long-lived objects have accumulated (a loop that keeps its estimates in a list
gets there), inside whichever update allocates at that moment: a stall of a hundred
periods.  ``gc.freeze()`` after the set-up (the observer made and reset) moves what exists
to a permanent generation that no collection walks (the same collection then takes
microseconds); :func:`live_loop` does it (``freeze_gc``, undone after the loop), as
``examples/realtime_loop.py`` does and a user's real-time loop should.

**The CPU-time tail is the machine's.**  On the machine of ``benchmarks/live_loop.md`` (a
2-core virtual machine, Linux at 250 Hz without separate interrupt-time accounting, so an
interrupt's time counts as the running thread's CPU time) an update's CPU p99.9 is 2.6–7.2×
its median (4.0–7.0 in that table), for work that is the same at every sample.
``benchmarks/live_tail.py`` and a copy of its loop read per update (UR5 ``kf``, ``ekf``,
``highgain``, ``sliding``, 20–30 s at 1 kHz, load 1.4–3.7): minor page faults 0–1 in
20 000–30 000 updates and none in any update of the top 0.1 % (20 runs of 20 s);
involuntary switches in 0–1 of those 20; no collection.  An update's allocations peak
8.2 KB above its start (``kf``, median; max 9.1; ``ekf`` 4.5, max 6.0 KB; ``tracemalloc``),
far below glibc's 128 KiB ``mmap`` threshold, and it keeps 24 bytes: memory is reused, not
returned and faulted back, and ``mallopt`` (trim threshold, top pad, mmap threshold at
256 / 64 / 256 MiB) left the ratio where it was (two alternated pairs: ``kf`` 3.5, 5.6 →
3.7, 5.8; ``ekf`` 3.1, 4.4 → 3.4, 5.5).  A fixed piece of work timed right after each
update, in the same tick, has the same spread (p99.9/median 1.6–7.3) and is above its own
p99 in 7–15 of the 20 slowest updates (six runs; by chance 0.2); the updates above the p99
gather at one phase of a 4 ms or 10 ms period (four runs: 32–53 % at one residue mod 4,
14–47 % mod 10, against 25 % and 10 % by chance; ``kf`` replaying one sample: 221 of 300
at one residue mod 10): the kernel's and the host's periodic interrupts and stolen time,
charged to whichever thread runs.  Nothing in the process removes them; a core isolated
for the loop (``isolcpus``, ``nohz_full``) on a machine not shared is the operating
system's remedy.  ``SCHED_FIFO`` here (three alternated pairs, 20 s) cut ``ekf``'s wall
p99.9/median (7.3, 10.3, 3.4 → 3.2, 2.3, 2.0) but not ``kf``'s (8.0, 3.7, 5.1 → 3.6, 5.2,
14.2).
"""

from __future__ import annotations

import gc
import os
import time
from dataclasses import asdict, dataclass
from typing import Any, NamedTuple

import numpy as np

from pinobs.model import aba_call, load
from pinobs.model.robot import Vector
from pinobs.observers import make_observer
from pinobs.simulation import Sensor, simulate

__all__ = [
    "ABA_BURST",
    "LIVE_OPTIONS",
    "LIVE_RUNS",
    "LiveTiming",
    "Quantiles",
    "blas_settings",
    "live_loop",
    "live_table",
    "print_live",
]

#: ``pin.aba`` calls timed back to back after each update (the warm reference).
ABA_BURST = 10
#: Seconds of ticks in each window of the spread (:attr:`LiveTiming.spread`).
WINDOW = 1.0
#: [s] The loop sleeps until this long before each tick, then spins.
SPIN = 2e-4
#: [rad or m] The simulated sensor's noise, and the observers' ``noise_std``.
NOISE_STD = 1e-4
#: A family's options in a live loop (:func:`live_loop`): what a user's real-time loop should
#: give it.  ``adaptive`` re-identifies its model on a worker process (its solves took 4–17 ms,
#: its first window 0.5 s, inside one update when synchronous: ``pinobs.observers.adaptive``).
LIVE_OPTIONS: dict[str, dict[str, Any]] = {"adaptive": {"learning": "background"}}


class Quantiles(NamedTuple):
    """Median, 99th and 99.9th percentiles and maximum of a sample."""

    median: float
    p99: float
    p999: float
    max: float

    @classmethod
    def of(cls, x: Any) -> Quantiles:
        a = np.asarray(x, dtype=float)
        return cls(*(float(v) for v in np.percentile(a, [50.0, 99.0, 99.9, 100.0])))

    def scaled(self, factor: float) -> Quantiles:
        return Quantiles(*(v * factor for v in self))


@dataclass(frozen=True)
class LiveTiming:
    """One observer's per-update times in a paced loop (:func:`live_loop`).

    Attributes:
        robot, observer: what ran; ``options``: its options beyond ``rate`` and ``noise_std``.
        rate: ticks per second [Hz]; ``duration``: seconds of ticks [s]; ``updates``: their number.
        update_us: wall time of one ``update`` [µs].
        cpu_us: this thread's CPU time in one ``update`` [µs] (without the time it waited
            for a core: the wall time minus this is the machine's load).
        aba_us: median wall time of one warm ``pin.aba`` call [µs] (bursts after updates).
        aba_cold_us: median wall time of the ``pin.aba`` call timed just before each update [µs].
        ratio: ``update_us`` over ``aba_us`` (each quantile over the median warm call).
        mean_ratio: the mean update over ``aba_us`` (what :func:`~pinobs.evaluation.measure_cost`
            reports: work done every k-th update at its amortised share).
        spread: ``(lo, hi)`` of the median and of the p99 ratio over windows of
            :data:`WINDOW` s: ``{"median": (lo, hi), "p99": (lo, hi)}``.
        misses: updates longer than the period (deadline misses).
        first_us: wall time of the first update [µs] (caches and lazy loading).
        blas: the BLAS and thread settings when the loop started (:func:`blas_settings`).
        blas_after: the same after the loop (an observer must leave them as they were).
        blas_limit: whether ``update`` ran with its one-BLAS-thread limit.
        load: the machine's load averages (1, 5, 15 min) at the end; ``cpus``: its cores.
        freeze_gc: whether the loop ran with the set-up's objects frozen (``gc.freeze``).
    """

    robot: str
    observer: str
    options: dict[str, Any]
    rate: float
    duration: float
    updates: int
    update_us: Quantiles
    cpu_us: Quantiles
    aba_us: float
    aba_cold_us: float
    ratio: Quantiles
    mean_ratio: float
    spread: dict[str, tuple[float, float]]
    misses: int
    first_us: float
    blas: str
    blas_after: str
    blas_limit: bool
    load: tuple[float, float, float]
    cpus: int
    freeze_gc: bool = False

    def as_dict(self) -> dict[str, Any]:
        """Plain values, for JSON."""
        return asdict(self)


def blas_settings() -> str:
    """The process's BLAS and OpenMP libraries and their thread counts, as threadpoolctl sees
    them (``"openblas 0.3.31 pthreads: 2 threads (libscipy_openblas64_…); …"``)."""
    from threadpoolctl import threadpool_info

    parts = []
    for lib in sorted(threadpool_info(), key=lambda d: (d["user_api"], d["filepath"])):
        name = os.path.basename(lib["filepath"]).split(".so")[0].split(".dylib")[0]
        layer = lib.get("threading_layer")
        parts.append(
            f"{lib['internal_api']} {lib.get('version') or ''}"
            f"{' ' + layer if layer else ''}: {lib['num_threads']} threads ({name})"
        )
    return "; ".join(parts)


def _window_ratios(
    wall: Vector, warm: Vector, per_window: int, aba_s: float
) -> tuple[list[float], list[float]]:
    """The median and p99 update time over each window of ``per_window`` ticks, each as a
    ratio to the window's own ``pin.aba`` median (the whole run if shorter than a window)."""
    med, p99 = [], []
    for i in range(0, wall.size - per_window + 1, per_window):
        w = slice(i, i + per_window)
        ref = float(np.median(warm[w]))
        med.append(float(np.median(wall[w])) / ref)
        p99.append(float(np.percentile(wall[w], 99.0)) / ref)
    if not med:  # shorter than one window: the whole run
        med, p99 = [float(np.median(wall)) / aba_s], [float(np.percentile(wall, 99.0)) / aba_s]
    return med, p99


def live_loop(
    robot_name: str,
    observer_name: str,
    *,
    duration: float = 10.0,
    rate: float = 1000.0,
    seed: int = 0,
    blas_limit: bool = True,
    options: dict[str, Any] | None = None,
    freeze_gc: bool = True,
) -> LiveTiming:
    """Run ``observer_name`` on ``robot_name`` in a loop paced at ``rate`` [Hz] for
    ``duration`` [s] of ticks (module docstring) and time every update.

    The samples come from :func:`pinobs.simulate` (default input, σ = :data:`NOISE_STD`,
    ``seed``), computed before the loop starts; the observer is built by
    :func:`pinobs.make_observer` with ``rate`` and ``noise_std`` and reset at the first
    sample.  A tick whose update ends after the next one is due starts the next at once
    (the loop catches up, as a control loop would).  ``blas_limit=False`` calls the
    update without its one-BLAS-thread limit (:mod:`pinobs.observers.blas`), for comparison.
    ``options``: the observer's options beyond ``rate`` and ``noise_std`` (default
    :data:`LIVE_OPTIONS` for its family: ``adaptive`` learns in its worker process).
    ``freeze_gc``: ``gc.collect()`` then ``gc.freeze()`` once the observer is reset, so that
    no collection walks the set-up's objects during the loop (module docstring); unfrozen
    after it.
    """
    robot = load(robot_name)
    sim = simulate(
        robot, [], duration=duration, sensor=Sensor(rate=rate, noise_std=NOISE_STD), seed=seed
    )
    opts = LIVE_OPTIONS.get(observer_name, {}) if options is None else options
    observer = make_observer(observer_name, robot, rate=rate, noise_std=NOISE_STD, **opts)
    observer.uses_blas = observer.uses_blas and blas_limit  # False: the caller's BLAS threads
    aba = aba_call(robot, seed=seed)
    settings = blas_settings()
    observer.reset(sim.t[0], sim.q[0], None, sim.tau[0])
    n = sim.t.size - 1
    wall, cpu, cold, warm = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    period = 1.0 / rate
    if freeze_gc:
        gc.collect()
        gc.freeze()
    try:
        _paced(observer, type(observer).update, aba, sim, rate, wall, cpu, cold, warm)
    finally:
        if freeze_gc:
            gc.unfreeze()
    aba_s = float(np.median(warm))
    med, p99 = _window_ratios(wall, warm, max(1, round(WINDOW * rate)), aba_s)
    load1, load5, load15 = os.getloadavg()
    return LiveTiming(
        robot=robot_name,
        observer=observer_name,
        options=dict(opts),
        rate=float(rate),
        duration=float(duration),
        updates=n,
        update_us=Quantiles.of(wall).scaled(1e6),
        cpu_us=Quantiles.of(cpu).scaled(1e6),
        aba_us=aba_s * 1e6,
        aba_cold_us=float(np.median(cold)) * 1e6,
        ratio=Quantiles.of(wall).scaled(1.0 / aba_s),
        mean_ratio=float(np.mean(wall)) / aba_s,
        spread={"median": (min(med), max(med)), "p99": (min(p99), max(p99))},
        misses=int(np.sum(wall > period)),
        first_us=float(wall[0]) * 1e6,
        blas=settings,
        blas_after=blas_settings(),
        blas_limit=observer.uses_blas,
        load=(load1, load5, load15),
        cpus=os.cpu_count() or 1,
        freeze_gc=freeze_gc,
    )


def _paced(
    observer: Any,
    update: Any,
    aba: Any,
    sim: Any,
    rate: float,
    wall: np.ndarray,
    cpu: np.ndarray,
    cold: np.ndarray,
    warm: np.ndarray,
) -> None:
    """:func:`live_loop`'s ticks: the times written into ``wall``, ``cpu``, ``cold``, ``warm``."""
    period = 1.0 / rate
    clock, cpu_clock = time.perf_counter, time.thread_time
    start = clock()
    for k in range(wall.size):
        due = start + (k + 1) * period
        while (now := clock()) < due:  # sleep, then spin the last SPIN seconds
            if due - now > SPIN:
                time.sleep(due - now - SPIN)
        t, q, tau = sim.t[k + 1], sim.q_meas[k + 1], sim.tau[k + 1]  # (the sample: not timed)
        t0 = clock()
        aba()
        t1 = clock()
        c1 = cpu_clock()
        update(observer, t, q, tau)
        c2 = cpu_clock()
        t2 = clock()
        for _ in range(ABA_BURST):
            aba()
        t3 = clock()
        cold[k], wall[k], cpu[k], warm[k] = t1 - t0, t2 - t1, c2 - c1, (t3 - t2) / ABA_BURST


def live_table(rows: list[LiveTiming]) -> Any:
    """A rich table of :func:`live_loop` results: ratios to the median warm ``pin.aba`` call
    (the min–max of the median over :data:`WINDOW`-second windows in brackets), the median
    in microseconds, deadline misses."""
    from rich import box
    from rich.table import Table

    table = Table(
        title="per update, × one warm pin.aba call timed in the same ticks", box=box.SIMPLE_HEAD
    )
    table.add_column("robot observer", no_wrap=True)
    for col in ("median ×", "mean ×", "p99 ×", "p99.9 ×", "max ×", "median µs", "misses"):
        table.add_column(col, justify="right", no_wrap=True)
    for r in rows:
        m_lo, m_hi = r.spread["median"]
        table.add_row(
            f"{r.robot} {r.observer}",
            f"{r.ratio.median:.0f} ({m_lo:.0f}–{m_hi:.0f})",
            f"{r.mean_ratio:.0f}",
            f"{r.ratio.p99:.0f}",
            f"{r.ratio.p999:.0f}",
            f"{r.ratio.max:.0f}",
            f"{r.update_us.median:.0f}",
            f"{r.misses}",
        )
    return table


#: What ``pinobs bench --live`` runs: ``(robot, observer)``.
LIVE_RUNS = (("ur5", "kf"), ("ur5", "ekf"), ("ur5", "riemannian"), ("ur5", "adaptive"))


def print_live(*, quick: bool = False, json_path: str | None = None) -> int:
    """``pinobs bench --live``: :data:`LIVE_RUNS` for 10 s each (1 s with ``quick``), printed
    as :func:`live_table` with the BLAS settings and the machine's load; returns 0."""
    import json
    from pathlib import Path

    from rich.console import Console

    duration = 1.0 if quick else 10.0
    console = Console()
    console.print(
        f"pinobs bench --live: each observer paced at 1 kHz for {duration:g} s, "
        f"σ = {NOISE_STD:g}; BLAS as this process has it"
    )
    rows = []
    for robot, observer in LIVE_RUNS:
        rows.append(live_loop(robot, observer, duration=duration))
        console.print(f"  {robot} {observer}: done", highlight=False)
    console.print(live_table(rows))
    load = rows[-1].load
    abas = ", ".join(f"{r.robot} {r.observer} {r.aba_us:.2f} ({r.aba_cold_us:.1f})" for r in rows)
    console.print(
        f"{rows[0].updates} updates each; misses: updates longer than the period.\n"
        f"× is over the median warm pin.aba call (a burst of {ABA_BURST} after each update, "
        "the reference of measure_cost); pin.aba µs warm (cold: one call just before each "
        f"update): {abas}\nBLAS: {rows[0].blas}\nload average {load[0]:.1f} / {load[1]:.1f} / "
        f"{load[2]:.1f} on {rows[0].cpus} cores",
        highlight=False,
    )
    if json_path is not None:
        path = Path(json_path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps([r.as_dict() for r in rows], indent=2) + "\n")
        console.print(f"wrote {path}")
    return 0

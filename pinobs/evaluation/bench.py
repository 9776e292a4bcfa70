"""The benchmark behind ``pinobs bench``: accuracy, cost, scaling.

For every registered observer and a set of robots, on the *same* sampled
trajectories (PD tracking of a multi-sine reference, 1 kHz; Gaussian noise
σ = 1e-4 rad, and a 16-bit quantized-encoder variant), it reports the
velocity RMS error after the transient, the convergence time from a perturbed
start, and the cost of one update as a multiple of one ``pin.aba`` call,
measured in the same run by :func:`~pinobs.evaluation.measure_cost` (the
observer alone, updates and ``pin.aba`` calls timed in alternating chunks; the
time inside the shared simulation loop, where two dozen observers evict each
other's data from the caches, is kept in the JSON as ``time_in_loop``).  Baselines users run today sit in the same table:

* ``diff``: the plain backward difference (``fd`` with the filter off);
* ``fd*``: backward difference + the best first-order low-pass (cut-off
  chosen on the run itself from a grid: an optimistic baseline);
* ``kf*``: the per-joint constant-acceleration Kalman filter with the best
  jerk density from a grid (also optimistic);
* ``ekf``: the extended Kalman filter with the exact model, when registered.

Every other observer runs with the gains it picks from ``rate`` and
``noise_std`` alone: nothing is tuned per robot.  Robots marked
``cost_only`` (the humanoid) are timed, not simulated for accuracy.

The scaling study times one update against ``nv`` and fits
``time ∝ nv^p`` by least squares on the log-log points.

The mismatch study (:data:`pinobs.simulation.MISMATCH_SCENARIOS`) runs the
truth on a perturbed copy of the robot while every observer keeps the nominal
model, and reports the velocity RMS error and the bias (RMS over joints of
the time-mean error after the transient).  It adds the mitigation rows
``ekf+d`` (the EKF with a joint-torque offset state, ``disturbance_psd`` = 1)
and ``ekf~`` (the EKF with raised process noise, ``accel_psd`` = 1e-2).
"""

from __future__ import annotations

import math
import platform
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from pinobs.errors import OptionError, PinobsError, UnsupportedRobotError
from pinobs.evaluation.metrics import Metrics, evaluate
from pinobs.evaluation.timing import measure_cost
from pinobs.model import Robot, aba_time, load, pinocchio_version
from pinobs.observers import Observer, make_observer, observer_names
from pinobs.simulation import MISMATCH_SCENARIOS, Result, Sensor, mismatched_plant, simulate

__all__ = [
    "BenchConfig",
    "BenchRow",
    "BenchTask",
    "bench_tasks",
    "format_bench",
    "run_bench",
    "run_bench_task",
    "scaling_exponent",
    "time_geometry",
]

FD_CUTOFFS = (2.0, 5.0, 10.0, 20.0, 40.0, 80.0, 160.0)  # [Hz]
KF_JERKS = (1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3, 1e4, 1e5)  # [rad²/s⁵]
_NO_FILTER = 1e12  # [Hz] a cut-off that makes the low-pass the identity at any sample rate


@dataclass(frozen=True)
class BenchConfig:
    """What a benchmark run covers.

    Attributes:
        robots: robots simulated for accuracy.
        cost_robots: robots only timed (scaling study and cost rows).
        duration: simulated time per run [s].
        rate: sample rate [Hz].
        noise_std: Gaussian position noise [rad].
        bits: encoder resolution of the quantized variant [bits/turn].
        perturb_q, perturb_v: initial estimation error [rad], [rad/s].
        seed: seed of every run.
        timing_updates: updates timed per observer and robot in the scaling study.
    """

    robots: tuple[str, ...] = ("cartpole", "ur5", "panda", "go1")
    mismatch_robots: tuple[str, ...] = ("ur5", "panda")
    cost_robots: tuple[str, ...] = ("pendulum", "planar_3r", "talos")
    duration: float = 4.0
    rate: float = 1000.0
    noise_std: float = 1e-4
    bits: int = 16
    perturb_q: float = 0.05
    perturb_v: float = 0.5
    seed: int = 0
    timing_updates: int = 800

    @classmethod
    def quick(cls) -> BenchConfig:
        """Under two minutes: two robots, short runs, a small scaling set."""
        return cls(
            robots=("cartpole", "ur5"),
            mismatch_robots=("ur5",),
            cost_robots=("panda",),
            duration=1.5,
            timing_updates=100,
        )


@dataclass(frozen=True)
class BenchRow:
    """One observer on one robot and sensor variant."""

    robot: str
    nv: int
    sensor: str
    observer: str
    rms_v_error: float
    convergence_time: float
    time_per_update: float
    cost_in_aba: float
    time_in_loop: float = math.nan
    options: dict[str, Any] = field(default_factory=dict)
    note: str = ""


def _sensors(cfg: BenchConfig) -> dict[str, tuple[Sensor, float]]:
    """Sensor variants and the noise level told to the observers (quantization: res/√12)."""
    res = 2.0 * math.pi / 2**cfg.bits
    return {
        f"gauss {cfg.noise_std:g}": (Sensor(cfg.rate, cfg.noise_std), cfg.noise_std),
        f"{cfg.bits}-bit": (Sensor(cfg.rate, 0.0, bits=cfg.bits), res / math.sqrt(12.0)),
    }


def _candidates(
    robot: Robot, rate: float, noise: float
) -> tuple[dict[str, Observer[Any]], dict[str, str]]:
    """Every registered observer with default gains, plus the baseline grids."""
    obs: dict[str, Observer[Any]] = {}
    skipped: dict[str, str] = {}
    for name in observer_names():
        try:
            obs[name] = make_observer(name, robot, rate=rate, noise_std=noise)
        except UnsupportedRobotError as exc:
            skipped[name] = str(exc).split(";")[0]
    obs["diff"] = make_observer("fd", robot, cutoff=_NO_FILTER, rate=rate, noise_std=noise)
    for fc in FD_CUTOFFS:
        obs[f"fd@{fc:g}"] = make_observer("fd", robot, cutoff=fc, rate=rate, noise_std=noise)
    for j in KF_JERKS:
        obs[f"kf@{j:g}"] = make_observer("kf", robot, jerk_psd=j, rate=rate, noise_std=noise)
    return obs, skipped


def _simulate(
    cfg: BenchConfig,
    robot: Robot,
    obs: dict[str, Observer[Any]],
    sensor: Sensor,
    plant: Robot | None = None,
) -> Result:
    """One benchmark run: PD tracking, the configured start error and seed."""
    return simulate(
        robot,
        obs,
        duration=cfg.duration,
        sensor=sensor,
        inputs="pd",
        perturb_q=cfg.perturb_q,
        perturb_v=cfg.perturb_v,
        seed=cfg.seed,
        plant=plant,
    )


def _best(metrics: dict[str, Metrics], prefix: str) -> tuple[str, Metrics]:
    grid = {k: m for k, m in metrics.items() if k.startswith(prefix + "@")}
    key = min(grid, key=lambda k: grid[k].rms_v_error)
    return key, grid[key]


@dataclass(frozen=True)
class BenchTask:
    """One independent piece of the benchmark: ``kind`` is ``"scaling"`` (time every
    observer on ``robot``), ``"accuracy"`` (one simulation with sensor ``variant``),
    ``"mismatch"`` (one simulation against scenario ``variant``) or ``"geometry"``."""

    kind: str
    robot: str
    variant: str
    cfg: BenchConfig


def bench_tasks(cfg: BenchConfig) -> list[BenchTask]:
    """Every task of :func:`run_bench`, in the order the serial run does them."""
    by_nv = sorted({*cfg.robots, *cfg.cost_robots}, key=lambda n: load(n).nv)
    return [
        *(BenchTask("scaling", r, "", cfg) for r in by_nv),
        *(BenchTask("accuracy", r, s, cfg) for r in cfg.robots for s in _sensors(cfg)),
        *(
            BenchTask("mismatch", r, s, cfg)
            for r in cfg.mismatch_robots
            for s in MISMATCH_SCENARIOS
        ),
        *(
            BenchTask("geometry", r, "", cfg)
            for r in dict.fromkeys((*cfg.robots, *cfg.cost_robots))
        ),
    ]


def run_bench_task(task: BenchTask) -> tuple[Any, str]:
    """One :class:`BenchTask`: its result and a line for the log."""
    cfg = task.cfg
    if task.kind == "scaling":
        return _scaling_points(cfg, task.robot)
    if task.kind == "accuracy":
        return _accuracy(cfg, task.robot, task.variant)
    if task.kind == "mismatch":
        return _mismatch(cfg, task.robot, task.variant)
    if task.kind == "geometry":
        return time_geometry((task.robot,))[0], f"  geometry calls timed on {task.robot}"
    raise OptionError(
        f"bench task kind {task.kind!r}: give scaling, accuracy, mismatch or geometry"
    )


def run_bench(
    cfg: BenchConfig,
    *,
    log: Callable[[str], None] = print,
    scheduler: str | None = None,
    workers: int | None = 0,
    processes: bool = True,
) -> dict[str, Any]:
    """Run the benchmark; returns a JSON-ready dict (rows, geometry costs, scaling, machine).

    The independent runs (:func:`bench_tasks`) go through
    :func:`pinobs.evaluation.distributed.run_tasks`: ``workers=0`` (default)
    one after the other in this process, else on a local Dask cluster of
    ``workers`` processes or the cluster at ``scheduler``.  The accuracy and
    mismatch numbers do not depend on where they ran (seeded runs); the costs
    are ratios to ``pin.aba`` in the same worker, but workers sharing cores
    load each other.

    A task that raises fails alone: the report lists it under ``failed`` (kind,
    robot, variant, error; logged as it fails) and holds the other tasks' results
    (its rows, scaling points or geometry costs are missing; a cost it would have
    timed is NaN).
    """
    from pinobs.evaluation.distributed import run_tasks

    def done(o: Any) -> None:
        t = o.task
        log(
            o.value[1]
            if o.error is None
            else f"  failed: {_what(t.kind, t.robot, t.variant)}: {o.error}"
        )

    started = time.perf_counter()
    outcomes = run_tasks(
        run_bench_task,
        bench_tasks(cfg),
        scheduler=scheduler,
        workers=workers,
        processes=processes,
        on_result=done,
    )
    failed = [
        {"kind": o.task.kind, "robot": o.task.robot, "variant": o.task.variant, "error": o.error}
        for o in outcomes
        if o.error is not None
    ]
    parts: dict[str, list[Any]] = {"scaling": [], "accuracy": [], "mismatch": [], "geometry": []}
    for o in outcomes:
        if o.error is None:
            parts[o.task.kind].append(o.value[0])
    scaling, cost = _scaling(parts["scaling"])
    rows, skipped_all = _costed_rows(parts["accuracy"], cost)
    return {
        "config": asdict(cfg),
        "machine": _machine(),
        "seconds": time.perf_counter() - started,
        "rows": [asdict(r) for r in rows],
        "skipped": skipped_all,
        "scaling": scaling,
        "geometry": parts["geometry"],
        "mismatch": [r for found in parts["mismatch"] for r in found],
        "failed": failed,
    }


def _scaling(
    found_points: list[Any],
) -> tuple[dict[str, Any], dict[tuple[str, str], tuple[float, float]]]:
    """The scaling tasks' points gathered per observer (the report's ``scaling``, with each
    observer's exponent) and each ``(observer, robot)``'s cost: seconds per update and
    ratio to ``pin.aba``."""
    points: dict[str, list[tuple[str, int, float, float]]] = {}
    for found in found_points:
        for name, point in found.items():
            points.setdefault(name, []).append(point)
    scaling = {
        name: {
            "points": [{"robot": b, "nv": n, "seconds": t, "cost_in_aba": r} for b, n, t, r in pts],
            "exponent": scaling_exponent([p[1] for p in pts], [p[2] for p in pts]),
        }
        for name, pts in points.items()
    }
    cost = {(name, p[0]): (p[2], p[3]) for name, pts in points.items() for p in pts}
    return scaling, cost


def _costed_rows(
    accuracy: list[Any], cost: dict[tuple[str, str], tuple[float, float]]
) -> tuple[list[BenchRow], dict[str, dict[str, str]]]:
    """The accuracy tasks' rows, each with the cost of the observer it is timed as (``fd*``
    and ``diff`` as ``fd``, ``kf*`` as ``kf``; NaN when not timed), and the observers each
    robot skipped."""
    rows: list[BenchRow] = []
    skipped_all: dict[str, dict[str, str]] = {}
    for found, skipped in accuracy:
        for row in found:
            timed = {"fd*": "fd", "kf*": "kf", "diff": "fd"}.get(row.observer, row.observer)
            seconds, ratio = cost.get((timed, row.robot), (math.nan, math.nan))
            rows.append(replace(row, time_per_update=seconds, cost_in_aba=ratio))
            skipped_all[row.robot] = skipped
    return rows, skipped_all


def _accuracy(
    cfg: BenchConfig, robot_name: str, label: str
) -> tuple[tuple[list[BenchRow], dict[str, str]], str]:
    """Every observer and baseline on one robot and sensor variant (costs filled in later)."""
    robot = load(robot_name)
    sensor, noise = _sensors(cfg)[label]
    obs, skipped = _candidates(robot, cfg.rate, noise)
    t0 = time.perf_counter()
    result = _simulate(cfg, robot, obs, sensor)
    metrics = {m.observer: m for m in evaluate(result, robot)}
    message = (
        f"  {robot_name:10s} {label:12s} {len(obs)} observers in {time.perf_counter() - t0:.1f} s"
    )
    fd_key, fd_best = _best(metrics, "fd")
    kf_key, kf_best = _best(metrics, "kf")
    picked = {
        **{n: (metrics[n], "") for n in obs if "@" not in n and n not in ("fd", "kf")},
        "fd*": (fd_best, f"best cut-off {fd_key.split('@')[1]} Hz"),
        "kf*": (kf_best, f"best jerk_psd {kf_key.split('@')[1]}"),
        "fd": (metrics["fd"], "default cut-off rule"),
        "kf": (metrics["kf"], "default jerk_psd"),
    }
    rows = []
    for name, (m, note) in picked.items():
        options = result.trace(m.observer).options
        rows.append(
            BenchRow(
                robot=robot_name,
                nv=robot.nv,
                sensor=label,
                observer=name,
                rms_v_error=m.rms_v_error,
                convergence_time=m.convergence_time,
                time_per_update=math.nan,
                cost_in_aba=math.nan,
                time_in_loop=m.time_per_update,
                options={
                    k: v
                    for k, v in options.items()
                    if isinstance(v, int | float | str | bool | None)
                },
                note=note if m.diverged_at is None else f"diverged at {m.diverged_at:.3g} s",
            )
        )
    return (rows, skipped), message


def _mismatch(cfg: BenchConfig, robot_name: str, scenario: str) -> tuple[list[dict[str, Any]], str]:
    """Every observer (nominal model) against one perturbed truth (module docstring)."""
    sensor = Sensor(cfg.rate, cfg.noise_std)
    robot = load(robot_name)
    obs, _ = _candidates(robot, cfg.rate, cfg.noise_std)
    obs["ekf+d"] = make_observer(
        "ekf", robot, rate=cfg.rate, noise_std=cfg.noise_std, disturbance_psd=1.0
    )
    obs["ekf~"] = make_observer(
        "ekf", robot, rate=cfg.rate, noise_std=cfg.noise_std, accel_psd=1e-2
    )
    t0 = time.perf_counter()
    result = _simulate(cfg, robot, obs, sensor, mismatched_plant(robot, scenario, seed=cfg.seed))
    metrics = {m.observer: m for m in evaluate(result, robot)}
    after = result.t >= result.t[0] + 0.25 * (result.t[-1] - result.t[0])
    fd_key, _ = _best(metrics, "fd")
    kf_key, _ = _best(metrics, "kf")
    names = {n: n for n in obs if "@" not in n}
    names.update({"fd*": fd_key, "kf*": kf_key})
    out: list[dict[str, Any]] = []
    for label, key in names.items():
        err = result.trace(key).v[after] - result.v[after]
        finite = bool(np.all(np.isfinite(err)))
        bias = float(np.sqrt(np.mean(np.mean(err, axis=0) ** 2))) if finite else math.inf
        out.append(
            {
                "robot": robot_name,
                "scenario": scenario,
                "observer": label,
                "rms_v_error": metrics[key].rms_v_error,
                "bias": bias,
            }
        )
    return out, f"  mismatch {robot_name:6s} {scenario:18s} in {time.perf_counter() - t0:.1f} s"


def _machine() -> dict[str, str]:
    return {
        "python": platform.python_version(),
        "pinocchio": pinocchio_version(),
        "numpy": np.__version__,
        "processor": platform.processor() or platform.machine(),
        "system": platform.platform(),
        "date": time.strftime("%Y-%m-%d"),
    }


def _scaling_points(
    cfg: BenchConfig, robot_name: str
) -> tuple[dict[str, tuple[str, int, float, float]], str]:
    """Every observer's cost on one robot: name -> (robot, nv, seconds, x aba)."""
    robot = load(robot_name)
    points: dict[str, tuple[str, int, float, float]] = {}
    for name in observer_names():
        try:
            ob = make_observer(name, robot, rate=cfg.rate, noise_std=cfg.noise_std)
            cost = measure_cost(
                ob, samples=cfg.timing_updates, rounds=4, rate=cfg.rate, seed=cfg.seed
            )
        except (UnsupportedRobotError, PinobsError):
            continue
        points[name] = (robot_name, robot.nv, cost["update_s"], cost["ratio"])
    return points, f"  timed {robot_name} (nv = {robot.nv})"


def scaling_exponent(nv: Sequence[int], seconds: Sequence[float]) -> float:
    """Least-squares slope of ``log(seconds)`` against ``log(nv)`` (NaN with fewer than 3 points)."""
    if len(nv) < 3:
        return math.nan
    slope, _ = np.polyfit(
        np.log(np.asarray(nv, dtype=float)), np.log(np.asarray(seconds, dtype=float)), 1
    )
    return float(slope)


def time_geometry(
    robots: Sequence[str], *, repeats: int = 300, seed: int = 0
) -> list[dict[str, Any]]:
    """Cost of the model layer's geometry calls, as multiples of one ``pin.aba`` call."""
    rng = np.random.default_rng(seed)
    out = []
    for name in robots:
        robot = load(name)
        aba = aba_time(robot)
        q = robot.random_configuration(rng)
        x, y, z = rng.standard_normal((3, robot.nv))
        calls: dict[str, tuple[Callable[..., object], tuple[Any, ...]]] = {
            "christoffel": (robot.christoffel, (q, x, y)),
            "connection": (robot.connection, (q, x, y)),
            "curvature": (robot.curvature, (q, x, y, z)),
        }
        row: dict[str, Any] = {"robot": name, "nv": robot.nv, "aba_seconds": aba}
        for key, (fn, fn_args) in calls.items():
            samples = []
            for _ in range(5):
                start = time.perf_counter()
                for _ in range(repeats):
                    fn(*fn_args)
                samples.append((time.perf_counter() - start) / repeats)
            row[key] = float(np.median(samples)) / aba
        out.append(row)
    return out


def format_bench(report: dict[str, Any]) -> str:
    """Markdown tables of a :func:`run_bench` report."""
    lines = []
    rows = report["rows"]
    for robot, sensor in dict.fromkeys((r["robot"], r["sensor"]) for r in rows):
        sel = sorted(
            (r for r in rows if r["robot"] == robot and r["sensor"] == sensor),
            key=lambda r: r["rms_v_error"],
        )
        nv = sel[0]["nv"]
        lines += [
            f"\n**{robot}** (nv = {nv}), {sensor}",
            "",
            "| observer | rms v err [rad/s] | t_conv [s] | update [us] | x aba | note |",
            "|---|---:|---:|---:|---:|---|",
        ]
        for r in sel:
            lines.append(
                f"| `{r['observer']}` | {r['rms_v_error']:.3g} | {r['convergence_time']:.3g} | "
                f"{r['time_per_update'] * 1e6:.1f} | {r['cost_in_aba']:.1f} | {r['note']} |"
            )
    lines += _format_mismatch(report.get("mismatch", []))
    lines += [
        "",
        "**Cost scaling** (`pinobs.evaluation.measure_cost`: chunks of 20 updates, each followed by"
        " 20 `pin.aba` calls; median ratio over the chunks; fitted `time ∝ nv^p`)",
        "",
    ]
    sc = report["scaling"]
    nvs = sorted({p["nv"] for s in sc.values() for p in s["points"]})
    lines.append("| observer | " + " | ".join(f"nv={n} [x aba]" for n in nvs) + " | p |")
    lines.append("|---|" + "---:|" * (len(nvs) + 1))
    for name, s in sorted(sc.items()):
        by = {p["nv"]: p["cost_in_aba"] for p in s["points"]}
        cells = [f"{by[n]:.1f}" if n in by else "-" for n in nvs]
        lines.append(f"| `{name}` | " + " | ".join(cells) + f" | {s['exponent']:.2f} |")
    lines += ["", "**Geometry calls** (multiples of one `pin.aba` call on the same robot)", ""]
    lines.append("| robot | nv | christoffel | connection | curvature |")
    lines.append("|---|---:|---:|---:|---:|")
    for g in report["geometry"]:
        lines.append(
            f"| {g['robot']} | {g['nv']} | {g['christoffel']:.1f} | {g['connection']:.1f} | {g['curvature']:.1f} |"
        )
    if report.get("failed"):
        lines += ["", "**Failed tasks** (their rows are missing above)", ""]
        lines += [
            f"- {_what(f['kind'], f['robot'], f['variant'])}: {f['error']}"
            for f in report["failed"]
        ]
    return "\n".join(lines)


def _what(kind: str, robot: str, variant: str) -> str:
    """A bench task in words: ``mismatch on ur5 friction``, ``geometry on ur5``."""
    return f"{kind} on {robot}" + (f" {variant}" if variant else "")


def _format_mismatch(rows: list[dict[str, Any]]) -> list[str]:
    """Markdown: per robot, observers × scenarios, ``rms (bias)`` in rad/s."""
    if not rows:
        return []
    lines: list[str] = []
    scenarios = list(dict.fromkeys(r["scenario"] for r in rows))
    for robot in dict.fromkeys(r["robot"] for r in rows):
        sel = [r for r in rows if r["robot"] == robot]
        cell = {(r["observer"], r["scenario"]): r for r in sel}
        ran = [s for s in scenarios if any(k[1] == s for k in cell)]  # not a failed task's
        order = sorted(
            dict.fromkeys(r["observer"] for r in sel),
            key=lambda o: cell.get((o, ran[0]), {"rms_v_error": math.inf})["rms_v_error"],
        )
        lines += [
            "",
            f"**Model mismatch, {robot}**: velocity RMS error (bias) [rad/s]; observers keep the nominal model",
            "",
            "| observer | " + " | ".join(scenarios) + " |",
            "|---|" + "---:|" * len(scenarios),
        ]
        for o in order:
            cells = [
                f"{cell[(o, s)]['rms_v_error']:.2g} ({cell[(o, s)]['bias']:.1g})"
                if (o, s) in cell
                else "-"
                for s in scenarios
            ]
            lines.append(f"| `{o}` | " + " | ".join(cells) + " |")
    return lines

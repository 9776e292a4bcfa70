"""Drive observers sample by sample against a simulated plant.

The plant is integrated on its configuration manifold with RKMK4
(:func:`pinobs.model.dynamics_rk4`) at ``substeps`` steps per sample, the torque
held over each sample interval (MATH §7).  Accuracy, measured in
``tests/simulation``: order 4 on every joint group; on a UR5 at 1 kHz
(one step per sample) the energy of a free motion at 1 rad/s per joint
drifts by 9.6e-8 J out of 33.4 J (3e-9 relative) over 2 s.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from pinobs.errors import DimensionError, GainError, ObserverDiverged, OptionError, PinobsError
from pinobs.model import Robot, dynamics_rk4
from pinobs.model.integrators import friction_substeps
from pinobs.model.robot import Vector
from pinobs.observers import Observer, make_observer
from pinobs.observers.base import positive
from pinobs.simulation.inputs import InputProfile, make_input
from pinobs.simulation.result import ObserverTrace, Result
from pinobs.simulation.sensors import Sensor, is_integer

__all__ = ["default_input", "perturb", "simulate"]

Progress = Callable[[int, int], None]


def default_input(robot: Robot) -> str:
    """``pd``: tracking a multi-sine reference keeps every robot's motion realistic.

    (On floating bases the base is then actuated too, like a body with
    thrusters: raw multi-sine torques on a quadruped reach 150 rad/s within 2 s.)
    """
    return "pd"


def perturb(
    robot: Robot, q: Vector, v: Vector, dq: float, dv: float, rng: np.random.Generator
) -> tuple[Vector, Vector]:
    """``(q ⊕ dq·u₁, v + dv·u₂)`` with ``u₁, u₂`` random unit vectors (norms ``dq`` [rad], ``dv`` [rad/s])."""
    u1 = rng.standard_normal(robot.nv)
    u2 = rng.standard_normal(robot.nv)
    u1 /= np.linalg.norm(u1)
    u2 /= np.linalg.norm(u2)
    return robot.integrate(q, dq * u1), v + dv * u2


def _plant_step(
    plant: Robot, q: Vector, v: Vector, tau: Vector, h: float, n: int
) -> tuple[Vector, Vector]:
    """``n`` RK4 steps over ``h``, each split further where joint friction is stiff
    (:func:`~pinobs.model.integrators.friction_substeps`, as the EKF's prediction): fixed steps
    are unstable on the smoothed Coulomb slope, and a double pendulum with 3 N·m of it
    chattered to |v| = 3.57 rad/s where it moves at 0.07 (silently: the observers were then
    scored against a non-physical truth)."""
    for _ in range(n):
        m = 1
        if plant.has_friction:
            acc = plant.forward_dynamics(q, v, tau)
            minv = np.diag(np.linalg.inv(plant.mass_matrix(q)))
            m = friction_substeps(plant, v, acc, minv, h / n)
        for _ in range(m):
            q, v = dynamics_rk4(plant, q, v, tau, h / (n * m))
    return q, v


def _portable_source(source: Any) -> Any:
    """A robot file's path made absolute (a saved result is played from anywhere); a
    registry name as it is."""
    if isinstance(source, str) and Path(source).is_file():
        return str(Path(source).resolve())
    return source


def _check_run(
    robot: Robot,
    observers: Any,
    duration: float,
    sensor: Sensor,
    perturb_q: float,
    perturb_v: float,
    seed: int,
    substeps: int,
    plant: Robot | None,
) -> None:
    """:func:`simulate`'s arguments, refused before any work (its ``Raises``)."""
    positive("duration", duration)
    if duration * sensor.rate < 1.0:
        raise GainError(
            f"duration={duration!r} s is shorter than one sample period at {sensor.rate:g} Hz; "
            f"give a duration >= {sensor.period:g} s"
        )
    positive("perturb_q", perturb_q, allow_zero=True)
    positive("perturb_v", perturb_v, allow_zero=True)
    if not is_integer(seed) or seed < 0:
        raise GainError(f"seed={seed!r}: give an integer >= 0")
    if not is_integer(substeps) or substeps < 1:
        raise GainError(f"substeps={substeps!r}: give an integer >= 1 (plant steps per sample)")
    if isinstance(observers, str | bytes):
        raise OptionError(
            f"observers={observers!r}: give a list of names ([{observers!r}]) or a mapping "
            "label -> observer"
        )
    if isinstance(observers, Mapping):
        wrong = {k: type(v).__name__ for k, v in observers.items() if not isinstance(v, Observer)}
        if wrong:
            raise OptionError(
                f"observers: {wrong} are not observers; a mapping gives label -> observer "
                "(pinobs.make_observer(name, robot)); give names as a list"
            )
    if plant is not None and (plant.nq, plant.nv) != (robot.nq, robot.nv):
        raise DimensionError(
            f"plant {plant.name!r} has nq = {plant.nq}, nv = {plant.nv}; the observers' robot "
            f"{robot.name!r} has nq = {robot.nq}, nv = {robot.nv}: give a plant of the same robot"
        )


# The observers' matrices are small (2nv ≤ 256): BLAS threads only contend (an ekf at
# nv = 64 on a busy 2-core machine: 3.3 ms per 128×128 product with two threads,
# 0.47 ms with one).  Set for the duration of the call (3 µs).
@threadpool_limits.wrap(limits=1, user_api="blas")
def simulate(
    robot: Robot,
    observers: Sequence[str] | Mapping[str, Observer[Any]],
    *,
    duration: float = 5.0,
    sensor: Sensor | None = None,
    inputs: str | InputProfile | None = None,
    q0: Vector | None = None,
    v0: Vector | None = None,
    perturb_q: float = 0.0,
    perturb_v: float = 0.0,
    seed: int = 0,
    substeps: int = 1,
    plant: Robot | None = None,
    progress: Progress | None = None,
) -> Result:
    """Simulate ``robot`` and run every observer on its sampled, noisy positions.

    Args:
        robot: the model the observers use (each builds its own copy).
        observers: registry names (built with the sensor's ``rate`` and
            :attr:`Sensor.effective_std` as hints: noise and quantization) or a mapping
            label -> observer instance.
        duration: simulated time [s].
        sensor: sample rate, noise, quantization, delay, dropouts (default: 1 kHz, no noise).
        inputs: ``"zero"``, ``"multisine"``, ``"pd"``, an :class:`InputProfile`,
            or ``None`` (:func:`default_input`).
        q0: true initial configuration (default: a seeded configuration near
            the neutral one).
        v0: true initial velocity (default: zero).
        perturb_q: norm of the initial estimation error in configuration [rad]
            (same draw for every observer).
        perturb_v: norm of the initial estimation error in velocity [rad/s]
            (same draw for every observer).
        seed: seed of every random draw of the run.
        substeps: plant integration steps per sample.
        plant: the truth's model if it differs from ``robot`` (model mismatch).
        progress: called as ``progress(k, n)`` after sample ``k`` of ``n``.

    An observer that fails (diverges, a singular matrix, a rejected input)
    stops there: its trace is NaN from then on, ``diverged_at`` is set and the
    reason is in ``meta["failures"]``; the other observers run on.

    Raises:
        GainError: ``duration`` not finite or shorter than one sample period,
            ``perturb_q``/``perturb_v`` not finite >= 0, ``seed`` not an integer
            >= 0, ``substeps`` not an integer >= 1.
        OptionError: ``observers`` a single string, or a mapping to something
            other than observers.
        DimensionError: a ``plant`` with another ``nq``/``nv`` than ``robot``.
    """
    sensor = sensor or Sensor()
    _check_run(robot, observers, duration, sensor, perturb_q, perturb_v, seed, substeps, plant)
    rng = np.random.default_rng(seed)
    truth = (plant or robot).copy()
    if q0 is None:
        q0 = truth.random_configuration(rng, scale=0.3)
    q0 = truth.check_configuration(q0, what="q0")
    v0 = np.zeros(truth.nv) if v0 is None else truth.check_vector(v0, truth.nv, what="v0")
    if not isinstance(inputs, InputProfile):
        inputs = make_input(inputs or default_input(truth), truth, rng=rng, center=q0)
    obs = _observers(robot, observers, sensor)
    start = perturb(truth, q0, v0, perturb_q, perturb_v, rng)
    rec = _Recording.empty(round(duration * sensor.rate) + 1, sensor.period, truth, obs)
    _run(rec, truth, obs, sensor, inputs, (q0, v0), start, substeps, rng, progress)
    meta = {
        **_robot_meta(robot),
        "duration": duration,
        **_sensor_meta(sensor),
        "input": inputs.name,
        "seed": seed,
        "perturb_q": perturb_q,
        "perturb_v": perturb_v,
        "substeps": substeps,
        "plant": truth.name if plant is not None else None,
        "failures": rec.failures,
    }
    return rec.result(robot.name, obs, meta)


def _observers(
    robot: Robot, observers: Sequence[str] | Mapping[str, Observer[Any]], sensor: Sensor
) -> dict[str, Observer[Any]]:
    """:func:`simulate`'s observers by label: those given, or built by name for the sensor."""
    if isinstance(observers, Mapping):
        return dict(observers)
    return {
        name: make_observer(name, robot, rate=sensor.rate, noise_std=sensor.effective_std)
        for name in observers
    }


def _robot_meta(robot: Robot) -> dict[str, Any]:
    """What a saved run needs to reload its robot (``pinobs play``)."""
    return {
        "robot": robot.name,
        "robot_source": _portable_source(getattr(robot, "source", robot.name)),
        "root_joint": getattr(robot, "root_joint", None),
        "mimic": getattr(robot, "mimic", None),
        "lock": dict(getattr(robot, "locked", {})) or None,  # pinobs play reloads it so
    }


def _sensor_meta(sensor: Sensor) -> dict[str, Any]:
    """The sensor's settings, as a run's ``meta`` keeps them."""
    return {
        "rate": sensor.rate,
        "noise_std": sensor.noise_std,
        "bits": sensor.bits,
        "delay": sensor.delay,
        "dropout": sensor.dropout,
    }


def _run(
    rec: _Recording,
    truth: Robot,
    obs: Mapping[str, Observer[Any]],
    sensor: Sensor,
    inputs: InputProfile,
    state: tuple[Vector, Vector],
    start: tuple[Vector, Vector],
    substeps: int,
    rng: np.random.Generator,
    progress: Progress | None,
) -> None:
    """The sample loop of :func:`simulate`, from the true ``state`` ``(q0, v0)``, the
    observers started at ``start`` ``(q̂0, v̂0)``: recorded into ``rec``."""
    history: deque[Vector] = deque(maxlen=sensor.delay + 1)
    q, v = state
    for k in range(rec.t.size):
        if k > 0:
            q, v = _plant_step(truth, q, v, rec.tau[k - 1], sensor.period, substeps)
        tau = inputs.torque(rec.t[k], q, v)
        rec.q[k], rec.v[k], rec.tau[k] = q, v, tau
        history.append(q)
        meas = sensor.measure(truth, history[0], rng) if k > 0 else None
        if meas is not None:
            rec.q_meas[k] = meas
        for name, ob in obs.items():
            if rec.diverged[name] is None:
                rec.update(name, ob, k, meas, tau, start)
        if progress is not None:
            progress(k + 1, rec.t.size)


@dataclass
class _Recording:
    """What :func:`simulate` records, filled sample by sample: the truth (``q``, ``v``,
    ``tau`` at times ``t`` [s]), the measurements (NaN where none) and each observer's
    estimates, update times [s] (NaN from a failure on), failure time [s] and reason."""

    t: Vector
    q: Vector
    v: Vector
    tau: Vector
    q_meas: Vector
    est_q: dict[str, Vector]
    est_v: dict[str, Vector]
    wall: dict[str, Vector]
    diverged: dict[str, float | None]
    failures: dict[str, str]

    @staticmethod
    def empty(n: int, h: float, truth: Robot, obs: Mapping[str, Observer[Any]]) -> _Recording:
        """A recording of ``n`` samples ``h`` [s] apart, nothing recorded yet."""
        return _Recording(
            t=np.arange(n) * h,
            q=np.empty((n, truth.nq)),
            v=np.empty((n, truth.nv)),
            tau=np.empty((n, truth.nv)),
            q_meas=np.full((n, truth.nq), np.nan),
            est_q={k: np.full((n, truth.nq), np.nan) for k in obs},
            est_v={k: np.full((n, truth.nv), np.nan) for k in obs},
            wall={k: np.full(n, np.nan) for k in obs},
            diverged=dict.fromkeys(obs),
            failures={},
        )

    def update(
        self,
        name: str,
        ob: Observer[Any],
        k: int,
        meas: Vector | None,
        tau: Vector,
        start: tuple[Vector, Vector],
    ) -> None:
        """Observer ``name`` at sample ``k`` (reset at ``start``, ``(q̂0, v̂0)``, at
        ``k = 0``), timed; a failure recorded, not raised."""
        t = self.t
        began = time.perf_counter()
        try:
            if k == 0:
                est = ob.reset(t[0], *start, tau)
            else:
                est = ob.update(t[k], meas, tau)
        except ObserverDiverged as exc:
            self.diverged[name] = exc.t
            self.failures[name] = str(exc)
            return
        except (ArithmeticError, np.linalg.LinAlgError, PinobsError) as exc:
            # one failing observer must not take the others' results with it
            self.diverged[name] = float(t[k])
            self.failures[name] = f"{type(exc).__name__} at t = {t[k]:.6g} s: {exc}"
            return
        self.wall[name][k] = time.perf_counter() - began
        self.est_q[name][k], self.est_v[name][k] = est.q, est.v

    def result(self, robot: str, obs: Mapping[str, Observer[Any]], meta: dict[str, Any]) -> Result:
        """The :class:`Result` of the run."""
        traces = tuple(
            ObserverTrace(
                name=name,
                q=self.est_q[name],
                v=self.est_v[name],
                update_time=self.wall[name],
                options=ob.options,
                diverged_at=self.diverged[name],
            )
            for name, ob in obs.items()
        )
        return Result(
            robot=robot,
            t=self.t,
            q=self.q,
            v=self.v,
            tau=self.tau,
            q_meas=self.q_meas,
            traces=traces,
            meta=meta,
        )

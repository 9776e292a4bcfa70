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
    n = round(duration * sensor.rate) + 1
    h = sensor.period
    if q0 is None:
        q0 = truth.random_configuration(rng, scale=0.3)
    q0 = truth.check_configuration(q0, what="q0")
    v0 = np.zeros(truth.nv) if v0 is None else truth.check_vector(v0, truth.nv, what="v0")
    if not isinstance(inputs, InputProfile):
        inputs = make_input(inputs or default_input(truth), truth, rng=rng, center=q0)
    if isinstance(observers, Mapping):
        obs = dict(observers)
    else:
        obs = {
            name: make_observer(name, robot, rate=sensor.rate, noise_std=sensor.effective_std)
            for name in observers
        }
    q_hat0, v_hat0 = perturb(truth, q0, v0, perturb_q, perturb_v, rng)

    t = np.arange(n) * h
    Q = np.empty((n, truth.nq))
    V = np.empty((n, truth.nv))
    TAU = np.empty((n, truth.nv))
    QM = np.full((n, truth.nq), np.nan)
    est_q = {k: np.full((n, truth.nq), np.nan) for k in obs}
    est_v = {k: np.full((n, truth.nv), np.nan) for k in obs}
    wall = {k: np.full(n, np.nan) for k in obs}
    diverged: dict[str, float | None] = dict.fromkeys(obs)
    failures: dict[str, str] = {}
    history: deque[Vector] = deque(maxlen=sensor.delay + 1)

    q, v = q0, v0
    for k in range(n):
        if k > 0:
            q, v = _plant_step(truth, q, v, TAU[k - 1], h, substeps)
        tau = inputs.torque(t[k], q, v)
        Q[k], V[k], TAU[k] = q, v, tau
        history.append(q)
        meas = sensor.measure(truth, history[0], rng) if k > 0 else None
        if meas is not None:
            QM[k] = meas
        for name, ob in obs.items():
            if diverged[name] is not None:
                continue
            start = time.perf_counter()
            try:
                if k == 0:
                    est = ob.reset(t[0], q_hat0, v_hat0, tau)
                else:
                    est = ob.update(t[k], meas, tau)
            except ObserverDiverged as exc:
                diverged[name] = exc.t
                failures[name] = str(exc)
                continue
            except (ArithmeticError, np.linalg.LinAlgError, PinobsError) as exc:
                # one failing observer must not take the others' results with it
                diverged[name] = float(t[k])
                failures[name] = f"{type(exc).__name__} at t = {t[k]:.6g} s: {exc}"
                continue
            wall[name][k] = time.perf_counter() - start
            est_q[name][k], est_v[name][k] = est.q, est.v
        if progress is not None:
            progress(k + 1, n)

    traces = tuple(
        ObserverTrace(
            name=name,
            q=est_q[name],
            v=est_v[name],
            update_time=wall[name],
            options=ob.options,
            diverged_at=diverged[name],
        )
        for name, ob in obs.items()
    )
    meta = {
        "robot": robot.name,
        "robot_source": _portable_source(getattr(robot, "source", robot.name)),
        "root_joint": getattr(robot, "root_joint", None),
        "mimic": getattr(robot, "mimic", None),
        "lock": dict(getattr(robot, "locked", {})) or None,  # pinobs play reloads it so
        "duration": duration,
        "rate": sensor.rate,
        "noise_std": sensor.noise_std,
        "bits": sensor.bits,
        "delay": sensor.delay,
        "dropout": sensor.dropout,
        "input": inputs.name,
        "seed": seed,
        "perturb_q": perturb_q,
        "perturb_v": perturb_v,
        "substeps": substeps,
        "plant": truth.name if plant is not None else None,
        "failures": failures,
    }
    return Result(robot=robot.name, t=t, q=Q, v=V, tau=TAU, q_meas=QM, traces=traces, meta=meta)

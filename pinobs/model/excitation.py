"""Excitation trajectories for identification: finite Fourier series within the joint limits.

Each actuated joint follows a periodic finite Fourier series (Swevers,
Ganseman, Tükel, De Schutter, Van Brussel, "Optimal robot excitation and
identification", IEEE T-RA 13(5), 1997, eq. 14)::

    q_i(t) = q_i,c + Σ_{l=1..L} a_il/(ω l) sin(ω l t) − b_il/(ω l) cos(ω l t),    ω = 2π f

(``f`` the base frequency), shifted so ``q(0) = q_c`` and with the
coefficients projected so ``v = a = 0`` at ``t = 0`` and every period: the
robot starts from rest at ``q_c`` (bring it there first).  Velocities and accelerations
are its exact derivatives; the nominal torque ``τ = M a + c + g`` comes from
the model.

**Design.**  The coefficients are chosen to minimise the condition number of
the identification regressor (the joint-torque regressor
``Y(q, v, a)`` with friction and offset columns, columns scaled by the
identification prior, rows by ``M(q)⁻¹``, restricted to its identifiable
combinations) sampled along the trajectory — Swevers' criterion — subject to
position limits (with a margin), velocity limits and effort limits (a
fraction of each).  Every candidate is first scaled down to meet the limits
(positions and velocities scale linearly with the coefficients); the search
is a seeded random search over candidates followed by coordinate-wise
refinement, not a gradient method: the criterion is non-smooth (the rank
decision) and each evaluation costs a few milliseconds.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pinobs.errors import GainError, IdentificationError, UnsupportedRobotError
from pinobs.model.identification import MomentumRegressor
from pinobs.model.robot import Robot, Vector
from pinobs.tolerances import COULOMB_SMOOTHING_VELOCITY

__all__ = ["Excitation", "excite"]


#: Most samples :func:`excite` writes (10⁷: 2.6 GB for a 7-joint arm's t, q, v, a, τ).
MAX_SAMPLES = 10**7


@dataclass(frozen=True)
class Excitation:
    """An excitation trajectory.

    Attributes:
        t: times [s], shape ``(N,)``.
        q, v, a: reference position, velocity, acceleration, shape ``(N, nv)``.
        tau: nominal torque along it [N·m], shape ``(N, nv)``.
        condition: the criterion at the chosen coefficients.
        joint_names: the joints, in ``v`` order.
    """

    t: Vector
    q: Vector
    v: Vector
    a: Vector
    tau: Vector
    condition: float
    joint_names: tuple[str, ...]


def _series(coef: Vector, t: Vector, omega: float, center: Vector) -> tuple[Vector, Vector, Vector]:
    """``(q, v, a)`` of the Fourier series with ``coef`` of shape ``(2, nv, L)``."""
    a_c, b_c = coef
    n_h = a_c.shape[1]
    lw = omega * np.arange(1, n_h + 1)  # (L,)
    # start (and every period) at rest: Σ_l a_il = 0 gives v(0) = 0, Σ_l b_il l ω = 0 gives a(0) = 0
    a_c = a_c - a_c.mean(axis=1, keepdims=True)
    b_c = b_c - np.outer((b_c @ lw) / (lw @ lw), lw)
    arg = np.outer(t, lw)  # (N, L)
    s, c = np.sin(arg), np.cos(arg)
    q = (s @ (a_c / lw).T) - (c @ (b_c / lw).T)
    q = q - (-(b_c / lw).sum(axis=1))  # q(0) = center
    v = c @ a_c.T + s @ b_c.T
    acc = -(s * lw) @ a_c.T + (c * lw) @ b_c.T
    return center + q, v, acc


def excite(
    robot: Robot,
    *,
    duration: float = 20.0,
    rate: float = 100.0,
    base_frequency: float | None = None,
    harmonics: int = 5,
    center: Vector | None = None,
    position_margin: float = 0.1,
    velocity_fraction: float = 0.5,
    effort_fraction: float = 0.5,
    candidates: int = 32,
    refine: int = 1,
    seed: int = 0,
) -> Excitation:
    """An excitation trajectory for ``robot`` (module docstring).

    Args:
        duration: length [s]; the series is periodic with period ``1/base_frequency``.
        rate: output sample rate [Hz].
        base_frequency: ``f`` [Hz] (default: the one making ``duration`` two periods).
        harmonics: ``L``, harmonics per joint.
        center: the configuration the motion is centred on (default: mid-range of
            the position limits, or the neutral configuration where unlimited).
        position_margin: fraction of each joint's range kept free at both ends.
        velocity_fraction, effort_fraction: fraction of the velocity and effort
            limits the trajectory may use (where the URDF gives limits).
        candidates: random candidates tried.
        refine: passes of coordinate-wise refinement.
        seed: seed of the search.

    Raises:
        GainError: ``duration`` or ``rate`` not a finite number > 0, a rate too low to
            sample the highest harmonic (at most ``2 · harmonics · f``), more than
            :data:`MAX_SAMPLES` samples, a negative seed.
        UnsupportedRobotError: a joint whose position is not one number (continuous
            joints' ``(cos, sin)``; a floating base cannot follow a reference).
        IdentificationError: no candidate fits the limits.
    """
    _check_arguments(robot, duration, rate, base_frequency, harmonics, seed)
    f = base_frequency or 2.0 / duration
    problem = _Problem.of(robot, f, center, position_margin, velocity_fraction, effort_fraction)
    rng = np.random.default_rng(seed)
    best, best_c = _search(problem, rng, candidates, harmonics)
    best, best_c = _refine(problem, best, best_c, refine)
    t = np.arange(round(duration * rate) + 1) / rate
    q, v, acc = _series(best, t, problem.omega, problem.center)
    model, data = problem.model, problem.data
    tau = np.array([pin.rnea(model, data, q[k], v[k], acc[k]) for k in range(len(t))])
    return Excitation(t, q, v, acc, tau, best_c, robot.joint_names)


def _check_arguments(
    robot: Robot,
    duration: float,
    rate: float,
    base_frequency: float | None,
    harmonics: int,
    seed: int,
) -> None:
    """:func:`excite`'s arguments, refused before any work (its ``Raises``)."""
    for name, value in (("duration", duration), ("rate", rate)):
        if (
            isinstance(value, bool)
            or not isinstance(value, numbers.Real)
            or not (math.isfinite(value) and value > 0)
        ):
            raise GainError(f"{name}={value!r} is out of range; give a finite number > 0")
    if base_frequency is not None and not (math.isfinite(base_frequency) and base_frequency > 0):
        raise GainError(
            f"base_frequency={base_frequency!r} is out of range; give a finite number > 0"
        )
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise GainError(f"seed={seed!r}: give an integer >= 0")
    f_top = harmonics * (base_frequency or 2.0 / duration)
    if rate <= 2.0 * f_top:  # Nyquist: the samples would miss (or alias) the motion
        raise GainError(
            f"rate={rate:g} Hz cannot sample the trajectory's highest harmonic "
            f"({f_top:g} Hz = {harmonics} harmonics of {f_top / harmonics:g} Hz); give a rate "
            f"> {2.0 * f_top:g} Hz or a longer duration"
        )
    samples = math.floor(duration * rate) + 1
    if samples > MAX_SAMPLES:
        raise GainError(
            f"duration={duration:g} s at rate={rate:g} Hz is {samples:.3g} samples, "
            f"{samples * (4 * robot.nv + 1) * 8 / 1e9:.3g} GB of output; give at most "
            f"{MAX_SAMPLES:.0e} samples (a lower rate or a shorter duration)"
        )
    if not robot.is_vector_space:
        other = [
            f"{b.name} ({'continuous: q = (cos, sin)' if b.kind == 'circle' else b.kind})"
            for b in robot.joints
            if b.kind != "vector"
        ]
        raise UnsupportedRobotError(
            f"robot {robot.name!r} has joints whose position is not one number: "
            f"{', '.join(other)}; excitation trajectories are for fixed-base arms with "
            "revolute (bounded) and prismatic joints"
        )


@dataclass(frozen=True)
class _Problem:
    """The design problem of :func:`excite`: the series' ``omega`` [rad/s] and ``center``,
    the bounds it must meet (``half``: the position half-range about ``center``, ``vmax``
    [rad/s], ``emax`` [N·m]: ``inf`` where unlimited), the regressor and its prior scale
    ``s``, and the times ``t_eval`` [s] over one period where both are evaluated."""

    robot: Robot
    model: pin.Model
    data: pin.Data
    omega: float
    center: Vector
    half: Vector
    vmax: Vector
    emax: Vector
    reg: MomentumRegressor
    s: Vector
    t_eval: Vector

    @staticmethod
    def of(
        robot: Robot,
        f: float,
        center: Vector | None,
        position_margin: float,
        velocity_fraction: float,
        effort_fraction: float,
    ) -> _Problem:
        """The problem of a series of base frequency ``f`` [Hz], its limits read from
        ``robot``'s model (:func:`excite`'s arguments)."""
        model = robot.model
        lo, hi = np.array(model.lowerPositionLimit), np.array(model.upperPositionLimit)
        # Pinocchio's "no limit" is ±1.8e308, whose difference overflows: clip before it
        lo, hi = np.clip(lo, -1e300, 1e300), np.clip(hi, -1e300, 1e300)
        finite = (hi - lo < 1e3) & (hi > lo)
        if center is None:
            center = np.where(finite, 0.5 * (lo + hi), robot.neutral())
        half = np.where(finite, (0.5 - position_margin) * (hi - lo), np.pi / 2)
        half = np.minimum(half, np.pi)  # continuous-looking ±2π limits: ±π is motion enough
        vmax = np.array(model.velocityLimit) * velocity_fraction
        vmax = np.where((vmax > 0) & np.isfinite(vmax), vmax, np.inf)
        emax = np.array(model.effortLimit) * effort_fraction
        emax = np.where((emax > 0) & np.isfinite(emax), emax, np.inf)
        reg = MomentumRegressor(robot)
        data = model.createData()
        s = reg.prior_std()
        omega = 2 * np.pi * f
        t_eval = np.linspace(0.0, 1.0 / f, 60, endpoint=False)
        return _Problem(robot, model, data, omega, center, half, vmax, emax, reg, s, t_eval)

    def fit_limits(self, coef: Vector) -> Vector | None:
        """``coef`` scaled down to meet the position, velocity and effort limits, or
        ``None`` when 20 shrinkings do not meet the effort limits."""
        model, data, center = self.model, self.data, self.center
        q, v, _ = _series(coef, self.t_eval, self.omega, center)
        ratio = max(
            float(np.max(np.abs(q - center) / self.half)),
            float(np.max(np.abs(v) / self.vmax)),
            1e-12,
        )
        coef = coef / ratio
        for _ in range(20):  # effort: not linear in the coefficients (gravity): shrink until met
            q, v, acc = _series(coef, self.t_eval, self.omega, center)
            tau = np.array([pin.rnea(model, data, q[k], v[k], acc[k]) for k in range(len(q))])
            over = float(np.max(np.abs(tau) / self.emax))
            if over <= 1.0:
                return coef
            coef = coef * 0.8
        return None

    def criterion(self, coef: Vector) -> float:
        """Swevers' criterion: the condition number of the scaled regressor along the
        series (module docstring)."""
        model, data, reg, nv = self.model, self.data, self.reg, self.robot.nv
        q, v, acc = _series(coef, self.t_eval, self.omega, self.center)
        rows = []
        for k in range(len(q)):
            # (nv, n) always: Pinocchio returns a 1-D row when nv = 1
            y = np.array(pin.computeJointTorqueRegressor(model, data, q[k], v[k], acc[k]))
            y = y.reshape(nv, -1)
            block = [y]
            if reg.friction:
                block.append(np.diag(v[k]))
                block.append(np.diag(np.tanh(v[k] / COULOMB_SMOOTHING_VELOCITY)))
            if reg.offset:
                block.append(-np.eye(nv))
            minv = np.linalg.inv(self.robot.mass_matrix(q[k]))
            rows.append(minv @ np.hstack(block))
        A = np.vstack(rows) * self.s
        sv = np.linalg.svd(A, compute_uv=False)
        keep = sv > 1e-8 * sv[0]
        return float(sv[0] / sv[keep][-1])


def _search(
    problem: _Problem, rng: np.random.Generator, candidates: int, harmonics: int
) -> tuple[Vector, float]:
    """The best of ``candidates`` random coefficients fitted to the limits, and its criterion."""
    best, best_c = None, np.inf
    for _ in range(candidates):
        coef = problem.fit_limits(rng.normal(size=(2, problem.robot.nv, harmonics)))
        if coef is None:
            continue
        c = problem.criterion(coef)
        if c < best_c:
            best, best_c = coef, c
    if best is None:
        raise IdentificationError(
            f"no excitation of {problem.robot.name!r} fits its effort limits; lower "
            "effort_fraction's demand (more margin) or check the URDF's <limit effort>"
        )
    return best, best_c


def _refine(problem: _Problem, best: Vector, best_c: float, refine: int) -> tuple[Vector, float]:
    """``refine`` passes of coordinate-wise refinement of ``best`` (step halved each pass)."""
    step = 0.3
    for _ in range(refine):  # coordinate-wise refinement
        for idx in np.ndindex(best.shape):
            for sign in (1.0, -1.0):
                trial = best.copy()
                trial[idx] += sign * step * (np.abs(best).mean() + 1e-9)
                trial = problem.fit_limits(trial)
                if trial is None:
                    continue
                c = problem.criterion(trial)
                if c < best_c:
                    best, best_c = trial, c
                    break
        step *= 0.5
    return best, best_c

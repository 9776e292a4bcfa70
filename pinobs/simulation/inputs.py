"""Input profiles: the torque a controller applies at each sample time.

A profile is called at the sample times ``t_k`` with the true state and
returns the torque held constant until the next sample (zero-order hold,
MATH §7).  Profiles are seeded and carry no hidden state.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from pinobs.errors import UnknownNameError
from pinobs.model import Robot
from pinobs.model.robot import Vector

__all__ = ["INPUT_NAMES", "InputProfile", "MultiSine", "PDTracking", "Zero", "make_input"]


class InputProfile(ABC):
    """Base of input profiles: ``torque(t, q, v) -> τ`` [N·m or N]."""

    name = ""

    @abstractmethod
    def torque(self, t: float, q: Vector, v: Vector) -> Vector:
        """The torque applied from ``t`` on, given the true state at ``t``."""

    def reference(self, t: float) -> tuple[Vector, Vector] | None:
        """The reference ``(q_ref, v_ref)`` tracked at ``t``, if the profile has one."""
        return None


@dataclass(frozen=True)
class Zero(InputProfile):
    """No torque: the system moves under gravity alone."""

    nv: int
    name = "zero"

    def torque(self, t: float, q: Vector, v: Vector) -> Vector:
        return np.zeros(self.nv)


def _sines(
    rng: np.random.Generator, nv: int, n: int, f_lo: float, f_hi: float
) -> tuple[Vector, Vector, Vector]:
    freqs = rng.uniform(f_lo, f_hi, (nv, n))
    phases = rng.uniform(0.0, 2.0 * np.pi, (nv, n))
    weights = rng.uniform(0.5, 1.0, (nv, n))
    weights /= weights.sum(axis=1, keepdims=True)
    return freqs, phases, weights


@dataclass(frozen=True)
class MultiSine(InputProfile):
    """``τ_i(t) = A_i Σ_j w_ij sin(2π f_ij t + φ_ij)`` plus gravity compensation if asked.

    Attributes:
        amplitude: per-joint amplitude [N·m or N], shape ``(nv,)``.
        freqs, phases, weights: shape ``(nv, n_sines)`` (seeded, see :func:`make_input`).
        gravity_compensation: add ``g(q)`` (computed on ``robot``).
    """

    amplitude: Vector
    freqs: Vector
    phases: Vector
    weights: Vector
    robot: Robot | None = None
    name = "multisine"

    def torque(self, t: float, q: Vector, v: Vector) -> Vector:
        s = (self.weights * np.sin(2.0 * np.pi * self.freqs * t + self.phases)).sum(axis=1)
        tau = self.amplitude * s
        if self.robot is not None:
            tau = tau + self.robot.gravity(q)
        return tau


@dataclass(frozen=True)
class PDTracking(InputProfile):
    """PD tracking of a multi-sine reference with gravity compensation.

        q_ref(t) = q_c ⊕ Σ_j A w_ij sin(2π f_ij t + φ_ij)
        τ = g(q) + M(q_ref)·(K_p e + K_d ė),  e = difference(q, q_ref), ė = v_ref − v

    (``v_ref`` is the time derivative of the reference's tangent coordinates,
    exact for vector joints.)  ``K_p = ω_n²``, ``K_d = 2 ζ ω_n`` with
    ``ω_n`` = ``bandwidth`` [rad/s], scaled by the reference mass matrix so
    every joint gets the same closed-loop bandwidth.
    """

    robot: Robot
    center: Vector
    amplitude: float
    freqs: Vector
    phases: Vector
    weights: Vector
    bandwidth: float = 20.0
    damping: float = 0.9
    name = "pd"
    _cache: dict[str, Vector] = field(default_factory=dict, compare=False, repr=False)

    def reference(self, t: float) -> tuple[Vector, Vector]:
        arg = 2.0 * np.pi * self.freqs * t + self.phases
        xi = self.amplitude * (self.weights * np.sin(arg)).sum(axis=1)
        xi_dot = self.amplitude * (self.weights * 2.0 * np.pi * self.freqs * np.cos(arg)).sum(
            axis=1
        )
        return self.robot.integrate(self.center, xi), xi_dot

    def torque(self, t: float, q: Vector, v: Vector) -> Vector:
        q_ref, v_ref = self.reference(t)
        e = self.robot.difference(q, q_ref)
        kp, kd = self.bandwidth**2, 2.0 * self.damping * self.bandwidth
        m = self._cache.get("M")
        if m is None:
            m = self.robot.mass_matrix(self.center)
            self._cache["M"] = m
        return self.robot.gravity(q) + m @ (kp * e + kd * (v_ref - v))


INPUT_NAMES = ("multisine", "pd", "zero")


def make_input(
    name: str,
    robot: Robot,
    *,
    rng: np.random.Generator,
    center: Vector | None = None,
    amplitude: float | None = None,
    n_sines: int = 3,
    f_lo: float = 0.1,
    f_hi: float = 1.0,
) -> InputProfile:
    """Build an input profile by name (``zero``, ``multisine``, ``pd``).

    Args:
        robot: the *plant's* robot (gravity compensation and PD use its model).
        rng: seeded generator for frequencies and phases.
        center: reference centre for ``pd`` (default: neutral configuration).
        amplitude: ``multisine``: torque amplitude as a fraction of the static
            gravity torque scale (default 1 N·m per unit of ``M`` diagonal);
            ``pd``: reference amplitude [rad] (default 0.5).
        n_sines: number of sines per joint.
        f_lo: lower end of their frequency band [Hz].
        f_hi: upper end of their frequency band [Hz].
    """
    if name == "zero":
        return Zero(robot.nv)
    freqs, phases, weights = _sines(rng, robot.nv, n_sines, f_lo, f_hi)
    c = robot.neutral() if center is None else center
    if name == "multisine":
        scale = np.sqrt(np.diag(robot.mass_matrix(c)))
        amp = (1.0 if amplitude is None else amplitude) * scale * 2.0 * np.pi * f_hi
        return MultiSine(amp, freqs, phases, weights, robot=robot)
    if name == "pd":
        return PDTracking(robot, c, 0.5 if amplitude is None else amplitude, freqs, phases, weights)
    raise UnknownNameError(f"unknown input profile {name!r}; available: {', '.join(INPUT_NAMES)}")

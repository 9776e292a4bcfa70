"""The papers' own example systems, as analytic models (shared by examples and tests).

* :func:`bowl_and_cylinder` — Ibrir §4: a cylinder rolling in a bowl on a
  spring.  The paper prints the equations of motion but not the parameters;
  its equations are those of the metric and potential

      M(θ) = [[M_eq, λ sin θ], [λ sin θ, J_eq]],   V = ½ k x² − λ g cos θ,   τ = (u, 0),

  with, chosen here: bowl 1.5 kg, solid cylinder 0.5 kg of radius 0.1 m
  rolling at ρ = 0.5 m from the bowl's centre, so M_eq = 2.0 kg,
  λ = m ρ = 0.25 kg·m, J_eq = 1.5 m ρ² = 0.1875 kg·m², k = 10 N/m,
  g = 9.81 m/s² (``BOWL``).
* :func:`sarras_eq21` — Sarras et al. eq. (21): ``M⁻¹`` on R³ depending on
  ``q₂`` only (a non-Euclidean metric whose factor (23) satisfies
  Assumption 1), with its exact derivative.

For the unit 3-sphere of Anisi–Hamberg §5 see :mod:`pinobs.model.sphere`.
"""

from __future__ import annotations

import math
from types import MappingProxyType

import numpy as np

from pinobs.model.analytic import AnalyticMetric

__all__ = ["BOWL", "bowl_and_cylinder", "sarras_eq21"]

#: Parameters of :func:`bowl_and_cylinder` (SI units).
BOWL = MappingProxyType({"M_eq": 2.0, "lam": 0.25, "J_eq": 0.1875, "k": 10.0, "g": 9.81})


def bowl_and_cylinder() -> AnalyticMetric:
    """Ibrir §4's system, ``q = (x, θ)`` (module docstring for the parameters)."""
    m_eq, lam, j_eq, k, g = (BOWL[n] for n in ("M_eq", "lam", "J_eq", "k", "g"))

    def mass(q: np.ndarray) -> np.ndarray:
        s = lam * math.sin(q[1])
        return np.array([[m_eq, s], [s, j_eq]])

    def dmass(q: np.ndarray, x: np.ndarray) -> np.ndarray:
        c = lam * math.cos(q[1]) * x[1]
        return np.array([[0.0, c], [c, 0.0]])

    def grad_v(q: np.ndarray) -> np.ndarray:
        return np.array([k * q[0], lam * g * math.sin(q[1])])

    def potential(q: np.ndarray) -> float:
        return 0.5 * k * q[0] ** 2 - lam * g * math.cos(q[1])

    return AnalyticMetric(
        mass,
        n=2,
        mass_matrix_derivative=dmass,
        gravity=grad_v,
        potential=potential,
        name="bowl_cylinder",
    )


def sarras_eq21() -> AnalyticMetric:
    """Sarras et al. eq. (21): ``M⁻¹(q)`` on R³, with its exact derivative."""

    def minv(q: np.ndarray) -> np.ndarray:
        a = 1.0 + q[1] ** 2
        s = q[1] * np.sqrt(a)
        return np.array([[a, 0.0, s], [0.0, a * a, 0.0], [s, 0.0, a]])

    def dminv(q: np.ndarray, x: np.ndarray) -> np.ndarray:
        a = 1.0 + q[1] ** 2
        ds = np.sqrt(a) + q[1] ** 2 / np.sqrt(a)
        return x[1] * np.array([[2 * q[1], 0.0, ds], [0.0, 4 * q[1] * a, 0.0], [ds, 0.0, 2 * q[1]]])

    return AnalyticMetric.from_inverse(
        minv, n=3, inverse_mass_matrix_derivative=dminv, name="sarras_eq21"
    )

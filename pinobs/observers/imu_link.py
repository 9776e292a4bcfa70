"""An IMU on a link that moves relative to the root joint (TALOS's ``imu_link``, on the torso).

The contact-aided filters' body is the IMU's link itself: their state ``(R, v, p)`` is that
frame's pose and velocity, and their equations are unchanged (the gyro and accelerometer
measure that link's motion; the feet are measured in its frame through every joint between,
:class:`pinobs.model.FootKinematics`' (K1)-(K2)).  What changes is the conversion between
that frame and the root joint (Pinocchio's ``q[0:7]``, ``v[0:6]`` in the root frame), which
now goes through the joints between them.  With ``(R_bi, r_bi)`` the IMU frame's placement in
the root frame and ``J_i``, ``J_iω`` its Jacobians (:meth:`FootKinematics.imu_motion`: its
origin's velocity and its angular velocity relative to the root, root frame, per joint
velocity), ``q̇`` the joints' velocities and ``ω = ω̃ − b̂_g`` the IMU's angular velocity::

    R = R_b R_bi,   p = p_b + R_b r_bi                               (M1)
    R_bi ω = ω_b + J_iω q̇,   R_bᵀ v = v_b + ω_b × r_bi + J_i q̇        (M2)

(M1) is ``oM_imu = oM_root · rootM_imu(q)``; (M2) its time derivative (the root frame's
angular and linear velocity plus the joints' contribution).  The root's pose and twist from
the IMU's, as the filters output them::

    R_b = R R_biᵀ,  p_b = p − R_b r_bi,
    ω_b = R_bi ω − J_iω q̇,   v_b = R_bᵀ v − ω_b × r_bi − J_i q̇                  (M3)

The output ``v_b`` is derived, not a state: its lever-arm term carries each gyro sample's
white noise (density ``N``; per sample ``N √rate``) times ``|r_bi|`` (TALOS's 0.16 m).  It is
traded against lag by taking that term's ``ω`` low-passed, to first order with time constant
``τ`` (:data:`LEVER_TAU`), ``ω̃_k`` the reading at sample ``k``, ``Δt`` the step::

    ω̄_k = ω̄_{k−1} + (1 − e^{−Δt/τ}) (ω̃_k − ω̄_{k−1}),   ω̄_0 = ω̃_0
    v_b = R_bᵀ v − ω̄_b × r_bi − J_i q̇,   ω̄_b = R_bi (ω̄ − b̂_g) − J_iω q̇
        = (M3)'s v_b + (R_bi (ω̃ − ω̄)) × r_bi                                        (M4)

(the bias and ``J_iω q̇`` cancel in the difference; the output ``ω_b`` stays (M3)'s, the
filter's state and covariance are unchanged).  A first-order filter passes the sampled white
noise (variance ``N² rate``, ``α = 1 − e^{−Δt/τ}``) with variance ``N² rate α/(2 − α) ≈
N²/(2τ)`` and lags a signal of bandwidth ``≪ 1/(2πτ)`` by ``τ``: an error ``≈ τ ω̇_b``; their
sum per axis ``N²/(2τ) + τ² |ω̇_b|²`` is least at ``τ³ = N²/(4 |ω̇_b|²)``.

(M4) is applied to every IMU frame off the root, moving or fixed (go1's ``imu_link``, 7 cm
off it: ``J_i = J_iω = 0``, the term ``(R_bi (ω̃ − ω̄)) × r_bi`` alone, in the compiled
conversion, :data:`~.inekf_loops.base_kernel`).  On MuJoCo's go1 through ``legged_run``
(10 s, seeds 3-5, held out: seeds 0-2 had been looked at) it lowers the root velocity RMS
12.5-13.6 % standing, 2.7-3.3 % swaying and 3.6-4.7 % trotting; on the real Go1 log the
state, ``q``, ``ω_b`` and the NIS keep their bits (CHANGELOG).  A frame at the root's origin
(``r_bi = 0``) has no lever arm: nothing to smooth.

For a frame fixed to the root ``J_i = J_iω = 0``: the conversion of
:mod:`pinobs.observers.legs` (compiled, :data:`~.inekf_loops.base_kernel`), which (M3)
extends by the joints' terms (:func:`root_twist`, after that kernel).  Without the joints'
velocities (``update`` without ``joint_velocities``) the root's twist is unknown: NaN.
"""

from __future__ import annotations

import math

import numpy as np

from pinobs.observers.base import Vector

__all__ = ["LEVER_TAU", "imu_state", "lever_shift", "root_twist", "smoothed"]

#: (M4)'s time constant τ [s] (:class:`~pinobs.observers.legs.InEKFGains`' ``lever_tau``;
#: cut-off ``1/(2πτ)`` ≈ 8 Hz): the least of TALOS's root velocity error in MuJoCo (stand and
#: sway, seed 0, τ from 0 to 50 ms: flat from 15 to 30 ms; ``benchmarks/talos_imu_link.md``
#: has the held-out seeds); the estimate above with the simulation's gyro density
#: ``N = 2·10⁻³ rad/s/√Hz`` and its truth's ``|ω̇_b|`` (0.18-0.21 rad/s² RMS per axis, stand
#: and sway, seed 0) gives 28-31 ms.
LEVER_TAU = 0.02


def imu_state(
    R_b: Vector, q: Vector, v: Vector, R_bi: Vector, r_bi: Vector, J_bi: Vector
) -> tuple[Vector, Vector]:
    """(M1)-(M2): the IMU frame's rotation ``R`` and rows ``(v, p)`` in the world from the
    root's pose ``(R_b, q[:3])``, its twist ``v[:6]`` (root frame) and the joints' ``v[6:]``:
    ``R_b R_bi`` and ``(R_b (v_b + ω_b × r_bi + J_i q̇), p_b + R_b r_bi)``."""
    velocity = R_b @ (v[:3] + np.cross(v[3:6], r_bi) + J_bi[:3] @ v[6:])
    return R_b @ R_bi, np.array([velocity, q[:3] + R_b @ r_bi])


def smoothed(lever: Vector | None, reading: Vector, dt: float, tau: float = LEVER_TAU) -> Vector:
    """(M4)'s ``ω̄_k`` from ``ω̄_{k−1}`` (``lever``; ``None``: none yet, the reading's
    ``ω̃_k``), the reading ``(ω̃_k, ã_k)``, the step ``dt`` [s] and the time constant ``tau``
    [s] (0: the reading).  In Python floats, axis by axis: the operations of
    ``lever + c (ω̃ − lever)`` on arrays, without three NumPy calls each sample."""
    if lever is None or tau == 0.0:
        return np.array(reading[:3], dtype=float)
    c = 1.0 - math.exp(-dt / tau)
    l0, l1, l2 = lever.tolist()
    r0, r1, r2 = reading[:3].tolist()
    return np.array([l0 + c * (r0 - l0), l1 + c * (r1 - l1), l2 + c * (r2 - l2)])


def lever_shift(R_bi: Vector, reading: Vector | None, lever: Vector | None) -> Vector | None:
    """(M4)'s ``R_bi (ω̃ − ω̄)`` (``None`` without both)."""
    if reading is None or lever is None:
        return None
    return np.asarray(R_bi @ (reading[:3] - lever))


def root_twist(
    base: Vector,
    R_b: Vector,
    dq: Vector | None,
    r_bi: Vector,
    J_bi: Vector,
    shift: Vector | None = None,
) -> None:
    """(M3), in place: ``base``'s rows ``(p_b, ω_b, v_b, R_b v_b)`` as the fixed-frame conversion
    leaves them (``ω_b = R_bi ω``, ``v_b = R_bᵀ v − R_bi ω × r_bi``), with the joints' terms
    ``a = J_iω q̇``, ``b = J_i q̇`` taken out: ``ω_b − a`` and ``v_b + a × r_bi − b``; with
    ``shift`` (:func:`lever_shift`), (M4)'s ``v_b + shift × r_bi``; NaN without ``dq``."""
    if dq is None:
        base[1:] = np.nan
        return
    a, b = J_bi[3:] @ dq, J_bi[:3] @ dq
    base[1] -= a
    arm = a if shift is None else a + shift  # (M4): −ω̄_b × r_bi = −(ω_b − shift) × r_bi
    base[2] += _cross(arm, r_bi) - b
    base[3] = R_b @ base[2]


def _cross(a: Vector, b: Vector) -> Vector:
    """``a × b`` of two 3-vectors (``np.cross``'s checks cost more than the product)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )

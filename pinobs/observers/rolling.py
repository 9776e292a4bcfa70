"""Spherical feet that roll: measure the point of the foot that touched the ground.

The contact-aided filters (:class:`pinobs.observers.inekf.InvariantEKF`,
:class:`pinobs.observers.qekf.QuaternionEKF`) keep a world point ``d_j`` per foot in contact
and model it as still (Hartley et al. IJRR 2020's contact model, ``ḋ_j = R h_R w_c``).  With
a foot frame at the centre ``c`` of a sphere of radius ``r`` (go1: 2 cm), the centre is not
still when the foot rolls: rolling without slipping on a plane with upward normal ``n`` (the
sphere's material point at the contact has zero velocity; the rolling constraint, e.g.
Murray, Li & Sastry 1994, *A Mathematical Introduction to Robotic Manipulation*, ch. 5)::

    ċ − ω × (r n) = 0   ⇒   ċ = ω × (r n)                                       (R1)

with ``ω`` the foot's angular velocity in the world: a drift along the walking direction at
``r |ω|`` (go1 trotting: 1.4 cm/s) that the filters take as a base velocity error.  The
point of the foot link that touched the ground at touch-down ``t₀``, fixed in the foot's
frame,::

    s = R_f(t₀)ᵀ (−r n),    a(t) = c(t) + R_f(t) s                               (R2)

stays (to second order) where it landed: rolling by an angle ``φ`` about a horizontal axis
``u`` (``R_f(t) = Exp(φ u) R_f(t₀)``, ``c(t) = c(t₀) + r φ (u × n)`` by (R1)) moves it by::

    a(t) − a(t₀) = r (φ − sin φ) (u × n) + r (1 − cos φ) n                       (R3)

(a cycloid: 3 µm along, 0.1 mm up for a 0.1 rad roll, against the centre's ``r φ`` = 2 mm).
So each foot is measured at ``a`` instead of ``c``: in the IMU frame, with ``h_j(q)`` the
foot frame's position, ``R_j(q)`` its orientation and ``J_j``, ``J_ω,j`` its linear and
angular Jacobians (:meth:`pinobs.model.FootKinematics.placements_and_jacobians`)::

    h_j ← h_j(q) + R_j(q) s_j,    J_j ← J_j − (R_j(q) s_j)^ J_ω,j,    s_j = R_j(q₀)ᵀ R̂₀ᵀ (−r n)   (R4)

``s_j`` fixed when the foot lands (its flag rises), from the estimated orientation ``R̂₀``
(an error ``δθ`` there moves the anchored point by ``r δθ`` on the sphere, whose drift is then
``r φ δθ``: second order); feet not in contact are measured at their centre (``s_j = 0``),
and a foot the foot gate re-anchors (``foot_gate``, still in contact) keeps its ``s_j``.
``r = 0`` leaves the filters as they were.

(R3)'s second term is not second order for a walking foot: its rise ``r (1 − cos φ)`` is
the same sign at every step (go1 trotting in MuJoCo: φ ≈ 0.13 rad, 0.18 mm a stance of
0.18 s: the trot's mean z velocity error −4.3 → −3.2 mm/s without it; ``legged_truth.md``'s
``lift_diagnosis``), and the filters carry it from foot to foot as a base velocity bias.
Rolling keeps the centre at ``r`` above the plane (R1 has no normal part), so the point
that is still is the anchored point's projection on the plane, ``a − (nᵀ(a − c) + r) n``:
R3 without its rise, its along-track term ``r (φ − sin φ)`` (7 µm) left.  With
``lift`` (the filters' ``rolling_lift``), ``o_j = R_j(q) s_j``, ``n̂ = n̂_j`` the normal in
the IMU frame and ``P = I − n̂ n̂ᵀ``::

    h_j ← h_j(q) + P o_j − r n̂,    J_j ← J_j − P o_j^ J_ω,j                      (R5)

(the derivative of ``P o_j`` is ``P`` times R4's).  ``n̂_j = R̂₀ᵀ n`` when the foot lands,
with ``s_j``, then carried by the filter's propagation alone, ``n̂_j ← (R̂⁺_{k−1}ᵀ R̂⁻_k)ᵀ n̂_j``
(the gyro's rotation over the step, without the corrections): an attitude error at touch-down
stays in ``n̂_j`` as it stays in ``s_j`` (a still foot's R5 point is then its R4 point, as
the attitude converges), and moves the removed rise by ``≈ r φ δθ``, second order like R4's.
With ``n̂ = R̂ᵀ n`` from the current estimate instead, the attitude's convergence from a
30° error moved a still foot's point by up to ``r (1 − cos 30°)`` = 2.7 mm (go1 standing:
base velocity RMS 1.11× R4's).  At touch-down ``o_j = −r n̂`` and (R5) is (R4).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from pinobs.errors import ConfigurationError
from pinobs.observers.base import Vector
from pinobs.observers.checks import positive
from pinobs.observers.linalg import LazyKernel

__all__ = ["RollingFeet"]


class RollingFeet:
    """The feet's measured points under (R4) (module docstring) for spheres of radius ``radius``.

    Args:
        kinematics: the legs; must have ``placements_and_jacobians`` (a
            :class:`pinobs.model.FootKinematics`).
        radius: the feet's sphere radius [m], > 0.
        normal: the ground's upward normal in the world (unit length after normalising).
        lift: (R5): the anchored points' cycloid lift removed (``False``, default: R4).

    Raises:
        ConfigurationError: legs without ``placements_and_jacobians`` (a kinematics that
            gives no foot orientation), or a zero normal.
        GainError: a radius that is not a finite number > 0.
    """

    def __init__(
        self,
        kinematics: object,
        radius: float,
        normal: ArrayLike = (0.0, 0.0, 1.0),
        *,
        lift: bool = False,
    ) -> None:
        if not callable(getattr(kinematics, "placements_and_jacobians", None)):
            raise ConfigurationError(
                f"foot_radius > 0 needs the feet's orientations: {type(kinematics).__name__} "
                "has no placements_and_jacobians (give a robot or a pinobs.model.FootKinematics)"
            )
        self.kinematics = kinematics
        #: the legs' placements and Jacobians, not copied where the kinematics can (read only)
        shared = getattr(kinematics, "shared_placements_and_jacobians", None)
        self._placements: Callable[[Vector], tuple[Vector, ...]] = (
            shared if shared is not None else kinematics.placements_and_jacobians  # type: ignore[attr-defined]
        )
        self.radius = float(positive("foot_radius", radius) or 0.0)
        n = np.asarray(normal, dtype=float).reshape(3)
        if not np.linalg.norm(n) > 0:
            raise ConfigurationError(f"the ground normal must be non-zero, got {normal!r}")
        self.normal = n / np.linalg.norm(n)
        self.offsets = np.zeros((len(kinematics.feet), 3))  # type: ignore[attr-defined]
        rolled_kernel.load()
        step_kernel.load()
        self.down = np.zeros(len(self.offsets), dtype=bool)
        #: (R5): the anchored point's cycloid lift removed (``False``: (R4) alone)
        self.lift = bool(lift)
        #: (R5): each foot's ``n̂_j`` (IMU frame; zero: not down), and the orientation the
        #: filter settled on at its last sample (:meth:`settle`; ``None``: none since)
        self.normals = np.zeros_like(self.offsets)
        self._settled: Vector | None = None

    def restart(self) -> None:
        """Forget every anchor (no foot down): the filter's ``reset``."""
        self.offsets[:] = 0.0
        self.down[:] = False
        self.normals[:] = 0.0
        self._settled = None

    def settle(self, R: Vector) -> None:
        """The orientation ``R̂`` the filter ended its sample with (after its correction): the
        next :meth:`legs` carries each ``n̂_j`` by the rotation from it to the predicted one
        (R5's gyro-only rotation)."""
        self._settled = np.asarray(R, dtype=float)

    def legs(
        self,
        q_joints: Vector,
        R: Vector | None = None,
        flags: Sequence[bool] | None = None,
    ) -> tuple[Vector, Vector]:
        """(R4): the measured points ``(K, 3)`` in the IMU frame and their Jacobians
        ``(K, 3, nv_joints)``.  With ``R`` (the estimated IMU orientation in the world) and
        ``flags`` (contacts now), feet that land are anchored first and feet that lifted off
        forgotten; without them, the anchors stay as they are."""
        h, rot, jac, jac_w = self._placements(q_joints)
        # C-contiguous, the kernels' loaded signatures (a slice's layout is another signature,
        # loaded at the first call by numba's full set-up: 0.3 s, issue 39)
        jac, jac_w = np.ascontiguousarray(jac), np.ascontiguousarray(jac_w)
        h_out, jac_out = np.empty_like(h), np.empty_like(jac)
        if R is not None and flags is not None:
            # the anchors (R4's s_j, R5's n̂_j), then (R4) and (R5), in one compiled call
            now = np.asarray(flags, dtype=bool)
            settled = self._settled
            kernel = step_kernel.compiled
            assert kernel is not None  # loaded by the constructor
            kernel(
                np.asarray(R, dtype=float),
                _EYE if settled is None else settled,
                settled is not None,
                self.normal,
                self.radius,
                now,
                self.down,
                self.lift,
                self.offsets,
                self.normals,
                h,
                rot,
                jac,
                jac_w,
                h_out,
                jac_out,
            )
            if self.lift:
                self._settled = None
            self.down = now
        else:  # (R4), and (R5) for the feet down, in one compiled call
            kernel = rolled_kernel.compiled
            assert kernel is not None  # loaded by the constructor
            args = (self.offsets, self.normals, self.down, self.lift, self.radius)
            kernel(h, rot, jac, jac_w, *args, h_out, jac_out)
        return h_out, jac_out


def _rolling_loops(h, rot, jac, jac_w, s, h_out, jac_out):  # type: ignore[no-untyped-def]
    """(R4) in loops (compiled in :data:`rolled_kernel`): ``h_out = h + R s`` and
    ``jac_out = J − (R s)^ J_ω`` per foot, the cross product written out column by column."""
    for k in range(h.shape[0]):
        o0 = rot[k, 0, 0] * s[k, 0] + rot[k, 0, 1] * s[k, 1] + rot[k, 0, 2] * s[k, 2]
        o1 = rot[k, 1, 0] * s[k, 0] + rot[k, 1, 1] * s[k, 1] + rot[k, 1, 2] * s[k, 2]
        o2 = rot[k, 2, 0] * s[k, 0] + rot[k, 2, 1] * s[k, 1] + rot[k, 2, 2] * s[k, 2]
        h_out[k, 0], h_out[k, 1], h_out[k, 2] = h[k, 0] + o0, h[k, 1] + o1, h[k, 2] + o2
        for c in range(jac.shape[2]):
            wx, wy, wz = jac_w[k, 0, c], jac_w[k, 1, c], jac_w[k, 2, c]
            jac_out[k, 0, c] = jac[k, 0, c] - (o1 * wz - o2 * wy)
            jac_out[k, 1, c] = jac[k, 1, c] - (o2 * wx - o0 * wz)
            jac_out[k, 2, c] = jac[k, 2, c] - (o0 * wy - o1 * wx)


def _lift_loops(h, rot, jac, jac_w, s, normals, down, r, h_out, jac_out):  # type: ignore[no-untyped-def]
    """(R5) in loops (compiled in :data:`rolled_kernel` and the step kernel), for the feet ``down``: ``h_out = h +
    P o − r n̂`` and ``jac_out = J − P (o^ J_ω)``, ``o = R s``, ``P = I − n̂ n̂ᵀ``."""
    for k in range(h.shape[0]):
        if not down[k]:
            continue
        n0, n1, n2 = normals[k, 0], normals[k, 1], normals[k, 2]
        o0 = rot[k, 0, 0] * s[k, 0] + rot[k, 0, 1] * s[k, 1] + rot[k, 0, 2] * s[k, 2]
        o1 = rot[k, 1, 0] * s[k, 0] + rot[k, 1, 1] * s[k, 1] + rot[k, 1, 2] * s[k, 2]
        o2 = rot[k, 2, 0] * s[k, 0] + rot[k, 2, 1] * s[k, 1] + rot[k, 2, 2] * s[k, 2]
        no = n0 * o0 + n1 * o1 + n2 * o2
        h_out[k, 0] = h[k, 0] + (o0 - no * n0) - r * n0
        h_out[k, 1] = h[k, 1] + (o1 - no * n1) - r * n1
        h_out[k, 2] = h[k, 2] + (o2 - no * n2) - r * n2
        for c in range(jac.shape[2]):
            wx, wy, wz = jac_w[k, 0, c], jac_w[k, 1, c], jac_w[k, 2, c]
            c0, c1, c2 = o1 * wz - o2 * wy, o2 * wx - o0 * wz, o0 * wy - o1 * wx
            nc = n0 * c0 + n1 * c1 + n2 * c2
            jac_out[k, 0, c] = jac[k, 0, c] - (c0 - nc * n0)
            jac_out[k, 1, c] = jac[k, 1, c] - (c1 - nc * n1)
            jac_out[k, 2, c] = jac[k, 2, c] - (c2 - nc * n2)


def _fma(a: float, b: float, c: float) -> float:
    """``a·b + c`` (compiled on its own with ``contract``: one fused multiply-add)."""
    return a * b + c


def _column_sums(A, x, out):  # type: ignore[no-untyped-def]
    """``out = Aᵀ x`` for a 3 × 3 ``A``, each entry ``Σ_k A_ki x_k`` by fused multiply-adds
    from ``k = 0``: the bits of NumPy's ``A.T @ x`` (OpenBLAS's ``gemv`` on a column-major
    matrix)."""
    for i in range(3):
        s = 0.0
        for k in range(3):
            s = _fma(A[k, i], x[k], s)
        out[i] = s


def _carry_loops(R, settled, has_settled, up, now, down, normals):  # type: ignore[no-untyped-def]  # noqa: C901 -- numba kernel: loops over small matrices
    """(R5)'s ``n̂_j`` in place: carried by ``settledᵀ R`` (the propagation's rotation alone)
    row-wise if ``has_settled``, ``up = Rᵀ n`` for the feet that land, zero for those that
    lifted off (:func:`_step_loops`; ``normals @ (settledᵀ R)`` in OpenBLAS's order)."""
    if has_settled:
        M = np.empty((3, 3))
        for i in range(3):
            for j in range(3):
                t = 0.0
                for k in range(3):
                    t = _fma(settled[k, i], R[k, j], t)
                M[i, j] = t
        carried = np.empty_like(normals)
        for f in range(normals.shape[0]):
            for j in range(3):
                t = 0.0
                for k in range(3):
                    t = _fma(normals[f, k], M[k, j], t)
                carried[f, j] = t
        normals[:, :] = carried
    for f in range(normals.shape[0]):
        if now[f] and not down[f]:
            normals[f, 0], normals[f, 1], normals[f, 2] = up[0], up[1], up[2]
        elif not now[f]:
            normals[f, 0], normals[f, 1], normals[f, 2] = 0.0, 0.0, 0.0


def _step_loops(  # type: ignore[no-untyped-def]
    R, settled, has_settled, normal, r, now, down, lift, offsets, normals,
    h, rot, jac, jac_w, h_out, jac_out,
):  # fmt: skip
    """:meth:`RollingFeet.legs` with the contacts ``now`` (``down`` before) and the estimated
    orientation ``R``, compiled (:data:`step_kernel`): with ``lift``, (R5)'s normals carried
    by ``settledᵀ R`` (``has_settled``) row-wise, ``Rᵀ n`` for the feet that land, zero for
    those that lifted off; (R4)'s ``s_j = R_jᵀ (−r Rᵀ n)`` for the feet that land, zero for
    those that lifted off; then (R4), and with ``lift`` (R5) for the feet down ``now``.  The products
    by fused multiply-adds in OpenBLAS's order (the bits of the NumPy ``@`` they replace:
    ``normals @ (settledᵀ R)``, ``Rᵀ n``, ``R_jᵀ d``)."""
    up = np.empty(3)
    _column_sums(R, normal, up)  # Rᵀ n, the IMU frame
    if lift:
        _carry_loops(R, settled, has_settled, up, now, down, normals)
    d = np.empty(3)
    for i in range(3):
        d[i] = -r * up[i]  # −r n in the IMU frame
    s = np.empty(3)
    for f in range(h.shape[0]):
        if now[f] and not down[f]:
            _column_sums(rot[f], d, s)  # (R4): s_j = R_j(q₀)ᵀ R̂₀ᵀ (−r n)
            offsets[f, 0], offsets[f, 1], offsets[f, 2] = s[0], s[1], s[2]
        elif not now[f]:
            offsets[f, 0], offsets[f, 1], offsets[f, 2] = 0.0, 0.0, 0.0
    _rolling_loops(h, rot, jac, jac_w, offsets, h_out, jac_out)  # (R4)
    if lift:  # (R5), the feet down now
        _lift_loops(h, rot, jac, jac_w, offsets, normals, now, r, h_out, jac_out)


def _rolled_loops(h, rot, jac, jac_w, s, normals, down, lift, r, h_out, jac_out):  # type: ignore[no-untyped-def]
    """:meth:`RollingFeet.legs` without contacts, compiled (:data:`rolled_kernel`): (R4)
    (:func:`_rolling_loops`), then with ``lift`` (R5) for the feet ``down``
    (:func:`_lift_loops`), the anchors as they are."""
    _rolling_loops(h, rot, jac, jac_w, s, h_out, jac_out)
    if lift:
        _lift_loops(h, rot, jac, jac_w, s, normals, down, r, h_out, jac_out)


#: :func:`_rolled_loops` compiled: ``(h, R, J, J_ω, s, n̂, down, lift, r, h_out, J_out)``.
rolled_kernel = LazyKernel(
    _rolled_loops,
    np.zeros((1, 3)),
    np.zeros((1, 3, 3)),
    np.zeros((1, 3, 2)),
    np.zeros((1, 3, 2)),
    np.zeros((1, 3)),
    np.zeros((1, 3)),
    np.zeros(1, dtype=bool),
    False,
    0.02,
    np.empty((1, 3)),
    np.empty((1, 3, 2)),
    helpers=(_rolling_loops, _lift_loops),
)

_EYE = np.eye(3)

#: :func:`_step_loops` compiled: ``(R, settled, has_settled, n, r, now, down, lift, s, n̂, h,
#: R_j, J, J_ω, h_out, J_out)``.
step_kernel = LazyKernel(
    _step_loops,
    np.eye(3),
    np.eye(3),
    False,
    np.zeros(3),
    0.02,
    np.zeros(1, dtype=bool),
    np.zeros(1, dtype=bool),
    False,
    np.zeros((1, 3)),
    np.zeros((1, 3)),
    np.zeros((1, 3)),
    np.zeros((1, 3, 3)),
    np.zeros((1, 3, 2)),
    np.zeros((1, 3, 2)),
    np.empty((1, 3)),
    np.empty((1, 3, 2)),
    helpers=(_column_sums, _carry_loops, _rolling_loops, _lift_loops),
    contracted=("_fma",),
)

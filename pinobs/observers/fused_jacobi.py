"""Compiled Jacobi operator of ``riemannian``: its products, its brackets and its calls.

``riemannian``'s Jacobi operator's products (:func:`jacobi_loops`, with ``ad`` by
:func:`ad_loops`: :func:`jacobi_lie_loops`; its calls: :class:`JacobiCalls`), so that its
update makes no BLAS call (issue 39), and the table of the compiled brackets
(:func:`bracket_table`, read by :mod:`pinobs.observers.fused_lie` and
:mod:`pinobs.observers.blockstep` too).  Split from :mod:`pinobs.observers.fused` (the
compiled steps around Pinocchio's calls, whose module docstring says what they fuse and
why), unchanged.  The equations are those of
:func:`pinobs.observers.riemannian.jacobi_operator`; the compiled operator equals the NumPy
one (tested).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pinobs.model import Robot
from pinobs.model.integrators import dynamics_calls, integrate_call
from pinobs.observers.base import Vector
from pinobs.observers.fused import loaded
from pinobs.observers.linalg import LazyKernel
from pinobs.tolerances import JACOBI_FD_STEP

__all__ = [
    "JacobiCalls",
    "ad_kernel",
    "bracket_table",
    "jacobi_kernel",
    "jacobi_lie_kernel",
]


def jacobi_loops(
    b_plus: Vector, b_minus: Vector, eps: float, p_v: Vector, b_v: Vector, b_g: Vector,
    ad_v: Vector, ad_g: Vector, sign: float, out: Vector,
) -> None:  # fmt: skip
    """The Jacobi operator from its four calls' matrices, without BLAS
    (:func:`pinobs.observers.riemannian.jacobi_operator`)::

        J = ½ D_v B_v − P_v + (½B_v + ½ad_v)(½B_v − ½ad_v) − ½(B_g − ad_g) − (½B_v − ½ad_v) ad_v

    with ``D_v B_v = (B₊ − B₋)/(2ε)``; ``ad ≡ 0`` on robots without Lie-group joints.  The
    matrices ``B₊, B₋, P_v, B_v, B_g`` are ``sign`` times the arguments: ``sign = −1`` reads
    the ABA derivatives of the model without gravity as they are (:class:`JacobiCalls`);
    ``±1 · x`` is exact, so the bits are those of the negated arrays."""
    n = b_v.shape[0]
    left = np.empty((n, n))
    right = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            b = sign * b_v[i, j]
            left[i, j] = 0.5 * (b - ad_v[i, j])
            right[i, j] = 0.5 * (b + ad_v[i, j])
    for i in range(n):
        for j in range(n):
            out[i, j] = (
                0.5 * ((sign * b_plus[i, j] - sign * b_minus[i, j]) / (2.0 * eps))
                - sign * p_v[i, j]
                - 0.5 * (sign * b_g[i, j] - ad_g[i, j])
            )
    for i in range(n):
        for k in range(n):
            c = right[i, k]
            e = left[i, k]
            for j in range(n):
                out[i, j] += c * left[k, j] - e * ad_v[k, j]


def jacobi_first_loops(
    ddq: Vector, ddq_dq: Vector, ddq_dv: Vector, g: Vector, p_v: Vector, b_v: Vector
) -> None:
    """After :class:`JacobiCalls`' first call: ``g = −ddq`` (``Γs(v, v)``, the next call's
    velocity) and the call's ``∂/∂q``, ``∂/∂v`` copied (``−P_v``, ``−B_v``)."""
    n = ddq.shape[0]
    for i in range(n):
        g[i] = -ddq[i]
        for j in range(n):
            p_v[i, j] = ddq_dq[i, j]
            b_v[i, j] = ddq_dv[i, j]


def jacobi_points_loops(
    ddq_dv: Vector, b_g: Vector, q: Vector, v: Vector, eps: float, q_p: Vector, q_m: Vector
) -> None:
    """After :class:`JacobiCalls`' second call, on a vector space: its ``∂/∂v`` copied
    (``−B_g``) and ``q ⊕ ±εv = q ± εv``, the product and the sum of NumPy's ``q + eps * v``
    (no fused multiply-add: the same bits; ``q + (−εv) = q − εv`` exactly)."""
    n = q.shape[0]
    for i in range(n):
        s = eps * v[i]
        q_p[i] = q[i] + s
        q_m[i] = q[i] - s
        for j in range(n):
            b_g[i, j] = ddq_dv[i, j]


#: The bracket blocks' kinds in the tables of :func:`ad_loops`, ``fused_lie.bracket_loops`` and
#: ``blockstep``'s ``_start_loops`` (:attr:`pinobs.model.JointBlock.kind`).
_KINDS = {"so3": 0, "se3": 1, "se2": 2}


def bracket_table(robot: Robot) -> NDArray[np.int64]:
    """One row ``(kind, first velocity index)`` per spherical (0), free-flyer (1) and planar (2)
    joint of ``robot``: the table of the compiled brackets (:func:`ad_loops`)."""
    kinds = [(_KINDS[b.kind], b.idx_v) for b in robot.joints if b.kind in _KINDS]
    return np.array(kinds, dtype=np.int64).reshape(-1, 2)


def _skew_into(x: Vector, j: int, out: Vector, r: int, c: int) -> None:
    """``out[r:r+3, c:c+3] = skew(x[j:j+3])`` (``pin.skew``: zeros and the entries, negated)."""
    out[r, c], out[r, c + 1], out[r, c + 2] = 0.0, -x[j + 2], x[j + 1]
    out[r + 1, c], out[r + 1, c + 1], out[r + 1, c + 2] = x[j + 2], 0.0, -x[j]
    out[r + 2, c], out[r + 2, c + 1], out[r + 2, c + 2] = -x[j + 1], x[j], 0.0


def ad_loops(table: Any, x: Vector, out: Vector) -> None:
    """``ad_x`` (:meth:`~pinobs.model.Robot.bracket_matrix`) on the blocks of ``table``
    (:func:`bracket_table`): ``skew(x)`` in a spherical joint, ``pin.Motion(x).action`` =
    ``[[skew(ω), skew(v)], [0, skew(ω)]]`` in a free-flyer (``x = (v, ω)``), the se(2) bracket
    in a planar joint; ``out`` elsewhere is not written (the caller's zeros).  Entries of ``x``
    and their negations: the bits of ``bracket_matrix``."""
    for r in range(table.shape[0]):
        kind, i = table[r, 0], table[r, 1]
        if kind == 0:
            _skew_into(x, i, out, i, i)
        elif kind == 1:
            _skew_into(x, i + 3, out, i, i)
            _skew_into(x, i, out, i, i + 3)
            _skew_into(x, i + 3, out, i + 3, i + 3)
            for a in range(3):
                for b in range(3):
                    out[i + 3 + a, i + b] = 0.0
        else:  # se2, x = (vx, vy, w)
            for a in range(3):
                for b in range(3):
                    out[i + a, i + b] = 0.0
            out[i, i + 1], out[i, i + 2] = -x[i + 2], x[i + 1]
            out[i + 1, i], out[i + 1, i + 2] = x[i + 2], -x[i]


def jacobi_lie_loops(
    table: Any, v: Vector, g: Vector, ad_v: Vector, ad_g: Vector, b_plus: Vector,
    b_minus: Vector, eps: float, p_v: Vector, b_v: Vector, b_g: Vector, out: Vector,
) -> None:  # fmt: skip
    """:func:`jacobi_loops` (``sign = −1``) with ``ad_v`` and ``ad_g = ad_{Γs(v,v)}`` written
    first by :func:`ad_loops` (into the caller's buffers, zero off the blocks): one call where
    :class:`JacobiCalls` made five on a robot with Lie-group joints."""
    ad_loops(table, v, ad_v)
    ad_loops(table, g, ad_g)
    jacobi_loops(b_plus, b_minus, eps, p_v, b_v, b_g, ad_v, ad_g, -1.0, out)


class JacobiCalls:
    """:func:`pinobs.observers.riemannian.jacobi_operator` on a :class:`Robot`, cheaper
    (issue 39: it was 185 of the 200 slowest updates of ``riemannian``'s 1 kHz loop on a
    UR5).  The same four ABA-derivatives calls of the model without gravity, at ``(q, v)``,
    ``(q, Γs(v, v))`` and ``(q ⊕ ±εv, v)``, on ``data``, the ``pin.Data`` of the observer's
    correction call (:func:`~pinobs.model.integrators.dynamics_calls`), which every update
    runs: the operator runs every tenth update, and a ``pin.Data`` of its own has left the
    cache by then; the caller reads that call's results first.  Between the calls, the
    copies, ``Γs(v, v) = −ddq`` and ``q ± εv`` (``q ⊕ ±εv`` on a vector space: Pinocchio's
    ``integrate`` of a revolute or prismatic joint is ``q + v``) are two compiled calls
    (:func:`jacobi_first_loops`, :func:`jacobi_points_loops`) on views of ``data``'s
    arrays, not a dozen NumPy ones (elsewhere ``integrate`` bound and the copies item
    assignments); the signs are folded into :func:`jacobi_loops` (``sign = −1``), with
    Lie-group joints with ``ad_v``, ``ad_g`` (:func:`jacobi_lie_loops`); ``|v|`` as
    ``np.linalg.norm`` computes it, ``√(v·v)``.  The same
    operations on the same numbers: equal to
    :func:`~pinobs.observers.riemannian.jacobi_operator` with its compiled products to the
    bit (tested).  UR5 at 1 kHz, paced, load 2.8–3.3, the variants interleaved in one loop:
    100 / 101 µs CPU for ``jacobi_operator`` (on the robot's data), 72 / 70 with these calls
    and NumPy between them, 64 / 59 as here (25 µs in a tight loop)."""

    def __init__(self, robot: Robot, data: Any = None) -> None:
        self.robot = robot
        self.calls = dynamics_calls(robot, gravity=False, data=data)
        self._call = self.calls.derivatives
        d = self.calls.data  # its arrays, as views (Pinocchio writes them in place)
        self._ddq, self._ddq_dq, self._ddq_dv = d.ddq, d.ddq_dq, d.ddq_dv
        n = robot.nv
        self._lie = robot.has_lie_group_joints
        self._zero_tau, self._zero_nn = np.zeros(n), np.zeros((n, n))
        self._scratch = tuple(np.empty((n, n)) for _ in range(4))  # −P_v, −B_v, −B_g, −B₊
        self._scratch_g = np.empty(n)  # Γs(v, v)
        self._scratch_points: tuple[Vector, Vector] = (np.empty(robot.nq), np.empty(robot.nq))
        self.first = loaded(jacobi_first_kernel)
        self.points = loaded(jacobi_points_kernel) if robot.is_vector_space else None
        self.integrate = integrate_call(robot)  # (pin.integrate bound: Robot.integrate's array)
        # the products: with ad_v, ad_g written into buffers (zero off the bracket blocks)
        self.kernel = loaded(jacobi_lie_kernel if self._lie else jacobi_kernel)
        self.table = bracket_table(robot)
        zero_nn = self._zero_nn  # (read only: no ad without Lie-group joints)
        self._scratch_ad = (np.zeros((n, n)), np.zeros((n, n))) if self._lie else (zero_nn, zero_nn)

    @classmethod
    def build(cls, robot: Robot, data: Any = None) -> JacobiCalls | None:
        """The calls for a :class:`Robot` (on ``data``, if given, a ``pin.Data`` of its
        model); ``None`` for another model."""
        return cls(robot, data) if isinstance(robot, Robot) else None

    def __call__(self, q: Vector, v: Vector) -> Vector:
        """The matrix ``J`` with ``J z = R(v, z) v`` at ``q``, shape ``(nv, nv)`` (fresh);
        overwrites ``data``."""
        n = v.shape[0]
        speed = math.sqrt(v.dot(v))  # np.linalg.norm(v), its operations
        if speed == 0.0:
            return np.zeros((n, n))
        call, zero, ddq_dv, g = self._call, self._zero_tau, self._ddq_dv, self._scratch_g
        p_v, b_v, b_g, b_p = self._scratch
        call(q, v, zero)  # −Γs(v, v), −P_v, −B_v
        self.first(self._ddq, self._ddq_dq, ddq_dv, g, p_v, b_v)
        call(q, g, zero)  # −B_g
        eps = JACOBI_FD_STEP / speed
        if self.points is not None:  # (a vector space)
            q_p, q_m = self._scratch_points
            self.points(ddq_dv, b_g, q, v, eps, q_p, q_m)
        else:  # (a copy by item assignment: np.copyto's bytes without its Python dispatcher)
            b_g[...] = ddq_dv
            q_p, q_m = self.integrate(q, eps * v), self.integrate(q, -eps * v)
        call(q_p, v, zero)  # −B₊
        b_p[...] = ddq_dv
        call(q_m, v, zero)  # −B₋, read in place
        out = np.empty((n, n))
        if self._lie:
            ad_v, ad_g = self._scratch_ad
            self.kernel(self.table, v, g, ad_v, ad_g, b_p, ddq_dv, eps, p_v, b_v, b_g, out)
        else:
            zero_nn = self._zero_nn
            self.kernel(b_p, ddq_dv, eps, p_v, b_v, b_g, zero_nn, zero_nn, -1.0, out)
        return out


#: :func:`jacobi_first_loops` compiled.
jacobi_first_kernel = LazyKernel(
    jacobi_first_loops, np.zeros(1), *(np.zeros((1, 1)),) * 2, np.zeros(1), *(np.zeros((1, 1)),) * 2
)
#: :func:`jacobi_points_loops` compiled.
jacobi_points_kernel = LazyKernel(
    jacobi_points_loops, *(np.zeros((1, 1)),) * 2, *(np.zeros(1),) * 2, 1.0, *(np.zeros(1),) * 2
)
#: :func:`jacobi_loops` compiled.
jacobi_kernel = LazyKernel(
    jacobi_loops, *(np.zeros((1, 1)),) * 2, 1.0, *(np.zeros((1, 1)),) * 5, 1.0, np.zeros((1, 1))
)
#: :func:`ad_loops` compiled: ``(table, x, out)``.
ad_kernel = LazyKernel(
    ad_loops, np.zeros((0, 2), dtype=np.int64), np.zeros(1), np.zeros((1, 1)),
    helpers=(_skew_into,),
)  # fmt: skip
#: :func:`jacobi_lie_loops` compiled.
jacobi_lie_kernel = LazyKernel(
    jacobi_lie_loops, np.zeros((0, 2), dtype=np.int64), np.zeros(1), np.zeros(1),
    *(np.zeros((1, 1)),) * 4, 1.0, *(np.zeros((1, 1)),) * 4,
    helpers=(jacobi_loops, ad_loops, _skew_into),
)  # fmt: skip

"""The Kalman filters' linear algebra, shared by the filter families.

The Joseph-form update for ``H = [I 0]`` (:func:`joseph_update`), the Cholesky
solve (:func:`cholesky_solve`, LAPACK ``dposv``), the transition matrix
``Φ ≈ exp(A h)`` (:func:`transition_matrix`, :func:`stiff_transition_matrix`)
and the numba kernels that run them on small states (:class:`LazyKernel`,
compiled on first use so that ``import pinobs`` imports neither numba nor
SciPy).  Written for :mod:`pinobs.observers.ekf` (issue 18: its module
docstring has the equations and the measurements), used as well by ``kf``,
``kalman``, ``adaptive`` and the smoother.
"""

from __future__ import annotations

import functools
import math
import types
from collections.abc import Callable
from typing import Any

import numpy as np

from pinobs.observers.base import Vector
from pinobs.observers.kernel_cache import load_signature

__all__ = [
    "KERNEL_MAX_NV",
    "LazyKernel",
    "cholesky_solve",
    "identity",
    "joseph_kernel",
    "joseph_update",
    "lapack_posv",
    "scaled_identity",
    "stiff_transition_matrix",
    "transition_kernel",
    "transition_matrix",
    "warm_linear_algebra",
]

_SERIES_NORM = 0.25  # ‖A h‖∞ up to which the third-order series is used as it is (error < 1e-4)


@functools.lru_cache(maxsize=8)
def identity(n: int) -> Vector:
    """The ``n × n`` identity, read-only and cached (no allocation per filter step)."""
    eye = np.eye(n)
    eye.setflags(write=False)
    return eye


@functools.lru_cache(maxsize=32)
def scaled_identity(n: int, scale: float) -> Vector:
    """``scale · I`` (``n × n``), read-only and cached on ``(n, scale)``."""
    out = scale * np.eye(n)
    out.setflags(write=False)
    return out


def _transition_loops(A: Vector, h: float, out: Vector) -> None:
    """:func:`transition_matrix` in loops (compiled by numba for small matrices)."""
    n = A.shape[0]
    inner = np.empty((n, n))  # I + Ah/3
    for i in range(n):
        for j in range(n):
            inner[i, j] = A[i, j] * h / 3.0 + (1.0 if i == j else 0.0)
    mid = np.empty((n, n))  # I + (Ah/2)(I + Ah/3)
    for i in range(n):
        for j in range(n):
            t = 0.0
            for k in range(n):
                t += A[i, k] * inner[k, j]
            mid[i, j] = 0.5 * h * t + (1.0 if i == j else 0.0)
    for i in range(n):
        for j in range(n):
            t = 0.0
            for k in range(n):
                t += A[i, k] * mid[k, j]
            out[i, j] = h * t + (1.0 if i == j else 0.0)


def transition_matrix(A: Vector, h: float) -> Vector:
    """``exp(A h)`` to third order, ``I + Ah(I + Ah/2 (I + Ah/3))`` (:mod:`pinobs.observers.ekf`), a new array."""
    if A.shape[0] <= 2 * KERNEL_MAX_NV and transition_kernel.compiled is not None:
        out = np.empty_like(A)
        transition_kernel.compiled(A, float(h), out)
        return out
    Ah = A * h
    eye = identity(A.shape[0])
    inner = Ah / 3.0
    inner += eye
    mid = (0.5 * Ah).dot(inner)
    mid += eye
    out = Ah.dot(mid)
    out += eye
    return out


def stiff_transition_matrix(A: Vector, h: float) -> Vector:
    """``exp(A h)`` for any ``‖A h‖``: the third-order series of :func:`transition_matrix` on
    ``A h / 2ˢ`` squared ``s`` times, ``s`` the least with ``‖A h‖∞ / 2ˢ ≤ 1/4``
    (Moler & Van Loan 2003, "Nineteen dubious ways", method 3: scaling and squaring).

    Needed where the smoothed Coulomb friction makes ``A`` stiff
    (:mod:`pinobs.observers.ekf`);
    equal to :func:`transition_matrix` when ``‖A h‖∞ ≤ 1/4``.
    """
    norm = float(np.abs(A).sum(axis=1).max()) * h
    if not math.isfinite(norm):  # a lost filter's Jacobian: NaN, reported by its caller
        return np.full_like(A, np.nan)
    s = 0 if norm <= _SERIES_NORM else math.ceil(math.log2(norm / _SERIES_NORM))
    Phi = transition_matrix(A, h / 2**s)
    for _ in range(s):
        Phi = Phi.dot(Phi)
    return Phi


@functools.cache
def lapack_posv() -> Any:
    """LAPACK ``dposv`` (Cholesky solve), imported on first use: ``scipy.linalg`` costs
    0.2 s at import, and ``np.linalg.solve`` 5× more per call on these small systems."""
    from scipy.linalg.lapack import dposv  # lazy: start-up time

    return dposv


def cholesky_solve(S: Vector, B: Vector) -> tuple[Vector, bool]:
    """``(S⁻¹ B, ok)`` for a symmetric positive definite ``S`` (LAPACK ``dposv``, upper triangle).

    ``ok`` is False when ``S`` is not positive definite; the result then comes
    from the general ``np.linalg.solve``, or is NaN if ``S`` is singular (a
    diverged filter, which :meth:`Observer.update` reports).
    """
    _, x, info = lapack_posv()(S, B)
    if info == 0:
        return x, True
    try:
        return np.linalg.solve(S, B), False
    except np.linalg.LinAlgError:  # singular or not finite: NaN, reported by the caller
        return np.full(B.shape, np.nan), False


def _joseph_loops(P: Vector, e: Vector, r: float, dx: Vector, out: Vector) -> bool:  # noqa: C901, PLR0912 -- numba kernel: its branches are loops over small matrices
    """:func:`joseph_update`'s arithmetic in loops (compiled by numba for small ``nv``).

    Cholesky ``S = L Lᵀ`` of ``S = P_qq + r I`` (lower triangle of ``P``),
    ``Kᵀ = S⁻¹ P_q·`` by two triangular solves, then ``C = P − K P_q·``,
    ``P⁺ = sym(C − (C_·q − r K) Kᵀ)`` and ``dx = K e`` into ``dx`` and ``out``.
    Returns False (outputs undefined) when ``S`` is not positive definite.

    The solves run by rows, every column at once (a vector loop along the row), each entry's
    operations in the order of the column-by-column solve (``t −= L_ik Kᵀ_kc`` over ``k``,
    then ``/ L_ii``; compiled without ``contract``): the same bits (tested), the UR5's
    ``ekf`` correction 3.47 → 2.85 µs warm (issue 39).  ``ekf``'s and ``kalman``'s fused
    kernels inline it.
    """
    n, nv = P.shape[0], e.shape[0]
    L = np.zeros((nv, nv))
    for j in range(nv):
        d = P[j, j] + r
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, nv):
            t = P[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / L[j, j]
    Kt = np.empty((nv, n))
    for i in range(nv):
        for c in range(n):
            Kt[i, c] = P[i, c]
        for k in range(i):
            a = L[i, k]
            for c in range(n):
                Kt[i, c] -= a * Kt[k, c]
        d = L[i, i]
        for c in range(n):
            Kt[i, c] = Kt[i, c] / d
    for i in range(nv - 1, -1, -1):
        for k in range(i + 1, nv):
            a = L[k, i]
            for c in range(n):
                Kt[i, c] -= a * Kt[k, c]
        d = L[i, i]
        for c in range(n):
            Kt[i, c] = Kt[i, c] / d
    # each entry's sum in the order of k as t −= …, with k outside the loop over j (the
    # entries of a row independent: no chain of dependent subtractions, the same bits)
    C = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            C[i, j] = P[i, j]
        for k in range(nv):
            c = Kt[k, i]
            for j in range(n):
                C[i, j] -= c * P[k, j]
    for i in range(n):
        for j in range(n):
            out[i, j] = C[i, j]
        for k in range(nv):
            g = C[i, k] - r * Kt[k, i]
            for j in range(n):
                out[i, j] -= g * Kt[k, j]
    for i in range(n):
        for j in range(i):
            m = 0.5 * (out[i, j] + out[j, i])
            out[i, j] = m
            out[j, i] = m
        t = 0.0
        for k in range(nv):
            t += Kt[k, i] * e[k]
        dx[i] = t
    return True


def _contracted(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` under its own name for numba's ``fastmath={"contract"}``: numba's cache keys a
    function's machine code by its module, qualified name, line and signature, not by its
    flags, so one function compiled with and without ``contract`` (``fused.rk4_start_loops``:
    a kernel of its own with it, an inlined helper of ``ekf_predict_loops`` without) shared
    one cache entry and the first to compile decided the other's bits (``kalman``'s steps
    moved by up to 5.3e-16 relative with numba's cache history).  A copy of ``fn`` (the same
    code and globals) named ``<qualname>__contract`` has its own entry."""
    clone = types.FunctionType(
        fn.__code__, fn.__globals__, fn.__name__, fn.__defaults__, fn.__closure__
    )
    clone.__qualname__ = f"{fn.__qualname__}__contract"
    clone.__doc__ = fn.__doc__
    return clone


class LazyKernel:
    """A numba-compiled function, built on :meth:`load` (``import pinobs`` does not import
    numba); ``compiled`` is ``None`` until then.  ``cache=True``: compiled once per
    installation, then loaded from numba's cache
    (:func:`~pinobs.observers.kernel_cache.load_signature`: without numba's full set-up).  ``error_model="numpy"``: a division by
    zero gives ``inf``/``nan`` as in the NumPy path the kernel replaces (numba's default
    raises ``ZeroDivisionError``: a ``kf`` fed a huge sample raised it from its compiled
    bank instead of reporting a diverged estimate).  ``helpers``: functions of ``fn``'s
    module that it calls, compiled first (the same error model; ``inline="always"``: numba
    inlines them into ``fn``) and put in their place there (numba resolves a call by name in
    ``fn``'s module when it compiles ``fn``).  ``contract``: ``a·b + c`` may be fused into one
    FMA instruction (numba's ``fastmath={"contract"}``, nothing else of fast-math), as
    OpenBLAS's products do: the RK4 stages of :mod:`pinobs.observers.fused` then give the
    same bits as the stacked ``c.dot(b)`` of :func:`pinobs.model.dynamics_rk4` (tested).
    ``contracted``: names of functions of ``fn``'s module that ``fn`` calls and that are
    compiled on their own with ``contract`` (not inlined by numba: their instructions keep
    their own flags, so a kernel without ``contract`` can call an RK4 stage with it and each
    part gives the bits it gives alone).  ``linked``: ``(name, kernel)`` pairs, a name in
    ``fn``'s module bound to another :class:`LazyKernel`'s compiled function, which ``fn`` then
    calls as it is (loaded first, not inlined: ``fn``'s compilation does not compile it
    again; a loop over another kernel's steps compiled in seconds, not a minute)."""

    def __init__(
        self,
        fn: Callable[..., Any],
        *warm_args: Any,
        helpers: tuple[Callable[..., Any], ...] = (),
        contract: bool = False,
        contracted: tuple[str, ...] = (),
        linked: tuple[tuple[str, LazyKernel], ...] = (),
    ) -> None:
        self.fn, self.warm_args, self.helpers = fn, warm_args, helpers
        self.linked = linked
        self.fastmath: set[str] | bool = {"contract"} if contract else False
        self.contracted = contracted
        self.compiled: Callable[..., Any] | None = None

    def load(self) -> None:
        """Compile (or load from numba's cache) and set :attr:`compiled`; once."""
        if self.compiled is None:
            import numba  # lazy: start-up time

            scope = self.fn.__globals__
            for helper in self.helpers:  # (shared helpers: compiled by the first kernel)
                if not hasattr(scope[helper.__name__], "py_func"):
                    compiled = numba.njit(cache=True, error_model="numpy", inline="always")
                    scope[helper.__name__] = compiled(helper)
            for name, other in self.linked:  # (called as compiled: not compiled again)
                other.load()
                scope[name] = other.compiled
            for name in self.contracted:  # (their own flags: numba.njit, not inlined)
                # the Python function, also where the name was bound to a kernel's inlined
                # helper compiled without `contract` (`from fused import rk4_start_loops` after
                # an ekf kernel had put its helper in fused's scope: the bits then depended
                # on which observer a process made first)
                base = getattr(scope[name], "py_func", scope[name])
                if not base.__qualname__.endswith("__contract"):
                    fma = numba.njit(cache=True, error_model="numpy", fastmath={"contract"})
                    scope[name] = fma(_contracted(base))
            fn = _contracted(self.fn) if self.fastmath else self.fn  # (its own cache entry)
            kernel = numba.njit(cache=True, error_model="numpy", fastmath=self.fastmath)(fn)
            load_signature(kernel, *self.warm_args)  # the float64 signature, loaded now
            self.compiled = kernel

    def unchecked(self) -> Callable[..., Any]:
        """The machine code of the signature :meth:`load` loads (the warm arguments' types),
        called without numba's dispatcher, which types every argument at every call (0.6–1 µs
        of a six-array call; issue 39).  Nothing checks the arguments: for a step's own buffers
        only (arrays of the warm arguments' dtypes and dimensions, C-contiguous), never an
        array a caller passed.  The dispatcher itself where numba's internals differ."""
        self.load()
        kernel = self.compiled
        try:
            sig = tuple(kernel.typeof_pyval(a) for a in self.warm_args)  # type: ignore[union-attr]
            return kernel.overloads[sig].entry_point  # type: ignore[no-any-return,union-attr]
        except (AttributeError, KeyError, TypeError):
            assert kernel is not None  # (load sets it)
            return kernel


#: Largest ``nv`` run by the compiled kernels; above, the NumPy path (BLAS products)
#: is faster than the loops.
KERNEL_MAX_NV = 12
#: :func:`joseph_update`'s arithmetic compiled: ``(P, e, r, dx, out) -> ok`` (loaded by
#: :func:`warm_linear_algebra`; ``kalman``'s fused kernel calls it too).
joseph_kernel = LazyKernel(
    _joseph_loops, np.eye(2), np.zeros(1), 1.0, np.zeros(2), np.zeros((2, 2))
)
#: :func:`transition_matrix` compiled: ``(A, h, out)``.
transition_kernel = LazyKernel(_transition_loops, np.eye(2), 1.0, np.zeros((2, 2)))


def warm_linear_algebra(nv: int) -> None:
    """Load the compiled :func:`joseph_update` for ``nv``, or import LAPACK where ``nv`` is
    past the kernels (a filter's constructor calls this, so that its first update does not
    pay for it)."""
    if nv <= KERNEL_MAX_NV:
        joseph_kernel.load()
        transition_kernel.load()
    else:
        lapack_posv()


def joseph_update(P: Vector, e: Vector, meas_var: float) -> tuple[Vector, Vector]:
    """Kalman update for ``H = [I 0]`` and ``R = meas_var · I``: returns ``(K e, P⁺)``.

    ``S = P_qq + R`` (symmetric positive definite, solved by Cholesky),
    ``K = P Hᵀ S⁻¹``, and the Joseph form ``P⁺ = (I − KH) P (I − KH)ᵀ + K R Kᵀ``,
    symmetrised, evaluated as ``C = P − K P_q·``, ``P⁺ = C − (C_·q − R K) Kᵀ``
    (the same expression: ``(I − KH) P = C``, ``C (I − KH)ᵀ = C − C_·q Kᵀ``),
    two products of ``(n × nv)(nv × n)`` instead of two of ``n × n``.
    """
    nv = e.shape[0]
    if nv <= KERNEL_MAX_NV and joseph_kernel.compiled is not None:
        dx = np.empty(P.shape[0])
        P_new = np.empty_like(P)
        if joseph_kernel.compiled(P, e, float(meas_var), dx, P_new):
            return dx, P_new
    B = P[:nv]  # H P
    S = B[:, :nv] + scaled_identity(nv, meas_var)
    Kt, _ = cholesky_solve(S, B)  # Kᵀ = S⁻¹ H P
    return joseph_from_gain(P, B, Kt.T, Kt, e, meas_var)


def joseph_from_gain(
    P: Vector, B: Vector, K: Vector, Kt: Vector, e: Vector, meas_var: float
) -> tuple[Vector, Vector]:
    """:func:`joseph_update` once its gain ``K`` (and ``Kt = Kᵀ``, ``B = H P``) is known:
    ``C = P − K B``, ``P⁺ = C − (C_·q − R K) Kᵀ``, symmetrised; returns ``(K e, P⁺)``."""
    nv = e.shape[0]
    C = P - K.dot(B)
    Y = K * -meas_var
    Y += C[:, :nv]
    P_new = C - Y.dot(Kt)
    P_new += P_new.T
    P_new *= 0.5
    return K.dot(e), P_new

"""``adaptive``'s learner: sliding-window momentum-form identification fed one committed sample
at a time (:mod:`pinobs.observers.adaptive` module docstring, 2 and 4).

:class:`Learner` keeps the bookkeeping (the buffer, the interval, when to solve, what a solve
changes) on the loop; its costly part, the rows of each window and the solves
(``_Identifier``), runs on the loop too (``learning="sync"``) or in a worker process
(``learning="background"``, :func:`learning_worker`, :class:`~pinobs.observers.worker.Worker`).
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
from collections import deque
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import IdentificationError
from pinobs.model import Robot
from pinobs.model.identification import MAX_FILL, MomentumRegressor, smooth_path, solve
from pinobs.model.identification.lapack import numpy_has_dgeqp3
from pinobs.model.sanity import mass_matrix_defect
from pinobs.observers.base import Vector, positive
from pinobs.observers.blas import blas_libraries, one_blas_thread
from pinobs.observers.worker import Worker
from pinobs.tolerances import TIME_EPS

__all__ = [
    "GAP_FRACTION",
    "NO_ROWS",
    "PRELOAD",
    "REJECTED_KEPT",
    "Learner",
    "check_options",
    "learning_worker",
    "load_learning",
    "split_samples",
]

#: What the worker processes' fork server imports once (:class:`~pinobs.observers.worker.Worker`).
#: (``scipy.linalg`` no more: the solve's QR is NumPy's LAPACK, :func:`load_learning`.)
PRELOAD = ("pinobs.observers.adaptive_learner", "scipy.ndimage")

#: A sample interval further than this fraction of ``h`` from it is a gap for the learner
#: (a lost sample is ``2h``): its windows restart after it.
GAP_FRACTION = 0.5

#: A solve's failure when every window was left out (:meth:`Learner.rejection_cause`).
NO_ROWS = "no rows: every window was left out"

#: The latest rejections kept in ``details["rejected"]`` (it grew without bound, two a second).
REJECTED_KEPT = 100

#: Consecutive off-interval samples after which the learner takes their median as ``h``.
_INTERVAL_CHECK = 10

#: Friction parameters within this many standard deviations of their nominal values are kept
#: nominal (the significance of a learned viscous or Coulomb coefficient).
_FRICTION_SIGMAS = 3.0


class Learner:
    """Sliding-window momentum-form identification fed one committed sample at a time.

    The bookkeeping (the buffer, the interval, when to solve, what a solve changes) runs on
    the loop; the rows of each window and the solves (:class:`_Identifier`) run on the loop
    too, or, given a ``worker``, in its process (``learning="background"``), their results
    taken at the first update after they are done (:meth:`collect`)."""

    #: Test hook: :meth:`collect` waits for every job asked for (background learning then
    #: gives what synchronous learning gives).
    join = False

    def __init__(
        self,
        robot: Robot,
        *,
        window: float,
        half_window: float,
        horizon: float,
        resolve_every: float,
        friction: bool,
        offset: bool,
        rate: float | None,
        worker: Worker | None = None,
    ) -> None:
        self.reg = MomentumRegressor(robot, friction=friction, offset=offset)
        self.nominal = self.reg.nominal()
        # the costly part: here (synchronous) or in the worker process (background)
        self.identifier = _Identifier(self.reg, max(1, round(horizon / window)))
        self.worker = worker  # None: synchronous (every job run in add)
        self.key = next(_KEYS)  # this learner's identifier in the worker process
        self.row_count = 0  # rows kept, as of the last window taken
        # the jobs asked for and not yet taken, in order: (job, (explained, current) of a solve)
        self.pending: deque[tuple[Any, tuple[bool, Vector] | None]] = deque()
        self.windows = 0  # windows of rows asked for (at most the rows kept)
        self.solving = False  # a solve is pending
        self._ripe = False  # a background solve's result was read in an earlier update
        self.window, self.half_window = window, half_window
        self.rate_given = rate
        self.h = math.nan  # the sample interval: 1/rate, or the first one seen (_interval)
        if rate is not None:
            self._counts(1.0 / rate)
        self.buf = _Samples(robot.nq, robot.nv)
        self.resolve_every = resolve_every
        # the first solve resolve_every after the reset, wherever the clock starts (:meth:`start`;
        # it was at t = resolve_every: a clock 100 s behind never solved, 3 s behind, 3.5 s late)
        self.next_solve = math.nan
        self._off_run: list[float] = []  # the latest consecutive update intervals off h
        self._t_last: float | None = None  # the latest update's time (committed or not)
        self.theta: Vector | None = None
        self.std: Vector | None = None
        self.excited: NDArray[np.bool_] | None = None
        self.condition = np.nan
        self.rank = 0
        self.solves = 0
        self.installs = 0
        self.validated = False  # a solve has checked the current model against the data
        self.inconclusive = 0  # solves that fitted their rows exactly and came out unphysical
        self.last_drop = np.nan
        self.history: list[tuple[float, float]] = []
        self.candidate: Vector | None = None  # the latest consistent solve
        self.minv_max: Vector = np.zeros(robot.nv)  # its largest (M⁻¹)ᵢᵢ at the checked q
        self.rejected: deque[str] = deque(maxlen=REJECTED_KEPT)  # the latest, said in details
        self.rejected_run = 0  # consecutive solves rejected (not physical, or failed)
        self.last_rejection = ""  # why the latest rejected solve was
        self.left_out = 0  # windows left out (a singular nominal M(q): _Identifier.add_window)
        self.left_out_said = ""  # the latest one's reason
        # (t, τ, gated) of the updates without a sample since the last one
        self._lost: list[tuple[float, Vector, bool]] = []

    def add(
        self,
        t: float,
        q: Vector | None,
        tau: Vector,
        *,
        explained: bool = False,
        gated: bool = False,
    ) -> bool:
        """Add the sample ``q`` taken at ``t`` and the torque ``tau`` applied from ``t`` on
        (``q`` None: no sample, nothing added); returns True when a new model was solved for.
        ``explained``: the filter's innovations say the current model explains the data
        (then a solve only validates it); ``gated``: ``q`` None because the filter's gate
        rejected the sample (not filled: :meth:`_fill`).

        Written for its cost (issue 39: every update of a live loop): a sample on the interval
        (the usual one) makes no Python call here (the buffer's row written inline; its length
        and latest time read from its fields), and :meth:`collect` is called only with jobs out."""
        t_last, h = self._t_last, self.h
        if t_last is not None and abs(t - t_last - h) <= GAP_FRACTION * h and not self._off_run:
            self._t_last = t  # on the interval: all that _track_interval would do
        else:
            self._track_interval(t)
        buf = self.buf
        if q is None:
            if buf.end > buf.start:
                self._lost.append((t, tau, gated))
            return self.collect() if self.pending else False  # shows as a gap in the times
        # a gap (a lost sample: 2h) or a doubled sample: windows never straddle one, unless
        # it is at most MAX_FILL lost samples, which are interpolated (_fill).  Jitter is not
        # a gap: the rows integrate over the samples' own times (MATH §9); at ±0.1 h this
        # test cleared the windows at every other sample and the learner never solved,
        # silently (a sweep found it, and a 500 Hz stream without rate)
        h = self.h
        if buf.end > buf.start and abs(t - buf.last_t - h) > GAP_FRACTION * h:
            if not self._fill(t, q):
                buf.clear()
        if self._lost:
            self._lost = []
        # buf.append((t, q, tau)), inline (issue 39: a Python call and a view less an update)
        end = buf.end if buf.end < buf.rows.shape[0] else buf.room()
        rows = buf.rows
        rows[end, 0] = t
        rows[end, buf.q_cols] = q
        rows[end, buf.tau_cols] = tau
        buf.end, buf.last_t = end + 1, t
        if math.isnan(h):
            return self.collect() if self.pending else False  # one sample: no interval yet
        if buf.end - buf.start >= self._need:
            self._add_windows()
        if (
            t >= self.next_solve - TIME_EPS  # (t₀ + kT: rounding)
            # (installs do not wait for rows that over-determine the fit, rows ≥ k·rank:
            # measured on run_bench's 4 s mismatch rows, k = 2 / 1.5 / just above 1, ur5
            # inertia5 1.25× / 1.25× / 1.14×, panda inertia5 1.30× / 1.15× / 1.49×.  Such
            # a solve, 12 rows of rank 12, lost the filter on a UR10e log all along: harmless
            # since a lost filter no longer gates the blend's bank, adaptive.py 3)
            and self.windows >= 2
            and not self.solving  # one solve at a time: a late one is used late, not queued
        ):
            self.next_solve = t + self.resolve_every
            current = self.nominal if self.theta is None else self.theta
            qs = self.buf.configurations(max(1, len(self.buf) // 4))
            self.solving = True
            self._run((explained, current), "solve", current.tobytes(), qs.tobytes())
        return self.collect() if self.pending else False

    def _track_interval(self, t: float) -> None:
        """Follow the stream's interval from every update's time ``t`` (a gated or lost
        sample is not a slower stream): counted when no rate was given, else a run of
        :data:`_INTERVAL_CHECK` intervals off the rate's checked (:meth:`_interval`)."""
        if self._t_last is not None:
            dt = t - self._t_last
            if math.isnan(self.h):
                self._counts(dt)  # no rate given: the stream's own interval
            elif abs(dt - self.h) > GAP_FRACTION * self.h:
                self._off_run.append(dt)
                if len(self._off_run) == _INTERVAL_CHECK:
                    self._interval(self._off_run)
                    self._off_run = []
            elif self._off_run:
                self._off_run = []
        self._t_last = t

    def _add_windows(self) -> None:
        """Every complete window of the buffer to the identifier's rows, the buffer moved on
        by a window each."""
        need = self._need
        while len(self.buf) >= need:
            # (the samples' rows written as they came, _Samples: built from a deque of
            # tuples here, 0.2–0.6 ms a window on a UR5 in a paced loop, caches cold)
            rows = self.buf.first(need).tobytes()  # (raw bytes: _Identifier)
            self._run(None, "add_window", rows, self.hw, self.win, self.stride)
            self.windows = min(self.windows + 1, self.identifier.rows.maxlen or 0)
            self.buf.popleft(self.win)

    def _run(self, solve: tuple[bool, Vector] | None, job: str, *args: Any) -> None:
        """Run the identifier's ``job(*args)`` now (synchronous) or queue it on the worker
        process (background); ``solve``: ``(explained, current model)`` of a solve, ``None``
        for a window."""
        if self.worker is None:
            self.pending.append((_Done(_local(self.identifier, job, *args)), solve))
        else:
            windows = self.identifier.rows.maxlen or 1
            self.pending.append((self.worker.submit(_remote, self.key, windows, job, *args), solve))

    def collect(self) -> bool:
        """Take the jobs that are done, in order (all of them, synchronous or with :attr:`join`),
        and apply a solve's result (:meth:`_apply`); True when it installs a new model.
        A job's exception is raised here, as the synchronous learner raises it in ``add``.
        In the background (not :attr:`join`), a solve's result read from the worker in this
        update is applied at the next one: reading it (0.05–0.25 ms on a UR5 in a paced loop)
        and installing the model it brings (0.2–0.4 ms) fall in two updates, not one."""
        installed = False
        while self.pending and (self.join or self.pending[0][0].done()):
            if self.pending[0][1] is not None and self.worker is not None and not self.join:
                if not self._ripe:  # read in this update: applied at the next one
                    self._ripe = True
                    break
                self._ripe = False
            job, solve = self.pending.popleft()
            result = job.result()
            if solve is None:
                self.row_count, said = result
                if said is not None:
                    self.rejected.append(said)
                    self.left_out += 1
                    self.left_out_said = said
            else:
                self.solving = False
                installed = self._apply(result, *solve) or installed
        return installed

    def _fill(self, t: float, q: Vector) -> bool:
        """Interpolate the ``k − 1`` samples lost between the last buffered one and ``q`` taken
        at ``t`` (``t − t_last ≈ k h``, ``k − 1 ≤`` :data:`~pinobs.model.identification.MAX_FILL`)
        linearly on the manifold, each with the torque of its own update (held from the last
        one given); False (nothing filled) for a longer or uneven gap, or one where the filter's
        gate rejected a sample (the model did not explain the data there: filled too, z1 with a
        payload went from 7.4e-4 to 1.22e-3 rad/s in ``benchmarks/learning.py``).  Cleared at every lost
        sample instead, the windows of ``win + 2 hw + 1`` consecutive samples never filled with
        2 % of the samples lost at random, and ``adaptive`` never learned (a sweep: UR5 with a
        payload, 5 % lost, 0 solves in 12 s, 1.19× kf, said "consistent").  The interpolation
        error, ``(k h)² |q̈| / 8``, is 2e-6 |q̈| rad at 1 kHz over 3 lost samples."""
        t0, q0, tau0 = self.buf[-1]
        k = round((t - t0) / self.h)
        if not 2 <= k <= MAX_FILL + 1 or abs(t - t0 - k * self.h) > GAP_FRACTION * self.h:
            return False
        if any(g for *_, g in self._lost):  # gated, not lost: the model was not explaining the
            return False  # data there (filled, z1 with a payload went 7.4e-4 -> 1.22e-3 rad/s)
        robot = self.reg.robot
        for i in range(1, k):
            ti = t0 + i * (t - t0) / k
            held = tau0
            for t_lost, tau_lost, _ in self._lost:  # the torque applied from the lost update on
                if t_lost <= ti + GAP_FRACTION * self.h:
                    held = tau_lost
            self.buf.append((ti, robot.interpolate(q0, q, i / k), held))
        return True

    def _counts(self, h: float) -> None:
        """The windows in samples for the interval ``h`` [s]."""
        self.h = h
        self.stride = max(1, round(0.004 / h))
        self.win = max(self.stride, round(self.window / h / self.stride) * self.stride)
        self.hw = max(2, round(self.half_window / h))
        self._need = self.win + 2 * self.hw + 1  # samples a window takes (_add_windows)

    def start(self, t0: float) -> None:
        """Begin at the reset time ``t0`` [s]: the first solve comes ``resolve_every`` after it."""
        self.next_solve = t0 + self.resolve_every

    def _interval(self, run: list[float]) -> None:
        """:data:`_INTERVAL_CHECK` consecutive intervals off ``h`` that agree among themselves:
        the stream is not at ``rate`` (or its first interval was not its own); their median
        becomes ``h``, said in ``rejected``.  A 500 Hz stream taken for 1 kHz (the default
        without ``rate``) never solved, silently."""
        h = float(np.median(run))
        if all(abs(d - h) <= GAP_FRACTION * h for d in run):
            given = f"rate = {self.rate_given:g} Hz" if self.rate_given else "its first interval"
            self.rejected.append(
                f"the samples come every {h:.6g} s, not {self.h:.6g} s ({given}): the "
                "identification windows are counted on the samples' interval from here"
            )
            self._counts(h)
            self.buf.clear()  # spaced (or filled: _fill) at the interval taken before

    def _inconclusive(self, current: Vector) -> None:
        """A solve asked to validate the ``current`` model (its innovations explain the data)
        whose rows do not over-determine it (rows ≤ rank: the first solves, 18 rows of rank 18
        on a UR5 at 0.5 s) came out unphysical: that says nothing about the data.  Fitted
        exactly, its residual scale is rounding (6e-12 to 1e-13 on those rows as their last
        bits move), its row weights ``1/σ²`` put the normal equations past their limit
        (:func:`~pinobs.model.identification.leastsquares._weighted_step`), and the directions
        the rows do not fix (60 of 78) get steps of the prior's width set by rounding: one ulp
        on the positions made that first solve unphysical in 6 of 19 draws, and whether the
        warm-up ended at 0.5 s or 1 s moved ``benchmarks/run_bench.py``'s UR5 16-bit cell 11×
        between two CPUs (2.65e-5 / 2.93e-4 rad/s).  The rows' minimum-norm exact fit there is
        physical (smallest eigenvalue of ``M(q)`` 0.0158, the nominal model's 0.0158).  So the
        current model is validated as by a physical solve (no candidate, nothing installed),
        and no rejection is counted (:attr:`rejected_run` unchanged, :attr:`inconclusive`
        counted)."""
        self.inconclusive += 1
        self.validated = True
        if self.theta is None:
            self.theta = current

    def _reject(self, why: str) -> None:
        self.rejected.append(why)
        self.last_rejection = why
        self.rejected_run += 1

    def rejection_cause(self) -> str:
        """Why the latest :attr:`rejected_run` solves were rejected, and what to check: when
        they had no rows because every window was left out for a singular nominal ``M(q)``
        (a URDF with a link that moves no mass, loaded with ``check=False``: the TX40's), that
        model; else no physical model fits the rows (the torques' signs, scales, columns)."""
        n = self.rejected_run
        if self.last_rejection == f"solve failed: {NO_ROWS}" and self.left_out:
            return (
                f"no rows to learn from: the last {n} solves had none, every window left out "
                f"({self.left_out} so far) because the nominal M(q) is singular at its "
                f"configurations ({self.left_out_said}); check the URDF's inertias, or lock or "
                "fix that link (not the torques: the model cannot weigh them)"
            )
        return (
            f"no physical model fits the data: the last {n} solves were rejected "
            f"({self.last_rejection}); check the torques' signs, scales and column order"
        )

    def _apply(self, sol: _Solution, explained: bool, current: Vector) -> bool:
        """Take the solve ``sol`` (:meth:`_Identifier.solve`, against ``current``, the model
        when it was asked for); True when it installs a new model.  Model selection: keep the
        current model unless the new one explains the rows better than fitting noise would
        (robust loss drop above rank + 3√rank, in units of ½χ²).  A solve that only validates
        (``explained``) and fits its rows exactly (rows ≤ rank) is not rejected for being
        unphysical: :meth:`_inconclusive`."""
        if sol.failure is not None:
            self._reject(f"solve failed: {sol.failure}")
            return False
        self.condition, self.rank = sol.condition, sol.rank
        if sol.unphysical is not None:
            if explained and sol.n_rows <= sol.rank:
                self._inconclusive(current)
                return False
            self._reject(f"{sol.unphysical} in solve {self.solves + 1}")
            return False
        assert sol.minv_max is not None and sol.theta is not None  # (a consistent solve)
        self.minv_max = sol.minv_max  # of the latest consistent solve (the candidate)
        self.candidate = sol.theta  # the latest consistent solve, installed or not
        drop = sol.loss_current - sol.loss_new
        self.history.append((sol.loss_current, sol.loss_new))
        self.solves += 1
        self.rejected_run = 0
        self.validated = True
        self.std, self.excited = sol.std, sol.excited
        self.last_drop = float(drop)
        if explained or drop <= sol.rank + 3.0 * np.sqrt(sol.rank):
            if self.theta is None:
                self.theta = current
            return False
        self.theta = sol.theta
        self.installs += 1
        return True


class _Samples:
    """The learner's buffer of samples ``(t, q, τ)``, oldest first, as the rows ``[t, q, τ]``
    of one preallocated array (each sample's row written when it comes, in ``O(nq + nv)``): a
    window is then one slice copied (:meth:`first`), not ``need`` tuples gathered at once in
    the update that completes it (issue 39: the worst updates of a live loop), and one block
    of float64 bytes to send to the worker process (:class:`_Identifier` takes its jobs'
    arrays as bytes: pickled as bytes, not through numpy's reduce of three arrays, which was
    most of what a window cost the loop; UR5 in a paced loop at load 0.3, the pickle 80 → 26
    µs, ``submit`` 137 → 79 µs).  The rows live in ``[start, end)``; moved to the front (or
    the array doubled) when ``end`` reaches the capacity, which happens once every
    capacity − length samples."""

    def __init__(self, nq: int, nv: int, capacity: int = 256) -> None:
        self.rows = np.empty((capacity, 1 + nq + nv))
        self.nq = nq
        self.q_cols, self.tau_cols = slice(1, 1 + nq), slice(1 + nq, 1 + nq + nv)  # of a row
        self.start = self.end = 0
        self.last_t = math.nan  # the latest sample's time [s] (its row's, as a float)

    def __len__(self) -> int:
        return self.end - self.start

    def __bool__(self) -> bool:
        return self.end > self.start

    def __getitem__(self, i: int) -> tuple[float, Vector, Vector]:
        """The sample ``i`` (``-1``: the latest), its arrays copies."""
        k = (self.end if i < 0 else self.start) + i
        if not self.start <= k < self.end:
            raise IndexError(f"sample {i} of {len(self)}")
        row, nq = self.rows[k], self.nq
        return float(row[0]), row[1 : 1 + nq].copy(), row[1 + nq :].copy()

    def append(self, sample: tuple[float, Vector, Vector]) -> None:
        """Add the sample ``(t, q, τ)`` (:meth:`Learner.add` does the same, inline)."""
        if self.end == self.rows.shape[0]:
            self._make_room()
        row, nq = self.rows[self.end], self.nq
        row[0], row[1 : 1 + nq], row[1 + nq :] = sample
        self.end += 1
        self.last_t = float(row[0])

    def room(self) -> int:
        """Make room for a row (:meth:`_make_room`); the index it goes to."""
        self._make_room()
        return self.end

    def _make_room(self) -> None:
        n, cap = len(self), self.rows.shape[0]
        grow = 2 * cap if 2 * n > cap else cap  # at most half full: moved to the front
        new = self.rows if grow == cap else np.empty((grow, self.rows.shape[1]))
        new[:n] = self.rows[self.start : self.end]
        self.rows, self.start, self.end = new, 0, n

    def clear(self) -> None:
        self.start = self.end = 0

    def popleft(self, n: int) -> None:
        """Drop the ``n`` oldest samples."""
        self.start = min(self.start + n, self.end)

    def first(self, n: int) -> Vector:
        """A copy of the ``n`` oldest samples' rows ``[t, q, τ]`` (:func:`split_samples`)."""
        return self.rows[self.start : self.start + n].copy()

    def configurations(self, step: int) -> Vector:
        """Every ``step``-th sample's ``q``, oldest first, as the rows of one array (a copy)."""
        return self.rows[self.start : self.end : step, 1 : 1 + self.nq].copy()


def split_samples(rows: Vector, nq: int) -> tuple[Vector, Vector, Vector]:
    """``(t, q, τ)`` of the rows ``[t, q, τ]`` of :meth:`_Samples.first`, each contiguous
    (copies: the arithmetic then runs on the arrays it ran on before)."""
    return rows[:, 0].copy(), rows[:, 1 : 1 + nq].copy(), rows[:, 1 + nq :].copy()


class _Solution(NamedTuple):
    """One solve of :class:`_Identifier` (``failure`` or ``unphysical`` said why it is not one)."""

    failure: str | None = None  # the solve raised
    unphysical: str | None = None  # a non-positive mass, or M(q) not positive definite
    condition: float = math.nan
    rank: int = 0
    theta: Vector | None = None  # friction clipped and kept nominal where the data do not show it
    std: Vector | None = None
    excited: NDArray[np.bool_] | None = None
    minv_max: Vector | None = None  # the largest (M⁻¹)ᵢᵢ at the checked configurations
    loss_current: float = math.nan  # the robust loss of the current model on the rows
    loss_new: float = math.nan  # the same of the solve
    n_rows: int = 0  # rows solved (no more than rank: fitted exactly, Learner._inconclusive)


class _Identifier:
    """The learner's costly part: the rows of each window and the solves, run in order on the
    loop (synchronous) or in the worker process (background), on its own regressor.  Its
    jobs take their arrays as float64 bytes (``ndarray.tobytes``; :class:`_Samples`)."""

    def __init__(self, reg: MomentumRegressor, windows: int) -> None:
        self.reg = reg
        self.nominal = reg.nominal()
        self.rows: deque[tuple[Vector, Vector]] = deque(maxlen=windows)
        self._data = reg.robot.model.createData()  # (its own: what a left-out window is told)

    def add_window(self, samples: bytes, hw: int, win: int, stride: int) -> tuple[int, str | None]:
        """The ``nv`` rows of one window (module docstring, MATH §9) from the samples, rows
        ``[t, q, τ]`` (:func:`split_samples`: ``q`` [rad] taken at ``t`` [s] with the torques
        ``τ``; ``win + 2 hw + 1`` of them: the smoother's half-width ``hw`` on both sides) as
        their float64 bytes; returns the rows kept and why the window was left out (or None).
        A nominal ``M(q)`` singular in the window (a model loaded with ``check=False``: the
        TX40's, ``benchmarks/real_logs.py``) leaves it out: its rows are weighted by
        ``M(q)⁻¹``; the error escaped ``update`` and ``pinobs.estimate`` re-initialised the
        observer at every window."""
        robot = self.reg.robot
        rows = np.frombuffer(samples).reshape(-1, 1 + robot.nq + robot.nv)
        t, q, tau = split_samples(rows, robot.nq)
        q_s, v = smooth_path(self.reg.robot, t, q, half_window=hw, edges=False)
        k = slice(hw, hw + win + 1)
        said = None
        try:
            self.rows.append(self.reg.system(t[k], q_s[k], v[k], tau[k], window=win, stride=stride))
        except np.linalg.LinAlgError as exc:
            model = self.reg.robot.model
            why = mass_matrix_defect(model, self._data, q_s[hw]) or "M(q) not invertible"
            said = (
                f"window at t = {t[hw]:.6g} s left out: {exc} (the rows' M(q)⁻¹ weighting: {why})"
            )
        return sum(r[0].shape[0] for r in self.rows), said

    def solve(self, current_bytes: bytes, qs_bytes: bytes) -> _Solution:
        """Solve the rows; check the masses and ``M(q) ≻ 0`` at the configurations ``qs``
        (rows); the robust losses of ``current`` and of the solve (for :meth:`Learner._apply`).
        Both given as their float64 bytes."""
        current = np.frombuffer(current_bytes).copy()  # (writable, as the arrays sent before)
        qs = np.frombuffer(qs_bytes).reshape(-1, self.reg.robot.nq).copy()
        if not self.rows:
            return _Solution(failure=NO_ROWS)
        A = np.vstack([r[0] for r in self.rows])
        y = np.concatenate([r[1] for r in self.rows])
        try:
            sol = solve(self.reg, A, y, consistent=False)
        except (IdentificationError, np.linalg.LinAlgError) as exc:
            return _Solution(failure=str(exc))
        theta = sol.theta
        n = self.reg.n_inertial
        masses = theta[0:n:10]
        if np.any(masses <= 0):
            return _Solution(None, "non-positive mass", sol.condition, sol.rank, n_rows=sol.n_rows)
        if self.reg.friction:
            theta = theta.copy()
            f = slice(n, n + 2 * self.reg.n_joint)
            theta[f] = np.maximum(theta[f], 0.0)  # friction never feeds energy in
            # friction the data do not show (within _FRICTION_SIGMAS σ of nominal) stays nominal:
            # a learned friction makes every prediction pay for it (ekf's stiff path)
            nominal = self.nominal[f]
            weak = np.abs(theta[f] - nominal) <= _FRICTION_SIGMAS * sol.std[f]
            theta[f] = np.where(weak, nominal, theta[f])
        robot = self.reg.with_parameters(theta)
        minv_max = np.zeros(robot.nv)
        for q in qs:
            m = robot.mass_matrix(q)
            if np.linalg.eigvalsh(m)[0] <= 0:
                why = "M(q) not positive definite"
                return _Solution(None, why, sol.condition, sol.rank, n_rows=sol.n_rows)
            minv_max = np.maximum(minv_max, np.diag(np.linalg.inv(m)))
        loss_cur = _huber_loss(A @ current - y, sol.sigma)
        loss_new = _huber_loss(A @ theta - y, sol.sigma)
        return _Solution(
            None, None, sol.condition, sol.rank, theta, sol.std, sol.excited, minv_max,
            loss_cur, loss_new, sol.n_rows,
        )  # fmt: skip


class _Done:
    """A job run on the loop (synchronous learning): its result, as a done future."""

    def __init__(self, result: Any) -> None:
        self._result = result

    def done(self) -> bool:
        return True

    def result(self) -> Any:
        return self._result


#: Learner keys (:attr:`Learner.key`): which learner a job in the worker process is for.
_KEYS = itertools.count()


def _worker_start(robot: Robot, friction: bool, offset: bool) -> dict[str, Any]:
    """The worker process's state (:class:`~pinobs.observers.worker.Worker`): its regressor
    (its own ``pin.Data``) and the identifier of the latest learner that sent a job."""
    load_learning()
    import scipy.ndimage  # noqa: F401  (the smoothing's convolution in C: convolve_nearest)

    # off the loop's scheduling: its own session (so its own group where Linux groups tasks
    # by session, autogroup: the loop's share is not spent on it) at the lowest priority.
    # UR5 live_loop at load 9-11, updates over 1 ms in 10 s: 62-77 in the loop's session,
    # 21-41 in its own (synchronous learning: 141-168)
    with contextlib.suppress(AttributeError, OSError):
        os.setsid()
    with contextlib.suppress(AttributeError, OSError):
        os.nice(19)
    # and never woken onto the loop's core ahead of it: Linux's SCHED_IDLE, whose tasks do not
    # preempt a running one at their wake-up (why, with the numbers: pinobs.observers.worker's
    # docstring).  Its own session's group keeps it its share of the machine: the policy only
    # orders it behind the loop on their core.
    with contextlib.suppress(AttributeError, OSError):
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    return {"reg": MomentumRegressor(robot, friction=friction, offset=offset), "key": None}


@one_blas_thread  # as in the worker process (_remote): the rest of an update calls no BLAS
def _local(identifier: _Identifier, job: str, *args: Any) -> Any:
    """In the loop's process (synchronous learning): the identifier's ``job(*args)`` on one
    BLAS thread, the caller's count restored after (``adaptive``'s :attr:`uses_blas` no longer
    puts every update on one thread for the few that run a job: 56 in 5000 on a UR5 at 1 kHz,
    ten windows and two solves a second)."""
    return getattr(identifier, job)(*args)


@one_blas_thread  # small matrices (and the loop is on the other core)
def _remote(state: dict[str, Any], key: int, windows: int, job: str, *args: Any) -> Any:
    """In the worker process: the job ``job(*args)`` of the identifier of learner ``key``
    (made afresh, keeping ``windows`` windows of rows, at that learner's first job: a reset)."""
    if state["key"] != key:
        state["key"], state["identifier"] = key, _Identifier(state["reg"], windows)
    return getattr(state["identifier"], job)(*args)


def check_options(**options: float) -> None:
    """Each of ``adaptive``'s ``options`` (named) > 0, and ``horizon ≥ 2 window`` (two
    identification windows at least)."""
    for key, val in options.items():
        positive(key, val)
    if options["horizon"] < 2 * options["window"]:
        positive("horizon - 2 window", options["horizon"] - 2 * options["window"])


def load_learning() -> None:
    """Load now, at construction, not in the loop (the first window's update would pay it),
    what the learner loads when it first runs: the LAPACK of its QR, found in NumPy's
    OpenBLAS (:func:`~pinobs.model.identification.lapack.pivoted_qr`), and the BLAS
    libraries scanned (:func:`~pinobs.observers.blas.blas_libraries`).  ``scipy.linalg`` only
    where NumPy carries no ``dgeqp3`` (its QR is then SciPy's): its import cost 0.13 s of the
    main thread's CPU and about 0.09 s more of its OpenBLAS's worker thread, spinning as the
    library loads (UR5 ``make_observer`` + first update without it: 500 → 331 ms of process
    CPU, load 2; over half of it SciPy's array-API layer, which imports every NumPy
    submodule, ``numpy.f2py`` and ``numpy.testing`` among them).  The smoothing no longer
    imports ``scipy.signal`` and ``scipy.ndimage`` (0.5 s CPU; the first window's update took
    494 ms on a UR5 importing them, then the observer's construction did):
    :func:`~pinobs.model.identification.convolve_nearest` does the same arithmetic in NumPy."""
    if not numpy_has_dgeqp3():
        import scipy.linalg  # noqa: F401

    blas_libraries()


def _huber_loss(r: Vector, sigma: float, c: float = 1.345) -> float:
    """``Σ ρ(rᵢ/σ)`` with Huber's ρ (½z² inside ``c``, ``c|z| − ½c²`` outside)."""
    z = np.abs(r) / sigma
    return float(np.sum(np.where(z <= c, 0.5 * z * z, c * z - 0.5 * c * c)))


def learning_worker(robot: Robot, friction: bool, offset: bool) -> Worker:
    """The worker process of ``learning="background"`` (started now, not in the loop; it ends
    when dropped: its jobs hold no observer), its regressor made for ``robot``."""
    return Worker(_worker_start, robot, friction, offset, preload=PRELOAD)

"""A worker process fed over two pipes, with no thread in the caller's process once started.

``adaptive``'s background learning (:mod:`pinobs.observers.adaptive`) runs its
window rows and solves here.  Not on a thread, and not through
:class:`concurrent.futures.ProcessPoolExecutor`: both put a second Python
thread in the loop's process (the worker, or the executor's manager and
queue feeder), and a loop thread that wakes for its tick while that thread
holds the GIL waits for it — for the whole time the OS has that thread off a
core on a loaded machine.  Measured on a 2-core machine at load 9–11 (UR5,
1 kHz, 10 s ``live_loop``; ``ekf`` alone in the same conditions: 2–5 updates
over 1 ms): ``adaptive`` learning on a thread, 61–149 updates over 1 ms (the
window rows hold the GIL: ``smooth_path`` and the regressor are Python and
Pinocchio calls; the solve mostly releases it, in LAPACK); through a
``ProcessPoolExecutor``, 128–306, most within 5 samples after a window was
sent.  Here the loop's own thread writes each job to the pipe (one
``pickle`` of a few arrays, a ``write``) and reads the results that are
there (a ``poll``, then a ``read``): nothing else in its process runs Python.
With the worker (forked from the loop's process then) in the loop's session:
62–77 (Linux groups a session's tasks for the scheduler, autogroup, so the
worker spent the loop's share); in its own session at nice 19, as
``adaptive``'s starts: 21–76; forked from the fork server, as now: 12–128
at load 7–9 (learning inside ``update``, in the same sessions: 141–350).
What remained was the write itself: a pipe write wakes its reader synchronously (the
kernel's hint that the writer will sleep), so the worker was queued on the loop's core and
preempted the loop there, which waited, inside ``submit``, for the whole job (1.5–7 ms wall
for 40–80 µs of the loop's CPU, one involuntary context switch each, at every window and
solve).  ``adaptive``'s worker runs at Linux's ``SCHED_IDLE`` policy, whose tasks never
preempt a running one at their wake-up (``learning_worker`` in
:mod:`pinobs.observers.adaptive_learner`): UR5, ``benchmarks/live_loop.py`` 20 s at load
2, updates over 1 ms 35–38 → 1–7, none of them in a ``submit``.

Workers are forked from multiprocessing's fork server (:class:`Worker`), not
from the loop's process: a fork of a process with threads can deadlock in the
child (Python 3.12 warns of it), and a forked copy shares the loop's pages
(copy-on-write: the loop's next full garbage collection copied them, 25 ms).

The pipe into the worker is grown to 1 MiB where the OS allows
(Linux ``F_SETPIPE_SZ``), and a job is written only when it fits in what the
worker has not yet taken (counted in pages, conservatively); otherwise it
waits in :attr:`Worker.outbox` and is written at a later :meth:`Worker.poll`.
So ``submit`` never blocks on a worker that is behind (unless nothing is
queued and one job is larger than the pipe: then it waits for the worker to
take it).  Jobs run in the order they were submitted; each one's result (or
its exception) comes back in that order.

The worker starts without the caller waiting for it (issue 39): the fork server's start
(a Python that imports Pinocchio and ``scipy.ndimage``, :data:`~pinobs.observers.adaptive_learner.PRELOAD`)
and the worker's ``init`` took ``adaptive``'s ``make_observer`` from 0.4 to 1.0 s of wall
time.  A starter thread does it (``Process.start`` and the wait for the worker's "ready"),
blocked in ``read`` nearly all along (GIL released) and gone once the worker is ready; jobs
submitted meanwhile are written to the pipe at once (the worker reads them when it runs) and
their results read only once it is ready; a start that failed is raised by the next
:meth:`Worker.submit` or :meth:`Worker.poll`.
"""

from __future__ import annotations

import pickle
import select
import sys
import threading
import weakref
from collections import deque
from collections.abc import Callable
from typing import Any

__all__ = ["Job", "Worker"]

#: [bytes] The pipe size asked for (Linux's default limit for an unprivileged process).
PIPE_BYTES = 1 << 20
_PAGE = 4096


class Job:
    """A job submitted to a :class:`Worker`: its result once the worker sent it."""

    def __init__(self, worker: Worker) -> None:
        self._worker = worker
        self._done = False
        self._ok = True
        self._value: Any = None

    def done(self) -> bool:
        """Whether the result is in (reads what the worker has sent, never waits)."""
        if not self._done:
            self._worker.poll()
        return self._done

    def result(self) -> Any:
        """The job's result, waiting for it if needed; its exception raised here."""
        while not self._done:
            self._worker.poll(wait=True)
        if not self._ok:
            raise self._value
        return self._value


class Worker:
    """One worker process: ``state = init(*init_args)`` there once, then each submitted
    ``fn(state, *args)`` in order (``fn`` a module-level function: it is sent by name).

    The process starts (and runs ``init``) from the constructor without it waiting: a starter
    thread starts it and reads its "ready" (module docstring); :meth:`started` waits for that.
    It ends when the worker is closed or dropped (the pipes close: it reads the end), or with
    the caller's process (a daemon).  It is forked from multiprocessing's fork server
    (spawned where there is none), never from the caller: a fork of a process with threads
    (OpenBLAS's, the user's) can deadlock in the child, and Python 3.12 warns of it; so, as
    ``multiprocessing`` asks, a script that makes one guards its top-level code with
    ``if __name__ == "__main__":`` (else its error is raised here, in the process that imports
    the script to start, and in the caller by :meth:`submit` or :meth:`poll`).  ``preload``:
    modules the fork server imports once (so a worker starts in milliseconds, not the seconds
    an import of Pinocchio and SciPy takes)."""

    def __init__(
        self, init: Callable[..., Any], *init_args: Any, preload: tuple[str, ...] = ()
    ) -> None:
        _not_bootstrapping()
        ctx = _context(preload)
        jobs_out, jobs_in = ctx.Pipe(duplex=False)  # (reader, writer)
        results_out, results_in = ctx.Pipe(duplex=False)
        self.process = ctx.Process(
            target=_main,
            args=(jobs_out, results_in, init, init_args, (jobs_in, results_out)),
            name="pinobs-worker",
            daemon=True,
        )
        self._send, self._recv = jobs_in, results_out
        # whether a result is in, without waiting: one poll object for the worker's life where
        # the OS has poll(2) (Connection.poll builds a selector at every call: 20 Python calls,
        # at every update while a job is out; issue 39)
        self._poller = select.poll() if hasattr(select, "poll") else None
        if self._poller is not None:
            self._poller.register(results_out.fileno(), select.POLLIN)
        self.capacity = _grow_pipe(jobs_in.fileno()) // _PAGE  # [pages]
        self.outbox: deque[tuple[bytes, int]] = deque()  # (message, pages) not yet written
        self._untaken: deque[int] = deque()  # pages of each job written and not yet answered
        self._jobs: deque[Job] = deque()  # submitted and not yet answered, in order
        self._failed: list[BaseException] = []  # the start's error (the starter's)
        starter = threading.Thread(
            target=_start,
            args=(self.process, results_out, (jobs_out, results_in), self._failed),
            name="pinobs-worker-start",
            daemon=True,
        )  # (given no reference to self: a worker dropped while it starts is finalized)
        starter.start()
        self._starter: threading.Thread | None = starter
        self._finalizer = weakref.finalize(self, _stop, jobs_in, results_out, self.process, starter)

    def started(self, *, wait: bool = True) -> bool:
        """Whether the worker process is ready (``wait``: waiting for it); a start that
        failed is raised here (and the worker closed)."""
        starter = self._starter
        if starter is not None:
            if starter.is_alive() and not wait:
                return False
            starter.join()
            self._starter = None
        if self._failed:
            self.close()
            raise self._failed[0]
        return True

    def submit(self, fn: Callable[..., Any], *args: Any) -> Job:
        """Queue ``fn(state, *args)``; returns its :class:`Job` at once."""
        if self._failed:
            self.started()  # (raises the start's error)
        data = pickle.dumps((fn, args), protocol=pickle.HIGHEST_PROTOCOL)
        self.outbox.append((data, -(-len(data) // _PAGE) + 2))  # + header and a partial page
        job = Job(self)
        self._jobs.append(job)
        self._flush()
        return job

    def poll(self, *, wait: bool = False) -> None:
        """Take the results the worker has sent (``wait``: at least one, waiting for it, and
        for the worker's start), then write the queued jobs that fit.  Nothing is read
        before the worker is ready (its "ready" is the starter's)."""
        if self._starter is not None and not self.started(wait=wait):
            self._flush()
            return
        while self._jobs and (
            wait or (self._recv.poll() if self._poller is None else bool(self._poller.poll(0)))
        ):
            wait = False
            self._flush()  # (a job waited for may still be in the outbox)
            ok, value = self._recv.recv()
            job = self._jobs.popleft()
            self._untaken.popleft()
            job._ok, job._value, job._done = ok, value, True
        self._flush()

    def close(self) -> None:
        """End the worker process (its jobs not yet done are dropped; one that is starting
        is waited for first)."""
        self._finalizer()

    def _flush(self) -> None:
        while self.outbox:
            data, pages = self.outbox[0]
            if self._untaken and sum(self._untaken) + pages > self.capacity:
                return  # the worker is behind: written at a later poll
            self._send.send_bytes(data)
            self.outbox.popleft()
            self._untaken.append(pages)


def _context(preload: tuple[str, ...]) -> Any:
    """multiprocessing's forkserver context (``preload`` added to what its server imports:
    ``__main__`` by default), or spawn where there is none (Windows)."""
    import multiprocessing  # here: synchronous learning never starts a worker (2.3 ms)

    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    ctx = multiprocessing.get_context("forkserver")
    if preload:
        ctx.set_forkserver_preload(["__main__", *preload])  # (before the server starts)
    return ctx


def _grow_pipe(fd: int) -> int:
    """Ask for a :data:`PIPE_BYTES` pipe (Linux); returns its size [bytes] (64 KiB assumed
    where it cannot be read)."""
    if sys.platform.startswith("linux"):
        import fcntl

        set_size = getattr(fcntl, "F_SETPIPE_SZ", 1031)
        get_size = getattr(fcntl, "F_GETPIPE_SZ", 1032)
        try:
            fcntl.fcntl(fd, set_size, PIPE_BYTES)
        except OSError:
            pass  # above the system's limit: keep what it has
        try:
            return int(fcntl.fcntl(fd, get_size))
        except OSError:
            pass
    return 1 << 16


def _not_bootstrapping() -> None:
    """Raise multiprocessing's error in a process that is importing its parent's main
    script to start (the fork server, or a spawned child, importing a script whose
    top-level code makes a worker): the starter thread would raise it out of sight, and
    the script would go on there."""
    import multiprocessing

    if getattr(multiprocessing.current_process(), "_inheriting", False):
        raise RuntimeError(
            "a pinobs worker process was started while the main script was imported to start "
            'another process: guard the script\'s top-level code with if __name__ == "__main__":'
        )


def _start(process: Any, recv: Any, theirs: tuple[Any, ...], failed: list[BaseException]) -> None:
    """The starter thread (:class:`Worker`): start ``process``, close the worker's ends of the
    pipes (``theirs``) here, and read its "ready" from ``recv`` (its init's error, or why it
    did not start, into ``failed``)."""
    try:
        process.start()
    except BaseException as exc:  # (the fork server could not import the main script)
        failed.append(_ended(process, exc))
        return
    finally:
        for conn in theirs:
            conn.close()
    try:
        ok, value = recv.recv()  # ready (or init failed)
    except EOFError as exc:  # it ended before it was ready
        failed.append(_ended(process, exc))
        return
    if not ok:
        failed.append(value)


def _ended(process: Any, cause: BaseException) -> RuntimeError:
    """The error of a worker process that did not start (``cause``: what the starter saw)."""
    if process.pid is not None:
        process.join(timeout=1.0)
    exitcode = process.exitcode
    err = RuntimeError(
        f"the worker process ended before it started (exit code {exitcode}); multiprocessing "
        "imports the main script in it: guard the script's top-level code with "
        'if __name__ == "__main__":'
    )
    err.__cause__ = cause
    return err


def _stop(send: Any, recv: Any, process: Any, starter: threading.Thread) -> None:
    """Close the pipes (the worker reads the end) and end the process now (its work is
    only ever wanted by this caller; a copy of the pipe forked into another worker would
    keep it reading); a start under way is waited for first (for 30 s at most: a worker
    that starts later reads the end of the closed pipe and ends)."""
    if starter is not threading.current_thread():
        starter.join(timeout=30.0)
    send.close()
    recv.close()
    if process.pid is not None and process.is_alive():
        process.terminate()
    if process.pid is not None:
        process.join(timeout=1.0)


def _main(
    jobs: Any, results: Any, init: Callable[..., Any], init_args: tuple[Any, ...], theirs: Any
) -> None:
    """The worker process: ``init``, then each job in order until the pipe ends (``theirs``:
    the caller's ends, closed here: a forked copy of its writer would keep the pipe open)."""
    for conn in theirs:
        conn.close()
    try:
        state = init(*init_args)
    except BaseException as exc:  # said to the caller, which raises it
        results.send((False, exc))
        return
    results.send((True, None))
    while True:
        try:
            fn, args = pickle.loads(jobs.recv_bytes())
        except (EOFError, OSError):
            return  # the caller closed (or dropped) the worker
        try:
            reply = (True, fn(state, *args))
        except BaseException as exc:
            reply = (False, exc)
        try:
            results.send(reply)
        except (pickle.PicklingError, TypeError, AttributeError) as exc:  # an unpicklable result
            results.send((False, RuntimeError(f"{fn.__name__}: {exc!r}")))
        except (BrokenPipeError, OSError):
            return

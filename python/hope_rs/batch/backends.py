"""Where the tasks of a batch run: this process, a pool of local processes, or Ray.

Every backend has the small interface of :class:`Backend`: ``submit`` a task, ``wait`` for at
least one to finish, ``close``. A task returns a dict (``{"error": ...}`` for a failure); a
backend turns a worker that died into such a failure of the task it was running, never into
an exception.
"""

from __future__ import annotations

import ctypes
import multiprocessing as mp
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
import warnings
from collections import deque
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor
from concurrent.futures import wait as wait_futures
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable, Protocol

import numpy as np

from .._threads import available_cores
from .progress import one_line_warning
from .ray_backend import RayBackend
from .tasks import error_text, limit_threads, pair_task

__all__ = [
    "Backend",
    "PoolBackend",
    "SerialBackend",
    "check_backend",
    "cpu_count",
    "default_jobs",
    "die_with_parent",
    "make_backend",
]

#: The error of a task whose worker process died while running it.
DIED = "its worker process died (killed, e.g. by the out-of-memory killer)"


class Backend(Protocol):
    """What the scheduler needs of a backend."""

    #: Whether pair tasks get the shapes' arrays (no shared disk) rather than cache digests.
    ships_data: bool

    @property
    def threads(self) -> int | None:
        """Rust threads per task (None: the process's own setting)."""

    def submit(self, fn: Callable[..., dict], *args) -> Any:
        """Start ``fn(*args)``; returns a handle."""

    def wait(self, handles: list) -> list[tuple[Any, dict]]:
        """Wait until at least one of ``handles`` is done; returns (handle, result) pairs."""

    def close(self, abort: bool = False) -> None:
        """Stop the workers (with ``abort``, without waiting for running tasks)."""


class _Task:
    """A task of the serial backend, run when it is waited for."""

    __slots__ = ("args", "fn")

    def __init__(self, fn, args):
        self.fn, self.args = fn, args


class SerialBackend:
    """Runs tasks in this process, one per :meth:`wait` (pairs before preparations, so each map
    is written as soon as possible)."""

    ships_data = False

    def __init__(self, threads: int | None = None):
        self.threads = threads

    def submit(self, fn, *args):
        return _Task(fn, args)

    def wait(self, handles):
        h = next((h for h in handles if h.fn is pair_task), handles[0])
        return [(h, h.fn(*h.args))]

    def close(self, abort: bool = False):
        pass


def die_with_parent(parent: int, poll: float = 1.0) -> None:
    """End this process when process ``parent`` ends, however it ends (even SIGKILL).

    On Linux the kernel sends SIGKILL at the parent's death (``prctl(PR_SET_PDEATHSIG)``);
    everywhere a daemon thread also checks every ``poll`` seconds that the parent is still
    this process's parent, and exits when it is not.
    """
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass  # no libc symbol: the thread below still applies
    if os.getppid() != parent:  # the parent died before the kernel watched it
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(poll)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="hope-rs-parent-watch", daemon=True).start()


def _init_worker(threads: int, parent: int) -> None:
    limit_threads(threads)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the parent, which ends us
    warnings.formatwarning = one_line_warning
    die_with_parent(parent)


def _run_marked(marks: str, task_id: int, fn, *args) -> dict:
    """Run ``fn(*args)`` in a worker after leaving a mark that task ``task_id`` started."""
    with open(os.path.join(marks, str(task_id)), "wb"):
        pass
    return fn(*args)


#: Why a batch stops when its worker processes die before running any pair.
WORKERS_FAILED = (
    "the batch's worker processes died while starting; they are spawned and import the main "
    "script, so a script that calls match_many must do so under "
    '`if __name__ == "__main__":` (or pass jobs=1)'
)


class _Job:
    """A task of the pool: its function, arguments and current future (None while it waits
    to be re-run alone)."""

    __slots__ = ("args", "fn", "future", "id")

    future: Future[dict] | None

    def __init__(self, task_id: int, fn, args):
        self.id, self.fn, self.args, self.future = task_id, fn, args, None


class PoolBackend:
    """A pool of ``jobs`` spawned processes (not forked: a forked Rust thread pool would hang).

    Workers ignore Ctrl-C (the parent ends them) and die with the parent process. When a worker
    dies (killed by the out-of-memory killer, a crash), the pool is restarted: the tasks that
    had not started run in the new pool, and those that had started (one of them killed the
    worker, the others were stopped with it) are re-run one at a time in a pool of their own,
    where a task that kills its worker again fails alone."""

    ships_data = False

    def __init__(self, jobs: int, threads: int):
        self.jobs, self.threads = jobs, threads
        self.marks = tempfile.mkdtemp(prefix="hope_rs-started-")
        self.ex = self._executor(jobs)
        self.alone: ProcessPoolExecutor | None = None  # runs the suspects, one at a time
        self.suspects: deque[_Job] = deque()
        self.live: set[_Job] = set()  # tasks with a future in self.ex
        self.solo: _Job | None = None  # the task running in self.alone
        self.count = 0

    def _executor(self, n: int) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(
            max_workers=n, mp_context=mp.get_context("spawn"),
            initializer=_init_worker, initargs=(self.threads, os.getpid()),
        )  # fmt: skip

    def _start(self, job: _Job, ex: ProcessPoolExecutor) -> None:
        job.future = ex.submit(_run_marked, self.marks, job.id, job.fn, *job.args)

    def submit(self, fn, *args):
        job = _Job(self.count, fn, args)
        self.count += 1
        self._start(job, self.ex)
        self.live.add(job)
        return job

    def wait(self, handles):
        self._next_alone()
        jobs = {h.future: h for h in handles if h.future is not None}
        done, _ = wait_futures(list(jobs), return_when=FIRST_COMPLETED)
        out, broken = [], False
        for f in done:
            job = jobs[f]
            try:
                out.append((job, f.result()))
            except BrokenProcessPool:
                if job is self.solo:  # alone in its pool: this task killed its worker
                    out.append((job, {"error": DIED, "died": True}))
                    self.solo = None
                    self._kill(self.alone)
                    self.alone = None
                else:
                    broken = True
                    continue
            except Exception as e:  # noqa: BLE001 - e.g. a result that cannot be unpickled
                out.append((job, {"error": f"worker process failed: {error_text(e)}"}))
            self.live.discard(job)
            if job is self.solo:
                self.solo = None
        if broken:
            if not os.listdir(self.marks):
                # No task has started in any pool: the workers die while starting up, and a
                # new pool would too (a script without the __main__ guard runs match_many
                # again in every spawned worker).
                self._kill(self.ex)
                raise RuntimeError(WORKERS_FAILED)
            self._restart()
        return out

    def _restart(self) -> None:
        """After a worker of the main pool died: a new pool for the tasks that had not started,
        the started ones queued to run alone."""
        old = self.ex
        # A broken pool fails every task it holds at once; wait for that to be recorded.
        # Every live task has a future: the filter only tells the type checker so.
        futures: list[Future[dict]] = [j.future for j in self.live if j.future is not None]
        wait_futures(futures, timeout=30)
        self._kill(old)
        self.ex = self._executor(self.jobs)
        for job in list(self.live):
            f = job.future
            assert f is not None  # a live task has a future in self.ex
            if f.done() and not f.cancelled() and f.exception() is None:
                continue  # finished before the pool broke: its result is waited for next
            if os.path.exists(os.path.join(self.marks, str(job.id))):
                self.live.discard(job)
                job.future = None
                self.suspects.append(job)
            else:
                self._start(job, self.ex)
        self._next_alone()

    def _next_alone(self) -> None:
        """Start the next suspect in the pool of one, when that pool is idle."""
        if self.solo is not None or not self.suspects:
            return
        if self.alone is None:
            self.alone = self._executor(1)
        self.solo = self.suspects.popleft()
        self._start(self.solo, self.alone)

    @staticmethod
    def _kill(ex: ProcessPoolExecutor | None) -> None:
        if ex is None:
            return
        for proc in list((getattr(ex, "_processes", None) or {}).values()):
            proc.kill()
        ex.shutdown(wait=True, cancel_futures=True)

    def close(self, abort: bool = False):
        """Wait for the workers to finish; with ``abort`` (an error, Ctrl-C), kill them first
        rather than wait for the pairs they are matching."""
        try:
            for ex in (self.ex, self.alone):
                if ex is None:
                    continue
                if abort:
                    self._kill(ex)
                else:
                    ex.shutdown(wait=True, cancel_futures=True)
        finally:
            shutil.rmtree(self.marks, ignore_errors=True)


def cpu_count() -> int:
    """The cores this process may run on."""
    return available_cores()


def default_jobs() -> int:
    """Local worker processes by default: one per two cores. The Rust kernels already use every
    core they are given, and more processes with fewer threads each were not faster while they
    took more memory (docs/decisions.md#speed)."""
    return max(1, cpu_count() // 2)


def check_backend(backend: str, jobs: int | None) -> int:
    """The number of local jobs, after checking both settings (before any work)."""
    jobs = default_jobs() if jobs is None else jobs
    if isinstance(jobs, bool) or not isinstance(jobs, (int, np.integer)) or jobs < 1:
        raise ValueError(f"jobs must be a positive integer, got {jobs!r}")
    if backend not in ("local", "ray"):
        raise ValueError(f"unknown backend {backend!r}; choose 'local' or 'ray'")
    return int(jobs)


def make_backend(backend: str, jobs: int | None, ray_options: dict | None) -> Backend:
    """The backend of a batch (settings checked by :func:`check_backend` first)."""
    jobs = check_backend(backend, jobs)
    if backend == "ray":
        return RayBackend(**(ray_options or {}))
    threads = max(1, cpu_count() // jobs)
    if jobs > 1 and getattr(mp.current_process(), "_inheriting", False):
        # This is a spawned worker importing a main script that starts a batch at import.
        raise RuntimeError(WORKERS_FAILED)
    return SerialBackend(None) if jobs == 1 else PoolBackend(jobs, threads)

"""One BLAS thread for small dense linear algebra.

OpenBLAS spreads even a 352 x 352 ``eigh`` over every core, and its spinning threads then compete
with rayon's, which slows such small problems many times over (docs/decisions.md#speed).
Large products keep all threads.

Most BLAS builds (OpenBLAS on pthreads, as NumPy's and SciPy's wheels ship it) keep one
process-wide limit, while a match's background thread enters it beside the caller's, and
concurrent matches in threads do too: the threads inside share the limit, set by every thread
that enters and restored by the last to leave to what it was before the first entered (each
thread restoring what it saw on entry left BLAS on one thread for good). threadpoolctl lets
only the first thread that set such a limit change it again, which left a match run in a
worker thread after one in the main thread on every core; the shared holder takes control
for each change under its own lock. OpenBLAS built on OpenMP keeps a limit per thread, so
each thread sets and restores its own.
"""

from __future__ import annotations

import contextlib
import functools
import signal
import threading
from collections.abc import Iterator

from threadpoolctl import ThreadpoolController

_controller: ThreadpoolController | None = None
_lock = threading.Lock()
_depth = 0  # entries inside the process-wide limit, over all threads
_limiter = None  # the first entry's limiter: it holds the process-wide limits to restore
_local = threading.local()  # per thread: depth and limiter of the per-thread (OpenMP) limits

#: Signals deferred while the main thread holds the lock: a handler raising there (Ctrl-C,
#: SIGTERM as hope_rs._terminate sets it) could leave the lock held and hang the next entry.
_DEFERRED = {signal.SIGINT, signal.SIGTERM} if hasattr(signal, "pthread_sigmask") else set()


def _blas_controller() -> ThreadpoolController:
    """One controller for the process: building one scans every loaded library, and a match
    sets BLAS limits many times (docs/decisions.md#speed)."""
    global _controller
    if _controller is None:
        # SciPy's wheels bring their own OpenBLAS; load it first so the controller sees it.
        import scipy.linalg  # noqa: F401

        _controller = ThreadpoolController()
    return _controller


def _blas_libraries(per_thread: bool) -> ThreadpoolController:
    """The BLAS libraries whose limit is per thread (OpenBLAS on OpenMP, which threadpoolctl
    limits through OpenMP's per-thread setting) or process-wide."""
    blas = _blas_controller().select(user_api="blas")
    libs = [
        lib
        for lib in blas.lib_controllers
        if (lib.internal_api == "openblas" and getattr(lib, "threading_layer", None) == "openmp")
        == per_thread
    ]
    return ThreadpoolController._from_controllers(libs)


def _take_control() -> None:
    """Let this thread change OpenBLAS's process-wide limit (threadpoolctl ≥ 3.6 ignores
    changes from any thread but the first that made one)."""
    for lib in _blas_controller().lib_controllers:
        clear = getattr(type(lib), "clear_controlling_thread", None)
        if clear is not None:
            clear(force=True)


@contextlib.contextmanager
def _held() -> Iterator[None]:
    """The module's lock, with SIGINT and SIGTERM deferred until it is released when the
    calling thread is the main one (only it runs Python's signal handlers)."""
    masked = bool(_DEFERRED) and threading.current_thread() is threading.main_thread()
    if masked:
        before = signal.pthread_sigmask(signal.SIG_BLOCK, _DEFERRED)
    try:
        with _lock:
            yield
    finally:
        if masked:
            signal.pthread_sigmask(signal.SIG_SETMASK, before)


def _enter() -> None:
    global _depth, _limiter
    with _held():
        _take_control()
        limiter = _blas_libraries(per_thread=False).limit(limits=1)
        if _depth == 0:
            _limiter = limiter
        _depth += 1
        if getattr(_local, "depth", 0) == 0:
            _local.limiter = _blas_libraries(per_thread=True).limit(limits=1)
        _local.depth = getattr(_local, "depth", 0) + 1


def _leave() -> None:
    global _depth, _limiter
    with _held():
        _local.depth -= 1
        if _local.depth == 0:
            _local.limiter.restore_original_limits()
            _local.limiter = None
        _depth -= 1
        if _depth == 0 and _limiter is not None:
            _take_control()
            _limiter.restore_original_limits()
            _limiter = None


@contextlib.contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Context manager limiting BLAS (and the LAPACK on top of it) to one thread, until every
    thread inside it has left."""
    _enter()
    try:
        yield
    finally:
        _leave()


def with_single_threaded_blas(fn):
    """Decorator: ``fn`` runs inside :func:`single_threaded_blas`."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with single_threaded_blas():
            return fn(*args, **kwargs)

    return wrapper

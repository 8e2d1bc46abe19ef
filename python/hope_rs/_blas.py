"""One BLAS thread for small dense linear algebra.

OpenBLAS spreads even a 352 x 352 ``eigh`` over every core, and its spinning threads then compete
with rayon's, which slows such small problems many times over (docs/decisions.md#speed).
Large products keep all threads.

Most BLAS builds (OpenBLAS on pthreads, as NumPy's and SciPy's wheels ship it) keep one
process-wide limit, while a match's background thread enters it beside the caller's, and
concurrent matches in threads do too: the threads inside share the limit, set by every thread
that enters and restored by the last to leave to what it was before the first entered (each
thread restoring what it saw on entry left BLAS on one thread for good). threadpoolctl lets
only one thread at a time change such a limit (the first to change it, until it gives
control back), which left a match run in a worker thread after one in the main thread on
every core; each change here takes control and gives it back, under this module's lock.
OpenBLAS built on OpenMP keeps a limit per thread, so each thread sets and restores its own.
"""

from __future__ import annotations

import contextlib
import functools
import threading
from collections.abc import Iterator
from typing import Any

from threadpoolctl import ThreadpoolController

_controller: ThreadpoolController | None = None
_lock = threading.Lock()
_depth = 0  # entries inside the process-wide limit, over all threads
_limiter: Any = None  # the first entry's limiter: it holds the process-wide limits to restore
_local = threading.local()  # per thread: depth and limiter of the per-thread (OpenMP) limits


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


def _free_control() -> None:
    """Let any thread change OpenBLAS's process-wide limit next (threadpoolctl ≥ 3.6 ignores
    changes from any thread but the one that last took control)."""
    for lib in _blas_controller().lib_controllers:
        clear = getattr(type(lib), "clear_controlling_thread", None)
        if clear is not None:
            clear(force=True)


def _set_shared(change):
    """``change()`` made by this thread, control given back after it (or after a failure)."""
    _free_control()
    try:
        return change()
    finally:
        _free_control()


def _enter() -> None:
    """Count this entry in, under the limit; on any failure, as if it never happened."""
    global _depth, _limiter
    with _lock:
        limiter = _set_shared(lambda: _blas_libraries(per_thread=False).limit(limits=1))
        own = None
        if getattr(_local, "depth", 0) == 0:
            try:
                own = _blas_libraries(per_thread=True).limit(limits=1)
            except BaseException:
                if _depth == 0:
                    _set_shared(limiter.restore_original_limits)
                raise
            _local.limiter = own
        if _depth == 0:
            _limiter = limiter
        _depth += 1
        _local.depth = getattr(_local, "depth", 0) + 1


def _leave() -> None:
    global _depth, _limiter
    with _lock:
        _local.depth -= 1
        _depth -= 1
        if _local.depth == 0:
            own, _local.limiter = _local.limiter, None
            own.restore_original_limits()
        if _depth == 0 and _limiter is not None:
            shared, _limiter = _limiter, None
            _set_shared(shared.restore_original_limits)


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

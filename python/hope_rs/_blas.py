"""One BLAS thread for small dense linear algebra.

OpenBLAS spreads even a 352 x 352 ``eigh`` over every core, and its spinning threads then compete
with rayon's, which slows such small problems many times over (docs/decisions.md#speed).
Large products keep all threads.
"""

from __future__ import annotations

import contextlib
import functools
import threading

from threadpoolctl import ThreadpoolController

_controller: ThreadpoolController | None = None
# The limit is process-wide: threads share one, set by the first to enter and restored by the
# last to leave (each restoring what it saw on entry left one thread for good, and lifted the
# limit under a solve still running).
_lock = threading.Lock()
_depth = 0
_limiter = None


def _blas_controller() -> ThreadpoolController:
    """One controller for the process: building one scans every loaded library, and a match
    sets BLAS limits many times (docs/decisions.md#speed)."""
    global _controller
    if _controller is None:
        # SciPy's wheels bring their own OpenBLAS; load it first so the controller sees it.
        import scipy.linalg  # noqa: F401

        _controller = ThreadpoolController()
    return _controller


@contextlib.contextmanager
def single_threaded_blas():
    """Context manager limiting BLAS (and the LAPACK on top of it) to one thread, until every
    thread inside it has left."""
    global _depth, _limiter
    with _lock:
        # Set from every thread that enters (as BLAS may read it per thread); the first
        # entry's limiter holds the limits to restore.
        limiter = _blas_controller().limit(limits=1, user_api="blas")
        if _depth == 0:
            _limiter = limiter
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0 and _limiter is not None:
                _limiter.restore_original_limits()
                _limiter = None


def with_single_threaded_blas(fn):
    """Decorator: ``fn`` runs inside :func:`single_threaded_blas`."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with single_threaded_blas():
            return fn(*args, **kwargs)

    return wrapper

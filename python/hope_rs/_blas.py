"""One BLAS thread for small dense linear algebra.

OpenBLAS spreads even a 352 x 352 ``eigh`` over every core, and its spinning threads then compete
with rayon's, which slows such small problems many times over (docs/decisions.md#speed).
Large products keep all threads.
"""

from __future__ import annotations

import functools

from threadpoolctl import ThreadpoolController

_controller: ThreadpoolController | None = None


def _blas_controller() -> ThreadpoolController:
    """One controller for the process: building one scans every loaded library, and a match
    sets BLAS limits many times (docs/decisions.md#speed)."""
    global _controller
    if _controller is None:
        # SciPy's wheels bring their own OpenBLAS; load it first so the controller sees it.
        import scipy.linalg  # noqa: F401

        _controller = ThreadpoolController()
    return _controller


def single_threaded_blas():
    """Context manager limiting BLAS (and the LAPACK on top of it) to one thread."""
    return _blas_controller().limit(limits=1, user_api="blas")


def with_single_threaded_blas(fn):
    """Decorator: ``fn`` runs inside :func:`single_threaded_blas`."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with single_threaded_blas():
            return fn(*args, **kwargs)

    return wrapper

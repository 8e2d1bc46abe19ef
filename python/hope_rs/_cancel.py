"""Stopping background work early: a flag the worker checks, and the exception that unwinds it.

The eigensolves of :class:`~hope_rs.pipeline.spectral.BasisPrefetch` run in a thread that Python cannot
interrupt; they check a :class:`threading.Event` at every step of the solver instead, so that
:func:`hope_rs.match` can stop them on any exit path (an error, Ctrl-C, a raising callback).
"""

from __future__ import annotations

import threading


class Cancelled(Exception):
    """A background solve stopped because its ``stop`` event was set. Never reaches the user:
    the thread that raises it catches it and ends."""


def check(stop: threading.Event | None) -> None:
    """Raise :class:`Cancelled` when ``stop`` is set."""
    if stop is not None and stop.is_set():
        raise Cancelled

"""SIGTERM (``kill``, ``timeout``, a scheduler or ``docker stop``) handled like Ctrl-C.

Python ends on SIGTERM without unwinding: no ``finally`` runs, so a batch would leave its
throw-away cache and marks folders behind and print no summary. While a command runs, the
signal raises :class:`Terminated` instead, a ``KeyboardInterrupt``, so every path that cleans
up after Ctrl-C cleans up after it too; the command then exits with 143 (128 + SIGTERM).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

#: The exit status after SIGTERM, as a shell reports a process it ended.
TERMINATED_STATUS = 128 + int(signal.SIGTERM)


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived while a command ran."""


def _raise_terminated(signum, frame) -> None:
    raise Terminated(f"signal {signum}")


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` in the main thread; the previous
    handler is restored after it. Outside the main thread (where Python cannot install a
    handler) a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def keep_sigterm(before) -> None:
    """Put :class:`Terminated` back as the SIGTERM handler when it was ``before`` (the handler
    read before a library, such as ``ray.init()``, installed its own)."""
    if before is _raise_terminated and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, before)


def interrupted_status(error: KeyboardInterrupt) -> int:
    """The exit status of a command ended by ``error``: 143 after SIGTERM, 130 after Ctrl-C."""
    return TERMINATED_STATUS if isinstance(error, Terminated) else 130

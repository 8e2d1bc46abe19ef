"""The ``hope-rs`` command."""

from .commands import main

__all__ = ["main"]

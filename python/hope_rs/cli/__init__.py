"""The ``hope-rs`` command."""

from .main import main

__all__ = ["main"]

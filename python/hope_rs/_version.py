"""The installed distribution's version."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("hope-rs")
except PackageNotFoundError:  # a source tree on sys.path without installed metadata
    __version__ = "0+unknown"

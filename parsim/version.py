"""The installed parsim's version: package metadata, or a marker in a source tree never installed."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("parsim")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"

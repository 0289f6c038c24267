"""parsim: piles and clusters of particles, simulated exactly and run as MPI ensembles."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("parsim")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"

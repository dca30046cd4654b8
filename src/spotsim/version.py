"""spotsim's version, as installed."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("spotsim")
except PackageNotFoundError:  # run from a source tree that was never installed
    __version__ = "unknown"

"""framechain: which hop of the pixel-to-world chain broke, which fault, how big."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("framechain")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]

"""The installed version of iloci (a leaf module: any module may import it)."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

__all__ = ["__version__"]

try:
    __version__ = version("iloci")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0+unknown"

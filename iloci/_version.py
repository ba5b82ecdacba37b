"""The installed version of iloci (a leaf module: any module may import it)."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version
import re

__all__ = ["__version__", "is_newer"]

try:
    __version__ = version("iloci")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0+unknown"


def is_newer(other: object, this: str | None = None) -> bool:
    """Whether version ``other`` (e.g. a memory file's ``"iloci"``) is newer than ``this``
    (default: this iloci's), by their leading numbers (``0.2.0 > 0.1.3``); False when
    either has none."""
    def key(v: object) -> tuple[int, ...] | None:
        m = re.match(r"\d+(?:\.\d+)*", str(v).strip())
        return tuple(int(x) for x in m.group(0).split(".")) if m else None

    a, b = key(other), key(this if this is not None else __version__)
    if a is None or b is None:
        return False
    n = max(len(a), len(b))
    return a + (0,) * (n - len(a)) > b + (0,) * (n - len(b))

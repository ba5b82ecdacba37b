"""iloci: Incremental Learning of Concepts by Imitation.

Public API::

    import iloci
    config = iloci.load_config("my.toml")   # or a dict, or None for defaults
    agent = iloci.build(config)

Plugins write ``from iloci import hookimpl``.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version as _version

from iloci.agent import Agent, build, preload
from iloci.config import Config, load_config
from iloci.hookspecs import hookimpl
from iloci.interfaces import Demonstration

try:
    __version__ = _version("iloci")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0+unknown"

__all__ = ["Agent", "Config", "Demonstration", "build", "hookimpl", "load_config",
           "preload", "__version__"]

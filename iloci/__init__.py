"""iloci: Incremental Learning of Concepts by Imitation.

Public API::

    import iloci
    config = iloci.load_config("my.toml")   # or a dict, or None for defaults
    agent = iloci.build(config)

Plugins write ``from iloci import hookimpl``.
"""

from __future__ import annotations

from iloci._version import __version__
from iloci.agent import Agent, build, preload
from iloci.config import Config, load_config
from iloci.hookspecs import hookimpl
from iloci.interfaces import Demonstration

__all__ = ["Agent", "Config", "Demonstration", "build", "hookimpl", "load_config",
           "preload", "__version__"]

"""Provenance of an evaluation: the versions and the machine it ran on (``metrics.json``)."""

from __future__ import annotations

import importlib.metadata as md
import os
import platform
import re
from typing import Any

from iloci.plugins import get_plugin_manager, plugin_infos

__all__ = ["machine", "versions"]


_NAME = re.compile(r"[A-Za-z0-9._-]+")


def versions(plugin_manager: Any = None) -> dict[str, str]:
    """Versions of Python, iloci, every plugin distribution and what each requires.

    The requirements are read from the distributions' metadata (extras
    included), so a third-party plugin and its libraries are listed as
    iloci's own are; a requirement that is not installed is left out.
    """
    pm = plugin_manager or get_plugin_manager()
    dists = ["iloci"] + sorted({i.distribution for i in plugin_infos(pm).values()
                                if i.distribution and i.distribution != "iloci"})
    names: list[str] = []
    for dist in dists:
        names.append(dist)
        try:
            names += [m.group(0) for r in md.requires(dist) or () if (m := _NAME.match(r))]
        except md.PackageNotFoundError:
            pass
    out = {"python": platform.python_version()}
    for name in dict.fromkeys(names):
        try:
            out[md.metadata(name)["Name"]] = md.version(name)
        except md.PackageNotFoundError:
            pass
    return out


def machine() -> dict[str, Any]:
    """The platform and CPU count this process runs on."""
    return {"platform": platform.platform(), "cpus": os.cpu_count()}

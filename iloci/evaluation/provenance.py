"""Provenance of an evaluation: the versions (with the git commit of a checkout) and the
machine it ran on (``metrics.json``)."""

from __future__ import annotations

import importlib.metadata as md
import os
from pathlib import Path
import platform
import re
import subprocess
from typing import Any

from iloci.plugins import get_plugin_manager, plugin_infos

__all__ = ["code_commit", "machine", "versions"]


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
    commit = code_commit()
    if commit:
        out["iloci_commit"] = commit
    return out


def code_commit(timeout: float = 2.0) -> str | None:
    """The git commit (40 hex digits) of the checkout iloci is imported from, or None.

    None when iloci is installed from a wheel (no ``.git`` beside the
    package), git is missing, slow (``timeout`` seconds) or fails: provenance
    never fails a run. Uncommitted changes are not recorded.
    """
    root = Path(__file__).resolve().parents[2]
    if not (root / ".git").exists():  # a folder, or a file in a git worktree
        return None
    try:
        res = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True,
                             text=True, timeout=timeout, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    sha = res.stdout.strip()
    return sha if res.returncode == 0 and re.fullmatch(r"[0-9a-f]{40}", sha) else None


def machine() -> dict[str, Any]:
    """The platform and CPU count this process runs on."""
    return {"platform": platform.platform(), "cpus": os.cpu_count()}

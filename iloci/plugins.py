"""The plugin manager: iloci's own plugins plus those installed as entry points.

Nothing happens at import time. :func:`get_plugin_manager` builds a fresh
manager; :func:`get_registry` asks every plugin to register its components.

Environment variables
---------------------
``ILOCI_DISABLE_PLUGIN_AUTOLOAD``
    Any non-empty value other than ``0``: do not load entry points of group
    ``iloci`` (only iloci's own plugins are registered).
``ILOCI_BLOCK_PLUGINS``
    Comma-separated plugin names (entry-point names, or ``iloci.teachers``
    for a built-in) not to register.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
import importlib
import importlib.metadata as md
import os
import warnings

import pluggy

from iloci import hookspecs
from iloci.errors import PluginError
from iloci.interfaces import COMPONENT_KINDS
from iloci.registry import Registry

__all__ = [
    "DEFAULT_PLUGINS",
    "ENTRY_POINT_GROUP",
    "PluginInfo",
    "PluginLoadWarning",
    "get_plugin_manager",
    "get_registry",
    "plugin_infos",
]

#: iloci's own plugins, registered through the same hooks as third-party ones.
DEFAULT_PLUGINS = ("iloci.teachers",)

#: Entry-point group third-party distributions register under.
ENTRY_POINT_GROUP = "iloci"

class PluginLoadWarning(UserWarning):
    """An installed plugin failed to import; it was skipped."""


@dataclass(frozen=True)
class PluginInfo:
    """Where a registered plugin came from."""

    name: str
    distribution: str | None
    version: str | None
    error: str | None = None


def _truthy(value: str | None) -> bool:
    return bool(value) and value.strip().lower() not in ("0", "false", "no", "")


def _blocked_from_env() -> set[str]:
    raw = os.environ.get("ILOCI_BLOCK_PLUGINS", "")
    return {p.strip() for p in raw.split(",") if p.strip()}


def get_plugin_manager(*, autoload: bool | None = None,
                       block: Iterable[str] = (),
                       plugins: Iterable[object] = ()) -> pluggy.PluginManager:
    """Build a plugin manager with iloci's hook specs and plugins.

    Parameters
    ----------
    autoload : bool, optional
        Load entry points of group ``iloci``. Defaults to true unless
        ``ILOCI_DISABLE_PLUGIN_AUTOLOAD`` is set.
    block : iterable of str
        Plugin names not to register, in addition to ``ILOCI_BLOCK_PLUGINS``.
    plugins : iterable of object
        Extra plugin objects (modules or instances with hook implementations)
        to register, e.g. from an embedding robot stack.

    Returns
    -------
    pluggy.PluginManager
        With attribute ``iloci_plugin_info`` (name -> :class:`PluginInfo`).

    Raises
    ------
    PluginError
        A plugin implements a hook that iloci does not specify (e.g. a
        misspelled hook name).
    """
    pm = pluggy.PluginManager(hookspecs.PROJECT)
    pm.add_hookspecs(hookspecs)
    blocked = set(block) | _blocked_from_env()
    for name in blocked:
        pm.set_blocked(name)
    info: dict[str, PluginInfo] = {}
    version = _own_version()
    for mod_name in DEFAULT_PLUGINS:
        if mod_name in blocked:
            continue
        pm.register(importlib.import_module(mod_name), name=mod_name)
        info[mod_name] = PluginInfo(mod_name, "iloci", version)
    if autoload is None:
        autoload = not _truthy(os.environ.get("ILOCI_DISABLE_PLUGIN_AUTOLOAD"))
    if autoload:
        for ep in sorted(md.entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
            if ep.name in blocked or pm.get_plugin(ep.name) is not None:
                continue
            dist = getattr(ep, "dist", None)
            dist_name = dist.metadata["Name"] if dist is not None else None
            dist_version = dist.version if dist is not None else None
            try:
                plugin = ep.load()
            except Exception as exc:  # a broken plugin must not break iloci
                msg = f"{type(exc).__name__}: {exc}"
                info[ep.name] = PluginInfo(ep.name, dist_name, dist_version, msg)
                warnings.warn(
                    f"iloci plugin {ep.name!r} (distribution {dist_name!r}) failed to "
                    f"import and was skipped: {msg}", PluginLoadWarning, stacklevel=2)
                continue
            pm.register(plugin, name=ep.name)
            info[ep.name] = PluginInfo(ep.name, dist_name, dist_version)
    for i, plugin in enumerate(plugins):
        name = getattr(plugin, "__name__", None) or f"extra-{i}"
        pm.register(plugin, name=name)
        info[name] = PluginInfo(name, None, None)
    try:
        pm.check_pending()
    except pluggy.PluginValidationError as exc:
        raise PluginError(
            f"{exc}. A plugin implements a hook that iloci does not define; check "
            "the spelling against `iloci.hookspecs` (hooks start with 'iloci_')."
        ) from None
    pm.iloci_plugin_info = info  # type: ignore[attr-defined]
    return pm


def _own_version() -> str | None:
    try:
        return md.version("iloci")
    except md.PackageNotFoundError:
        return None


def plugin_infos(pm: pluggy.PluginManager) -> dict[str, PluginInfo]:
    """Name -> :class:`PluginInfo` of every plugin the manager saw."""
    return dict(getattr(pm, "iloci_plugin_info", {}))


def get_registry(pm: pluggy.PluginManager | None = None) -> Registry:
    """Call every registration hook and return the filled registry.

    Each implementation is called with a registry view bound to its kind and
    to the plugin's name and distribution, so ``iloci plugins`` can say who
    registered what.
    """
    if pm is None:
        pm = get_plugin_manager()
    info = plugin_infos(pm)
    registry = Registry()
    for kind in COMPONENT_KINDS.values():
        caller = getattr(pm.hook, kind.hook)
        # Reverse pluggy's LIFO order so built-ins register first.
        for impl in reversed(caller.get_hookimpls()):
            pinfo = info.get(impl.plugin_name, PluginInfo(impl.plugin_name, None, None))
            view = registry.view(kind.name, plugin=impl.plugin_name,
                                 distribution=pinfo.distribution, version=pinfo.version)
            try:
                impl.function(**{arg: view for arg in impl.argnames})
            except PluginError:
                raise
            except Exception as exc:
                raise PluginError(
                    f"plugin {impl.plugin_name!r} failed in {caller.name}: "
                    f"{type(exc).__name__}: {exc}") from exc
    return registry

"""The plugin manager: iloci's own plugins plus those installed as entry points.

Nothing happens at import time. :func:`get_plugin_manager` builds a fresh
manager; :func:`get_registry` asks every plugin to register its components.

Environment variables
---------------------
``ILOCI_DISABLE_PLUGIN_AUTOLOAD``
    Any non-empty value other than ``0``, ``false`` or ``no``: load only iloci's own plugins, the
    built-ins and the first-party back-end distributions
    (:data:`FIRST_PARTY_DISTRIBUTIONS`: ``iloci-torch``, ``iloci-scipy``,
    ...); no third-party entry point of group ``iloci`` is loaded.
``ILOCI_BLOCK_PLUGINS``
    Comma-separated plugin names (entry-point names, or ``iloci.teachers``
    for a built-in) not to register.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
import importlib
import importlib.metadata as md
import os
import types
import warnings
from typing import Any

import pluggy

from iloci import hookspecs
from iloci.errors import IlociError, PluginError
from iloci.interfaces import ALL_KINDS
from iloci.registry import FIRST_PARTY, Registry, ambiguity

__all__ = [
    "DEFAULT_PLUGINS",
    "ENTRY_POINT_GROUP",
    "FIRST_PARTY_DISTRIBUTIONS",
    "PluginInfo",
    "PluginLoadWarning",
    "STATUSES",
    "get_plugin_manager",
    "get_registry",
    "hook_results",
    "plugin_infos",
]

#: iloci's own plugins, registered through the same hooks as third-party ones.
DEFAULT_PLUGINS = ("iloci.teachers", "iloci.evaluation.executors",
                   "iloci.sensorimotor.robots.presets")

#: Entry-point group third-party distributions register under.
ENTRY_POINT_GROUP = "iloci"

#: iloci's own back-end distributions (``plugins/`` in its repository), kept
#: when autoloading is off by ``ILOCI_DISABLE_PLUGIN_AUTOLOAD`` (or
#: ``autoload="first-party"``). Recognized by distribution name.
FIRST_PARTY_DISTRIBUTIONS = frozenset({
    # the back ends' (iloci.registry.FIRST_PARTY), and those adding commands or robots
    *FIRST_PARTY.values(), "iloci-ray", "iloci-robots", "iloci-ros",
})

class PluginLoadWarning(UserWarning):
    """An installed plugin failed to import or to register; it was skipped."""


#: :attr:`PluginInfo.status` values.
STATUSES = ("loaded", "failed", "blocked", "not autoloaded")


@dataclass(frozen=True)
class PluginInfo:
    """Where a plugin came from and whether it was loaded.

    Attributes
    ----------
    name : str
        Plugin name (the entry-point name; ``NAME@DISTRIBUTION`` for the
        second of two distributions with the same entry-point name).
    distribution, version : str or None
    error : str or None
        Why it failed, for ``status == "failed"``.
    status : str
        One of :data:`STATUSES`: ``"blocked"`` (``ILOCI_BLOCK_PLUGINS`` or
        ``block=``), ``"not autoloaded"`` (``ILOCI_DISABLE_PLUGIN_AUTOLOAD``
        or ``autoload=False``).
    """

    name: str
    distribution: str | None
    version: str | None
    error: str | None = None
    status: str = "loaded"

    @property
    def why_unloaded(self) -> str:
        """What to tell a user whose config needs this plugin's components."""
        dist = f" (distribution {self.distribution})" if self.distribution else ""
        if self.status == "blocked":
            return (f"plugin {self.name!r}{dist} is installed but blocked by "
                    "ILOCI_BLOCK_PLUGINS (or block=); unblock it to use its components")
        if self.status == "not autoloaded":
            return (f"plugin {self.name!r}{dist} is installed but was not loaded: plugin "
                    "autoloading is off (ILOCI_DISABLE_PLUGIN_AUTOLOAD, or autoload=False)")
        if self.status == "failed":
            return f"plugin {self.name!r}{dist} is installed but failed to load: {self.error}"
        return f"plugin {self.name!r}{dist} is loaded"


def _truthy(value: str | None) -> bool:
    return value is not None and value.strip().lower() not in ("0", "false", "no", "")


def _blocked_from_env() -> set[str]:
    raw = os.environ.get("ILOCI_BLOCK_PLUGINS", "")
    return {p.strip() for p in raw.split(",") if p.strip()}


def _warn(message: str) -> None:
    warnings.warn(message, PluginLoadWarning, stacklevel=3)


def _entry_points() -> list[tuple[str, md.EntryPoint, str | None, str | None]]:
    """(plugin name, entry point, distribution, version) of every ``iloci`` entry point.

    Entry points are sorted by name, then distribution. When two
    distributions use one entry-point name, the first keeps it and the
    others are named ``NAME@DISTRIBUTION``, with a warning naming both.
    """
    found = []
    for ep in md.entry_points(group=ENTRY_POINT_GROUP):
        dist = getattr(ep, "dist", None)
        dist_name = dist.metadata["Name"] if dist is not None else None
        found.append((ep, dist_name, dist.version if dist is not None else None))
    found.sort(key=lambda f: (f[0].name, f[1] or ""))
    out = []
    first: dict[str, tuple[str | None, str | None]] = {}
    for ep, dist_name, version in found:
        name = ep.name
        if name in first:
            name = f"{ep.name}@{dist_name}"
            other, other_version = first[ep.name]
            _warn(f"two distributions register an iloci plugin named {ep.name!r}: "
                  f"{other} {other_version} and {dist_name} {version}; both are loaded, the "
                  f"second as {name!r}. Block either with ILOCI_BLOCK_PLUGINS.")
        else:
            first[name] = (dist_name, version)
        out.append((name, ep, dist_name, version))
    return out


def _register_isolated(pm: pluggy.PluginManager, plugin: object, name: str) -> str | None:
    """Register ``plugin``; on a validation error unregister it and return the error."""
    if pm.get_plugin(name) is not None:
        return f"another plugin is already registered as {name!r}"
    try:
        pm.register(plugin, name=name)
        pm.check_pending()
    except (pluggy.PluginValidationError, ValueError) as exc:
        # pluggy adds hook implementations one by one: drop those it added
        if pm.get_plugin(name) is not None:
            pm.unregister(name=name)
        return f"{type(exc).__name__}: {exc}".replace("\n", " ")
    return None


def get_plugin_manager(*, autoload: bool | str | None = None,
                       block: Iterable[str] = (),
                       plugins: Iterable[object] = ()) -> pluggy.PluginManager:
    """Build a plugin manager with iloci's hook specs and plugins.

    A faulty installed plugin never breaks iloci: one that fails to import,
    or whose hooks do not match iloci's (a misspelt hook or argument name),
    is skipped with a :class:`PluginLoadWarning` and listed as failed by
    ``iloci plugins``. Two distributions with the same entry-point name are
    both loaded, with a warning naming both (see :func:`_entry_points`).

    Parameters
    ----------
    autoload : bool or "first-party", optional
        Load entry points of group ``iloci``: all of them (True), none
        (False), or only those of :data:`FIRST_PARTY_DISTRIBUTIONS`
        (``"first-party"``). Defaults to True, or to ``"first-party"`` when
        ``ILOCI_DISABLE_PLUGIN_AUTOLOAD`` is set.
    block : iterable of str
        Plugin names not to register, in addition to ``ILOCI_BLOCK_PLUGINS``.
        An entry-point name blocks every distribution using it.
    plugins : iterable of object
        Extra plugin objects (modules or instances with hook implementations)
        to register, e.g. from an embedding robot stack.

    Returns
    -------
    pluggy.PluginManager
        With attribute ``iloci_plugin_info`` (name -> :class:`PluginInfo`,
        blocked and not-autoloaded entry points included).

    Raises
    ------
    PluginError
        One of the given ``plugins`` implements a hook that iloci does not
        specify (e.g. a misspelled hook name), or misnames its arguments.
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
            info[mod_name] = PluginInfo(mod_name, "iloci", version, status="blocked")
            continue
        pm.register(importlib.import_module(mod_name), name=mod_name)
        info[mod_name] = PluginInfo(mod_name, "iloci", version)
    if autoload is None:
        autoload = ("first-party" if _truthy(os.environ.get("ILOCI_DISABLE_PLUGIN_AUTOLOAD"))
                    else True)
    if autoload not in (True, False, "first-party"):
        raise PluginError(f"autoload must be True, False or 'first-party', got {autoload!r}.")
    for name, ep, dist_name, dist_version in _entry_points():
        if ep.name in blocked or name in blocked:
            info[name] = PluginInfo(name, dist_name, dist_version, status="blocked")
            continue
        if not autoload or (autoload == "first-party"
                            and dist_name not in FIRST_PARTY_DISTRIBUTIONS):
            info[name] = PluginInfo(name, dist_name, dist_version, status="not autoloaded")
            continue
        try:
            plugin = ep.load()
        except (Exception, SystemExit) as exc:  # a broken plugin must not break iloci
            # (a module that calls sys.exit() on import ended every command, no name said)
            msg = f"{type(exc).__name__}: {exc}"
            info[name] = PluginInfo(name, dist_name, dist_version, msg, "failed")
            _warn(f"iloci plugin {name!r} (distribution {dist_name!r}) failed to "
                  f"import and was skipped: {msg}")
            continue
        if pm.is_registered(plugin):  # two entry points naming one module
            other = pm.get_name(plugin)
            _warn(f"iloci plugin {name!r} (distribution {dist_name!r}) is the same object "
                  f"as plugin {other!r}; it is registered once, as {other!r}.")
            continue
        error = _register_isolated(pm, plugin, name)
        if error is not None:
            info[name] = PluginInfo(name, dist_name, dist_version, error, "failed")
            _warn(f"iloci plugin {name!r} (distribution {dist_name!r}) does not match "
                  f"iloci's hooks and was skipped: {error}. Check its hook and argument "
                  "names against `iloci.hookspecs`.")
            continue
        info[name] = PluginInfo(name, dist_name, dist_version)
        unmarked = _unmarked(pm, plugin)
        if unmarked:  # pluggy passes them over: never called, without a word
            _warn(f"iloci plugin {name!r} (distribution {dist_name!r}) defines "
                  f"{', '.join(unmarked)} without @iloci.hookimpl: iloci never calls "
                  f"{'it' if len(unmarked) == 1 else 'them'}. Mark each hook with "
                  "@iloci.hookimpl (docs/hooks.md).")
    if isinstance(plugins, (str, bytes)) or not isinstance(plugins, Iterable):
        raise PluginError(f"plugins must be a list of plugin objects (modules or instances "
                          f"with @iloci.hookimpl methods), got {type(plugins).__name__}: "
                          "write plugins=[it].")
    for i, plugin in enumerate(plugins):
        name = getattr(plugin, "__name__", None) or f"extra-{i}"
        if isinstance(plugin, type):
            raise PluginError(f"plugins[{i}] is the class {plugin.__qualname__}, not an "
                              f"instance of it: its hook methods would be called without "
                              f"self. Pass {plugin.__qualname__}() instead.")
        if pm.is_registered(plugin):
            raise PluginError(f"plugins[{i}] ({_short_repr(plugin)}) is given twice (or is "
                              "a plugin already registered); give each plugin once.")
        unmarked = _unmarked(pm, plugin)
        if unmarked:  # pluggy would pass them over: never called, without a word
            raise PluginError(f"plugins[{i}] ({_short_repr(plugin)}) has "
                              f"{', '.join(unmarked)} without @iloci.hookimpl: iloci would "
                              "never call it. Mark each hook method with @iloci.hookimpl.")
        try:
            pm.register(plugin, name=name)
            pm.check_pending()
        except pluggy.PluginValidationError as exc:
            raise PluginError(
                f"{exc}. A plugin implements a hook that iloci does not define, or names "
                "its arguments differently; check the spelling against `iloci.hookspecs` "
                "(hooks start with 'iloci_')."
            ) from None
        info[name] = PluginInfo(name, None, None)
    pm.iloci_plugin_info = info  # type: ignore[attr-defined]
    return pm


def _unmarked(pm: pluggy.PluginManager, plugin: object) -> list[str]:
    """The ``iloci_*`` callables of ``plugin`` that pluggy does not take for hooks (no
    ``@iloci.hookimpl``); in a module, only those it defines (not ones it imports)."""
    module = getattr(plugin, "__name__", None) if isinstance(plugin, types.ModuleType) else None
    out = []
    for a in dir(plugin):
        obj = getattr(plugin, a, None)
        if not a.startswith("iloci_") or not callable(obj) or isinstance(obj, type):
            continue
        if module is not None and getattr(obj, "__module__", module) != module:
            continue
        if pm.parse_hookimpl_opts(plugin, a) is None:
            out.append(a)
    return out


def _short_repr(obj: object) -> str:
    text = repr(obj)
    return text if len(text) <= 60 else text[:57] + "..."


def _own_version() -> str | None:
    try:
        return md.version("iloci")
    except md.PackageNotFoundError:
        return None


def plugin_infos(pm: pluggy.PluginManager) -> dict[str, PluginInfo]:
    """Name -> :class:`PluginInfo` of every plugin the manager saw."""
    return dict(getattr(pm, "iloci_plugin_info", {}))


def hook_results(pm: pluggy.PluginManager, hook: str, *, only: str | None = None,
                 **kwargs: Any) -> Iterator[tuple[Any, str, str | None]]:
    """Call hook ``hook`` one implementation at a time, in pluggy's order (the last
    registered first); yield ``(result, plugin, distribution)`` for each non-None result.
    ``only``: call only that plugin's implementation.

    For hooks whose result iloci uses (``iloci_make_executor``) or that act
    (``iloci_add_commands``): a result of the wrong type can then be refused naming
    the plugin and its distribution.

    Raises
    ------
    PluginError
        An implementation raised anything but an iloci error: naming the plugin, its
        distribution and the hook, and what to do (the original is the cause).
    """
    info = getattr(pm, "iloci_plugin_info", {}) or {}
    caller = getattr(pm.hook, hook)
    for impl in reversed(caller.get_hookimpls()):
        if only is not None and impl.plugin_name != only:
            continue
        pinfo = info.get(impl.plugin_name)
        dist = getattr(pinfo, "distribution", None)
        try:
            result = impl.function(**{arg: kwargs[arg] for arg in impl.argnames})
        except IlociError:
            raise
        except Exception as exc:
            raise PluginError(
                f"plugin {impl.plugin_name!r} (distribution {dist or 'none'}) failed in "
                f"{hook}: {type(exc).__name__}: {exc}. Fix or update the plugin, or block "
                f"it with ILOCI_BLOCK_PLUGINS={impl.plugin_name}.") from exc
        if result is not None:
            yield result, impl.plugin_name, dist


def get_registry(pm: pluggy.PluginManager | None = None) -> Registry:
    """Call every registration hook and return the filled registry.

    Each implementation is called with a registry view bound to its kind and
    to the plugin's name and distribution, so ``iloci plugins`` can say who
    registered what.
    """
    if pm is None:
        pm = get_plugin_manager()
    info = getattr(pm, "iloci_plugin_info", None)
    if info is None:
        info = pm.iloci_plugin_info = {}  # type: ignore[attr-defined]
    registry = Registry()
    failed: set[str] = set()
    for kind in ALL_KINDS.values():
        caller = getattr(pm.hook, kind.hook)
        # registration order: built-ins first, then installed plugins, then the
        # caller's, so a name registered twice is blamed on the later plugin
        for impl in caller.get_hookimpls():
            if impl.plugin_name in failed:
                continue
            pinfo = info.get(impl.plugin_name, PluginInfo(impl.plugin_name, None, None))
            view = registry.view(kind.name, plugin=impl.plugin_name,
                                 distribution=pinfo.distribution, version=pinfo.version)
            try:
                if "robots" in impl.argnames:  # the deprecated dict form
                    returned = _register_robot_dict(impl, view, pinfo)
                else:
                    returned = impl.function(**{arg: view for arg in impl.argnames})
                if returned is not None:
                    raise PluginError(
                        f"plugin {impl.plugin_name!r} (distribution "
                        f"{pinfo.distribution or 'none'}): its {caller.name} returned "
                        f"{type(returned).__name__} {returned!r:.60}, but a registration hook "
                        "returns nothing: it registers each component with "
                        "registry.add(name, factory, ...) (see docs/writing-a-plugin.md)")
            except Exception as exc:
                error = exc if isinstance(exc, PluginError) else PluginError(
                    f"plugin {impl.plugin_name!r} failed in {caller.name}: "
                    f"{type(exc).__name__}: {exc}")
                if pinfo.distribution is None or pinfo.distribution == "iloci":
                    # a plugin object the caller passed, or iloci's own: their bug
                    if error is exc:
                        raise
                    raise error from exc
                # an installed plugin: skip it, keep the rest working
                failed.add(impl.plugin_name)
                registry.remove_plugin(impl.plugin_name)
                info[impl.plugin_name] = PluginInfo(pinfo.name, pinfo.distribution,
                                                    pinfo.version, str(error), "failed")
                _warn(f"iloci plugin {impl.plugin_name!r} (distribution "
                      f"{pinfo.distribution!r}) failed to register its components and was "
                      f"skipped: {error}")
    registry.unloaded = [i for i in info.values() if i.status != "loaded"]
    for (kind_name, name), claims in registry.ambiguous.items():
        _warn(ambiguity(kind_name, name, claims))
    return registry


def _register_robot_dict(impl: Any, view: Any, pinfo: PluginInfo) -> Any:
    """Call an ``iloci_register_robots(robots)`` of the old, dict form; register what it added.

    Deprecated (a :class:`DeprecationWarning` names the plugin): the dict
    starts empty, and each value it adds must quack like a
    :class:`~iloci.sensorimotor.robots.RobotPreset` (``make``, ``summary``,
    ``joints``, ``plane``); it is registered as if by ``registry.add``, so
    provenance, collisions and listings are the registry's.
    """
    dist = f" (distribution {pinfo.distribution})" if pinfo.distribution else ""
    warnings.warn(
        f"iloci plugin {impl.plugin_name!r}{dist} registers robots through "
        "iloci_register_robots(robots), a dict: deprecated. Write "
        "iloci_register_robots(registry) and call registry.add(name, factory, summary=..., "
        "joints=J, plane='given' or 'auto') (docs/hooks.md).", DeprecationWarning, stacklevel=4)
    robots: dict[str, Any] = {}
    returned = impl.function(**{arg: robots if arg == "robots" else view
                                for arg in impl.argnames})
    for name, preset in robots.items():
        if not callable(getattr(preset, "make", None)) or not isinstance(
                getattr(preset, "joints", None), int):
            raise PluginError(
                f"plugin {impl.plugin_name!r}{dist}: its iloci_register_robots added "
                f"{name!r}: {type(preset).__name__}; it must add RobotPreset objects to the "
                "dict it receives (robots[name] = RobotPreset(...)) and return nothing. Fix "
                f"the plugin, or block it with ILOCI_BLOCK_PLUGINS={impl.plugin_name}.")
        view.add(name, preset.make, summary=getattr(preset, "summary", ""),
                 joints=preset.joints, plane=getattr(preset, "plane", "given"))
    return returned

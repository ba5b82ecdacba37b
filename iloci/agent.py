"""The Agent: assembled components plus the robot's memory; the library's face."""

from __future__ import annotations

from typing import Any

import pluggy

from iloci.config import Config, load_config
from iloci.plugins import get_plugin_manager, get_registry
from iloci.registry import Registry

__all__ = ["Agent", "build"]


class Agent:
    """A robot that learns concepts by imitation.

    Built by :func:`build` from a :class:`~iloci.config.Config`. Holds one
    instance of each configured component.

    Attributes
    ----------
    config : Config
    perceptual_model : PerceptualModel
    clusterer : Clusterer
    teacher : Teacher
    ik_solver : IKSolver
    simulator : Simulator or None
    plugin_manager : pluggy.PluginManager
        Observer hooks (``iloci_on_*``) are called through it.
    """

    def __init__(self, config: Config, components: dict[str, Any],
                 plugin_manager: pluggy.PluginManager, registry: Registry) -> None:
        self.config = config
        self.plugin_manager = plugin_manager
        self.registry = registry
        self.perceptual_model = components["perceptual_model"]
        self.clusterer = components["clusterer"]
        self.teacher = components["teacher"]
        self.ik_solver = components["ik"]
        self.simulator = components.get("simulator")

    def __repr__(self) -> str:
        c = self.config
        return (f"Agent(perceptual_model={c.perceptual_model.name!r}, "
                f"clusterer={c.clusterer.name!r}, teacher={c.teacher.name!r}, "
                f"ik={c.ik.name!r}, simulator={c.simulator.name!r})")


def build(config: Any = None, *, plugin_manager: pluggy.PluginManager | None = None,
          **overrides: Any) -> Agent:
    """Assemble an :class:`Agent` from a config.

    Parameters
    ----------
    config : Config, path, mapping or None
        Anything :func:`~iloci.config.load_config` takes; ``None`` for the
        defaults (the paper's settings).
    plugin_manager : pluggy.PluginManager, optional
        Defaults to :func:`~iloci.plugins.get_plugin_manager`.
    **overrides
        Component instances to use instead of building them from the config,
        by section name (``teacher=my_teacher``, ``ik=my_solver``): how an
        embedding robot stack plugs in its own objects.

    Raises
    ------
    ConfigError, UnknownComponentError
        Invalid config (before anything heavy is imported).
    MissingBackendError
        A configured back end is not installed (names the pip command).
    """
    pm = plugin_manager or get_plugin_manager()
    registry = get_registry(pm)
    cfg = load_config(config, registry=registry)
    from iloci.config import COMPONENT_SECTIONS
    unknown = set(overrides) - set(COMPONENT_SECTIONS)
    if unknown:
        from iloci.errors import ConfigError
        raise ConfigError(f"build() got unknown component override(s) {sorted(unknown)}; "
                          f"valid: {', '.join(COMPONENT_SECTIONS)}.")
    components: dict[str, Any] = {}
    for sec, kind in COMPONENT_SECTIONS.items():
        if sec in overrides:
            components[sec] = overrides[sec]
            continue
        cc = getattr(cfg, sec)
        if cc.name == "none":
            components[sec] = None
            continue
        components[sec] = registry.build(kind, cc.name, cc.params, seed=cfg.seed)
    return Agent(cfg, components, pm, registry)

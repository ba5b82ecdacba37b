"""Assembling an agent's parts from a config: one place, one robot, its plane placed once.

:func:`assemble` is the one assembly of an agent: the config read and
validated, the component objects built through the registry, the robot read
and its drawing plane placed by
:func:`~iloci.sensorimotor.robots.assembly.robot_and_ik` (robot -> IK ->
place the plane -> IK again). :func:`~iloci.agent.build` and
:meth:`Agent.load <iloci.agent.Agent.load>` construct their agent from what
it returns; :func:`iloci.drawing.load_drawing_parts`, ``iloci show`` and
``iloci robots``, which need no agent, place their robot through
``robot_and_ik`` too.
"""

from __future__ import annotations

from collections.abc import Mapping
import dataclasses
from typing import Any, NamedTuple

import numpy as np
import pluggy

from iloci.config import Config, load_config
from iloci.errors import ConfigError, InvalidInputError, NotLoadedError
from iloci.interfaces import COMPONENT_KINDS, unmet_members
from iloci.plugins import get_plugin_manager, get_registry
from iloci.registry import Registry
from iloci.sensorimotor.encoding import feature_names
from iloci.sensorimotor.robots import robot_and_ik

__all__ = ["PURPOSES", "NotLoaded", "Parts", "assemble", "preload", "size_network",
           "check_overrides"]


#: What each use of a saved memory needs (:meth:`Agent.load`'s ``purpose``):
#: recognition encodes a demonstration's motion (the IK solver) and finds its
#: PB (the perceptual model); it never clusters, asks a teacher or executes.
PURPOSES: dict[str, tuple[str, ...]] = {
    "recognize": ("perceptual_model", "ik"),
    "learn": ("perceptual_model", "clusterer", "teacher", "ik", "simulator"),
}


class NotLoaded:
    """Stands in for a component :meth:`Agent.load` did not build for its purpose.

    Any use raises :class:`~iloci.errors.NotLoadedError` naming the section
    and what to do (load the memory for learning).
    """

    def __init__(self, section: str, purpose: str, path: str) -> None:
        self._section = section
        self._purpose = purpose
        self._path = path

    def __repr__(self) -> str:
        return f"NotLoaded({self._section!r})"

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        raise NotLoadedError(
            f"the {self._section} was not loaded: the memory {self._path} was loaded for "
            f"{self._purpose!r}, which does not need it. Load it with "
            f"iloci.Agent.load({self._path!r}) (purpose='learn') to keep learning.")


class Parts(NamedTuple):
    """What :func:`assemble` makes: the arguments of :class:`~iloci.agent.Agent`."""

    config: Config
    #: section -> component object (None for a left-out simulator), and
    #: ``"robot"`` -> the :class:`~iloci.sensorimotor.robots.Robot`, plane placed.
    components: dict[str, Any]
    plugin_manager: pluggy.PluginManager
    registry: Registry


def preload(config: Any = None, *, plugin_manager: pluggy.PluginManager | None = None
            ) -> tuple[str, ...]:
    """Import the configured components' back ends now, building nothing.

    ``import iloci`` imports no back end; :func:`~iloci.agent.build` imports the
    configured ones (torch, pinocchio, ...), and a native library's import
    holds the GIL for its whole loading (torch: 0.3 to 1 s), stalling every
    other thread of the process. A program with a control loop calls this
    before the loop starts, so that building and loading later, in any
    thread, imports nothing heavy (see docs/embedding.md, "Keeping a control
    loop on time").

    Parameters
    ----------
    config, plugin_manager
        As for :func:`~iloci.agent.build`.

    Returns
    -------
    tuple of str
        ``"section=name"`` of each component whose back end was imported.

    Raises
    ------
    ConfigError, UnknownComponentError, MissingBackendError
        As :func:`~iloci.agent.build`.
    """
    pm = plugin_manager or get_plugin_manager()
    registry = get_registry(pm)
    cfg = load_config(config, registry=registry)
    done = []
    for sec in COMPONENT_KINDS:
        name = getattr(cfg, sec).name
        if name == "none":
            continue
        registry.load_factory(registry.get(sec, name))
        done.append(f"{sec}={name}")
    return tuple(done)


def assemble(config: Any = None, plugin_manager: pluggy.PluginManager | None = None,
             overrides: Mapping[str, Any] | None = None) -> Parts:
    """An agent's parts: config, components, robot (plane placed once), plugins.

    What :func:`~iloci.agent.build` does, short of constructing the
    :class:`~iloci.agent.Agent`; see it for the parameters and errors.
    ``overrides`` may hold :class:`NotLoaded` stand-ins
    (:meth:`Agent.load <iloci.agent.Agent.load>` for recognition).
    """
    overrides = dict(overrides or {})
    unknown = set(overrides) - set(COMPONENT_KINDS)
    if unknown:
        raise ConfigError(f"build() got unknown component override(s) {sorted(unknown)}; "
                          f"valid: {', '.join(COMPONENT_KINDS)}.")
    check_overrides({sec: obj for sec, obj in overrides.items()
                     if not isinstance(obj, NotLoaded)})
    if plugin_manager is not None and not isinstance(plugin_manager, pluggy.PluginManager):
        raise InvalidInputError(f"plugin_manager must be a pluggy.PluginManager (from "
                                f"iloci.plugins.get_plugin_manager), got "
                                f"{type(plugin_manager).__name__}.")
    pm = plugin_manager or get_plugin_manager()
    registry = get_registry(pm)
    cfg = load_config(config, registry=registry, supplied=overrides)

    def make(sec: str, robot: Any) -> Any:
        cc = getattr(cfg, sec)
        if cc.name == "none":
            return None
        # the robot goes to the components that draw with it
        extra = {"robot": robot} if sec in ("ik", "simulator") else {}
        return registry.build(sec, cc.name, cc.params, seed=cfg.seed,
                              **extra)

    def sized(robot: Any) -> None:  # before the plane search: fails fast
        nonlocal cfg
        cfg = size_network(cfg, robot, overrides)

    robot, ik = robot_and_ik(cfg.robot, lambda r: make("ik", r), plugin_manager=pm,
                             ik=overrides.get("ik"), before_placing=sized)
    check_ik_limits(ik, robot)
    components: dict[str, Any] = {}
    for sec in COMPONENT_KINDS:
        if sec in overrides:
            components[sec] = overrides[sec]
        elif sec == "ik":
            components[sec] = ik
        else:
            components[sec] = make(sec, robot)
    components["robot"] = robot
    return Parts(cfg, components, pm, registry)


def check_ik_limits(ik: Any, robot: Any) -> None:
    """Refuse an IK solver whose joints and limits do not describe the robot's arm.

    A caller's solver with 3 limits for 4 joints, or a lower limit above its
    upper one, was taken by :func:`build` and failed at the first learning
    inside numpy (or never kept its arm within limits).

    Raises
    ------
    InvalidInputError
        Naming the solver and what is wrong.
    """
    who = f"the IK solver {type(ik).__qualname__}"
    joints = len(robot.joint_names)
    names = tuple(getattr(ik, "joint_names", ()) or ())
    try:
        lo = np.asarray(ik.lower, dtype=np.float64).reshape(-1)
        hi = np.asarray(ik.upper, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError, AttributeError):
        raise InvalidInputError(f"{who}: lower and upper must be arrays of numbers, one "
                                f"per joint ({joints}).") from None
    if names and len(names) != joints or len(lo) != joints or len(hi) != joints:
        raise InvalidInputError(
            f"{who} describes {len(names) or '?'} joint(s) with {len(lo)} lower and "
            f"{len(hi)} upper limit(s), but robot {robot.name!r} has {joints} "
            f"({', '.join(robot.joint_names)}): one name and one limit each per joint.")
    bad = np.flatnonzero(~(lo <= hi))  # NaN too
    if bad.size:
        j = int(bad[0])
        raise InvalidInputError(f"{who}: joint {robot.joint_names[j]!r} has lower limit "
                                f"{lo[j]:g} above its upper limit {hi[j]:g} (rad or m).")


def size_network(cfg: Config, robot: Any, overrides: Mapping[str, Any] | None = None
                 ) -> Config:
    """The config with the perceptual model's ``input_size`` set to the robot's 2 + J.

    Parameters
    ----------
    cfg : Config
    robot : Robot
    overrides : mapping, optional
        Component objects given to :func:`build`; a given perceptual model
        must take 2 + J inputs.

    Raises
    ------
    ConfigError
        ``[perceptual_model] input_size`` is set and is not the robot's
        2 + J features per step (:func:`~iloci.sensorimotor.encoding.feature_names`).
    InvalidInputError
        A given perceptual model takes another number of inputs.
    """
    overrides = overrides or {}
    names = feature_names(len(robot.joint_names))
    width = len(names)
    if "perceptual_model" in overrides:
        got = getattr(overrides["perceptual_model"], "input_size", width)
        if got != width:
            raise InvalidInputError(
                f"the perceptual model given to build() takes {got} inputs; robot "
                f"{robot.name!r} needs 2 + {len(robot.joint_names)} = {width}.")
        return cfg
    params = cfg.perceptual_model.params
    if params is None or not hasattr(params, "input_size") or params.input_size == width:
        return cfg
    default = next((f.default for f in dataclasses.fields(params)
                    if f.name == "input_size"), None)
    if params.input_size != default:
        raise ConfigError(
            f"perceptual_model.input_size is {params.input_size}, but robot {robot.name!r} "
            f"gives every encoded demonstration {width} features per step "
            f"({', '.join(names)}): set it to {width} or leave it out (it is sized "
            "from the robot).", source=cfg.source, key="perceptual_model.input_size")
    sized = dataclasses.replace(params, input_size=width)
    return dataclasses.replace(
        cfg, perceptual_model=dataclasses.replace(cfg.perceptual_model, params=sized))


def check_overrides(overrides: dict[str, Any]) -> None:
    """Raise one InvalidInputError for every override that is not a component."""
    problems = []
    for sec, obj in overrides.items():
        kind = COMPONENT_KINDS[sec]
        protocol = kind.protocol
        where = f"iloci.interfaces.{protocol.__name__}"
        label = kind.label
        a_label = ("an " if label[0].lower() in "aeiou" else "a ") + label
        if obj is None:
            if not kind.optional:
                problems.append(f"{sec}=None: {a_label} is required (only simulator=None "
                                "is allowed)")
        elif isinstance(obj, type):
            problems.append(f"{sec}={obj.__name__} is a class; pass an instance, "
                            f"{obj.__name__}(...), implementing {where}")
        else:
            unmet = unmet_members(obj, protocol)
            if unmet:
                problems.append(f"{sec}={type(obj).__name__}(...) is not {a_label}: it lacks "
                                f"{', '.join(unmet)} (see {where})")
    if problems:
        raise InvalidInputError("build() got component object(s) it cannot use: "
                                + "; ".join(problems) + ".")



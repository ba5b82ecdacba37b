"""Robot presets by name: the Nao's right arm ships with iloci, plugins add more.

Robots are a kind of the registry (``robot``, :data:`iloci.interfaces.EXTRA_KINDS`),
like the components: a plugin's ``iloci_register_robots(registry)`` calls
``registry.add(name, factory, summary=..., joints=J, plane="given" | "auto")``;
the registry records the plugin and its distribution, refuses a name
registered twice (naming both plugins), and ``iloci plugins`` and ``iloci
robots`` list them. This module is also the plugin that registers the Nao.
:func:`get_robot` makes one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from importlib import resources
from pathlib import Path
from typing import Any

from iloci.hookspecs import hookimpl
from iloci.plugins import get_plugin_manager, get_registry
from iloci.registry import KindRegistry
from iloci.sensorimotor.robots.model import DrawingPlane, Robot, _frozen
from iloci.sensorimotor.robots.urdf import kinematics_fingerprint

__all__ = ["NAO_PLANE", "NAO_Q_HOME", "ROBOTS", "RobotPreset", "available_robots", "get_robot"]


@dataclass(frozen=True)
class RobotPreset:
    """A named robot: how to describe it, and a one-line summary (a registry entry's view).

    Attributes
    ----------
    name : str
    make : callable () -> Robot
        Builds the description (may raise MissingBackendError when the
        files it needs are not installed); for a registered robot,
        the registry's build (its factory's result checked).
    summary : str
    joints : int
        ``J``.
    source : str
        Distribution providing it (``"iloci"`` for the built-in one; the
        registry's record of the plugin's distribution).
    plane : str
        ``"given"`` or ``"auto"`` (placed by the search when built).
    plugin : str
        The plugin that registered it (the registry's record).
    """

    name: str
    make: Callable[[], Robot]
    summary: str
    joints: int
    source: str = "iloci"
    plane: str = "given"
    plugin: str = "iloci"


def nao_v32_right_arm() -> Robot:
    """The Nao V3.2's right arm, the paper's robot: 4 joints, pen tip ``r_pen_tip``."""
    path = Path(str(resources.files("iloci.sensorimotor.robots") / "nao_v32_right_arm.urdf"))
    # limits as in the URDF (docs/method.md, "The robot"), rad
    lower = _frozen([-2.0856685, -1.6493361, -2.0856685, 0.0087266])
    upper = _frozen([2.0856685, -0.0087266, 2.0856685, 1.5620696])
    return Robot(
        name="nao-v32-right-arm",
        urdf_path=path,
        joint_names=("RShoulderPitch", "RShoulderRoll", "RElbowYaw", "RElbowRoll"),
        lower=lower,
        upper=upper,
        end_effector_frame="r_pen_tip",
        q_home=_frozen(NAO_Q_HOME),
        plane=NAO_PLANE,
        fixed_joints={"RWristYaw": 0.0},
        # once per robot, not at every save of a memory (persistence.robot_record)
        kinematics=kinematics_fingerprint(path, "torso", "r_pen_tip"),
    )


#: The Nao's drawing plane (m, torso frame): a 10 cm square 16.5 cm in front
#: of the torso, centred 2.7 cm outside and level with the right shoulder
#: (shoulder at y = -0.098, z = 0.100). Chosen by a grid search over centres
#: maximising the smallest joint-limit margin of the rectangle grown by 1 cm.
NAO_PLANE = DrawingPlane(x=0.165, y=-0.125, z=0.10, width=0.10, height=0.10)
#: Nao start posture (rad): pen tip at the plane centre (within 1e-7 m);
#: about (-5.2, -46.1, 0.5, 66.4) degrees.
NAO_Q_HOME = (-0.091452, -0.804138, 0.008353, 1.159141)

#: The built-in robots: name -> preset (registered by :func:`iloci_register_robots`
#: below). Plugins add more (see :func:`available_robots`).
ROBOTS: dict[str, RobotPreset] = {
    "nao-v32-right-arm": RobotPreset(
        "nao-v32-right-arm", nao_v32_right_arm,
        "Nao V3.2 right arm (the paper's robot), primitive geometry, 10 cm plane", 4),
}


@hookimpl
def iloci_register_robots(registry: KindRegistry) -> None:
    """Register the built-in robots (:data:`ROBOTS`)."""
    for p in ROBOTS.values():
        registry.add(p.name, p.make, summary=p.summary, joints=p.joints, plane=p.plane)


def available_robots(plugin_manager: Any = None) -> dict[str, RobotPreset]:
    """Every robot preset the registry holds: the built-in ones and those plugins register.

    Parameters
    ----------
    plugin_manager : pluggy.PluginManager, optional
        Default: :func:`iloci.plugins.get_plugin_manager`.

    Returns
    -------
    dict
        Name -> :class:`RobotPreset`, sorted by name; ``make`` builds
        through the registry.

    Raises
    ------
    PluginError
        A plugin the caller passed registers a robot badly (a name taken,
        a missing fact, not a preset); an installed plugin that does is
        skipped with a warning instead (see :func:`iloci.plugins.get_registry`).
    """
    registry = get_registry(plugin_manager or get_plugin_manager())
    return {s.name: RobotPreset(s.name, partial(registry.build, "robot", s.name), s.summary,
                                s.fact("joints"), s.distribution or "none", s.fact("plane"),
                                s.plugin)
            for s in registry.specs("robot")}


def get_robot(name: str = "nao-v32-right-arm", plugin_manager: Any = None) -> Robot:
    """The preset robot registered under ``name``, built through the registry.

    A preset whose plane is ``"auto"`` comes with its placeholder plane:
    :func:`robot_from_config` (what :func:`iloci.build` uses) places it.
    Without ``plugin_manager`` a built-in robot (:data:`ROBOTS`) is made
    without loading the plugins.

    Raises
    ------
    UnknownComponentError
        No such robot (lists the known names, did you mean).
    MissingBackendError
        A first-party preset whose plugin is not installed (``panda``,
        ``ur5``: ``iloci-robots``), or whose files are not installed.
    PluginNotLoadedError
        Its plugin is installed but blocked or not loaded.
    """
    if plugin_manager is None and isinstance(name, str) and name in ROBOTS:
        robot: Robot = ROBOTS[name].make()
        return robot
    return get_registry(plugin_manager or get_plugin_manager()).build("robot", str(name))

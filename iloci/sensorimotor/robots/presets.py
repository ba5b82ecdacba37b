"""Robot presets by name: the Nao's right arm ships with iloci, plugins add more
(``iloci_register_robots``); :func:`get_robot` makes one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Any

from iloci.errors import PluginError, UnknownComponentError
from iloci.plugins import get_plugin_manager
from iloci.sensorimotor.robots.model import DrawingPlane, Robot, _frozen

__all__ = ["NAO_PLANE", "NAO_Q_HOME", "ROBOTS", "RobotPreset", "available_robots", "get_robot"]


@dataclass(frozen=True)
class RobotPreset:
    """A named robot a plugin ships: how to describe it, and a one-line summary.

    Attributes
    ----------
    name : str
    make : callable () -> Robot
        Builds the description (may raise MissingBackendError when the
        files it needs are not installed).
    summary : str
    joints : int
        ``J``.
    source : str
        Distribution providing it (``"iloci"`` for the built-in one).
    plane : str
        ``"given"`` or ``"auto"`` (placed by the search when built).
    plugin : str
        The plugin that registered it (set by :func:`available_robots`).
    """

    name: str
    make: Callable[[], Robot]
    summary: str
    joints: int
    source: str = "iloci"
    plane: str = "given"
    plugin: str = "iloci"


def _nao_v32_right_arm() -> Robot:
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
    )


#: The Nao's drawing plane (m, torso frame): a 10 cm square 16.5 cm in front
#: of the torso, centred 2.7 cm outside and level with the right shoulder
#: (shoulder at y = -0.098, z = 0.100). Chosen by a grid search over centres
#: maximising the smallest joint-limit margin of the rectangle grown by 1 cm.
NAO_PLANE = DrawingPlane(x=0.165, y=-0.125, z=0.10, width=0.10, height=0.10)
#: Nao start posture (rad): pen tip at the plane centre (within 1e-7 m);
#: about (-5.2, -46.1, 0.5, 66.4) degrees.
NAO_Q_HOME = (-0.091452, -0.804138, 0.008353, 1.159141)

#: The built-in robots: name -> preset. Plugins add more (see :func:`available_robots`).
ROBOTS: dict[str, RobotPreset] = {
    "nao-v32-right-arm": RobotPreset(
        "nao-v32-right-arm", _nao_v32_right_arm,
        "Nao V3.2 right arm (the paper's robot), primitive geometry, 10 cm plane", 4),
}


def available_robots(plugin_manager: Any = None) -> dict[str, RobotPreset]:
    """Every robot preset: the built-in ones and those plugins register.

    Plugins implement the ``iloci_register_robots(robots)`` hook and add
    :class:`RobotPreset` objects to the dict it receives.

    Parameters
    ----------
    plugin_manager : pluggy.PluginManager, optional
        Default: :func:`iloci.plugins.get_plugin_manager`.
    """
    pm = plugin_manager or get_plugin_manager()
    found: dict[str, RobotPreset] = dict(ROBOTS)
    info = getattr(pm, "iloci_plugin_info", {}) or {}

    def who(plugin: str) -> str:
        dist = getattr(info.get(plugin), "distribution", None)
        return f"plugin {plugin!r} (distribution {dist or 'none'})"

    # registration order (built-ins, installed plugins, the caller's), so a name
    # registered twice is blamed on the later plugin, as for components
    for impl in pm.hook.iloci_register_robots.get_hookimpls():
        before = dict(found)
        returned = impl.function(**{arg: found for arg in impl.argnames})
        changed = {k: v for k, v in found.items() if before.get(k) is not v}
        bad = {k: v for k, v in changed.items() if not isinstance(v, RobotPreset)}
        if returned is not None or bad or len(found) < len(before):
            what = (f"added {', '.join(f'{k!r}: {type(v).__name__}' for k, v in bad.items())}"
                    if bad else f"returned {type(returned).__name__}" if returned is not None
                    else "removed robots")
            raise PluginError(
                f"{who(impl.plugin_name)}: its iloci_register_robots {what}; it must add "
                "RobotPreset objects to the dict it receives (robots[name] = RobotPreset(...)) "
                f"and return nothing. Fix the plugin, or block it with "
                f"ILOCI_BLOCK_PLUGINS={impl.plugin_name}.")
        taken = [k for k in changed if k in before]
        if taken:  # a later plugin must not silently replace an earlier one's robot
            raise PluginError(
                f"robot {taken[0]!r} is registered twice: by {who(before[taken[0]].plugin)} "
                f"and by {who(impl.plugin_name)}. Uninstall or block one of them "
                f"(ILOCI_BLOCK_PLUGINS={impl.plugin_name}).")
        for k, v in changed.items():  # provenance: who registered it
            found[k] = replace(v, plugin=impl.plugin_name)
    return found


def get_robot(name: str = "nao-v32-right-arm", plugin_manager: Any = None) -> Robot:
    """The preset robot registered under ``name``.

    A preset whose plane is ``"auto"`` comes with its placeholder plane:
    :func:`robot_from_config` (what :func:`iloci.build` uses) places it.

    Raises
    ------
    UnknownComponentError
        No such robot (lists the known names, did you mean).
    MissingBackendError
        The preset's files are not installed.
    """
    presets = available_robots(plugin_manager) if plugin_manager is not None or \
        name not in ROBOTS else ROBOTS
    try:
        preset = presets[name]
    except (KeyError, TypeError):
        raise UnknownComponentError("robot", str(name), list(presets)) from None
    return preset.make()

"""iloci plugin: robot presets ``panda`` and ``ur5`` from example-robot-data.

example-robot-data (a cmeel wheel) installs its robots under
``site-packages/cmeel.prefix/share/example-robot-data/robots``; its URDFs
name meshes ``package://example-robot-data/robots/...``, resolved from the
``share`` directory. Each preset's drawing plane is placed automatically
(:func:`iloci.sensorimotor.robots.plane.find_drawing_plane`) when an agent
is built.

Light on import: nothing but the standard library and iloci's kernel.
"""

from __future__ import annotations

from importlib import metadata
from pathlib import Path

from iloci import hookimpl
from iloci.errors import MissingBackendError
from iloci.registry import KindRegistry
from iloci.sensorimotor.robots import Robot, RobotPreset, describe_robot

__all__ = ["PRESETS", "share_dir"]

_DIST = "example-robot-data"


def share_dir() -> Path:
    """The directory holding ``example-robot-data/`` (the ``package://`` root).

    Raises
    ------
    MissingBackendError
        example-robot-data is not installed.
    """
    try:
        dist = metadata.distribution(_DIST)
    except metadata.PackageNotFoundError:
        raise MissingBackendError("robot", "panda/ur5", [_DIST],
                                  "pip install ./plugins/iloci-robots "
                                  "(or pip install example-robot-data)") from None
    share = Path(str(dist.locate_file("cmeel.prefix/share")))
    if not (share / _DIST / "robots").is_dir():
        raise MissingBackendError("robot", "panda/ur5", [f"{_DIST}'s robots directory"],
                                  f"reinstall {_DIST}: {share / _DIST / 'robots'} is missing")
    return share


def panda() -> Robot:
    """Franka Emika Panda, 7 joints, pen at ``panda_hand_tcp`` (between the fingertips).

    Base ``panda_link0``; rest posture the Panda's usual "ready" posture
    (0, -45, 0, -135, 0, 90, 45 degrees); the fingers are held closed.
    """
    share = share_dir()
    return describe_robot(
        share / _DIST / "robots/panda_description/urdf/panda.urdf", name="panda",
        base_frame="panda_link0", tip_frame="panda_hand_tcp",
        rest=[0.0, -0.785398, 0.0, -2.356194, 0.0, 1.570796, 0.785398],
        package_dirs=[share], fixed_joints={"panda_finger_joint1": 0.0,
                                            "panda_finger_joint2": 0.0})


def ur5() -> Robot:
    """Universal Robots UR5, 6 joints, pen at ``tool0`` (the tool flange).

    Base ``base_link``; rest posture (0, -90, 90, -90, -90, 0) degrees: the
    elbow up and the flange pointing down in front of the robot.
    """
    share = share_dir()
    return describe_robot(
        share / _DIST / "robots/ur_description/urdf/ur5_robot.urdf", name="ur5",
        base_frame="base_link", tip_frame="tool0",
        rest=[0.0, -1.570796, 1.570796, -1.570796, -1.570796, 0.0], package_dirs=[share])


#: The presets this plugin registers (each through ``registry.add``).
PRESETS = {
    "panda": RobotPreset("panda", panda, "Franka Emika Panda (example-robot-data), pen at "
                         "the hand's TCP, plane placed automatically", 7,
                         source="iloci-robots", plane="auto"),
    "ur5": RobotPreset("ur5", ur5, "Universal Robots UR5 (example-robot-data), pen at tool0, "
                       "plane placed automatically", 6, source="iloci-robots", plane="auto"),
}


@hookimpl
def iloci_register_robots(registry: KindRegistry) -> None:
    for p in PRESETS.values():
        registry.add(p.name, f"iloci_robots:{p.name}", summary=p.summary, joints=p.joints,
                     plane=p.plane, install="pip install ./plugins/iloci-robots (or pip "
                     "install example-robot-data)")

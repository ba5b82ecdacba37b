"""Robots iloci draws with: the public robot description and the drawing plane.

A :class:`Robot` says everything iloci needs of an arm: its URDF file, the
base frame targets are expressed in, the pen-tip frame that draws, the
``J`` joints used (their column order in every joint path), their limits,
an optional rest posture, the start posture and the :class:`DrawingPlane`.
Every back end (IK, simulators, an embedding stack's executor) reads the
same description; :func:`get_robot` returns a shipped preset by name and
:func:`describe_robot` describes any arm from its URDF. A config's
``[robot]`` section (:class:`iloci.config.RobotConfig`) chooses one.

Presets
-------
``"nao-v32-right-arm"`` ships with iloci: the right arm of the Nao V3.2
humanoid of the paper, as a URDF written from the published link
dimensions and joint limits (package data, primitive geometry only). More
presets come from plugins (``iloci-robots``: ``panda``, ``ur5``) through the
``iloci_register_robots`` hook; ``iloci robots`` lists them.

The Nao's drawing plane
-----------------------
A y-z rectangle at a fixed x in the torso frame, chosen by hand before the
automatic search existed (:func:`iloci.sensorimotor.robots.plane.find_drawing_plane`
places a plane for any other arm). Its margin, as checked by
``benchmarks/ik.py`` (key ``plane`` of ``benchmarks/results/ik.json``) and by
``tests/plugins/test_pinocchio.py``, on a 41 x 41 grid over the rectangle
*grown by 10 mm on every side*, each point solved by the Pinocchio IK from
:attr:`Robot.q_home`:

* every point is reached (position error below 1e-7 m), and
* every joint stays at least 17 degrees inside its limits (RShoulderRoll
  17.2, RElbowRoll 20.4, RShoulderPitch 96.6, RElbowYaw 109.4 degrees).

Along the 182 LASA paths (warm-started point to point) the smallest
margins are 23.9 degrees (RShoulderRoll) and 20.8 degrees (RElbowRoll).

The parts: :mod:`~iloci.sensorimotor.robots.model` (the description),
:mod:`~iloci.sensorimotor.robots.presets` (robots by name),
:mod:`~iloci.sensorimotor.robots.plane` (the automatic plane search),
:mod:`~iloci.sensorimotor.robots.assembly` (a config's robot made ready:
robot -> IK -> place the plane -> IK again, once).
"""

from __future__ import annotations

from iloci.sensorimotor.robots.assembly import (check_robot, place_robot, plane_cache_dir,
                                                robot_and_ik, robot_from_config)
from iloci.sensorimotor.robots.model import DrawingPlane, Robot, describe_robot
from iloci.sensorimotor.robots.presets import (NAO_PLANE, NAO_Q_HOME, ROBOTS, RobotPreset,
                                               available_robots, get_robot)

__all__ = ["NAO_PLANE", "NAO_Q_HOME", "ROBOTS", "DrawingPlane", "Robot", "RobotPreset",
           "available_robots", "check_robot", "describe_robot", "get_robot", "place_robot",
           "plane_cache_dir", "robot_and_ik", "robot_from_config"]

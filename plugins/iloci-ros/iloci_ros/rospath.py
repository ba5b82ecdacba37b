"""Finding the system's ROS 1 Python packages from an iloci in a virtual environment.

Debian installs ROS 1 Noetic's Python side (``python3-rospy``,
``python3-nav-msgs``, ...) for its own ``/usr/bin/python3``, in
``/usr/lib/python3/dist-packages``; pip has no rospy. An iloci installed in a
virtual environment of the same Python minor version reaches them by
*appending* that directory to ``sys.path``: everything the environment has
(numpy, scipy, torch) still comes from the environment, and only what it
lacks (rospy, genpy, the message packages, rospkg, yaml, ...) from the
system. ``ILOCI_ROS_PYTHONPATH`` names other directories to append
(``os.pathsep``-separated), e.g. a ROS workspace's ``devel/lib/python3/dist-packages``.
"""

from __future__ import annotations

import importlib
import os
import sys

from iloci.errors import MissingBackendError

__all__ = ["SYSTEM_DIRS", "import_rospy"]

#: Where Debian's python3-rospy lives.
SYSTEM_DIRS = ("/usr/lib/python3/dist-packages",)

INSTALL = ("apt-get install ros-core python3-rospy python3-nav-msgs python3-geometry-msgs "
           "python3-trajectory-msgs python3-std-msgs")


def import_rospy():
    """Import rospy, appending the system's ROS directories to ``sys.path`` if needed.

    Raises
    ------
    MissingBackendError
        No rospy anywhere: says the apt-get command.
    """
    try:
        return importlib.import_module("rospy")
    except ImportError:
        pass
    extra = [d for d in os.environ.get("ILOCI_ROS_PYTHONPATH", "").split(os.pathsep) if d]
    for d in [*extra, *SYSTEM_DIRS]:
        if os.path.isdir(d) and d not in sys.path:
            sys.path.append(d)
    try:
        return importlib.import_module("rospy")
    except ImportError as exc:
        raise MissingBackendError("ROS node", "ros", ["rospy"], INSTALL) from exc

"""iloci plugin: the robot as a ROS 1 node (``iloci ros --memory FILE``).

* :mod:`iloci_ros.session`: the transport-neutral core, a
  :class:`~iloci_ros.session.TeachingSession` (a drawing in, the robot's
  guess out with an answer id; feedback by answer id, a stale id refused).
  A ROS 2, web-socket or serial adapter wraps this same object.
* :mod:`iloci_ros.node`: the ROS 1 adapter (rospy): topics, message
  conversion, the ``iloci ros`` command.
* :mod:`iloci_ros.rospath`: finds the system's rospy (Debian installs it for
  ``/usr/bin/python3`` only) for an iloci installed in a virtual environment.

Importing this module imports neither rospy nor the agent's back ends.
"""

from iloci import hookimpl


@hookimpl
def iloci_add_commands(subparsers) -> None:
    from iloci_ros.node import register
    register(subparsers)

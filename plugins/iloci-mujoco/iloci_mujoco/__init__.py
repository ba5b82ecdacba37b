"""iloci plugin: the ``mujoco`` Simulator (Nao arm, position servos, headless).

Light on import: MuJoCo is imported only when the simulator is built.

MuJoCo picks its OpenGL back end once, when it is first imported, from the
``MUJOCO_GL`` environment variable; its default (GLFW) needs a display. On a
Linux machine without one, loading this plugin sets ``MUJOCO_GL=egl`` unless
the variable is already set, so that offscreen rendering works headless
wherever ``libEGL`` is installed (see :mod:`iloci_mujoco.sim`).
"""

import os
import sys

from iloci import hookimpl
from iloci_mujoco.params import MuJoCoParams

__all__ = ["MuJoCoParams", "choose_opengl"]


def choose_opengl() -> None:
    """Select EGL for MuJoCo on a display-less Linux machine, unless MUJOCO_GL is set.

    Has no effect once ``mujoco`` has been imported.
    """
    if sys.platform.startswith("linux") and "MUJOCO_GL" not in os.environ and \
            not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ["MUJOCO_GL"] = "egl"


choose_opengl()


@hookimpl
def iloci_register_simulators(registry) -> None:
    registry.add("mujoco", "iloci_mujoco.sim:MuJoCoSimulator", params=MuJoCoParams,
                 requires=("mujoco",), install="pip install 'mujoco>=3.2'",
                 summary="Nao arm (URDF through MjSpec) tracking the joint path with "
                         "position servos in MuJoCo; offscreen images need EGL or OSMesa")

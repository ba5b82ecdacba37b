"""iloci plugin: the ``pybullet`` Simulator (Nao arm, position control, headless).

Light on import: PyBullet is imported only when the simulator is built.
"""

from iloci import hookimpl
from iloci_pybullet.params import PyBulletParams

__all__ = ["PyBulletParams"]


@hookimpl
def iloci_register_simulators(registry) -> None:
    registry.add("pybullet", "iloci_pybullet.sim:PyBulletSimulator", params=PyBulletParams,
                 requires=("pybullet",), install="pip install 'pybullet>=3.2'",
                 summary="Nao arm tracking the joint path under POSITION_CONTROL in "
                         "PyBullet (DIRECT), software-rendered images")

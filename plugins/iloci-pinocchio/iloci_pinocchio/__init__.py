"""iloci plugin: the ``pinocchio`` IKSolver (damped least squares, Pinocchio FK/Jacobians).

Light on import: the Pinocchio module is imported only when the solver is
built.
"""

from iloci import hookimpl
from iloci_pinocchio.params import PinocchioIKParams

__all__ = ["PinocchioIKParams"]


@hookimpl
def iloci_register_ik_solvers(registry) -> None:
    registry.add("pinocchio", "iloci_pinocchio.ik:PinocchioIK", params=PinocchioIKParams,
                 requires=("pinocchio",), install="pip install 'pin>=3.0'",
                 summary="position-only damped least squares IK with Pinocchio "
                         "(warm-started, joint limits enforced)")

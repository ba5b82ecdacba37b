"""The five interfaces every back end implements, and the values they exchange.

Back ends are plain classes that satisfy these :class:`typing.Protocol` s
structurally; they never subclass anything from iloci. Arrays crossing an
interface are numpy ``float64`` unless stated; a back end never leaks its own
tensors. Shapes use these letters:

``N``  points of a pen trajectory, ``T`` steps of a sequence or joint path,
``D``  features per step of an encoded sequence (6 in the paper: dy, dz and
four joint deltas), ``P`` size of a parametric-bias (PB) vector (4),
``J``  actuated joints of the arm (4), ``B`` sequences in a batch.

One module per kind of component (:mod:`~iloci.interfaces.perceptual_model`,
:mod:`~iloci.interfaces.clusterer`, :mod:`~iloci.interfaces.teacher`,
:mod:`~iloci.interfaces.ik`, :mod:`~iloci.interfaces.simulator`,
:mod:`~iloci.interfaces.executor`, :mod:`~iloci.interfaces.robot`), the values they exchange
(:mod:`~iloci.interfaces.values`) and the table of kinds
(:mod:`~iloci.interfaces.kinds`); every name is importable from here.
"""

from iloci.interfaces.clusterer import Clusterer
from iloci.interfaces.executor import FoldExecutor
from iloci.interfaces.ik import IKSolver
from iloci.interfaces.kinds import (ALL_KINDS, COMPONENT_KINDS, EXTRA_KINDS, KINDS,
                                    OPTIONAL_MEMBERS, ComponentKind, unmet_members)
from iloci.interfaces.perceptual_model import PerceptualModel
from iloci.interfaces.robot import RobotDescription
from iloci.interfaces.simulator import Simulator
from iloci.interfaces.teacher import Teacher, check_feedback
from iloci.interfaces.values import LONGEST_STROKE_S, Demonstration, Execution, Response

__all__ = [
    "Demonstration",
    "FoldExecutor",
    "Response",
    "Execution",
    "PerceptualModel",
    "Clusterer",
    "Teacher",
    "IKSolver",
    "RobotDescription",
    "Simulator",
    "ALL_KINDS",
    "ComponentKind",
    "COMPONENT_KINDS",
    "EXTRA_KINDS",
    "KINDS",
    "LONGEST_STROKE_S",
    "OPTIONAL_MEMBERS",
    "check_feedback",
    "unmet_members",
]

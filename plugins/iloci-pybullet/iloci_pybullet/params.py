"""Settings of the ``pybullet`` simulator (section ``[simulator]``); light, no PyBullet import."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from iloci.sensorimotor.simulation import SimulatorParams

__all__ = ["PyBulletParams"]


@dataclass(frozen=True)
class PyBulletParams(SimulatorParams):
    """Settings of :class:`iloci_pybullet.sim.PyBulletSimulator`: ``robot`` and
    ``gravity`` as every simulator's, and PyBullet's physics step and motor gains."""

    POSITIVE: ClassVar[tuple[str, ...]] = ("timestep", "position_gain")
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = ("gravity", "velocity_gain")

    #: Longest physics step (s); each step ``dt`` of the joint path is split
    #: into ``ceil(dt / timestep)`` equal physics steps, the motors'
    #: set-points updated at each.
    timestep: float = 0.001
    #: Position gain of PyBullet's POSITION_CONTROL motor (its error term is
    #: ``position_gain * (q_target - q) + velocity_gain * (dq_target - dq)``).
    position_gain: float = 0.1
    #: Velocity gain of the motor.
    velocity_gain: float = 1.0

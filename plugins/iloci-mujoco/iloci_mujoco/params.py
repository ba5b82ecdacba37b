"""Settings of the ``mujoco`` simulator (section ``[simulator]``); light, no MuJoCo import."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from iloci.sensorimotor.simulation import SimulatorParams

__all__ = ["MuJoCoParams"]


@dataclass(frozen=True)
class MuJoCoParams(SimulatorParams):
    """Settings of :class:`iloci_mujoco.sim.MuJoCoSimulator`: ``robot`` and
    ``gravity`` as every simulator's, and the servos' gains and update rates."""

    POSITIVE: ClassVar[tuple[str, ...]] = ("control_period", "timestep", "kp")
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = ("gravity", "kv")

    #: Longest period (s) at which the servos' set-points are updated: each
    #: step ``dt`` of the joint path is split into ``ceil(dt / control_period)``
    #: equal control periods.
    control_period: float = 0.001
    #: Longest physics step (s); each control period is split into equal
    #: physics steps no longer than this. The arm's smallest inertia (about
    #: 1e-4 kg m^2, elbow yaw) against ``kp`` needs steps well under 1 ms
    #: while a servo is at its torque limit.
    timestep: float = 0.0002
    #: Stiffness of each joint's position servo (N m / rad). The gravity
    #: torque on the shoulder (about 0.4 N m) sags it by 0.4 / kp rad.
    kp: float = 1000.0
    #: Gain of each joint's velocity servo (N m s / rad), which tracks the
    #: path's velocity and damps the position servo.
    kv: float = 2.0
    #: Compensate gravity on every link (MuJoCo's ``gravcomp``), as the
    #: controllers of industrial arms do: without it a heavy arm (the
    #: Panda's, the UR5's) sags by its gravity torque over ``kp``.
    gravity_compensation: bool = False

    def validate(self) -> None:
        super().validate()
        if not self.timestep <= self.control_period:
            raise ValueError(f"need timestep <= control_period (s), got timestep="
                             f"{self.timestep}, control_period={self.control_period}")

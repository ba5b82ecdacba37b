"""Settings of the ``mujoco`` simulator (section ``[simulator]``); light, no MuJoCo import."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["MuJoCoParams"]


@dataclass(frozen=True)
class MuJoCoParams:
    """Settings of :class:`iloci_mujoco.sim.MuJoCoSimulator`."""

    #: Robot (a name of :mod:`iloci.sensorimotor.robots`).
    robot: str = "nao-v32-right-arm"
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
    #: Gravity (m/s^2) pulling along -z of the torso frame; 0 switches it off.
    gravity: float = 9.81

    def validate(self) -> None:
        if not self.control_period > 0:
            raise ValueError(f"control_period must be > 0 (s), got {self.control_period}")
        if not 0 < self.timestep <= self.control_period:
            raise ValueError(f"need 0 < timestep <= control_period (s), got timestep="
                             f"{self.timestep}, control_period={self.control_period}")
        if not self.kp > 0:
            raise ValueError(f"kp must be > 0, got {self.kp}")
        if not self.kv >= 0:
            raise ValueError(f"kv must be >= 0, got {self.kv}")
        if not self.gravity >= 0:
            raise ValueError(f"gravity must be >= 0 (m/s^2, pointing down), got {self.gravity}")

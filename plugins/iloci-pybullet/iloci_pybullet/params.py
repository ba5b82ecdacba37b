"""Settings of the ``pybullet`` simulator (section ``[simulator]``); light, no PyBullet import."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["PyBulletParams"]


@dataclass(frozen=True)
class PyBulletParams:
    """Settings of :class:`iloci_pybullet.sim.PyBulletSimulator`."""

    #: Robot (a name of :mod:`iloci.sensorimotor.robots`).
    robot: str = "nao-v32-right-arm"
    #: Longest physics step (s); each step ``dt`` of the joint path is split
    #: into ``ceil(dt / timestep)`` equal physics steps, the motors'
    #: set-points updated at each.
    timestep: float = 0.001
    #: Position gain of PyBullet's POSITION_CONTROL motor (its error term is
    #: ``position_gain * (q_target - q) + velocity_gain * (dq_target - dq)``).
    position_gain: float = 0.1
    #: Velocity gain of the motor.
    velocity_gain: float = 1.0
    #: Gravity (m/s^2) pulling along -z of the torso frame; 0 switches it off.
    gravity: float = 9.81

    def validate(self) -> None:
        if not self.timestep > 0:
            raise ValueError(f"timestep must be > 0 (s), got {self.timestep}")
        if not self.position_gain > 0:
            raise ValueError(f"position_gain must be > 0, got {self.position_gain}")
        if not self.velocity_gain >= 0:
            raise ValueError(f"velocity_gain must be >= 0, got {self.velocity_gain}")
        if not self.gravity >= 0:
            raise ValueError(f"gravity must be >= 0 (m/s^2, pointing down), got {self.gravity}")

"""Settings of the ``pinocchio`` IK solver (section ``[ik]``); light, no Pinocchio import."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

__all__ = ["PinocchioIKParams"]


@dataclass(frozen=True)
class PinocchioIKParams:
    """Settings of :class:`iloci_pinocchio.ik.PinocchioIK`."""

    #: A saved memory's motor channels are this robot's joint angles, which
    #: the null-space pull shapes for a redundant arm.
    MEMORY_KEYS: ClassVar[tuple[str, ...]] = ("posture_gain",)

    #: Stop iterating on a point once its position error is below this (m).
    tolerance: float = 1e-7
    #: A point whose error stays above this after every start is unreachable (m).
    max_error: float = 1e-4
    #: Damped-least-squares iterations per point and start.
    max_iterations: int = 100
    #: Damping lambda of the least-squares step (m); keeps steps bounded near
    #: singular (stretched-arm) configurations.
    damping: float = 1e-3
    #: Redundant arms with a rest posture: fraction of the way to it taken
    #: per iteration in the null space of the pen-tip task, so that among
    #: the many solutions the path keeps near the rest posture (0: off).
    posture_gain: float = 0.1

    def validate(self) -> None:
        if not 0 < self.tolerance <= self.max_error:
            raise ValueError("need 0 < tolerance <= max_error, got tolerance="
                             f"{self.tolerance}, max_error={self.max_error}")
        if self.max_iterations < 1:
            raise ValueError(f"max_iterations must be >= 1, got {self.max_iterations}")
        if not 0 <= self.posture_gain <= 1:
            raise ValueError(f"posture_gain must be in [0, 1], got {self.posture_gain}")
        if self.damping < 0:
            raise ValueError(f"damping must be >= 0, got {self.damping}")

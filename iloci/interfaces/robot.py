"""A robot preset's interface: what its factory returns (kind ``robot`` of the registry)."""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["RobotDescription"]


@runtime_checkable
class RobotDescription(Protocol):
    """What a robot preset's factory returns: :class:`iloci.sensorimotor.robots.Robot`.

    Build one with :func:`iloci.sensorimotor.robots.describe_robot` from a
    URDF; a preset registers the function that does (``iloci_register_robots``).
    Lengths in m, angles in rad, arrays of shape ``(J,)``.
    """

    name: str
    urdf_path: Any
    joint_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    end_effector_frame: str
    q_home: np.ndarray
    plane: Any
    plane_report: dict[str, Any]

    def describe(self) -> dict[str, Any]:
        """URDF, frames, joints, limits and drawing plane, as ``iloci robots --show`` prints."""
        ...

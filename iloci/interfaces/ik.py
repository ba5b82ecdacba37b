"""The IK solver's interface: pen positions in the drawing plane -> the arm's joint path."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


__all__ = ["IKSolver"]


@runtime_checkable
class IKSolver(Protocol):
    """Inverse and forward kinematics of the drawing arm."""

    #: Names of the ``J`` actuated joints, in column order.
    joint_names: tuple[str, ...]
    #: Joint limits (rad), each shape (J,).
    lower: np.ndarray
    upper: np.ndarray

    def solve(self, points: np.ndarray, q0: np.ndarray | None = None) -> np.ndarray:
        """Joint path reaching each target, warm-started point to point.

        Parameters
        ----------
        points : ndarray, shape (T, 3)
            Pen-tip targets (m, torso frame).
        q0 : ndarray, shape (J,), optional
            Start configuration.

        Returns
        -------
        ndarray, shape (T, J)

        Raises
        ------
        UnreachableTargetError
            A target cannot be reached within tolerance (names the point).
        """
        ...

    def forward(self, q: np.ndarray) -> np.ndarray:
        """Pen-tip positions, shape (T, 3), of joint configurations (T, J)."""
        ...

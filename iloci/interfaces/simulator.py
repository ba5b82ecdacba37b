"""The simulator's interface: a joint path executed (or a real arm's executor), what it drew."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


from iloci.interfaces.values import Execution

__all__ = ["Simulator"]


@runtime_checkable
class Simulator(Protocol):
    """A physics engine executing the arm's joint path.

    :mod:`iloci.sensorimotor.simulation` holds what every simulator shares:
    the input checks, the set-point schedule and tracking loop, the camera
    and colours of the picture, and the base of the settings' schema.
    """

    def execute(self, joint_path: np.ndarray, dt: float) -> Execution:
        """Track a joint path under position control.

        A simulator starts the arm at rest in the path's first posture; a
        real arm, which is wherever it was left, first moves from its
        current posture to the path's first one (see
        :class:`iloci.sensorimotor.hardware.ArmExecutor`). Then the servos'
        set-points move linearly from one row to the next over ``dt``.

        Parameters
        ----------
        joint_path : ndarray, shape (T, J)
            Joint angles (rad) at times ``0, dt, 2 dt, ...``, within the
            robot's joint limits.
        dt : float
            Time between two rows (s), > 0.

        Returns
        -------
        Execution
            ``joint_path`` (T, J): the angles reached at each time;
            ``end_effector`` (T, 3): the pen tip reached (m, torso frame);
            ``dt``. Row 0 is the start posture itself.

        Raises
        ------
        InvalidInputError
            Not numeric, wrong shape (a width other than J), NaN or inf, a
            joint outside its limits, or ``dt`` not a positive finite number.
        """
        ...

    def render(self, execution: Execution, width: int = 480,
               height: int = 360) -> np.ndarray:
        """Image of the arm in its last posture and the path its pen drew (optional).

        Parameters
        ----------
        execution : Execution
            As :meth:`execute` returned it, or a prefix of one (the drawing
            so far).
        width, height : int
            Image size (pixels).

        Returns
        -------
        ndarray, shape (height, width, 3), uint8

        Raises
        ------
        InvalidInputError
            Not an Execution, malformed arrays, or a bad image size.
        """
        ...

    def close(self) -> None:
        """Release the engine (idempotent)."""
        ...

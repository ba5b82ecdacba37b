"""The teacher's frame: showing the robot's drawing the way the teacher drew.

Preprocessing fits a demonstration into the robot's drawing plane with one
uniform scale and a shift (:func:`iloci.sensorimotor.preprocess.fit_to_plane`:
the teacher's x becomes the plane's y, the teacher's y its z). A
:class:`TeacherFrame` is the inverse of that fit for one demonstration, so
whatever the robot draws in the plane (metres, torso frame) can be shown in
the demonstration's own units and orientation, at the size and place the
demonstration had: a person judges the answer beside their own drawing,
on equal axes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from iloci.errors import InvalidInputError
from iloci.interfaces import Demonstration

__all__ = ["TeacherFrame"]


@dataclass(frozen=True)
class TeacherFrame:
    """Maps drawing-plane points ``(y, z)`` (m) to a demonstration's frame.

    ``teacher = (plane - plane_center) / scale + teacher_center``.

    Attributes
    ----------
    plane_center : ndarray, shape (2,)
        Centre of the demonstration's bounding box in the plane (m).
    teacher_center : ndarray, shape (2,)
        Centre of its bounding box in its own frame (its units).
    scale : float
        Plane metres per teacher unit (> 0).
    """

    plane_center: np.ndarray
    teacher_center: np.ndarray
    scale: float

    @classmethod
    def of(cls, demo: Demonstration, plane_points: np.ndarray) -> TeacherFrame:
        """The frame of ``demo``, given where preprocessing put it in the plane.

        Parameters
        ----------
        demo : Demonstration
        plane_points : ndarray, shape (T, 2)
            The demonstration fitted into the plane (``Motion.plane_points``).

        The scale is the ratio of the bounding boxes along the axis the
        demonstration spans most (the fit is uniform, so either axis gives
        it; the longer one is the more precise); smoothing moves the box by
        a fraction of a percent at most.
        """
        pos = np.asarray(demo.positions, dtype=np.float64)
        plane = np.asarray(plane_points, dtype=np.float64)
        if plane.ndim != 2 or plane.shape[1] != 2 or not np.isfinite(plane).all():
            raise InvalidInputError(f"plane points must be a finite (T, 2) array, got "
                                    f"{plane.shape}.")
        lo, hi = pos.min(axis=0), pos.max(axis=0)
        plo, phi = plane.min(axis=0), plane.max(axis=0)
        axis = int(np.argmax(hi - lo))
        scale = float((phi - plo)[axis] / (hi - lo)[axis])
        if not (np.isfinite(scale) and scale > 0):
            raise InvalidInputError(f"cannot relate {demo.key!r} to its plane points: "
                                    "zero extent.")
        return cls((plo + phi) / 2, (lo + hi) / 2, scale)

    def to_teacher(self, plane_points: np.ndarray) -> np.ndarray:
        """Plane points ``(y, z)`` (m), shape (T, 2) -> the teacher's frame, shape (T, 2)."""
        p = np.asarray(plane_points, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 2:
            raise InvalidInputError(f"plane points must have shape (T, 2), got {p.shape}.")
        return (p - self.plane_center) / self.scale + self.teacher_center

    def to_plane(self, points: np.ndarray) -> np.ndarray:
        """Teacher-frame points, shape (T, 2) -> plane points ``(y, z)`` (m), shape (T, 2)."""
        p = np.asarray(points, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 2:
            raise InvalidInputError(f"points must have shape (T, 2), got {p.shape}.")
        return (p - self.teacher_center) * self.scale + self.plane_center

"""Robots iloci can draw with, and the drawing plane of each.

One robot ships with iloci: ``"nao-v32-right-arm"``, the right arm of the
Nao V3.2 humanoid of the paper, as a URDF written from the published link
dimensions and joint limits (package data, primitive geometry only).

The drawing plane is a y-z rectangle at a fixed x in the torso frame. The
demonstration is scaled (aspect ratio kept) and centred into it. It was
chosen by sampling: a grid search over plane positions for the largest
smallest joint-limit margin. The margin, as checked by ``benchmarks/ik.py``
(key ``plane`` of ``benchmarks/results/ik.json``) and by
``tests/plugins/test_pinocchio.py``, on a 41 x 41 grid over the rectangle
*grown by 10 mm on every side*, each point solved by the Pinocchio IK from
:attr:`Robot.q_home`:

* every point is reached (position error below 1e-7 m), and
* every joint stays at least 17 degrees inside its limits (RShoulderRoll
  17.2, RElbowRoll 20.4, RShoulderPitch 96.6, RElbowYaw 109.4 degrees).

Along the 182 LASA paths (warm-started point to point) the smallest
margins are 23.9 degrees (RShoulderRoll) and 20.8 degrees (RElbowRoll).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from iloci.errors import InvalidInputError, UnknownComponentError
from iloci.validation import check_array

__all__ = ["ROBOTS", "DrawingPlane", "Robot", "get_robot"]


@dataclass(frozen=True)
class DrawingPlane:
    """A vertical rectangle the robot draws in: x fixed, spanning y and z.

    Coordinates are metres in the robot's torso frame (x forward, y left,
    z up). A 2-D plane point is ``(y, z)`` in that frame, not relative to
    the centre.

    Attributes
    ----------
    x : float
        Distance of the plane in front of the torso origin (m).
    y, z : float
        Centre of the rectangle (m).
    width : float
        Extent along y (m).
    height : float
        Extent along z (m).
    """

    x: float
    y: float
    z: float
    width: float
    height: float

    def __post_init__(self) -> None:
        vals = (self.x, self.y, self.z, self.width, self.height)
        if not all(np.isfinite(v) for v in vals) or self.width <= 0 or self.height <= 0:
            raise InvalidInputError(
                f"drawing plane needs finite x, y, z and positive width and height, "
                f"got {vals}.")

    @property
    def center(self) -> np.ndarray:
        """Centre ``(y, z)``, shape (2,)."""
        return np.array([self.y, self.z])

    @property
    def size(self) -> np.ndarray:
        """``(width, height)``, shape (2,)."""
        return np.array([self.width, self.height])

    @property
    def corners(self) -> np.ndarray:
        """The rectangle's corners ``(y, z)``, shape (4, 2), counter-clockwise."""
        hw, hh = self.width / 2, self.height / 2
        return self.center + np.array([[-hw, -hh], [hw, -hh], [hw, hh], [-hw, hh]])

    def contains(self, points2d: np.ndarray, tol: float = 1e-9) -> np.ndarray:
        """Whether each plane point lies in the rectangle.

        Parameters
        ----------
        points2d : ndarray, shape (T, 2)

        Returns
        -------
        ndarray of bool, shape (T,)
        """
        p = _as_points(points2d, 2, "plane points")
        half = self.size / 2 + tol
        return np.all(np.abs(p - self.center) <= half, axis=1)

    def to_3d(self, points2d: np.ndarray) -> np.ndarray:
        """Plane points ``(y, z)`` -> torso-frame points ``(x, y, z)``.

        Parameters
        ----------
        points2d : ndarray, shape (T, 2)

        Returns
        -------
        ndarray, shape (T, 3)
        """
        p = _as_points(points2d, 2, "plane points")
        return np.column_stack([np.full(len(p), self.x), p])

    def to_2d(self, points3d: np.ndarray) -> np.ndarray:
        """Torso-frame points ``(x, y, z)`` -> their ``(y, z)`` in the plane.

        The x coordinate is dropped (orthogonal projection onto the plane).

        Parameters
        ----------
        points3d : ndarray, shape (T, 3)

        Returns
        -------
        ndarray, shape (T, 2)
        """
        p = _as_points(points3d, 3, "3-D points")
        return p[:, 1:3].copy()


def _as_points(a: np.ndarray, width: int, what: str) -> np.ndarray:
    return check_array(a, what, (None, width), finite_hint=" Pass finite coordinates.")


@dataclass(frozen=True, eq=False)
class Robot:
    """A drawing arm: its URDF, actuated joints and drawing plane.

    Attributes
    ----------
    name : str
        Registered name, e.g. ``"nao-v32-right-arm"``.
    urdf_path : pathlib.Path
        The URDF file (package data).
    joint_names : tuple of str
        The ``J`` actuated joints, in column order of every joint path.
    lower, upper : ndarray, shape (J,)
        Joint limits (rad), as in the URDF.
    end_effector_frame : str
        Name of the URDF link whose origin draws (the pen tip).
    q_home : ndarray, shape (J,)
        Start configuration: its pen tip is near the plane's centre, every
        joint well inside its limits. IK paths are warm-started from it.
    plane : DrawingPlane
    """

    name: str
    urdf_path: Path
    joint_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    end_effector_frame: str
    q_home: np.ndarray
    plane: DrawingPlane
    base_frame: str = "torso"
    fixed_joints: dict[str, float] = field(default_factory=dict)

    @property
    def urdf_text(self) -> str:
        """The URDF as a string."""
        return self.urdf_path.read_text(encoding="utf-8")


def _nao_v32_right_arm() -> Robot:
    path = Path(str(resources.files("iloci.sensorimotor.robots") / "nao_v32_right_arm.urdf"))
    # limits as in the URDF (docs/method.md, "The robot"), rad
    lower = np.array([-2.0856685, -1.6493361, -2.0856685, 0.0087266])
    upper = np.array([2.0856685, -0.0087266, 2.0856685, 1.5620696])
    for a in (lower, upper):
        a.flags.writeable = False
    q_home = np.array(NAO_Q_HOME)
    q_home.flags.writeable = False
    return Robot(
        name="nao-v32-right-arm",
        urdf_path=path,
        joint_names=("RShoulderPitch", "RShoulderRoll", "RElbowYaw", "RElbowRoll"),
        lower=lower,
        upper=upper,
        end_effector_frame="r_pen_tip",
        q_home=q_home,
        plane=NAO_PLANE,
        fixed_joints={"RWristYaw": 0.0},
    )


#: The Nao's drawing plane (m, torso frame): a 10 cm square 16.5 cm in front
#: of the torso, centred 2.7 cm outside and level with the right shoulder
#: (shoulder at y = -0.098, z = 0.100). Chosen by a grid search over centres
#: maximising the smallest joint-limit margin of the rectangle grown by 1 cm.
NAO_PLANE = DrawingPlane(x=0.165, y=-0.125, z=0.10, width=0.10, height=0.10)
#: Nao start posture (rad): pen tip at the plane centre (within 1e-7 m);
#: about (-5.2, -46.1, 0.5, 66.4) degrees.
NAO_Q_HOME = (-0.091452, -0.804138, 0.008353, 1.159141)

#: Robot name -> constructor.
ROBOTS = {"nao-v32-right-arm": _nao_v32_right_arm}


def get_robot(name: str = "nao-v32-right-arm") -> Robot:
    """The robot registered under ``name``.

    Raises
    ------
    UnknownComponentError
        No such robot (lists the known names).
    """
    try:
        make = ROBOTS[name]
    except (KeyError, TypeError):
        raise UnknownComponentError("robot", str(name), list(ROBOTS)) from None
    return make()

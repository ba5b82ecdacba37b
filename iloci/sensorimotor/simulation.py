"""What every simulator of the drawing arm shares, whatever its physics engine.

A :class:`~iloci.interfaces.Simulator` plugin (``pybullet``, ``mujoco``, or a
third party's) keeps only what its engine needs; this module holds the rest,
numpy only:

* the checks of what crosses the interface: :func:`check_joint_path`,
  :func:`check_postures`, :func:`check_execution`, :func:`check_image_size`,
  and :func:`check_settings` for the constructor's settings;
* the settings every simulator takes, :class:`SimulatorParams` (the base of
  each plugin's schema);
* the servo set-points of a joint path, :func:`setpoints`, interpolated the
  way Nao's motion controller interpolates the commands it is sent, and
  :func:`track`, the loop that drives an engine along them and records
  what the arm reached;
* the picture: the teacher's camera :data:`VIEW`, the colours and sizes of
  the pen path, its start and the drawing plane's outline
  (:func:`plane_outline`), and :func:`path_dots` for engines that draw a
  path with dots.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from iloci.linalg import matmul
from iloci.errors import InvalidInputError
from iloci.interfaces import Execution
from iloci.sensorimotor.robots import DrawingPlane, Robot
from iloci.validation import is_integer

__all__ = [
    "FRAME_RADIUS", "FRAME_RGBA", "MAX_IMAGE_SIZE", "PEN_RADIUS", "PEN_RGBA", "START_RADIUS",
    "START_RGBA", "VIEW", "SimulatorParams", "check_execution", "check_image_size",
    "check_joint_path", "check_postures", "check_settings", "path_dots", "plane_outline",
    "setpoints", "track", "updates_per_step", "approach", "camera_for", "to_base",
    "to_world",
]

#: Camera of every simulator's ``render``: the teacher's view, in front of the
#: robot, above and to the side of its right arm (m, torso frame), with a
#: vertical field of view in degrees. Seen from the front, the drawing reads
#: as the teacher drew it (see :mod:`iloci.sensorimotor.preprocess`).
VIEW: dict[str, Any] = {"eye": (0.45, -0.28, 0.25), "target": (0.11, -0.12, 0.11),
                        "fov": 38.0}

#: Colour (RGBA, 0..1) and radius (m) of the pen path in an image.
PEN_RGBA = (0.10, 0.20, 0.80, 1.0)
PEN_RADIUS = 0.0016
#: Colour and radius (m) of the dot marking where the pen starts.
START_RGBA = (0.10, 0.70, 0.20, 1.0)
START_RADIUS = 0.003
#: Colour and radius (m) of the drawing plane's outline.
FRAME_RGBA = (0.55, 0.55, 0.55, 1.0)
FRAME_RADIUS = 0.0008

#: Largest image side (pixels) ``render`` accepts.
MAX_IMAGE_SIZE = 4096


@dataclass(frozen=True)
class SimulatorParams:
    """Settings every simulator takes (section ``[simulator]``); plugins extend it.

    A subclass adds its engine's settings as fields, names those that must
    be > 0 in ``POSITIVE`` and those that must be >= 0 in ``NON_NEGATIVE``,
    and overrides :meth:`validate` (calling ``super().validate()``) only for
    rules that relate settings.
    """

    #: Settings (field names) that must be > 0.
    POSITIVE: ClassVar[tuple[str, ...]] = ()
    #: Settings (field names) that must be >= 0.
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = ("gravity",)

    #: Gravity (m/s^2) pulling along -z of the torso frame; 0 switches it off.
    gravity: float = 9.81

    def validate(self) -> None:
        for name, value in vars(self).items():
            # TOML can spell inf and nan; no setting of a simulator means either
            if isinstance(value, float) and not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value}")
        for names, ok, rule in ((self.POSITIVE, lambda v: v > 0, "> 0"),
                                (self.NON_NEGATIVE, lambda v: v >= 0, ">= 0")):
            for name in names:
                value = getattr(self, name)
                if not ok(value):
                    raise ValueError(f"{name} must be {rule}, got {value}")


def check_settings(params: Any) -> None:
    """Validate a simulator's settings as its constructor received them.

    Parameters
    ----------
    params : SimulatorParams
        An instance of the plugin's schema holding the constructor's values.

    Raises
    ------
    InvalidInputError
        A value out of range (the message names it and the schema).
    """
    try:
        params.validate()
    except ValueError as exc:
        cls = type(params)
        raise InvalidInputError(f"{exc}; see {cls.__module__}.{cls.__qualname__}.") from None


def check_joint_path(joint_path: np.ndarray, dt: float, robot: Robot,
                     tol: float = 1e-6, limits: bool = True) -> tuple[np.ndarray, float]:
    """Validate a joint path and its time step for execution.

    Parameters
    ----------
    joint_path : array_like, shape (T, J)
        Joint angles (rad), columns in ``robot.joint_names`` order, ``T >= 1``.
    dt : float
        Time between two rows (s), > 0.
    robot : Robot
    tol : float
        Slack on the joint limits (rad); the path is clipped to the limits.
    limits : bool
        Check the limits. Off for paths an arm already performed, which a
        physics engine lets overshoot a limit slightly (its joint limits are
        soft constraints); they are returned unclipped.

    Returns
    -------
    (ndarray of shape (T, J), float)

    Raises
    ------
    InvalidInputError
        Not numeric, wrong shape, NaN or inf, a joint outside its limits, or
        ``dt`` not a positive finite number.
    """
    names = tuple(robot.joint_names)
    J = len(names)
    try:
        q = np.asarray(joint_path, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidInputError(f"joint path must be a numeric array of shape (T, {J}).") \
            from None
    if q.ndim != 2 or q.shape[1] != J or len(q) == 0:
        raise InvalidInputError(
            f"joint path must have shape (T, {J}) with T >= 1, one column per joint "
            f"({', '.join(names)}), got {q.shape}.")
    if not np.all(np.isfinite(q)):
        row, col = (int(i) for i in np.argwhere(~np.isfinite(q))[0])
        raise InvalidInputError(
            f"joint path contains NaN or inf (first at step {row}, joint {names[col]}); "
            "pass finite angles in radians.")
    lo = np.asarray(robot.lower, dtype=np.float64)
    hi = np.asarray(robot.upper, dtype=np.float64)
    bad = (q < lo - tol) | (q > hi + tol) if limits else np.zeros(q.shape, dtype=bool)
    if bad.any():
        row, col = (int(i) for i in np.argwhere(bad)[0])
        raise InvalidInputError(
            f"joint path step {row}: {names[col]} = {q[row, col]:.4f} rad is outside its "
            f"limits [{lo[col]:.4f}, {hi[col]:.4f}] ({int(bad.any(axis=1).sum())} step(s) "
            "out of range). Clip the path to the robot's limits (robot.lower, "
            "robot.upper) before executing it.")
    try:
        step = float(dt)
    except (TypeError, ValueError):
        raise InvalidInputError(f"dt must be a number of seconds, got {dt!r}.") from None
    if not (math.isfinite(step) and step > 0):
        raise InvalidInputError(f"dt must be a positive, finite time step (s), got {dt!r}.")
    return (np.clip(q, lo, hi) if limits else q), step


def check_postures(q: np.ndarray, robot: Robot) -> tuple[np.ndarray, bool]:
    """Validate the postures a simulator's ``forward`` takes (limits not checked).

    Parameters
    ----------
    q : array_like, shape (T, J) or (J,)
        Joint angles (rad).
    robot : Robot

    Returns
    -------
    (ndarray of shape (T, J), bool)
        The postures, and whether ``q`` was a single one (the caller returns
        shape (3,) then instead of (T, 3)).
    """
    single = np.ndim(q) == 1
    qs, _ = check_joint_path(np.atleast_2d(q), 1.0, robot, limits=False)
    return qs, single


def check_execution(execution: Any, robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """Validate the :class:`~iloci.interfaces.Execution` a ``render`` is asked to draw.

    Parameters
    ----------
    execution : Execution
        As a simulator's ``execute`` returned it, or a prefix of one.
    robot : Robot

    Returns
    -------
    (ndarray of shape (T, J), ndarray of shape (T, 3))
        The joint path reached and the pen path (m, torso frame).

    Raises
    ------
    InvalidInputError
        Not an Execution, or its arrays malformed.
    """
    if not isinstance(execution, Execution):
        raise InvalidInputError(f"render takes an Execution (from execute), got "
                                f"{type(execution).__name__}.")
    q, _ = check_joint_path(execution.joint_path, execution.dt, robot, limits=False)
    pen = np.asarray(execution.end_effector, dtype=np.float64)
    if pen.shape != (len(q), 3) or not np.all(np.isfinite(pen)):
        raise InvalidInputError(
            f"execution.end_effector must be finite with shape ({len(q)}, 3), got "
            f"{pen.shape}.")
    return q, pen


def check_image_size(width: int, height: int,
                     largest: int = MAX_IMAGE_SIZE) -> tuple[int, int]:
    """Validate an image size in pixels; returns ``(width, height)`` as ints."""
    out = []
    for name, v in (("width", width), ("height", height)):
        if not is_integer(v) or not 1 <= int(v) <= largest:
            raise InvalidInputError(
                f"image {name} must be an integer number of pixels in 1..{largest}, "
                f"got {v!r}.")
        out.append(int(v))
    return out[0], out[1]


def setpoints(q: np.ndarray, dt: float, period: float
              ) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """The servos' set-points along a joint path, segment by segment.

    Each joint's set-point moves linearly from one path point to the next
    over ``dt``, updated ``n = ceil(dt / period)`` times per segment, and its
    target velocity is the segment's velocity (the feed-forward of a
    trajectory-following servo).

    Parameters
    ----------
    q : ndarray, shape (T, J)
        A checked joint path (see :func:`check_joint_path`).
    dt : float
        Time between two rows (s).
    period : float
        Longest time (s) between two set-point updates.

    Yields
    ------
    (int, ndarray of shape (n, J), ndarray of shape (J,))
        For the segment from row ``i`` to row ``i + 1``: ``i``, the set-points
        (the last one is row ``i + 1``) and the velocity (rad/s). Each
        set-point is held for ``dt / n``.
    """
    n = updates_per_step(dt, period)
    fractions = (np.arange(1, n + 1) / n)[:, None]
    for i in range(len(q) - 1):
        delta = q[i + 1] - q[i]
        yield i, q[i] + fractions * delta, delta / dt


def track(q: np.ndarray, dt: float, period: float,
          hold: Callable[[np.ndarray, np.ndarray], None],
          read: Callable[[], tuple[np.ndarray, np.ndarray]]) -> Execution:
    """Drive an engine's servos along a joint path and record what the arm reached.

    The engine-specific parts are two callbacks; the arm must already rest
    in the path's first posture.

    Parameters
    ----------
    q, dt, period
        The joint path (T, J), its time step (s) and the longest time (s)
        between two set-point updates, as for :func:`setpoints`.
    hold : callable (target, velocity) -> None
        Sets the servos' set-point, shape (J,) (rad), and target velocity,
        shape (J,) (rad/s), and advances the engine by ``dt / n``.
    read : callable () -> (ndarray of shape (J,), ndarray of shape (3,))
        The joint angles (rad) and pen tip (m, torso frame) now.

    Returns
    -------
    Execution
        ``joint_path`` (T, J) and ``end_effector`` (T, 3) read at each time
        of the path (row 0 before any step), and ``dt``.
    """
    reached_q = np.empty_like(q)
    reached_x = np.empty((len(q), 3))
    reached_q[0], reached_x[0] = read()
    for i, targets, velocity in setpoints(q, dt, period):
        for target in targets:
            hold(target, velocity)
        reached_q[i + 1], reached_x[i + 1] = read()
    return Execution(joint_path=reached_q, end_effector=reached_x, dt=dt)


def updates_per_step(dt: float, period: float) -> int:
    """How many periods of at most ``period`` make up ``dt``: ``ceil(dt / period)``, >= 1."""
    # the slack keeps dt = k * period from rounding up to k + 1
    return max(1, math.ceil(dt / period - 1e-9))


def to_world(robot: Robot, points: np.ndarray) -> np.ndarray:
    """Base-frame points (T, 3) -> the URDF root frame, where engines load the robot."""
    T = np.asarray(robot.base_pose, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64)
    return p if np.array_equal(T, np.eye(4)) else matmul(p, T[:3, :3].T) + T[:3, 3]


def to_base(robot: Robot, points: np.ndarray) -> np.ndarray:
    """Root-frame points (T, 3) or (3,) -> the robot's base frame."""
    T = np.asarray(robot.base_pose, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64)
    return p if np.array_equal(T, np.eye(4)) else matmul(p - T[:3, 3], T[:3, :3])


def camera_for(robot: Robot) -> dict[str, Any]:
    """The teacher's camera for ``robot``, in the URDF root frame (like :data:`VIEW`).

    The Nao arm gets :data:`VIEW`. Any other arm is seen from in front of
    its drawing plane, above and to the side, from far enough to hold the
    base, the plane and the arm between them.
    """
    if robot.name == "nao-v32-right-arm":
        return dict(VIEW)
    plane = robot.plane
    u, v, n = plane.axes
    centre = plane.origin
    target = 0.75 * centre  # between the base and the plane, nearer the plane
    radius = max(float(np.linalg.norm(centre)), float(np.hypot(plane.width, plane.height)))
    direction = 0.75 * n - 0.45 * u + 0.5 * v
    direction /= np.linalg.norm(direction)
    distance = 0.8 * radius / math.tan(math.radians(VIEW["fov"] / 2))
    eye = target + distance * direction
    return {"eye": tuple(to_world(robot, eye[None])[0].tolist()),
            "target": tuple(to_world(robot, target[None])[0].tolist()), "fov": VIEW["fov"]}


def approach(current: np.ndarray, first: np.ndarray, dt: float,
             max_speed: float = 0.5) -> np.ndarray:
    """Joint path from the arm's current posture to a path's first one.

    What a real arm must do before it draws: it is wherever it was left,
    not at the path's start. Each joint moves linearly, the slowest so that
    no joint exceeds ``max_speed``; the path's time step is kept.

    Parameters
    ----------
    current, first : ndarray, shape (J,)
        Joint angles (rad).
    dt : float
        Time step (s) of the returned path.
    max_speed : float
        Largest joint speed (rad/s).

    Returns
    -------
    ndarray, shape (K, J)
        From ``current`` (row 0) to ``first`` (last row), ``K >= 2``.
    """
    a = np.asarray(current, dtype=np.float64)
    b = np.asarray(first, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 1:
        raise InvalidInputError(f"current and first postures must both have shape (J,), got "
                                f"{a.shape} and {b.shape}.")
    if not (max_speed > 0 and dt > 0):
        raise InvalidInputError("approach needs max_speed > 0 and dt > 0.")
    steps = max(1, math.ceil(float(np.abs(b - a).max(initial=0.0)) / (max_speed * dt)))
    return a + np.linspace(0.0, 1.0, steps + 1)[:, None] * (b - a)


def plane_outline(plane: DrawingPlane) -> np.ndarray:
    """The drawing plane's rectangle as a closed polyline, shape (5, 3) (m, torso frame)."""
    return plane.to_3d(np.vstack([plane.corners, plane.corners[:1]]))


def path_dots(points: np.ndarray, spacing: float) -> np.ndarray:
    """Points along a polyline every ``spacing`` metres (and every vertex).

    Parameters
    ----------
    points : ndarray, shape (T, 3)
    spacing : float

    Returns
    -------
    ndarray, shape (K, 3)
    """
    out = [points[:1]]
    for a, b in itertools.pairwise(points):
        n = max(1, math.ceil(float(np.linalg.norm(b - a)) / spacing))
        s = np.arange(1, n + 1)[:, None] / n
        out.append(a + s * (b - a))
    return np.concatenate(out)

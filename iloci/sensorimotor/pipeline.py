"""Demonstration -> :class:`Motion`: the pen path in the robot's plane and the joint path.

::

    Demonstration (N x 2)  -- preprocess -->  plane points (T x 2, y-z in m)
                           -- plane.to_3d -->  pen-tip targets (T x 3, base frame)
                           -- IKSolver.solve (from the robot's q_home) --> joints (T x J)
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
import hashlib
from typing import Any

import numpy as np

from iloci.linalg import matmul
from iloci.config import Config, SensorimotorConfig
from iloci.errors import InvalidInputError, UnreachableTargetError
from iloci.interfaces import Demonstration, IKSolver
from iloci.sensorimotor.preprocess import fit_to_plane, preprocess
from iloci.sensorimotor.robots import Robot, get_robot

__all__ = ["UNTIMED_PACE", "Motion", "MotionCache", "motion_dt", "preprocessed", "tilted",
           "to_motion", "to_motions"]


@dataclass(frozen=True, eq=False)
class Motion:
    """One demonstration as the robot would perform it.

    Attributes
    ----------
    demo_key : str
        Key ``"SHAPE/INDEX"`` of the source demonstration.
    plane_points : ndarray, shape (T, 2)
        Pen path ``(y, z)`` in the drawing plane (m, torso frame).
    targets : ndarray, shape (T, 3)
        The same path in 3-D, the IK targets (m, torso frame).
    joint_path : ndarray, shape (T, J)
        Joint angles reaching the targets (rad), one column per joint of
        the robot (``J = 4`` for the Nao arm).
    dt : float
        Time between two steps (s): the demonstration's duration over
        ``T - 1``.
    """

    demo_key: str
    plane_points: np.ndarray
    targets: np.ndarray
    joint_path: np.ndarray
    dt: float

    def __post_init__(self) -> None:
        for name in ("plane_points", "targets", "joint_path"):
            a = np.array(getattr(self, name), dtype=np.float64)
            a.flags.writeable = False
            object.__setattr__(self, name, a)
        T = len(self.plane_points)
        if (self.plane_points.shape != (T, 2) or self.targets.shape != (T, 3)
                or self.joint_path.ndim != 2 or len(self.joint_path) != T):
            raise InvalidInputError(
                f"motion {self.demo_key!r}: plane_points (T, 2), targets (T, 3) and "
                f"joint_path (T, J) must share T; got {self.plane_points.shape}, "
                f"{self.targets.shape}, {self.joint_path.shape}.")
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise InvalidInputError(f"motion {self.demo_key!r}: dt must be > 0, got {self.dt}.")

    def __len__(self) -> int:
        return len(self.plane_points)

    def __repr__(self) -> str:
        return f"Motion({self.demo_key!r}, T={len(self)}, dt={self.dt:.4g})"


def _sensorimotor(config: SensorimotorConfig | Config | None) -> SensorimotorConfig:
    if config is None:
        return SensorimotorConfig()
    if isinstance(config, Config):
        return config.sensorimotor
    if isinstance(config, SensorimotorConfig):
        return config
    raise InvalidInputError(f"expected a SensorimotorConfig or Config, got "
                            f"{type(config).__name__}.")


def preprocessed(demo: Demonstration,
                 config: SensorimotorConfig | Config | None = None,
                 robot: Robot | None = None) -> np.ndarray:
    """:func:`~iloci.sensorimotor.preprocess.preprocess` with a config's settings.

    Parameters
    ----------
    robot
        The arm whose drawing plane the points are scaled to (default: the
        shipped Nao V3.2 right arm; an agent passes ``agent.robot``).

    Returns
    -------
    ndarray, shape (steps, 2)
        Plane points ``(a, b)`` of the robot's
        :class:`~iloci.sensorimotor.robots.DrawingPlane` (m; the Nao's plane:
        ``(y, z)`` in its torso frame).
    """
    cfg = _sensorimotor(config)
    plane = (robot if robot is not None else get_robot()).plane
    return preprocess(demo, steps=cfg.steps, resample_by=cfg.resample,
                      smoothing=cfg.smoothing, smoothing_window=cfg.smoothing_window,
                      rest_tolerance=cfg.rest_tolerance, y_axis=cfg.y_axis,
                      min_points=cfg.min_points, plane=plane)


def to_motion(demo: Demonstration, config: SensorimotorConfig | Config | None,
              ik: IKSolver, robot: Robot | None = None) -> Motion:
    """Preprocess a demonstration and solve IK along it.

    Parameters
    ----------
    demo : Demonstration
    config : SensorimotorConfig or Config or None
        Steps, resampling and smoothing (``None``: defaults).
    ik : IKSolver
        Solves the path, warm-started from the robot's ``q_home``.
    robot : Robot, optional
        Its plane and start posture; default: the IK solver's ``robot``
        attribute, else the Nao preset.

    Returns
    -------
    Motion

    Raises
    ------
    InvalidDemonstrationError, UnreachableTargetError
    """
    cfg = _sensorimotor(config)
    robot = _robot(ik, robot)
    points = preprocessed(demo, cfg, robot)
    return _solved(demo.key, points, motion_dt(demo, points, robot.plane.height), ik, robot)


#: The pace of a drawing given without time stamps, in heights of the robot's drawing
#: plane per second along the pen's path: LASA's median (measured over its 182
#: demonstrations in the Nao's plane, 0.1 m high: 0.045 m/s; 10th-90th percentile
#: 0.029-0.065 m/s), so an untimed drawing takes about as long as a recorded one of its
#: size and length, on any robot (a LASA G: 5 s).
UNTIMED_PACE = 0.45


def motion_dt(demo: Demonstration, points: np.ndarray, plane_height: float) -> float:
    """The time step (s) of the motion of ``demo``, whose path in the plane is ``points``.

    Timed (:attr:`~iloci.interfaces.Demonstration.timed`): its duration spread
    over the steps. Untimed (sample numbers only): the path's length in the
    plane drawn at :data:`UNTIMED_PACE` (before, one second per sample: a
    1000-sample CSV without times took 17 minutes to draw).

    Parameters
    ----------
    points : ndarray, shape (steps, 2)
        Plane points (m), as :func:`preprocessed` gives them.
    plane_height : float
        The drawing plane's height (m).
    """
    steps = len(points)
    times = demo.times
    assert times is not None  # Demonstration fills in times when none are given
    if demo.timed:
        return float(times[-1] - times[0]) / (steps - 1)
    length = float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
    return length / (UNTIMED_PACE * plane_height) / (steps - 1)


def _robot(ik: IKSolver, robot: Robot | None) -> Robot:
    """``robot``, else the IK solver's ``robot`` attribute, else the Nao preset."""
    return robot if robot is not None else getattr(ik, "robot", None) or get_robot()


def _solved(key: str, plane_points: np.ndarray, dt: float, ik: IKSolver,
            robot: Robot) -> Motion:
    """The motion along ``plane_points``: IK solved from the robot's ``q_home``."""
    targets = robot.plane.to_3d(plane_points)
    return Motion(key, plane_points, targets, _checked_path(
        ik, ik.solve(targets, q0=np.array(robot.q_home)), len(targets), robot, key), dt)


#: How far (rad or m) a solver's joint path may pass its own limits: rounding, not a fault.
LIMIT_SLACK = 1e-6


def _checked_path(ik: IKSolver, path: Any, steps: int, robot: Robot, key: str) -> np.ndarray:
    """What ``ik.solve`` returned, as a (steps, J) float array within the solver's limits.

    A solver is a plugin (or the caller's own class): its faults are said as its own,
    naming it, as an :class:`UnreachableTargetError` (a demonstration ``teach``
    skips), not found later as a network input of the wrong width.
    """
    who = f"the IK solver {type(ik).__module__}.{type(ik).__qualname__}"
    joints = len(robot.joint_names)
    try:
        arr = np.asarray(path, dtype=np.float64)
    except (TypeError, ValueError):
        raise UnreachableTargetError(f"{who} returned {type(path).__name__}, not a joint path "
                                     f"of numbers, for {key!r}.") from None
    if arr.shape != (steps, joints):
        raise UnreachableTargetError(
            f"{who} returned a joint path of shape {arr.shape} for {key!r}; it must be "
            f"({steps}, {joints}): one row per target, one column per joint of "
            f"{robot.name!r} ({', '.join(robot.joint_names)}).")
    if not np.all(np.isfinite(arr)):
        row = int(np.argwhere(~np.isfinite(arr))[0][0])
        raise UnreachableTargetError(f"{who} returned NaN or inf for {key!r} (first at "
                                     f"target {row}): a solver should raise "
                                     "UnreachableTargetError for a target it cannot reach.")
    lower, upper = getattr(ik, "lower", None), getattr(ik, "upper", None)
    if lower is not None and upper is not None:
        lo, hi = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
        if lo.shape == hi.shape == (joints,):
            beyond = (arr < lo - LIMIT_SLACK) | (arr > hi + LIMIT_SLACK)
            if beyond.any():
                row, j = (int(v) for v in np.argwhere(beyond)[0])
                raise UnreachableTargetError(
                    f"{who} returned a joint path beyond its own limits for {key!r}: joint "
                    f"{robot.joint_names[j]!r} at {arr[row, j]:.4g} (limits {lo[j]:.4g} .. "
                    f"{hi[j]:.4g}) at target {row}. The arm could not follow it; the solver "
                    "must keep within its limits or raise UnreachableTargetError.")
    return arr


def tilted(motion: Motion, degrees: float, ik: IKSolver, robot: Robot | None = None) -> Motion:
    """The motion of the same drawing turned by ``degrees`` in the drawing plane.

    The pen path is rotated about the plane's centre (counter-clockwise as
    the teacher sees it for ``degrees > 0``), fitted into the plane again as
    any drawing is (:func:`~iloci.sensorimotor.preprocess.fit_to_plane`, so
    a turned drawing fills the plane as an upright one would), and IK is
    solved along it from the robot's ``q_home``. Resampling and smoothing
    commute with a rotation, so this is the motion of the demonstration
    turned before preprocessing, without reading it again. Recognition's
    tilt search (``[learner] tilts``) uses it.

    Parameters
    ----------
    motion : Motion
        The drawing as read (:func:`to_motion`).
    degrees : float
        Angle (degrees); 0 returns ``motion`` itself.
    ik : IKSolver
    robot : Robot, optional
        As for :func:`to_motion`.

    Returns
    -------
    Motion
        Same key and ``dt``.

    Raises
    ------
    InvalidInputError
        ``degrees`` is not a finite number.
    UnreachableTargetError
        The turned path cannot be reached.
    """
    try:
        a = float(degrees)
    except (TypeError, ValueError):
        a = float("nan")
    if not np.isfinite(a):
        raise InvalidInputError(f"tilt must be a finite number of degrees, got {degrees!r}.")
    if a == 0.0:
        return motion
    robot = _robot(ik, robot)
    plane = robot.plane
    c, s = np.cos(np.deg2rad(a)), np.sin(np.deg2rad(a))
    turned = matmul(motion.plane_points - plane.center, np.array([[c, s], [-s, c]])) + plane.center
    return _solved(motion.demo_key, fit_to_plane(turned, plane), motion.dt, ik, robot)


def to_motions(demos: Iterable[Demonstration], config: SensorimotorConfig | Config | None,
               ik: IKSolver, robot: Robot | None = None) -> list[Motion]:
    """:func:`to_motion` of each demonstration, in order."""
    return [to_motion(d, config, ik, robot) for d in demos]


class MotionCache:
    """Motions of demonstrations already converted, for one set of conversion settings.

    :func:`to_motion` (preprocessing + IK, a few ms per demonstration) gives
    the same motion for the same demonstration whenever the sensorimotor
    settings, the robot and the IK solver are the same. An evaluation meets
    each demonstration in every fold (in the learning set of one, in the
    test set of the others); an agent given a cache
    (:attr:`iloci.agent.Agent.motion_cache`) converts each once per process.

    A cache holds motions for ONE conversion setting: its owner keeps it
    for one config (sensorimotor section, robot, IK solver) and never
    shares it between configs. Entries are keyed by the demonstration's key
    and a BLAKE2b digest of its positions, times and whether they were given, so a changed or
    perturbed demonstration under the same key is converted anew, never
    answered with another's motion.

    Parameters
    ----------
    max_items : int
        Motions kept (oldest dropped first); about 4 KB each at 50 steps.
    """

    def __init__(self, max_items: int = 4096) -> None:
        if max_items < 1:
            raise InvalidInputError(f"max_items must be >= 1, got {max_items}.")
        self.max_items = max_items
        self._items: dict[tuple[str, bytes], Motion] = {}
        #: Lookups answered from the cache, and conversions run.
        self.hits = 0
        self.misses = 0

    def __len__(self) -> int:
        return len(self._items)

    @staticmethod
    def _key(demo: Demonstration) -> tuple[str, bytes]:
        h = hashlib.blake2b(digest_size=16)
        for a in (demo.positions, demo.times):
            a = np.ascontiguousarray(a, dtype=np.float64)
            h.update(repr(a.shape).encode())
            h.update(a.tobytes())
        h.update(b"timed" if demo.timed else b"untimed")   # the same times, another pace
        return demo.key, h.digest()

    def get(self, demo: Demonstration, convert: Callable[[Demonstration], Motion]) -> Motion:
        """The motion of ``demo``: from the cache, else ``convert(demo)`` (then kept).

        Errors of ``convert`` (an unusable or unreachable demonstration)
        propagate and nothing is kept.
        """
        key = self._key(demo)
        motion = self._items.get(key)
        if motion is not None:
            self.hits += 1
            return motion
        motion = convert(demo)
        self.misses += 1
        self._keep(key, motion)
        return motion

    def _keep(self, key: tuple[str, bytes], motion: Motion) -> None:
        if key not in self._items and len(self._items) >= self.max_items:
            del self._items[next(iter(self._items))]
        self._items[key] = motion

    def converted(self, demos: Sequence[Demonstration]) -> list[tuple[tuple[str, bytes], Motion]]:
        """The motions of those of ``demos`` this cache holds, for another cache's :meth:`add`.

        Returns
        -------
        list of (key, Motion)
            Keyed as here (the demonstration's key and the digest of its
            samples), so another cache answers only the same demonstration
            with them.
        """
        keys = (self._key(d) for d in demos)
        return [(k, self._items[k]) for k in keys if k in self._items]

    def add(self, converted: Sequence[tuple[tuple[str, bytes], Motion]]) -> None:
        """Keep motions another cache converted (:meth:`converted`), e.g. in another
        process, under the same conversion settings (its owner's responsibility, as
        for the motions it converts itself)."""
        for key, motion in converted:
            self._keep(key, motion)

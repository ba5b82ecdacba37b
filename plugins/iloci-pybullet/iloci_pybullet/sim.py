"""The Nao arm drawing in PyBullet: position-controlled tracking of a joint path.

One headless (``DIRECT``) physics client per simulator, the robot's URDF
loaded once, fixed base, gravity on. :meth:`PyBulletSimulator.execute`
tracks a joint path the way a servoed arm does:

* the arm starts at rest in the path's first posture (the robot moves there
  with the pen lifted before it draws);
* each joint's set-point moves linearly from one path point to the next
  over the path's time step ``dt``, and its target velocity is that
  segment's velocity (the velocity feed-forward of a trajectory-following
  servo), as Nao's motion controller interpolates the commands it is sent;
* PyBullet's ``POSITION_CONTROL`` motor follows the set-point with at most
  the joint's effort limit from the URDF (1.33 N m, elbow roll 0.54 N m),
  against gravity and the links' inertia, at ``ceil(dt / timestep)``
  physics steps per path step, the set-point updated at each.

What is returned is what the arm reached: joint angles and the pen tip
(the URDF frame of ``r_pen_tip``) at each time of the path.

Images come from PyBullet's software renderer (``ER_TINY_RENDERER``), which
needs no display or GPU.
"""

from __future__ import annotations

import contextlib
import ctypes
import itertools
import math
import os
import sys
from collections.abc import Iterator
from typing import Self

import numpy as np

from iloci.errors import IlociError, InvalidInputError
from iloci.interfaces import Execution
from iloci.sensorimotor.robots import Robot, get_robot


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """Silence PyBullet's C-level banners ("pybullet build time" on stderr when
    imported, "argv[0]=" on stdout when connecting)."""
    try:
        fds = [sys.stdout.fileno(), sys.stderr.fileno()]
    except (AttributeError, OSError, ValueError):  # streams replaced (e.g. captured)
        yield
        return
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(fd) for fd in fds]
    try:
        with open(os.devnull, "wb") as null:
            for fd in fds:
                os.dup2(null.fileno(), fd)
        yield
    finally:
        # C stdio may still hold the banner: flush it into /dev/null first
        with contextlib.suppress(Exception):
            ctypes.CDLL(None).fflush(None)
        for fd, old in zip(fds, saved):
            os.dup2(old, fd)
            os.close(old)


with _quiet():
    import pybullet as pb
    from pybullet_utils.bullet_client import BulletClient

__all__ = ["VIEW", "PyBulletSimulator"]

#: Camera of :meth:`PyBulletSimulator.render`: the teacher's view, in front of
#: the robot, above and to the side of its right arm (m, torso frame), with a
#: vertical field of view in degrees. Seen from the front, the drawing reads
#: as the teacher drew it (see :mod:`iloci.sensorimotor.preprocess`).
VIEW = {"eye": (0.45, -0.28, 0.25), "target": (0.11, -0.12, 0.11), "fov": 38.0}

_PEN_RGBA = (0.10, 0.20, 0.80, 1.0)
_START_RGBA = (0.10, 0.70, 0.20, 1.0)
_FRAME_RGBA = (0.55, 0.55, 0.55, 1.0)
#: Dots available to draw a pen path, and where unused ones wait (out of view).
_POOL = 800
_PARKED = (0.0, 0.0, -10.0)


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


def check_image_size(width: int, height: int, largest: int = 4096) -> tuple[int, int]:
    """Validate an image size in pixels; returns ``(width, height)`` as ints."""
    out = []
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or \
                not 1 <= int(v) <= largest:
            raise InvalidInputError(
                f"image {name} must be an integer number of pixels in 1..{largest}, "
                f"got {v!r}.")
        out.append(int(v))
    return out[0], out[1]


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


class PyBulletSimulator:
    """The ``pybullet`` Simulator: a Nao arm tracking joint paths in PyBullet.

    Parameters
    ----------
    robot : str or Robot
        Robot name (see :func:`iloci.sensorimotor.robots.get_robot`) or a
        :class:`~iloci.sensorimotor.robots.Robot`.
    timestep : float
        Longest physics step (s).
    position_gain, velocity_gain : float
        Gains of PyBullet's ``POSITION_CONTROL`` motors.
    gravity : float
        Gravity (m/s^2) along -z; 0 switches it off.

    Attributes
    ----------
    robot : Robot
    joint_names : tuple of str
        The ``J = 4`` actuated joints, in column order.
    lower, upper : ndarray, shape (J,)
        Joint limits (rad).

    Notes
    -----
    The URDF is loaded once per instance; :meth:`execute` restores the
    state saved after loading, so repeated calls are independent and
    deterministic. The arm's own links do not collide with one another
    (PyBullet's default without ``URDF_USE_SELF_COLLISION``).
    """

    def __init__(self, robot: str | Robot = "nao-v32-right-arm", timestep: float = 0.001,
                 position_gain: float = 0.1, velocity_gain: float = 1.0,
                 gravity: float = 9.81) -> None:
        for name, v, ok in (("timestep", timestep, timestep > 0),
                            ("position_gain", position_gain, position_gain > 0),
                            ("velocity_gain", velocity_gain, velocity_gain >= 0),
                            ("gravity", gravity, gravity >= 0)):
            if not (math.isfinite(v) and ok):
                raise InvalidInputError(f"{name} = {v!r} is out of range; see "
                                        "iloci_pybullet.PyBulletParams.")
        self.robot = robot if isinstance(robot, Robot) else get_robot(robot)
        self.timestep = float(timestep)
        self.position_gain = float(position_gain)
        self.velocity_gain = float(velocity_gain)
        self.gravity = float(gravity)
        self.joint_names = tuple(self.robot.joint_names)
        self.lower = np.array(self.robot.lower, dtype=np.float64)
        self.upper = np.array(self.robot.upper, dtype=np.float64)

        with _quiet():
            self._client: BulletClient | None = BulletClient(connection_mode=pb.DIRECT)
        c = self._client
        c.setGravity(0.0, 0.0, -self.gravity)
        # the torso frame is the world frame: base at the origin, fixed
        self._body = c.loadURDF(str(self.robot.urdf_path), basePosition=(0, 0, 0),
                                useFixedBase=True, flags=pb.URDF_USE_INERTIA_FROM_FILE)
        joints = {}
        links = {}
        for i in range(c.getNumJoints(self._body)):
            info = c.getJointInfo(self._body, i)
            joints[info[1].decode()] = (i, info[2], info[10])
            links[info[12].decode()] = i
        missing = [n for n in self.joint_names if n not in joints]
        if missing or self.robot.end_effector_frame not in links:
            raise InvalidInputError(
                f"URDF {self.robot.urdf_path} lacks joint(s) {missing} or the pen-tip link "
                f"{self.robot.end_effector_frame!r} that robot {self.robot.name!r} names.")
        self._joints = [joints[n][0] for n in self.joint_names]
        if any(joints[n][1] != pb.JOINT_REVOLUTE for n in self.joint_names):
            raise InvalidInputError(f"the joints {self.joint_names} of {self.robot.name!r} "
                                    "must be revolute in its URDF.")
        # the motors' torque limit is the URDF's effort limit
        self._forces = [float(joints[n][2]) for n in self.joint_names]
        self._pen = links[self.robot.end_effector_frame]
        # switch off the default velocity motors on every other movable joint
        others = [i for n, (i, kind, _) in joints.items()
                  if kind != pb.JOINT_FIXED and n not in self.joint_names]
        if others:
            c.setJointMotorControlArray(self._body, others, pb.VELOCITY_CONTROL,
                                        forces=[0.0] * len(others))
        self._home_state = c.saveState()
        self._scene: BulletClient | None = None

    def __repr__(self) -> str:
        return (f"PyBulletSimulator(robot={self.robot.name!r}, timestep={self.timestep}, "
                f"gravity={self.gravity})")

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ engine
    @property
    def _c(self) -> BulletClient:
        if self._client is None:
            raise IlociError("this PyBulletSimulator was closed; build a new one "
                             "(iloci.build(config).simulator or PyBulletSimulator()).")
        return self._client

    def _set_posture(self, q: np.ndarray) -> None:
        c = self._c
        for j, qj in zip(self._joints, q):
            c.resetJointState(self._body, j, float(qj), 0.0)

    def _pen_position(self) -> tuple[float, float, float]:
        return self._c.getLinkState(self._body, self._pen, computeForwardKinematics=True)[4]

    def _joint_positions(self) -> list[float]:
        return [s[0] for s in self._c.getJointStates(self._body, self._joints)]

    def forward(self, q: np.ndarray) -> np.ndarray:
        """Pen-tip positions by PyBullet's kinematics (postures set, no dynamics).

        Parameters
        ----------
        q : ndarray, shape (T, J) or (J,)
            Joint angles (rad).

        Returns
        -------
        ndarray, shape (T, 3) or (3,)
            Pen-tip positions (m, torso frame).
        """
        single = np.ndim(q) == 1
        qs, _ = check_joint_path(np.atleast_2d(q), 1.0, self.robot, limits=False)
        out = np.empty((len(qs), 3))
        for i, qi in enumerate(qs):
            self._set_posture(qi)
            out[i] = self._pen_position()
        return out[0] if single else out

    def execute(self, joint_path: np.ndarray, dt: float) -> Execution:
        """Track a joint path under position control.

        Parameters
        ----------
        joint_path : ndarray, shape (T, J)
            Joint angles (rad) at times ``0, dt, 2 dt, ...``, within the limits.
        dt : float
            Time between two rows (s).

        Returns
        -------
        Execution
            ``joint_path`` (T, J): the angles reached at each time;
            ``end_effector`` (T, 3): the pen tip reached (m, torso frame);
            ``dt``. Row 0 is the start posture itself.

        Raises
        ------
        InvalidInputError
            Wrong shape, NaN or inf, a joint outside its limits, or ``dt <= 0``.
        """
        q, step = check_joint_path(joint_path, dt, self.robot)
        c = self._c
        c.restoreState(self._home_state)
        n = max(1, math.ceil(step / self.timestep - 1e-9))
        c.setTimeStep(step / n)
        self._set_posture(q[0])
        body, joints, forces = self._body, self._joints, self._forces
        kp = [self.position_gain] * len(joints)
        kv = [self.velocity_gain] * len(joints)
        reached_q = np.empty_like(q)
        reached_x = np.empty((len(q), 3))
        reached_q[0] = self._joint_positions()
        reached_x[0] = self._pen_position()
        fractions = np.arange(1, n + 1) / n
        for i in range(len(q) - 1):
            delta = q[i + 1] - q[i]
            velocity = (delta / step).tolist()
            for s in fractions:
                c.setJointMotorControlArray(
                    body, joints, pb.POSITION_CONTROL,
                    targetPositions=(q[i] + s * delta).tolist(), targetVelocities=velocity,
                    forces=forces, positionGains=kp, velocityGains=kv)
                c.stepSimulation()
            reached_q[i + 1] = self._joint_positions()
            reached_x[i + 1] = self._pen_position()
        return Execution(joint_path=reached_q, end_effector=reached_x, dt=step)

    # ------------------------------------------------------------------ render
    def _scene_client(self) -> BulletClient:
        """The second, never-stepped client the images are rendered in (made once).

        It holds a copy of the arm and a pool of dot bodies that draw the
        path. They live apart from the physics client because every extra
        body there slows stepping (600 dots: 20 times).
        """
        self._c  # noqa: B018  (raises when closed)
        if self._scene is not None:
            return self._scene
        with _quiet():
            c = BulletClient(connection_mode=pb.DIRECT)
        body = c.loadURDF(str(self.robot.urdf_path), basePosition=(0, 0, 0),
                          useFixedBase=True)

        def dots(points, radius, rgba) -> list[int]:
            shape = c.createVisualShape(pb.GEOM_SPHERE, radius=radius, rgbaColor=rgba)
            # one body per dot: PyBullet's batch creation returns unusable ids
            return [c.createMultiBody(baseMass=0, baseVisualShapeIndex=shape,
                                      basePosition=tuple(map(float, p))) for p in points]

        plane = self.robot.plane
        dots(path_dots(plane.to_3d(np.vstack([plane.corners, plane.corners[:1]])), 0.004),
             0.0008, _FRAME_RGBA)
        parked = np.tile(_PARKED, (_POOL, 1))
        self._scene = c
        self._scene_body = body
        self._pen_dots = dots(parked, 0.0016, _PEN_RGBA)
        self._start_dot = dots(parked[:1], 0.003, _START_RGBA)[0]
        self._dots_used = 0
        return c

    def render(self, execution: Execution, width: int = 480, height: int = 360) -> np.ndarray:
        """Image of the arm in its last posture and the path its pen drew.

        The pen path (``execution.end_effector``) is drawn in blue with its
        start in green; grey dots outline the robot's drawing plane. The
        camera is :data:`VIEW`. Rendering does not touch the physics: it
        happens in a separate PyBullet client.

        Parameters
        ----------
        execution : Execution
            As returned by :meth:`execute` (a prefix of one shows the drawing
            so far).
        width, height : int
            Image size (pixels).

        Returns
        -------
        ndarray, shape (height, width, 3), uint8
        """
        w, h = check_image_size(width, height)
        if not isinstance(execution, Execution):
            raise InvalidInputError(f"render takes an Execution (from execute), got "
                                    f"{type(execution).__name__}.")
        q, _ = check_joint_path(execution.joint_path, execution.dt, self.robot, limits=False)
        pen = np.asarray(execution.end_effector, dtype=np.float64)
        if pen.shape != (len(q), 3) or not np.all(np.isfinite(pen)):
            raise InvalidInputError(
                f"execution.end_effector must be finite with shape ({len(q)}, 3), got "
                f"{pen.shape}.")
        c = self._scene_client()
        for j, qj in zip(self._joints, q[-1]):
            c.resetJointState(self._scene_body, j, float(qj), 0.0)
        # dots 0.8 mm apart (radius 1.6 mm) make a solid line; a very long
        # path spreads the pool's dots further apart
        length = float(np.linalg.norm(np.diff(pen, axis=0), axis=1).sum())
        points = path_dots(pen, max(0.0008, 1.05 * length / (_POOL - len(pen))))[:_POOL]
        move = c.resetBasePositionAndOrientation
        for i, p in zip(self._pen_dots, points):
            move(i, tuple(map(float, p)), (0, 0, 0, 1))
        for i in self._pen_dots[len(points):self._dots_used]:
            move(i, _PARKED, (0, 0, 0, 1))
        self._dots_used = len(points)
        move(self._start_dot, tuple(map(float, pen[0])), (0, 0, 0, 1))
        view = c.computeViewMatrix(VIEW["eye"], VIEW["target"], (0, 0, 1))
        proj = c.computeProjectionMatrixFOV(VIEW["fov"], w / h, 0.01, 5.0)
        img = c.getCameraImage(w, h, view, proj, renderer=pb.ER_TINY_RENDERER,
                               lightDirection=(1.0, -0.6, 1.5), shadow=0)
        rgba = np.reshape(np.asarray(img[2], dtype=np.uint8), (h, w, 4))
        return np.ascontiguousarray(rgba[:, :, :3])

    def close(self) -> None:
        """Disconnect the physics and rendering clients (idempotent)."""
        for attr in ("_client", "_scene"):
            client = getattr(self, attr, None)
            setattr(self, attr, None)
            if client is not None:
                with contextlib.suppress(Exception):
                    client.disconnect()

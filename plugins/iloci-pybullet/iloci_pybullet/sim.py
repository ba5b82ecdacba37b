"""The Nao arm drawing in PyBullet: position-controlled tracking of a joint path.

One headless (``DIRECT``) physics client per simulator, the robot's URDF
loaded once, fixed base, gravity on. :meth:`PyBulletSimulator.execute`
tracks a joint path the way a servoed arm does:

* the arm starts at rest in the path's first posture (the robot moves there
  with the pen lifted before it draws);
* each joint's set-point moves linearly from one path point to the next
  over the path's time step ``dt``, and its target velocity is that
  segment's velocity (the velocity feed-forward of a trajectory-following
  servo), as Nao's motion controller interpolates the commands it is sent
  (:func:`iloci.sensorimotor.simulation.setpoints`);
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
import os
import sys
import tempfile
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Self

import numpy as np

from iloci.errors import IlociError, InvalidInputError
from iloci.interfaces import Execution
from iloci.sensorimotor import simulation
from iloci.sensorimotor.robots import Robot, get_robot
from iloci.sensorimotor.robots.urdf import read_urdf, resolved_urdf_text
from iloci_pybullet.params import PyBulletParams


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

__all__ = ["PyBulletSimulator"]

#: Dots available to draw a pen path, and where unused ones wait (out of view).
_POOL = 800
_PARKED = (0.0, 0.0, -10.0)


class PyBulletSimulator:
    """The ``pybullet`` Simulator: a Nao arm tracking joint paths in PyBullet.

    Parameters
    ----------
    robot : str or Robot
        A robot of :mod:`iloci.sensorimotor.robots`, by name or itself.
    timestep, position_gain, velocity_gain, gravity : float
        The physics step (s), the motors' gains and gravity (m/s^2), as
        :class:`~iloci_pybullet.params.PyBulletParams` describes them.

    Attributes
    ----------
    robot : Robot
        Its ``joint_names`` (the J columns of a joint path) and joint limits
        ``lower``, ``upper`` (J,) are attributes of the simulator too.

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
        simulation.check_settings(PyBulletParams(
            timestep=timestep, position_gain=position_gain, velocity_gain=velocity_gain,
            gravity=gravity))
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
        # the URDF with its mesh names resolved (package://, relative) to absolute paths
        self._urdf_dir = tempfile.TemporaryDirectory(prefix="iloci-pybullet-")
        self._urdf = Path(self._urdf_dir.name) / self.robot.urdf_path.name
        self._urdf.write_text(resolved_urdf_text(self.robot.urdf_path, self.robot.package_dirs),
                              encoding="utf-8")
        # the URDF's root frame is the world frame: root at the origin, fixed
        massless = read_urdf(self.robot.urdf_path).massless_moving()
        if massless:  # said once here, not as PyBullet's C-level line per link
            warnings.warn(
                f"{self.robot.urdf_path}: link(s) {', '.join(map(repr, massless))} move with a "
                "joint but have no <inertial>; PyBullet gives each 1 kg and an inertia of "
                "1 kg m^2, so the arm tracks its joint path less closely. Add <inertial> "
                "elements with the real masses for a faithful simulation.",
                UserWarning, stacklevel=2)
        try:
            with _quiet():  # PyBullet's b3Warning lines (a missing inertial, ...)
                self._body = c.loadURDF(str(self._urdf), basePosition=(0, 0, 0),
                                        useFixedBase=True,
                                        flags=pb.URDF_USE_INERTIA_FROM_FILE)
        except pb.error as exc:
            raise InvalidInputError(f"PyBullet cannot load the URDF of {self.robot.name!r} "
                                    f"({self.robot.urdf_path}): {exc}") from None
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
        # every other movable joint is held where the robot fixes it (the IK
        # assumes it there), by a motor as strong as its effort limit (>= 1)
        held = [(i, float(self.robot.fixed_joints.get(n, 0.0)), max(float(f), 1.0))
                for n, (i, kind, f) in joints.items()
                if kind != pb.JOINT_FIXED and n not in self.joint_names]
        for i, value, force in held:
            c.resetJointState(self._body, i, value, 0.0)
            c.setJointMotorControl2(self._body, i, pb.POSITION_CONTROL, targetPosition=value,
                                    force=force)
        self._home_state = c.saveState()
        # pen and outline thickness grow with the plane (drawn for the Nao's 10 cm)
        self._scale = max(1.0, max(self.robot.plane.width, self.robot.plane.height) / 0.1)
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

    def _pen_position(self) -> np.ndarray:
        world = self._c.getLinkState(self._body, self._pen, computeForwardKinematics=True)[4]
        return simulation.to_base(self.robot, np.array(world))

    def _joint_positions(self) -> list[float]:
        return [s[0] for s in self._c.getJointStates(self._body, self._joints)]

    def forward(self, q: np.ndarray) -> np.ndarray:
        """Pen-tip positions of postures by PyBullet's kinematics (no dynamics).

        ``q`` is (T, J) or (J,) in rad; each posture is set in the physics
        client and its pen tip read: (T, 3) or (3,), m, torso frame.
        """
        qs, single = simulation.check_postures(q, self.robot)
        out = np.empty((len(qs), 3))
        for i, qi in enumerate(qs):
            self._set_posture(qi)
            out[i] = self._pen_position()
        return out[0] if single else out

    def execute(self, joint_path: np.ndarray, dt: float) -> Execution:
        """Track a joint path (T, J) with PyBullet's ``POSITION_CONTROL`` motors.

        One physics step per set-point update. Returns the
        :class:`~iloci.interfaces.Execution` reached: ``joint_path`` (T, J)
        and ``end_effector`` (T, 3); shapes and errors are those of
        :meth:`iloci.interfaces.Simulator.execute`.
        """
        q, step = simulation.check_joint_path(joint_path, dt, self.robot)
        c = self._c
        c.restoreState(self._home_state)
        c.setTimeStep(step / simulation.updates_per_step(step, self.timestep))
        self._set_posture(q[0])
        body, joints, forces = self._body, self._joints, self._forces
        kp = [self.position_gain] * len(joints)
        kv = [self.velocity_gain] * len(joints)

        def hold(target: np.ndarray, velocity: np.ndarray) -> None:
            c.setJointMotorControlArray(
                body, joints, pb.POSITION_CONTROL, targetPositions=target.tolist(),
                targetVelocities=velocity.tolist(), forces=forces, positionGains=kp,
                velocityGains=kv)
            c.stepSimulation()

        def read() -> tuple[list[float], tuple[float, float, float]]:
            return self._joint_positions(), self._pen_position()

        return simulation.track(q, step, self.timestep, hold, read)

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
            body = c.loadURDF(str(self._urdf), basePosition=(0, 0, 0), useFixedBase=True)

        def dots(points, radius, rgba) -> list[int]:
            shape = c.createVisualShape(pb.GEOM_SPHERE, radius=radius, rgbaColor=rgba)
            # one body per dot: PyBullet's batch creation returns unusable ids
            return [c.createMultiBody(baseMass=0, baseVisualShapeIndex=shape,
                                      basePosition=tuple(map(float, p))) for p in points]

        outline = simulation.to_world(self.robot, simulation.plane_outline(self.robot.plane))
        dots(simulation.path_dots(outline, 0.004 * self._scale), self._scale *
             simulation.FRAME_RADIUS, simulation.FRAME_RGBA)
        parked = np.tile(_PARKED, (_POOL, 1))
        self._scene = c
        self._scene_body = body
        self._pen_dots = dots(parked, self._scale * simulation.PEN_RADIUS, simulation.PEN_RGBA)
        self._start_dot = dots(parked[:1], self._scale * simulation.START_RADIUS,
                               simulation.START_RGBA)[0]
        self._dots_used = 0
        return c

    def render(self, execution: Execution, width: int = 480, height: int = 360) -> np.ndarray:
        """Image (height, width, 3) uint8 of the arm and the path its pen drew.

        PyBullet's software renderer draws ``execution`` (see
        :meth:`iloci.interfaces.Simulator.render`): the arm in its last
        posture, the pen path as blue dots starting at a green one, grey dots
        around the drawing plane, seen from
        :data:`iloci.sensorimotor.simulation.VIEW`. It does not touch the
        physics: the scene lives in a second PyBullet client.
        """
        w, h = simulation.check_image_size(width, height)
        q, pen = simulation.check_execution(execution, self.robot)
        pen = simulation.to_world(self.robot, pen)
        c = self._scene_client()
        for j, qj in zip(self._joints, q[-1]):
            c.resetJointState(self._scene_body, j, float(qj), 0.0)
        # dots 0.8 mm apart (radius 1.6 mm) make a solid line; a very long
        # path spreads the pool's dots further apart
        length = float(np.linalg.norm(np.diff(pen, axis=0), axis=1).sum())
        spacing = max(0.0008 * self._scale, 1.05 * length / (_POOL - len(pen)))
        points = simulation.path_dots(pen, spacing)[:_POOL]
        move = c.resetBasePositionAndOrientation
        for i, p in zip(self._pen_dots, points):
            move(i, tuple(map(float, p)), (0, 0, 0, 1))
        for i in self._pen_dots[len(points):self._dots_used]:
            move(i, _PARKED, (0, 0, 0, 1))
        self._dots_used = len(points)
        move(self._start_dot, tuple(map(float, pen[0])), (0, 0, 0, 1))
        camera = simulation.camera_for(self.robot)
        view = c.computeViewMatrix(camera["eye"], camera["target"], (0, 0, 1))
        proj = c.computeProjectionMatrixFOV(camera["fov"], w / h, 0.01, 20.0)
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

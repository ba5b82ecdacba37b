"""The Nao arm drawing in MuJoCo: position servos tracking a joint path.

The robot's URDF is compiled once per simulator through :class:`mujoco.MjSpec`,
which adds what a URDF cannot say:

* one **position servo** (``kp``) and one **velocity servo** (``kv``) per
  actuated joint; together they are a PD controller with velocity
  feed-forward, the torque clamped by the joint's effort limit from the URDF
  (MuJoCo imports it as ``actuatorfrcrange``: 1.33 N m, elbow roll 0.54 N m);
* the ``implicitfast`` integrator, which integrates the servos' damping
  implicitly; with it the stiff servos are stable at the 0.2 ms physics step
  even while one is at its torque limit (at 1 ms they oscillate then: the
  elbow-yaw inertia is only about 1e-4 kg m^2);
* **no contacts between the arm's own links**, as in PyBullet without
  ``URDF_USE_SELF_COLLISION``: the URDF's primitive cylinders overlap at the
  elbow for bent-elbow postures inside the joint limits (Nao's real links
  do not), and the contact would push the arm off its path;
* a light backdrop and an offscreen framebuffer for :meth:`render`.

:meth:`MuJoCoSimulator.execute` starts the arm at rest in the path's first
posture, moves each servo's set-point linearly from one path point to the
next over ``dt`` (updated every ``control_period``, 1 ms) with that
segment's velocity as the velocity set-point, and steps the physics
(``timestep``, 0.2 ms) against gravity. It returns the joint angles and the pen tip (the ``r_pen_tip``
body) reached at each time of the path.

Rendering is offscreen OpenGL. On a Linux machine without a display, this
module selects EGL (``MUJOCO_GL=egl``) unless ``MUJOCO_GL`` is set; it needs
Mesa's or a GPU driver's ``libEGL`` (Debian/Ubuntu: ``apt-get install
libegl1``). ``MUJOCO_GL=osmesa`` (pure software) needs ``libosmesa6``
instead. The variable is read when MuJoCo is first imported, so set it
before anything imports ``mujoco``. Without a working context,
:meth:`~MuJoCoSimulator.render` raises
:class:`~iloci.errors.MissingBackendError` saying this; :meth:`execute`
needs no OpenGL at all.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
from typing import Self

import numpy as np

from iloci.errors import IlociError, InvalidInputError, MissingBackendError
from iloci.interfaces import Execution
from iloci.sensorimotor.robots import Robot, get_robot
from iloci_mujoco import choose_opengl

choose_opengl()
try:
    import mujoco
except ImportError:
    raise
except Exception as exc:  # noqa: BLE001  (MuJoCo starts OpenGL on import; it may fail)
    mujoco = None
    _IMPORT_ERROR: MissingBackendError | None = MissingBackendError(
        "simulator", "mujoco",
        [(f"a working OpenGL back end (MuJoCo failed to import with MUJOCO_GL="
          f"{os.environ.get('MUJOCO_GL', '')!r}: {type(exc).__name__}: {exc})")],
        "unset MUJOCO_GL or set MUJOCO_GL=egl (needs libEGL: apt-get install libegl1); "
        "MUJOCO_GL=osmesa needs apt-get install libosmesa6")
else:
    _IMPORT_ERROR = None

__all__ = ["RENDER_HELP", "VIEW", "MuJoCoSimulator"]

#: Camera of :meth:`MuJoCoSimulator.render`, the same as the ``pybullet``
#: simulator's: in front of the robot, above and to the side of its right arm
#: (m, torso frame), vertical field of view in degrees.
VIEW = {"eye": (0.45, -0.28, 0.25), "target": (0.11, -0.12, 0.11), "fov": 38.0}

#: What offscreen rendering needs, quoted by the error when it fails.
RENDER_HELP = ("on a headless Linux machine: apt-get install libegl1 and set MUJOCO_GL=egl, "
               "or apt-get install libosmesa6 and set MUJOCO_GL=osmesa, before mujoco is "
               "first imported")

_PEN_RGBA = np.array([0.10, 0.20, 0.80, 1.0], dtype=np.float32)
_START_RGBA = np.array([0.10, 0.70, 0.20, 1.0], dtype=np.float32)
_FRAME_RGBA = np.array([0.55, 0.55, 0.55, 1.0], dtype=np.float32)
#: Largest image side (pixels) :meth:`MuJoCoSimulator.render` accepts.
MAX_IMAGE_SIZE = 4096


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


def check_image_size(width: int, height: int,
                     largest: int = MAX_IMAGE_SIZE) -> tuple[int, int]:
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


class MuJoCoSimulator:
    """The ``mujoco`` Simulator: a Nao arm tracking joint paths in MuJoCo.

    Parameters
    ----------
    robot : str or Robot
        Robot name (see :func:`iloci.sensorimotor.robots.get_robot`) or a
        :class:`~iloci.sensorimotor.robots.Robot`.
    control_period : float
        Longest period (s) between two set-point updates.
    timestep : float
        Longest physics step (s), at most ``control_period``.
    kp : float
        Stiffness of each joint's position servo (N m / rad).
    kv : float
        Gain of each joint's velocity servo (N m s / rad).
    gravity : float
        Gravity (m/s^2) along -z; 0 switches it off.

    Attributes
    ----------
    robot : Robot
    joint_names : tuple of str
        The ``J = 4`` actuated joints, in column order.
    lower, upper : ndarray, shape (J,)
        Joint limits (rad).
    model : mujoco.MjModel
        The compiled robot with its servos.

    Notes
    -----
    The model is compiled once per instance; :meth:`execute` resets the
    simulation state, so repeated calls are independent and deterministic.
    """

    def __init__(self, robot: str | Robot = "nao-v32-right-arm",
                 control_period: float = 0.001, timestep: float = 0.0002,
                 kp: float = 1000.0, kv: float = 2.0, gravity: float = 9.81) -> None:
        if _IMPORT_ERROR is not None:
            raise _IMPORT_ERROR
        for name, v, ok in (("control_period", control_period, control_period > 0),
                            ("timestep", timestep, 0 < timestep <= control_period),
                            ("kp", kp, kp > 0), ("kv", kv, kv >= 0),
                            ("gravity", gravity, gravity >= 0)):
            if not (math.isfinite(v) and ok):
                raise InvalidInputError(f"{name} = {v!r} is out of range; see "
                                        "iloci_mujoco.MuJoCoParams.")
        self.robot = robot if isinstance(robot, Robot) else get_robot(robot)
        self.control_period = float(control_period)
        self.timestep = float(timestep)
        self.kp = float(kp)
        self.kv = float(kv)
        self.gravity = float(gravity)
        self.joint_names = tuple(self.robot.joint_names)
        self.lower = np.array(self.robot.lower, dtype=np.float64)
        self.upper = np.array(self.robot.upper, dtype=np.float64)
        self.model = self._compile()
        self._data: mujoco.MjData | None = mujoco.MjData(self.model)
        m = self.model
        self._qadr = np.array([m.jnt_qposadr[m.joint(n).id] for n in self.joint_names])
        self._pen = m.body(self.robot.end_effector_frame).id
        self._renderer: mujoco.Renderer | None = None

    def _compile(self) -> mujoco.MjModel:
        try:
            spec = mujoco.MjSpec.from_file(str(self.robot.urdf_path))
        except Exception as exc:  # noqa: BLE001  (MuJoCo's parser error, own message)
            raise InvalidInputError(f"MuJoCo cannot load the URDF of {self.robot.name!r} "
                                    f"({self.robot.urdf_path}): {exc}") from None
        joints = {j.name: j for j in spec.joints}
        bodies = [b.name for b in spec.bodies if b.name != "world"]
        missing = [n for n in self.joint_names if n not in joints]
        if missing or self.robot.end_effector_frame not in bodies:
            raise InvalidInputError(
                f"URDF {self.robot.urdf_path} compiled by MuJoCo lacks joint(s) {missing} or "
                f"the pen-tip body {self.robot.end_effector_frame!r} that robot "
                f"{self.robot.name!r} names (keep fusestatic='false' in its <mujoco> tag).")
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        spec.option.gravity = [0.0, 0.0, -self.gravity]
        spec.option.timestep = self.timestep
        for i, a in enumerate(bodies):
            for b in bodies[i + 1:]:
                ex = spec.add_exclude()
                ex.bodyname1, ex.bodyname2 = a, b
        for n in self.joint_names:
            act = spec.add_actuator()
            act.name, act.target, act.trntype = f"{n}_position", n, mujoco.mjtTrn.mjTRN_JOINT
            act.set_to_position(kp=self.kp)
        for n in self.joint_names:
            act = spec.add_actuator()
            act.name, act.target, act.trntype = f"{n}_velocity", n, mujoco.mjtTrn.mjTRN_JOINT
            act.set_to_velocity(kv=self.kv)
        # white-to-grey backdrop (MuJoCo's default background is black)
        sky = spec.add_texture()
        sky.name, sky.type = "backdrop", mujoco.mjtTexture.mjTEXTURE_SKYBOX
        sky.builtin = mujoco.mjtBuiltin.mjBUILTIN_GRADIENT
        sky.rgb1, sky.rgb2 = [1.0, 1.0, 1.0], [0.85, 0.85, 0.88]
        sky.width = sky.height = 64
        spec.visual.headlight.ambient = [0.45, 0.45, 0.45]
        spec.visual.headlight.diffuse = [0.55, 0.55, 0.55]
        spec.visual.global_.fovy = VIEW["fov"]
        return spec.compile()

    def __repr__(self) -> str:
        return (f"MuJoCoSimulator(robot={self.robot.name!r}, control_period="
                f"{self.control_period}, timestep={self.timestep}, kp={self.kp}, "
                f"kv={self.kv}, gravity={self.gravity})")

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ engine
    @property
    def _d(self) -> mujoco.MjData:
        if self._data is None:
            raise IlociError("this MuJoCoSimulator was closed; build a new one "
                             "(iloci.build(config).simulator or MuJoCoSimulator()).")
        return self._data

    def _set_posture(self, q: np.ndarray) -> None:
        d = self._d
        mujoco.mj_resetData(self.model, d)
        d.qpos[self._qadr] = q
        mujoco.mj_forward(self.model, d)

    def forward(self, q: np.ndarray) -> np.ndarray:
        """Pen-tip positions by MuJoCo's kinematics (postures set, no dynamics).

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
        m, d = self.model, self._d
        out = np.empty((len(qs), 3))
        for i, qi in enumerate(qs):
            d.qpos[self._qadr] = qi
            mujoco.mj_kinematics(m, d)
            out[i] = d.xpos[self._pen]
        return out[0] if single else out

    def execute(self, joint_path: np.ndarray, dt: float) -> Execution:
        """Track a joint path with the position and velocity servos.

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
        m, d = self.model, self._d
        n = max(1, math.ceil(step / self.control_period - 1e-9))
        physics = max(1, math.ceil(step / n / self.timestep - 1e-9))
        m.opt.timestep = step / (n * physics)
        self._set_posture(q[0])
        J = len(self.joint_names)
        qadr, pen = self._qadr, self._pen
        reached_q = np.empty_like(q)
        reached_x = np.empty((len(q), 3))
        reached_q[0] = d.qpos[qadr]
        reached_x[0] = d.xpos[pen]
        fractions = np.arange(1, n + 1) / n
        for i in range(len(q) - 1):
            delta = q[i + 1] - q[i]
            d.ctrl[J:] = delta / step
            for s in fractions:
                d.ctrl[:J] = q[i] + s * delta
                mujoco.mj_step(m, d, physics)
            # mj_step leaves xpos at the state before its integration
            mujoco.mj_kinematics(m, d)
            reached_q[i + 1] = d.qpos[qadr]
            reached_x[i + 1] = d.xpos[pen]
        return Execution(joint_path=reached_q, end_effector=reached_x, dt=step)

    # ------------------------------------------------------------------ render
    def _get_renderer(self, width: int, height: int) -> mujoco.Renderer:
        r = self._renderer
        if r is not None and (r.width, r.height) == (width, height):
            return r
        self._close_renderer()
        vis = self.model.vis.global_
        # the offscreen framebuffer is sized from the model when a context is made
        vis.offwidth, vis.offheight = max(width, 1), max(height, 1)
        try:
            self._renderer = mujoco.Renderer(self.model, height=height, width=width)
        except Exception as exc:  # noqa: BLE001  (ImportError, RuntimeError, FatalError...)
            backend = os.environ.get("MUJOCO_GL", "")
            raise MissingBackendError(
                "simulator", "mujoco", ["an OpenGL context for offscreen rendering"],
                f"{RENDER_HELP}. MuJoCo's OpenGL back end here is MUJOCO_GL={backend!r}, "
                f"and it said: {type(exc).__name__}: {exc}") from None
        return self._renderer

    def _close_renderer(self) -> None:
        r, self._renderer = self._renderer, None
        if r is not None:
            # a half-made context may fail to close: nothing is left to release then
            with contextlib.suppress(Exception):
                r.close()

    def render(self, execution: Execution, width: int = 480, height: int = 360) -> np.ndarray:
        """Image of the arm in its last posture and the path its pen drew.

        The pen path (``execution.end_effector``) is drawn in blue with its
        start in green; grey lines outline the robot's drawing plane. The
        camera is :data:`VIEW`.

        Parameters
        ----------
        execution : Execution
            As returned by :meth:`execute` (a prefix of one shows the drawing
            so far).
        width, height : int
            Image size (pixels), at most :data:`MAX_IMAGE_SIZE`.

        Returns
        -------
        ndarray, shape (height, width, 3), uint8

        Raises
        ------
        MissingBackendError
            No OpenGL context can be made (see :data:`RENDER_HELP`).
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
        renderer = self._get_renderer(w, h)
        self._set_posture(q[-1])
        eye, target = np.array(VIEW["eye"]), np.array(VIEW["target"])
        look = target - eye
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = target
        cam.distance = float(np.linalg.norm(look))
        cam.azimuth = math.degrees(math.atan2(look[1], look[0]))
        cam.elevation = math.degrees(math.asin(look[2] / cam.distance))
        option = mujoco.MjvOption()
        option.geomgroup[0] = 0  # hide collision geometry, show the visual shapes
        renderer.update_scene(self._d, camera=cam, scene_option=option)
        scene = renderer.scene
        plane = self.robot.plane
        frame = plane.to_3d(np.vstack([plane.corners, plane.corners[:1]]))
        segments = [(a, b, 0.0007, _FRAME_RGBA) for a, b in itertools.pairwise(frame)]
        segments += [(a, b, 0.0016, _PEN_RGBA) for a, b in itertools.pairwise(pen)]
        if len(pen) == 1:
            segments.append((pen[0], pen[0] + 1e-9, 0.0016, _PEN_RGBA))
        if scene.ngeom + len(segments) + 1 > scene.maxgeom:
            raise InvalidInputError(f"the path has {len(pen)} points, too many to draw "
                                    f"(at most {scene.maxgeom - scene.ngeom - 2}).")
        eye3 = np.eye(3).ravel()
        for a, b, radius, rgba in segments:
            g = scene.geoms[scene.ngeom]
            mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_CAPSULE, np.zeros(3), np.zeros(3),
                                eye3, rgba)
            mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_CAPSULE, radius, a, b)
            scene.ngeom += 1
        g = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_SPHERE, np.full(3, 0.003), pen[0], eye3,
                            _START_RGBA)
        scene.ngeom += 1
        return np.ascontiguousarray(renderer.render(), dtype=np.uint8)

    def close(self) -> None:
        """Release the renderer and the simulation data (idempotent)."""
        if getattr(self, "_renderer", None) is not None:
            self._close_renderer()
        self._data = None

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
(``timestep``, 0.2 ms) against gravity (the loop is
:func:`iloci.sensorimotor.simulation.track`). It returns the joint angles
and the pen tip (the ``r_pen_tip`` body) reached at each time of the path.

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
from iloci.sensorimotor import simulation
from iloci.sensorimotor.robots import Robot, get_robot
from iloci.sensorimotor.robots.urdf import read_urdf, resolved_urdf_text
from iloci_mujoco import choose_opengl
from iloci_mujoco.params import MuJoCoParams

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

__all__ = ["RENDER_HELP", "MuJoCoSimulator"]

#: What offscreen rendering needs, quoted by the error when it fails.
RENDER_HELP = ("on a headless Linux machine: apt-get install libegl1 and set MUJOCO_GL=egl, "
               "or apt-get install libosmesa6 and set MUJOCO_GL=osmesa, before mujoco is "
               "first imported")


class MuJoCoSimulator:
    """The ``mujoco`` Simulator: a Nao arm tracking joint paths in MuJoCo.

    Parameters
    ----------
    robot : str or Robot
        The robot (a name of :mod:`iloci.sensorimotor.robots`, or one of its
        :class:`~iloci.sensorimotor.robots.Robot` objects).
    control_period, timestep, kp, kv, gravity : float
        Set-point period and physics step (s), the servos' gains and gravity
        (m/s^2); see :class:`~iloci_mujoco.params.MuJoCoParams`.

    Attributes
    ----------
    model : mujoco.MjModel
        The compiled robot with its servos.
    robot : Robot
        Also giving the simulator its attributes ``joint_names`` (J names,
        column order) and ``lower``, ``upper`` (J,), the joint limits (rad).

    Notes
    -----
    The model is compiled once per instance; :meth:`execute` resets the
    simulation state, so repeated calls are independent and deterministic.
    """

    def __init__(self, robot: str | Robot = "nao-v32-right-arm",
                 control_period: float = 0.001, timestep: float = 0.0002,
                 kp: float = 1000.0, kv: float = 2.0, gravity: float = 9.81,
                 gravity_compensation: bool = False) -> None:
        if _IMPORT_ERROR is not None:
            raise _IMPORT_ERROR
        simulation.check_settings(MuJoCoParams(
            control_period=control_period, timestep=timestep, kp=kp, kv=kv, gravity=gravity))
        self.robot = robot if isinstance(robot, Robot) else get_robot(robot)
        self.control_period = float(control_period)
        self.timestep = float(timestep)
        self.kp = float(kp)
        self.kv = float(kv)
        self.gravity = float(gravity)
        self.gravity_compensation = bool(gravity_compensation)
        self.joint_names = tuple(self.robot.joint_names)
        self.lower = np.array(self.robot.lower, dtype=np.float64)
        self.upper = np.array(self.robot.upper, dtype=np.float64)
        self.model = self._compile()
        self._data: mujoco.MjData | None = mujoco.MjData(self.model)
        m = self.model
        self._qadr = np.array([m.jnt_qposadr[m.joint(n).id] for n in self.joint_names])
        self._pen = m.body(self.robot.end_effector_frame).id
        self._held = [(int(m.jnt_qposadr[m.joint(n).id]), float(v))
                      for n, v in self.robot.fixed_joints.items()
                      if n not in self.joint_names and mujoco.mj_name2id(
                          m, mujoco.mjtObj.mjOBJ_JOINT, n) >= 0]
        self._renderer: mujoco.Renderer | None = None

    def _compile(self) -> mujoco.MjModel:
        # MuJoCo reads the URDF with its mesh names made absolute (package://,
        # relative paths), visual COLLADA meshes swapped for their STL beside
        # them or in the sibling collision directory (MuJoCo reads no .dae),
        # and every link kept as a body (fusestatic off) so frames stay named
        import xml.etree.ElementTree as ET
        massless = read_urdf(self.robot.urdf_path).massless_message()
        if massless:  # before MuJoCo's own "mass and inertia of moving bodies" error
            raise InvalidInputError(massless)
        try:
            text = resolved_urdf_text(self.robot.urdf_path, self.robot.package_dirs,
                                      replace_suffix={".dae": ".stl"})
            root = ET.fromstring(text)
            ext = root.find("mujoco")
            if ext is None:
                ext = ET.SubElement(root, "mujoco")
            comp = ext.find("compiler")
            if comp is None:
                comp = ET.SubElement(ext, "compiler")
            comp.set("fusestatic", "false")
            comp.set("strippath", "false")
            # keep the visual shapes: render shows them, not the collision ones
            comp.set("discardvisual", comp.get("discardvisual", "false"))
            comp.set("balanceinertia", comp.get("balanceinertia", "true"))
            spec = mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"))
        except InvalidInputError:
            raise
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
                f"{self.robot.name!r} names.")
        # other movable joints are held where the robot fixes them (the IK assumes it)
        for name, joint in joints.items():
            if name not in self.joint_names:
                eq = spec.add_equality()
                eq.type = mujoco.mjtEq.mjEQ_JOINT
                eq.name1 = name
                eq.data[0] = float(self.robot.fixed_joints.get(name, 0.0))
                joint.ref = 0.0
        if self.gravity_compensation:
            for b in spec.bodies:
                b.gravcomp = 1.0
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
        spec.visual.global_.fovy = simulation.VIEW["fov"]
        try:
            return spec.compile()
        except ValueError as exc:  # MuJoCo's compiler (a mesh it cannot read, ...)
            raise InvalidInputError(f"MuJoCo cannot compile the URDF of {self.robot.name!r} "
                                    f"({self.robot.urdf_path}): {exc}") from None

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
        for adr, value in self._held:
            d.qpos[adr] = value
        mujoco.mj_forward(self.model, d)

    def forward(self, q: np.ndarray) -> np.ndarray:
        """Where MuJoCo's kinematics puts the pen tip for each posture.

        ``q`` is (T, J) or (J,) in rad; the result (T, 3) or (3,) in m,
        torso frame. ``mj_kinematics`` only: no dynamics.
        """
        qs, single = simulation.check_postures(q, self.robot)
        m, d = self.model, self._d
        out = np.empty((len(qs), 3))
        for i, qi in enumerate(qs):
            d.qpos[self._qadr] = qi
            mujoco.mj_kinematics(m, d)
            out[i] = simulation.to_base(self.robot, d.xpos[self._pen])
        return out[0] if single else out

    def execute(self, joint_path: np.ndarray, dt: float) -> Execution:
        """Track a joint path (T, J) with MuJoCo's position and velocity servos.

        Set-points are updated every ``control_period``, each held for
        several physics steps of at most ``timestep``. What the arm reached
        comes back as an :class:`~iloci.interfaces.Execution` (``joint_path``
        (T, J), ``end_effector`` (T, 3)), as
        :meth:`iloci.interfaces.Simulator.execute` specifies, errors included.
        """
        q, step = simulation.check_joint_path(joint_path, dt, self.robot)
        m, d = self.model, self._d
        n = simulation.updates_per_step(step, self.control_period)
        physics = simulation.updates_per_step(step / n, self.timestep)
        m.opt.timestep = step / (n * physics)
        self._set_posture(q[0])
        J = len(self.joint_names)
        qadr, pen = self._qadr, self._pen

        def hold(target: np.ndarray, velocity: np.ndarray) -> None:
            d.ctrl[:J] = target
            d.ctrl[J:] = velocity
            mujoco.mj_step(m, d, physics)

        def read() -> tuple[np.ndarray, np.ndarray]:
            # mj_step leaves xpos at the state before its integration
            mujoco.mj_kinematics(m, d)
            return d.qpos[qadr], simulation.to_base(self.robot, d.xpos[pen])

        return simulation.track(q, step, self.control_period, hold, read)

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
        """Offscreen OpenGL picture of an :class:`~iloci.interfaces.Execution`.

        As :meth:`iloci.interfaces.Simulator.render` specifies: an RGB image,
        shape (height, width, 3), uint8, of the arm in its last posture with
        the pen path as blue capsules (its start a green sphere) and the
        drawing plane outlined in grey, seen from
        :data:`iloci.sensorimotor.simulation.VIEW`. Raises
        :class:`~iloci.errors.MissingBackendError` when no OpenGL context can
        be made (see :data:`RENDER_HELP`).
        """
        w, h = simulation.check_image_size(width, height)
        q, pen = simulation.check_execution(execution, self.robot)
        pen = simulation.to_world(self.robot, pen)
        renderer = self._get_renderer(w, h)
        self._set_posture(q[-1])
        camera = simulation.camera_for(self.robot)
        eye, target = np.array(camera["eye"]), np.array(camera["target"])
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
        frame = simulation.to_world(self.robot, simulation.plane_outline(self.robot.plane))
        # pen and outline thickness grow with the plane (drawn for the Nao's 10 cm)
        scale = max(1.0, max(self.robot.plane.width, self.robot.plane.height) / 0.1)
        line = (scale * simulation.FRAME_RADIUS, simulation.FRAME_RGBA)
        ink = (scale * simulation.PEN_RADIUS, simulation.PEN_RGBA)
        segments = [(a, b, *line) for a, b in itertools.pairwise(frame)]
        segments += [(a, b, *ink) for a, b in itertools.pairwise(pen)]
        if len(pen) == 1:
            segments.append((pen[0], pen[0] + 1e-9, *ink))
        if scene.ngeom + len(segments) + 1 > scene.maxgeom:
            raise InvalidInputError(f"the path has {len(pen)} points, too many to draw "
                                    f"(at most {scene.maxgeom - scene.ngeom - 2}).")
        eye3 = np.eye(3).ravel()
        for a, b, radius, rgba in segments:
            g = scene.geoms[scene.ngeom]
            mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_CAPSULE, np.zeros(3), np.zeros(3),
                                eye3, np.asarray(rgba, dtype=np.float32))
            mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_CAPSULE, radius, a, b)
            scene.ngeom += 1
        g = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_SPHERE,
                            np.full(3, scale * simulation.START_RADIUS), pen[0], eye3,
                            np.asarray(simulation.START_RGBA, dtype=np.float32))
        scene.ngeom += 1
        return np.ascontiguousarray(renderer.render(), dtype=np.uint8)

    def close(self) -> None:
        """Release the renderer and the simulation data (idempotent)."""
        if getattr(self, "_renderer", None) is not None:
            self._close_renderer()
        self._data = None

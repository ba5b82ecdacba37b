"""A config's robot made ready to draw: read (:func:`robot_from_config`), checked
(:func:`check_robot`), its plane placed with an IK solver (:func:`place_robot`, the
automatic planes cached on disk), and the one assembly every caller uses,
robot -> IK -> place the plane -> IK again (:func:`robot_and_ik`).
"""

from __future__ import annotations

from collections.abc import Callable
import contextlib
import hashlib
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from iloci._version import __version__
from iloci.data.files import write_atomic
from iloci.errors import InvalidInputError
from iloci.sensorimotor.robots.model import DrawingPlane, Robot, _vec3, describe_robot
from iloci.sensorimotor.robots.plane import find_drawing_plane
from iloci.sensorimotor.robots.presets import get_robot
from iloci.sensorimotor.robots.urdf import read_urdf, resolved_urdf_text

__all__ = ["check_robot", "place_robot", "plane_cache_dir", "robot_and_ik",
           "robot_from_config"]


def robot_from_config(cfg: Any, plugin_manager: Any = None) -> tuple[Robot, str]:
    """The robot a ``[robot]`` section describes, and what is left to do for it.

    Parameters
    ----------
    cfg : iloci.config.RobotConfig

    Returns
    -------
    (Robot, str)
        The robot and ``"ready"``, ``"auto"`` (its plane must be placed by
        :func:`iloci.sensorimotor.robots.plane.find_drawing_plane`) or
        ``"home"`` (its plane is given; the start posture reaching the
        plane's centre must be solved). :func:`iloci.build` does both with
        the configured IK solver.
    """
    if not cfg.urdf:
        robot = get_robot(cfg.name, plugin_manager)
        mode = "auto" if robot.plane_report.get("method") == "placeholder" else "ready"
        overrides = [k for k in ("base_frame", "tip_frame", "joints", "rest")
                     if getattr(cfg, k)]
        if overrides:
            robot = describe_robot(
                robot.urdf_path, base_frame=cfg.base_frame or robot.base_frame,
                tip_frame=cfg.tip_frame or robot.end_effector_frame,
                joints=cfg.joints or robot.joint_names,
                rest=cfg.rest or (None if robot.rest is None else robot.rest.tolist()),
                name=robot.name, package_dirs=robot.package_dirs)
            mode = "auto"
    else:
        robot = describe_robot(cfg.urdf, base_frame=cfg.base_frame or None,
                               tip_frame=cfg.tip_frame, joints=cfg.joints,
                               rest=cfg.rest or None,
                               name=None if cfg.name == "nao-v32-right-arm" else cfg.name,
                               package_dirs=cfg.package_dirs)
        mode = "auto"
    if cfg.plane != "auto":
        c = [float(v) for v in cfg.plane]
        plane = DrawingPlane(c[0], c[1], c[2], c[3], c[4], normal=tuple(cfg.plane_normal),
                             up=tuple(cfg.plane_up))
        robot = robot.with_plane(plane, robot.q_home, {"method": "given"})
        mode = "home"
    return robot, mode


def check_robot(cfg: Any, simulator: str = "none", plugin_manager: Any = None) -> Robot:
    """Check a ``[robot]`` section without placing its plane: what ``iloci config check``
    and ``iloci robots`` report before anything runs.

    Reads the URDF (unexpanded xacro, limits, ``<mimic>`` couplings on the pen
    tip's chain, frames and joints; see :func:`describe_robot`) and, for the
    ``"mujoco"`` simulator, that every moving link has a mass; with a simulator, that
    every mesh file is found (relative to the URDF, ``package://``).

    Parameters
    ----------
    cfg : iloci.config.RobotConfig
    simulator : str
        The configured simulator's name.

    Returns
    -------
    Robot
        Its plane not yet placed.

    Raises
    ------
    InvalidInputError
        Naming the joint or link at fault and what to do.
    UnknownComponentError, MissingBackendError
        An unknown preset, or one whose files are not installed.
    """
    robot, _ = robot_from_config(cfg, plugin_manager)
    if simulator == "mujoco":
        massless = read_urdf(robot.urdf_path).massless_message()
        if massless:
            raise InvalidInputError(massless)
    if simulator != "none":  # the simulators load the meshes: every mesh file must be found
        resolved_urdf_text(robot.urdf_path, robot.package_dirs)
    return robot


def place_robot(robot: Robot, mode: str, ik: Any, cfg: Any) -> Robot:
    """Finish what :func:`robot_from_config` left to do, with an IK solver for ``robot``.

    ``"auto"``: find the plane (cached per process for the same robot and
    settings); ``"home"``: solve the start posture at the given plane's
    centre from the rest posture; ``"ready"``: nothing.
    """
    if mode == "ready":
        return robot
    start = np.asarray(robot.rest if robot.rest is not None else robot.q_home)
    if mode == "home":
        q = np.asarray(ik.solve(robot.plane.to_3d(robot.plane.center[None]), start))[0]
        return robot.with_plane(robot.plane, q, robot.plane_report)
    settings = {k: getattr(cfg, k) for k in (
        "plane_normal", "plane_up", "plane_aspect", "plane_joint_margin", "plane_min_singular",
        "plane_max_height", "plane_min_up", "plane_seed")}
    key = _plane_key(robot, settings, ik)
    found = _PLANES.get(key) or _read_cached_plane(key)
    if found is None:
        found = find_drawing_plane(
            robot, ik, normal=tuple(cfg.plane_normal), up=tuple(cfg.plane_up),
            aspect=cfg.plane_aspect, joint_margin=math.radians(cfg.plane_joint_margin),
            min_singular=cfg.plane_min_singular, max_height=cfg.plane_max_height,
            min_up=cfg.plane_min_up, seed=cfg.plane_seed)
        _write_cached_plane(key, found)
    _PLANES[key] = found
    plane, q_home, report = found
    return robot.with_plane(plane, q_home, report)


def robot_and_ik(cfg: Any, make_ik: Callable[[Robot], Any], *, plugin_manager: Any = None,
                 ik: Any = None, before_placing: Callable[[Robot], None] | None = None
                 ) -> tuple[Robot, Any]:
    """The robot a ``[robot]`` section describes, its plane placed, and its IK solver.

    Robot -> IK -> place the plane -> IK again, written once: :func:`iloci.build`
    (hence :meth:`iloci.Agent.load`), :func:`iloci.drawing.load_drawing_parts`,
    ``iloci show`` and ``iloci robots`` assemble their robot here.

    Parameters
    ----------
    cfg : iloci.config.RobotConfig
    make_ik : callable
        ``make_ik(robot)`` -> the IK solver for ``robot`` (its start posture
        is the robot's).
    plugin_manager : pluggy.PluginManager, optional
        Where robot presets are looked up.
    ik : IKSolver, optional
        A solver given by the caller: it places the plane and is returned
        as it is (not made again for the placed robot).
    before_placing : callable, optional
        Called with the robot read, before the (possibly long) plane
        search: a check that can fail fast.

    Returns
    -------
    (Robot, IKSolver)
        The robot, plane placed (:func:`place_robot`), and the solver made
        for it.
    """
    robot, mode = robot_from_config(cfg, plugin_manager)
    if before_placing is not None:
        before_placing(robot)
    given = ik is not None
    if ik is None:
        ik = make_ik(robot)
    placed = place_robot(robot, mode, ik, cfg)
    if placed is not robot and not given:
        ik = make_ik(placed)  # its start posture at the placed plane
    return placed, ik


def _plane_key(robot: Robot, settings: dict[str, Any], ik: Any) -> str:
    """Digest of everything the automatic plane depends on."""
    h = hashlib.sha256()
    h.update(robot.urdf_path.read_bytes())
    h.update(json.dumps({
        "iloci": __version__, "base": robot.base_frame, "tip": robot.end_effector_frame,
        "joints": robot.joint_names, "fixed": robot.fixed_joints,
        "rest": None if robot.rest is None else robot.rest.tolist(),
        "q_home": robot.q_home.tolist(), "ik": repr(ik),
        "settings": {k: list(v) if isinstance(v, tuple) else v for k, v in settings.items()},
    }, sort_keys=True).encode())
    return h.hexdigest()[:32]


def plane_cache_dir() -> Path:
    """Where automatic planes are cached: ``$ILOCI_CACHE_DIR`` or ``~/.cache/iloci``, ``/planes``.

    The search takes tens of seconds; every process building the same
    robot with the same settings (e.g. the folds of an evaluation) reads
    the plane found first. Delete the directory to search again.
    """
    root = os.environ.get("ILOCI_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "iloci")
    return Path(root) / "planes"


def _read_cached_plane(key: str) -> tuple[DrawingPlane, np.ndarray, dict[str, Any]] | None:
    f = plane_cache_dir() / f"{key}.json"
    try:
        d = json.loads(f.read_text(encoding="utf-8"))
        p = d["plane"]
        x, y, z = _vec3(p["center"])
        plane = DrawingPlane(x, y, z, float(p["width"]), float(p["height"]),
                             normal=_vec3(p["normal"]), up=_vec3(p["up"]))
        return plane, np.array(d["q_home"], dtype=np.float64), d["report"]
    except (OSError, ValueError, KeyError, TypeError, InvalidInputError):
        return None


def _write_cached_plane(key: str, found: tuple[DrawingPlane, np.ndarray, dict[str, Any]]
                        ) -> None:
    plane, q_home, report = found
    data = {"plane": {"center": plane.origin.tolist(), "width": plane.width,
                      "height": plane.height, "normal": list(plane.normal),
                      "up": list(plane.up)},
            "q_home": np.asarray(q_home).tolist(), "report": report}
    with contextlib.suppress(OSError):  # a read-only home only costs the next search
        write_atomic(plane_cache_dir() / f"{key}.json",
                     lambda fh: fh.write(json.dumps(data, indent=1).encode()), mkdir=True)


#: Planes found in this process, by robot and search settings.
_PLANES: dict[str, tuple[DrawingPlane, np.ndarray, dict[str, Any]]] = {}

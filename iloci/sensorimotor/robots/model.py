"""The robot description: :class:`Robot` (an arm's URDF, frames, joints, limits) and its
:class:`DrawingPlane`; :func:`describe_robot` reads any arm from its URDF.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
import os
from pathlib import Path
from typing import Any
import warnings

import numpy as np

from iloci.linalg import matmul
from iloci.errors import InvalidInputError, did_you_mean
from iloci.sensorimotor.robots.urdf import (MOVABLE, chain_fingerprint, limits_message,
                                            read_urdf, resolve_uri, urdf_unicode)
from iloci.validation import check_array

__all__ = ["DrawingPlane", "Robot", "describe_robot"]


def _unit(v: Sequence[float], what: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    n = float(np.sqrt(matmul(a, a))) if a.shape == (3,) and np.all(np.isfinite(a)) else 0.0
    if n == 0.0:
        raise InvalidInputError(f"{what} must be a non-zero 3-vector, got {v!r}.")
    return a / n


@dataclass(frozen=True)
class DrawingPlane:
    """A rectangle the robot draws in, in the robot's base frame.

    ``(x, y, z)`` is its centre (m, base frame). Its orientation is given by
    ``normal`` (pointing away from the robot, the way the arm faces) and
    ``up`` (the rectangle's height direction); its width runs along
    ``u = up x normal``. The default, ``normal = (1, 0, 0)`` and
    ``up = (0, 0, 1)``, is a vertical y-z rectangle facing the robot's
    forward axis: ``u = +y``, the Nao's plane.

    A 2-D plane point ``(a, b)`` is the position's coordinates along ``u``
    and ``up`` (m, not relative to the centre): for the default orientation
    exactly the base frame's ``(y, z)``.

    Attributes
    ----------
    x, y, z : float
        Centre (m, base frame).
    width, height : float
        Extent along ``u`` and along ``up`` (m).
    normal, up : tuple of 3 floats
        Unit vectors (base frame), orthogonal.
    """

    x: float
    y: float
    z: float
    width: float
    height: float
    normal: tuple[float, float, float] = (1.0, 0.0, 0.0)
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)

    def __post_init__(self) -> None:
        vals = (self.x, self.y, self.z, self.width, self.height)
        if not all(np.isfinite(v) for v in vals) or self.width <= 0 or self.height <= 0:
            raise InvalidInputError(
                f"drawing plane needs finite x, y, z and positive width and height, "
                f"got {vals}.")
        n, up = _unit(self.normal, "plane normal"), _unit(self.up, "plane up")
        if abs(float(matmul(n, up))) > 1e-6:
            raise InvalidInputError(f"plane normal {self.normal} and up {self.up} must be "
                                    "orthogonal.")
        object.__setattr__(self, "normal", tuple(float(v) for v in n))
        object.__setattr__(self, "up", tuple(float(v) for v in up))

    @property
    def axes(self) -> np.ndarray:
        """Rows ``u`` (width), ``up`` (height), ``normal``: shape (3, 3), base frame."""
        n, v = np.array(self.normal), np.array(self.up)
        return np.array([np.cross(v, n), v, n])

    @property
    def origin(self) -> np.ndarray:
        """Centre ``(x, y, z)``, shape (3,) (m, base frame)."""
        return np.array([self.x, self.y, self.z])

    @property
    def distance(self) -> float:
        """Signed distance of the plane from the base origin along ``normal`` (m)."""
        return float(matmul(self.origin, np.array(self.normal)))

    @property
    def center(self) -> np.ndarray:
        """Centre as a 2-D plane point, shape (2,)."""
        return matmul(self.axes[:2], self.origin)

    @property
    def size(self) -> np.ndarray:
        """``(width, height)``, shape (2,)."""
        return np.array([self.width, self.height])

    @property
    def corners(self) -> np.ndarray:
        """The rectangle's corners as plane points, shape (4, 2), counter-clockwise."""
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
        """Plane points ``(a, b)`` -> base-frame points ``(x, y, z)``.

        Parameters
        ----------
        points2d : ndarray, shape (T, 2)

        Returns
        -------
        ndarray, shape (T, 3)
        """
        p = _as_points(points2d, 2, "plane points")
        u, v, n = self.axes
        return self.distance * n + p[:, :1] * u + p[:, 1:2] * v

    def to_2d(self, points3d: np.ndarray) -> np.ndarray:
        """Base-frame points ``(x, y, z)`` -> their plane points ``(a, b)``.

        The component along ``normal`` is dropped (orthogonal projection).

        Parameters
        ----------
        points3d : ndarray, shape (T, 3)

        Returns
        -------
        ndarray, shape (T, 2)
        """
        p = _as_points(points3d, 3, "3-D points")
        return matmul(p, self.axes[:2].T)

    def grown(self, margin: float) -> DrawingPlane:
        """The same plane with ``margin`` (m) added on every side."""
        return replace(self, width=self.width + 2 * margin, height=self.height + 2 * margin)


def _as_points(a: np.ndarray, width: int, what: str) -> np.ndarray:
    return check_array(a, what, (None, width), finite_hint=" Pass finite coordinates.")


def _vec3(v: Sequence[float] | np.ndarray) -> tuple[float, float, float]:
    """Three floats (a direction or point; its length is checked by DrawingPlane)."""
    a = [float(x) for x in v]
    if len(a) != 3:
        raise InvalidInputError(f"expected 3 numbers (x, y, z), got {a}.")
    return a[0], a[1], a[2]


def _frozen(a: Any) -> np.ndarray:
    out = np.array(a, dtype=np.float64)
    out.flags.writeable = False
    return out


@dataclass(frozen=True, eq=False)
class Robot:
    """A drawing arm: everything iloci and its back ends need to know of it.

    Build one with :func:`describe_robot` (any URDF) or :func:`get_robot`
    (a preset); in a config, with a ``[robot]`` section.

    Attributes
    ----------
    name : str
        Its name, e.g. ``"nao-v32-right-arm"``, ``"panda"``; recorded in
        memory files.
    urdf_path : pathlib.Path
        The URDF file.
    joint_names : tuple of str
        The ``J`` joints used, in column order of every joint path.
    lower, upper : ndarray, shape (J,)
        Joint limits (rad, m for a prismatic joint), as in the URDF.
    end_effector_frame : str
        The URDF link whose origin draws (the pen tip).
    q_home : ndarray, shape (J,)
        Start posture: IK paths are warm-started from it; its pen tip is at
        (or near) the plane's centre.
    plane : DrawingPlane
        Where the robot draws (base frame).
    base_frame : str
        The URDF link whose frame targets are expressed in; it must not
        move with the joints used (the root link or fixed to it).
    fixed_joints : dict of str to float
        The other movable joints of the URDF and the value each is held at.
    rest : ndarray, shape (J,), or None
        Rest posture: a redundant arm's IK pulls the joints towards it in
        the null space of the pen-tip task. None: no such pull.
    package_dirs : tuple of Path
        Directories holding the packages ``package://`` mesh names refer to.
    base_pose : ndarray, shape (4, 4)
        The base frame in the URDF's root frame (identity when the base is
        the root); simulators load the URDF with its root at the world origin.
    plane_report : dict
        How the plane was found (``"given"`` or the automatic search's
        margins, see :func:`iloci.sensorimotor.robots.plane.find_drawing_plane`).
    kinematics : str or None
        :func:`~iloci.sensorimotor.robots.urdf.chain_fingerprint` of the joints
        from ``base_frame`` to the pen tip as the URDF held them when the robot
        was described (a memory records it); None: read from the file when asked.
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
    rest: np.ndarray | None = None
    package_dirs: tuple[Path, ...] = ()
    base_pose: np.ndarray = field(default_factory=lambda: _frozen(np.eye(4)))
    plane_report: dict[str, Any] = field(default_factory=lambda: {"method": "given"})
    kinematics: str | None = None

    @property
    def dof(self) -> int:
        """``J``, the number of joints used."""
        return len(self.joint_names)

    @property
    def urdf_text(self) -> str:
        """The URDF as a string (decoded as its file declares; see
        :func:`~iloci.sensorimotor.robots.urdf.urdf_unicode`)."""
        return urdf_unicode(self.urdf_path)

    @property
    def tip_frame(self) -> str:
        """Alias of :attr:`end_effector_frame`."""
        return self.end_effector_frame

    def resolve(self, uri: str) -> Path:
        """The file a mesh name of this robot's URDF refers to (see :mod:`.urdf`)."""
        return resolve_uri(uri, self.urdf_path.parent, self.package_dirs)

    def describe(self) -> dict[str, Any]:
        """A JSON-able summary: name, URDF, frames, joints, limits, postures, plane."""
        p = self.plane
        return {
            "name": self.name, "urdf": str(self.urdf_path), "base_frame": self.base_frame,
            "tip_frame": self.end_effector_frame, "joints": list(self.joint_names),
            "lower": self.lower.tolist(), "upper": self.upper.tolist(),
            "q_home": self.q_home.tolist(),
            "rest": None if self.rest is None else self.rest.tolist(),
            "fixed_joints": dict(self.fixed_joints),
            "plane": {"center": p.origin.tolist(), "width": p.width, "height": p.height,
                      "normal": list(p.normal), "up": list(p.up)},
            "plane_report": dict(self.plane_report),
        }

    def with_plane(self, plane: DrawingPlane, q_home: np.ndarray,
                   report: dict[str, Any] | None = None) -> Robot:
        """The same robot drawing in another plane, starting from ``q_home``."""
        return replace(self, plane=plane, q_home=_frozen(q_home),
                       plane_report=dict(report or {"method": "given"}))


#: Longest arm (m, base to pen tip along the joints) read without a warning: industrial
#: arms reach about 3 m; a URDF in millimetres is 1000 times its size.
LONGEST_ARM_M = 20.0


def describe_robot(urdf: str | os.PathLike[str], *, base_frame: str | None = None,
                   tip_frame: str, joints: Sequence[str] = (),
                   rest: Sequence[float] | None = None,
                   plane: DrawingPlane | None = None, name: str | None = None,
                   package_dirs: Sequence[str | os.PathLike[str]] = (),
                   fixed_joints: dict[str, float] | None = None) -> Robot:
    """Describe an arm from its URDF.

    Parameters
    ----------
    urdf : path-like or str
        The URDF file, or ``"package://PACKAGE/path.urdf"`` for a file inside
        an installed Python package or a package in ``package_dirs`` /
        ``ROS_PACKAGE_PATH``.
    base_frame : str, optional
        Link whose frame targets and the plane are expressed in (default:
        the URDF's root link). It must not move with ``joints``.
    tip_frame : str
        Link whose origin is the pen tip.
    joints : sequence of str
        Joints used, in column order (default: every movable joint from
        ``base_frame`` to ``tip_frame``). Each must lie on that chain.
    rest : sequence of J floats, optional
        Rest posture (rad); it is also the start posture until a plane is
        placed. Default: the middle of each joint's range.
    plane : DrawingPlane, optional
        Where to draw. Without one the robot's plane is a placeholder (a
        1 cm square 0.3 m ahead) until
        :func:`iloci.sensorimotor.robots.plane.find_drawing_plane` places it
        (a config's ``plane = "auto"``).
    name : str, optional
        Default: the URDF's ``<robot name>``.
    package_dirs : sequence of path-like
        Where ``package://`` names are looked up first.
    fixed_joints : dict, optional
        Values (rad) of movable joints outside ``joints`` (default: 0, or
        the nearest limit when 0 is outside it).

    Returns
    -------
    Robot

    Raises
    ------
    InvalidInputError
        URDF not found or malformed; a frame or joint not found (with "did
        you mean"); a joint off the base-to-tip chain, fixed, or unbounded;
        ``rest`` of the wrong length or outside the limits; a moving base.
    """
    dirs = tuple(Path(d) for d in package_dirs)
    path = _urdf_path(str(urdf), dirs)
    tree = read_urdf(path)
    base = base_frame or tree.root
    tree.check_link(base, "base frame")
    tree.check_link(tip_frame, "pen-tip frame")
    on_chain = tree.movable_between(base, tip_frame)
    if joints:
        names = tuple(joints)
        for j in names:
            if j not in tree.joints:
                raise InvalidInputError(
                    f"joint {j!r} is not in {path}; movable joints from {base!r} to "
                    f"{tip_frame!r}: {', '.join(on_chain) or '(none)'}."
                    f"{did_you_mean(j, tree.joints)}")
            if j not in on_chain:
                raise InvalidInputError(
                    f"joint {j!r} does not move the pen tip {tip_frame!r} relative to the "
                    f"base {base!r} (it is fixed or off the chain); use joints among "
                    f"{', '.join(on_chain) or '(none)'}.")
        if len(set(names)) != len(names):
            raise InvalidInputError(f"joints {list(names)} name a joint twice.")
    else:
        names = tuple(on_chain)
    if not names:
        below = [j.child for j in tree.joints.values()
                 if j.type in MOVABLE and base in _ancestors(tree, j.parent)]
        where = ", ".join(map(repr, below[-3:])) or f"none hangs below {base!r}"
        raise InvalidInputError(
            f"no movable joint between the base frame {base!r} and the pen-tip frame "
            f"{tip_frame!r} in {path}: the pen could not move. Choose a tip_frame below a "
            f"movable joint ({where}) or a "
            "base_frame higher up the tree.")
    multi = [j for j in tree.chain(base, tip_frame) if j.type in ("planar", "floating")]
    if multi:
        raise InvalidInputError(
            f"{path}: joint(s) {', '.join(f'{j.name!r} ({j.type})' for j in multi)} lie on "
            f"the way from the base frame {base!r} to the pen tip {tip_frame!r}; iloci moves "
            "one-coordinate joints (revolute, prismatic) and cannot hold a planar or "
            "floating joint still, so the pen's place would be unknown. Make each a fixed "
            "joint if it does not move while drawing, or choose a base_frame below it.")
    # the base must not move with the joints used: it lies above all of them
    above_base = {j.name for j in tree.chain(tree.root, base)}
    moving = [n for n in names if n in above_base]
    if moving:
        raise InvalidInputError(f"base frame {base!r} moves with joint(s) {moving}; choose "
                                "a base frame above every joint used.")
    _check_mimic(tree, base, tip_frame, names, path)
    reach = float(sum(np.linalg.norm(j.origin[:3, 3]) for j in tree.chain(base, tip_frame)))
    if reach > LONGEST_ARM_M:
        warnings.warn(f"{path}: the arm from {base!r} to {tip_frame!r} is {reach:.4g} m "
                      "long (the sum of its joints' offsets); URDF lengths are in metres: "
                      f"was it written in millimetres or centimetres? A robot arm is under "
                      f"{LONGEST_ARM_M:g} m; iloci goes on with the file as it is.",
                      stacklevel=2)
    faults = limits_message([tree.joints[n] for n in names])
    if faults:
        raise InvalidInputError(f"{path}: {faults}.")
    lo = np.array([tree.joints[n].lower for n in names])
    hi = np.array([tree.joints[n].upper for n in names])
    if rest is None:
        q_rest = (lo + hi) / 2
        rest_given = None
    else:
        q_rest = np.asarray(rest, dtype=np.float64)
        if q_rest.shape != (len(names),) or not np.all(np.isfinite(q_rest)):
            raise InvalidInputError(f"rest posture must be {len(names)} finite angles "
                                    f"(joints {', '.join(names)}), got {list(rest)}.")
        if np.any(q_rest < lo) or np.any(q_rest > hi):
            raise InvalidInputError(f"rest posture {q_rest.round(4).tolist()} lies outside "
                                    f"the limits [{lo.round(4).tolist()}, "
                                    f"{hi.round(4).tolist()}].")
        rest_given = q_rest
    fixed = dict(fixed_joints or {})
    for uj in tree.joints.values():
        if uj.type in MOVABLE and uj.name not in names and uj.name not in fixed:
            fixed[uj.name] = float(np.clip(0.0, uj.lower, uj.upper))
    placeholder = plane is None
    if plane is None:
        plane = DrawingPlane(0.3, 0.0, 0.0, 0.01, 0.01)
    return Robot(
        name=name or tree.name, urdf_path=path, joint_names=names, lower=_frozen(lo),
        upper=_frozen(hi), end_effector_frame=tip_frame, q_home=_frozen(q_rest),
        plane=plane, base_frame=base, fixed_joints=fixed,
        rest=None if rest_given is None else _frozen(rest_given), package_dirs=dirs,
        base_pose=_frozen(tree.pose_of(base)),
        plane_report={"method": "placeholder" if placeholder else "given"},
        kinematics=chain_fingerprint(tree.chain(base, tip_frame)))


def _ancestors(tree: Any, link: str) -> set[str]:
    """Every link above ``link`` in the tree (``link`` itself included)."""
    out = {link}
    j = tree.parent_joint(link)
    while j is not None and j.parent not in out:
        out.add(j.parent)
        j = tree.parent_joint(j.parent)
    return out


def _check_mimic(tree: Any, base: str, tip: str, names: Sequence[str], path: Path) -> None:
    """Refuse a ``<mimic>`` joint that moves the pen tip with a joint iloci uses.

    iloci solves every joint it uses as free, so the joint path would break the
    coupling and the real arm would draw another shape. A mimic joint off the
    base-to-tip chain (a gripper finger), or one whose leader is held fixed too,
    is harmless.
    """
    for j in tree.chain(base, tip):
        if j.mimic is None:
            continue
        leader, mult, off = j.mimic
        if j.name in names or leader in names:
            raise InvalidInputError(
                f"{path}: joint {j.name!r} mimics joint {leader!r} (<mimic multiplier="
                f'"{mult:g}" offset="{off:g}">: its angle is {mult:g} * {leader} + {off:g}, '
                "not free), and iloci cannot plan a joint path that keeps such a coupling: "
                "it would solve the joint as free and the real arm would draw another shape. "
                f"Describe the arm without the coupling on the way to the pen tip: make "
                f"{j.name!r} a fixed joint (or a free one, if the real arm's joint is free), "
                "or choose a tip_frame above it.")


def _urdf_path(urdf: str, dirs: tuple[Path, ...]) -> Path:
    if urdf.startswith("package://"):
        try:
            return resolve_uri(urdf, Path.cwd(), dirs)
        except InvalidInputError as exc:
            raise InvalidInputError(f"URDF not found: {exc}") from None
    return Path(urdf).expanduser()


# -- presets -------------------------------------------------------------------------

"""What iloci reads from a URDF itself: links, joints, the kinematic chain, mesh files.

Kinematics and dynamics are the back ends' business (Pinocchio, PyBullet,
MuJoCo each parse the URDF); the kernel only needs the tree, to choose the
joints between a base and a pen-tip frame, to check names (with "did you
mean"), to read joint limits, and to resolve mesh file names so that every
engine loads the same meshes. The file is parsed with the standard
library's :mod:`xml.etree.ElementTree`.

Mesh file names
---------------
A ``<mesh filename=...>`` is resolved as ROS tools do:

* ``package://NAME/rest``: ``rest`` under the directory of package ``NAME``,
  looked up in the robot's ``package_dirs`` (each a directory that holds
  ``NAME/``), then ``ROS_PACKAGE_PATH``, then the directories above the URDF
  (a URDF inside ``.../NAME/urdf/`` finds ``NAME``), then an importable
  Python package ``NAME``;
* ``file:///abs/path`` and absolute paths as they are;
* relative paths relative to the URDF's directory.
"""

from __future__ import annotations

from dataclasses import dataclass
import hashlib
import importlib.util
import json
import os
from pathlib import Path
import xml.etree.ElementTree as ET

import numpy as np

from iloci.errors import InvalidInputError, did_you_mean

__all__ = ["JOINT_TYPES", "MOVABLE", "UrdfJoint", "UrdfTree", "limits_message", "read_urdf",
           "resolve_uri", "resolved_urdf_text", "urdf_unicode"]

#: URDF joint types with one degree of freedom a drawing arm can use.
MOVABLE = ("revolute", "continuous", "prismatic")
#: Every joint type of the URDF specification (http://wiki.ros.org/urdf/XML/joint).
JOINT_TYPES = (*MOVABLE, "fixed", "floating", "planar")


@dataclass(frozen=True)
class UrdfJoint:
    """One ``<joint>`` of a URDF.

    Attributes
    ----------
    name, type, parent, child : str
        As in the file (``parent`` and ``child`` are link names).
    lower, upper : float
        Limits (rad or m); +-inf for a ``continuous`` joint or a joint
        without ``<limit>``.
    origin : ndarray, shape (4, 4)
        The child link's frame in the parent link's frame at zero motion.
    mimic : tuple (str, float, float) or None
        ``(joint, multiplier, offset)`` of a ``<mimic>`` element: this joint's
        value is ``multiplier * q[joint] + offset``, not free.
    limits_given : bool
        Whether the file gives both ``lower`` and ``upper`` (URDF lets a
        revolute or prismatic joint leave them out: they then read 0).
    axis : (float, float, float)
        ``<axis xyz>`` in the joint's frame (URDF's default ``1 0 0``).
    """

    name: str
    type: str
    parent: str
    child: str
    lower: float
    upper: float
    origin: np.ndarray
    mimic: tuple[str, float, float] | None = None
    limits_given: bool = True
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)

    def limits_fault(self) -> str:
        """What keeps iloci from moving this joint: ``"continuous"`` (no limits),
        ``"missing"`` (no lower/upper given), ``"infinite"`` (a limit is inf or nan),
        ``"empty"`` (not lower < upper) or "".

        iloci keeps every joint it moves inside finite limits (margins of the
        drawing plane, IK clipping), so a joint used needs ``lower < upper``;
        :func:`limits_message` words the faults of several joints.
        """
        if self.type == "continuous":
            return "continuous"
        if not self.limits_given:
            return "missing"
        if not (np.isfinite(self.lower) and np.isfinite(self.upper)):
            return "infinite"
        if self.lower >= self.upper:
            return "empty"
        return ""


def limits_message(joints: list[UrdfJoint]) -> str:
    """One sentence per kind of limit fault of ``joints`` (see :meth:`UrdfJoint.limits_fault`),
    naming the joints and what to do; "" when every joint has usable limits."""
    by: dict[str, list[UrdfJoint]] = {}
    for j in joints:
        fault = j.limits_fault()
        if fault:
            by.setdefault(fault, []).append(j)
    out = []
    if "continuous" in by:
        names = ", ".join(repr(j.name) for j in by["continuous"])
        out.append(f"joint(s) {names} are continuous (they turn without limits), and iloci "
                   "keeps every joint it moves inside finite limits: make each "
                   'type="revolute" with <limit lower="-3.14159" upper="3.14159" .../> (or '
                   "the range it should use), or leave it out of [robot] joints so it is "
                   "held fixed")
    if "missing" in by:
        names = ", ".join(f"{j.name!r} ({j.type})" for j in by["missing"])
        out.append(f"joint(s) {names} have no lower and upper in a <limit> (URDF then reads "
                   "both as 0: a joint that cannot move): give each "
                   '<limit lower="..." upper="..." effort="..." velocity="..."/> with its '
                   "range (rad; m for a prismatic joint), or leave it out of [robot] joints")
    if "infinite" in by:
        names = ", ".join(f"{j.name!r} [{j.lower:g}, {j.upper:g}]" for j in by["infinite"])
        out.append(f"joint(s) {names} have a limit that is not a finite number (iloci keeps "
                   "every joint it moves inside finite limits): give the real range in "
                   "<limit>, or leave the joint out of [robot] joints")
    if "empty" in by:
        def rng(j: UrdfJoint) -> str:
            swapped = " (lower above upper: swapped?)" if j.lower > j.upper else ""
            return f"{j.name!r} [{j.lower:g}, {j.upper:g}]{swapped}"
        names = ", ".join(rng(j) for j in by["empty"])
        out.append(f"joint(s) {names} have limits with no range (iloci needs lower < upper "
                   "for every joint it moves): give the real range in <limit>, or leave the "
                   "joint out of [robot] joints")
    return "; ".join(out)


@dataclass(frozen=True)
class UrdfTree:
    """The kinematic tree of a URDF file.

    Attributes
    ----------
    path : pathlib.Path
    name : str
        The ``<robot name=...>``.
    links : tuple of str
    joints : dict of str to UrdfJoint
        By joint name.
    root : str
        The one link that is no joint's child.
    massless : tuple of str
        Links without an ``<inertial>`` of positive mass (MuJoCo cannot move
        such a body; see :meth:`massless_moving`).
    """

    path: Path
    name: str
    links: tuple[str, ...]
    joints: dict[str, UrdfJoint]
    root: str
    massless: tuple[str, ...] = ()

    def massless_moving(self) -> list[str]:
        """Links moved by a joint (child of a movable joint) with nothing of positive mass
        attached to them by fixed joints: the bodies MuJoCo refuses to compile
        ("mass and inertia of moving bodies must be larger than mjMINVAL")."""
        fixed_children: dict[str, list[str]] = {}
        for j in self.joints.values():
            if j.type not in MOVABLE:
                fixed_children.setdefault(j.parent, []).append(j.child)

        def has_mass(link: str) -> bool:
            return link not in self.massless or any(
                has_mass(c) for c in fixed_children.get(link, ()))

        return [j.child for j in self.joints.values()
                if j.type in MOVABLE and not has_mass(j.child)]

    def massless_message(self) -> str:
        """Why MuJoCo cannot simulate this URDF, naming the links and what to do; "" if it can."""
        links = self.massless_moving()
        if not links:
            return ""
        return (f"{self.path}: link(s) {', '.join(map(repr, links))} move with a joint but "
                "have no <inertial> with a positive <mass> (nor anything fixed to them "
                "that has one); MuJoCo cannot simulate a massless moving body. Add "
                '<inertial><mass value="..."/><inertia .../></inertial> to each, or choose '
                'the PyBullet simulator ([simulator] name = "pybullet"), which accepts them.')

    def parent_joint(self, link: str) -> UrdfJoint | None:
        """The joint whose child is ``link`` (None for the root)."""
        for j in self.joints.values():
            if j.child == link:
                return j
        return None

    def check_link(self, link: str, what: str) -> None:
        """Raise InvalidInputError naming ``what`` when ``link`` is not a link (did you mean)."""
        if link not in self.links:
            raise InvalidInputError(
                f"{what} {link!r} is not a link of {self.path}; its links are "
                f"{', '.join(self.links)}.{did_you_mean(link, self.links)}")

    def chain(self, base: str, tip: str) -> list[UrdfJoint]:
        """The joints from link ``base`` down to link ``tip``, in order.

        Raises
        ------
        InvalidInputError
            A name is not a link (did you mean), or ``base`` is not an
            ancestor of ``tip``.
        """
        self.check_link(base, "base frame")
        self.check_link(tip, "pen-tip frame")
        out = []
        link = tip
        while link != base:
            j = self.parent_joint(link)
            if j is None:
                raise InvalidInputError(
                    f"the pen-tip frame {tip!r} does not hang below the base frame {base!r} "
                    f"in {self.path} (the tree's root is {self.root!r}); choose a base frame "
                    "on the way from the root to the pen tip.")
            out.append(j)
            link = j.parent
        return out[::-1]

    def movable_between(self, base: str, tip: str) -> list[str]:
        """Names of the movable joints (see :data:`MOVABLE`) from ``base`` to ``tip``."""
        return [j.name for j in self.chain(base, tip) if j.type in MOVABLE]

    def pose_of(self, link: str) -> np.ndarray:
        """Pose (4, 4) of ``link`` in the root frame with every joint at zero."""
        T = np.eye(4)
        for j in self.chain(self.root, link):
            T = T @ j.origin
        return T


def kinematics_fingerprint(path: str | os.PathLike[str], base: str, tip: str) -> str:
    """SHA-256 of the joints from ``base`` to ``tip`` as they move the tip: each one's
    name, type, origin, axis, limits and mimic (to 1e-9), not the file's bytes.

    A memory records it (``robot.kinematics``): its patterns are this arm's joint
    motions, so an edit of the chain (a link's length, a limit) makes them another
    arm's, while comments, colours, meshes and joints off the chain change nothing.

    Raises
    ------
    InvalidInputError
        As :func:`read_urdf` and :meth:`UrdfTree.chain`.
    """
    return chain_fingerprint(read_urdf(path).chain(base, tip))


def chain_fingerprint(chain: list[UrdfJoint]) -> str:
    """:func:`kinematics_fingerprint` of joints already read (:meth:`UrdfTree.chain`)."""
    h = hashlib.sha256()
    for j in chain:
        h.update(json.dumps([j.name, j.type, np.round(j.origin, 9).tolist(),
                             np.round(j.axis, 9).tolist(), repr(j.lower), repr(j.upper),
                             j.mimic]).encode())
    return h.hexdigest()


def _floats(text: str | None, n: int, what: str, path: Path) -> np.ndarray:
    if text is None:
        return np.zeros(n)
    try:
        v = np.array([float(x) for x in text.split()])
    except ValueError:
        v = np.zeros(0)
    if v.shape != (n,):
        raise InvalidInputError(f"{path}: {what} {text!r} is not {n} numbers.")
    if not np.all(np.isfinite(v)):
        raise InvalidInputError(f"{path}: {what} {text!r} holds nan or inf; give "
                                f"{n} finite numbers.")
    return v


def _child_attr(el: ET.Element, tag: str, attr: str) -> str:
    """Attribute ``attr`` of ``el``'s first ``<tag>`` child; "" when either is missing."""
    child = el.find(tag)
    return child.get(attr, "") if child is not None else ""


def _origin(el: ET.Element | None, path: Path) -> np.ndarray:
    T = np.eye(4)
    if el is None:
        return T
    xyz = _floats(el.get("xyz"), 3, "origin xyz", path)
    r, p, y = _floats(el.get("rpy"), 3, "origin rpy", path)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    # URDF: fixed-axis roll about x, then pitch about y, then yaw about z
    T[:3, :3] = [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                 [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                 [-sp, cp * sr, cp * cr]]
    T[:3, 3] = xyz
    return T


def read_urdf(path: str | os.PathLike[str]) -> UrdfTree:
    """Parse a URDF file's kinematic tree.

    Raises
    ------
    InvalidInputError
        The file does not exist, is not XML, or is not a URDF tree (no
        ``<robot>``, a joint naming an unknown link, not exactly one root).
    """
    p = Path(path)
    if p.is_dir():
        raise InvalidInputError(f"urdf {p} is a directory; give the robot's .urdf file in "
                                "it.")
    if not p.is_file():
        raise InvalidInputError(
            f"URDF not found: {p}. Give an existing file path, or "
            "'package://PACKAGE/path/to/robot.urdf' for a file inside an installed package; "
            "`iloci robots` lists the shipped robots.")
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise InvalidInputError(f"cannot read the URDF {p}: {exc.strerror}.") from None
    try:
        root = ET.fromstring(raw)
    except ET.ParseError as exc:
        if b"xacro:" in raw:  # an undeclared xacro: prefix is not even XML
            raise InvalidInputError(_xacro_message(p, "its xacro: tags")) from None
        raise InvalidInputError(f"{p} is not valid XML: {exc}.{_encoding_hint(raw)}") from None
    _check_expanded(root, p)
    if root.tag != "robot":
        raise InvalidInputError(f"{p} is not a URDF: its root element is <{root.tag}>, "
                                "not <robot>.")
    links = tuple(el.get("name", "") for el in root.findall("link"))
    _check_unique(links, "link", p)
    _check_unique([el.get("name", "") for el in root.findall("joint")], "joint", p)
    massless = tuple(el.get("name", "") for el in root.findall("link") if not _has_mass(el, p))
    joints: dict[str, UrdfJoint] = {}
    for el in root.findall("joint"):
        name, kind = el.get("name", ""), el.get("type", "")
        parent, child = (_child_attr(el, tag, "link") for tag in ("parent", "child"))
        if kind not in JOINT_TYPES:
            raise InvalidInputError(
                f"{p}: joint {name!r} has type {kind!r}, not a URDF joint type "
                f"({', '.join(JOINT_TYPES)}).{did_you_mean(kind, JOINT_TYPES)}")
        for link in (parent, child):
            if link not in links:
                raise InvalidInputError(f"{p}: joint {name!r} names link {link!r}, which the "
                                        "file does not define.")
        lim = el.find("limit")
        lo, hi = -np.inf, np.inf
        given = kind == "continuous" or (lim is not None and "lower" in lim.attrib
                                         and "upper" in lim.attrib)
        if kind != "continuous" and lim is not None:
            lo = _number(lim.get("lower", "0"), f"joint {name!r} <limit lower>", p)
            hi = _number(lim.get("upper", "0"), f"joint {name!r} <limit upper>", p)
        elif kind in ("revolute", "prismatic"):
            given = False
        axis = np.eye(3)[0]
        if kind in ("revolute", "continuous", "prismatic"):
            axis = _floats(_child_attr(el, "axis", "xyz") or None, 3, f"joint {name!r} "
                           "<axis xyz>", p) if el.find("axis") is not None else np.eye(3)[0]
            if not np.linalg.norm(axis) > 1e-9:
                raise InvalidInputError(
                    f"{p}: joint {name!r} has <axis xyz=\"{_child_attr(el, 'axis', 'xyz')}\">, "
                    "a zero vector: a joint moves about (or along) an axis; give its "
                    "direction, e.g. xyz=\"0 0 1\".")
        mimic = None
        m = el.find("mimic")
        if m is not None:
            mimic = (m.get("joint", ""),
                     _number(m.get("multiplier", "1"), f"joint {name!r} <mimic multiplier>", p),
                     _number(m.get("offset", "0"), f"joint {name!r} <mimic offset>", p))
        joints[name] = UrdfJoint(name, kind, parent, child, lo, hi,
                                 _origin(el.find("origin"), p), mimic, given,
                                 (float(axis[0]), float(axis[1]), float(axis[2])))
    parents: dict[str, list[str]] = {}
    for j in joints.values():
        parents.setdefault(j.child, []).append(j.name)
    twice = {link: js for link, js in parents.items() if len(js) > 1}
    if twice:
        link, js = next(iter(twice.items()))
        raise InvalidInputError(
            f"{p}: link {link!r} is the child of joints {', '.join(map(repr, js))}; in a URDF "
            "tree every link hangs from at most one joint (closed loops are not supported): "
            "keep one of these joints, or give the other a new child link.")
    children = {j.child for j in joints.values()}
    roots = [link for link in links if link not in children]
    if len(roots) != 1:
        raise InvalidInputError(f"{p}: a URDF tree has exactly one root link, found "
                                f"{roots or 'none'}.")
    return UrdfTree(p, root.get("name", p.stem), links, joints, roots[0], massless)


def _check_unique(names: list[str] | tuple[str, ...], what: str, path: Path) -> None:
    """Raise InvalidInputError naming the first ``what`` (link or joint) defined twice."""
    seen: set[str] = set()
    for n in names:
        if not n:
            raise InvalidInputError(f"{path}: a <{what}> has no name attribute; give each "
                                    f"<{what} name=...> a unique name.")
        if n in seen:
            raise InvalidInputError(
                f"{path}: {what} {n!r} is defined twice (every {what} name must be unique, "
                f"as back ends look {what}s up by name): rename or remove one of them.")
        seen.add(n)


def _encoding_hint(raw: bytes) -> str:
    """Why bytes that fail to parse may be in another encoding than they declare."""
    head = raw[:200].lower()
    if b"encoding=" in head:
        return ""
    try:
        raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        return (f" Its bytes are not UTF-8 (byte {raw[exc.start]:#04x} at offset {exc.start})"
                " and it declares no encoding: save it as UTF-8, or declare its encoding on "
                'the first line (<?xml version="1.0" encoding="ISO-8859-1"?>).')
    return ""


def _xacro_message(path: Path, what: str) -> str:
    out = path.stem if path.suffix == ".xacro" else path.stem + ".expanded.urdf"
    if not out.endswith(".urdf"):
        out += ".urdf"
    return (f"{path} is a xacro file, not a URDF yet ({what}); iloci reads plain URDF: "
            f"run xacro first (`xacro {path.name} > {out}`, "
            "from ROS's xacro package or `pip install xacro`) and give the expanded file.")


def _check_expanded(root: ET.Element, path: Path) -> None:
    """Raise InvalidInputError naming the first xacro tag or ``${...}`` / ``$(...)`` left."""
    parent = {c: p for p in root.iter() for c in p}
    for el in root.iter():
        tag = el.tag if isinstance(el.tag, str) else ""
        if (tag.startswith("{") and "xacro" in tag.partition("}")[0]) or \
                tag.startswith("xacro:"):
            raise InvalidInputError(_xacro_message(path, f"<xacro:{tag.rpartition('}')[2]}>"))
        for key, value in (*el.attrib.items(), ("text", el.text or "")):
            if "${" in value or "$(" in value:
                where = f"<{tag}" + (f" name={el.get('name')!r}" if el.get("name") else "")
                up = parent.get(el)
                if up is not None and up.get("name") and not el.get("name"):
                    where = f"<{up.tag} name={up.get('name')!r}> " + where
                raise InvalidInputError(_xacro_message(
                    path, f"{where}> {key}={value.strip()!r} is an unexpanded expression"))


def _number(text: str, what: str, path: Path) -> float:
    try:
        v = float(text)
    except ValueError:
        raise InvalidInputError(f"{path}: {what} is {text!r}, not a number.") from None
    if np.isnan(v):
        raise InvalidInputError(f"{path}: {what} is {text!r}, not a number.")
    return v


def _has_mass(link: ET.Element, path: Path) -> bool:
    mass = link.find("inertial/mass")
    if mass is None:
        return False
    return _number(mass.get("value", "0"), f"link {link.get('name')!r} <mass value>", path) > 0


def resolve_uri(uri: str, urdf_dir: Path, package_dirs: tuple[Path, ...] = ()) -> Path:
    """The file a URDF's mesh (or other resource) name refers to.

    Parameters
    ----------
    uri : str
        ``package://NAME/rest``, ``file://...``, an absolute or a relative path.
    urdf_dir : Path
        Directory of the URDF (relative paths and the ancestor search start there).
    package_dirs : tuple of Path
        Directories holding packages (``DIR/NAME/``), searched first.

    Raises
    ------
    InvalidInputError
        No such file (names the places searched).
    """
    uri = uri.removeprefix("file://")
    if not uri.startswith("package://"):
        f = Path(uri)
        f = f if f.is_absolute() else urdf_dir / f
        if not f.is_file():
            raise InvalidInputError(f"mesh file {uri!r} of the URDF in {urdf_dir} not found "
                                    f"(looked for {f}).")
        return f
    name, _, rest = uri[len("package://"):].partition("/")
    tried: list[Path] = []
    roots = list(package_dirs)
    roots += [Path(d) for d in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if d]
    roots += [d.parent for d in (urdf_dir, *urdf_dir.parents) if d.name == name]
    for r in roots:
        f = r / name / rest
        tried.append(f)
        if f.is_file():
            return f
    try:
        spec = importlib.util.find_spec(name.replace("-", "_"))
    except (ImportError, ValueError):
        spec = None
    if spec is not None and spec.submodule_search_locations:
        for loc in spec.submodule_search_locations:
            f = Path(loc) / rest
            tried.append(f)
            if f.is_file():
                return f
    raise InvalidInputError(
        f"cannot resolve {uri!r}: package {name!r} not found (tried "
        f"{', '.join(map(str, tried)) or 'no location'}). Add the directory holding "
        f"{name}/ to the robot's package_dirs or to ROS_PACKAGE_PATH.")


def urdf_unicode(path: Path) -> str:
    """The URDF's text as a str, whatever encoding its file declares (a byte-order mark,
    UTF-16, ``encoding="ISO-8859-1"``), without the XML declaration: what back ends
    whose own parsers read UTF-8 only are given (see :func:`resolved_urdf_text`)."""
    return ET.tostring(ET.parse(path).getroot(), encoding="unicode")


def resolved_urdf_text(path: Path, package_dirs: tuple[Path, ...] = (),
                       replace_suffix: dict[str, str] | None = None) -> str:
    """The URDF's text with every mesh file name made an absolute path (a str, whatever
    encoding the file declares; without the XML declaration).

    Parameters
    ----------
    path : Path
    package_dirs : tuple of Path
        As for :func:`resolve_uri`.
    replace_suffix : dict, optional
        For engines that cannot read a mesh format: e.g. ``{".dae": ".stl"}``
        swaps a visual mesh for a file of the same stem with that suffix
        when one exists beside it or in a sibling ``collision`` directory.

    Raises
    ------
    InvalidInputError
        A mesh file cannot be found.
    """
    tree = ET.parse(path)
    for mesh in tree.getroot().iter("mesh"):
        uri = mesh.get("filename")
        if not uri:
            continue
        try:
            f = resolve_uri(uri, path.parent, package_dirs)
        except InvalidInputError as exc:
            raise InvalidInputError(f"{path}: <mesh filename={uri!r}>: {exc}") from None
        for old, new in (replace_suffix or {}).items():
            if f.suffix.lower() == old:
                for cand in (f.with_suffix(new),
                             f.parent.parent / "collision" / (f.stem + new)):
                    if cand.is_file():
                        f = cand
                        break
        mesh.set("filename", str(f.resolve()))
    return ET.tostring(tree.getroot(), encoding="unicode")

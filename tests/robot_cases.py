"""A small five-joint arm written as a URDF with STL meshes, for the robot tests.

Five revolute joints drive a 3-D pen position: a redundant arm like the
Panda's, but light enough for quick tests, and with meshes named both as
``package://testarm/...`` and by a relative path, as real descriptions do.
"""

from __future__ import annotations

from pathlib import Path

def _box_stl(h: float = 0.02) -> bytes:
    """A binary STL box of ``2 h`` a side (12 triangles), centred on the origin."""
    import struct
    v = [(-h, -h, -h), (h, -h, -h), (h, h, -h), (-h, h, -h),
         (-h, -h, h), (h, -h, h), (h, h, h), (-h, h, h)]
    faces = [(0, 2, 1), (0, 3, 2), (4, 5, 6), (4, 6, 7), (0, 1, 5), (0, 5, 4),
             (1, 2, 6), (1, 6, 5), (2, 3, 7), (2, 7, 6), (3, 0, 4), (3, 4, 7)]
    out = bytearray(b"iloci test box".ljust(80, b" ")) + struct.pack("<I", len(faces))
    for f in faces:
        out += struct.pack("<3f", 0, 0, 0)
        for i in f:
            out += struct.pack("<3f", *v[i])
        out += struct.pack("<H", 0)
    return bytes(out)


def _link(name: str, mesh: str | None, length: float, mass: float) -> str:
    visual = (f'<visual><geometry><mesh filename="{mesh}"/></geometry></visual>'
              f'<collision><geometry><mesh filename="{mesh}"/></geometry></collision>'
              if mesh else "")
    return (f'<link name="{name}">{visual}<inertial><origin xyz="0 0 {length / 2}"/>'
            f'<mass value="{mass}"/><inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" '
            'izz="0.001"/></inertial></link>')


def _joint(name: str, parent: str, child: str, z: float, axis: str, lo: float,
           hi: float) -> str:
    return (f'<joint name="{name}" type="revolute"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="0 0 {z}"/><axis xyz="{axis}"/>'
            f'<limit lower="{lo}" upper="{hi}" effort="100" velocity="3"/></joint>')


def write_test_arm(root: Path) -> Path:
    """Write ``root/testarm/urdf/arm.urdf`` with its meshes; returns the URDF path.

    Links ``base`` -> ``l1`` .. ``l5`` -> ``pen`` (fixed); joints ``j1`` (yaw),
    ``j2``-``j4`` (pitch), ``j5`` (roll); a prismatic ``grip`` joint off the
    chain, and a fixed ``camera`` link.
    """
    pkg = root / "testarm"
    (pkg / "urdf").mkdir(parents=True, exist_ok=True)
    (pkg / "meshes").mkdir(exist_ok=True)
    (pkg / "meshes" / "box.stl").write_bytes(_box_stl())
    parts = ['<?xml version="1.0"?>', '<robot name="testarm">',
             _link("base", "package://testarm/meshes/box.stl", 0.1, 2.0)]
    chain = [("j1", "base", "l1", 0.10, "0 0 1", -2.5, 2.5),
             ("j2", "l1", "l2", 0.05, "0 1 0", -1.8, 1.8),
             ("j3", "l2", "l3", 0.25, "0 1 0", -2.4, 2.4),
             ("j4", "l3", "l4", 0.22, "0 1 0", -2.0, 2.0),
             ("j5", "l4", "l5", 0.08, "0 0 1", -2.8, 2.8)]
    for i, (name, parent, child, z, axis, lo, hi) in enumerate(chain):
        mesh = "../meshes/box.stl" if i % 2 else "package://testarm/meshes/box.stl"
        parts.append(_link(child, mesh, 0.2, 0.2))
        parts.append(_joint(name, parent, child, z, axis, lo, hi))
    parts.append(_link("pen", None, 0.0, 0.01))
    parts.append('<joint name="pen_joint" type="fixed"><parent link="l5"/><child link="pen"/>'
                 '<origin xyz="0.0 0 0.06"/></joint>')
    parts.append(_link("finger", None, 0.0, 0.01))
    parts.append('<joint name="grip" type="prismatic"><parent link="l5"/>'
                 '<child link="finger"/><origin xyz="0.03 0 0.03"/><axis xyz="1 0 0"/>'
                 '<limit lower="0" upper="0.02" effort="5" velocity="0.1"/></joint>')
    parts.append(_link("camera", None, 0.0, 0.01))
    parts.append('<joint name="camera_joint" type="fixed"><parent link="base"/>'
                 '<child link="camera"/><origin xyz="0 0 0.3"/></joint>')
    parts.append("</robot>")
    path = pkg / "urdf" / "arm.urdf"
    path.write_text("\n".join(parts), encoding="utf-8")
    return path


#: The test arm's rest posture (rad): elbow bent, pen in front of the base.
REST = [0.0, 0.4, 0.9, 0.9, 0.0]

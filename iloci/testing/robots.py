"""Conformance checks of a robot preset (kind ``robot``), and of its registration.

``make(seed)`` returns the robot description
(:class:`iloci.interfaces.RobotDescription`, in practice a
:class:`iloci.sensorimotor.robots.Robot`); the seed is ignored. The checks
read the description only: no IK solver or simulator is needed, so they run
in every environment the preset is installed in.
"""

from __future__ import annotations

from collections.abc import Callable
import json
from pathlib import Path
from typing import Any

import numpy as np

from iloci.interfaces import RobotDescription, unmet_members

__all__ = ["ROBOT_CHECKS", "check_registration"]

#: ``make(seed) -> robot description`` (the seed is ignored).
Factory = Callable[[int], Any]


def rb_protocol(make: Factory) -> None:
    """The description has every member of ``RobotDescription``; its URDF exists."""
    robot = make(0)
    unmet = unmet_members(robot, RobotDescription)
    assert not unmet, f"robot lacks {', '.join(unmet)} (see iloci.interfaces.RobotDescription)"
    assert Path(robot.urdf_path).is_file(), f"its URDF {robot.urdf_path} is not a file"


def rb_joints_and_limits(make: Factory) -> None:
    """``J >= 1`` joints; ``lower``, ``upper`` and ``q_home`` of shape ``(J,)``, finite,
    ``lower < upper`` and ``q_home`` within them."""
    robot = make(0)
    j = len(robot.joint_names)
    assert j >= 1, "no joints"
    assert len(set(robot.joint_names)) == j, f"a joint named twice: {robot.joint_names}"
    for what in ("lower", "upper", "q_home"):
        a = np.asarray(getattr(robot, what))
        assert a.shape == (j,), f"{what} has shape {a.shape}, expected ({j},)"
        assert np.all(np.isfinite(a)), f"{what} is not finite: {a}"
    lo, hi, q = (np.asarray(robot.lower), np.asarray(robot.upper), np.asarray(robot.q_home))
    assert np.all(lo < hi), f"lower {lo} not below upper {hi}"
    assert np.all((lo <= q) & (q <= hi)), f"q_home {q} outside [{lo}, {hi}]"


def rb_describe_is_json(make: Factory) -> None:
    """``describe()`` is what ``iloci robots --show --json`` prints: JSON, the same joints."""
    robot = make(0)
    desc = robot.describe()
    json.dumps(desc)
    assert desc["name"] == robot.name, f"describe() names {desc['name']!r}, not {robot.name!r}"
    assert list(desc["joints"]) == list(robot.joint_names), "describe()'s joints differ"


def rb_deterministic(make: Factory) -> None:
    """Two builds describe the same robot (joints, limits, start posture, plane)."""
    a, b = make(0), make(1)
    assert a.describe() == b.describe(), "two builds of the preset differ"


ROBOT_CHECKS: list[Callable[[Factory], None]] = [rb_protocol, rb_joints_and_limits,
                                                 rb_describe_is_json, rb_deterministic]


def check_registration(spec: Any, robot: Any) -> None:
    """A robot's registration states what its description is.

    Parameters
    ----------
    spec : iloci.registry.ComponentSpec
        Of kind ``robot``.
    robot : RobotDescription
        What the registry builds for it.

    Raises
    ------
    AssertionError
        ``joints`` is not the robot's ``J``, or ``plane`` is ``"auto"`` and
        the robot comes with a plane (or ``"given"`` and it comes with a
        placeholder to be placed).
    """
    joints, plane = spec.fact("joints"), spec.fact("plane")
    assert plane in ("given", "auto"), f"robot {spec.name!r}: plane {plane!r} is neither " \
        "'given' nor 'auto'"
    assert joints == len(robot.joint_names), (
        f"robot {spec.name!r} is registered with joints={joints}, but has "
        f"{len(robot.joint_names)}")
    placeholder = robot.plane_report.get("method") == "placeholder"
    assert placeholder == (plane == "auto"), (
        f"robot {spec.name!r} is registered with plane={plane!r}, but its plane is "
        f"{'a placeholder' if placeholder else 'given'}")

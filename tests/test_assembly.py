"""One assembly path: every way to a robot ready to draw places its plane once, in one function.

``iloci.sensorimotor.robots.assembly.robot_and_ik`` (robot -> IK -> place the
plane -> IK again) is the only caller of ``place_robot``, which is the only
caller of the plane search; an agent is assembled only by
``iloci.agent.assembly.assemble`` (for ``build`` and ``Agent.load``); drawing,
``iloci show`` and ``iloci robots`` call ``robot_and_ik`` themselves.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import iloci
from iloci.sensorimotor.robots import assembly

ROOT = Path(__file__).resolve().parents[1] / "iloci"


def _callers(name: str) -> set[str]:
    """``module:function`` of every call of ``name`` (a bare or dotted name) in iloci/."""
    out = set()
    for path in sorted(ROOT.rglob("*.py")):
        module = ".".join(path.relative_to(ROOT.parent).with_suffix("").parts)
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for fn in ast.walk(tree):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if isinstance(node, ast.Call):
                    f = node.func
                    called = f.id if isinstance(f, ast.Name) else \
                        f.attr if isinstance(f, ast.Attribute) else None
                    if called == name:
                        out.add(f"{module}:{fn.name}")
    return out


def test_the_plane_is_placed_in_one_function_and_reached_from_the_four_assemblies():
    assert _callers("find_drawing_plane") == {"iloci.sensorimotor.robots.assembly:place_robot"}
    assert _callers("place_robot") == {"iloci.sensorimotor.robots.assembly:robot_and_ik"}
    assert _callers("robot_and_ik") == {
        "iloci.agent.assembly:assemble",             # build, Agent.load
        "iloci.drawing:load_drawing_parts",
        "iloci.commands.show:_components",
        "iloci.commands.robots:describe",
    }
    assert _callers("assemble") == {"iloci.agent.core:build",
                                    "iloci.agent.persistence:load"}


@pytest.mark.usefixtures("default_back_ends")
def test_each_assembly_places_the_robots_plane_once(monkeypatch, tmp_path):
    from iloci.commands import robots, show
    from iloci.drawing import load_drawing_parts

    placed: list[str] = []
    place_robot = assembly.place_robot

    def counted(robot, mode, ik, cfg):
        placed.append(mode)
        return place_robot(robot, mode, ik, cfg)

    monkeypatch.setattr(assembly, "place_robot", counted)

    def once(make):
        placed.clear()
        out = make()
        assert len(placed) == 1, placed
        return out

    agent = once(lambda: iloci.build())
    path = agent.save(tmp_path / "memory.npz")
    once(lambda: iloci.Agent.load(path))
    once(lambda: iloci.Agent.load(path, purpose="recognize"))
    once(lambda: load_drawing_parts(path))
    once(lambda: show._components(None))
    once(lambda: robots.describe(None, None))

"""The import graph of iloci/ follows the layers of docs/development.md ("Architecture").

The graph counts every import of iloci's own modules: at the top of a
module, inside a function, under ``TYPE_CHECKING``. A circle, an import up a
layer, an arrow the forbidden table names, or a module no layer places fails.
"""

from __future__ import annotations

import ast
from pathlib import Path
import re

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "development.md"


def _modules() -> dict[str, Path]:
    out = {}
    for p in sorted((ROOT / "iloci").rglob("*.py")):
        parts = list(p.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = p
    return out


def import_graph() -> dict[str, set[str]]:
    """Module -> the iloci modules it imports (each import resolved to a module of iloci/)."""
    mods = _modules()

    def resolve(name: str) -> str | None:
        while name not in mods and "." in name:
            name = name.rsplit(".", 1)[0]
        return name if name in mods else None

    graph: dict[str, set[str]] = {m: set() for m in mods}
    for mod, path in mods.items():
        package = mod if path.name == "__init__.py" else mod.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[:len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([base] if base else []))
                names = [f"{base}.{a.name}" for a in node.names]
            else:
                continue
            for name in names:
                if name == "iloci" or name.startswith("iloci."):
                    target = resolve(name)
                    if target is not None and target != mod:
                        graph[mod].add(target)
    return graph


def _table(marker: str) -> list[list[str]]:
    text = DOC.read_text(encoding="utf-8")
    start = text.index(f"<!-- {marker}:")
    rows = []
    for line in text[start:].splitlines()[1:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        if cells[0] in ("layer", "from") or set(cells[0]) <= {"-"}:
            continue
        rows.append(cells)
    return rows


def _names(cell: str) -> list[str]:
    return re.findall(r"`([\w.]+)`", cell)


def _covers(prefix: str, module: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


def layers() -> dict[str, int]:
    """Module -> its layer's rank (0 lowest), from the documented table."""
    rows = _table("layers")
    assert rows, "docs/development.md lost its layer table"
    out = {}
    for rank, row in enumerate(rows):
        for name in _names(row[1]):
            out[name] = rank
    return out


def _layer_of(module: str, ranks: dict[str, int]) -> int | None:
    # the longest documented prefix places the module
    best = [p for p in ranks if _covers(p, module)]
    return ranks[max(best, key=len)] if best else None


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return import_graph()


def test_the_import_graph_has_no_circle(graph):
    assert _circles(graph) == []


def test_every_module_has_a_layer(graph):
    ranks = layers()
    assert [m for m in graph if _layer_of(m, ranks) is None] == []


def test_no_import_goes_up_a_layer(graph):
    ranks = layers()
    names = {r: row[0] for r, row in enumerate(_table("layers"))}
    up = [f"{a} ({names[_layer_of(a, ranks)]}) -> {b} ({names[_layer_of(b, ranks)]})"
          for a in sorted(graph) for b in sorted(graph[a])
          if _layer_of(b, ranks) > _layer_of(a, ranks)]
    assert up == []


def _forbidden(graph: dict[str, set[str]]) -> list[str]:
    rules = [(_names(r[0])[0], _names(r[1])[0]) for r in _table("forbidden")]
    assert rules, "docs/development.md lost its forbidden-arrow table"
    return [f"{a} -> {b}" for a in sorted(graph) for b in sorted(graph[a])
            for src, dst in rules if _covers(src, a) and _covers(dst, b)]


def test_no_forbidden_arrow(graph):
    assert _forbidden(graph) == []


@pytest.mark.parametrize("target", ["iloci.concepts.memory", "iloci.concepts.learner",
                                    "iloci.concepts.rehearsal", "iloci.sensorimotor.frames",
                                    "iloci.rnnpb.common"])
def test_the_web_page_uses_the_agents_public_face_only(graph, target):
    """A new import of the robot's mind (or its perception) by the web layer fails."""
    assert not any(_covers("iloci.web", a) and _covers(target.rsplit(".", 1)[0], b)
                   for a in graph for b in graph[a])
    assert _forbidden({"iloci.web.classroom": {target}}) == [f"iloci.web.classroom -> {target}"]


def test_the_checks_catch_what_they_forbid():
    """A circle, an import up a layer and a forbidden arrow are each found."""
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    ranks = layers()
    assert _layer_of("iloci.concepts.memory", ranks) > _layer_of("iloci.config", ranks)
    assert _layer_of("iloci.evaluation.fold", ranks) > _layer_of("iloci.hookspecs", ranks)
    assert _layer_of("iloci.data.concepts", ranks) == _layer_of("iloci.data", ranks)
    assert _layer_of("iloci.sensorimotor.robots.plane", ranks) > _layer_of("iloci.config", ranks)

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


def local_imports_without_a_reason() -> list[str]:
    """``module:line`` of each import of iloci's own modules inside a function with no comment.

    The reason is a comment on a line of the import's run (consecutive import
    statements) or on the line just above the run.
    """
    return sorted(f"{mod}:{line}" for mod, path in _modules().items()
                  for line in _unexplained(path.read_text(encoding="utf-8")))


def _unexplained(source: str) -> list[int]:
    """Lines of ``source`` importing iloci's own modules in a function, with no comment."""
    lines = source.splitlines()
    tree = ast.parse(source)
    functions = [n for n in ast.walk(tree)
                 if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
    out = set()
    for block in (b for fn in functions for n in ast.walk(fn) for b in _bodies(n)):
        for run in _runs(block):
            own = [n for n in run if _imports_iloci(n)]
            first, last = run[0].lineno, run[-1].end_lineno or run[-1].lineno
            if own and not any("#" in line for line in lines[max(first - 2, 0):last]):
                out.update(n.lineno for n in own)
    return sorted(out)


def _bodies(node: ast.AST) -> list[list[ast.stmt]]:
    return [getattr(node, f) for f in ("body", "orelse", "finalbody")
            if isinstance(getattr(node, f, None), list)]


def _runs(body: list[ast.stmt]) -> list[list[ast.stmt]]:
    """Runs of consecutive import statements in a statement list."""
    runs: list[list[ast.stmt]] = []
    prev: ast.stmt | None = None
    for stmt in body:
        if isinstance(stmt, (ast.Import, ast.ImportFrom)):
            if runs and runs[-1][-1] is prev:
                runs[-1].append(stmt)
            else:
                runs.append([stmt])
        prev = stmt
    return runs


def _imports_iloci(node: ast.stmt) -> bool:
    if isinstance(node, ast.ImportFrom):
        return node.level > 0 or (node.module or "").split(".")[0] == "iloci"
    return isinstance(node, ast.Import) and any(a.name.split(".")[0] == "iloci"
                                                for a in node.names)


def test_an_import_inside_a_function_says_why():
    """iloci's own modules are imported at the top; one inside a function carries its reason.

    A reason is a cycle that forces it, or a heavy or optional third-party
    library the imported module loads (scipy, rich, starlette) that a
    command or ``import iloci`` should not pay for until it is used
    (docs/development.md, "Architecture").
    """
    assert local_imports_without_a_reason() == []


def test_the_import_check_finds_a_local_import_without_a_reason():
    code = ("def f():\n    x = 1\n    import json\n    from iloci.errors import IlociError\n"
            "    return x\n\n"
            "def g():\n    # the learner imports scipy: loaded when first used\n"
            "    import json\n    from iloci.concepts import learner\n\n"
            "def h():\n    from iloci import errors  # a cycle: errors imports h's module\n"
            "    import numpy\n")
    assert _unexplained(code) == [4]

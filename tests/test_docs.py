"""The documentation is complete and true to the code.

Hooks: every spec in ``iloci/hookspecs.py`` is documented in docs/hooks.md
with its arguments (and nothing else is), and has a test. Config: every key
of every section, including the schemas of the installed first-party
components, is in docs/config.md, and that file is what ``python -m
iloci.docgen`` generates now. Snippets: docs/embedding.md runs, the files
shown in docs/writing-a-plugin.md are the example plugin's, links resolve,
and the command-line options the guide names exist.
"""

from __future__ import annotations

import dataclasses
import inspect
import re

import pytest
from conftest import ROOT
from test_hooks import hookspec_names

from iloci import hookspecs
from iloci.config import _PLAIN_SECTIONS
from iloci.docgen import PAPER, config_reference, first_party
from iloci.interfaces import COMPONENT_KINDS
from iloci.plugins import get_registry
from iloci.registry import FIRST_PARTY

DOCS = ROOT / "docs"
REGENERATE = ("docs/config.md is out of date: regenerate it with "
              "`python -m iloci.docgen > docs/config.md`")


def read(name: str) -> str:
    return (DOCS / name).read_text(encoding="utf-8")


def fenced_blocks(text: str, lang: str) -> list[tuple[str, str]]:
    """(line before the fence, body) of every ```lang block."""
    out = []
    for m in re.finditer(rf"^([^\n]*)\n```{lang}\n(.*?)^```$", text, re.S | re.M):
        out.append((m.group(1), m.group(2)))
    return out


# -- hooks -----------------------------------------------------------------------

def documented_hooks() -> dict[str, list[str]]:
    """Hook name -> argument names, from the ``### `name(args)``` headings of hooks.md."""
    out = {}
    for m in re.finditer(r"^### `(iloci_\w+)\(([^)]*)\)`", read("hooks.md"), re.M):
        out[m.group(1)] = [a.strip() for a in m.group(2).split(",") if a.strip()]
    return out


@pytest.mark.parametrize("hook", hookspec_names())
def test_every_hookspec_is_documented_with_its_arguments(hook):
    documented = documented_hooks()
    assert hook in documented, f"docs/hooks.md has no section for {hook}"
    args = list(inspect.signature(getattr(hookspecs, hook)).parameters)
    assert documented[hook] == args, f"docs/hooks.md gives {hook} arguments " \
                                     f"{documented[hook]}, the spec takes {args}"


def test_hooks_md_documents_no_hook_that_does_not_exist():
    assert set(documented_hooks()) == set(hookspec_names())


@pytest.mark.parametrize("hook", hookspec_names())
def test_every_hookspec_has_a_test(hook):
    # tests/test_hooks.py calls every hook for real; a new spec must be added there
    users = [p.name for p in (ROOT / "tests").rglob("test_*.py")
             if p.name != "test_docs.py" and hook in p.read_text(encoding="utf-8")]
    assert "test_hooks.py" in users, f"no test calls {hook}: implement it in " \
                                     "tests/test_hooks.py's Recorder"


# -- configuration reference -------------------------------------------------------

def reference_blocks(text: str) -> list[str]:
    """The text split before every heading."""
    return [b for b in re.split(r"(?m)^(?=#)", text) if b.strip()]


def component_block(text: str, name: str) -> str:
    for block in reference_blocks(text):
        if block.startswith(f'#### `name = "{name}"`'):
            return block
    raise AssertionError(f'docs/config.md has no section for name = "{name}"')


def test_config_reference_is_current():
    committed = read("config.md")
    generated = config_reference()
    registered = {(s.kind, s.name) for s in get_registry().specs()}
    if {k for k in FIRST_PARTY if k[0] in COMPONENT_KINDS} <= registered:  # all installed
        assert committed == generated, REGENERATE
    else:  # the installed back ends' sections, and everything else
        have = set(reference_blocks(committed))
        stale = [b.splitlines()[0] for b in reference_blocks(generated) if b not in have]
        assert not stale, f"{REGENERATE} (sections differing: {stale})"


def test_every_settings_key_is_in_the_reference():
    text = read("config.md")
    for section, cls in _PLAIN_SECTIONS.items():
        for f in dataclasses.fields(cls):
            assert f"`{section}.{f.name}`" in text, f"{section}.{f.name} missing"
    for section in COMPONENT_KINDS:
        assert f"`{section}.name`" in text


def test_every_first_party_component_is_in_the_reference():
    text = read("config.md")
    for kind, name in FIRST_PARTY:
        if kind in COMPONENT_KINDS:  # executors are chosen on the command line, not in a config
            component_block(text, name)
    for name in ("oracle", "noisy", "console"):
        component_block(text, name)


@pytest.mark.parametrize("spec", [s for s in get_registry().specs() if first_party(s)],
                         ids=lambda s: f"{s.kind}:{s.name}")
def test_every_key_of_an_installed_component_is_in_its_section(spec):
    block = component_block(read("config.md"), spec.name)
    section = spec.kind  # a kind is its config section
    fields = dataclasses.fields(spec.params) if spec.params else ()
    for f in fields:
        assert f"`{section}.{f.name}`" in block, f"{section}.{f.name} of {spec.name} missing"
    if not fields:
        assert "No further keys." in block


def test_paper_symbols_name_real_keys():
    keys = {f"{sec}.{f.name}" for sec, cls in _PLAIN_SECTIONS.items()
            for f in dataclasses.fields(cls)}
    text = read("config.md")
    for key, symbol in PAPER.items():
        section = key.split(".")[0]
        if section in _PLAIN_SECTIONS:
            assert key in keys, f"docgen.PAPER names {key}, which is not a config key"
        assert f"| `{key}` |" in text and symbol in text


# -- snippets and files --------------------------------------------------------------

VARIES = "<!-- output varies: depends on the network's training -->"


def snippets_and_outputs(text: str) -> list[tuple[str, str | None]]:
    """Each python block with the output the page shows after it (None: none or it varies)."""
    out = []
    pattern = r"(?ms)^```python\n(.*?)^```\n(?:\n(<!--[^\n]*-->\n)?```text\n(.*?)^```$)?"
    for m in re.finditer(pattern, text):
        code, marker, shown = m.groups()
        out.append((code, None if marker and marker.strip() == VARIES else shown))
    return out


def test_embedding_snippets_run_and_print_what_the_page_shows(tmp_path, monkeypatch, capsys):
    pytest.importorskip("iloci_native")  # the page's settings name native-rnnpb
    pytest.importorskip("pinocchio")
    from iloci.errors import MissingBackendError

    monkeypatch.chdir(tmp_path)  # the snippets write a memory file
    namespace: dict = {"__name__": "embedding_md"}
    snippets = snippets_and_outputs(read("embedding.md"))
    assert len(snippets) == len(fenced_blocks(read("embedding.md"), "python")) >= 10
    for i, (code, shown) in enumerate(snippets):
        where = f"docs/embedding.md, python block {i + 1}"
        capsys.readouterr()
        try:
            exec(compile(code, where, "exec"), namespace)
        except MissingBackendError as exc:  # e.g. the torch plugin not installed
            pytest.skip(str(exc))
        printed = capsys.readouterr().out
        if shown is not None:
            assert printed == shown, f"{where} prints something else than the page shows"


def test_plugin_walkthrough_shows_the_example_plugin_files():
    example = DOCS / "examples" / "iloci-example-plugin"
    shown = {}
    for before, body in fenced_blocks(read("writing-a-plugin.md"), r"\w+"):
        m = re.fullmatch(r"<!-- file: (\S+) -->", before.strip())
        if m:
            shown[m.group(1)] = body
    files = {"pyproject.toml", "iloci_replay/__init__.py", "iloci_replay/teacher.py",
             "tests/test_replay.py"}
    assert set(shown) == files
    for path, body in shown.items():
        assert body == (example / path).read_text(encoding="utf-8"), \
            f"docs/writing-a-plugin.md shows a different {path} than {example / path}"


def _slug(heading: str) -> str:
    """GitHub's anchor for a Markdown heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


@pytest.mark.parametrize("page", sorted(p.name for p in DOCS.glob("*.md")) + ["../README.md"])
def test_links_resolve(page):
    path = (DOCS / page).resolve()
    text = path.read_text(encoding="utf-8")
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):
            continue
        file, _, anchor = target.partition("#")
        dest = (path.parent / file).resolve() if file else path
        assert dest.exists(), f"{page}: link to missing {target}"
        if anchor:
            prose = re.sub(r"(?ms)^```.*?^```$", "", dest.read_text(encoding="utf-8"))
            headings = re.findall(r"^#+ (.*)$", prose, re.M)
            assert anchor in {_slug(h) for h in headings}, f"{page}: no heading for {target}"


def test_index_links_every_page():
    index = read("index.md")
    for page in DOCS.glob("*.md"):
        if page.name != "index.md":
            assert f"]({page.name})" in index, f"docs/index.md does not link {page.name}"


def test_guide_names_only_real_command_line_options():
    import argparse

    from iloci.cli import make_parser

    options: set[str] = set()
    commands: set[str] = set()
    stack = [make_parser()]
    while stack:
        parser = stack.pop()
        for action in parser._actions:
            options.update(action.option_strings)
            if isinstance(action, argparse._SubParsersAction):
                commands.update(action.choices)
                stack.extend(action.choices.values())
    guide = read("guide.md")
    named = set(re.findall(r"(?<![\w-])--[a-z][a-z-]*", guide))
    assert named <= options, f"options the CLI does not have: {sorted(named - options)}"
    # in code: `iloci CMD ...` inline, or a command line of a sh/text block
    used = set(re.findall(r"`iloci ([a-z]+)", guide))
    for _, body in fenced_blocks(guide, "(?:sh|text)"):
        used |= set(re.findall(r"(?m)^(?:\$ )?iloci ([a-z]+)", body))
    assert used <= commands, f"commands the CLI does not have: {sorted(used - commands)}"


def test_the_method_is_in_the_repository_with_full_references():
    """docs/method.md cites the paper and Tani's RNNPB in full; report.md cites it."""
    text = " ".join(read("method.md").split())  # references wrap across lines
    for needle in ("Incremental learning of high-level concepts by imitation",
                   "Alibeigi", "Nili Ahmadabadi", "Araabi", "10.1109/TRO.2016.2623329",
                   "Tani", "RNNPB", "10.1109/TSMCA.2003.809171",
                   "10.1016/j.neunet.2004.05.007", "Khansari-Zadeh"):
        assert needle in text, needle
    for section in ("## Words", "## Learning phase", "## Inference phase",
                    "## Where the paper is silent", "## Evaluation protocol", "## References"):
        assert section in text, section
    import inspect

    from iloci.evaluation import report
    assert "docs/method.md" in inspect.getsource(report._write_outputs)  # the report.md it writes


def test_no_file_refers_to_a_design_document_outside_the_repository():
    name = "DESIGN" + ".md"
    offenders = [str(p.relative_to(ROOT)) for top in ("iloci", "docs", "plugins", "benchmarks",
                                                       "tests", "README.md", "tox.ini")
                 for p in ([ROOT / top] if (ROOT / top).is_file() else (ROOT / top).rglob("*"))
                 if p.is_file() and p.suffix in (".py", ".md", ".toml", ".urdf", ".ini", ".c")
                 and name in p.read_text(errors="replace")]
    assert offenders == []


def test_install_commands_for_the_defaults_name_the_default_back_ends():
    """The README's quickstart and the guide's install line for the defaults install
    exactly the plugins of the default config's components (the guide once installed
    iloci-torch, which pulls torch, for a default that is native-rnnpb)."""
    from iloci.config import DEFAULT_NAMES

    wanted = {FIRST_PARTY[(kind, name)] for kind, name in DEFAULT_NAMES.items()
              if (kind, name) in FIRST_PARTY}
    assert "iloci-native" in wanted
    pages = {"README.md": (ROOT / "README.md").read_text(encoding="utf-8"),
             "docs/guide.md": (ROOT / "docs" / "guide.md").read_text(encoding="utf-8")}
    lines = {page: [m.group(1) for m in re.finditer(
        r"pip install \. ((?:\./plugins/[\w.-]+ ?)+)", text)] for page, text in pages.items()}
    for page, found in lines.items():
        assert found, f"{page}: no 'pip install . ./plugins/...' line for the defaults"
        plugins = set(re.findall(r"\./plugins/([\w.-]+)", found[0]))
        assert plugins == wanted, f"{page}: {found[0]!r} installs {sorted(plugins)}, " \
                                  f"the defaults need {sorted(wanted)}"

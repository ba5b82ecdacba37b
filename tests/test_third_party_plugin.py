"""A third-party plugin distribution, built and pip-installed inside the test.

It registers a Teacher through the ``iloci`` entry-point group; nothing in
iloci changes. ``iloci plugins`` lists it and a config naming it builds it.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from conftest import run_cli

PYPROJECT = """
[build-system]
requires = ["setuptools>=61"]
build-backend = "setuptools.build_meta"

[project]
name = "iloci-polite-teacher"
version = "1.2.3"
dependencies = []

[project.entry-points.iloci]
polite = "iloci_polite"
"""

PLUGIN = '''
from dataclasses import dataclass
from iloci import hookimpl

@dataclass(frozen=True)
class PoliteParams:
    reward: int = 1

@hookimpl
def iloci_register_teachers(registry):
    registry.add("polite", "iloci_polite.teacher:PoliteTeacher", params=PoliteParams,
                 summary="always rewards")
    registry.add("picky", "iloci_polite.teacher:PoliteTeacher",
                 requires=("iloci_polite_missing_lib",),
                 install="pip install iloci-polite-teacher[picky]")
'''

TEACHER = '''
class PoliteTeacher:
    def __init__(self, reward=1, seed=0):
        self.reward = reward
        self.seed = seed

    def feedback(self, demo, response):
        return self.reward
'''


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    src = tmp_path_factory.mktemp("src")
    (src / "pyproject.toml").write_text(PYPROJECT)
    pkg = src / "iloci_polite"
    pkg.mkdir()
    (pkg / "__init__.py").write_text(PLUGIN)
    (pkg / "teacher.py").write_text(TEACHER)
    target = tmp_path_factory.mktemp("site")
    # A real pip install (wheel build, dist-info with entry_points.txt), into a
    # separate directory so the rest of the test session is unaffected.
    res = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                          "--target", str(target), str(src)],
                         capture_output=True, text=True)
    if res.returncode != 0:
        pytest.fail(f"pip could not install the test plugin:\n{res.stderr[-2000:]}")
    assert list(target.glob("iloci_polite_teacher-1.2.3.dist-info/entry_points.txt"))
    env = {"PYTHONPATH": os.pathsep.join([str(target), os.environ.get("PYTHONPATH", "")])}
    return env


def test_iloci_plugins_lists_it(installed):
    res = run_cli("plugins", env=installed)
    assert res.returncode == 0, res.stderr
    rows = [line.split(None, 4) for line in res.stdout.splitlines()[1:]]
    polite = [r for r in rows if r[:2] == ["teacher", "polite"]]
    assert polite and polite[0][2:4] == ["iloci-polite-teacher", "1.2.3"]
    assert polite[0][4] == "available"
    picky = [r for r in rows if r[:2] == ["teacher", "picky"]][0]
    assert "missing iloci_polite_missing_lib" in picky[4]
    assert "pip install iloci-polite-teacher[picky]" in picky[4]


def test_config_naming_it_builds_it(installed, tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text('[teacher]\nname = "polite"\nreward = -1\n')
    code = textwrap.dedent(f"""
        import iloci
        from iloci.errors import MissingBackendError
        from iloci.plugins import get_registry
        from iloci.registry import validate_params
        try:  # the whole agent, when the default back ends are installed
            t = iloci.build({str(cfg)!r}).teacher
        except MissingBackendError:  # bare kernel: build just the teacher
            reg = get_registry()
            params = validate_params(reg.get("teacher", "polite"), {{"reward": -1}})
            t = reg.build("teacher", "polite", params, seed=0)
        print(type(t).__module__, t.reward, t.seed)
    """)
    env = dict(os.environ, **installed)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["iloci_polite.teacher", "-1", "0"]
    res = run_cli("config", "show", str(cfg), env=installed)
    if res.returncode == 0:  # default back ends installed: the resolved config shows it
        assert 'name = "polite"' in res.stdout and "reward = -1" in res.stdout
    else:  # bare kernel: the missing default back end is named, the teacher is fine
        assert "needs iloci-" in res.stderr and "polite" not in res.stderr


def test_missing_library_of_plugin_component_gives_pip_command(installed):
    code = textwrap.dedent("""
        from iloci.plugins import get_registry
        from iloci.errors import MissingBackendError
        try:
            get_registry().build("teacher", "picky")
        except MissingBackendError as exc:
            print(exc)
    """)
    env = dict(os.environ, **installed)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env)
    assert "pip install iloci-polite-teacher[picky]" in out.stdout, out.stderr

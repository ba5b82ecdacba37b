"""Shared fixtures. Tests use real components and small slices of real data."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

try:  # property tests (tests/test_properties.py): few examples in CI, many by hand
    from hypothesis import settings as _hypothesis_settings
except ImportError:  # the bare kernel's environment may lack hypothesis
    pass
else:
    _hypothesis_settings.register_profile("ci", max_examples=60, deadline=None,
                                          print_blob=True, derandomize=True)
    _hypothesis_settings.register_profile("thorough", max_examples=2000, deadline=None)
    _hypothesis_settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


def run_cli(*args: str, env: dict | None = None, input: str | None = None,
            cwd: str | Path | None = None) -> subprocess.CompletedProcess:
    """Run ``python -m iloci ARGS`` in a subprocess; return the completed process."""
    full_env = dict(os.environ)
    full_env.update(env or {})
    return subprocess.run([sys.executable, "-m", "iloci", *args], capture_output=True,
                          text=True, env=full_env, input=input, cwd=cwd, timeout=600)


@pytest.fixture
def cli():
    return run_cli


@pytest.fixture(scope="session", autouse=True)
def _plane_cache(tmp_path_factory):
    """Drawing planes found by the tests are cached apart from the user's (ILOCI_CACHE_DIR)."""
    mp = pytest.MonkeyPatch()
    mp.setenv("ILOCI_CACHE_DIR", str(tmp_path_factory.mktemp("iloci-cache")))
    yield
    mp.undo()

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


#: the module each first-party back end is imported from
_BACK_END_MODULES = {"jax-rnnpb": "iloci_jax", "torch-rnnpb": "iloci_torch",
                     "native-rnnpb": "iloci_native", "pinocchio": "iloci_pinocchio",
                     "scipy": "iloci_scipy", "sklearn": "iloci_sklearn"}


def needs_default_back_ends() -> None:
    """Skip the calling test unless the default config's back ends are installed.

    For tests that build an agent from the default config (no ``--config``), which
    the kernel alone (tox env ``bare``) cannot.
    """
    from iloci.config import DEFAULT_NAMES
    for kind in ("perceptual_model", "ik", "clusterer"):
        name = DEFAULT_NAMES[kind]
        if name in _BACK_END_MODULES:
            pytest.importorskip(_BACK_END_MODULES[name],
                                reason=f"default {kind} {name!r} not installed")


@pytest.fixture
def default_back_ends() -> None:
    """A fixture form of :func:`needs_default_back_ends` (``usefixtures``)."""
    needs_default_back_ends()


@pytest.fixture
def dtaidistance():
    """The DTW baselines' library, or a skip where it is absent (the bare kernel)."""
    return pytest.importorskip("dtaidistance",
                               reason="the DTW baselines need dtaidistance (iloci[report])")


#: Epochs (training, rehearsal, recognition) of the small real agent the step-wise,
#: page, arm and session tests build: enough to tell GShape from Angle, and fast.
SMALL_EPOCHS = 30


def small_config(**sections: dict) -> dict:
    """The small real agent's settings: native-rnnpb, :data:`SMALL_EPOCHS`, seed 0.

    A new dict each call; ``sections`` update its sections (``learner={...}``
    adds to the learner's settings) or add others (``simulator={...}``).
    Tests building it need native-rnnpb and Pinocchio (:func:`small_agent`
    skips without them).
    """
    cfg: dict = {"perceptual_model": {"name": "native-rnnpb", "epochs": SMALL_EPOCHS,
                                      "recognition_steps": SMALL_EPOCHS},
                 "learner": {"rehearsal_epochs": SMALL_EPOCHS}, "evaluation": {"seed": 0}}
    for name, values in sections.items():
        cfg[name] = {**cfg.get(name, {}), **values}
    return cfg


@pytest.fixture(scope="session")
def small_agent():
    """A builder of the small real agent: ``small_agent(**sections)`` -> ``iloci.build(...)``.

    Skips the test without native-rnnpb or Pinocchio.
    """
    pytest.importorskip("iloci_native")
    pytest.importorskip("pinocchio")
    import iloci

    def build(**sections: dict):
        return iloci.build(small_config(**sections))
    return build


@pytest.fixture(scope="module")
def lasa():
    """LASA's GShape and Angle demonstrations by key (``"GShape/0"``...)."""
    from iloci.data import load_lasa
    return {d.key: d for d in load_lasa(["GShape", "Angle"])}


def agent_state(agent) -> tuple[dict, dict, dict]:
    """An agent's memory (arrays, meta, as saved) and network state, to compare exactly."""
    arrays, meta = agent.memory.to_arrays()
    return arrays, meta, agent.perceptual_model.state()


def assert_same_state(s1: tuple, s2: tuple) -> None:
    """Two :func:`agent_state` results are equal bit for bit."""
    import numpy as np
    (a1, m1, n1), (a2, m2, n2) = s1, s2
    assert m1 == m2 and a1.keys() == a2.keys() and n1.keys() == n2.keys()
    for k in a1:
        np.testing.assert_array_equal(a1[k], a2[k])
    for k in n1:
        np.testing.assert_array_equal(n1[k], n2[k])

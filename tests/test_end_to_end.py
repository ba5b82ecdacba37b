"""Short end-to-end runs of the CLI on whatever back ends are installed.

``iloci evaluate`` with ``docs/examples/tiny.toml`` (3 shapes, 2 folds, a
small training budget), then ``iloci teach``, ``recognize`` and, when a
simulator is installed, ``draw``: the commands docs/guide.md shows. Each
tox env of the back-end matrix runs these with its own combination; the
``test`` env, with every back end, pairs them up so each one takes part.
"""

from __future__ import annotations

import json
import os
import tomllib
from pathlib import Path

import pytest
from conftest import ROOT, run_cli

from iloci.config import load_config, to_toml
from iloci.docgen import first_party
from iloci.plugins import get_registry

TINY = ROOT / "docs" / "examples" / "tiny.toml"
SHAPES = ("GShape", "Sine", "Leaf_1")
CONCEPTS = {"GShape", "Sine", "Leaf"}


def _available(kind: str) -> list[str]:
    return [s.name for s in get_registry().specs(kind) if first_party(s) and s.available]


def combinations() -> list[dict[str, str]]:
    """Component names per run: the i-th run takes the i-th installed back end of each kind."""
    pms, cls, iks = (_available(k) for k in ("perceptual_model", "clusterer", "ik"))
    sims = _available("simulator")
    if not (pms and cls and iks):
        return []
    n = max(len(pms), len(cls), len(sims))
    return [{"perceptual_model": pms[i % len(pms)], "clusterer": cls[i % len(cls)],
             "ik": iks[i % len(iks)],
             "simulator": sims[i % len(sims)] if sims else "none"} for i in range(n)]


COMBINATIONS = combinations()
needs_backends = pytest.mark.skipif(not COMBINATIONS,
                                    reason="needs an RNNPB, a clusterer and an IK back end")


def _ids(combo: dict[str, str]) -> str:
    return "-".join(combo.values())


def _report_libraries() -> None:
    """`iloci evaluate` writes figures and runs the DTW baseline: the [report] extra."""
    for module in ("matplotlib", "sklearn", "dtaidistance"):
        try:
            __import__(module)
        except ImportError:
            if os.environ.get("ILOCI_EXPECT_BACKENDS"):  # a tox env meant to run this
                pytest.fail(f"{module} is missing: install iloci[report] in this env")
            pytest.skip(f"needs {module} (pip install iloci[report])")


def _config(tmp_path: Path, combo: dict[str, str]) -> Path:
    data = tomllib.loads(TINY.read_text())
    for section, name in combo.items():
        data.setdefault(section, {})["name"] = name
    path = tmp_path / "tiny.toml"
    path.write_text(to_toml(load_config(data)))
    return path


@needs_backends
@pytest.mark.parametrize("combo", COMBINATIONS, ids=_ids)
def test_tiny_evaluate(tmp_path, combo):
    _report_libraries()
    out = tmp_path / "out"
    res = run_cli("evaluate", "--config", str(_config(tmp_path, combo)), "--out", str(out),
                  "--quiet")
    assert res.returncode == 0, res.stderr[-3000:]
    assert "CCR (mean ± std, %)" in res.stdout
    metrics = json.loads((out / "metrics.json").read_text())
    assert {sec: metrics["config"][sec]["name"] for sec in combo} == combo
    assert len(metrics["ccr_folds"]) == 2 and 0.0 <= metrics["ccr_mean"] <= 1.0
    assert "baseline" in metrics
    folds = json.loads((out / "folds.json").read_text())
    for fold in folds:
        # each fold learns one partition and tests the rest of the 3 x 7 demonstrations
        assert len(fold["learn"]) + len(fold["test"]) == 7 * len(SHAPES)
        assert len(fold["predicted"]) == len(fold["test"])
        assert set(fold["predicted"]) <= CONCEPTS and not fold["skipped"]
    assert sorted(f["fold"] for f in folds) == [0, 1]
    report = (out / "report.md").read_text()
    assert f"perceptual_model = {combo['perceptual_model']}" in report
    for figure in ("confusion", "confidence", "reinforcement", "first_guess"):
        assert (out / "figures" / f"{figure}.png").stat().st_size > 0


@pytest.fixture(scope="module")
def taught(tmp_path_factory):
    """(combo, memory file, teach result): three LASA demonstrations taught with the oracle."""
    combo = COMBINATIONS[-1]
    tmp = tmp_path_factory.mktemp("teach")
    memory = tmp / "memory.npz"
    res = run_cli("teach", "--config", str(_config(tmp, combo)), "--memory", str(memory),
                  "GShape/0", "Sine/0", "GShape/1", cwd=tmp)
    return combo, memory, res


@needs_backends
def test_teach(taught):
    _, memory, res = taught
    assert res.returncode == 0, res.stderr[-3000:]
    assert "learned 3 demonstration(s)" in res.stdout and memory.exists()


@needs_backends
def test_recognize(taught, tmp_path):
    _, memory, _ = taught
    res = run_cli("recognize", "--memory", str(memory), "--json", "GShape/5", "Sine/6",
                  cwd=tmp_path)
    assert res.returncode == 0, res.stderr[-3000:]
    answers = [json.loads(line) for line in res.stdout.splitlines()]
    assert [a["demo"] for a in answers] == ["GShape/5", "Sine/6"]
    assert all(0.0 <= a["confidence"] <= 1.0 for a in answers)


#: Component kinds whose plugins `iloci draw` must do without, but for the memory's
#: own perceptual model (its network regenerates the concept).
NOT_FOR_DRAWING = ("perceptual_model", "clusterer", "teacher")


def _block_all_but(combo: dict[str, str], *keep_sections: str) -> str:
    """ILOCI_BLOCK_PLUGINS value: every plugin of NOT_FOR_DRAWING but those of ``combo``'s
    ``keep_sections`` (and of its IK solver and simulator)."""
    registry = get_registry()
    keep = {registry.get(sec, combo[sec]).plugin
            for sec in (*keep_sections, "ik", "simulator")}
    blocked = {s.plugin for s in registry.specs() if s.kind in NOT_FOR_DRAWING} - keep
    return ",".join(sorted(blocked))


needs_simulator = pytest.mark.skipif(not COMBINATIONS or COMBINATIONS[-1]["simulator"] == "none",
                                     reason="needs a simulator back end")


@needs_backends
@needs_simulator
def test_draw_needs_only_the_memorys_network_ik_and_simulator(taught, tmp_path):
    """`iloci draw` builds the memory's perceptual model, IK solver and the simulator, and
    nothing else: not the clusterer or teacher the memory was taught with, nor any default
    back end (it once resolved the defaults and built a whole agent)."""
    combo, memory, _ = taught
    blocked = _block_all_but(combo, "perceptual_model")
    # every clusterer and teacher is among them: the memory's, and the default ones
    assert {s.plugin for s in get_registry().specs() if s.kind in ("clusterer", "teacher")} \
        <= set(blocked.split(",")), blocked
    image = tmp_path / "gshape.png"
    res = run_cli("draw", "--memory", str(memory), "--concept", "GShape",
                  "--simulator", combo["simulator"], "--out", str(image), cwd=tmp_path,
                  env={"ILOCI_BLOCK_PLUGINS": blocked})
    assert res.returncode == 0, res.stderr[-3000:]
    assert image.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"in {combo['simulator']}" in res.stdout


@needs_backends
@needs_simulator
def test_draw_without_the_memorys_network_names_the_back_end_to_install(taught, tmp_path):
    """Drawing regenerates the concept with the memory's network: without its perceptual
    model the command says which one, why, and why it is missing: here its plugin is
    installed but blocked, which is said as such (not "not installed", not a pip
    command)."""
    combo, memory, _ = taught
    image = tmp_path / "gshape.png"
    res = run_cli("draw", "--memory", str(memory), "--concept", "GShape",
                  "--simulator", combo["simulator"], "--out", str(image), cwd=tmp_path,
                  env={"ILOCI_BLOCK_PLUGINS": _block_all_but(combo)})
    assert res.returncode == 2, res.stderr[-3000:]
    err = res.stderr
    assert f"perceptual model {combo['perceptual_model']!r}" in err
    assert "so drawing needs it" in err and "blocked by ILOCI_BLOCK_PLUGINS" in err
    assert "not installed" not in err
    assert "Traceback" not in err and not image.exists()

"""The whole evaluation pipeline on a small slice of LASA (3 shapes, 2 folds)."""

from __future__ import annotations

import json
import math

import pytest

pytest.importorskip("iloci_torch")
pytest.importorskip("iloci_pinocchio")
pytest.importorskip("iloci_scipy")
pytest.importorskip("matplotlib")

from iloci.cli import main  # noqa: E402
from iloci.errors import InvalidInputError  # noqa: E402
from iloci.evaluation.evaluate import evaluate  # noqa: E402

SMALL = """
[perceptual_model]
name = "torch-rnnpb"
epochs = 150
recognition_steps = 40
[learner]
rehearsal_epochs = 80
[data]
shapes = ["GShape", "Angle", "Sshape"]
[evaluation]
folds = 2
seed = 3
"""


@pytest.fixture(scope="module")
def small_config(tmp_path_factory):
    path = tmp_path_factory.mktemp("cfg") / "small.toml"
    path.write_text(SMALL)
    return path


@pytest.fixture(scope="module")
def run_dir(small_config, tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "lasa"
    code = main(["evaluate", "--config", str(small_config), "--out", str(out), "--jobs", "1",
                 "--quiet"])
    assert code == 0
    return out


def test_every_output_file_exists_and_parses(run_dir):
    from PIL import Image

    metrics = json.loads((run_dir / "metrics.json").read_text())
    for key in ("ccr_mean", "ccr_std", "ccr_folds", "wall_seconds", "interactions_per_demo",
                "exemplars", "prototypes", "concepts", "generation_error", "config", "seed",
                "versions", "baseline"):
        assert key in metrics, key
    assert len(metrics["ccr_folds"]) == 2
    assert all(0.0 <= c <= 1.0 for c in metrics["ccr_folds"])
    assert math.isclose(metrics["ccr_mean"], sum(metrics["ccr_folds"]) / 2)
    assert metrics["versions"]["iloci"]
    assert 0.0 <= metrics["baseline"]["ccr_mean"] <= 1.0
    folds = json.loads((run_dir / "folds.json").read_text())
    assert [f["fold"] for f in folds] == [0, 1]
    for f in folds:
        # every learning demo got at least one interaction; each test demo one answer
        assert len(f["predicted"]) == len(f["true"]) == len(f["test"]) > 0
        assert f["exemplars"] + f["prototypes"] == f["entries"] >= f["concepts"] >= 1
        assert set(f["shapes"]) <= {"GShape", "Angle", "Sshape"}
    report = (run_dir / "report.md").read_text()
    figures = sorted((run_dir / "figures").glob("*.png"))
    names = {p.name for p in figures}
    assert {"confusion.png", "confidence.png", "reinforcement.png", "first_guess.png",
            "pb_space.png", "shapes.png", "baseline_confusion.png"} <= names
    for p in figures:
        assert f"figures/{p.name}" in report, f"{p.name} not linked from report.md"
        with Image.open(p) as im:
            im.verify()
            assert min(im.size) >= 200
    assert "CCR" in report and "DTW" in report


def test_parallel_folds_give_the_same_results_as_serial(small_config, run_dir):
    serial = json.loads((run_dir / "folds.json").read_text())
    _, parallel = evaluate(small_config, jobs=2, baseline=False)
    for a, b in zip(serial, parallel):
        assert a["predicted"] == b["predicted"]
        assert a["feedbacks"] == b["feedbacks"]
        assert a["entries"] == b["entries"]


def test_unknown_fold_is_a_clear_error(small_config):
    with pytest.raises(InvalidInputError, match="fold 7 does not exist"):
        evaluate(small_config, folds=[7])

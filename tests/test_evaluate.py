"""The whole evaluation pipeline on a small slice of LASA (3 shapes, 2 folds)."""

from __future__ import annotations

import json
import math
import sys
import tomllib

import pytest

pytest.importorskip("iloci_native")
pytest.importorskip("iloci_pinocchio")
pytest.importorskip("iloci_scipy")
pytest.importorskip("matplotlib")

from iloci.cli import main  # noqa: E402
from iloci.errors import InvalidInputError, MissingBackendError  # noqa: E402
from iloci.evaluation.evaluate import FoldResult, evaluate  # noqa: E402
from iloci.evaluation.results import FOLD_KEYS  # noqa: E402

SMALL = """
[perceptual_model]
name = "native-rnnpb"
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
                 "--quiet", "--robustness"])
    assert code == 0
    return out


def test_every_output_file_exists_and_parses(run_dir):
    from PIL import Image

    metrics = json.loads((run_dir / "metrics.json").read_text())
    for key in ("ccr_mean", "ccr_std", "ccr_folds", "wall_seconds", "interactions_per_demo",
                "exemplars", "prototypes", "concepts", "generation_error", "config", "seed",
                "versions", "baseline", "ccr_matched", "ccr_source", "purity",
                "named_concepts"):
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
        assert len(f["predicted"]) == len(f["true_concepts"]) == len(f["test"]) > 0
        assert f["entries"] >= f["concepts"] >= 1
        assert tuple(f) == FOLD_KEYS
        assert set(f["shapes"]) <= {"GShape", "Angle", "Sshape"}
        # the robot's own labels are scored; an oracle keeps every robot concept pure
        assert len(f["robot_predicted"]) == len(f["test"])
        assert f["purity"] == 1.0 and f["ccr"] == f["ccr_source"] == f["ccr_matched"]
    report = (run_dir / "report.md").read_text()
    figures = sorted((run_dir / "figures").glob("*.png"))
    names = {p.name for p in figures}
    assert {"confusion.png", "confidence.png", "reinforcement.png", "first_guess.png",
            "pb_space.png", "shapes.png", "baseline_confusion.png", "robustness.png"} <= names
    for p in figures:
        assert f"figures/{p.name}" in report, f"{p.name} not linked from report.md"
        with Image.open(p) as im:
            im.verify()
            assert min(im.size) >= 200
    assert "CCR" in report and "DTW" in report and "purity" in report


def test_robustness_section(run_dir):
    from iloci.evaluation.perturb import SUITE

    metrics = json.loads((run_dir / "metrics.json").read_text())
    folds = json.loads((run_dir / "folds.json").read_text())
    rob = metrics["robustness"]
    assert list(rob) == [p.name for p in SUITE]
    for name, row in rob.items():
        assert len(row["ccr_folds"]) == len(row["baseline"]["ccr_folds"]) == 2
        for f, ccr in zip(folds, row["ccr_folds"]):
            predicted = f["robustness"][name]["predicted"]
            assert len(predicted) == len(f["test"])
            true = f["true_concepts"]
            assert ccr == sum(p == t for p, t in zip(predicted, true)) / len(true)
    # the unperturbed suite entry is the fold's own recognition
    assert rob["clean"]["ccr_folds"] == metrics["ccr_folds"]
    assert rob["clean"]["baseline"]["ccr_folds"] == metrics["baseline"]["ccr_folds"]
    for name, b in metrics["baselines"].items():  # every baseline beside iloci
        assert rob["clean"]["baselines"][name]["ccr_folds"] == b["ccr_folds"]
    # iloci scales every drawing into its plane, so a drawing at 1 % of the size does
    # not change its answers; nor those of DTW on normalised paths (scaled to unit size)
    assert rob["scale_0.01"]["ccr_folds"] == rob["clean"]["ccr_folds"]
    assert rob["scale_0.01"]["baseline"]["ccr_folds"] == rob["clean"]["baseline"]["ccr_folds"]
    report = (run_dir / "report.md").read_text()
    assert "## Robustness" in report and "sampled at 25 points" in report


def test_blocked_order_teaches_concept_by_concept():
    from iloci.config import load_config
    from iloci.data import load_lasa
    from iloci.evaluation.evaluate import fold_plan

    demos = load_lasa()
    shuffled = fold_plan(demos, load_config(None))
    blocked = fold_plan(demos, load_config({"evaluation": {"order": "blocked"}}))
    for (ls, ts), (lb, tb) in zip(shuffled, blocked):
        assert ts == tb and sorted(ls) == sorted(lb) and ls != lb
        concepts = [demos[i].true_concept for i in lb]
        runs = [c for k, c in enumerate(concepts) if k == 0 or c != concepts[k - 1]]
        assert len(runs) == len(set(concepts))  # each concept in one block


def test_parallel_folds_give_the_same_results_as_serial(small_config, run_dir, tmp_path):
    import iloci

    serial = json.loads((run_dir / "folds.json").read_text())
    _, parallel = evaluate(small_config, jobs=2, baseline=False, memory_dir=str(tmp_path))
    for a, b in zip(serial, parallel):
        _same_fold(b, a)
        # each fold's learned robot was kept, and answers as it did in the fold
        agent = iloci.Agent.load(tmp_path / f"fold-{b.fold}.npz")
        assert len(agent.memory) == b.entries


@pytest.mark.parametrize("jobs", [1, 2])
def test_progress_tells_when_a_folds_test_set_is_recognized(small_config, jobs):
    """After a fold's last learning message its test set is recognized (a minute or more
    on a few hundred drawings): a message when that starts and one when each part ends
    (jobs=2: the one fold's recognition split over the 2 workers), printed by the
    command line's progress display; with jobs=1 (in this process) too."""
    import io

    from iloci.display import FoldProgress

    msgs: list[dict] = []
    _, (fold,) = evaluate(small_config, jobs=jobs, folds=[0], baseline=False,
                          progress=msgs.append)
    n, parts = len(fold.answers), jobs
    kinds = [m["kind"] for m in msgs]
    started = [m for m in msgs if m["kind"] == "recognition"]
    ended = [m for m in msgs if m["kind"] == "recognized"]
    assert [(m["part"], m["parts"], m["total"]) for m in sorted(started, key=lambda m: m[
        "part"])] == [(k, parts, n) for k in range(parts)]
    assert sorted(m["part"] for m in ended) == list(range(parts))
    assert sum(m["drawings"] for m in ended) == n and all(m["seconds"] > 0 for m in ended)
    last_learning = max(i for i, k in enumerate(kinds) if k == "interaction")
    assert last_learning < kinds.index("recognition")
    assert max(i for i, k in enumerate(kinds) if k == "recognized") < kinds.index("fold_done")
    log = io.StringIO()
    with FoldProgress(log) as bars:
        for m in msgs:
            bars(m)
    text = log.getvalue()
    if parts == 1:
        assert f"fold 0: recognizing {n} test drawings ...\n" in text
        assert f"fold 0: recognized {n} test drawings in " in text
    else:
        assert text.count(f"fold 0: recognizing {n} test drawings in 2 parts ...\n") == 1
        for k, m in enumerate(sorted(ended, key=lambda m: m["part"])):
            assert f"fold 0: recognized part {k + 1} of 2 ({m['drawings']} drawings) in " \
                in text


def test_untaught_concepts_leave_the_learning_set_for_the_test_set(small_config):
    from iloci.config import load_config
    from iloci.data import load_lasa
    from iloci.evaluation.evaluate import fold_plan, untaught_concepts

    data = tomllib.loads(SMALL)
    data["evaluation"]["untaught"] = 1
    config = load_config(data)
    demos = load_lasa(["GShape", "Angle", "Sshape"])
    plain = fold_plan(demos, load_config(tomllib.loads(SMALL)))
    for k, (learn, test) in enumerate(fold_plan(demos, config)):
        (left_out,) = untaught_concepts(demos, config, k)
        assert all(demos[i].true_concept != left_out for i in learn)
        assert sorted(learn + test) == list(range(len(demos)))
        assert set(test) >= set(plain[k][1])  # the plain test set, plus the left-out ones
    data["evaluation"]["untaught"] = 2
    with pytest.raises(InvalidInputError, match="untaught = 2 leaves fewer than 2"):
        untaught_concepts(demos, load_config(data), 0)


def test_stream_protocol_scores_each_demonstration_before_teaching_it(small_config,
                                                                       tmp_path):
    out = tmp_path / "stream"
    code = main(["evaluate", "--config", str(small_config), "--protocol", "stream",
                 "--out", str(out), "--quiet"])
    assert code == 0
    metrics = json.loads((out / "metrics.json").read_text())
    steps = json.loads((out / "stream.json").read_text())
    assert metrics["protocol"] == "stream" and metrics["demonstrations"] == len(steps) == 21
    # the first demonstration meets an empty memory; a concept's first one cannot be right
    assert steps[0]["predicted"] == "none" and not steps[0]["correct"]
    for s in steps:
        if not s["seen_before"]:
            assert not s["correct"]
        else:
            assert s["correct"] == (s["predicted"] == s["true"])
    assert len(metrics["curve"]) == 21
    assert metrics["feedbacks_per_demo"] == pytest.approx(
        sum(len(s["feedbacks"]) for s in steps) / 21)
    report = (out / "report.md").read_text()
    assert "figures/stream.png" in report and (out / "figures" / "stream.png").is_file()


def test_unknown_fold_is_a_clear_error(small_config):
    with pytest.raises(InvalidInputError, match="fold 7 does not exist"):
        evaluate(small_config, folds=[7])


def test_jobs_default_to_one_per_core_and_are_checked(small_config, monkeypatch):
    import os

    from iloci.config import EvaluationConfig, load_config
    from iloci.errors import ConfigError
    from iloci.evaluation.evaluate import default_jobs
    assert EvaluationConfig().jobs == 0                    # 0: one per CPU core
    if hasattr(os, "sched_getaffinity"):
        assert default_jobs() == len(os.sched_getaffinity(0))
    with pytest.raises(InvalidInputError, match="jobs must be >= 1"):
        evaluate(small_config, jobs=0)                     # an explicit 0 is a mistake
    with pytest.raises(ConfigError, match="jobs"):
        load_config({"evaluation": {"jobs": -1}})
    # one fold asked for: one process, whatever the cores
    monkeypatch.setattr("iloci.evaluation.evaluate.default_jobs", lambda: 8)
    metrics, _ = evaluate(small_config, folds=[0], baseline=False)
    assert metrics["jobs"] == 1


# -- a plugin registered on the caller's own plugin manager (no entry point) ----------

def _own_plugin_manager(factory="iloci.teachers:OracleTeacher", **extra):
    """A program's own plugin on its own plugin manager: a teacher only it knows."""
    from iloci import hookimpl
    from iloci.plugins import get_plugin_manager

    class HouseTeachers:
        @hookimpl
        def iloci_register_teachers(self, registry):
            registry.add("house-oracle", factory, **extra)

    return get_plugin_manager(plugins=[HouseTeachers()])


def _house_config() -> dict:
    data = tomllib.loads(SMALL)
    data["teacher"] = {"name": "house-oracle"}
    return data


def _same_fold(a, b: dict) -> None:
    """``a``, a FoldResult, ran the fold that ``b``, its folds.json entry, records."""
    assert isinstance(a, FoldResult)
    assert a.fold == b["fold"]
    assert a.predicted == b["predicted"]
    assert a.feedbacks == b["feedbacks"]
    assert a.entries == b["entries"]


def test_evaluate_resolves_names_through_the_given_plugin_manager(run_dir):
    serial = json.loads((run_dir / "folds.json").read_text())
    pm = _own_plugin_manager()  # the oracle, under a name only this manager knows
    metrics, results = evaluate(_house_config(), plugin_manager=pm, jobs=1, folds=[0],
                                baseline=False)
    assert metrics["config"]["teacher"]["name"] == "house-oracle"
    _same_fold(results[0], serial[0])  # the oracle under another name: the same fold


def test_evaluate_workers_resolve_names_through_the_given_plugin_manager(run_dir):
    from iloci import hookimpl

    serial = json.loads((run_dir / "folds.json").read_text())
    pm = _own_plugin_manager()
    finished = []

    class Folds:
        @hookimpl
        def iloci_on_fold_finished(self, event):
            finished.append(event.fold)

    pm.register(Folds())
    # jobs=2: the fold runs in a spawned worker process, which cannot import the plugin
    metrics, results = evaluate(_house_config(), plugin_manager=pm, jobs=2, folds=[1],
                                baseline=False)
    assert metrics["jobs"] == 2 and finished == [1]
    _same_fold(results[0], serial[1])


def test_evaluate_workers_cannot_receive_an_unpicklable_component(small_config):
    from iloci.teachers import OracleTeacher

    pm = _own_plugin_manager(lambda: OracleTeacher())
    with pytest.raises(InvalidInputError, match="house-oracle") as exc:
        evaluate(_house_config(), plugin_manager=pm, jobs=2, baseline=False)
    assert "jobs=1" in str(exc.value) and "module:attribute" in str(exc.value)


def test_a_worker_error_reaches_the_caller_as_itself(small_config):
    # resolves (and pickles) in the parent; its import fails in the worker
    pm = _own_plugin_manager("iloci_no_such_module_for_test:Teacher",
                             install="pip install house-teachers")
    with pytest.raises(MissingBackendError, match="pip install house-teachers"):
        evaluate(_house_config(), plugin_manager=pm, jobs=2, folds=[0], baseline=False)


def test_a_motion_cache_shared_between_folds_changes_no_result(small_config):
    from iloci.config import load_config
    from iloci.data import load_lasa
    from iloci.evaluation.evaluate import fold_plan, run_fold
    from iloci.sensorimotor.pipeline import MotionCache

    config = load_config(small_config)
    demos = load_lasa(list(config.data.shapes))
    plan = fold_plan(demos, config)

    def fold(k, cache):
        learn, test = plan[k]
        res = run_fold(config, k, [demos[i] for i in learn], [demos[i] for i in test],
                       baseline=False, motion_cache=cache).to_dict()
        for key in ("wall_seconds", "rehearsal_seconds"):
            res.pop(key)
        return json.dumps(res, sort_keys=True)  # NaN == NaN as text

    cache = MotionCache()
    fold(0, cache)
    converted = cache.misses
    assert converted == len(demos) and cache.hits == 0  # every demonstration met once
    assert fold(1, cache) == fold(1, None)  # the second fold only looks them up
    assert cache.misses == converted and cache.hits == len(demos)


def _timeless(value):
    """``value`` without what a run's clock and machine decide (times, jobs, versions)."""
    if isinstance(value, dict):
        return {k: _timeless(v) for k, v in value.items()
                if not str(k).endswith("seconds") and k not in ("jobs", "versions", "machine")}
    if isinstance(value, list):
        return [_timeless(v) for v in value]
    return value


def test_two_jobs_write_the_same_metrics_and_folds_as_one_bit_for_bit(tmp_path):
    # 3 folds on 2 workers: learning, baselines and recognition are separate tasks
    # there (iloci.evaluation.parallel.run_folds), all in one process here
    cfg = tmp_path / "three.toml"
    cfg.write_text(SMALL.replace("folds = 2", "folds = 3"))
    texts = {}
    for jobs in (1, 2):
        out = tmp_path / f"jobs{jobs}"
        assert main(["evaluate", "--config", str(cfg), "--out", str(out), "--jobs", str(jobs),
                     "--quiet"]) == 0
        texts[jobs] = [json.dumps(_timeless(json.loads((out / name).read_text())),
                                  sort_keys=True, allow_nan=True)
                       for name in ("metrics.json", "folds.json")]
    folds = json.loads(texts[1][1])
    assert len(folds) == 3 and all(f["baselines"] for f in folds)  # the baselines ran
    assert texts[2] == texts[1]


def test_the_last_learnings_recognition_is_split_over_the_free_workers(small_config, tmp_path):
    # one fold, no baselines, 2 workers: when its learning ends nothing else runs,
    # so its test set is recognized in 2 parts, one task each; the answers are the
    # serial run's, in the test set's order, bit for bit
    from iloci.config import load_config
    from iloci.data import load_lasa
    from iloci.evaluation.evaluate import fold_plan
    from iloci.evaluation.executors import LocalExecutor
    from iloci.evaluation.parallel import FoldTask, run_folds

    class Recording(LocalExecutor):
        def run_then(self, tasks, emit, then=None):
            def noted(res):
                more = then(res)
                self.follow_ups += [args for _, args in more]
                return more
            self.follow_ups = []
            return super().run_then(tasks, emit, noted)

    config = load_config(small_config)
    shapes = list(config.data.shapes)
    learn, test = fold_plan(load_lasa(shapes), config)[1]
    runner, got = Recording(2), []
    demos = load_lasa(shapes)
    run_folds(config.to_dict(), [FoldTask(1, learn, test)], demos, runner, baseline=False,
              specs=None, emit=lambda msg: None, on_result=got.append)
    parts = [args[3] for args in runner.follow_ups]  # each part's test demonstrations
    assert len(parts) == 2 and parts[0] + parts[1] == [demos[i] for i in test]
    assert all(parts)
    _, (serial,) = evaluate(small_config, jobs=1, folds=[1], baseline=False)
    (split,) = got
    assert json.dumps(_timeless(split.to_dict()), sort_keys=True) == \
        json.dumps(_timeless(serial.to_dict()), sort_keys=True)


@pytest.mark.usefixtures("default_back_ends")
def test_a_run_on_your_own_data_never_writes_over_lasas_report(tmp_path, cli):
    """Without --out, `iloci evaluate --data` writes runs/<the data set's name>, not
    runs/lasa (a fresh user's trial: it overwrote the LASA results), and the start line
    says why one job runs for one fold."""
    from test_own_data import TINY, _shapes

    root = _shapes(tmp_path / "lab shapes", per=4)
    (tmp_path / "tiny.toml").write_text(TINY)
    (tmp_path / "runs" / "lasa").mkdir(parents=True)
    (tmp_path / "runs" / "lasa" / "metrics.json").write_text("{}")
    done = cli("evaluate", "--data", str(root), "--config", "tiny.toml", "--folds", "0",
               "--no-baseline", "--quiet", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "jobs 1 (one per fold: 1 fold(s) to run" in done.stderr
    assert json.loads((tmp_path / "runs" / "lab_shapes" / "metrics.json").read_text())[
        "dataset"]["samples"] == 8
    assert (tmp_path / "runs" / "lasa" / "metrics.json").read_text() == "{}"
    assert "wrote runs/lab_shapes/metrics.json" in done.stdout
    # one fold of the config's 2: the report says which, and shows no spread of one value
    report = (tmp_path / "runs" / "lab_shapes" / "report.md").read_text()
    assert "Fold 0 of a 2-fold evaluation (`--folds`: the others were not run) on " in report
    assert "(one fold)" in report and "± 0.00" not in report


@pytest.mark.skipif(sys.platform != "linux",
                    reason="RLIMIT_FSIZE in a child process: Linux")
def test_a_full_disk_at_the_report_says_so_after_the_results(small_config, tmp_path):
    """A disk that fills while the report is written (here the file size limit, as
    `ulimit -f` sets it) gave "failed: OSError: [Errno 27] File too large" after the whole
    evaluation, and the results were lost. Now the results are printed first, then one
    error naming the file and saying what is complete; no cut file is left behind."""
    import resource
    import subprocess

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (2048, 2048))

    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "iloci", "evaluate", "--config",
                           str(small_config), "--out", str(out), "--jobs", "1", "--quiet",
                           "--no-baseline"], capture_output=True, text=True, timeout=600,
                          preexec_fn=limit)
    assert done.returncode == 1, done.stderr
    assert "interactions per learning demo" in done.stdout      # the results, printed
    error = done.stderr.strip().splitlines()[-1]
    assert error.startswith(f"error: could not write {out / 'metrics.json'}: the disk is "
                            "full (or the file size limit is reached)"), error
    assert "nothing is there" in error and "run the command again" in error
    assert "Traceback" not in done.stderr and "failed:" not in done.stderr
    assert not [p for p in out.rglob("*") if p.is_file()]      # no cut file, no temporary


@pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_FSIZE in a child process: Linux")
def test_any_command_that_meets_a_full_disk_names_the_file_in_one_error(tmp_path):
    """The CLI's last resort: an OSError the machine raised (no space, a file size limit,
    a read-only disk) is one error naming the file and what to do, not "failed: ..."."""
    import resource
    import subprocess

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))

    image = tmp_path / "g.png"
    done = subprocess.run([sys.executable, "-m", "iloci", "show", "GShape/0", "--out",
                           str(image)], capture_output=True, text=True, timeout=600,
                          preexec_fn=limit)
    assert done.returncode == 1
    assert done.stderr.strip() == (
        f"error: could not write {image}: the disk is full (or the file size limit is "
        "reached) (File too large). Free some space (or write elsewhere) and run the "
        "command again.")
    assert not list(tmp_path.iterdir())

"""The iloci-ray plugin: sweep specs, run keys, a resumable sweep and folds on real Ray."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("iloci_ray")
pytest.importorskip("ray")

from iloci.errors import ConfigError, UnknownComponentError  # noqa: E402
from iloci_ray.sweep import load_spec, plan_runs, run_key, run_sweep, settings  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / "docs/examples/tiny.toml"

# two shapes, 60 epochs: a run takes seconds (its CCR says nothing)
SMALL = f'''
base = "{TINY}"
seeds = [0]
folds = [0]
[config]
perceptual_model = {{ epochs = 60 }}
learner = {{ rehearsal_epochs = 60 }}
data = {{ shapes = ["GShape", "Sine"] }}
'''


def write(tmp_path: Path, text: str, name: str = "spec.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("top, values, match", [
    ("", "", r"\[values\] must name"),
    ("", '"learner.k_cutoff" = []', "empty list"),
    ("", '"k_cutoff" = [1.0]', "'section.key'"),
    ("", '"learner.k_cutoff" = { low = 0.1, high = 1.0 }', "ranges need search"),
    ('search = "random"', '"learner.k_cutoff" = [1.0]', "samples = N"),
    ('search = "random"\nsamples = 2', '"learner.k_cutoff" = { low = 1.0, high = 0.1 }',
     "low < high"),
    ('search = "annealing"', '"learner.k_cutoff" = [1.0]', "'grid' or 'random'"),
    ("epochs = 3", '"learner.k_cutoff" = [1.0]', "unknown key"),
    ("", '"learner.k_cutoff" = [-1.0]', "k_cutoff must be >= 0"),
    ("", '"learner.no_such_key" = [1]', "no_such_key"),
    ("", '"learner.k_cutoff" = ["a"]', r"setting \{'learner.k_cutoff': 'a'\}: learner.k_cutoff "
     "must be a number"),
    ("", '"learner.k_cutoff" = [nan]', "must be a finite number"),
    ("", '"learner.k_cutoff" = [[0.1, 0.2]]', "must be a number, got \\[0.1, 0.2\\]"),
    ("", '"learner.k_cutoff" = 0.5', "give a list of values"),
    # an audit: the swept values silently replaced the fixed one; a value listed twice ran
    # (and was reported) twice
    ("", '"perceptual_model.epochs" = [60, 80]', r"perceptual_model.epochs is both fixed in "
     r"\[config\] and swept in \[values\]"),
    ("", '"learner.k_cutoff" = [0.5, 1.0, 0.5]', "learner.k_cutoff lists 0.5 more than once"),
    ("", f'"learner.k_cutoff" = {list(range(50))}\n"learner.num_threshold" = '
         f'{list(range(1, 51))}', "2,500 settings .50 x 50. x 1 seed.s.; a sweep spec names "
                                 "at most 2,000"),
])
def test_a_bad_spec_is_one_config_error_naming_what_is_wrong(tmp_path, top, values, match):
    text = top + "\n" + SMALL + ("[values]\n" + values + "\n" if values else "")
    with pytest.raises(ConfigError, match=match):
        load_spec(write(tmp_path, text))


def test_a_data_set_that_does_not_exist_is_said_before_ray_starts(tmp_path):
    """An audit: it started Ray, recorded every run as failed, and exited 1."""
    spec = write(tmp_path, 'seeds = [0]\nfolds = [0]\n[config]\nperceptual_model = '
                           '{ epochs = 60 }\n[values]\n"data.path" = ["no-such-folder"]\n')
    with pytest.raises(ConfigError, match=r"\[data\] path 'no-such-folder' does not exist"):
        load_spec(spec)


def test_bad_spec_on_the_command_line_exits_2_without_traceback(tmp_path, cli):
    r = cli("sweep", str(write(tmp_path, "not = [toml")), "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and "malformed TOML" in r.stderr and "Traceback" not in r.stderr
    r = cli("sweep", str(tmp_path / "missing.toml"))
    assert r.returncode == 2 and "sweep spec file not found" in r.stderr


def test_grid_is_settings_x_seeds_x_folds_with_stable_distinct_keys(tmp_path):
    spec = load_spec(write(tmp_path, SMALL.replace("seeds = [0]", "seeds = [0, 3]")
                           .replace("folds = [0]", "") + '[values]\n"learner.k_cutoff" = '
                           '[0.25, 0.5]\n"learner.num_threshold" = [2, 3, 4]\n'))
    runs = plan_runs(spec)
    assert len(runs) == 2 * 3 * 2 * 2  # settings x seeds x the config's 2 folds
    assert len({r.key for r in runs}) == len(runs)
    assert [r.key for r in plan_runs(spec)] == [r.key for r in runs]
    r = runs[0]
    assert r.config["learner"]["k_cutoff"] == 0.25 and r.config["evaluation"]["seed"] == 0
    # the key is of the resolved config: any value that changes the run changes it
    changed = json.loads(json.dumps(r.config))
    changed["perceptual_model"]["epochs"] += 1
    assert run_key(changed, r.fold, r.seed) != r.key
    assert run_key(r.config, r.fold + 1, r.seed) != r.key


def test_random_search_is_seeded_and_stays_in_range(tmp_path):
    body = ('search = "random"\nsamples = 6\nrandom_seed = 4\n' + SMALL +
            '[values]\n"learner.k_cutoff" = { low = 0.1, high = 2.0, log = true }\n'
            '"learner.num_threshold" = { low = 2, high = 5, integer = true }\n')
    a = settings(load_spec(write(tmp_path, body)))
    b = settings(load_spec(write(tmp_path, body, "again.toml")))
    assert a == b and len(a) == 6
    assert all(0.1 <= s["learner.k_cutoff"] <= 2.0 for s in a)
    assert all(isinstance(s["learner.num_threshold"], int) and 2 <= s["learner.num_threshold"]
               <= 5 for s in a)
    other = settings(load_spec(write(tmp_path, body.replace("random_seed = 4",
                                                            "random_seed = 5"), "c.toml")))
    assert other != a


@pytest.fixture(scope="module")
def ray_local():
    import ray

    from iloci_ray.executor import connect
    connect(None, 2)
    yield ray
    ray.shutdown()


@pytest.mark.slow
def test_sweep_stores_each_run_and_resumes_without_recomputing(tmp_path, ray_local):
    from iloci_ray.report import write_report

    spec = load_spec(write(tmp_path, SMALL + '[values]\n"learner.k_cutoff" = [0.5, 1.0]\n'))
    out = tmp_path / "out"
    events = []
    records, info = run_sweep(spec, out, jobs=2, on_event=lambda k, r, m: events.append(k))
    assert info["computed"] == 2 and info["reused"] == 0
    assert sorted(p.stem for p in (out / "runs").glob("*.json")) == sorted(
        r["key"] for r in records)
    assert all(0.0 <= r["ccr"] <= 1.0 and r["feedbacks"] >= 1 for r in records)
    # started again: nothing recomputed, the same records
    again, info2 = run_sweep(spec, out, jobs=2)
    assert info2["computed"] == 0 and info2["reused"] == 2 and again == records
    # a run lost (or never finished) is the only one computed; the result is the same
    (out / "runs" / f"{records[1]['key']}.json").unlink()
    third, info3 = run_sweep(spec, out, jobs=2)
    assert info3["computed"] == 1 and info3["reused"] == 1
    assert [r["ccr"] for r in third] == [r["ccr"] for r in records]
    assert [r["feedbacks"] for r in third] == [r["feedbacks"] for r in records]
    report = write_report(out, spec, third, info3)
    text = report.read_text()
    assert "Best setting" in text and "figures/learner-k_cutoff.png" in text
    # the baselines ran on each run's fold (same for both settings: same folds)
    assert [r["baselines"] for r in third] == [records[0]["baselines"]] * 2
    assert set(records[0]["baselines"]) == {"dtw_normalised", "dollar1", "dtw_raw"}
    assert "Baselines on the same folds" in text and "the best baseline" in text
    assert (out / "figures/learner-k_cutoff.png").stat().st_size > 1000
    with open(out / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["learner.k_cutoff"]) for r in rows] == [0.5, 1.0]


@pytest.mark.slow
def test_evaluate_on_ray_gives_the_local_results(ray_local):
    from iloci.config import load_config
    from iloci.evaluation.evaluate import evaluate

    cfg = load_config(TINY).replace(perceptual_model={"epochs": 60},
                                    learner={"rehearsal_epochs": 60},
                                    data={"shapes": ["GShape", "Sine"]})
    seen = []
    m_ray, r_ray = evaluate(cfg, jobs=2, executor="ray", baseline=False, progress=seen.append)
    m_loc, r_loc = evaluate(cfg, jobs=1, baseline=False)
    assert m_ray["ccr_folds"] == m_loc["ccr_folds"]
    assert [r.predicted for r in r_ray] == [r.predicted for r in r_loc]
    assert [r.feedbacks for r in r_ray] == [r.feedbacks for r in r_loc]
    kinds = {m["kind"] for m in seen}
    assert {"fold_queued", "fold_start", "interaction", "recognition", "recognized",
            "fold_done"} <= kinds


def test_an_iloci_error_in_a_ray_task_reaches_the_caller_as_itself(ray_local):
    from iloci.config import load_config
    from iloci.data import load_lasa
    from iloci.evaluation.parallel import FoldTask, _run_fold_in_worker
    from iloci_ray.executor import RayExecutor

    # a fold whose config names a model the worker does not know: the worker raises
    config = load_config(TINY).to_dict()
    config["perceptual_model"] = {"name": "no-such-model"}
    learn, test = load_lasa("GShape")[:1], load_lasa("GShape")[1:2]
    call = (config, FoldTask(0, [0], [1]), learn, test, False, None)
    with pytest.raises(UnknownComponentError, match="unknown perceptual model 'no-such-model'"):
        list(RayExecutor(1).run(_run_fold_in_worker, [call], lambda m: None))


def test_no_cluster_at_the_address_is_a_clear_error(tmp_path, cli):
    spec = write(tmp_path, SMALL + '[values]\n"learner.k_cutoff" = [0.5]\n')
    r = cli("sweep", str(spec), "--address", "127.0.0.1:1", "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and "no Ray cluster at '127.0.0.1:1'" in r.stderr


def test_a_swept_component_name_keeps_what_the_base_wrote_and_takes_its_defaults(tmp_path):
    pytest.importorskip("iloci_sklearn")
    spec = load_spec(write(tmp_path, SMALL + '[values]\n"clusterer.name" = ["scipy", '
                           '"sklearn"]\n'))
    runs = plan_runs(spec)
    assert [r.config["clusterer"]["name"] for r in runs] == ["scipy", "sklearn"]
    assert all(r.config["perceptual_model"]["epochs"] == 60 for r in runs)
    assert runs[0].key != runs[1].key


# -- faults of the world (issue 29): a worker killed, the driver killed, a BOM base ------

def _session(sid: int) -> list[str]:
    """Live processes of session ``sid`` (pid and command line), zombies left out."""
    out = []
    for d in Path("/proc").glob("[0-9]*"):
        try:
            stat = (d / "stat").read_text().rpartition(")")[2].split()
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if int(stat[3]) == sid and stat[0] not in "ZX":
            out.append(f"{d.name} {cmd[:100]}")
    return out


def _sweep(tmp_path: Path, values: str) -> Any:
    import os
    import subprocess
    import sys

    spec = write(tmp_path, SMALL.replace("folds = [0]\n", "") + f"[values]\n{values}\n")
    iloci = Path(sys.executable).with_name("iloci")
    return subprocess.Popen(["setsid", str(iloci), "sweep", str(spec), "--out",
                             str(tmp_path / "out"), "--jobs", "2", "-q"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ})


def _first_worker(sid: int, timeout: float = 300) -> int:
    import time

    t = time.monotonic()
    while time.monotonic() - t < timeout:
        for line in _session(sid):
            pid, cmd = line.split(" ", 1)
            if cmd.startswith("ray::fold_run"):
                return int(pid)
        time.sleep(0.3)
    raise AssertionError("no ray::fold_run worker appeared")


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads /proc")
def test_a_killed_worker_is_retried_and_the_sweep_leaves_no_ray_process(tmp_path):
    import os
    import signal
    import time

    d = _sweep(tmp_path, '"learner.k_cutoff" = [1.0]')  # 2 runs: fold 0 and fold 1
    time.sleep(1)
    os.kill(_first_worker(d.pid), signal.SIGKILL)  # what the OOM killer does
    log = d.communicate(timeout=900)[0]
    assert d.returncode == 0, log
    assert len(list((tmp_path / "out" / "runs").glob("*.json"))) == 2
    assert "2 runs: 2 stored (2 computed now, 1 of them after a retry" in log
    assert "WorkerCrashedError" not in log.split("2 runs:")[1]
    time.sleep(1)
    assert _session(d.pid) == []


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads /proc")
def test_a_killed_raylet_is_restarted_and_every_run_is_stored(tmp_path):
    import os
    import signal
    import time

    # 4 runs, 2 at once: the last 2 need the raylet after it was killed
    d = _sweep(tmp_path, '"learner.k_cutoff" = [0.5, 1.0]')
    _first_worker(d.pid)
    raylet = next(int(line.split(" ", 1)[0]) for line in _session(d.pid)
                  if "/raylet/raylet " in line)
    os.kill(raylet, signal.SIGKILL)  # the node's manager gone: no run is to blame
    log = d.communicate(timeout=900)[0]
    assert d.returncode == 0, log
    assert len(list((tmp_path / "out" / "runs").glob("*.json"))) == 4
    summary = log.split("4 runs:")[1]
    assert summary.startswith(" 4 stored") and "0 failed" in summary
    time.sleep(1)
    assert _session(d.pid) == []


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads /proc")
def test_ray_left_by_a_driver_killed_with_sigkill_is_stopped_by_the_next_start(tmp_path):
    import os
    import signal
    import time

    from iloci_ray.lifecycle import marker_dir, reap_orphans

    d = _sweep(tmp_path, '"learner.k_cutoff" = [1.0]')
    _first_worker(d.pid)
    assert (marker_dir() / f"{d.pid}.json").is_file()
    os.kill(d.pid, signal.SIGKILL)
    d.wait()
    time.sleep(3)
    left = _session(d.pid)
    try:
        assert reap_orphans() >= len(left)  # what the next `iloci sweep` does first
        time.sleep(1)
        assert _session(d.pid) == []
        assert not (marker_dir() / f"{d.pid}.json").exists()
    finally:
        for line in _session(d.pid):
            os.kill(int(line.split()[0]), signal.SIGKILL)


def test_a_failed_run_is_reported_with_how_to_resume(tmp_path):
    from iloci_ray.sweep import summary_lines

    info = {"runs": 4, "computed": 2, "retried": 1, "reused": 1, "retries": 2, "failed": [
        {"key": "abc", "setting": {"learner.k_cutoff": 0.5}, "seed": 0, "fold": 1,
         "error": "WorkerCrashedError: its Ray worker process died", "attempts": 3}]}
    text = "\n".join(summary_lines(info, [{}, {}, {}], "iloci sweep s.toml"))
    assert "4 runs: 3 stored (2 computed now, 1 of them after a retry; 1 stored before), " \
        "1 failed." in text
    assert "abc" in text and "WorkerCrashedError" in text and "{'learner.k_cutoff': 0.5}" in text
    assert "Run the same command again to resume (iloci sweep s.toml)" in text


def test_a_base_config_with_a_byte_order_mark_passes_check_and_sweep(tmp_path, capsys):
    from iloci.cli import main

    base = tmp_path / "bom.toml"
    base.write_bytes(b"\xef\xbb\xbf[learner]\nk_cutoff = 0.5\n")
    assert main(["config", "check", str(base)]) == 0
    spec = load_spec(write(tmp_path, f'base = "{base.name}"\n[values]\n'
                                     '"learner.num_threshold" = [3]\n'))
    assert spec.base["learner"]["k_cutoff"] == 0.5
    assert plan_runs(spec)[0].config["learner"]["k_cutoff"] == 0.5


@pytest.mark.parametrize("encoded, match", [
    ("\ufeff[learner]\r\nk_cutoff = 0.5\r\n".encode(), None),   # BOM and CRLF: read
    ("# caf\xe9\n[learner]\nk_cutoff = 0.5\n".encode("latin-1"),
     "not UTF-8 text .*iconv -f cp1252"),
    (b"[learner]\rk_cutoff = 0.5\r", "carriage return only"),
], ids=["bom-crlf", "latin-1", "cr"])
def test_a_base_config_in_another_encoding_reads_as_config_check_reads_it(
        tmp_path, capsys, encoded, match):
    from iloci.cli import main

    base = tmp_path / "base.toml"
    base.write_bytes(encoded)
    spec = write(tmp_path, 'base = "base.toml"\n[values]\n"learner.num_threshold" = [3]\n')
    if match is None:
        assert main(["config", "check", str(base)]) == 0
        assert plan_runs(load_spec(spec))[0].config["learner"]["k_cutoff"] == 0.5
        return
    assert main(["config", "check", str(base)]) == 2
    assert re.search(match, capsys.readouterr().err)
    with pytest.raises(ConfigError, match=match):
        load_spec(spec)


def test_ray_that_does_not_import_is_named_with_how_to_install(tmp_path, monkeypatch):
    import sys

    from iloci.errors import MissingBackendError
    from iloci_ray.lifecycle import import_ray

    monkeypatch.setitem(sys.modules, "ray", None)  # what `import ray` meets without Ray
    with pytest.raises(MissingBackendError, match=r"command 'iloci sweep' needs ray "
                       r"\(ModuleNotFoundError.*pip install 'ray>=2.9'"):
        import_ray()
    spec = load_spec(write(tmp_path, SMALL + '[values]\n"learner.k_cutoff" = [1.0]\n'))
    with pytest.raises(MissingBackendError, match="iloci sweep' needs ray"):
        run_sweep(spec, tmp_path / "out")


@pytest.mark.slow
@pytest.mark.skipif(__import__("sys").getfilesystemencoding() != "utf-8",
                    reason="a UTF-8 file system encoding")
def test_a_sweep_whose_file_names_are_not_utf8_runs_and_reports(tmp_path):
    import os
    import subprocess
    import sys

    spec = write(tmp_path, SMALL + '[values]\n"learner.k_cutoff" = [1.0]\n',
                 name=os.fsdecode(b"sp\xe9.toml"))
    out = tmp_path / os.fsdecode(b"o\xe9")
    # bytes, not text: the names' own bytes may be echoed (Ray's log lines)
    r = subprocess.run([sys.executable, "-m", "iloci", "sweep", str(spec), "--out", str(out),
                        "-q"], capture_output=True, timeout=600)
    assert r.returncode == 0, r.stderr.decode(errors="replace")
    assert len(list((out / "runs").glob("*.json"))) == 1
    assert (out / "report.md").read_bytes().startswith(b"# Sweep: ")
    assert b"sp\\xe9.toml" in (out / "report.md").read_bytes()


def test_an_out_folder_with_another_specs_report_is_pointed_out(tmp_path):
    """An audit: a second spec's sweep replaced the first one's report.md, results.csv and
    summary.json in the same --out without a word (its stored runs were kept)."""
    from iloci_ray.sweep import other_spec

    assert other_spec(tmp_path, str(tmp_path / "a.toml")) is None          # no report yet
    (tmp_path / "summary.json").write_text(json.dumps({"spec": str(tmp_path / "a.toml")}))
    assert other_spec(tmp_path, str(tmp_path / "a.toml")) is None          # this spec's
    assert other_spec(tmp_path, str(tmp_path / "b.toml")) == str(tmp_path / "a.toml")

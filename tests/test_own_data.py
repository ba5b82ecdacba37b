"""A user's own data set: the baselines, the UNIPEN reader, data set folders and
manifests with their errors, and the oracle on data that is not LASA."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from iloci.data import load_lasa
from iloci.data.datasets import check_protocol, load_dataset, writer_folds
from iloci.data.unipen import read_unipen, unipen_digits, unipen_letters
from iloci.errors import InvalidInputError
from iloci.interfaces import Demonstration

UNIPEN = Path(__file__).parent / "data" / "unipen" / "train_r01_v07"


def _circle(i: int, n: int = 60, r: float = 1.0, centre=(0.0, 0.0)) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi * (0.9 + 0.02 * i), n)
    return np.column_stack([centre[0] + r * np.cos(t), centre[1] + r * np.sin(t)])


def _line(i: int, n: int = 60, length: float = 2.0) -> np.ndarray:
    s = np.linspace(0, length, n)
    return np.column_stack([s, (0.3 + 0.05 * i) * s + 0.02 * np.sin(3 * s)])


# ---------------------------------------------------------------- baselines

@pytest.mark.usefixtures("dtaidistance")
def test_normalised_dtw_does_not_care_where_or_how_large_a_shape_is_drawn():
    from iloci.evaluation.baselines import dtw_normalised_1nn, dtw_raw_1nn

    learn = [Demonstration(_circle(0), shape="circle", true_concept="circle"),
             Demonstration(_line(0) + [10, 10], shape="line", true_concept="line")]
    # a small circle drawn in the middle of where the line was drawn
    far = Demonstration(_circle(1, r=0.1, centre=(11.0, 10.3)), shape="q")
    assert dtw_normalised_1nn(learn, [far]) == ["circle"]
    assert dtw_raw_1nn(learn, [far]) == ["line"]  # why the raw one is kept only by name


def test_dollar1_is_rotation_invariant_and_names_the_nearest_template():
    from iloci.evaluation.baselines import (_dollar1_distances, dollar1_1nn,
                                            dollar1_template)

    c = _circle(0)
    th = np.radians(30)
    rot = c @ np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]])
    a, b = dollar1_template(c), dollar1_template(rot * 3 + 5)
    assert _dollar1_distances(b, a[None])[0] < 1.0  # of a 250-unit square
    learn = [Demonstration(_circle(0), shape="circle", true_concept="circle"),
             Demonstration(_line(0), shape="line", true_concept="line")]
    test = [Demonstration(rot, shape="q"), Demonstration(_line(2) * 4, shape="q", index=1)]
    assert dollar1_1nn(learn, test) == ["circle", "line"]


def test_dollar1_golden_section_matches_the_papers_scalar_search():
    """The vectorised search is the paper's DISTANCE-AT-BEST-ANGLE, template by template."""
    from iloci.evaluation import baselines as bl

    rng = np.random.default_rng(0)
    cand = bl.dollar1_template(np.cumsum(rng.normal(size=(40, 2)), axis=0))
    temps = np.stack([bl.dollar1_template(np.cumsum(rng.normal(size=(40, 2)), axis=0))
                      for _ in range(5)])

    def scalar(t):
        d = lambda th: bl._path_distance(cand, t[None], np.array([th]))[0]  # noqa: E731
        a, b, phi = -bl.DOLLAR1_ANGLE, bl.DOLLAR1_ANGLE, bl._PHI
        x1, x2 = phi * a + (1 - phi) * b, (1 - phi) * a + phi * b
        f1, f2 = d(x1), d(x2)
        while abs(b - a) > bl.DOLLAR1_THRESHOLD:
            if f1 < f2:
                b, x2, f2 = x2, x1, f1
                x1 = phi * a + (1 - phi) * b
                f1 = d(x1)
            else:
                a, x1, f1 = x1, x2, f2
                x2 = (1 - phi) * a + phi * b
                f2 = d(x2)
        return min(f1, f2)

    np.testing.assert_allclose(bl._dollar1_distances(cand, temps),
                               [scalar(t) for t in temps], rtol=1e-12)


@pytest.mark.usefixtures("dtaidistance")
def test_baselines_run_side_by_side_on_one_fold_of_lasa():
    from iloci.evaluation.baselines import BASELINE_NAMES, best_baseline, run_baselines

    demos = load_lasa(["GShape", "Angle", "Sine"])
    learn = [d for d in demos if d.index < 2]
    test = [d for d in demos if d.index >= 2]
    out = run_baselines(learn, test)
    assert list(out) == list(BASELINE_NAMES)
    for row in out.values():
        assert len(row["predicted"]) == len(test) and 0 <= row["ccr"] <= 100
    name, ccr = best_baseline({k: v["ccr"] for k, v in out.items()})
    assert ccr == max(v["ccr"] for v in out.values()) and name in out
    with pytest.raises(InvalidInputError, match="true_concept"):
        run_baselines([Demonstration(_line(0))], test)
    with pytest.raises(InvalidInputError, match="unknown baseline"):
        run_baselines(learn, test, ["nearest"])


# ---------------------------------------------------------------- UNIPEN

def test_unipen_reader_finds_labelled_single_stroke_digits_of_each_writer():
    digits = unipen_digits(UNIPEN)
    assert {s.label for s in digits} <= set("0123456789")
    assert len({s.label for s in digits}) >= 8
    assert {s.writer for s in digits} == {"aga/amywldrp", "aga/crlmtchl", "aga/greghunt"}
    assert all(s.single_stroke for s in digits)
    every = read_unipen(UNIPEN, "1a", labels="0123456789", single_stroke=False)
    assert len(every) > len(digits) and any(not s.single_stroke for s in every)
    # the file's first segment: component 73 of amywldrp, a "1" (a near-vertical stroke,
    # drawn downwards: the tablet's y is up), in mm (856.7 points per inch)
    one = next(s for s in digits if s.writer == "aga/amywldrp" and s.label == "1")
    p = one.strokes[0]
    assert len(p) == 20 and np.ptp(p[:, 1]) > 3 * np.ptp(p[:, 0]) and p[-1, 1] < p[0, 1]
    assert 2 < np.ptp(p[:, 1]) < 30
    d = one.demonstration(4)
    assert d.key == "1/4" and d.true_concept == "1" and d.times[1] == pytest.approx(0.01)


def test_unipen_drawing_stored_twice_is_read_once_keeping_the_first(tmp_path):
    """train_r01_v07 stores some digits twice: a segment listed twice in one file, and a
    file repeated under another writer id (IBM's r02-04 repeats r01-04). Rebuilt here from
    the slice's real strokes: ``aga/greghunt``'s file listed again under the writer id
    ``zzcopy`` (sorted after it), and its first segment listed twice."""
    import shutil

    from iloci.data.unipen import balanced_subset

    root = tmp_path / "train_r01_v07"
    shutil.copytree(UNIPEN, root)
    inc = root / "include" / "aga" / "data"
    (inc / "zzcopy.dat").write_text((inc / "greghunt.dat").read_text(encoding="latin-1")
                                    .replace(".WRITER_ID  greghunt", ".WRITER_ID  zzcopy"),
                                    encoding="latin-1")
    data = root / "data" / "1a" / "aga"
    lines = (data / "greghunt.dat").read_text(encoding="latin-1").splitlines()
    (data / "zzcopy.dat").write_text("\n".join(lines).replace("aga/data/greghunt.dat",
                                                              "aga/data/zzcopy.dat") + "\n",
                                     encoding="latin-1")
    first = next(i for i, line in enumerate(lines) if line.startswith(".SEGMENT"))
    (data / "greghunt.dat").write_text("\n".join(lines + [lines[first]]) + "\n",
                                       encoding="latin-1")

    original = unipen_digits(UNIPEN)
    every = unipen_digits(root, drop_copies=False)
    greg = [s for s in original if s.writer == "aga/greghunt"]
    assert len(every) == len(original) + len(greg) + 1           # the copies are there
    digits = unipen_digits(root)                                   # the default drops them
    assert [(s.label, s.writer, s.path) for s in digits] == [
        (s.label, s.writer, s.path) for s in original]           # first copy kept, in order
    keys = {np.concatenate(s.strokes).tobytes() for s in digits}
    assert len(keys) == len(digits)
    # the writer rule still holds: zzcopy drew nothing of its own, so it is not picked
    chosen = balanced_subset(digits, per=1, seed=0, labels="1")
    assert "aga/zzcopy" not in {s.writer for s in chosen}
    assert "aga/zzcopy" in {s.writer for s in balanced_subset(every, per=1, seed=0,
                                                                 labels="1")}


def test_unipen_ibm_session_ids_of_one_person_are_one_writer():
    """IBM's ibm0 set names its files' writers ``rNN-WW``: 12 writers (its ibm0.doc), three
    sessions each, and session files of one ``WW`` share recorded ink. Real strokes: the
    slice's r01-04 and r02-04 (one person, sharing drawings) and r01-12 (another)."""
    from iloci.data.unipen import balanced_subset, person

    root = UNIPEN.parent / "ibm" / "train_r01_v07"
    every = unipen_digits(root, drop_copies=False)
    assert {s.writer_id for s in every} == {"ibm/r01-04", "ibm/r02-04", "ibm/r01-12"}
    by_id = {s.writer_id: s.writer for s in every}
    assert by_id["ibm/r01-04"] == by_id["ibm/r02-04"] == "ibm/writer-04"
    assert by_id["ibm/r01-12"] == "ibm/writer-12"
    assert person("aga", "greghunt") == "aga/greghunt"
    assert person("ibm", "kem11") == "ibm/kem11"   # ibm1's ids are not session ids
    # the two sessions share real drawings: the copies are dropped, both writer ids stay
    digits = unipen_digits(root)
    assert len(digits) < len(every)
    assert {s.writer_id for s in digits} == {"ibm/r01-04", "ibm/r02-04", "ibm/r01-12"}
    # a person is picked once, from all their sessions' drawings (so writer-disjoint
    # folds, which deal writers, never teach a person and test them under another id)
    eights = balanced_subset(digits, per=2, seed=0, labels="8")  # one 8 in each session
    assert [s.writer for s in eights] == ["ibm/writer-04"] * 2
    assert {s.writer_id for s in eights} == {"ibm/r01-04", "ibm/r02-04"}


def test_unipen_letters_and_clear_errors():
    letters = unipen_letters(UNIPEN)
    assert letters and {s.label for s in letters} <= set("acelos")
    with pytest.raises(InvalidInputError, match="git clone"):
        unipen_digits(UNIPEN / "data")
    with pytest.raises(InvalidInputError, match="category '2'"):
        read_unipen(UNIPEN, "2")


# ---------------------------------------------------------------- data sets

def _write(path: Path, xy: np.ndarray, header: str = "x,y") -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(path, xy, delimiter=",", header=header, comments="")


def _shapes(root: Path, per: int = 5, writers: tuple[str, ...] = ()) -> Path:
    for i in range(per):
        w = f"{writers[i % len(writers)]}/" if writers else ""
        _write(root / "circle" / f"{w}{i}.csv", _circle(i))
        _write(root / "line" / f"{w}{i}.csv", _line(i))
    return root


def test_a_folder_per_concept_is_a_data_set_with_a_checksum(tmp_path):
    ds = load_dataset(_shapes(tmp_path / "shapes"))
    assert ds.concepts == {"circle": 5, "line": 5} and ds.layout == "folders"
    assert [d.key for d in ds.demos[:2]] == ["circle/0", "circle/1"]
    assert all(d.true_concept == s.concept for d, s in zip(ds.demos, ds.samples))
    assert len(ds.checksum) == 64 and load_dataset(tmp_path / "shapes").checksum == ds.checksum
    _write(tmp_path / "shapes" / "line" / "0.csv", _line(7))
    assert load_dataset(tmp_path / "shapes").checksum != ds.checksum
    check_protocol(ds, 5)
    with pytest.raises(InvalidInputError, match=r"fewer samples than the 6 folds(.|\n)*circle: 5"):
        check_protocol(ds, 6)


def test_writer_sub_folders_give_writer_disjoint_folds(tmp_path):
    ds = load_dataset(_shapes(tmp_path / "s", per=8, writers=("ann", "bob", "cy", "di")))
    assert ds.writers == ["ann", "bob", "cy", "di"]
    plan = writer_folds(ds.samples, 2, seed=0)
    for learn, test in plan:
        seen = {ds.samples[i].writer for i in learn}
        assert seen.isdisjoint({ds.samples[i].writer for i in test})
        assert {ds.samples[i].concept for i in learn} == {"circle", "line"}
    assert writer_folds(ds.samples, 2, seed=0)[0][0].tolist() == plan[0][0].tolist()
    with pytest.raises(InvalidInputError, match="at least 5 writers"):
        writer_folds(ds.samples, 5, seed=0)
    flat = load_dataset(_shapes(tmp_path / "flat"))
    with pytest.raises(InvalidInputError, match="needs a writer"):
        check_protocol(flat, 2, "writers")


def test_a_manifest_names_files_concepts_and_writers(tmp_path):
    root = _shapes(tmp_path / "any")
    rows = [{"file": f"{c}/{i}.csv", "concept": c.upper(), "writer": f"w{i % 2}"}
            for c in ("circle", "line") for i in range(5)]
    (root / "list.json").write_text(json.dumps(rows))
    (root / "list.csv").write_text("File;Label;Subject\n" + "".join(  # Windows paths too
        f"{r['file'].replace('/', chr(92))};{r['concept']};{r['writer']}\n" for r in rows))
    for m in ("list.json", "list.csv"):
        ds = load_dataset(root / m)
        assert ds.concepts == {"CIRCLE": 5, "LINE": 5} and ds.writers == ["w0", "w1"]
        assert ds.layout == "manifest"
    (root / "manifest.json").write_text(json.dumps({"samples": rows}))
    assert load_dataset(root).layout == "manifest"


@pytest.mark.parametrize("breakage, message", [
    ("empty", r"square: concept folder is empty"),
    ("unreadable", r"circle/3.csv"),
    ("units", r"mixes position units(.|\n)*mm: 1 file"),
    ("times", r"mixes units of time"),
    ("manifest", r"line/9.csv: listed in manifest.csv but not found"),
    ("columns", r"needs a 'file' and a 'concept' column"),
    ("missing", r"does not exist"),
    ("one", r"1 concept"),
])
def test_bad_data_sets_get_one_clear_error_naming_paths(tmp_path, breakage, message):
    root = _shapes(tmp_path / "d")
    if breakage == "empty":
        (root / "square").mkdir()
    elif breakage == "unreadable":
        (root / "circle" / "3.csv").write_text("x,y\n1,2\nthree,4\n5,6\n")
    elif breakage == "units":
        _write(root / "circle" / "0.csv", _circle(0), "x_mm,y_mm")
        _write(root / "line" / "0.csv", _line(0), "x_px,y_px")
    elif breakage == "times":
        _write(root / "circle" / "0.csv", np.column_stack([np.linspace(0, 1, 60), _circle(0)]),
               "t,x,y")
    elif breakage == "manifest":
        (root / "manifest.csv").write_text("file,concept\ncircle/0.csv,circle\n"
                                           "line/9.csv,line\n")
    elif breakage == "columns":
        (root / "manifest.csv").write_text("name,kind\ncircle/0.csv,circle\n")
    elif breakage == "missing":
        root = root / "nope"
    elif breakage == "one":
        import shutil
        shutil.rmtree(root / "line")
    with pytest.raises(InvalidInputError, match=message):
        load_dataset(root)


# ---------------------------------------------------------------- the oracle

@pytest.mark.usefixtures("default_back_ends")
def test_the_oracle_knows_the_founding_demonstration_of_a_concept_outside_lasa():
    """Two circles and two lines: the first circle founds a concept without a question,
    so the oracle never judged it and, looking 'circle/0' up by LASA shape name, said
    "no" to the right guess on the second circle, which founded a third concept."""
    import iloci
    from iloci.teachers import OracleTeacher

    oracle = OracleTeacher()
    first = Demonstration(_circle(0), shape="circle", true_concept="circle")
    oracle.show(first)
    assert oracle.concept_of_key("circle/0") == "circle"
    assert OracleTeacher().concept_of_key("GShape/0") is None  # nothing from LASA names
    with pytest.raises(Exception, match="does not know the concept"):
        oracle.show(Demonstration(_line(0), shape="nameless"))

    demos = [Demonstration(_circle(i, r=0.05), shape="circle", index=i, true_concept="circle")
             for i in range(2)]
    demos += [Demonstration(_line(i, length=0.1), shape="line", index=i, true_concept="line")
              for i in range(2)]
    agent = iloci.build()
    report = agent.teach([demos[0], demos[2], demos[1], demos[3]])
    members = agent.memory.concept_members(lambda k: k.split("/")[0])
    assert sorted(sorted(set(v)) for v in members.values()) == [["circle"], ["line"]]
    assert len(report.outcomes) == 4


# ---------------------------------------------------------------- iloci evaluate --data

TINY = """
[perceptual_model]
name = "native-rnnpb"
epochs = 150
recognition_steps = 40
[learner]
rehearsal_epochs = 80
[evaluation]
folds = 2
seed = 1
"""


def _square(i: int, n: int = 60) -> np.ndarray:
    s = np.linspace(0, 4, n)
    side = np.minimum(np.floor(s), 3)
    f = s - side
    corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], dtype=float)
    return (corners[side.astype(int)] * (1 - f[:, None]) + corners[side.astype(int) + 1]
            * f[:, None]) * (1 + 0.05 * i)


@pytest.mark.usefixtures("default_back_ends")
def test_iloci_evaluate_data_runs_the_protocol_on_a_users_folder(tmp_path, cli):
    root = _shapes(tmp_path / "shapes", per=4, writers=("ann", "bob", "cy", "di"))
    for i in range(4):
        _write(root / "square" / ("ann", "bob", "cy", "di")[i] / f"{i}.csv", _square(i))
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TINY)
    out = tmp_path / "run"
    done = cli("evaluate", "--data", str(root), "--split", "writers", "--config", str(cfg),
               "--out", str(out), "--jobs", "1", "--quiet")
    assert done.returncode == 0, done.stderr
    assert ("data set shapes (12 samples, 3 concepts, 4 writers; concepts: circle, line, "
            "square)") in done.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    ds = load_dataset(root)
    assert metrics["dataset"]["checksum"] == ds.checksum
    assert metrics["dataset"]["samples"] == 12 and metrics["split"] == "writers"
    assert set(metrics["baselines"]) == {"dtw_normalised", "dollar1", "dtw_raw"}
    assert metrics["best_baseline"] in metrics["baselines"]
    folds = json.loads((out / "folds.json").read_text())
    for f in folds:  # writer-disjoint: no writer on both sides
        writer = {d.key: s.writer for d, s in zip(ds.demos, ds.samples)}
        assert {writer[k] for k in f["learn"]}.isdisjoint({writer[k] for k in f["test"]})
        assert set(f["true_concepts"]) == {"circle", "line", "square"}
    report = (out / "report.md").read_text()
    assert "on shapes (writer-disjoint folds)" in report and ds.checksum in report
    # the reading that decides whether a screen-coordinate set is learned upside down
    assert "read with their y axis pointing up (`[sensorimotor] y_axis`" in report
    # each fold names the writers it was taught and those it recognized ...
    plan = writer_folds(ds.samples, len(folds), seed=metrics["config"]["evaluation"]["seed"])
    for row, (learn, test) in zip(metrics["folds"], plan):
        assert row["writers_taught"] == sorted({ds.samples[i].writer for i in learn})
        assert row["writers_recognized"] == sorted({ds.samples[i].writer for i in test})
        assert set(row["writers_taught"]).isdisjoint(row["writers_recognized"])
        assert (f"| {row['fold']} | {', '.join(row['writers_taught'])} | "
                f"{', '.join(row['writers_recognized'])} |") in report
    # ... and every key folds.json names a sample by leads to its file
    assert set(metrics["samples"]) == {d.key for d in ds.demos}
    for f in folds:
        for key in f["learn"] + f["test"]:
            s = metrics["samples"][key]
            assert (root / s["file"]).is_file() and s["file"].split("/")[0] == s["concept"]
            assert s["writer"] == s["file"].split("/")[1]
    with open(out / "samples.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert [(r["key"], r["file"], r["concept"], r["writer"]) for r in table] == [
        (k, v["file"], v["concept"], v["writer"]) for k, v in metrics["samples"].items()]
    assert "`samples.csv`" in report and "paths's" not in report
    assert "± is the population standard deviation over the folds (ddof=0" in report
    # the code that ran: its version and, from a git checkout (this one), its commit
    from iloci.evaluation.provenance import code_commit
    assert metrics["versions"].get("iloci_commit") == code_commit()
    # in worker processes (sent the demonstrations the parent read): the same results
    out2 = tmp_path / "run2"
    done = cli("evaluate", "--data", str(root), "--split", "writers", "--config", str(cfg),
               "--out", str(out2), "--jobs", "2", "--quiet")
    assert done.returncode == 0, done.stderr

    def timeless(value):
        if isinstance(value, dict):
            return {k: timeless(v) for k, v in value.items()
                    if not k.endswith("seconds") and k not in ("jobs", "versions")}
        return [timeless(v) for v in value] if isinstance(value, list) else value

    for name in ("metrics.json", "folds.json"):  # as text: NaN equals NaN
        assert json.dumps(timeless(json.loads((out2 / name).read_text())), sort_keys=True) \
            == json.dumps(timeless(json.loads((out / name).read_text())), sort_keys=True), name
    assert "$1 recognizer" in report and "best baseline" in report
    assert "paper" not in metrics  # the paper's CCR is LASA's (docs/guide.md)


@pytest.mark.usefixtures("default_back_ends")
def test_the_stream_protocol_on_a_data_set_says_which_sample_is_which(tmp_path):
    """--protocol stream on a data set writes samples.csv and metrics.json's samples and
    dataset, as the folds protocol does: every key stream.json names leads to its file."""
    from iloci.cli import main

    root = _shapes(tmp_path / "shapes", per=4, writers=("ann", "bob"))
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TINY)
    out = tmp_path / "stream"
    assert main(["evaluate", "--data", str(root), "--protocol", "stream", "--config",
                 str(cfg), "--out", str(out), "--quiet"]) == 0
    ds = load_dataset(root)
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["samples"] == ds.sample_files()
    assert metrics["dataset"]["checksum"] == ds.checksum and metrics["dataset"]["samples"] == 8
    steps = json.loads((out / "stream.json").read_text())
    assert len(steps) == 8
    for step in steps:
        s = metrics["samples"][step["demo"]]
        assert (root / s["file"]).is_file() and s["concept"] == step["true"]
        assert s["writer"] == s["file"].split("/")[1]
    with open(out / "samples.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert [(r["key"], r["file"], r["concept"], r["writer"]) for r in table] == [
        (k, v["file"], v["concept"], v["writer"]) for k, v in metrics["samples"].items()]
    report = (out / "report.md").read_text()
    assert "8 demonstrations of shapes" in report and "`samples.csv`" in report
    assert "`stream.json` names it by" in report


@pytest.mark.usefixtures("default_back_ends")
def test_the_stream_protocol_refuses_a_drawing_too_short_before_learning(tmp_path, cli):
    """--protocol stream checks the data set's drawings as the folds protocol does: a file
    of 4 points (fewer than min_points once read) is named in one error, nothing learned."""

    root = _shapes(tmp_path / "shapes", per=4, writers=("ann", "bob"))
    short = sorted(root.rglob("*.csv"))[-1]
    short.write_text("x,y\n1,2\n1,3\n2,3\n3,5\n")
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TINY)
    out = tmp_path / "stream"
    done = cli("evaluate", "--data", str(root), "--protocol", "stream", "--config", str(cfg),
               "--out", str(out), "--quiet")
    assert done.returncode != 0
    assert f"{short}: 4 point(s)" in done.stderr and "nothing was learned" in done.stderr
    assert "Traceback" not in done.stderr and not (out / "stream.json").exists()


def test_the_code_commit_is_recorded_from_a_checkout_and_never_fails_a_run(monkeypatch):
    import re
    import subprocess

    from iloci.evaluation import provenance

    sha = provenance.code_commit()
    root = Path(provenance.__file__).resolve().parents[2]
    assert (sha is not None) == (root / ".git").exists()
    if sha is not None:
        assert re.fullmatch(r"[0-9a-f]{40}", sha)
        assert provenance.versions()["iloci_commit"] == sha

    def hangs(*args, **kwargs):
        raise subprocess.TimeoutExpired(args[0], kwargs.get("timeout", 0))

    monkeypatch.setattr(subprocess, "run", hangs)
    assert provenance.code_commit() is None and "iloci_commit" not in provenance.versions()


@pytest.mark.usefixtures("default_back_ends")
def test_iloci_evaluate_data_refuses_a_bad_data_set_before_learning(tmp_path, cli):
    root = _shapes(tmp_path / "shapes", per=3)
    (root / "line" / "2.csv").write_text("x,y\n0,0\n")
    (root / "empty").mkdir()
    done = cli("evaluate", "--data", str(root), "--out", str(tmp_path / "run"), "--quiet")
    assert done.returncode != 0
    assert "Traceback" not in done.stderr
    assert "empty: concept folder is empty" in done.stderr
    assert not (tmp_path / "run" / "metrics.json").exists()
    (root / "empty").rmdir()
    done = cli("evaluate", "--data", str(root), "--out", str(tmp_path / "run"), "--quiet")
    assert "line/2.csv" in done.stderr and "Traceback" not in done.stderr
    (root / "line" / "2.csv").unlink()
    done = cli("evaluate", "--data", str(root), "--out", str(tmp_path / "run"), "--quiet")
    assert "line: 2 sample(s)" in done.stderr and "fewer samples than the 5 folds" in done.stderr

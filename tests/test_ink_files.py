"""InkML (.inkml) and $1/$N/$P gesture-log (.xml) trajectory files: real UNIPEN drawings
written in each format and read back, data sets of them, every bad file's one clear error,
and XML entity declarations refused."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import numpy as np
import pytest

from iloci.data.datasets import check_protocol, load_dataset
from iloci.data.files import TRAJECTORY_READERS, TRAJECTORY_SUFFIXES, load_trajectory
from iloci.data.streams import resolve_demos
from iloci.data.unipen import UnipenSample, read_unipen, unipen_digits
from iloci.errors import InvalidDemonstrationError, InvalidInputError, TimeUnitWarning

UNIPEN = Path(__file__).parent / "data" / "unipen" / "train_r01_v07"
GUIDE = Path(__file__).resolve().parents[1] / "docs" / "guide.md"


def _samples() -> list[UnipenSample]:
    """Real digits of the committed UNIPEN slice: the multi-stroke ones and a few single."""
    every = read_unipen(UNIPEN, "1a", labels="0123456789", single_stroke=False)
    multi = [s for s in every if len(s.strokes) > 1]
    single = [s for s in every if len(s.strokes) == 1][:3]
    assert len(multi) >= 3 and single
    return multi[:4] + single


def _times(s: UnipenSample) -> list[np.ndarray]:
    """Each stroke's time stamps (s), from the sample's rate, running on across strokes."""
    n = np.cumsum([0] + [len(k) for k in s.strokes])
    return [np.arange(a, b) / s.points_per_second for a, b in zip(n[:-1], n[1:])]


def _inkml(s: UnipenSample, units: str | None = "s", time: bool = True) -> str:
    """An InkML document of the sample: a trace per stroke, X Y [T] in a context of
    <definitions>, plus a pressure channel F that the reader must ignore."""
    t_channel = ""
    if time:
        t_channel = '<channel name="T" type="decimal"' + (f' units="{units}"' if units else "")
        t_channel += "/>"
    scale = {"s": 1.0, "ms": 1e3, None: 1.0}[units]
    traces = []
    for stroke, t in zip(s.strokes, _times(s)):
        pts = [f"{x!r} {y!r}" + (f" {ti * scale!r}" if time else "") + f" {j % 7}"
               for j, ((x, y), ti) in enumerate(zip(stroke.tolist(), t.tolist()))]
        traces.append('  <trace contextRef="#ctx0">' + ",\n    ".join(pts) + "</trace>")
    return ('<?xml version="1.0" encoding="UTF-8"?>\n'
            '<ink xmlns="http://www.w3.org/2003/InkML">\n'
            '  <definitions>\n    <context xml:id="ctx0">\n      <traceFormat>\n'
            '        <channel name="X" type="decimal"/>\n        <channel name="Y" '
            f'type="decimal"/>\n        {t_channel}\n        <channel name="F" '
            'type="integer"/>\n      </traceFormat>\n    </context>\n  </definitions>\n'
            '  <annotation type="truth">' + s.label + "</annotation>\n"
            + "\n".join(traces) + "\n</ink>\n")


def _gesture_xml(s: UnipenSample, strokes: bool, time: bool = True) -> str:
    """A $1 (points in <Gesture>) or $N/$P (points in <Stroke>s) log of the sample, T in ms."""
    def points(stroke: np.ndarray, t: np.ndarray) -> str:
        return "".join(f'    <Point X="{x!r}" Y="{y!r}"'
                       + (f' T="{round(ti * 1000) + 9250250}"' if time else "") + " />\n"
                       for (x, y), ti in zip(stroke.tolist(), t.tolist()))

    body = ("".join(f'  <Stroke index="{k + 1}">\n{points(st, t)}  </Stroke>\n'
                    for k, (st, t) in enumerate(zip(s.strokes, _times(s))))
            if strokes else "".join(points(st, t) for st, t in zip(s.strokes, _times(s))))
    n = sum(len(k) for k in s.strokes)
    return ('<?xml version="1.0" encoding="utf-8" standalone="yes"?>\n'
            f'<Gesture Name="{s.label}01" Subject="1" Speed="fast" Number="1" NumPts="{n}" '
            'Millseconds="460" AppName="Gestures">\n' + body + "</Gesture>\n")


# ---------------------------------------------------------------- reading real drawings

@pytest.mark.parametrize("units", ["s", "ms", None])
def test_unipen_drawings_written_as_inkml_read_back_as_written(tmp_path, units):
    for i, s in enumerate(_samples()):
        f = tmp_path / f"{s.label}_{i}.inkml"
        f.write_text(_inkml(s, units), encoding="utf-8")
        d = load_trajectory(f)
        joined = s.demonstration()  # how the UNIPEN reader joins a multi-stroke sample
        np.testing.assert_array_equal(d.positions, np.concatenate(s.strokes))
        np.testing.assert_array_equal(d.positions, joined.positions)
        # T in s (or no units: read as s) is exact; in ms it is divided by 1000
        np.testing.assert_allclose(d.times, joined.times, rtol=1e-12, atol=1e-15)
        assert d.key == f"{s.label}_{i}/0"


def test_inkml_without_a_time_channel_counts_samples(tmp_path):
    s = _samples()[0]
    f = tmp_path / "five.inkml"
    f.write_text(_inkml(s, time=False))
    d = load_trajectory(f)
    np.testing.assert_array_equal(d.positions, np.concatenate(s.strokes))
    np.testing.assert_array_equal(d.times, np.arange(len(d.positions), dtype=float))


def test_an_inkml_time_channel_without_units_is_read_as_seconds(tmp_path):
    """As a CSV file's ``t``; milliseconds in it get the TimeUnitWarning that says so."""
    f = tmp_path / "ms.inkml"
    f.write_text(_INK.format('<traceFormat><channel name="X"/><channel name="Y"/><channel '
                             'name="T"/></traceFormat><trace>0 0 9250250, 1 5 9250300, '
                             "2 0 9250350, 3 5 9250400</trace>"))
    with pytest.warns(TimeUnitWarning, match="look like milliseconds"):
        d = load_trajectory(f)
    np.testing.assert_array_equal(d.times, [9250250, 9250300, 9250350, 9250400])


def _encode(values: np.ndarray, modes: str) -> list[str]:
    """InkML 3.2.1 values of one channel: mode per point '!' explicit (every other one in
    hexadecimal), "'" first difference, '"' second difference; the prefix written only where
    the mode changes."""
    out, prev_mode, v1, d1 = [], "!", None, None
    for j, (v, mode) in enumerate(zip(values.tolist(), modes)):
        if mode == "!":
            text = str(v) if j % 2 else ("-" if v < 0 else "") + "#" + format(abs(v), "X")
        elif mode == "'":
            text = str(v - v1)
        else:
            text = str((v - v1) - d1)
        out.append((mode if mode != prev_mode else "") + text)
        d1 = None if v1 is None else v - v1
        v1, prev_mode = v, mode
    return out


def test_inkml_difference_encodings_decode_to_the_drawing(tmp_path):
    """Real strokes in tablet units (integers, so differences are exact), written with the
    spec's ! ' " prefixes, hexadecimal and juxtaposed values, read back bit for bit."""
    ink = ['<ink xmlns="http://www.w3.org/2003/InkML">']
    expected = []
    for stroke in _samples()[0].strokes:
        xy = np.round(stroke * 100).astype(int)
        expected.append(xy)
        n = len(xy)
        # explicit, first differences, second differences, explicit again, second again
        modes = ("!" + "'" * 3 + '"' * 5 + "!" * 2 + '"' * n)[:n]
        xs, ys = _encode(xy[:, 0], modes), _encode(xy[:, 1], modes)
        # juxtaposed where the grammar allows it (before a sign or a prefix), else a space
        pts = [a + b if b[0] in "-'\"!" else f"{a} {b}" for a, b in zip(xs, ys)]
        assert any("'" in p for p in pts) and any('"' in p for p in pts)
        assert any("#" in p for p in pts) and any(re.search(r"\d['\"-]", p) for p in pts)
        ink.append(f"<trace>{','.join(pts)},</trace>")  # a trailing comma is read too
    ink.append("</ink>")
    f = tmp_path / "diff.inkml"
    f.write_text("\n".join(ink))
    d = load_trajectory(f)
    np.testing.assert_array_equal(d.positions, np.concatenate(expected).astype(float))


def test_inkml_trace_formats_from_contexts_trace_groups_and_orientation(tmp_path):
    """The trace format comes from the trace's contextRef, its traceGroup's, or the last
    <context> before it; a bare <traceFormat> (as CROHME's files have) counts too; penUp
    traces are hover, left out, and an empty trace adds nothing; orientation="-ve" negates
    a channel."""
    f = tmp_path / "ctx.inkml"
    f.write_text("""<ink>
  <definitions>
    <traceFormat xml:id="tyx"><channel name="Y"/><channel name="X"/></traceFormat>
    <context xml:id="a" traceFormatRef="#tyx"/>
    <inkSource xml:id="src"><traceFormat>
      <channel name="X"/><channel name="Y" orientation="-ve"/></traceFormat></inkSource>
    <context id="b" inkSourceRef="#src"/>
    <context xml:id="c" contextRef="#b"/>
  </definitions>
  <trace>0 0, 1 1</trace>
  <trace type="penUp">50 50, 60 60</trace>
  <trace/>
  <context contextRef="#a"/>
  <trace>3 2, 5 4</trace>
  <traceGroup contextRef="#c"><trace>6 7</trace></traceGroup>
  <trace contextRef="#c">8 9</trace>
  <traceFormat><channel name="X"/><channel name="Y"/><channel name="T" units="ms"/>
  </traceFormat>
</ink>""")
    d = load_trajectory(f)
    np.testing.assert_array_equal(d.positions, [[0, 0], [1, 1], [2, 3], [4, 5], [6, -7],
                                                [8, -9]])


@pytest.mark.parametrize("strokes", [False, True], ids=["$1 points", "$N strokes"])
def test_unipen_drawings_written_as_gesture_logs_read_back_as_written(tmp_path, strokes):
    for i, s in enumerate(_samples()):
        f = tmp_path / f"{s.label}{i:02d}.xml"
        f.write_text(_gesture_xml(s, strokes), encoding="utf-8")
        d = load_trajectory(f)
        np.testing.assert_array_equal(d.positions, np.concatenate(s.strokes))
        ms = np.round(np.concatenate(_times(s)) * 1000) + 9250250
        np.testing.assert_array_equal(d.times, ms / 1000)  # T is ms, read as s
    g = tmp_path / "untimed.xml"
    g.write_text(_gesture_xml(_samples()[0], strokes, time=False))
    assert np.array_equal(load_trajectory(g).times, np.arange(len(load_trajectory(g).times)))


def test_a_gesture_log_repeating_time_stamps_has_them_spread(tmp_path):
    f = tmp_path / "coarse.xml"
    f.write_text('<Gesture Name="x"><Point X="0" Y="0" T="100"/><Point X="1" Y="1" T="100"/>'
                 '<Point X="2" Y="0" T="110"/><Point X="3" Y="1" T="120"/></Gesture>')
    np.testing.assert_allclose(load_trajectory(f).times, [0.1, 0.105, 0.11, 0.12])


def test_an_xml_file_holding_inkml_is_read_as_inkml(tmp_path):
    s = _samples()[1]
    f = tmp_path / "ink.xml"
    f.write_text(_inkml(s))
    np.testing.assert_array_equal(load_trajectory(f).positions, np.concatenate(s.strokes))


def test_suffixes_are_matched_without_case_everywhere(tmp_path):
    s = _samples()[0]
    assert {".inkml", ".xml", ".csv", ".npy"} == set(TRAJECTORY_SUFFIXES) == set(
        TRAJECTORY_READERS)
    a, b = tmp_path / "A.INKML", tmp_path / "B.Xml"
    a.write_text(_inkml(s))
    b.write_text(_gesture_xml(s, strokes=True))
    assert np.array_equal(load_trajectory(a).positions, load_trajectory(b).positions)
    # `iloci teach` FILE arguments: file names, read when their turn comes
    items = resolve_demos([str(a), str(b)])
    assert [i.key for i in items] == ["A/0", "B/0"]
    assert np.array_equal(items[0].load().positions, np.concatenate(s.strokes))
    # data-set folders pick them up
    root = tmp_path / "set"
    for c, (one, two) in (("five", (4, 0)), ("nine", (5, 1))):
        (root / c).mkdir(parents=True)
        (root / c / "ONE.INKML").write_text(_inkml(_samples()[one]))
        (root / c / "Two.XML").write_text(_gesture_xml(_samples()[two], strokes=True))
    ds = load_dataset(root)
    assert ds.concepts == {"five": 2, "nine": 2}


# ---------------------------------------------------------------- data sets


def _digit_set(root: Path, fmt: str, labels: str = "679", per: int = 4) -> list[dict]:
    """A folder per digit with a sub-folder per writer: real single-stroke UNIPEN digits."""
    rows = []
    digits = unipen_digits(UNIPEN)
    for label in labels:
        chosen = [s for s in digits if s.label == label][:per]
        assert len(chosen) == per
        for i, s in enumerate(chosen):
            rel = f"{label}/{s.writer.split('/')[1]}/{label}{i:02d}.{fmt}"
            (root / rel).parent.mkdir(parents=True, exist_ok=True)
            text = _inkml(s, "ms") if fmt == "inkml" else _gesture_xml(s, strokes=False)
            (root / rel).write_text(text, encoding="utf-8")
            rows.append({"file": rel, "concept": f"digit {label}", "writer": s.writer})
    return rows


@pytest.mark.parametrize("fmt", ["inkml", "xml"])
def test_a_data_set_of_ink_files_as_folders_and_manifest(tmp_path, fmt):
    root = tmp_path / "digits"
    rows = _digit_set(root, fmt)
    ds = load_dataset(root)
    assert ds.layout == "folders" and ds.concepts == {"6": 4, "7": 4, "9": 4}
    assert set(ds.writers) <= {"amywldrp", "crlmtchl", "greghunt"} and len(ds.writers) > 1
    check_protocol(ds, 2)
    digits = {s.label: [] for s in unipen_digits(UNIPEN)}
    for s in unipen_digits(UNIPEN):
        digits[s.label].append(s)
    for d, smp in zip(ds.demos, ds.samples):  # each file read back as the digit written
        i = int(Path(smp.path).stem[1:])
        assert np.array_equal(d.positions, digits[smp.concept][i].strokes[0])
    (root / "manifest.json").write_text(json.dumps(rows))
    man = load_dataset(root)
    assert man.layout == "manifest" and man.concepts == {"digit 6": 4, "digit 7": 4,
                                                         "digit 9": 4}
    assert man.writers == sorted({r["writer"] for r in rows})


def test_bad_ink_files_in_a_data_set_are_listed_together_before_learning(tmp_path):
    root = tmp_path / "digits"
    _digit_set(root, "xml")
    (root / "6" / "broken.xml").write_text('<Gesture Name="x"><Point X="1" Y="2"/>')
    (root / "7" / "empty.inkml").write_text('<ink xmlns="http://www.w3.org/2003/InkML"/>')
    (root / "9" / "svg.xml").write_text('<svg><path d="M0 0"/></svg>')
    with pytest.raises(InvalidInputError) as err:
        load_dataset(root)
    text = str(err.value)
    assert "3 file(s) cannot be used; nothing was learned" in text
    assert "6/broken.xml: broken.xml is not a gesture log" in text
    assert "7/empty.inkml: no pen-down trace" in text  # the file named once
    assert "9/svg.xml: svg.xml, line 1: the root element is <svg>" in text
    assert ".inkml (InkML) or .xml ($1/$N gesture log)" in text


def _filed_by_writer(tmp_path: Path) -> tuple[Path, list[dict]]:
    """The digits of :func:`_digit_set` filed as the $1 logs are: writer/speed/gestureNN.xml."""
    rows = _digit_set(tmp_path / "by_digit", "xml", labels="679", per=4)
    root = tmp_path / "xml_logs"
    for r in rows:  # 6/amywldrp/601.xml -> s02/fast/six01.xml
        label, _, name = r["file"].split("/")
        writer = f"s0{int(name[1:3]) % 2 + 1}"  # 2 writers, each drew every digit twice
        word = {"6": "six", "7": "seven", "9": "nine"}[label]
        text = (tmp_path / "by_digit" / r["file"]).read_text().replace(
            f'Name="{label}01"', f'Name="{word}{name[1:3]}"')
        dest = root / writer / "fast" / f"{word}{name[1:3]}.xml"
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_text(text)
    return root, rows


def test_gesture_logs_filed_by_writer_are_refused_as_a_data_set_of_folders(tmp_path):
    """The $1 logs' own layout (writer/speed/gestureNN.xml) read as folders would make each
    writer a concept and run without an error; the logs' Name attributes show it: one
    error that says so and points to the manifest, before anything is read or learned.
    A folder that groups several gestures on purpose (none shared with another) is read."""
    root, rows = _filed_by_writer(tmp_path)
    with pytest.raises(InvalidInputError) as err:
        load_dataset(root)
    text = str(err.value)
    assert "gesture logs name other gestures than the folders they are in" in text
    assert "holds 3 gestures (nine, seven, six" in text and "write a manifest" in text
    # gestures grouped on purpose: 'round' holds six and nine, 'straight' seven
    grouped = tmp_path / "grouped"
    for r in rows:
        label, writer, name = r["file"].split("/")
        dest = grouped / ("straight" if label == "7" else "round") / writer / name
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_text((tmp_path / "by_digit" / r["file"]).read_text())
    assert load_dataset(grouped).concepts == {"round": 8, "straight": 4}
    # logs named after their writer (Name="s01_3") in concept/writer folders name no gesture
    by_name = tmp_path / "writer_names"
    for i, r in enumerate(rows):
        label, _, name = r["file"].split("/")
        writer = f"s0{i % 2 + 1}"
        dest = by_name / label / writer / name
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_text((tmp_path / "by_digit" / r["file"]).read_text().replace(
            f'Name="{label}01"', f'Name="{writer}_{i}"'))
    assert load_dataset(by_name).concepts == {"6": 4, "7": 4, "9": 4}


@pytest.mark.usefixtures("default_back_ends")
def test_iloci_evaluate_refuses_gesture_logs_filed_by_writer_in_one_error(tmp_path, cli):
    root, _ = _filed_by_writer(tmp_path)
    done = cli("evaluate", "--data", str(root), "--quiet")
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "gesture logs name other gestures" in done.stderr
    assert "write a manifest" in done.stderr


@pytest.mark.usefixtures("default_back_ends")
def test_iloci_evaluate_runs_on_a_data_set_of_gesture_logs(tmp_path, cli):
    from test_own_data import TINY

    root = tmp_path / "logs"
    _digit_set(root, "xml", labels="79", per=4)
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TINY + '[sensorimotor]\ny_axis = "down"\n')
    out = tmp_path / "run"
    done = cli("evaluate", "--data", str(root), "--config", str(cfg), "--out", str(out),
               "--jobs", "1", "--quiet")
    assert done.returncode == 0, done.stderr
    assert "data set logs (8 samples, 2 concepts" in done.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["dataset"]["samples"] == 8
    assert metrics["dataset"]["checksum"] == load_dataset(root).checksum


# ---------------------------------------------------------------- bad files

_INK = '<ink xmlns="http://www.w3.org/2003/InkML">\n{}\n</ink>\n'
_TXYT = ('<traceFormat><channel name="X"/><channel name="Y"/><channel name="T" units="{}"/>'
         "</traceFormat>")


@pytest.mark.parametrize("suffix, text, error, message", [
    # not XML at all, or not complete
    (".inkml", "x,y\n0,0\n1,1\n", InvalidInputError,
     r"a\.inkml is not an InkML file: it is not well-formed XML \(line 1, column 0: "
     r"syntax error\)"),
    (".xml", "\x93NUMPY\x01\x00", InvalidInputError,
     r"a\.xml is not a gesture log .*line 1, column 0"),
    (".inkml", _INK.format("<trace>0 0, 1 1"), InvalidInputError,
     r"a\.inkml is not an InkML file: .*\(line 3, column 2: mismatched tag\)"),
    (".inkml", "", InvalidInputError, r"a\.inkml is not an InkML file: .*no element found"),
    (".xml", '<?xml version="1.0" encoding="x-nope"?><Gesture/>', InvalidInputError,
     r"a\.xml: unknown encoding: x-nope .*Save it as UTF-8"),
    (".inkml", "<ink>" + "<traceGroup>" * 5000 + "<trace>0 0, 1 1, 2 2</trace>"
     + "</traceGroup>" * 5000 + "</ink>", InvalidDemonstrationError, r"nested too deeply"),
    # not InkML, or no traces
    (".inkml", '<Gesture Name="x"><Point X="1" Y="2"/></Gesture>', InvalidDemonstrationError,
     r"a\.inkml, line 1: the root element is <Gesture>, not InkML's <ink>"),
    (".inkml", _INK.format(""), InvalidDemonstrationError,
     r"a\.inkml: no pen-down trace to read: it has no <trace> element"),
    (".inkml", _INK.format('<trace type="penUp">0 0, 1 1, 2 2</trace>'),
     InvalidDemonstrationError, r"no pen-down trace to read: its traces are all "
     r'type="penUp"'),
    (".inkml", _INK.format("<definitions><trace>0 0, 1 1</trace></definitions>"),
     InvalidDemonstrationError, r"inside <definitions> \(drawn through <traceView>"),
    # a point with one value, values that are not numbers, point widths that differ
    (".inkml", _INK.format("<trace>\n0 0,\n1,\n2 2</trace>"), InvalidDemonstrationError,
     r"a\.inkml, line 4: trace 1, point 2 has 1 value\(s\) where the trace format \(the "
     r"default trace format \(X Y\): X Y\) has 2 channel\(s\)"),
    (".inkml", _INK.format("<trace>0 0, 1 1, 2 2</trace>\n<trace>0 0, 1 one</trace>"),
     InvalidDemonstrationError, r"line 3: trace 2, point 2: 'one' is not a number"),
    (".inkml", _INK.format(_TXYT.format("ms") + "<trace>0 0 0, 1 1 10, 2 2</trace>"),
     InvalidDemonstrationError, r"trace 1, point 3 has 2 value\(s\) where the trace format "
     r"\(the traceFormat on line 2: X Y T\) has 3"),
    (".inkml", _INK.format("<trace>0 0, 1 1e999, 2 2</trace>"), InvalidDemonstrationError,
     r"point 2: channel Y is '1e999', too large"),
    # unsupported features: named
    (".inkml", _INK.format("<trace>0 0, 1 ?, 2 2</trace>"), InvalidDemonstrationError,
     r"point 2: channel Y is '\?' \(a value not known\), which is not read"),
    (".inkml", _INK.format("<trace>'0 0, 1 1, 2 2</trace>"), InvalidDemonstrationError,
     r"point 1: channel X is given as a first difference \('0\) with no previous value"),
    (".inkml", _INK.format("<trace>0 0, \"1 1, 2 2</trace>"), InvalidDemonstrationError,
     r"point 2: channel X is given as a second difference .* no previous difference"),
    (".inkml", _INK.format(_TXYT.format("ms") + '<trace timeOffset="5">0 0 0, 1 1 1, 2 2 2'
                           "</trace>"), InvalidDemonstrationError,
     r"trace 1 has a timeOffset, .* not read"),
    (".inkml", _INK.format(_TXYT.format("min") + "<trace>0 0 0, 1 1 1, 2 2 2</trace>"),
     InvalidDemonstrationError, r"line 2: the T channel's units 'min' are not read"),
    (".inkml", _INK.format('<traceFormat><channel name="x"/><channel name="y"/></traceFormat>'
                           "<trace>0 0, 1 1, 2 2</trace>"), InvalidDemonstrationError,
     r"no X channel \(its channels: x y\).*case-sensitive"),
    (".inkml", _INK.format('<traceFormat><channel name="Y"/><intermittentChannels><channel '
                           'name="X"/></intermittentChannels></traceFormat><trace>0 0</trace>'),
     InvalidDemonstrationError, r"channel X is intermittent"),
    (".inkml", _INK.format('<trace contextRef="other.inkml#c">0 0, 1 1, 2 2</trace>'),
     InvalidDemonstrationError, r"contextRef='other.inkml#c' refers to another file"),
    (".inkml", _INK.format('<trace contextRef="#nope">0 0, 1 1, 2 2</trace>'),
     InvalidDemonstrationError, r"contextRef='#nope' names no <context> in the file"),
    (".inkml", _INK.format(_TXYT.format("s") + "<trace>0 0 0, 1 1 1, 2 2 2</trace>"
                           "<traceFormat><channel name='X'/><channel name='Y'/></traceFormat>"
                           "<trace>3 3, 4 4</trace>"), InvalidDemonstrationError,
     r"some traces have a T \(time\) channel and some do not"),
    (".inkml", _INK.format(_TXYT.format("s") + "<trace>0 0 0, 1 1 1\n</trace>\n<trace>2 2 0.5"
                           ", 3 3 3</trace>"), InvalidDemonstrationError,
     r"a\.inkml: trace 2 \(line 4\), point 1: time 0\.5 is before the previous row's 1"),
    # gesture logs
    (".xml", '<Gesture Name="arrow01" NumPts="0">\n</Gesture>', InvalidDemonstrationError,
     r"a\.xml, line 1: the <Gesture> has no <Point> \(an empty recording\)"),
    (".xml", '<Gestures><Gesture Name="a"/></Gestures>', InvalidDemonstrationError,
     r"a\.xml, line 1: the root element is <Gestures>; a \$1/\$N gesture log's is <Gesture>"),
    (".xml", '<Gesture>\n<Point X="1" Y="2" T="0"/>\n<Point X="1" T="5"/>\n</Gesture>',
     InvalidDemonstrationError, r"a\.xml, line 3: <Point> 2 has no Y attribute"),
    (".xml", '<Gesture>\n<Point X="1" Y="2"/>\n<Point X="1,5" Y="3"/>\n</Gesture>',
     InvalidDemonstrationError, r"line 3: <Point> 2: X='1,5' is not a number"),
    (".xml", '<Gesture>\n<Point X="1" Y="2" T="0"/>\n<Point X="2" Y="3"/></Gesture>',
     InvalidDemonstrationError, r"line 3: <Point> 2 has no T where <Point> 1 has"),
    (".xml", '<Gesture><Point X="1" Y="2"/><Stroke><Point X="1" Y="2"/></Stroke></Gesture>',
     InvalidDemonstrationError, r"holds both <Point> and <Stroke>"),
    (".xml", '<Gesture>\n<Point X="1" Y="2" T="9"/>\n<Point X="2" Y="3" T="8"/>\n'
     '<Point X="3" Y="1" T="10"/></Gesture>', InvalidDemonstrationError,
     r"a\.xml: line 3 \(<Point> 2\): time 0\.008 is before the previous row's 0\.009"),
    (".xml", '<Gesture><Point X="1" Y="2"/><Point X="2" Y="3"/></Gesture>',
     InvalidDemonstrationError, r"a\.xml: demonstration 'a/0' has 2 point\(s\); at least 3"),
])
def test_each_bad_file_gets_one_error_naming_it(tmp_path, suffix, text, error, message):
    f = tmp_path / f"a{suffix}"
    f.write_text(text, encoding="latin-1")
    with pytest.raises(error, match=message) as err:
        load_trajectory(f)
    assert type(err.value) is error and str(err.value).startswith(f"a{suffix}")


_LAUGHS = """<?xml version="1.0"?>
<!DOCTYPE ink [
  <!ENTITY lol "lol">
  <!ENTITY lol1 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
  <!ENTITY lol2 "&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;">
  <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
  <!ENTITY lol4 "&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;">
  <!ENTITY lol5 "&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;">
  <!ENTITY lol6 "&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;">
  <!ENTITY lol7 "&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;">
  <!ENTITY lol8 "&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;">
  <!ENTITY lol9 "&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;">
]>
<ink><trace>0 0, 1 1, 2 2</trace><annotation>&lol9;</annotation></ink>
"""


@pytest.mark.parametrize("suffix", [".inkml", ".xml"])
@pytest.mark.parametrize("doc", [
    _LAUGHS,
    # one harmless entity: refused all the same (no entity is ever expanded)
    '<!DOCTYPE Gesture [<!ENTITY x "1">]><Gesture><Point X="&x;" Y="2"/></Gesture>',
    # an external entity would read another file
    '<!DOCTYPE ink [<!ENTITY secret SYSTEM "file:///etc/passwd">]><ink><trace>0 0, 1 1, 2 2'
    "</trace><annotation>&secret;</annotation></ink>",
], ids=["billion laughs", "internal", "external"])
def test_xml_entity_declarations_are_refused_before_any_expansion(tmp_path, suffix, doc):
    f = tmp_path / f"bomb{suffix}"
    f.write_text(doc)
    start = time.perf_counter()
    with pytest.raises(InvalidInputError, match=r"bomb\.(inkml|xml), line \d+: declares the "
                       r"XML entity '(lol|x|secret)' .*refused.*billion laughs"):
        load_trajectory(f)
    assert time.perf_counter() - start < 1.0


@pytest.mark.parametrize("name, text, message", [
    ("bomb.inkml", _LAUGHS, "bomb.inkml, line 3: declares the XML entity 'lol'"),
    ("empty.XML", '<Gesture Name="arrow01"/>', "empty.XML, line 1: the <Gesture> has no"),
])
def test_a_bad_ink_file_on_the_command_line_exits_2_without_a_traceback(tmp_path, cli, name,
                                                                          text, message):
    f = tmp_path / name
    f.write_text(text)
    out = cli("show", str(f), "--out", str(tmp_path / "x.png"))
    assert out.returncode == 2 and message in out.stderr and "Traceback" not in out.stderr


def test_a_doctype_without_entities_is_read(tmp_path):
    f = tmp_path / "dtd.xml"
    f.write_text('<?xml version="1.0"?>\n<!DOCTYPE Gesture>\n<Gesture><Point X="0" Y="0"/>'
                 '<Point X="1" Y="1"/><Point X="2" Y="0"/></Gesture>')
    assert load_trajectory(f).positions.shape == (3, 2)


# ---------------------------------------------------------------- the guide


def test_the_guides_minimal_examples_read_as_shown(tmp_path):
    """The guide's minimal InkML and gesture-log files read, with the times it says."""
    text = GUIDE.read_text()
    ink = re.search(r"```xml\n(<ink .*?</ink>)\n```", text, flags=re.S)
    log = re.search(r"```xml\n(<Gesture .*?</Gesture>)\n```", text, flags=re.S)
    assert ink and log
    (tmp_path / "stroke.inkml").write_text(ink.group(1))
    (tmp_path / "arrow01.xml").write_text(log.group(1))
    d = load_trajectory(tmp_path / "stroke.inkml")
    assert d.positions.shape == (8, 2) and d.positions[5].tolist() == [20, 5]  # 2 traces
    np.testing.assert_allclose(d.times, [0, 0.01, 0.02, 0.03, 0.04, 0.06, 0.07, 0.08])
    g = load_trajectory(tmp_path / "arrow01.xml")
    assert g.positions.tolist()[:2] == [[65, 139], [72, 138]] and len(g.positions) == 5
    np.testing.assert_allclose(np.diff(g.times), 0.01)  # T in ms

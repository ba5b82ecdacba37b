"""The console teacher and what it shows (kernel only; a real simulator in a learning
run is tested in tests/plugins/test_pybullet.py)."""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np
import pytest

from iloci.data import load_lasa
from iloci.errors import FeedbackError
from iloci.interfaces import Execution, Response
from iloci.teachers import ConsoleTeacher


def _response(executed: bool) -> Response:
    t = np.linspace(0, 1, 20)
    motion = np.column_stack([-0.125 + 0.04 * np.cos(6 * t), 0.1 + 0.04 * np.sin(6 * t)])
    execution = None
    if executed:
        # the arm drew it 3 mm lower than the network meant
        pen = np.column_stack([np.full(20, 0.165), motion + [0.0, -0.003]])
        execution = Execution(np.zeros((20, 4)), pen, 0.05)
    return Response("c1", motion, np.zeros((20, 4)), "GShape/0", ("GShape/0",), execution)


def test_response_drawing_is_the_executed_pen_path_when_there_is_one():
    plain, executed = _response(False), _response(True)
    np.testing.assert_array_equal(plain.drawing, plain.motion)
    np.testing.assert_array_equal(executed.drawing, executed.execution.end_effector[:, 1:])
    assert executed.drawing.shape == (20, 2)


@pytest.mark.parametrize("executed", [False, True])
def test_console_picture_draws_what_the_teacher_judges(tmp_path, monkeypatch, executed):
    pytest.importorskip("matplotlib")
    from matplotlib.axes import Axes

    drawn, titles = [], []
    plot, set_title = Axes.plot, Axes.set_title

    def spy_plot(ax, *args, **kw):
        if args[2:] == ("b-",):  # the robot's pen path
            drawn.append(np.column_stack(args[:2]))
        return plot(ax, *args, **kw)

    def spy_title(ax, title, *args, **kw):
        titles.append(title)
        return set_title(ax, title, *args, **kw)

    monkeypatch.setattr(Axes, "plot", spy_plot)
    monkeypatch.setattr(Axes, "set_title", spy_title)
    out = io.StringIO()
    teacher = ConsoleTeacher(str(tmp_path), stdin=io.StringIO("maybe\ny\n"), stdout=out)
    response = _response(executed)
    assert teacher.feedback(load_lasa("GShape")[0], response) == 1
    assert (tmp_path / "answer-0001.png").stat().st_size > 0
    assert len(drawn) == 1
    np.testing.assert_array_equal(drawn[0], response.drawing)
    assert titles[-1] == ("robot drew: concept c1" if executed else
                          "robot generated: concept c1")
    text = out.getvalue()
    assert "its drawing is in" in text and "Please answer y or n." in text


def test_console_teacher_eof_is_a_clear_error():
    teacher = ConsoleTeacher("", stdin=io.StringIO(""), stdout=io.StringIO())
    with pytest.raises(FeedbackError, match="EOF"):
        teacher.feedback(load_lasa("GShape")[0], _response(False))


def test_console_picture_leaves_the_host_backend_alone(tmp_path):
    """Embedding iloci in a program with its own matplotlib backend (a GUI, a
    notebook) must not switch it."""
    import subprocess
    import sys
    pytest.importorskip("matplotlib")
    code = (
        "import io, matplotlib\n"
        "matplotlib.use('svg')\n"
        "from iloci.data import load_lasa\n"
        "from iloci.teachers import ConsoleTeacher\n"
        "from test_teachers import _response\n"
        f"t = ConsoleTeacher({str(tmp_path)!r}, stdin=io.StringIO('y\\n'), stdout=io.StringIO())\n"
        "t.feedback(load_lasa('GShape')[0], _response(True))\n"
        "print(matplotlib.get_backend())\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).parent)
    assert out.stdout.strip() == "svg"
    assert (tmp_path / "answer-0001.png").read_bytes()[:4] == b"\x89PNG"


def _session(directory, demos) -> list[str]:
    """One console-teacher session: a fresh teacher judging one answer per demonstration.

    Returns the names of the pictures the teacher said it wrote, in order."""
    out = io.StringIO()
    teacher = ConsoleTeacher(str(directory), stdin=io.StringIO("y\n" * len(demos)), stdout=out)
    for demo in demos:
        assert teacher.feedback(demo, _response(demo.key.endswith("/1"))) == 1
    return [Path(p).name for p in re.findall(r"its drawing is in (\S+\.png)", out.getvalue())]


def test_a_second_session_numbers_its_pictures_on_and_keeps_the_first_ones(tmp_path):
    """`iloci teach` twice in one directory: each session has a new ConsoleTeacher, and the
    second one's pictures follow the first one's instead of replacing them."""
    pytest.importorskip("matplotlib")
    first = _session(tmp_path, load_lasa("GShape")[:2])
    assert first == ["answer-0001.png", "answer-0002.png"]
    kept = {name: (tmp_path / name).read_bytes() for name in first}
    second = _session(tmp_path, load_lasa("Sine")[:3])
    assert second == ["answer-0003.png", "answer-0004.png", "answer-0005.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"answer-{i:04d}.png"
                                                          for i in range(1, 6)]
    for name, data in kept.items():
        assert (tmp_path / name).read_bytes() == data, f"{name} was overwritten"
    for name in second:
        assert (tmp_path / name).read_bytes()[:4] == b"\x89PNG"


def test_pictures_follow_the_highest_number_and_never_replace_a_file(tmp_path, monkeypatch):
    """Numbering goes on from the highest ``answer-<n>.png`` there; a name another
    teacher took meanwhile is skipped, not replaced."""
    pytest.importorskip("matplotlib")
    from iloci import teachers

    (tmp_path / "answer-0007.png").write_bytes(b"a person's picture")
    (tmp_path / "answer-12.png").write_bytes(b"unpadded")  # numbers, not names, count
    (tmp_path / "notes.txt").write_text("answer-0099.png is not a picture name")
    (tmp_path / "answer-0050.png.bak").write_bytes(b"not a picture either")
    assert _session(tmp_path, load_lasa("GShape")[:1]) == ["answer-0013.png"]
    # another session takes the next name between the directory scan and the write
    monkeypatch.setattr(teachers, "_last_picture_number", lambda directory: 0)
    (tmp_path / "answer-0001.png").write_bytes(b"taken")
    teacher = ConsoleTeacher(str(tmp_path), stdin=io.StringIO("y\n"), stdout=io.StringIO())
    teacher.feedback(load_lasa("GShape")[0], _response(False))
    assert (tmp_path / "answer-0001.png").read_bytes() == b"taken"
    assert (tmp_path / "answer-0002.png").read_bytes()[:4] == b"\x89PNG"
    assert (tmp_path / "answer-0007.png").read_bytes() == b"a person's picture"
    assert not list(tmp_path.glob(".*.tmp")), "no temporary file left behind"


def _novel(sources: tuple[str, ...]) -> Response:
    motion = np.zeros((20, 2))
    return Response("c9", motion, np.zeros((20, 4)), None, sources, novel=True)


def test_oracle_and_noisy_teachers_judge_the_novelty_answer():
    from iloci.teachers import NoisyTeacher, OracleTeacher

    g, angle = load_lasa("GShape")[0], load_lasa("Angle")[0]
    oracle, noisy1, noisy0 = OracleTeacher(), NoisyTeacher(p=1.0), NoisyTeacher(p=0.0)
    for teacher in (oracle, noisy1, noisy0):  # it knows what it was shown, from the data
        for d in load_lasa(["Angle", "Sine", "GShape"]):
            teacher.show(d)
    # new exactly when no demonstration the memory stands for has its concept
    assert oracle.feedback(g, _novel(("Angle/0", "Sine/1"))) == 1
    assert oracle.feedback(g, _novel(("Angle/0", "GShape/3"))) == -1
    assert oracle.feedback(angle, _novel(())) == 1
    assert noisy1.feedback(g, _novel(("Angle/0",))) == -1
    assert noisy0.feedback(g, _novel(("Angle/0",))) == 1


def test_noisy_teacher_errs_by_demonstration_and_attempt_not_by_call_order():
    """A resumed session re-teaches the interrupted demonstration from attempt
    1: the noisy teacher must answer it as the uninterrupted session did."""
    from iloci.teachers import NoisyTeacher

    demos = [d for s in ("GShape", "Angle", "Sine", "Leaf_1") for d in load_lasa(s)]
    guesses = [(d, Response("c1", np.zeros((20, 2)), np.zeros((20, 4)), d.key, (d.key,),
                            attempt=a)) for d in demos for a in (1, 2, 3)]
    first = NoisyTeacher(p=0.3, seed=7)
    forward = [first.feedback(d, r) for d, r in guesses]
    resumed = NoisyTeacher(p=0.3, seed=7)       # a new process, asked in another order
    backward = [resumed.feedback(d, r) for d, r in reversed(guesses)][::-1]
    assert forward == backward
    flipped = sum(v == -1 for v in forward) / len(forward)   # the oracle says +1 to each
    assert 0.15 < flipped < 0.45, flipped                    # p = 0.3 over 84 draws
    other = [NoisyTeacher(p=0.3, seed=8).feedback(d, r) for d, r in guesses]
    assert other != forward                                  # the seed matters


def test_console_teacher_asks_whether_a_novelty_answer_is_new():
    out = io.StringIO()
    teacher = ConsoleTeacher("", stdin=io.StringIO("y\n"), stdout=out)
    assert teacher.feedback(load_lasa("GShape")[0], _novel(("Angle/0", "Sine/1"))) == 1
    text = out.getvalue()
    assert "something new" in text and "Is it a new concept?" in text


def test_drawing_teacher_judges_only_the_drawing():
    pytest.importorskip("dtaidistance")
    from iloci.data import load_lasa
    from iloci.teachers import DrawingTeacher

    demos = load_lasa(["GShape", "Angle"])
    refs = [d for d in demos if d.index < 6]
    teacher = DrawingTeacher(refs)
    g, angle = demos[6], demos[13]
    assert (g.key, angle.key) == ("GShape/6", "Angle/6")
    t = np.linspace(g.times[0], g.times[-1], 50)
    drawn = np.column_stack([np.interp(t, g.times, g.positions[:, k]) for k in (0, 1)])
    # a G drawn in metres somewhere in the plane: scale and place do not matter
    response = Response("c1", drawn * 0.003 + [0.05, 0.2], np.zeros((50, 4)),
                        source="Angle/0")                    # the label would say "Angle"
    assert teacher.feedback(g, response) == 1
    assert teacher.feedback(angle, response) == -1
    with pytest.raises(FeedbackError, match="reference"):
        DrawingTeacher([])

"""The ``pybullet`` simulator plugin: the shared simulator cases (sim_cases.py), its
settings, and ``iloci draw``."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pybullet")
pytest.importorskip("pinocchio")

from iloci_pinocchio.ik import PinocchioIK
from iloci_pybullet.sim import PyBulletSimulator
from sim_cases import *  # the shared simulator tests

from iloci.config import load_config
from iloci.data import load_lasa
from iloci.errors import ConfigError
from iloci.sensorimotor.robots import get_robot
from iloci.testing import parametrize_with_checks, registry_factory


@pytest.fixture(scope="module")
def make():
    return PyBulletSimulator


@parametrize_with_checks([("simulator", registry_factory("simulator", "pybullet"))])
def test_conformance(component, check):
    check(component)


def test_config_section():
    cfg = load_config({"simulator": {"name": "pybullet", "timestep": 0.002}})
    assert cfg.simulator.params.timestep == 0.002
    with pytest.raises(ConfigError, match="timestep"):
        load_config({"simulator": {"name": "pybullet", "timestep": -1.0}})
    with pytest.raises(ConfigError, match="position_gain"):
        load_config({"simulator": {"name": "pybullet", "position_gain": float("inf")}})
    with pytest.raises(ConfigError, match="substeps"):
        load_config({"simulator": {"name": "pybullet", "substeps": 4}})


# -- iloci draw ------------------------------------------------------------------

@pytest.fixture(scope="module")
def memory_file(tmp_path_factory):
    """A small taught memory: two concepts, a briefly trained torch RNNPB."""
    pytest.importorskip("iloci_native")
    import iloci
    agent = iloci.build({"perceptual_model": {"name": "native-rnnpb", "epochs": 30}})
    agent.teach(load_lasa("GShape")[:1] + load_lasa("Angle")[:1])
    path = tmp_path_factory.mktemp("memory") / "memory.npz"
    agent.save(path)
    return path


def _png_size(path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def test_draw_png(memory_file, tmp_path, capsys):
    from iloci.cli import main
    out = tmp_path / "c1.png"
    assert main(["draw", "--memory", str(memory_file), "--concept", "c1", "--out", str(out),
                 "--size", "200x150"]) == 0
    assert _png_size(out) == (200, 150)
    text = capsys.readouterr().out
    assert "concept c1" in text and "GShape/0" in text and "pybullet" in text
    # the PNG holds the rendered image, pixel for pixel
    plt = pytest.importorskip("matplotlib.pyplot")
    img = (plt.imread(out)[..., :3] * 255).round().astype(np.uint8)
    assert img.shape == (150, 200, 3) and img.std() > 0
    assert not list(tmp_path.glob("*.tmp")), "no temporary file left behind"


def test_draw_by_lasa_concept_name_and_gif(memory_file, tmp_path, capsys):
    from iloci.cli import main
    PIL = pytest.importorskip("PIL.Image")
    out = tmp_path / "angle.gif"
    assert main(["draw", "--memory", str(memory_file), "--concept", "Angle", "--gif",
                 "--out", str(out), "--size", "64x48"]) == 0
    assert "Angle/0" in capsys.readouterr().out
    with PIL.open(out) as gif:
        assert gif.size == (64, 48)
        assert gif.n_frames > 10


@pytest.mark.parametrize("argv, message", [
    (["--concept", "Gshape", "--out", "x.png"], "Did you mean 'GShape'"),
    (["--concept", "c1", "--out", "x.gif"], ".png"),
    (["--concept", "c1", "--gif", "--out", "x.png"], ".gif"),
    (["--concept", "c1", "--out", "x.png", "--size", "big"], "WIDTHxHEIGHT"),
    (["--concept", "c1", "--out", "x.png", "--simulator", "pybulet"], "Did you mean 'pybullet'"),
])
def test_draw_bad_arguments(memory_file, tmp_path, capsys, argv, message):
    from iloci.cli import main
    argv = [str(tmp_path / a) if a.startswith("x.") else a for a in argv]
    assert main(["draw", "--memory", str(memory_file), *argv]) == 2
    assert message in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_draw_missing_memory(tmp_path, capsys):
    from iloci.cli import main
    assert main(["draw", "--memory", str(tmp_path / "none.npz"), "--concept", "c1",
                 "--out", str(tmp_path / "x.png")]) == 2
    assert "none.npz" in capsys.readouterr().err


# -- the learning loop -------------------------------------------------------------

def test_learning_run_executes_responses_and_the_console_teacher_sees_the_drawing(
        tmp_path, monkeypatch):
    """``[simulator] name = "pybullet"``: every response of a learning run is
    executed on the arm, and the console teacher's picture draws the pen path
    the arm reached, not the one the network generated."""
    pytest.importorskip("iloci_native")
    pytest.importorskip("matplotlib")
    import io
    import sys

    from matplotlib.axes import Axes

    import iloci
    from iloci.interfaces import Execution

    pictures = tmp_path / "answers"
    config = tmp_path / "iloci.toml"
    config.write_text(f"""
[perceptual_model]
name = "native-rnnpb"
epochs = 30
[teacher]
name = "console"
picture_dir = "{pictures.as_posix()}"
[simulator]
name = "pybullet"
""")
    # GShape/0 starts concept c1 (nothing to guess yet); GShape/1 is guessed c1,
    # the person says yes; Angle/0 is guessed c1 too, the person says no
    answers = io.StringIO("y\nn\n")
    monkeypatch.setattr(sys, "stdin", answers)
    agent = iloci.build(config)
    assert isinstance(agent.simulator, PyBulletSimulator)

    drawn = []  # each pen path plotted in a picture's right panel, (T, 2)
    shown = []  # (response, the pen path its picture drew)
    plot, feedback = Axes.plot, agent.teacher.feedback

    def spy_plot(ax, *args, **kw):
        if len(args) == 3 and args[2] == "b-":  # the robot's pen path
            drawn.append(np.column_stack([args[0], args[1]]))
        return plot(ax, *args, **kw)

    def spy_feedback(demo, response):
        n = len(drawn)
        value = feedback(demo, response)
        shown.append((response, drawn[n] if len(drawn) > n else None))
        return value

    monkeypatch.setattr(Axes, "plot", spy_plot)
    monkeypatch.setattr(agent.teacher, "feedback", spy_feedback)
    try:
        report = agent.teach([load_lasa("GShape")[0], load_lasa("GShape")[1],
                              load_lasa("Angle")[0]])
    finally:
        agent.simulator.close()

    assert answers.read() == "", "the person was asked fewer times than expected"
    assert len(shown) == 2 and len(report.outcomes) == 3
    assert sorted(p.name for p in pictures.iterdir()) == ["answer-0001.png",
                                                          "answer-0002.png"]
    robot = get_robot()
    for response, picture_path in shown:
        ex = response.execution
        assert isinstance(ex, Execution), "the response was not executed"
        assert ex.joint_path.shape == response.joint_path.shape
        assert ex.end_effector.shape == (len(response.joint_path), 3)
        # the arm drew what its joints say, within the 2 mm of the tracking target
        planned = PinocchioIK().forward(response.joint_path)
        assert np.linalg.norm(ex.end_effector - planned, axis=1).max() < 0.002
        # the picture is the executed drawing, shown in the demonstration's frame:
        # the plane's (y, z) under one uniform scale and a shift
        executed = robot.plane.to_2d(ex.end_effector)
        np.testing.assert_array_equal(response.drawing, executed)
        np.testing.assert_array_equal(picture_path, response.teacher_drawing)
        A = np.column_stack([executed.ravel(), np.tile([1.0, 0.0], len(executed)),
                             np.tile([0.0, 1.0], len(executed))])
        coef, *_ = np.linalg.lstsq(A, picture_path.ravel(), rcond=None)
        assert coef[0] > 0
        np.testing.assert_allclose(A @ coef, picture_path.ravel(), atol=1e-9)
        assert not np.allclose(picture_path, response.motion, atol=1e-6), \
            "the network's pen path and the arm's coincide: the test cannot tell them apart"

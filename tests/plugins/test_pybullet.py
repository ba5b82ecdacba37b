"""The ``pybullet`` simulator plugin: tracking, determinism, rendering, bad input."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pybullet")
pytest.importorskip("pinocchio")

from iloci_pinocchio.ik import PinocchioIK
from iloci_pybullet.sim import PyBulletSimulator

from iloci.config import load_config
from iloci.data import load_lasa
from iloci.errors import ConfigError, IlociError, InvalidInputError
from iloci.interfaces import Execution, Simulator
from iloci.sensorimotor.pipeline import to_motion
from iloci.sensorimotor.robots import get_robot
from iloci.testing import parametrize_with_checks, registry_factory


@pytest.fixture(scope="module")
def sim():
    s = PyBulletSimulator()
    yield s
    s.close()


@pytest.fixture(scope="module")
def ik():
    return PinocchioIK()


@pytest.fixture(scope="module")
def motion(ik):
    return to_motion(load_lasa("GShape")[0], None, ik)


@parametrize_with_checks([("simulator", registry_factory("simulator", "pybullet"))])
def test_conformance(component, check):
    check(component)


def test_satisfies_protocol(sim):
    assert isinstance(sim, Simulator)


def test_tracks_lasa_joint_path_within_2mm(sim, ik, motion):
    ex = sim.execute(motion.joint_path, motion.dt)
    assert isinstance(ex, Execution)
    assert ex.joint_path.shape == motion.joint_path.shape
    assert ex.end_effector.shape == (len(motion), 3)
    assert ex.dt == pytest.approx(motion.dt)
    err = np.linalg.norm(ex.end_effector - ik.forward(motion.joint_path), axis=1)
    assert err.max() < 0.002
    # the arm starts at rest in the first posture: row 0 is exact
    assert err[0] < 1e-6
    # and the reached joint angles are what the pen positions say
    np.testing.assert_allclose(sim.forward(ex.joint_path), ex.end_effector, atol=1e-6)


def test_repeated_execution_is_independent_and_deterministic(sim, motion):
    a = sim.execute(motion.joint_path, motion.dt)
    sim.execute(motion.joint_path[::-1], motion.dt / 2)  # something else in between
    b = sim.execute(motion.joint_path, motion.dt)
    np.testing.assert_array_equal(a.end_effector, b.end_effector)
    np.testing.assert_array_equal(a.joint_path, b.joint_path)


def test_gravity_sags_a_held_posture_only_slightly(motion):
    # hold the first posture for 2 s: the motors must carry the arm's weight
    q = np.repeat(motion.joint_path[:1], 41, axis=0)
    with PyBulletSimulator() as s:
        held = s.execute(q, 0.05)
    with PyBulletSimulator(gravity=0.0) as s:
        free = s.execute(q, 0.05)
    sag = np.linalg.norm(held.end_effector - held.end_effector[0], axis=1).max()
    assert 1e-7 < sag < 0.001, "gravity must act, and the motors must hold the arm"
    assert np.linalg.norm(free.end_effector - free.end_effector[0], axis=1).max() < 1e-9


def test_render_shows_the_drawn_path(sim, ik, motion):
    ex = sim.execute(motion.joint_path, motion.dt)
    img = sim.render(ex, 160, 120)
    assert img.shape == (120, 160, 3) and img.dtype == np.uint8
    blue = (img[..., 2].astype(int) - img[..., 0] > 80) & (img[..., 2] > 120)
    assert blue.sum() > 50, "the pen path is not in the image"
    # half the drawing draws fewer blue pixels; rendering leaves no bodies behind
    half = Execution(ex.joint_path[:25], ex.end_effector[:25], ex.dt)
    img_half = sim.render(half, 160, 120)
    blue_half = (img_half[..., 2].astype(int) - img_half[..., 0] > 80) & (img_half[..., 2] > 120)
    assert 0 < blue_half.sum() < blue.sum()
    np.testing.assert_array_equal(sim.render(ex, 160, 120), img)


def test_a_path_ending_at_a_limit_executes_and_renders():
    """The IK clamps to the limits; the arm may overshoot one a little (soft
    limits), and what it reached must still render and evaluate."""
    robot = get_robot()
    q = np.repeat(robot.q_home[None], 30, axis=0)
    q[:, 1] = np.linspace(robot.q_home[1], robot.upper[1], 30)
    q[:, 3] = np.linspace(robot.q_home[3], robot.lower[3], 30)
    with PyBulletSimulator() as s:
        ex = s.execute(q, 0.02)
        assert np.abs(ex.joint_path - q).max() < 0.01
        np.testing.assert_allclose(s.forward(ex.joint_path), ex.end_effector, atol=1e-6)
        assert s.render(ex, 32, 24).shape == (24, 32, 3)


@pytest.mark.parametrize("bad, what", [
    (lambda q: q[:, :3], "shape"),
    (lambda q: q[:, 0], "shape"),
    (lambda q: q[:0], "shape"),
    (lambda q: np.where(np.arange(q.size).reshape(q.shape) == 7, np.nan, q), "NaN"),
    (lambda q: q + np.array([0, 0, 0, 3.0]), "RElbowRoll"),
    (lambda q: q - np.array([0, 2.0, 0, 0]), "RShoulderRoll"),
    (lambda q: [["a"] * 4] * 3, "numeric"),
])
def test_bad_joint_path(sim, motion, bad, what):
    with pytest.raises(InvalidInputError, match=what):
        sim.execute(bad(np.array(motion.joint_path)), 0.05)


@pytest.mark.parametrize("dt", [0.0, -0.1, float("nan"), float("inf"), "fast"])
def test_bad_dt(sim, motion, dt):
    with pytest.raises(InvalidInputError, match="dt"):
        sim.execute(motion.joint_path, dt)


@pytest.mark.parametrize("size", [(0, 10), (10, -1), (10.5, 10), (True, 10), (10, 10_000)])
def test_bad_image_size(sim, motion, size):
    ex = sim.execute(motion.joint_path[:3], motion.dt)
    with pytest.raises(InvalidInputError, match="width|height"):
        sim.render(ex, *size)


def test_render_rejects_what_is_not_an_execution(sim, motion):
    with pytest.raises(InvalidInputError, match="Execution"):
        sim.render(motion.joint_path, 32, 24)
    ex = Execution(np.array(motion.joint_path), np.zeros((3, 3)), motion.dt)
    with pytest.raises(InvalidInputError, match="end_effector"):
        sim.render(ex, 32, 24)


def test_closed_simulator_says_so(motion):
    s = PyBulletSimulator()
    s.close()
    s.close()  # idempotent
    with pytest.raises(IlociError, match="closed"):
        s.execute(motion.joint_path, motion.dt)


def test_bad_settings():
    with pytest.raises(InvalidInputError, match="timestep"):
        PyBulletSimulator(timestep=0.0)
    with pytest.raises(InvalidInputError, match="gravity"):
        PyBulletSimulator(gravity=-1.0)


def test_config_section():
    cfg = load_config({"simulator": {"name": "pybullet", "timestep": 0.002}})
    assert cfg.simulator.params.timestep == 0.002
    with pytest.raises(ConfigError, match="timestep"):
        load_config({"simulator": {"name": "pybullet", "timestep": -1.0}})
    with pytest.raises(ConfigError, match="substeps"):
        load_config({"simulator": {"name": "pybullet", "substeps": 4}})


def test_robot_object_accepted():
    with PyBulletSimulator(get_robot()) as s:
        assert s.joint_names == get_robot().joint_names


# -- iloci draw ------------------------------------------------------------------

@pytest.fixture(scope="module")
def memory_file(tmp_path_factory):
    """A small taught memory: two concepts, a briefly trained torch RNNPB."""
    pytest.importorskip("torch")
    import iloci
    agent = iloci.build({"perceptual_model": {"name": "torch-rnnpb", "epochs": 30}})
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

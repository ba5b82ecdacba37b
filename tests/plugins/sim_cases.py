"""Behaviour tests every simulator back end must pass (imported by test_pybullet.py
and test_mujoco.py, which provide the module-scoped ``make`` fixture:
``make(**settings)`` builds a simulator of their engine, and may override
``can_render`` when their engine cannot always make images).

These need the Pinocchio IK (the planned pen path of a LASA demonstration);
the importing module skips when it is absent.
"""

from __future__ import annotations

import numpy as np
import pytest

from iloci.data import load_lasa
from iloci.errors import IlociError, InvalidInputError
from iloci.interfaces import Execution, Simulator
from iloci.sensorimotor.pipeline import to_motion
from iloci.sensorimotor.robots import get_robot


@pytest.fixture(scope="module")
def sim(make):
    s = make()
    yield s
    s.close()


@pytest.fixture(scope="module")
def ik():
    from iloci_pinocchio.ik import PinocchioIK
    return PinocchioIK()


@pytest.fixture(scope="module")
def motion(ik):
    return to_motion(load_lasa("GShape")[0], None, ik)


@pytest.fixture(scope="module")
def can_render():
    return True


def _blue(img: np.ndarray) -> np.ndarray:
    """Pixels of the pen's blue, shape (H, W) bool."""
    return (img[..., 2].astype(int) - img[..., 0] > 80) & (img[..., 2] > 120)


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


def test_forward_of_one_posture(sim, ik):
    q = get_robot().q_home
    assert sim.forward(q).shape == (3,)
    np.testing.assert_allclose(sim.forward(q), ik.forward(q[None])[0], atol=1e-6)


def test_repeated_execution_is_independent_and_deterministic(sim, motion):
    a = sim.execute(motion.joint_path, motion.dt)
    sim.execute(motion.joint_path[::-1], motion.dt / 2)  # something else in between
    b = sim.execute(motion.joint_path, motion.dt)
    np.testing.assert_array_equal(a.end_effector, b.end_effector)
    np.testing.assert_array_equal(a.joint_path, b.joint_path)


def test_gravity_sags_a_held_posture_only_slightly(make, motion):
    # hold the first posture for 2 s: the motors must carry the arm's weight
    q = np.repeat(motion.joint_path[:1], 41, axis=0)
    with make() as s:
        held = s.execute(q, 0.05)
    with make(gravity=0.0) as s:
        free = s.execute(q, 0.05)
    sag = np.linalg.norm(held.end_effector - held.end_effector[0], axis=1).max()
    assert 1e-7 < sag < 0.001, "gravity must act, and the motors must hold the arm"
    assert np.linalg.norm(free.end_effector - free.end_effector[0], axis=1).max() < 1e-9


def test_render_shows_the_drawn_path(sim, motion, can_render):
    if not can_render:
        pytest.skip("this engine cannot make images here")
    ex = sim.execute(motion.joint_path, motion.dt)
    img = sim.render(ex, 160, 120)
    assert img.shape == (120, 160, 3) and img.dtype == np.uint8
    assert _blue(img).sum() > 50, "the pen path is not in the image"
    # half the drawing draws fewer blue pixels; rendering leaves nothing behind
    half = Execution(ex.joint_path[:25], ex.end_effector[:25], ex.dt)
    assert 0 < _blue(sim.render(half, 160, 120)).sum() < _blue(img).sum()
    np.testing.assert_array_equal(sim.render(ex, 160, 120), img)


def test_a_path_ending_at_a_limit_executes_and_renders(make, can_render):
    """The IK clamps to the limits; the arm may overshoot one a little (soft
    limits), and what it reached must still render and evaluate."""
    robot = get_robot()
    q = np.repeat(robot.q_home[None], 30, axis=0)
    q[:, 1] = np.linspace(robot.q_home[1], robot.upper[1], 30)
    q[:, 3] = np.linspace(robot.q_home[3], robot.lower[3], 30)
    with make() as s:
        ex = s.execute(q, 0.02)
        assert np.abs(ex.joint_path - q).max() < 0.01
        np.testing.assert_allclose(s.forward(ex.joint_path), ex.end_effector, atol=1e-6)
        if can_render:
            assert s.render(ex, 32, 24).shape == (24, 32, 3)


def _nan_at_step_1(q):
    q = q.copy()
    q[1, 2] = np.nan
    return q


@pytest.mark.parametrize("bad, what", [
    (lambda q: q[:, :3], r"shape \(T, 4\).*got \(50, 3\)"),
    (lambda q: np.hstack([q, q[:, :1]]), r"shape \(T, 4\).*got \(50, 5\)"),
    (lambda q: q[:, 0], "shape"),
    (lambda q: q[:0], "T >= 1"),
    (_nan_at_step_1, "NaN or inf .first at step 1, joint RElbowYaw"),
    (lambda q: q + np.array([0, 0, 0, 3.0]), "RElbowRoll = .* outside its limits"),
    (lambda q: q - np.array([0, 2.0, 0, 0]), "RShoulderRoll = .* outside its limits"),
    (lambda q: [["a"] * 4] * 3, "numeric"),
], ids=["3 columns", "5 columns", "1-D", "empty", "NaN", "above a limit", "below a limit",
        "not numbers"])
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
    ex = Execution(np.array(motion.joint_path)[:, :3], np.zeros((len(motion), 3)), motion.dt)
    with pytest.raises(InvalidInputError, match="shape"):
        sim.render(ex, 32, 24)


def test_closed_simulator_says_so(make, motion):
    s = make()
    s.close()
    s.close()  # idempotent
    with pytest.raises(IlociError, match="closed"):
        s.execute(motion.joint_path, motion.dt)


@pytest.mark.parametrize("settings, what", [
    ({"timestep": 0.0}, "timestep must be > 0"),
    ({"gravity": -1.0}, "gravity must be >= 0"),
    ({"gravity": float("nan")}, "gravity must be a finite number"),
    ({"timestep": float("inf")}, "timestep must be a finite number"),
])
def test_bad_settings(make, settings, what):
    with pytest.raises(InvalidInputError, match=what):
        make(**settings)


def test_robot_object_accepted(make):
    with make(get_robot()) as s:
        assert s.joint_names == get_robot().joint_names
        assert s.robot is not None and np.array_equal(s.lower, get_robot().lower)

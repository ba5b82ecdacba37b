"""PyBullet, MuJoCo and Pinocchio agree on where the same joint path puts the pen."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("iloci_mujoco")  # chooses MuJoCo's OpenGL back end before mujoco loads
pytest.importorskip("mujoco")
pytest.importorskip("pybullet")
pytest.importorskip("pinocchio")

from iloci_mujoco.sim import MuJoCoSimulator
from iloci_pinocchio.ik import PinocchioIK
from iloci_pybullet.sim import PyBulletSimulator

from iloci.data import load_lasa
from iloci.sensorimotor.pipeline import to_motions
from iloci.sensorimotor.robots import get_robot

TOLERANCE_M = 0.001


@pytest.fixture(scope="module")
def engines():
    pb, mj = PyBulletSimulator(), MuJoCoSimulator()
    yield pb, mj, PinocchioIK()
    pb.close()
    mj.close()


def _pairwise_max(paths: dict[str, np.ndarray]) -> dict[str, float]:
    names = list(paths)
    return {f"{a} vs {b}": float(np.linalg.norm(paths[a] - paths[b], axis=1).max())
            for i, a in enumerate(names) for b in names[i + 1:]}


def test_same_kinematics(engines):
    """Postures set directly (no dynamics): the three models of the URDF coincide."""
    pb, mj, ik = engines
    robot = get_robot()
    rng = np.random.default_rng(0)
    q = robot.lower + rng.random((200, 4)) * (robot.upper - robot.lower)
    q = np.vstack([q, robot.lower, robot.upper, robot.q_home])
    gaps = _pairwise_max({"pybullet": pb.forward(q), "mujoco": mj.forward(q),
                          "pinocchio": ik.forward(q)})
    assert max(gaps.values()) < 1e-6, gaps


@pytest.mark.parametrize("shape", ["GShape", "Sine", "Spoon", "heee"])
def test_executed_lasa_paths_agree_within_1mm(engines, shape):
    """The IK joint path of a LASA demonstration, executed in both engines and
    evaluated by Pinocchio's FK, gives the same pen path within 1 mm."""
    pb, mj, ik = engines
    motion = to_motions(load_lasa(shape)[:1], None, ik)[0]
    paths = {"pybullet": pb.execute(motion.joint_path, motion.dt).end_effector,
             "mujoco": mj.execute(motion.joint_path, motion.dt).end_effector,
             "pinocchio": ik.forward(motion.joint_path)}
    gaps = _pairwise_max(paths)
    assert max(gaps.values()) < TOLERANCE_M, gaps


def test_fast_path_agrees_within_1mm(engines):
    """A path 10 times faster than LASA's (a 0.5 s drawing) still agrees."""
    pb, mj, ik = engines
    motion = to_motions(load_lasa("Worm")[:1], None, ik)[0]
    dt = 0.5 / (len(motion) - 1)
    gaps = _pairwise_max({"pybullet": pb.execute(motion.joint_path, dt).end_effector,
                          "mujoco": mj.execute(motion.joint_path, dt).end_effector,
                          "pinocchio": ik.forward(motion.joint_path)})
    assert max(gaps.values()) < TOLERANCE_M, gaps

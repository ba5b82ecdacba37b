"""The ``panda`` and ``ur5`` presets (plugins/iloci-robots, example-robot-data).

Run by ``tox -e robots`` (the only environment installing the 130 MB
example-robot-data); skipped elsewhere unless ``ILOCI_EXPECT_ROBOTS`` is
set, which makes a missing plugin a failure.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

if os.environ.get("ILOCI_EXPECT_ROBOTS"):
    import iloci_robots  # noqa: F401  (fail, do not skip, where the env installs it)
pytest.importorskip("iloci_robots")
pytest.importorskip("pinocchio")

import iloci
from iloci.data import load_lasa
from iloci.sensorimotor.robots import available_robots, get_robot

PRESETS = {"panda": 7, "ur5": 6}


@pytest.fixture(scope="module", params=sorted(PRESETS))
def agent(request):
    return iloci.build({"robot": {"name": request.param},
                        "perceptual_model": {"epochs": 30}})


def test_presets_are_listed_and_described(cli):
    presets = available_robots()
    assert {"nao-v32-right-arm", "panda", "ur5"} <= set(presets)
    for name, J in PRESETS.items():
        robot = get_robot(name)
        assert robot.dof == J and presets[name].joints == J
        assert robot.urdf_path.is_file() and robot.package_dirs
    r = cli("robots")
    assert r.returncode == 0 and "panda" in r.stdout and "ur5" in r.stdout


def test_auto_plane_ik_and_network(agent):
    robot, ik = agent.robot, agent.ik_solver
    J = PRESETS[robot.name]
    assert agent.perceptual_model.input_size == 2 + J
    rep = robot.plane_report
    assert rep["method"] == "auto" and rep["min_joint_margin_deg"] >= 10
    assert rep["min_singular_relative"] >= 0.1
    for demo in load_lasa(["GShape", "Leaf_2", "NShape"])[::7]:
        m = agent.motion(demo)
        assert m.joint_path.shape == (len(m), J)
        err = np.linalg.norm(ik.forward(m.joint_path) - m.targets, axis=1)
        assert err.max() < 1e-4
        assert np.all(m.joint_path >= robot.lower) and np.all(m.joint_path <= robot.upper)
        assert np.abs(np.diff(m.joint_path, axis=0)).max() < 0.2


@pytest.mark.parametrize("engine", ["pybullet", "mujoco"])
def test_engines_load_the_meshes_and_track(agent, engine):
    pytest.importorskip(engine)
    params = ({"kp": 20000.0, "kv": 200.0, "gravity_compensation": True}
              if engine == "mujoco" else {})
    sim = agent.registry.build("simulator", engine, params, robot=agent.robot)
    try:
        m = agent.motion(load_lasa(["Angle"])[0])
        ex = sim.execute(m.joint_path, m.dt)
        assert np.linalg.norm(ex.end_effector - m.targets, axis=1).max() < 2e-3
        img = sim.render(ex, 120, 90)
        assert img.shape == (90, 120, 3) and img.std() > 0
    finally:
        sim.close()


def test_teach_save_load_and_refuse_another_robot(agent, tmp_path):
    from iloci.errors import MemoryFileError
    agent.teach(load_lasa(["GShape", "Angle"])[:2])
    path = agent.save(tmp_path / "m.npz")
    back = iloci.Agent.load(path)
    assert back.robot.name == agent.robot.name
    assert back.perceptual_model.input_size == 2 + PRESETS[agent.robot.name]
    with pytest.raises(MemoryFileError, match=f"learned by robot '{agent.robot.name}'"):
        iloci.Agent.load(path, {"perceptual_model": {"epochs": 30}})

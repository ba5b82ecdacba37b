"""The ``mujoco`` simulator plugin: the shared simulator cases (sim_cases.py), its
settings, the servos at their torque limit, rendering without OpenGL, ``iloci draw``."""

from __future__ import annotations

import numpy as np
import pytest

# the plugin chooses MuJoCo's OpenGL back end: import it before mujoco itself
pytest.importorskip("iloci_mujoco")
pytest.importorskip("mujoco")
pytest.importorskip("pinocchio")

from iloci_mujoco.sim import MuJoCoSimulator
from sim_cases import *  # the shared simulator tests

from iloci.config import load_config
from iloci.data import load_lasa
from iloci.errors import ConfigError, InvalidInputError, MissingBackendError
from iloci.sensorimotor.robots import get_robot
from iloci.testing import parametrize_with_checks, registry_factory


@pytest.fixture(scope="module")
def make():
    return MuJoCoSimulator


def _can_render() -> bool:
    with MuJoCoSimulator() as s:
        ex = s.execute(np.array([get_robot().q_home] * 2), 0.01)
        try:
            s.render(ex, 8, 8)
        except MissingBackendError:
            return False
    return True


CAN_RENDER = _can_render()
needs_gl = pytest.mark.skipif(not CAN_RENDER, reason="no OpenGL context (EGL/OSMesa)")


@pytest.fixture(scope="module")
def can_render():
    return CAN_RENDER


@parametrize_with_checks([("simulator", registry_factory("simulator", "mujoco"))])
def test_conformance(component, check):
    if check.__name__ == "sim_render" and not CAN_RENDER:
        pytest.skip("no OpenGL context (EGL/OSMesa) for offscreen rendering")
    check(component)


def test_servo_settings():
    with pytest.raises(InvalidInputError, match="timestep <= control_period"):
        MuJoCoSimulator(timestep=0.01, control_period=0.001)
    with pytest.raises(InvalidInputError, match="kp"):
        MuJoCoSimulator(kp=float("nan"))
    with pytest.raises(InvalidInputError, match="kv must be >= 0"):
        MuJoCoSimulator(kv=-1.0)


def test_config_section():
    cfg = load_config({"simulator": {"name": "mujoco", "timestep": 0.0005}})
    assert cfg.simulator.params.timestep == 0.0005
    with pytest.raises(ConfigError, match="timestep"):
        load_config({"simulator": {"name": "mujoco", "timestep": -1.0}})
    with pytest.raises(ConfigError, match="timestep"):
        load_config({"simulator": {"name": "mujoco", "timestep": 0.01}})
    with pytest.raises(ConfigError, match="substeps"):
        load_config({"simulator": {"name": "mujoco", "substeps": 4}})


def test_torque_limit_holds_and_stays_stable():
    """A fast path that saturates the servos at its start (the arm at rest, the
    path already moving) must not set them oscillating."""
    robot = get_robot()
    s = np.linspace(0, 1, 60)[:, None]
    mid, half = (robot.lower + robot.upper) / 2, (robot.upper - robot.lower) / 2
    q = mid + 0.2 * half * np.sin(2 * np.pi * s)
    with MuJoCoSimulator() as sim:
        ex = sim.execute(q, 0.02)
    assert np.abs(ex.joint_path - q).max() < 0.01


def test_render_without_opengl_is_a_clear_error(tmp_path):
    """With an OpenGL back end that cannot start, render says what is needed."""
    import subprocess
    import sys
    code = (
        "import numpy as np\n"
        "from iloci.errors import MissingBackendError\n"
        "from iloci.sensorimotor.robots import get_robot\n"
        "try:\n"
        "    from iloci_mujoco.sim import MuJoCoSimulator\n"
        "    s = MuJoCoSimulator()\n"
        "    s.render(s.execute(np.array([get_robot().q_home] * 2), 0.01), 8, 8)\n"
        "except MissingBackendError as e:\n"
        "    print('ERROR', e)\n"
        "else:\n"
        "    print('RENDERED')\n")
    env = {k: v for k, v in __import__("os").environ.items() if k != "DISPLAY"}
    env["MUJOCO_GL"] = "osmesa"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, timeout=120, check=False)
    assert out.returncode == 0, out.stderr
    if "RENDERED" in out.stdout:
        pytest.skip("OSMesa is installed here: rendering works, no error to check")
    assert "ERROR" in out.stdout and "MUJOCO_GL=egl" in out.stdout, out.stdout
    assert "libosmesa6" in out.stdout and "osmesa" in out.stdout


@needs_gl
def test_draw_png_in_mujoco(tmp_path, capsys):
    """`iloci draw --simulator mujoco` on a small taught memory."""
    pytest.importorskip("iloci_native")
    import iloci
    from iloci.cli import main
    agent = iloci.build({"perceptual_model": {"name": "native-rnnpb", "epochs": 30}})
    agent.teach(load_lasa("Angle")[:1])
    memory = tmp_path / "memory.npz"
    agent.save(memory)
    out = tmp_path / "angle.png"
    assert main(["draw", "--memory", str(memory), "--concept", "Angle", "--simulator",
                 "mujoco", "--out", str(out), "--size", "120x90"]) == 0
    assert "in mujoco" in capsys.readouterr().out
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert (int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")) == (120, 90)

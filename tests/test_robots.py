"""Any robot arm from its URDF: description, errors, automatic plane, IK, memory, executors.

The arm is a small five-joint URDF with STL meshes written per test session
(tests/robot_cases.py); the Panda and UR5 presets are tested in
tests/plugins/test_robot_presets.py (they need example-robot-data).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import iloci
from iloci.errors import InvalidInputError, MemoryFileError
from iloci.sensorimotor.robots import DrawingPlane, describe_robot, get_robot
from iloci.sensorimotor.robots.urdf import read_urdf, resolve_uri, resolved_urdf_text
from robot_cases import REST, write_test_arm


@pytest.fixture(scope="session")
def arm_urdf(tmp_path_factory) -> Path:
    return write_test_arm(tmp_path_factory.mktemp("arm"))


def arm_config(urdf: Path, **robot) -> dict:
    return {"robot": {"name": "testarm", "urdf": str(urdf), "tip_frame": "pen",
                      "rest": REST, **robot}}


# ---------------------------------------------------------------- description
def test_describe_defaults_to_the_movable_joints_from_root_to_tip(arm_urdf):
    r = describe_robot(arm_urdf, tip_frame="pen")
    assert r.base_frame == "base" and r.joint_names == ("j1", "j2", "j3", "j4", "j5")
    assert r.dof == 5 and r.fixed_joints == {"grip": 0.0}
    np.testing.assert_allclose(r.lower, [-2.5, -1.8, -2.4, -2.0, -2.8])
    assert r.rest is None and np.allclose(r.q_home, 0)  # mid-range when no rest is given
    assert r.plane_report == {"method": "placeholder"}
    r2 = describe_robot(arm_urdf, tip_frame="pen", joints=["j4", "j2", "j3"], rest=[1, 0, 1])
    assert r2.joint_names == ("j4", "j2", "j3") and r2.rest.tolist() == [1, 0, 1]


def test_frame_and_joint_errors_name_the_fix(arm_urdf):
    with pytest.raises(InvalidInputError, match=r"pen-tip frame 'pne'.*Did you mean 'pen'"):
        describe_robot(arm_urdf, tip_frame="pne")
    with pytest.raises(InvalidInputError, match=r"base frame 'bas'.*Did you mean 'base'"):
        describe_robot(arm_urdf, base_frame="bas", tip_frame="pen")
    with pytest.raises(InvalidInputError, match=r"joint 'j6'.*Did you mean"):
        describe_robot(arm_urdf, tip_frame="pen", joints=["j1", "j6"])
    with pytest.raises(InvalidInputError, match=r"'grip' does not move the pen tip"):
        describe_robot(arm_urdf, tip_frame="pen", joints=["j1", "grip"])
    with pytest.raises(InvalidInputError, match=r"does not hang below the base frame 'l3'"):
        describe_robot(arm_urdf, base_frame="l3", tip_frame="camera")
    with pytest.raises(InvalidInputError, match="rest posture must be 5 finite angles"):
        describe_robot(arm_urdf, tip_frame="pen", rest=[0.0, 0.0])
    with pytest.raises(InvalidInputError, match="outside the limits"):
        describe_robot(arm_urdf, tip_frame="pen", rest=[3.0, 0, 0, 0, 0])


def test_urdf_not_found_is_one_clear_error(tmp_path, cli):
    with pytest.raises(InvalidInputError, match="URDF not found: .*missing.urdf"):
        iloci.build({"robot": {"urdf": str(tmp_path / "missing.urdf"), "tip_frame": "pen"}})
    with pytest.raises(InvalidInputError, match="URDF not found: cannot resolve"):
        describe_robot("package://no_such_pkg/robot.urdf", tip_frame="pen")
    (tmp_path / "bad.urdf").write_text("<robot><link name='a'>")
    with pytest.raises(InvalidInputError, match="not valid XML"):
        describe_robot(tmp_path / "bad.urdf", tip_frame="a")
    cfg = tmp_path / "c.toml"
    cfg.write_text('[robot]\nurdf = "nowhere.urdf"\ntip_frame = "pen"\n')
    r = cli("robots", "--show", "--config", str(cfg))
    assert r.returncode == 2 and "URDF not found" in r.stderr and "Traceback" not in r.stderr


def test_mesh_names_resolve_like_ros(arm_urdf, tmp_path):
    tree = read_urdf(arm_urdf)
    assert tree.root == "base" and "grip" in tree.joints
    pkg_root = arm_urdf.parent.parent.parent
    box = pkg_root / "testarm" / "meshes" / "box.stl"
    # package:// from the directories above the URDF, from package_dirs, relative paths
    assert resolve_uri("package://testarm/meshes/box.stl", arm_urdf.parent) == box
    assert resolve_uri("package://testarm/meshes/box.stl", tmp_path, (pkg_root,)) == box
    assert resolve_uri("../meshes/box.stl", arm_urdf.parent).resolve() == box.resolve()
    with pytest.raises(InvalidInputError, match="package 'other' not found"):
        resolve_uri("package://other/box.stl", arm_urdf.parent)
    text = resolved_urdf_text(arm_urdf)
    assert "package://" not in text and text.count(str(box.resolve())) == 12


def test_plane_orientation_round_trips():
    nao = get_robot().plane
    assert nao.axes.tolist() == [[0, 1, 0], [0, 0, 1], [1, 0, 0]]
    tilted = DrawingPlane(0.3, 0.1, 0.2, 0.1, 0.05, normal=(1, 1, 0), up=(0, 0, 1))
    p2 = np.array([[0.01, 0.2], [0.05, 0.25]])
    p3 = tilted.to_3d(p2)
    np.testing.assert_allclose(tilted.to_2d(p3), p2, atol=1e-12)
    np.testing.assert_allclose((p3 - tilted.origin) @ np.array(tilted.normal), 0, atol=1e-12)
    np.testing.assert_allclose(tilted.to_3d(tilted.center[None])[0], tilted.origin, atol=1e-12)
    with pytest.raises(InvalidInputError, match="orthogonal"):
        DrawingPlane(0.3, 0, 0, 0.1, 0.1, normal=(1, 0, 0), up=(1, 0, 1))


def test_config_section_validates(tmp_path):
    from iloci.config import load_config
    from iloci.errors import ConfigError
    with pytest.raises(ConfigError, match="urdf needs tip_frame"):
        load_config({"robot": {"urdf": "a.urdf"}})
    with pytest.raises(ConfigError, match=r"plane must be 'auto' or \[x, y, z, width, height\]"):
        load_config({"robot": {"plane": "manual"}})
    with pytest.raises(ConfigError, match="unknown key 'robot.tipframe'.*tip_frame"):
        load_config({"robot": {"tipframe": "pen"}})
    cfg = load_config({"robot": {"plane": [0.2, 0, 0.3, 0.1, 0.1]}})
    assert cfg.robot.plane == (0.2, 0.0, 0.3, 0.1, 0.1)
    # the plane's orientation is checked with the config (config check), not first when
    # the plane is placed (an audit: plane_normal parallel to plane_up passed the check)
    with pytest.raises(ConfigError, match=r"plane_normal \[0.0, 0.0, 1.0\] and plane_up "
                       r"\[0.0, 0.0, 1.0\] must be orthogonal \(0.0 deg apart\)"):
        load_config({"robot": {"plane_normal": [0, 0, 1]}})
    with pytest.raises(ConfigError, match="plane_up must be a direction"):
        load_config({"robot": {"plane_up": [0, 0, 0]}})
    cfg = load_config({"robot": {"plane_normal": [0, 2, 0], "plane_up": [0, 0, 0.5]}})
    assert cfg.robot.plane_normal == (0.0, 2.0, 0.0)  # any length: DrawingPlane scales it


# ------------------------------------------------------- IK, plane, agent (pinocchio)
pin = pytest.importorskip("pinocchio")


@pytest.fixture(scope="module")
def arm_agent(arm_urdf):
    return iloci.build({**arm_config(arm_urdf), "perceptual_model": {"epochs": 30}})


def test_automatic_plane_keeps_its_margins(arm_agent):
    robot, ik = arm_agent.robot, arm_agent.ik_solver
    rep = robot.plane_report
    assert rep["method"] == "auto" and robot.plane.width == pytest.approx(0.3)  # the cap
    assert rep["min_joint_margin_deg"] >= 10.0 and rep["min_singular_relative"] >= 0.1
    assert robot.plane.to_3d(robot.plane.corners).min(axis=0)[2] - rep["edge_m"] >= 0
    # independently: a 21 x 21 grid over the grown plane, warm-started, every joint
    # >= 10 degrees inside its limits and every point reached
    g = np.linspace(-0.5, 0.5, 21)
    big = robot.plane.grown(rep["edge_m"])
    pts = np.array([[a, b] for b in g for a in (g if int((b + 0.5) * 20) % 2 == 0
                                                  else g[::-1])]) * big.size + big.center
    q = ik.solve(robot.plane.to_3d(pts), robot.q_home)
    err = np.linalg.norm(ik.forward(q) - robot.plane.to_3d(pts), axis=1)
    assert err.max() < 1e-4
    margin = np.minimum(q - robot.lower, robot.upper - q).min()
    assert math.degrees(margin) >= 10.0


def test_network_and_encoding_are_sized_from_the_robot(arm_agent):
    from iloci.data import load_lasa
    assert arm_agent.perceptual_model.input_size == 7  # 2 + 5 joints
    assert arm_agent.config.perceptual_model.params.input_size == 7
    demos = load_lasa(["GShape", "Angle"])[:2]
    arm_agent.teach(demos)
    enc = arm_agent.memory.encoder
    assert enc.scale_.shape == (7,)
    seq, start = enc.encode(arm_agent.motion(demos[0]))
    assert seq.shape[1] == 7 and start.shape == (7,)
    _, joints = enc.decode(seq, start)
    assert joints.shape == (len(seq) + 1, 5)
    from iloci.errors import ConfigError
    with pytest.raises(ConfigError, match=r"input_size is 5, but robot 'testarm' gives .* 7 "
                                          r"features per step \(dy, dz, dq1, .* dq5\)"):
        iloci.build({**arm_config(arm_agent.robot.urdf_path),
                     "perceptual_model": {"input_size": 5}})


def test_redundant_ik_stays_continuous_and_near_rest(arm_agent, arm_urdf):
    from iloci.data import load_lasa
    ik, robot = arm_agent.ik_solver, arm_agent.robot
    rest = np.array(REST)
    for demo in load_lasa(["Sshape", "WShape", "Leaf_1"])[::7]:
        m = arm_agent.motion(demo)
        np.testing.assert_array_less(np.linalg.norm(ik.forward(m.joint_path) - m.targets,
                                                    axis=1), 1e-4)
        assert np.abs(np.diff(m.joint_path, axis=0)).max() < 0.2
        # j5 (a roll about the pen's own axis) does not move the pen: the null-space
        # pull keeps it at rest
        np.testing.assert_allclose(m.joint_path[:, 4], rest[4], atol=1e-6)
    # ten times round a circle: the minimum-norm steps alone drift along the
    # self-motion; the null-space pull brings the arm back to where it started
    pl = robot.plane
    t = np.linspace(0, 20 * np.pi, 1000)
    pts = pl.to_3d(pl.center + 0.12 * np.column_stack([np.cos(t), np.sin(t)]))
    without = iloci.build({**arm_config(arm_urdf), "ik": {"posture_gain": 0.0}})
    drift = {}
    for name, solver in (("pull", ik), ("none", without.ik_solver)):
        q = solver.solve(pts, robot.q_home)
        drift[name] = float(np.linalg.norm(q[-1] - q[0]))
        assert np.abs(np.diff(q, axis=0)).max() < 0.05
    assert drift["pull"] < 1e-4
    assert drift["none"] > 0.005


def test_no_reachable_plane_says_what_to_relax(arm_urdf):
    from iloci.sensorimotor.robots.plane import NoReachablePlaneError
    with pytest.raises(NoReachablePlaneError, match="no drawing plane found for 'testarm'.*"
                                                    "plane_min_up"):
        iloci.build(arm_config(arm_urdf, plane_min_up=2.0))


def test_no_plane_for_an_arm_whose_base_frame_is_below_its_joints_says_so(arm_urdf):
    """An audit's base_frame one link too low (below the shoulder joints, which iloci then
    holds still) got the plane search's advice only; the error now says which joints the
    arm has and which movable joints lie above its base."""
    from iloci.sensorimotor.robots.plane import NoReachablePlaneError
    with pytest.raises(NoReachablePlaneError) as err:
        iloci.build(arm_config(arm_urdf, base_frame="l3", rest=[]))
    message = str(err.value)
    assert "moves 2 joint(s): j4, j5" in message
    assert "below the movable joint(s) j1, j2, j3" in message
    assert "the URDF's root is 'base'" in message
    with pytest.raises(NoReachablePlaneError) as err:  # a right base: no such sentence
        iloci.build(arm_config(arm_urdf, plane_min_up=2.0))
    assert "moves 5 joint(s)" in str(err.value) and "below the movable" not in str(err.value)


def test_given_plane_gets_a_start_posture_at_its_centre(arm_urdf):
    agent = iloci.build(arm_config(arm_urdf, plane=[0.25, 0.0, 0.35, 0.12, 0.12]))
    robot = agent.robot
    assert robot.plane_report["method"] == "given"
    np.testing.assert_allclose(agent.ik_solver.forward(robot.q_home), [0.25, 0.0, 0.35],
                               atol=1e-6)


def test_memory_records_its_robot_and_refuses_another(arm_agent, tmp_path):
    path = arm_agent.save(tmp_path / "arm.npz")
    from iloci.concepts.memory import load_memory
    header = load_memory(path)[2]
    assert header["robot"]["name"] == "testarm" and len(header["robot"]["joints"]) == 5
    again = iloci.Agent.load(path)  # its own robot, from the saved config
    assert again.robot.joint_names == arm_agent.robot.joint_names
    with pytest.raises(MemoryFileError, match=r"learned by robot 'testarm' with 5 joints.*"
                                              r"'nao-v32-right-arm' has 4"):
        iloci.Agent.load(path, {"perceptual_model": {"epochs": 30}})


def test_a_memory_refuses_its_arm_once_the_urdf_moved_its_joints(tmp_path):
    """An audit lengthened a link of a taught arm's URDF by 1 cm: the memory was read,
    and taught further, with the other arm's kinematics, without a word."""
    import shutil

    from iloci.sensorimotor.robots.urdf import kinematics_fingerprint

    urdf = write_test_arm(tmp_path / "a")
    agent = iloci.build({**arm_config(urdf), "perceptual_model": {"epochs": 30}})
    path = agent.save(tmp_path / "arm.npz")
    before = path.read_bytes()
    text = urdf.read_text()
    urdf.write_text(text.replace("<robot", "<!-- a comment -->\n<robot", 1)
                    .replace('<joint name="grip"', '<joint name="grip" '))  # no motion
    assert iloci.Agent.load(path).robot.name == "testarm"
    fp = kinematics_fingerprint(urdf, "base", "pen")
    urdf.write_text(text.replace('<origin xyz="0 0 0.25"/>', '<origin xyz="0 0 0.26"/>'))
    assert kinematics_fingerprint(urdf, "base", "pen") != fp
    with pytest.raises(MemoryFileError, match=r"the arm's joints from 'base' to 'pen' in "
                                              r".*arm.urdf have changed since"):
        iloci.Agent.load(path)
    assert path.read_bytes() == before
    # the arm recorded is the one the robot was built with, not the file at save time
    urdf.write_text(text)
    agent = iloci.build({**arm_config(urdf), "perceptual_model": {"epochs": 30}})
    urdf.write_text(text.replace('<origin xyz="0 0 0.25"/>', '<origin xyz="0 0 0.26"/>'))
    later = agent.save(tmp_path / "later.npz")   # while serving, someone edits the URDF
    with pytest.raises(MemoryFileError, match=r"have changed since"):
        iloci.Agent.load(later)
    shutil.rmtree(tmp_path / "a")


def test_a_urdf_in_millimetres_is_pointed_out(tmp_path):
    import re
    import warnings

    urdf = write_test_arm(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the arm in metres: no warning
        describe_robot(urdf, tip_frame="pen")
    urdf.write_text(re.sub(r'<origin xyz="0 0 ([\d.]+)"/>',
                           lambda m: f'<origin xyz="0 0 {1000 * float(m.group(1)):g}"/>',
                           urdf.read_text()))
    with pytest.warns(UserWarning, match=r"the arm from 'base' to 'pen' is 700\.1 m long.*"
                                         r"was it written in millimetres"):
        describe_robot(urdf, tip_frame="pen")


def test_a_joint_without_an_axis_or_with_nan_is_refused_naming_it(tmp_path):
    urdf = write_test_arm(tmp_path)
    text = urdf.read_text()
    urdf.write_text(text.replace('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>', 1))
    with pytest.raises(InvalidInputError, match=r"joint 'j2' has <axis xyz=\"0 0 0\">, a "
                                                r"zero vector"):
        read_urdf(urdf)
    urdf.write_text(text.replace('<origin xyz="0 0 0.25"/>', '<origin xyz="0 0 nan"/>'))
    with pytest.raises(InvalidInputError, match=r"origin xyz '0 0 nan' holds nan or inf"):
        read_urdf(urdf)
    with pytest.raises(InvalidInputError, match=r"is a directory; give the robot's .urdf"):
        read_urdf(urdf.parent)


# -------------------------------------------------------------- IK conformance
def test_conformance_catches_a_solver_that_jumps_between_branches():
    """The IK contract requires a continuous joint path (``ik_continuous_path``)."""
    from iloci.testing import check_component
    from iloci_pinocchio.ik import PinocchioIK

    class Jumpy(PinocchioIK):
        """Solves every point from a fixed posture, as a naive wrapper of a
        global IK would: often another solution branch than its neighbour's."""

        def solve(self, points, q0=None):
            starts = (self.robot.q_home, (self.lower + self.upper) / 2)
            return np.vstack([super(Jumpy, self).solve(np.asarray(points)[i:i + 1],
                                                       starts[i % 2])
                              for i in range(len(points))])

    assert check_component(lambda seed: PinocchioIK(), "ik",
                           checks=["ik_continuous_path"])[0].passed
    res = check_component(lambda seed: Jumpy(), "ik", checks=["ik_continuous_path"],
                          raise_on_failure=False)
    assert not res[0].passed and "joint path jumps" in res[0].message


# ------------------------------------------------------------- engines, executor
@pytest.mark.parametrize("engine", ["pybullet", "mujoco"])
def test_simulators_load_the_urdf_with_its_meshes_and_track(arm_agent, engine):
    pytest.importorskip(engine)
    from iloci.data import load_lasa
    params = {"mujoco": {"gravity_compensation": True, "kp": 5000.0, "kv": 50.0}}.get(engine, {})
    sim = arm_agent.registry.build("simulator", engine, params, robot=arm_agent.robot)
    try:
        m = arm_agent.motion(load_lasa(["GShape"])[0])
        ex = sim.execute(m.joint_path, m.dt)
        assert np.linalg.norm(ex.end_effector - m.targets, axis=1).max() < 2e-3
        np.testing.assert_allclose(sim.forward(m.joint_path[:5]),
                                   arm_agent.ik_solver.forward(m.joint_path[:5]), atol=1e-6)
        img = sim.render(ex, 96, 72)
        assert img.shape == (72, 96, 3) and img.std() > 0
    finally:
        sim.close()


def test_arm_executor_starts_from_the_current_posture(arm_agent):
    """A real arm's executor: Simulator protocol, no render, approach first.

    The plant is a PyBullet arm stepped by the driver (a real physics engine
    standing in for the hardware).
    """
    pytest.importorskip("pybullet")
    from iloci.data import load_lasa
    from iloci.sensorimotor.hardware import ArmExecutor
    from iloci.testing import check_component

    class PyBulletArm:
        """Driver: each command holds a set-point for one control period."""

        def __init__(self, sim, q, period=0.005):
            self.sim, self.period = sim, period
            self.c = sim._c
            sim._set_posture(q)
            self.c.setTimeStep(0.001)

        def read_joints(self):
            return np.array(self.sim._joint_positions())

        def command(self, position, velocity):
            import pybullet as pb
            for _ in range(round(self.period / 0.001)):
                self.c.setJointMotorControlArray(
                    self.sim._body, self.sim._joints, pb.POSITION_CONTROL,
                    targetPositions=list(position), targetVelocities=list(velocity),
                    forces=self.sim._forces, positionGains=[0.1] * 5, velocityGains=[1.0] * 5)
                self.c.stepSimulation()

        def close(self):
            self.sim.close()

    robot = arm_agent.robot

    def make(seed=0):
        sim = arm_agent.registry.build("simulator", "pybullet", robot=robot)
        return ArmExecutor(PyBulletArm(sim, np.array(REST)), robot, arm_agent.ik_solver.forward,
                           control_period=0.005, sleep=lambda s: None)

    ex_ = make()
    m = arm_agent.motion(load_lasa(["Angle"])[0])
    ex = ex_.execute(m.joint_path, m.dt)
    np.testing.assert_allclose(ex_.last_approach[0], REST, atol=1e-6)
    np.testing.assert_allclose(ex_.last_approach[-1], m.joint_path[0])
    assert np.abs(np.diff(ex_.last_approach, axis=0)).max() <= 0.5 * m.dt + 1e-9
    assert np.linalg.norm(ex.end_effector - m.targets, axis=1).max() < 2e-3
    assert not hasattr(ex_, "render")
    ex_.close()
    # accepted by build() and by the conformance suite without render
    agent = iloci.build(arm_config(robot.urdf_path), simulator=make())
    assert agent.simulator is not None
    check_component(make, "simulator")


class _ArmPlugin:
    """Registers robot ``name`` (the Nao's description under that name)."""

    def __init__(self, name: str, joints: int = 4) -> None:
        self.robot_name, self.joints = name, joints

    from iloci import hookimpl

    @hookimpl
    def iloci_register_robots(self, registry):
        from iloci.sensorimotor.robots.presets import nao_v32_right_arm
        registry.add(self.robot_name, nao_v32_right_arm, summary="the Nao, renamed",
                     joints=self.joints, plane="given")


class _OldArmPlugin:
    """The deprecated dict form of ``iloci_register_robots``."""

    def __init__(self, name: str) -> None:
        self.robot_name = name

    from iloci import hookimpl

    @hookimpl
    def iloci_register_robots(self, robots):
        from iloci.sensorimotor.robots import ROBOTS
        import dataclasses
        robots[self.robot_name] = dataclasses.replace(ROBOTS["nao-v32-right-arm"],
                                                      name=self.robot_name)


BUILT_IN = "iloci.sensorimotor.robots.presets"


def test_robots_are_a_kind_of_the_registry_with_provenance():
    from iloci.plugins import get_plugin_manager, get_registry
    from iloci.sensorimotor.robots import available_robots

    one = _ArmPlugin("house-arm")
    pm = get_plugin_manager(autoload=False, plugins=[one])
    registry = get_registry(pm)
    spec = registry.get("robot", "house-arm")
    assert (spec.plugin, spec.distribution) == (pm.get_name(one), None)
    assert dict(spec.facts) == {"joints": 4, "plane": "given"}
    nao = registry.get("robot", "nao-v32-right-arm")
    assert (nao.plugin, nao.distribution) == (BUILT_IN, "iloci")
    found = available_robots(pm)
    assert found["house-arm"].plugin == pm.get_name(one)
    assert (found["nao-v32-right-arm"].plugin, found["nao-v32-right-arm"].source) == \
        (BUILT_IN, "iloci")
    # built through the registry: the factory's result is checked, then returned
    assert found["house-arm"].make().joint_names == get_robot().joint_names
    assert get_robot("house-arm", pm).describe() == get_robot().describe()


def test_a_robot_registered_twice_names_both_plugins():
    from iloci.errors import PluginError
    from iloci.plugins import get_plugin_manager
    from iloci.sensorimotor.robots import available_robots

    one, two = _ArmPlugin("house-arm"), _ArmPlugin("house-arm")
    pm = get_plugin_manager(autoload=False, plugins=[one, two])
    with pytest.raises(PluginError, match=r"robot 'house-arm' is registered twice: by plugin "
                       rf"'{pm.get_name(one)}' and by plugin '{pm.get_name(two)}'"):
        available_robots(pm)
    pm = get_plugin_manager(autoload=False, plugins=[_ArmPlugin("nao-v32-right-arm")])
    with pytest.raises(PluginError, match=r"robot 'nao-v32-right-arm' is registered twice: "
                       rf"by plugin '{BUILT_IN}' \(distribution iloci\) and by plugin"):
        get_robot("nao-v32-right-arm", pm)


def test_a_robot_preset_that_is_not_what_its_registration_says_is_refused():
    """An audit's plugin registered the Nao's 4-joint arm with joints=6: `iloci robots`
    listed 6 joints and every command built and used the arm without a word. Building the
    preset now checks its registration, naming the plugin."""
    from iloci.errors import PluginError
    from iloci.plugins import get_plugin_manager

    plugin = _ArmPlugin("nao-copy", joints=6)
    pm = get_plugin_manager(autoload=False, plugins=[plugin])
    with pytest.raises(PluginError, match=rf"robot 'nao-copy' of plugin '{pm.get_name(plugin)}'"
                       r".*registered with joints=6, but the robot its factory builds moves 4 "
                       r"\(RShoulderPitch, RShoulderRoll, RElbowYaw, RElbowRoll\)"):
        get_robot("nao-copy", pm)
    right = get_plugin_manager(autoload=False, plugins=[_ArmPlugin("nao-copy")])
    assert get_robot("nao-copy", right).dof == 4


def test_iloci_robots_lists_a_broken_preset_as_broken_and_the_others_as_before(monkeypatch,
                                                                                capsys):
    import json

    import iloci.commands.robots as robots_command
    from iloci.cli import main
    from iloci.plugins import get_plugin_manager, get_registry

    plugin = _ArmPlugin("nao-copy", joints=6)
    pm = get_plugin_manager(autoload=False, plugins=[plugin])
    monkeypatch.setattr(robots_command, "get_registry", lambda: get_registry(pm))
    assert main(["robots", "--json"]) == 0
    listed = {r["name"]: r for r in json.loads(capsys.readouterr().out)}
    assert listed["nao-v32-right-arm"]["status"] == "available"
    assert listed["nao-copy"]["status"].startswith("broken: robot 'nao-copy' of plugin")
    assert main(["robots"]) == 0
    assert "(broken: robot 'nao-copy'" in capsys.readouterr().out


def test_a_robot_registration_must_state_its_joints_and_plane():
    from iloci.errors import PluginError
    from iloci.plugins import get_plugin_manager, get_registry

    class Vague:
        from iloci import hookimpl

        @hookimpl
        def iloci_register_robots(self, registry):
            registry.add("vague-arm", "iloci.sensorimotor.robots.presets:nao_v32_right_arm")

    with pytest.raises(PluginError, match=r"robot 'vague-arm' must state joints, plane"):
        get_registry(get_plugin_manager(autoload=False, plugins=[Vague()]))


def test_the_old_dict_hook_still_registers_with_a_deprecation_warning():
    from iloci.errors import PluginError
    from iloci.plugins import get_plugin_manager, get_registry

    old = _OldArmPlugin("house-arm")
    pm = get_plugin_manager(autoload=False, plugins=[old])
    with pytest.warns(DeprecationWarning, match=rf"plugin '{pm.get_name(old)}' registers "
                      r"robots through iloci_register_robots\(robots\), a dict: deprecated"):
        registry = get_registry(pm)
    spec = registry.get("robot", "house-arm")
    assert spec.plugin == pm.get_name(old) and dict(spec.facts) == {"joints": 4,
                                                                    "plane": "given"}
    assert registry.build("robot", "house-arm").joint_names == get_robot().joint_names
    # a collision through the old form is the registry's error too, naming both
    pm = get_plugin_manager(autoload=False, plugins=[_ArmPlugin("house-arm"), old])
    with pytest.warns(DeprecationWarning), pytest.raises(
            PluginError, match=r"robot 'house-arm' is registered twice: by plugin '.*' "
                               rf"and by plugin '{pm.get_name(old)}'"):
        get_registry(pm)


def test_iloci_plugins_and_iloci_robots_list_the_registry_robots(capsys):
    import json

    from iloci.cli import main

    assert main(["plugins", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["components"]
    robots = {r["name"]: r for r in rows if r["kind"] == "robot"}
    assert robots["nao-v32-right-arm"]["distribution"] == "iloci"
    assert robots["nao-v32-right-arm"]["facts"] == {"joints": 4, "plane": "given"}
    assert main(["robots", "--json"]) == 0
    listed = {r["name"]: r for r in json.loads(capsys.readouterr().out)}
    assert set(listed) == set(robots)
    assert listed["nao-v32-right-arm"]["plugin"] == BUILT_IN
    for name, r in listed.items():
        assert (r["source"], r["joints"], r["plane"]) == (
            robots[name]["distribution"], robots[name]["facts"]["joints"],
            robots[name]["facts"]["plane"])


def test_config_check_looks_the_robot_preset_up_in_the_registry():
    from iloci.config import check_installed, load_config
    from iloci.errors import MissingBackendError, PluginNotLoadedError, UnknownComponentError
    from iloci.interfaces import KINDS
    from iloci.plugins import get_plugin_manager, get_registry

    def config(robot):  # the components stand supplied: only the robot is looked up
        return load_config({"robot": robot}, supplied=KINDS)

    # iloci-robots blocked where it is installed, absent elsewhere
    registry = get_registry(get_plugin_manager(block=["robots"]))
    with pytest.raises(UnknownComponentError, match=r"\[robot\] name: unknown robot "
                       r"'nao-v32-rigt-arm'.* Did you mean 'nao-v32-right-arm'\?"):
        check_installed(config({"name": "nao-v32-rigt-arm"}), registry)
    # a first-party preset whose plugin is not loaded: what to install or unblock
    with pytest.raises((MissingBackendError, PluginNotLoadedError), match="iloci-robots"):
        check_installed(config({"name": "panda"}), registry)
    # a URDF of one's own needs no preset
    check_installed(config({"name": "panda", "urdf": str(get_robot().urdf_path),
                            "tip_frame": "r_pen_tip"}), registry)


def test_robots_show_gives_a_prismatic_joints_range_in_millimetres(arm_urdf):
    """`iloci robots --show` printed a prismatic joint's range (metres) as degrees."""
    from iloci.commands.robots import _prismatic

    assert _prismatic({"urdf": str(arm_urdf), "joints": ["j1", "grip", "j2"]}) == {"grip"}
    assert _prismatic({"urdf": "gone.urdf", "joints": ["j1"]}) == set()

"""The ``pinocchio`` IK solver, checked against independent engines and the LASA data."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pinocchio")

from iloci.config import SensorimotorConfig
from iloci.data import load_lasa
from iloci.errors import ConfigError, InvalidInputError, UnreachableTargetError
from iloci.interfaces import IKSolver
from iloci.plugins import get_registry
from iloci.sensorimotor.encoding import SensorimotorEncoder
from iloci.sensorimotor.pipeline import Motion, to_motion, to_motions
from iloci.sensorimotor.robots import get_robot

N_POSES = 1000


@pytest.fixture(scope="module")
def robot():
    return get_robot()


@pytest.fixture(scope="module")
def ik():
    return get_registry().build("ik", "pinocchio")


@pytest.fixture(scope="module")
def poses(robot):
    rng = np.random.default_rng(12345)
    return rng.uniform(robot.lower, robot.upper, size=(N_POSES, 4))


def test_registered_by_name_and_satisfies_protocol(ik, robot):
    from iloci_pinocchio.ik import PinocchioIK

    assert isinstance(ik, PinocchioIK) and isinstance(ik, IKSolver)
    spec = get_registry().get("ik", "pinocchio")
    assert spec.distribution == "iloci-pinocchio"
    assert ik.joint_names == robot.joint_names
    assert np.array_equal(ik.lower, robot.lower) and np.array_equal(ik.upper, robot.upper)


def test_forward_at_zero_is_the_v32_geometry(ik):
    # arm straight forward: shoulder (0, -98, 100) mm + upper arm 90 + lower arm 50.55
    # + hand (58, 0, -15.9) mm
    expected = np.array([0.090 + 0.05055 + 0.058, -0.098, 0.100 - 0.0159])
    assert np.allclose(ik.forward(np.zeros(4)), expected, atol=1e-12)
    # RElbowRoll = +90 deg turns the forearm and hand towards the body (+y)
    q = np.array([0.0, 0.0, 0.0, np.pi / 2])
    assert np.allclose(ik.forward(q), [0.090, -0.098 + 0.10855, 0.100 - 0.0159], atol=1e-12)


def test_forward_shapes(ik, poses):
    assert ik.forward(poses[0]).shape == (3,)
    many = ik.forward(poses[:7])
    assert many.shape == (7, 3)
    assert np.array_equal(many[3], ik.forward(poses[3]))
    for bad in (np.zeros(3), np.zeros((2, 5)), np.zeros((2, 2, 4))):
        with pytest.raises(InvalidInputError, match=r"shape \(T, 4\)"):
            ik.forward(bad)
    with pytest.raises(InvalidInputError, match="NaN or inf"):
        ik.forward([0.0, np.nan, 0.0, 0.0])


def test_forward_agrees_with_pybullet(ik, robot, poses):
    pb = pytest.importorskip("pybullet")
    client = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(str(robot.urdf_path), useFixedBase=True, physicsClientId=client)
        joints, tip = {}, None
        for j in range(pb.getNumJoints(body, physicsClientId=client)):
            info = pb.getJointInfo(body, j, physicsClientId=client)
            joints[info[1].decode()] = j
            if info[12].decode() == robot.end_effector_frame:
                tip = j
        assert tip is not None
        idx = [joints[n] for n in robot.joint_names]
        got = np.empty((N_POSES, 3))
        for k, q in enumerate(poses):
            for j, v in zip(idx, q):
                pb.resetJointState(body, j, float(v), physicsClientId=client)
            state = pb.getLinkState(body, tip, computeForwardKinematics=True,
                                    physicsClientId=client)
            got[k] = state[4]  # URDF link frame origin, not the inertial frame
    finally:
        pb.disconnect(client)
    assert np.abs(got - ik.forward(poses)).max() < 1e-6


def test_forward_agrees_with_mujoco(ik, robot, poses):
    mujoco = pytest.importorskip("mujoco")
    model = mujoco.MjSpec.from_file(str(robot.urdf_path)).compile()
    data = mujoco.MjData(model)
    assert [model.joint(i).name for i in range(model.njnt)] == list(robot.joint_names)
    got = np.empty((200, 3))
    for k, q in enumerate(poses[:200]):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        got[k] = data.body(robot.end_effector_frame).xpos
    assert np.abs(got - ik.forward(poses[:200])).max() < 1e-6


def test_solve_reaches_random_reachable_targets(ik, robot, poses):
    # targets made by FK of random postures near q_home: reachable by construction
    rng = np.random.default_rng(7)
    q_true = np.clip(robot.q_home + rng.normal(0, 0.25, (200, 4)), robot.lower, robot.upper)
    targets = ik.forward(q_true)
    for target in targets:
        q = ik.solve(target[None])
        assert np.linalg.norm(ik.forward(q[0]) - target) < 1e-6
        assert np.all(q >= robot.lower) and np.all(q <= robot.upper)


def test_drawing_plane_is_reachable_with_margin(ik, robot):
    """The documented margin: rectangle grown by 10 mm, every joint >= 15 deg inside."""
    plane, grow, n = robot.plane, 0.010, 15
    worst = np.full(4, np.inf)
    for y in plane.y + np.linspace(-0.5, 0.5, n) * (plane.width + 2 * grow):
        for z in plane.z + np.linspace(-0.5, 0.5, n) * (plane.height + 2 * grow):
            target = np.array([[plane.x, y, z]])
            q = ik.solve(target, q0=robot.q_home)
            assert np.linalg.norm(ik.forward(q) - target) < 1e-6
            worst = np.minimum(worst, np.minimum(q[0] - robot.lower, robot.upper - q[0]))
    assert np.rad2deg(worst).min() > 15.0, np.rad2deg(worst)


def test_q_home_draws_at_the_plane_centre(ik, robot):
    centre = robot.plane.to_3d(robot.plane.center[None])[0]
    assert np.linalg.norm(ik.forward(robot.q_home) - centre) < 1e-6


@pytest.fixture(scope="module")
def motions(ik):
    return to_motions(load_lasa(["GShape", "Sine", "Zshape", "Leaf_2"]), None, ik)


def test_lasa_paths_are_accurate_continuous_and_within_limits(motions, ik, robot):
    for m in motions:
        assert isinstance(m, Motion) and m.joint_path.shape == (50, 4)
        assert np.abs(ik.forward(m.joint_path) - m.targets).max() < 1e-6
        q = m.joint_path
        assert np.all(q >= robot.lower) and np.all(q <= robot.upper)
        # warm start: neighbouring points get neighbouring postures
        assert np.abs(np.diff(q, axis=0)).max() < 0.2
        assert robot.plane.contains(m.plane_points).all()
        assert np.allclose(m.targets[:, 0], robot.plane.x)


def test_to_motion_settings_and_determinism(ik):
    demo = load_lasa(["Angle"])[2]
    a = to_motion(demo, None, ik)
    b = to_motion(demo, SensorimotorConfig(), ik)
    assert a.demo_key == "Angle/2"
    assert np.array_equal(a.joint_path, b.joint_path)
    assert a.dt == pytest.approx((demo.times[-1] - demo.times[0]) / 49)
    short = to_motion(demo, SensorimotorConfig(steps=20, resample="arc_length"), ik)
    assert short.joint_path.shape == (20, 4)
    with pytest.raises(InvalidInputError, match="SensorimotorConfig"):
        to_motion(demo, {"steps": 20}, ik)


def test_encode_decode_round_trip_on_real_motions(motions):
    enc = SensorimotorEncoder().fit(motions[::2])
    for m in motions:
        seq, start = enc.encode(m)
        assert seq.shape == (49, 6)
        pp, q = enc.decode(seq, start)
        assert np.abs(pp - m.plane_points).max() < 1e-9
        assert np.abs(q - m.joint_path).max() < 1e-9


def test_unreachable_target_names_the_point(ik, robot):
    path = robot.plane.to_3d(robot.plane.center + np.array([[0.0, 0.0], [0.01, 0.0],
                                                            [0.02, 0.0]]))
    path = np.vstack([path, [[0.40, -0.10, 0.10]]])
    with pytest.raises(UnreachableTargetError, match=r"IK target 3 of 4") as info:
        ik.solve(path)
    err = info.value
    assert err.index == 3 and err.point == (0.40, -0.10, 0.10)
    assert err.error > 0.15          # 40 cm away from a 20 cm arm
    # a point behind the shoulder, within reach but not within the joint limits' reach
    with pytest.raises(UnreachableTargetError, match="outside the reachable workspace"):
        ik.solve([[0.0, 0.05, 0.10]])


@pytest.mark.parametrize("points, match", [
    ([[0.165, -0.12, np.nan]], "not finite"),
    ([[0.165, np.inf, 0.1]], "not finite"),
    (np.zeros((4, 2)), r"shape \(T, 3\)"),
    (np.zeros(3), r"shape \(T, 3\)"),
    (np.zeros((0, 3)), r"T >= 1"),
    ([["a", "b", "c"]], "numeric"),
])
def test_solve_rejects_bad_targets(ik, points, match):
    with pytest.raises(InvalidInputError, match=match):
        ik.solve(points)


def test_solve_rejects_bad_q0(ik, robot):
    target = robot.plane.to_3d(robot.plane.center[None])
    with pytest.raises(InvalidInputError, match="outside the joint limits"):
        ik.solve(target, q0=np.zeros(4))        # RShoulderRoll 0 is above its -0.5 deg limit
    with pytest.raises(InvalidInputError, match=r"shape \(4,\)"):
        ik.solve(target, q0=np.zeros((2, 4)))
    with pytest.raises(InvalidInputError, match=r"shape \(T, 4\)"):
        ik.solve(target, q0=np.zeros(3))


def test_deterministic(ik, motions):
    m = motions[0]
    assert np.array_equal(ik.solve(m.targets), ik.solve(m.targets))
    from iloci_pinocchio.ik import PinocchioIK
    assert np.array_equal(PinocchioIK().solve(m.targets), m.joint_path)


def test_config_params_are_validated(ik):
    registry = get_registry()
    spec = registry.get("ik", "pinocchio")
    from iloci.registry import validate_params
    with pytest.raises(ConfigError, match="max_error"):
        validate_params(spec, {"tolerance": 1e-3, "max_error": 1e-4})
    with pytest.raises(ConfigError):
        validate_params(spec, {"tolerence": 1e-6})
    built = registry.build("ik", "pinocchio", {"max_error": 1e-3})
    assert built.max_error == 1e-3


def test_cli_show_writes_a_png(tmp_path, cli):
    pytest.importorskip("matplotlib")
    out = tmp_path / "fig" / "g.png"
    res = cli("show", "GShape", "--demo", "1", "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert "GShape/1" in res.stdout and "within limits: yes" in res.stdout
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(out.parent.glob("*.tmp"))
    # a user's own file works too
    f = tmp_path / "tri.csv"
    f.write_text("0,0\n1,2\n2,0\n3,2\n4,0\n")
    res = cli("show", str(f), "--out", str(tmp_path / "tri.png"))
    assert res.returncode == 0, res.stderr
    # and the SHAPE/INDEX name teach and recognize take
    res = cli("show", "GShape/1", "--out", str(tmp_path / "g1.png"))
    assert res.returncode == 0, res.stderr
    assert "GShape/1" in res.stdout


def test_cli_show_bad_input_exit_2(tmp_path, cli):
    res = cli("show", "GShape", "--demo", "9", "--out", str(tmp_path / "x.png"))
    assert res.returncode == 2 and "--demo must be 0..6" in res.stderr
    res = cli("show", "Gshape")
    assert res.returncode == 2 and "Did you mean 'GShape'" in res.stderr
    res = cli("show", "GShape/7")
    assert res.returncode == 2 and "index must be 0..6" in res.stderr
    res = cli("show", "GShape/2", "--demo", "1")
    assert res.returncode == 2 and "not both" in res.stderr
    bad = tmp_path / "bad.csv"
    bad.write_text("0,0\n1,nan\n2,0\n")
    res = cli("show", str(bad), "--out", str(tmp_path / "b.png"))
    assert res.returncode == 2 and "NaN or inf" in res.stderr

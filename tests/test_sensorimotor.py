"""Preprocessing, the robot and drawing plane, motions and the sensorimotor encoding.

Everything here runs with the kernel alone (numpy/scipy). The path through
a real IK solver is tested in tests/plugins/test_pinocchio.py.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from iloci.config import SensorimotorConfig, load_config
from iloci.data import load_lasa
from iloci.errors import (
    ConfigError,
    InvalidDemonstrationError,
    InvalidInputError,
    NotFittedError,
    UnknownComponentError,
)
from iloci.sensorimotor.encoding import FEATURES, SensorimotorEncoder
from iloci.sensorimotor.pipeline import Motion
from iloci.sensorimotor.preprocess import fit_to_plane, preprocess, resample, smooth
from iloci.sensorimotor.robots import DrawingPlane, get_robot


@pytest.fixture(scope="module")
def robot():
    return get_robot()


@pytest.fixture(scope="module")
def demos():
    return load_lasa(["GShape", "Sine", "Line"])


# -------------------------------------------------------------------- robot, plane
def test_robot_matches_its_urdf(robot):
    assert robot.urdf_path.is_file() and robot.urdf_path.name == "nao_v32_right_arm.urdf"
    root = ET.parse(robot.urdf_path).getroot()
    joints = {j.get("name"): j for j in root.iter("joint")}
    movable = [n for n, j in joints.items() if j.get("type") == "revolute"]
    assert tuple(movable) == robot.joint_names == (
        "RShoulderPitch", "RShoulderRoll", "RElbowYaw", "RElbowRoll")
    for k, name in enumerate(robot.joint_names):
        lim = joints[name].find("limit")
        assert float(lim.get("lower")) == pytest.approx(robot.lower[k])
        assert float(lim.get("upper")) == pytest.approx(robot.upper[k])
    # the V3.2 limits (docs/method.md, "The robot"), degrees
    assert np.allclose(np.rad2deg(robot.lower), [-119.5, -94.5, -119.5, 0.5], atol=1e-4)
    assert np.allclose(np.rad2deg(robot.upper), [119.5, -0.5, 119.5, 89.5], atol=1e-4)
    assert joints["RWristYaw"].get("type") == "fixed"
    assert robot.end_effector_frame in {link.get("name") for link in root.iter("link")}
    assert np.all(robot.q_home > robot.lower) and np.all(robot.q_home < robot.upper)


def test_urdf_has_inertials_and_no_meshes(robot):
    root = ET.parse(robot.urdf_path).getroot()
    for link in root.iter("link"):
        mass = link.find("inertial/mass")
        assert mass is not None and float(mass.get("value")) > 0, link.get("name")
    assert not list(root.iter("mesh"))


def test_unknown_robot():
    with pytest.raises(UnknownComponentError, match="did you mean|Did you mean"):
        get_robot("nao-v32-right-armm")


def test_plane_round_trip_and_errors(robot):
    plane = robot.plane
    pts = plane.center + np.array([[0.0, 0.0], [0.01, -0.02], [-0.03, 0.04]])
    p3 = plane.to_3d(pts)
    assert p3.shape == (3, 3) and np.all(p3[:, 0] == plane.x)
    assert np.array_equal(plane.to_2d(p3), pts)
    assert plane.contains(plane.corners).all()
    assert not plane.contains(plane.center + 1.01 * (plane.corners - plane.center)).any()
    with pytest.raises(InvalidInputError, match=r"shape \(T, 2\)"):
        plane.to_3d(np.zeros((4, 3)))
    with pytest.raises(InvalidInputError, match=r"shape \(T, 3\)"):
        plane.to_2d(np.zeros(3))
    with pytest.raises(InvalidInputError, match="NaN or inf"):
        plane.to_3d([[np.nan, 0.0]])
    with pytest.raises(InvalidInputError, match="positive width"):
        DrawingPlane(0.1, 0.0, 0.0, 0.0, 0.1)


# --------------------------------------------------------------------- preprocess
def test_smooth_removes_noise_and_keeps_shape(demos):
    clean = demos[0].positions
    rng = np.random.default_rng(0)
    noisy = clean + rng.normal(0, 0.3, clean.shape)
    out = smooth(noisy, 31)
    assert out.shape == clean.shape
    assert np.sqrt(np.mean((out - clean) ** 2)) < 0.4 * np.sqrt(np.mean((noisy - clean) ** 2))
    # a cubic fit leaves a smooth curve nearly unchanged (no flattening, no lag)
    assert np.abs(smooth(clean, 31) - clean).max() < 0.05 * np.ptp(clean)
    assert np.array_equal(smooth(noisy, 0), noisy) and np.array_equal(smooth(noisy, 1), noisy)


def test_smooth_window_longer_than_path_and_bad_window():
    p = np.column_stack([np.linspace(0, 1, 7), np.linspace(0, 1, 7) ** 2])
    assert smooth(p, 31).shape == (7, 2)
    assert np.array_equal(smooth(p[:4], 31), p[:4])
    with pytest.raises(InvalidInputError, match="odd"):
        smooth(p, 30)
    with pytest.raises(InvalidInputError, match="odd"):
        smooth(p, -3)


def test_resample_by_time_and_arc_length():
    t = np.linspace(0, 1, 201) ** 2       # slow start: samples crowd at the beginning
    p = np.column_stack([t, np.zeros_like(t)])
    p[:, 1] = p[:, 0]
    r_time = resample(p, t, steps=11, by="time")
    assert r_time.shape == (11, 2)
    assert np.allclose(r_time[:, 0], np.linspace(0, 1, 11))       # x == t
    r_arc = resample(p, None, steps=5, by="arc_length")
    seg = np.linalg.norm(np.diff(r_arc, axis=0), axis=1)
    assert np.allclose(seg, seg[0])
    assert np.allclose(r_arc[[0, -1]], p[[0, -1]])
    # pen at rest (repeated points) is fine along the arc length
    rest = np.vstack([p, np.repeat(p[-1:], 20, axis=0)])
    assert np.allclose(resample(rest, None, 5, "arc_length"), r_arc)


def test_resample_errors():
    p = np.column_stack([np.arange(5.0), np.arange(5.0)])
    with pytest.raises(InvalidInputError, match="steps"):
        resample(p, steps=2)
    with pytest.raises(InvalidInputError, match="'time' or 'arc_length'"):
        resample(p, by="speed")
    with pytest.raises(InvalidInputError, match="strictly increasing"):
        resample(p, times=[0, 1, 1, 2, 3])
    with pytest.raises(InvalidDemonstrationError, match="zero length"):
        resample(np.ones((5, 2)), by="arc_length")


def test_fit_to_plane_keeps_aspect_ratio_and_centres(robot, demos):
    plane = robot.plane
    for d in demos:
        raw = d.positions
        fitted = fit_to_plane(raw, plane)
        assert plane.contains(fitted).all()
        ext_raw, ext_fit = np.ptp(raw, axis=0), np.ptp(fitted, axis=0)
        assert ext_fit[0] / ext_fit[1] == pytest.approx(ext_raw[0] / ext_raw[1])
        # fills the rectangle along its tighter side, centred
        assert np.max(ext_fit / plane.size) == pytest.approx(1.0)
        box_centre = (fitted.min(0) + fitted.max(0)) / 2
        assert np.allclose(box_centre, plane.center)
        # teacher x -> plane y, teacher y -> plane z (no mirroring)
        assert np.corrcoef(raw[:, 0], fitted[:, 0])[0, 1] == pytest.approx(1.0)
        assert np.corrcoef(raw[:, 1], fitted[:, 1])[0, 1] == pytest.approx(1.0)


def test_fit_flat_line_and_zero_extent(robot):
    line = np.column_stack([np.linspace(-5, 5, 10), np.full(10, 2.0)])
    fitted = fit_to_plane(line, robot.plane)
    assert np.ptp(fitted[:, 0]) == pytest.approx(robot.plane.width)
    assert np.allclose(fitted[:, 1], robot.plane.z)
    with pytest.raises(InvalidDemonstrationError, match="zero extent"):
        fit_to_plane(np.ones((4, 2)), robot.plane)


@pytest.mark.parametrize("bad, match", [
    (np.array([[0, 0], [1, np.nan], [2, 1]]), "NaN or inf"),
    (np.array([[0, 0], [1, np.inf], [2, 1]]), "NaN or inf"),
    (np.array([[0, 0], [1, 1]]), "at least 3"),
    (np.zeros((5, 3)), r"shape \(N, 2\)"),
    (np.arange(6.0), r"shape \(N, 2\)"),
])
def test_preprocess_functions_reject_bad_arrays(robot, bad, match):
    for fn in (lambda a: smooth(a, 5), lambda a: resample(a, steps=5),
               lambda a: fit_to_plane(a, robot.plane)):
        with pytest.raises(InvalidDemonstrationError, match=match):
            fn(bad)


def test_preprocess_demo(robot, demos):
    out = preprocess(demos[0], steps=50, plane=robot.plane)
    assert out.shape == (50, 2) and robot.plane.contains(out).all()
    again = preprocess(demos[0], steps=50, plane=robot.plane)
    assert np.array_equal(out, again)
    timed = preprocess(demos[0], steps=50, resample_by="time", plane=robot.plane)
    assert not np.allclose(timed, out)
    with pytest.raises(InvalidInputError, match="'time' or 'arc_length'"):
        preprocess(demos[0], resample_by="speed", plane=robot.plane)
    with pytest.raises(InvalidInputError, match="expected a Demonstration"):
        preprocess(np.zeros((5, 2)), plane=robot.plane)


def test_an_untimed_drawing_is_paced_by_its_path_not_a_second_per_sample(robot):
    """A 1000-sample CSV without times took 17 minutes to draw (dt 20 s per step): its
    sample numbers were read as seconds. Now its path sets the time, at LASA's pace."""
    from iloci.interfaces import Demonstration
    from iloci.sensorimotor.pipeline import motion_dt, preprocessed

    t = np.linspace(0, 1.8 * np.pi, 1000)
    circle = np.stack([np.cos(t), np.sin(t)], axis=1)

    def seconds(demo):
        points = preprocessed(demo, None, robot)
        return motion_dt(demo, points, robot.plane.height) * (len(points) - 1)
    dense, sparse = Demonstration(circle), Demonstration(circle[::10])
    assert not dense.timed and not sparse.timed
    assert 2 < seconds(dense) < 15                                # not 999 s
    assert seconds(sparse) == pytest.approx(seconds(dense), rel=0.02)  # not the sample count
    timed = Demonstration(circle, times=np.linspace(0, 3.0, 1000))
    assert timed.timed and seconds(timed) == pytest.approx(3.0)


def test_config_rejects_even_smoothing_window():
    with pytest.raises(ConfigError, match="odd"):
        load_config({"sensorimotor": {"smoothing_window": 30}},
                    registry=_registry_without_plugins())
    assert SensorimotorConfig().steps == 50


def _registry_without_plugins():
    from iloci.plugins import get_plugin_manager, get_registry
    return get_registry(get_plugin_manager(autoload=False))


# ----------------------------------------------------------------------- encoding
def _motion(demo, robot) -> Motion:
    """A Motion with a smooth joint path made from the plane path (no IK needed)."""
    pp = preprocess(demo, plane=robot.plane)
    u = (pp - robot.plane.center) / robot.plane.size
    q = robot.q_home + 0.3 * np.column_stack([u[:, 0], u[:, 1], u[:, 0] * u[:, 1],
                                              np.sin(u[:, 0])])
    return Motion(demo.key, pp, robot.plane.to_3d(pp), q, 0.1)


def test_encode_decode_round_trip(robot, demos):
    motions = [_motion(d, robot) for d in demos]
    enc = SensorimotorEncoder().fit(motions[:10])
    assert len(FEATURES) == 6 and enc.scale_.shape == (6,)
    for m in motions:
        seq, start = enc.encode(m)
        assert seq.shape == (len(m) - 1, 6) and start.shape == (6,)
        assert np.array_equal(start, np.r_[m.plane_points[0], m.joint_path[0]])
        pp, q = enc.decode(seq, start)
        assert np.abs(pp - m.plane_points).max() < 1e-9
        assert np.abs(q - m.joint_path).max() < 1e-9
    # the largest displacement of each channel in the learning data encodes to `limit`
    seqs, starts = enc.encode_all(motions[:10])
    assert np.allclose(np.abs(np.vstack(seqs)).max(axis=0), 0.9)
    assert starts.shape == (10, 6)


def test_encoding_is_relative(robot, demos):
    m = _motion(demos[0], robot)
    shifted = Motion(m.demo_key, m.plane_points + [0.01, -0.02], m.targets,
                     m.joint_path + 0.05, m.dt)
    enc = SensorimotorEncoder().fit([m])
    assert np.allclose(enc.encode(m)[0], enc.encode(shifted)[0], atol=1e-12)


def test_encoder_state_round_trip_and_errors(robot, demos):
    m = _motion(demos[1], robot)
    enc = SensorimotorEncoder(limit=0.5).fit([m])
    state = enc.state()
    assert set(state) == {"scale", "limit"}
    assert all(isinstance(v, np.ndarray) for v in state.values())
    back = SensorimotorEncoder.from_state(state)
    assert back.limit == 0.5
    assert np.array_equal(back.encode(m)[0], enc.encode(m)[0])
    with pytest.raises(NotFittedError, match="fit"):
        SensorimotorEncoder().encode(m)
    with pytest.raises(InvalidInputError, match="at least one motion"):
        SensorimotorEncoder().fit([])
    with pytest.raises(InvalidInputError, match="scale"):
        SensorimotorEncoder.from_state({"scale": np.zeros(6), "limit": np.array(0.9)})
    with pytest.raises(InvalidInputError, match="'scale'"):
        SensorimotorEncoder.from_state({"limit": np.array(0.9)})
    with pytest.raises(InvalidInputError, match="positive"):
        SensorimotorEncoder(limit=0)
    seq, start = enc.encode(m)
    with pytest.raises(InvalidInputError, match=r"shape \(T, 6\)"):
        enc.decode(seq[:, :4], start)
    with pytest.raises(InvalidInputError, match=r"shape \(6,\)"):
        enc.decode(seq, start[:5])
    with pytest.raises(InvalidInputError, match="NaN or inf"):
        enc.decode(np.where(np.arange(6) == 2, np.nan, seq), start)
    with pytest.raises(InvalidInputError, match="expected a Motion"):
        enc.encode(seq)


def test_motion_checks_shapes(robot):
    pp = np.zeros((5, 2))
    with pytest.raises(InvalidInputError, match="share T"):
        Motion("x/0", pp, np.zeros((5, 3)), np.zeros((4, 4)), 0.1)
    with pytest.raises(InvalidInputError, match="dt"):
        Motion("x/0", pp, np.zeros((5, 3)), np.zeros((5, 4)), 0.0)


# ---------------------------------------------------------------------- simulation
# What every simulator shares (iloci.sensorimotor.simulation), without an engine.

def _arm_path(robot, T=20) -> np.ndarray:
    s = np.linspace(0, 1, T)[:, None]
    return robot.q_home + 0.2 * np.sin(2 * np.pi * s) * np.array([1.0, 0.5, 1.0, 0.5])


@pytest.mark.parametrize("bad, match", [
    (lambda q: q[:, :3], (r"shape \(T, 4\) with T >= 1, one column per joint "
                          r"\(RShoulderPitch, RShoulderRoll, RElbowYaw, RElbowRoll\), "
                          r"got \(20, 3\)")),
    (lambda q: np.zeros((20, 6)), r"got \(20, 6\)"),
    (lambda q: q[0], r"got \(4,\)"),
    (lambda q: q[:0], r"T >= 1.*got \(0, 4\)"),
    (lambda q: np.where(np.arange(80).reshape(20, 4) == 13, np.nan, q),
     r"NaN or inf \(first at step 3, joint RShoulderRoll\)"),
    (lambda q: np.where(np.arange(80).reshape(20, 4) == 9, np.inf, q), "NaN or inf"),
    (lambda q: np.vstack([q, [0.0, 0.0, 0.0, 1.0]]),
     (r"step 20: RShoulderRoll = 0.0000 rad is outside its limits \[-1.6493, -0.0087\] "
      r"\(1 step\(s\) out of range\)\. Clip the path")),
    (lambda q: q + np.array([0, 0, 0, 1.0]), r"RElbowRoll = .* outside its limits"),
    (lambda q: [["a"] * 4] * 3, "numeric array of shape"),
    (lambda q: None, "shape"),
], ids=["3 columns", "6 columns", "one row as 1-D", "empty", "NaN", "inf", "outside limit",
        "above a limit", "strings", "None"])
def test_check_joint_path_errors_say_what_is_wrong(robot, bad, match):
    from iloci.sensorimotor.simulation import check_joint_path
    with pytest.raises(InvalidInputError, match=match):
        check_joint_path(bad(_arm_path(robot)), 0.05, robot)


def test_check_joint_path_clips_within_tolerance_and_checks_dt(robot):
    from iloci.sensorimotor.simulation import check_joint_path
    q = _arm_path(robot)
    q[5, 1] = robot.upper[1] + 5e-7  # a rounding error past a limit passes, clipped
    out, dt = check_joint_path(q.tolist(), np.float32(0.05), robot)
    assert out.dtype == np.float64 and out[5, 1] == robot.upper[1] and type(dt) is float
    # a path the arm already performed may overshoot a limit: kept as it is
    q[5, 1] = robot.upper[1] + 0.01
    out, _ = check_joint_path(q, 0.05, robot, limits=False)
    assert out[5, 1] == q[5, 1]
    for dt in (0, -1.0, float("nan"), float("inf"), "fast", None):
        with pytest.raises(InvalidInputError, match="dt"):
            check_joint_path(_arm_path(robot), dt, robot)


def test_check_postures_execution_and_image_size(robot):
    from iloci.interfaces import Execution
    from iloci.sensorimotor.simulation import check_execution, check_image_size, check_postures
    qs, single = check_postures(robot.q_home, robot)
    assert qs.shape == (1, 4) and single
    qs, single = check_postures(np.tile(robot.lower - 0.1, (3, 1)), robot)  # limits not checked
    assert qs.shape == (3, 4) and not single
    with pytest.raises(InvalidInputError, match="NaN"):
        check_postures(np.array([np.nan, 0, 0, 0]), robot)

    q = _arm_path(robot, 5)
    ex = Execution(q, np.zeros((5, 3)), 0.1)
    q2, pen = check_execution(ex, robot)
    assert q2.shape == (5, 4) and pen.shape == (5, 3)
    with pytest.raises(InvalidInputError, match="render takes an Execution .*got ndarray"):
        check_execution(q, robot)
    with pytest.raises(InvalidInputError, match=r"end_effector must be finite with shape "
                                                r"\(5, 3\), got \(5, 2\)"):
        check_execution(Execution(q, np.zeros((5, 2)), 0.1), robot)
    with pytest.raises(InvalidInputError, match="end_effector must be finite"):
        check_execution(Execution(q, np.full((5, 3), np.nan), 0.1), robot)
    with pytest.raises(InvalidInputError, match="joint path"):
        check_execution(Execution(q[:, :2], np.zeros((5, 3)), 0.1), robot)

    assert check_image_size(np.int64(64), 48) == (64, 48)
    for w, h, which in ((0, 10, "width"), (10, 5000, "height"), (2.0, 10, "width"),
                        (False, 10, "width"), ("64", 10, "width")):
        with pytest.raises(InvalidInputError, match=f"image {which} must be an integer"):
            check_image_size(w, h)


def test_setpoints_and_track_follow_the_path_linearly(robot):
    """A perfect servo (the state is the set-point) reaches every row exactly."""
    from iloci.sensorimotor.simulation import setpoints, track, updates_per_step
    assert updates_per_step(0.05, 0.001) == 50  # no extra update from rounding
    assert updates_per_step(0.0005, 0.001) == 1
    q = _arm_path(robot, 6)
    segments = list(setpoints(q, 0.01, 0.004))
    assert [i for i, _, _ in segments] == [0, 1, 2, 3, 4]
    _, targets, velocity = segments[2]
    assert targets.shape == (3, 4)
    np.testing.assert_allclose(targets[-1], q[3])
    np.testing.assert_allclose(targets[0], q[2] + (q[3] - q[2]) / 3)
    np.testing.assert_allclose(velocity, (q[3] - q[2]) / 0.01)

    state = {"q": q[0].copy(), "holds": 0}

    def hold(target, velocity):
        state["q"] = target.copy()
        state["holds"] += 1

    ex = track(q, 0.01, 0.004, hold, lambda: (state["q"], np.r_[0.0, state["q"][:2]]))
    assert state["holds"] == 5 * 3
    np.testing.assert_allclose(ex.joint_path, q)
    np.testing.assert_allclose(ex.end_effector[:, 1:], q[:, :2])
    assert ex.dt == 0.01
    # a single posture: nothing to track, the start is what is read
    one = track(q[:1], 0.01, 0.004, hold, lambda: (q[0], np.zeros(3)))
    assert one.joint_path.shape == (1, 4) and one.end_effector.shape == (1, 3)


def test_simulator_params_and_settings_errors():
    from dataclasses import dataclass
    from typing import ClassVar

    from iloci.sensorimotor.simulation import SimulatorParams, check_settings

    @dataclass(frozen=True)
    class EngineParams(SimulatorParams):
        POSITIVE: ClassVar[tuple[str, ...]] = ("step",)
        step: float = 0.001

    EngineParams().validate()
    for kw, msg in (({"step": 0.0}, "step must be > 0, got 0.0"),
                    ({"gravity": -9.81}, "gravity must be >= 0"),
                    ({"step": float("nan")}, "step must be a finite number"),
                    ({"gravity": float("inf")}, "gravity must be a finite number")):
        with pytest.raises(InvalidInputError, match=msg + ".*see .*EngineParams"):
            check_settings(EngineParams(**kw))


def test_picture_helpers(robot):
    from iloci.sensorimotor.simulation import VIEW, path_dots, plane_outline
    outline = plane_outline(robot.plane)
    assert outline.shape == (5, 3) and np.array_equal(outline[0], outline[-1])
    assert np.allclose(outline[:, 0], robot.plane.x)
    dots = path_dots(outline, 0.004)
    # a 10 cm square every 4 mm: 25 dots a side (26 where 0.1 / 0.004 rounds
    # up), plus the first point
    assert 101 <= len(dots) <= 105 and dots.shape[1] == 3
    assert np.linalg.norm(np.diff(dots, axis=0), axis=1).max() <= 0.004 + 1e-12
    # the camera looks at the plane from in front of the robot
    assert VIEW["eye"][0] > robot.plane.x > 0 and 0 < VIEW["fov"] < 90


def test_simulation_module_is_light():
    import subprocess
    import sys
    code = ("import sys, iloci.sensorimotor.simulation; "
            "print(sorted(m for m in ('pybullet', 'mujoco', 'pinocchio', 'matplotlib', 'torch')"
            " if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"


def test_motion_cache_converts_each_demonstration_once_and_never_mixes_them_up():
    from iloci.interfaces import Demonstration
    from iloci.sensorimotor.pipeline import MotionCache

    calls = []

    def convert(d):
        calls.append(d.key)
        if d.shape == "bad":
            raise InvalidInputError("unusable")
        T = len(d.positions)
        return Motion(d.key, d.positions, np.zeros((T, 3)), np.zeros((T, 4)), 0.1)

    xy = np.linspace(0.0, 1.0, 20)[:, None] * np.array([[1.0, 2.0]])
    a = Demonstration(xy, shape="line", index=0)
    cache = MotionCache(max_items=2)
    m = cache.get(a, convert)
    assert cache.get(Demonstration(xy.copy(), shape="line", index=0), convert) is m
    # the same key with other positions (a perturbed copy) or times is converted anew
    moved = Demonstration(xy + 1e-9, shape="line", index=0)
    assert cache.get(moved, convert) is not m
    slower = Demonstration(xy, times=np.linspace(0, 2, 20), shape="line", index=0)
    cache.get(slower, convert)
    assert (cache.hits, cache.misses, len(cache)) == (1, 3, 2)  # oldest dropped
    with pytest.raises(InvalidInputError):
        cache.get(Demonstration(xy, shape="bad", index=0), convert)
    assert len(cache) == 2 and calls == ["line/0"] * 3 + ["bad/0"]
    with pytest.raises(InvalidInputError):
        MotionCache(max_items=0)
    # motions one cache converted answer another's lookups of the same demonstrations
    # only (another process's: the parallel evaluation sends them with its tasks)
    other = MotionCache()
    other.add(cache.converted([a, moved, slower]))
    assert len(other) == 2 and other.get(slower, convert) is cache.get(slower, convert)
    assert other.get(moved, convert) is cache.get(moved, convert)
    n = len(calls)
    other.get(a, convert)  # dropped from the first cache: converted here
    assert calls[n:] == ["line/0"] and other.misses == 1

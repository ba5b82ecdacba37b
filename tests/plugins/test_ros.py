"""The iloci-ros node end to end against a real roscore, with rostopic-level traffic.

Needs ROS 1 from the system (Debian: ``apt-get install ros-core python3-rospy
python3-nav-msgs python3-geometry-msgs python3-trajectory-msgs``; .ci/run
installs them when it runs as root) and the iloci-ros plugin; skipped with a
message otherwise. A real roscore on a free port, the node as ``iloci ros``
in a subprocess, drawings published from this process with rospy, a
feedback published with the ``rostopic`` command.
"""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path
import queue
import shutil
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

pytest.importorskip("iloci_ros", reason="the iloci-ros plugin is not installed")
pytest.importorskip("iloci_native")
pytest.importorskip("pinocchio")

from iloci.errors import MissingBackendError  # noqa: E402

try:
    from iloci_ros.rospath import import_rospy
    rospy = import_rospy()
except MissingBackendError as exc:
    pytest.skip(f"no ROS 1 on this machine: {exc}", allow_module_level=True)
if shutil.which("roscore") is None or shutil.which("rostopic") is None:
    pytest.skip("no roscore/rostopic on PATH (apt-get install ros-core)",
                allow_module_level=True)

EPOCHS = 30
SETTINGS = {"perceptual_model": {"name": "native-rnnpb", "epochs": EPOCHS,
                                 "recognition_steps": EPOCHS},
            "learner": {"rehearsal_epochs": EPOCHS}, "evaluation": {"seed": 0}}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    """A real roscore on a free port; the environment that points at it."""
    home = tmp_path_factory.mktemp("ros-home")
    port = _free_port()
    env = {**os.environ, "ROS_MASTER_URI": f"http://127.0.0.1:{port}",
           "ROS_HOME": str(home), "ROS_LOG_DIR": str(home / "log"),
           "ROS_HOSTNAME": "127.0.0.1"}
    core = subprocess.Popen(["roscore", "-p", str(port)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + 60
    while subprocess.run(["rostopic", "list"], env=env, capture_output=True).returncode:
        if time.monotonic() > deadline or core.poll() is not None:
            core.kill()
            pytest.fail("roscore did not start within 60 s")
        time.sleep(0.5)
    os.environ.update({k: env[k] for k in ("ROS_MASTER_URI", "ROS_HOSTNAME")})
    yield env
    if rospy.core.is_initialized():   # this process's test node, before its master goes
        rospy.signal_shutdown("iloci-ros tests done")
    os.killpg(core.pid, 15)
    core.wait(timeout=30)


@pytest.fixture(scope="module")
def memory(tmp_path_factory):
    """A memory taught GShape and Angle, saved."""
    import iloci
    from iloci.data import load_lasa
    demos = {d.key: d for d in load_lasa(["GShape", "Angle"])}
    agent = iloci.build(SETTINGS)
    agent.teach([demos["GShape/0"], demos["Angle/0"]])
    path = agent.save(tmp_path_factory.mktemp("mem") / "memory.npz")
    return path, demos


class Listener:
    """Every message on the node's out topics, in a queue per topic."""

    def __init__(self):
        from std_msgs.msg import String
        from trajectory_msgs.msg import JointTrajectory
        self.q = {name: queue.Queue() for name in ("guess", "joint_path", "outcome",
                                                   "feedback_result", "error")}
        for name in self.q:
            kind = JointTrajectory if name == "joint_path" else String
            rospy.Subscriber(f"/iloci/{name}", kind, self._put(name))

    def _put(self, name):
        def put(msg):
            self.q[name].put((time.perf_counter(),
                              msg if name == "joint_path" else json.loads(msg.data)))
        return put

    def get(self, name, timeout=60.0):
        try:
            return self.q[name].get(timeout=timeout)
        except queue.Empty:
            raise AssertionError(f"nothing on /iloci/{name} within {timeout} s") from None

    def empty(self, name, wait=1.0):
        time.sleep(wait)
        return self.q[name].empty()


def _path_msg(xy):
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Path as PathMsg
    msg = PathMsg()
    msg.header.frame_id = "tablet"
    for x, y in xy:
        pose = PoseStamped()
        pose.pose.position.x, pose.pose.position.y = float(x), float(y)
        pose.pose.orientation.w = 1.0
        msg.poses.append(pose)
    return msg


def _wait_for_subscribers(pub, timeout=30.0):
    deadline = time.monotonic() + timeout
    while pub.get_num_connections() == 0:
        assert time.monotonic() < deadline, f"no subscriber on {pub.name}"
        time.sleep(0.1)


def _start_node(ros_env, memory_file, tmp_path):
    """A copy of the taught memory and an `iloci ros` node teaching it (its own session)."""
    taught = tmp_path / "robot.npz"
    taught.write_bytes(Path(memory_file).read_bytes())
    node = subprocess.Popen([sys.executable, "-m", "iloci", "ros", "--memory", str(taught)],
                            env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    return taught, node


def test_drawing_guess_feedback_over_a_real_roscore(ros_env, memory, tmp_path):
    from nav_msgs.msg import Path as PathMsg
    path, demos = memory
    taught, node = _start_node(ros_env, path, tmp_path)
    try:
        rospy.init_node("iloci_test", anonymous=True, disable_signals=True)
        listen = Listener()
        pub = rospy.Publisher("/iloci/drawing", PathMsg, queue_size=10)
        _wait_for_subscribers(pub, timeout=120)
        deadline = time.monotonic() + 30       # the node's publishers, too
        while "/iloci/guess" not in dict(rospy.get_published_topics()):
            assert time.monotonic() < deadline, "the node publishes no /iloci/guess"
            time.sleep(0.2)
        time.sleep(1.0)                        # our subscribers connect to them

        # a drawing in: a guess and its joint path out
        pub.publish(_path_msg(demos["Angle/3"].positions))
        _, guess = listen.get("guess")
        _, traj = listen.get("joint_path")
        assert guess["kind"] == "guess" and guess["concept"] in ("c1", "c2")
        assert 0 <= guess["confidence"] <= 1 and guess["attempt"] == 1
        assert traj.joint_names == guess["joint_names"] and len(traj.points) == guess["steps"]
        assert traj.header.stamp.to_sec() == pytest.approx(guess["stamp"])
        q = np.array([p.positions for p in traj.points])
        assert q.shape == (guess["steps"], 4) and np.isfinite(q).all()

        # a feedback naming another answer is refused and changes nothing
        before = taught.read_bytes()
        bogus = json.dumps({"answer_id": "not-an-answer", "value": 1})
        subprocess.run(["rostopic", "pub", "-1", "/iloci/feedback", "std_msgs/String",
                        f"data: '{bogus}'"], env=ros_env, check=True, capture_output=True,
                       timeout=60)
        _, result = listen.get("feedback_result")
        assert result == {"answer_id": "not-an-answer", "accepted": False,
                          "error": result["error"]}
        assert "refused" in result["error"] and guess["answer_id"] in result["error"]

        # the right feedback, with rostopic: the drawing is placed and the memory saved
        right = json.dumps({"answer_id": guess["answer_id"],
                            "value": 1 if guess["concept"] == "c2" else -1})
        subprocess.run(["rostopic", "pub", "-1", "/iloci/feedback", "std_msgs/String",
                        f"data: '{right}'"], env=ros_env, check=True, capture_output=True,
                       timeout=60)
        _, result = listen.get("feedback_result")
        assert result["accepted"] and result["answer_id"] == guess["answer_id"]
        if guess["concept"] != "c2":            # a -1: the next guess, a new answer id
            _, nxt = listen.get("guess")
            listen.get("joint_path")
            assert nxt["answer_id"] != guess["answer_id"] and nxt["attempt"] == 2
            value = 1 if nxt["concept"] == "c2" else -1
            subprocess.run(["rostopic", "pub", "-1", "/iloci/feedback", "std_msgs/String",
                            "data: '" + json.dumps({"answer_id": nxt["answer_id"],
                                                    "value": value}) + "'"],
                           env=ros_env, check=True, capture_output=True, timeout=60)
            listen.get("feedback_result")
        _, placed = listen.get("outcome", timeout=120)
        assert placed["kind"] == "placed" and placed["demo"] == guess["demo"]
        deadline = time.monotonic() + 30
        while taught.read_bytes() == before:
            assert time.monotonic() < deadline, "the memory was not saved"
            time.sleep(0.2)

        # the same feedback again (a duplicate): refused, the memory unchanged
        saved = taught.read_bytes()
        subprocess.run(["rostopic", "pub", "-1", "/iloci/feedback", "std_msgs/String",
                        f"data: '{right}'"], env=ros_env, check=True, capture_output=True,
                       timeout=60)
        _, result = listen.get("feedback_result")
        assert not result["accepted"] and "no answer is pending" in result["error"]
        assert listen.empty("outcome") and taught.read_bytes() == saved

        # a drawing the robot cannot use: one error message, the node keeps running
        pub.publish(_path_msg(np.zeros((20, 2))))
        _, err = listen.get("error")
        assert "zero extent" in err["error"]
        assert node.poll() is None
    finally:
        os.killpg(node.pid, 2)
        try:
            out, errs = node.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(node.pid, 9)
            out, errs = node.communicate()
    assert "iloci ros: node /iloci" in errs, errs


def test_messages_convert_to_drawings():
    from geometry_msgs.msg import Point32, PolygonStamped
    from iloci_ros.node import path_to_drawing, polygon_to_drawing
    xy = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 2.0]])
    msg = _path_msg(xy)
    positions, times = path_to_drawing(msg)
    assert np.array_equal(positions, xy) and times is None       # no stamps: no times
    for i, pose in enumerate(msg.poses):
        pose.header.stamp = rospy.Time.from_sec(100 + 0.1 * i)
    positions, times = path_to_drawing(msg)
    np.testing.assert_allclose(times, [0.0, 0.1, 0.2], atol=1e-6)
    poly = PolygonStamped()
    poly.polygon.points = [Point32(x=float(x), y=float(y), z=0.0) for x, y in xy]
    positions, times = polygon_to_drawing(poly)
    np.testing.assert_allclose(positions, xy)
    assert times is None


def test_a_second_writer_and_bad_names_are_refused_before_the_node_starts(ros_env, memory,
                                                                           tmp_path):
    """An audit: two nodes (or a node and iloci teach) on one memory each saved over the
    other's drawings; a --prefix or --node-name ROS refuses gave FATAL lines while the node
    stayed up, or "report it to its authors"."""
    path, _ = memory
    taught, node = _start_node(ros_env, path, tmp_path)
    try:
        deadline = time.monotonic() + 120
        while not (tmp_path / "robot.npz.lock.json").exists():
            assert node.poll() is None, node.stderr.read()
            assert time.monotonic() < deadline, "the node took no lock"
            time.sleep(0.2)
        for argv in (["ros", "--memory", str(taught), "--node-name", "second"],
                     ["teach", "--memory", str(taught), "GShape/1"]):
            done = subprocess.run([sys.executable, "-m", "iloci", *argv], env=ros_env,
                                  capture_output=True, text=True, timeout=300)
            assert done.returncode == 2, done.stderr
            assert "is being taught by another process or session: iloci ros" in done.stderr
    finally:
        os.killpg(node.pid, signal.SIGINT)
        node.wait(timeout=60)
    for argv, said in ((["--prefix", "bad name!"], "--prefix 'bad name!' is not a ROS name"),
                       (["--prefix", ""], "--prefix '' is not a ROS name"),
                       (["--node-name", "a/b"], "--node-name 'a/b' is not a ROS node name")):
        done = subprocess.run([sys.executable, "-m", "iloci", "ros", "--memory",
                               str(tmp_path / "new.npz"), *argv], env=ros_env,
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 2 and said in done.stderr, done.stderr


def _init_test_node():
    if not rospy.core.is_initialized():
        rospy.init_node("iloci_test", anonymous=True, disable_signals=True)


def test_a_burst_of_feedback_while_a_drawing_is_handled_is_answered_message_for_message(
        ros_env, memory, tmp_path):
    """An audit: the node's subscribers kept 10 messages; feedback that arrived while a
    drawing was being handled was dropped past the 10th, without a word (a teacher's
    judgement lost)."""
    from nav_msgs.msg import Path as PathMsg
    from std_msgs.msg import String
    path, demos = memory
    taught, node = _start_node(ros_env, path, tmp_path)
    try:
        _init_test_node()
        listen = Listener()
        pub = rospy.Publisher("/iloci/drawing", PathMsg, queue_size=100)
        feedback = rospy.Publisher("/iloci/feedback", String, queue_size=100)
        _wait_for_subscribers(pub, timeout=120)
        _wait_for_subscribers(feedback)
        time.sleep(1.0)
        pub.publish(_path_msg(demos["Angle/3"].positions))
        time.sleep(0.02)                       # the drawing first: it holds the session
        for i in range(40):
            feedback.publish(String(data=json.dumps({"answer_id": f"burst-{i}", "value": 1})))
        listen.get("guess")
        answered = [listen.get("feedback_result", timeout=60)[1] for _ in range(40)]
        assert sorted(r["answer_id"] for r in answered) == sorted(f"burst-{i}"
                                                                 for i in range(40))
        assert not any(r["accepted"] for r in answered)
    finally:
        os.killpg(node.pid, signal.SIGINT)
        node.wait(timeout=60)


def test_ctrl_c_while_a_drawing_is_learned_lets_it_be_learned_and_saved(ros_env, memory,
                                                                        tmp_path):
    """An audit: Ctrl-C while the node trained on a drawing ended the process under the
    training: the drawing was lost and nothing said so."""
    from nav_msgs.msg import Path as PathMsg
    import iloci
    _, demos = memory
    slow = tmp_path / "slow.toml"
    slow.write_text("[perceptual_model]\nepochs = 600000\n")   # about 14 s of training here
    new = tmp_path / "new.npz"
    node = subprocess.Popen([sys.executable, "-m", "iloci", "ros", "--memory", str(new),
                             "--config", str(slow), "--prefix", "slow"], env=ros_env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        _init_test_node()
        pub = rospy.Publisher("/slow/drawing", PathMsg, queue_size=10)
        _wait_for_subscribers(pub, timeout=120)
        time.sleep(1.0)
        # the first drawing founds the first concept: the node trains on it at once
        pub.publish(_path_msg(demos["GShape/0"].positions))
        time.sleep(1.5)
        assert not new.exists()
        os.killpg(node.pid, signal.SIGINT)
        _, err = node.communicate(timeout=120)
    finally:
        if node.poll() is None:
            os.killpg(node.pid, 9)
            node.communicate()
    assert "stopping once the drawing in progress is learned and saved" in err, err
    assert new.exists(), err
    assert len(iloci.Agent.load(new).memory) == 1


def _topics(env) -> str:
    return subprocess.run(["rostopic", "list"], env=env, capture_output=True, text=True,
                          timeout=60).stdout


def test_the_topics_follow_the_nodes_namespace(ros_env, memory, tmp_path):
    """An audit: the topics were absolute (/iloci/...), so ROS_NAMESPACE or a launch file's
    <group ns="robot1"> did not move them, and two robots' nodes shared one set."""
    path, _ = memory
    taught = tmp_path / "robot.npz"
    taught.write_bytes(Path(path).read_bytes())
    node = subprocess.Popen([sys.executable, "-m", "iloci", "ros", "--memory", str(taught)],
                            env={**ros_env, "ROS_NAMESPACE": "robot1"}, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while "/robot1/iloci/drawing" not in _topics(ros_env):
            assert node.poll() is None, node.stderr.read()
            assert time.monotonic() < deadline, _topics(ros_env)
            time.sleep(0.5)
    finally:
        os.killpg(node.pid, signal.SIGINT)
        _, err = node.communicate(timeout=60)
    assert "on /robot1/iloci/*" in err, err


def test_a_restarted_roscore_stops_the_node_with_a_message_not_a_deaf_node(memory, tmp_path):
    """An audit: after roscore was restarted, the node stayed up registered with the old
    master, deaf to every drawing and feedback, and said nothing."""
    path, _ = memory
    home = tmp_path / "home"
    port = _free_port()
    env = {**os.environ, "ROS_MASTER_URI": f"http://127.0.0.1:{port}", "ROS_HOME": str(home),
           "ROS_LOG_DIR": str(home / "log"), "ROS_HOSTNAME": "127.0.0.1"}

    def core():
        proc = subprocess.Popen(["roscore", "-p", str(port)], env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                start_new_session=True)
        deadline = time.monotonic() + 60
        while subprocess.run(["rostopic", "list"], env=env, capture_output=True).returncode:
            assert time.monotonic() < deadline and proc.poll() is None, "no roscore"
            time.sleep(0.5)
        return proc

    first = core()
    taught = tmp_path / "robot.npz"
    taught.write_bytes(Path(path).read_bytes())
    node = subprocess.Popen([sys.executable, "-m", "iloci", "ros", "--memory", str(taught)],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    second = None
    try:
        deadline = time.monotonic() + 120
        while "/iloci/drawing" not in _topics(env):
            assert node.poll() is None, node.stderr.read()
            assert time.monotonic() < deadline
            time.sleep(0.5)
        os.killpg(first.pid, signal.SIGINT)
        first.wait(timeout=30)
        second = core()
        _, err = node.communicate(timeout=60)
        assert node.returncode == 1, err
        assert "the ROS master was restarted" in err and "start the node again" in err
    finally:
        if node.poll() is None:
            os.killpg(node.pid, 9)
            node.communicate()
        for proc in (first, second):
            if proc is not None and proc.poll() is None:
                os.killpg(proc.pid, signal.SIGINT)
                proc.wait(timeout=30)

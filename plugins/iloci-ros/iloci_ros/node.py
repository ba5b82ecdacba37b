"""The ROS 1 adapter: topics and messages around a :class:`~iloci_ros.session.TeachingSession`.

Topics (``PREFIX`` is ``iloci`` unless ``--prefix`` says otherwise):

========================  ===================================  ==========================
topic                     type                                 what
========================  ===================================  ==========================
``/PREFIX/drawing``       ``nav_msgs/Path`` (in)               a drawing: the poses'
                                                               ``x, y``; their header
                                                               stamps as time stamps when
                                                               strictly increasing
``/PREFIX/polygon``       ``geometry_msgs/PolygonStamped``     a drawing without times
                          (in)                                 (answered at
                                                               ``UNTIMED_PACE``)
``/PREFIX/feedback``      ``std_msgs/String`` (in)             JSON ``{"answer_id": ID,
                                                               "value": 1 | -1}``
``/PREFIX/guess``         ``std_msgs/String`` (out)            JSON: ``kind: "guess"``,
                                                               ``answer_id``, ``demo``,
                                                               ``concept``,
                                                               ``confidence``, ``attempt``,
                                                               ``joint_names``, ``dt``,
                                                               ``stamp``
``/PREFIX/joint_path``    ``trajectory_msgs/JointTrajectory``  the guess's joint path
                          (out)                                (rad), same header stamp as
                                                               its guess
``/PREFIX/outcome``       ``std_msgs/String`` (out)            JSON ``kind: "placed"``: a
                                                               drawing's turn ended
``/PREFIX/feedback_result`` ``std_msgs/String`` (out)          JSON ``{"answer_id",
                                                               "accepted", "error"}`` for
                                                               every feedback
``/PREFIX/error``         ``std_msgs/String`` (out)            JSON ``{"error"}``: a
                                                               drawing that could not be
                                                               used
========================  ===================================  ==========================

The guess goes out before its joint path, both with one header stamp (the
guess's JSON carries it as ``stamp``, seconds). Every message type is a
standard one, so ``rostopic`` and ``rosbag`` handle them without building
anything. A feedback whose ``answer_id`` is not the pending answer's
(duplicate, late, other drawing) is refused on ``feedback_result`` and
changes nothing.
"""

from __future__ import annotations

import argparse
import json
import re
import signal
import threading
from pathlib import Path
import sys
from typing import Any

import numpy as np

from iloci.errors import IlociError
from iloci_ros.session import Guess, Placed, TeachingSession

__all__ = ["RosNode", "path_to_drawing", "polygon_to_drawing", "register", "run"]


def path_to_drawing(msg: Any) -> tuple[np.ndarray, np.ndarray | None]:
    """A ``nav_msgs/Path`` as ``(positions (N, 2), times (N,) s or None)``.

    Times are the poses' header stamps, used only when strictly increasing
    (a path whose poses carry no stamps gives None: no time stamps).
    """
    poses = msg.poses
    xy = np.array([[p.pose.position.x, p.pose.position.y] for p in poses], dtype=np.float64)
    t = np.array([p.header.stamp.to_sec() for p in poses], dtype=np.float64)
    times = t - t[0] if len(t) > 1 and np.all(np.diff(t) > 0) else None
    return xy.reshape(-1, 2), times


def polygon_to_drawing(msg: Any) -> tuple[np.ndarray, None]:
    """A ``geometry_msgs/PolygonStamped`` as ``(positions (N, 2), None)``."""
    xy = np.array([[p.x, p.y] for p in msg.polygon.points], dtype=np.float64)
    return xy.reshape(-1, 2), None


class RosNode:
    """Subscribes to drawings and feedback, publishes guesses, joint paths and outcomes.

    Parameters
    ----------
    session : TeachingSession
    rospy : module
        From :func:`iloci_ros.rospath.import_rospy`, after ``rospy.init_node``.
    prefix : str
        Topic namespace: relative (``iloci``: resolved in the node's
        namespace, so ``ROS_NAMESPACE=robot1`` or a launch file's ``<group
        ns="robot1">`` gives ``/robot1/iloci/drawing``), or absolute
        (``/iloci``).
    watch_master : float
        Seconds between checks that the ROS master is the one the node
        registered with (0: none). A roscore restarted under a rospy node
        leaves it registered nowhere, deaf to every topic, without a word;
        on a new master (its ``/run_id`` changed) the node stops
        (:attr:`master_restarted`), so that it can be started again (by
        hand or by ``respawn="true"``).
    """

    def __init__(self, session: TeachingSession, rospy: Any, prefix: str = "iloci",
                 watch_master: float = 2.0) -> None:
        from geometry_msgs.msg import PolygonStamped
        from nav_msgs.msg import Path as PathMsg
        from std_msgs.msg import String
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

        self.session = session
        self.rospy = rospy
        self._String = String
        self._JointTrajectory = JointTrajectory
        self._Point = JointTrajectoryPoint
        # a relative prefix resolves in the node's namespace (ROS_NAMESPACE, <group ns>)
        p = "/" + prefix.strip("/") if prefix.startswith("/") else prefix.strip("/")
        #: The topics' namespace as resolved (``/iloci``, ``/robot1/iloci``).
        self.topics = rospy.resolve_name(p)
        #: True once the node stopped because its ROS master was replaced.
        self.master_restarted = False
        self._master_lost = False
        self._run_id = self._master_run_id()
        pub = rospy.Publisher
        self.pub_guess = pub(f"{p}/guess", String, queue_size=10)
        self.pub_path = pub(f"{p}/joint_path", JointTrajectory, queue_size=10)
        self.pub_outcome = pub(f"{p}/outcome", String, queue_size=10)
        self.pub_result = pub(f"{p}/feedback_result", String, queue_size=10)
        self.pub_error = pub(f"{p}/error", String, queue_size=10)
        # no bound on the incoming queues (queue_size=None): a drawing is learned for
        # seconds while messages wait, and a bounded queue drops the oldest without a
        # word (10 feedbacks sent during a rehearsal lost the 11th's teacher judgement)
        self.subs = [
            rospy.Subscriber(f"{p}/drawing", PathMsg, self._on_path, queue_size=None),
            rospy.Subscriber(f"{p}/polygon", PolygonStamped, self._on_polygon,
                             queue_size=None),
            rospy.Subscriber(f"{p}/feedback", String, self._on_feedback, queue_size=None),
        ]

        if watch_master > 0 and self._run_id is not None:
            self._watch = rospy.Timer(rospy.Duration(watch_master), self._check_master)

    # -- the master ------------------------------------------------------------------
    def _master_run_id(self) -> str | None:
        try:
            return str(self.rospy.get_param("/run_id"))
        except Exception:          # noqa: BLE001  (no master, no /run_id: socket or KeyError)
            return None

    def _check_master(self, _event: Any = None) -> None:
        run_id = self._master_run_id()
        if run_id is None:
            if not self._master_lost:
                self._master_lost = True
                self.rospy.logwarn("iloci: the ROS master does not answer; waiting for it")
            return
        self._master_lost = False
        if run_id != self._run_id:
            self.master_restarted = True
            self.rospy.logerr("iloci: the ROS master was restarted; stopping")
            self.rospy.signal_shutdown("the ROS master was restarted")

    # -- in ------------------------------------------------------------------------
    def _on_path(self, msg: Any) -> None:
        self._drawing(*path_to_drawing(msg), key=self._key(msg))

    def _on_polygon(self, msg: Any) -> None:
        self._drawing(*polygon_to_drawing(msg), key=self._key(msg))

    def _key(self, msg: Any) -> str | None:
        """``"{shape}/{stamp in ns}"`` of a message with a header stamp, else None (a counter).

        The same message delivered again (a duplicate, a late copy, a bag
        replayed) then has the same key, and teaching it again changes
        nothing (``already_learned``).
        """
        stamp = getattr(getattr(msg, "header", None), "stamp", None)
        ns = int(stamp.to_nsec()) if stamp is not None else 0
        return f"{self.session.shape}/{ns}" if ns > 0 else None

    def _drawing(self, positions: np.ndarray, times: np.ndarray | None,
                 key: str | None = None) -> None:
        try:
            result = self.session.drawing(positions, times, key=key)
        except IlociError as exc:
            self.rospy.logwarn(f"iloci: drawing refused: {exc}")
            self._send(self.pub_error, {"error": str(exc)})
            return
        self._publish(result)

    def _on_feedback(self, msg: Any) -> None:
        try:
            data = json.loads(msg.data)
            answer_id, value = data["answer_id"], data["value"]
        except (ValueError, TypeError, KeyError, RecursionError):  # Recursion: "[[[..."
            self._send(self.pub_result, {
                "answer_id": None, "accepted": False,
                "error": f"feedback must be JSON {{\"answer_id\": ID, \"value\": 1 | -1}}, "
                         f"got {msg.data!r}"})
            return
        try:
            result = self.session.feedback(str(answer_id), value)
        except IlociError as exc:
            self.rospy.logwarn(f"iloci: feedback refused: {exc}")
            self._send(self.pub_result, {"answer_id": answer_id, "accepted": False,
                                         "error": str(exc)})
            return
        self._send(self.pub_result, {"answer_id": answer_id, "accepted": True, "error": None})
        self._publish(result)

    # -- out -----------------------------------------------------------------------
    def _send(self, pub: Any, data: dict[str, Any]) -> None:
        pub.publish(self._String(data=json.dumps(data)))

    def _publish(self, result: Guess | Placed) -> None:
        if isinstance(result, Placed):
            self._send(self.pub_outcome, result.to_dict())
            if result.save_error:
                self.rospy.logerr(f"iloci: {result.save_error}")
                self._send(self.pub_error, {"error": result.save_error})
            return
        stamp = self.rospy.Time.now()
        self._send(self.pub_guess, {**result.to_dict(), "stamp": stamp.to_sec()})
        traj = self._JointTrajectory()
        traj.header.stamp = stamp
        traj.joint_names = list(result.joint_names)
        for i, q in enumerate(result.joint_path):
            point = self._Point()
            point.positions = [float(v) for v in q]
            point.time_from_start = self.rospy.Duration.from_sec(i * result.dt)
            traj.points.append(point)
        self.pub_path.publish(traj)


def _finish(session: TeachingSession) -> None:
    """On the way out (Ctrl-C, rosnode kill): let the drawing in progress be learned and
    saved, and say what is left unlearned (before, the process ended under it)."""
    if threading.current_thread() is threading.main_thread():
        # rospy's handler only shuts down again: a second Ctrl-C must reach us
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if session.busy:
        print("iloci ros: stopping once the drawing in progress is learned and saved "
              "(Ctrl-C again abandons it) ...", file=sys.stderr, flush=True)
        try:
            session.finish()
        except KeyboardInterrupt:
            print("iloci ros: abandoned: the drawing in progress is not learned; the memory "
                  "file holds what was saved before it.", file=sys.stderr, flush=True)
            return
    pending = session.pending
    if pending is not None:
        print(f"iloci ros: drawing {pending.demo} was not learned: its answer "
              f"{pending.answer_id} was never judged.", file=sys.stderr, flush=True)
    else:
        print("iloci ros: stopped; no drawing was in progress.", file=sys.stderr, flush=True)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "ros", help="run the robot as a ROS 1 node: drawings in, guesses and joint paths out",
        description="A ROS 1 node (rospy) teaching the memory FILE: subscribes to "
                    "/PREFIX/drawing (nav_msgs/Path) and /PREFIX/polygon "
                    "(geometry_msgs/PolygonStamped), publishes /PREFIX/guess (JSON: concept, "
                    "confidence, answer_id) and /PREFIX/joint_path "
                    "(trajectory_msgs/JointTrajectory), takes /PREFIX/feedback (JSON "
                    "answer_id, value) and saves the memory after each drawing placed. "
                    "Topic details: python -c 'import iloci_ros.node as n; print(n.__doc__)'. "
                    "Needs a running roscore (ROS_MASTER_URI).")
    p.add_argument("--memory", metavar="FILE", required=True,
                   help="the memory to teach (created on the first drawing placed when "
                        "missing)")
    p.add_argument("--config", metavar="TOML", default=None,
                   help="config for a new memory (default: the defaults)")
    p.add_argument("--prefix", default="iloci", help="topic namespace (default: iloci)")
    p.add_argument("--node-name", default="iloci", help="ROS node name (default: iloci)")
    p.add_argument("--worker", action="store_true",
                   help="run the network in a worker process (Agent.start_worker)")
    # roslaunch appends remappings (__name:=..., __log:=...); rospy reads them from sys.argv
    p.add_argument("remappings", nargs="*", metavar="NAME:=VALUE",
                   help="ROS remappings, as roslaunch passes them")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import iloci
    from iloci_ros.rospath import import_rospy

    from iloci.data.writes import check_memory_path
    from iloci.errors import InvalidInputError
    from iloci.progress import acquire_memory_lock
    bad = [r for r in args.remappings if ":=" not in r]
    if bad:
        raise InvalidInputError(f"iloci ros: unexpected argument(s) {bad}; only ROS "
                                "remappings NAME:=VALUE may follow the options.")
    if not re.fullmatch(r"/?[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*/?", args.prefix):
        raise InvalidInputError(f"--prefix {args.prefix!r} is not a ROS name: letters, digits "
                                "and _, starting with a letter, parts joined by / (e.g. "
                                "iloci or robot1/iloci; a leading / makes it absolute, "
                                "outside the node's namespace).")
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", args.node_name):
        raise InvalidInputError(f"--node-name {args.node_name!r} is not a ROS node name: "
                                "letters, digits and _, starting with a letter (e.g. iloci).")
    rospy = import_rospy()
    path = Path(args.memory)
    check_memory_path(path)  # a folder, a loop, a folder that takes no file: said now
    # one writer per memory, as iloci teach and iloci serve (two nodes on one file lost
    # each other's drawings)
    release = acquire_memory_lock(path, "iloci ros")
    try:
        agent = (iloci.Agent.load(path, args.config) if path.exists()
                 else iloci.build(args.config))
        if args.worker:
            agent.start_worker()
        session = TeachingSession(agent, save_to=path)
        rospy.init_node(args.node_name, anonymous=False, disable_signals=False)
        node = RosNode(session, rospy, prefix=args.prefix)
        print(f"iloci ros: node {rospy.get_name()} on {node.topics}/*, memory "
              f"{path} ({len(agent.memory)} entries, robot {agent.robot.name})",
              file=sys.stderr, flush=True)
        try:
            rospy.spin()
        finally:
            _finish(session)
            agent.close()
    finally:
        release()
    if node.master_restarted:
        print("iloci ros: the ROS master was restarted (its /run_id changed): this node's "
              "topics were registered with the old one, and no message would have reached "
              "it. Stopped, with the memory saved; start the node again (in a launch file, "
              "respawn=\"true\" does).", file=sys.stderr, flush=True)
        return 1
    return 0

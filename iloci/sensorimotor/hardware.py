"""Driving a real arm: an executor with the Simulator protocol, without rendering.

An embedding robot stack supplies an :class:`ArmDriver`, the few calls its
arm's controller offers (read the joint angles, send a set-point);
:class:`ArmExecutor` turns it into a :class:`~iloci.interfaces.Simulator`
that iloci can execute responses on::

    executor = ArmExecutor(MyDriver(), robot=agent.robot, forward=agent.ik_solver.forward)
    agent = iloci.build("my.toml", simulator=executor)

A real arm is wherever it was left: :meth:`ArmExecutor.execute` first moves
it from its current posture to the path's first one
(:func:`iloci.sensorimotor.simulation.approach`, no joint faster than
``approach_speed``), then streams the path's set-points in real time, as the
simulators do (:func:`iloci.sensorimotor.simulation.setpoints`: linear in
each step ``dt``, updated every ``control_period``, with the step's velocity
as feed-forward), and reads the joints back after each step. The pen tip is
the forward kinematics of the angles read. It has no ``render``.

A real arm takes seconds per answer. :meth:`ArmExecutor.submit` runs a
motion in the background (one arm thread; motions run one after the other,
in the order submitted) and returns an :class:`ArmMotion` at once: a future
with completion events (``done()``, ``wait()``, ``result()``,
``add_done_callback()``) and ``cancel()``. With ``background=True`` the
executor, attached to an agent (``agent.simulator = executor``, or
:meth:`ArmExecutor.attach`), submits every answer that way:
``agent.observe`` and ``turn.feedback`` return while the arm moves, the
answer's drawing is the generated pen path (``response.execution`` is
None), and ``executor.last_motion`` is the motion of the latest answer.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import CancelledError, Future, ThreadPoolExecutor
import logging
import threading
import time
from typing import Any, Protocol, runtime_checkable

import numpy as np

from iloci.errors import InvalidInputError
from iloci.interfaces import Execution
from iloci.sensorimotor import simulation
from iloci.sensorimotor.robots import Robot

LOG = logging.getLogger(__name__)

__all__ = ["ArmDriver", "ArmExecutor", "ArmMotion"]


@runtime_checkable
class ArmDriver(Protocol):
    """What :class:`ArmExecutor` needs of a real arm's controller."""

    def read_joints(self) -> np.ndarray:
        """The joint angles now, shape (J,) (rad), in the robot's joint order."""
        ...

    def command(self, position: np.ndarray, velocity: np.ndarray) -> None:
        """Send a set-point: positions (J,) (rad) and feed-forward velocities (J,) (rad/s)."""
        ...


class ArmMotion:
    """One motion of the arm running in the background (:meth:`ArmExecutor.submit`).

    A thin wrapper around a :class:`concurrent.futures.Future` of the
    motion's :class:`~iloci.interfaces.Execution`.

    Attributes
    ----------
    joint_path : ndarray, shape (T, J)
        The path submitted (rad).
    dt : float
        s.
    started, finished : threading.Event
        Set when the arm starts the motion (after the motions before it),
        and when it has ended (done, failed or cancelled).
    """

    def __init__(self, future: Future, joint_path: np.ndarray, dt: float,
                 started: threading.Event, stop: threading.Event) -> None:
        self._future = future
        self._stop = stop
        self.joint_path = joint_path
        self.dt = dt
        self.started = started
        self.finished = threading.Event()
        self._callbacks: list[Callable[[ArmMotion], None]] = []
        self._callbacks_lock = threading.Lock()
        future.add_done_callback(self._ended)

    def _ended(self, _: Future) -> None:
        # One done-callback of the future runs the caller's callbacks in order and only
        # then sets ``finished``, so that once result(), wait() or done() say the motion
        # ended, every callback has run (a Future wakes its waiters before its callbacks).
        with self._callbacks_lock:
            callbacks, self._callbacks = self._callbacks, []
        for fn in callbacks:
            try:
                fn(self)
            except Exception:
                LOG.exception("a done-callback of %r raised", self)
        self.finished.set()

    def __repr__(self) -> str:
        state = ("cancelled" if self._future.cancelled() else "done" if self._future.done()
                 else "running" if self.started.is_set() else "queued")
        return f"ArmMotion({len(self.joint_path)} steps, dt={self.dt:g} s, {state})"

    def done(self) -> bool:
        """Whether the motion has ended (done, failed or cancelled); never blocks."""
        return self.finished.is_set()

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the motion ends, at most ``timeout`` s; whether it ended."""
        return self.finished.wait(timeout)

    def result(self, timeout: float | None = None) -> Execution:
        """The :class:`~iloci.interfaces.Execution`, once the motion ended.

        Raises
        ------
        TimeoutError
            Not ended within ``timeout`` s.
        concurrent.futures.CancelledError
            The motion was cancelled.
        Exception
            Whatever the driver raised (the arm stopped where it was).
        """
        if not self.finished.wait(timeout):
            raise TimeoutError(f"the motion did not end within {timeout} s")
        return self._future.result(0)

    def add_done_callback(self, fn: Callable[[ArmMotion], None]) -> None:
        """Call ``fn(motion)`` when the motion ends, in the arm's thread (at once if it has).

        Callbacks run in the order they were added, before :attr:`finished` is set.
        """
        with self._callbacks_lock:
            if not self._future.done():
                self._callbacks.append(fn)
                return
        self.finished.wait()      # the future's own callback is running the others
        fn(self)

    def cancel(self) -> bool:
        """Stop the motion: a queued one never starts, a running one stops at its next
        set-point (the arm holds the last one sent). Whether it had not ended yet."""
        if self._future.cancel():
            return True
        if self._future.done():
            return False
        self._stop.set()
        return True


class ArmExecutor:
    """A :class:`~iloci.interfaces.Simulator` driving a real arm through an :class:`ArmDriver`.

    Parameters
    ----------
    driver : ArmDriver
    robot : Robot
        The arm's description (joint order, limits).
    forward : callable (T, J) -> (T, 3)
        Forward kinematics of the pen tip, base frame (an IK solver's
        ``forward``).
    control_period : float
        Time between two set-points (s).
    approach_speed : float
        Largest joint speed while moving to the path's first posture (rad/s).
    clock : callable () -> float, optional
        Seconds, monotonic (default :func:`time.monotonic`).
    sleep : callable (float) -> None, optional
        Waits that many seconds (default :func:`time.sleep`). A driver that
        blocks until its controller's next cycle passes ``lambda s: None``.
    background : bool
        :meth:`execute` submits the motion (:meth:`submit`) and returns
        None at once instead of waiting for the arm: for an agent whose
        ``observe`` and ``feedback`` must not wait for the arm. The motion
        of the latest answer is :attr:`last_motion`.

    Attributes
    ----------
    robot : Robot
    joint_names : tuple of str
    lower, upper : ndarray, shape (J,)
    last_approach : ndarray, shape (K, J)
        The joint path of the last move to a path's start.
    last_motion : ArmMotion or None
        The motion last submitted.
    """

    def __init__(self, driver: Any, robot: Robot, forward: Callable[[np.ndarray], np.ndarray],
                 control_period: float = 0.01, approach_speed: float = 0.5,
                 clock: Callable[[], float] | None = None,
                 sleep: Callable[[float], None] | None = None,
                 background: bool = False) -> None:
        if not isinstance(driver, ArmDriver):
            raise InvalidInputError(f"driver {type(driver).__name__} must have read_joints() "
                                    "and command(position, velocity) (see "
                                    "iloci.sensorimotor.hardware.ArmDriver).")
        if not (control_period > 0 and approach_speed > 0):
            raise InvalidInputError("control_period and approach_speed must be > 0.")
        self.driver = driver
        self.robot = robot
        self.forward = forward
        self.control_period = float(control_period)
        self.approach_speed = float(approach_speed)
        self._clock = clock or time.monotonic
        self._sleep = sleep or time.sleep
        self.joint_names = tuple(robot.joint_names)
        self.lower = np.array(robot.lower, dtype=np.float64)
        self.upper = np.array(robot.upper, dtype=np.float64)
        self.last_approach = np.zeros((0, len(self.joint_names)))
        self.background = bool(background)
        self.last_motion: ArmMotion | None = None
        self._pool: ThreadPoolExecutor | None = None
        self._pool_lock = threading.Lock()

    @classmethod
    def attach(cls, agent: Any, driver: Any, **options: Any) -> ArmExecutor:
        """An executor for ``agent``'s robot and IK, set as its simulator (no second load).

        ``options`` as for the constructor (e.g. ``background=True``).
        Returns the executor; ``agent.simulator`` is it from now on.
        """
        executor = cls(driver, agent.robot, agent.ik_solver.forward, **options)
        agent.simulator = executor
        return executor

    def __repr__(self) -> str:
        return (f"ArmExecutor({type(self.driver).__name__}, robot={self.robot.name!r}, "
                f"control_period={self.control_period})")

    def _read(self) -> np.ndarray:
        q = np.asarray(self.driver.read_joints(), dtype=np.float64)
        if q.shape != (len(self.joint_names),) or not np.all(np.isfinite(q)):
            raise InvalidInputError(f"driver.read_joints() gave {q!r}; expected "
                                    f"{len(self.joint_names)} finite angles "
                                    f"({', '.join(self.joint_names)}).")
        return q

    def _stream(self, q: np.ndarray, dt: float, record: bool,
                stop: threading.Event | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Send the set-points of path ``q`` in real time; the angles read after each step."""
        reached = np.empty_like(q)
        reached[0] = self._read()
        n = simulation.updates_per_step(dt, self.control_period)
        tick = self._clock()
        for i, targets, velocity in simulation.setpoints(q, dt, self.control_period):
            for target in targets:
                if stop is not None and stop.is_set():
                    raise CancelledError("the arm's motion was cancelled")
                self.driver.command(target, velocity)
                tick += dt / n
                wait = tick - self._clock()
                if wait > 0:
                    self._sleep(wait)
            if record:
                reached[i + 1] = self._read()
        pen = np.asarray(self.forward(reached), dtype=np.float64) if record else np.zeros(0)
        return reached, pen

    def execute(self, joint_path: np.ndarray, dt: float) -> Execution:
        """Move to the path's first posture, then track the path; what the arm reached.

        Shapes and errors as :meth:`iloci.interfaces.Simulator.execute`;
        row 0 of the result is the posture read once the arm reached the
        path's start. With ``background=True``: :meth:`submit`, and None
        at once (the path is checked first: errors as above).
        """
        if self.background:
            self.submit(joint_path, dt)
            return None  # type: ignore[return-value]  # documented: background mode
        with self._pool_lock:
            busy = self.last_motion is not None and not self.last_motion.done()
        if busy:  # one arm: wait for the motions submitted before
            return self.submit(joint_path, dt).result()
        return self._run(joint_path, dt)

    def submit(self, joint_path: np.ndarray, dt: float) -> ArmMotion:
        """Run the motion in the background; an :class:`ArmMotion` at once.

        The path is checked now (errors as :meth:`execute`, raised here);
        the arm runs it after the motions submitted before it.
        """
        q, step = simulation.check_joint_path(joint_path, dt, self.robot)
        started, stop = threading.Event(), threading.Event()

        def run() -> Execution:
            started.set()
            return self._run(q, step, stop)

        with self._pool_lock:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(1, thread_name_prefix="iloci-arm")
            motion = ArmMotion(self._pool.submit(run), q, step, started, stop)
            self.last_motion = motion
        return motion

    def _run(self, joint_path: np.ndarray, dt: float,
             stop: threading.Event | None = None) -> Execution:
        q, step = simulation.check_joint_path(joint_path, dt, self.robot)
        lead = simulation.approach(self._read(), q[0], step, self.approach_speed)
        self.last_approach = lead
        if len(lead) > 1:
            self._stream(lead, step, record=False, stop=stop)
        reached, pen = self._stream(q, step, record=True, stop=stop)
        return Execution(joint_path=reached, end_effector=pen, dt=step)

    def close(self) -> None:
        """Cancel queued motions, wait for the running one, release the driver (idempotent)."""
        with self._pool_lock:
            pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
        close = getattr(self.driver, "close", None)
        if callable(close):
            close()

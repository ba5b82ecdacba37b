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
"""

from __future__ import annotations

from collections.abc import Callable
import time
from typing import Any, Protocol, runtime_checkable

import numpy as np

from iloci.errors import InvalidInputError
from iloci.interfaces import Execution
from iloci.sensorimotor import simulation
from iloci.sensorimotor.robots import Robot

__all__ = ["ArmDriver", "ArmExecutor"]


@runtime_checkable
class ArmDriver(Protocol):
    """What :class:`ArmExecutor` needs of a real arm's controller."""

    def read_joints(self) -> np.ndarray:
        """The joint angles now, shape (J,) (rad), in the robot's joint order."""
        ...

    def command(self, position: np.ndarray, velocity: np.ndarray) -> None:
        """Send a set-point: positions (J,) (rad) and feed-forward velocities (J,) (rad/s)."""
        ...


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

    Attributes
    ----------
    robot : Robot
    joint_names : tuple of str
    lower, upper : ndarray, shape (J,)
    last_approach : ndarray, shape (K, J)
        The joint path of the last move to a path's start.
    """

    def __init__(self, driver: Any, robot: Robot, forward: Callable[[np.ndarray], np.ndarray],
                 control_period: float = 0.01, approach_speed: float = 0.5,
                 clock: Callable[[], float] | None = None,
                 sleep: Callable[[float], None] | None = None) -> None:
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

    def _stream(self, q: np.ndarray, dt: float, record: bool) -> tuple[np.ndarray, np.ndarray]:
        """Send the set-points of path ``q`` in real time; the angles read after each step."""
        reached = np.empty_like(q)
        reached[0] = self._read()
        n = simulation.updates_per_step(dt, self.control_period)
        tick = self._clock()
        for i, targets, velocity in simulation.setpoints(q, dt, self.control_period):
            for target in targets:
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
        path's start.
        """
        q, step = simulation.check_joint_path(joint_path, dt, self.robot)
        lead = simulation.approach(self._read(), q[0], step, self.approach_speed)
        self.last_approach = lead
        if len(lead) > 1:
            self._stream(lead, step, record=False)
        reached, pen = self._stream(q, step, record=True)
        return Execution(joint_path=reached, end_effector=pen, dt=step)

    def close(self) -> None:
        """Release the driver when it has a ``close`` (idempotent)."""
        close = getattr(self.driver, "close", None)
        if callable(close):
            close()

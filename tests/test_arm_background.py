"""The real-arm executor in the background: observe/feedback return while the arm moves.

The arm is a driver whose controller is held by a gate the test opens: a
call that waited for the arm would never return while the gate is shut, so
returning at all proves it did not wait (no timing in the assertions).
"""

from __future__ import annotations

from concurrent.futures import CancelledError
import threading

import numpy as np
import pytest

import iloci
from iloci.errors import InvalidInputError
from iloci.sensorimotor.hardware import ArmExecutor, ArmMotion

pytest.importorskip("iloci_native")
pytest.importorskip("pinocchio")



class GatedArm:
    """A perfect servo whose controller runs only while ``gate`` is open."""

    def __init__(self, q):
        self.q = np.array(q, dtype=float)
        self.gate = threading.Event()
        self.commands = 0
        self.threads = set()

    def read_joints(self):
        return self.q.copy()

    def command(self, position, velocity):
        assert self.gate.wait(60), "the test never opened the gate"
        self.threads.add(threading.current_thread().name)
        self.commands += 1
        self.q = np.array(position, dtype=float)


@pytest.fixture(scope="module")
def taught(small_agent, lasa):
    agent = small_agent()
    agent.teach([lasa["GShape/0"], lasa["Angle/0"]])
    return agent, lasa


def test_submit_returns_at_once_with_completion_events(taught):
    agent, _ = taught
    arm = GatedArm(agent.robot.q_home + 0.1)
    executor = ArmExecutor(arm, agent.robot, agent.ik_solver.forward, sleep=lambda s: None)
    path = agent.respond("c1").joint_path
    first = executor.submit(path, 0.05)            # the gate is shut: the arm cannot move
    second = executor.submit(path[::-1].copy(), 0.05)
    assert isinstance(first, ArmMotion) and not first.done() and not second.started.is_set()
    ended = []
    first.add_done_callback(ended.append)
    arm.gate.set()
    execution = first.result(timeout=60)
    assert execution.joint_path.shape == path.shape and first.finished.is_set()
    assert ended == [first]
    assert second.wait(60) and second.started.is_set()
    np.testing.assert_allclose(arm.q, path[0])     # in order: the second path ends at path[0]
    assert arm.threads and all(t.startswith("iloci-arm") for t in arm.threads)
    with pytest.raises(InvalidInputError):          # a bad path fails at submit, not later
        executor.submit(np.full((5, 4), np.nan), 0.05)
    executor.close()


def test_cancel_stops_a_running_motion(taught):
    agent, _ = taught
    arm = GatedArm(agent.robot.q_home)
    executor = ArmExecutor(arm, agent.robot, agent.ik_solver.forward, sleep=lambda s: None)
    path = agent.respond("c1").joint_path
    motion = executor.submit(path, 0.05)
    queued = executor.submit(path, 0.05)
    assert motion.started.wait(60)
    assert queued.cancel() and motion.cancel()
    arm.gate.set()
    assert motion.wait(60)
    with pytest.raises(CancelledError):
        motion.result()
    with pytest.raises(CancelledError):
        queued.result()
    # stopped at its next set-point: at most the one it was waiting to send
    assert arm.commands <= 1
    executor.close()


def test_an_attached_background_arm_does_not_hold_observe_or_feedback(taught, tmp_path):
    agent, demos = taught
    loaded = iloci.Agent.load(agent.save(tmp_path / "m.npz"))
    arm = GatedArm(loaded.robot.q_home + 0.2)
    executor = ArmExecutor.attach(loaded, arm, background=True, sleep=lambda s: None)
    assert loaded.simulator is executor              # attached: no second load
    try:
        turn = loaded.observe(demos["Angle/1"])       # returns with the arm's gate shut
        motion = executor.last_motion
        assert motion is not None and not motion.done()
        assert turn.answer.response.execution is None     # drawn path: the generated one
        right = turn.answer.concept == "c2"
        step = turn.feedback(1 if right else -1, turn.answer.id)   # returns too
        if not right:
            assert executor.last_motion is not motion   # the next guess's motion, queued
        arm.gate.set()
        assert executor.last_motion.wait(60)
        assert executor.last_motion.result().joint_path.shape[1] == 4
        assert step is not None
    finally:
        arm.gate.set()
        executor.close()

"""The robot's answers performed: an entry regenerated, or a demonstration imitated back.

A free function of the network and the memory, so performing needs no
clusterer and no teacher: a turn's guesses (:meth:`Learner.respond
<iloci.concepts.learner.Learner.respond>`), :meth:`Agent.respond
<iloci.agent.Agent.respond>` and :func:`iloci.drawing.draw` call
:func:`perform`; the novelty answer calls :func:`perform_novel`. Both decode
through :func:`act`, the one place a generated sequence becomes a joint path
clipped to the arm's limits and, with a simulator, an execution.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from iloci.concepts import rehearsal
from iloci.concepts.memory import Memory
from iloci.errors import NotFittedError
from iloci.interfaces import PerceptualModel, Response, Simulator
from iloci.sensorimotor.frames import TeacherFrame

__all__ = ["Acted", "act", "ik_joint_limits", "perform", "perform_novel"]


class Acted(NamedTuple):
    """What :func:`act` made of an encoded sequence."""

    #: (T, 2) the sensory channels decoded into plane points (m).
    plane: np.ndarray
    #: (T, J) the motor channels decoded (rad), clipped to the joint limits.
    joints: np.ndarray
    #: Joint values moved onto a limit.
    clipped: int
    #: The simulator's execution of ``joints`` (``None`` without a simulator).
    execution: Any
    #: What was drawn, in the teacher's frame when one is given (else ``None``).
    teacher_drawing: np.ndarray | None


def act(memory: Memory, sequence: np.ndarray, start: np.ndarray, dt: float, *,
        joint_limits: tuple[np.ndarray, np.ndarray] | None = None,
        simulator: Simulator | None = None, frame: TeacherFrame | None = None) -> Acted:
    """An encoded sequence decoded, clipped to the joint limits and executed.

    Parameters
    ----------
    memory : Memory
        With a fitted encoder (its scales decode ``sequence``).
    sequence : ndarray, shape (T - 1, D)
    start : ndarray, shape (D,)
        Absolute first sample ``[y, z, q1..qJ]`` (m, rad).
    dt : float
        Time step (s) the simulator executes the joint path at.
    joint_limits, simulator, frame
        As for :func:`perform`.

    Raises
    ------
    NotFittedError
        The memory has no fitted encoder.
    """
    encoder = memory.encoder
    if encoder is None:
        raise NotFittedError("the memory has no fitted sensorimotor encoder.")
    plane, joints = encoder.decode(sequence, start)
    clipped = 0
    if joint_limits is not None:
        lower, upper = (np.asarray(a, dtype=np.float64) for a in joint_limits)
        inside = np.clip(joints, lower, upper)
        clipped = int(np.count_nonzero(inside != joints))
        joints = inside
    execution = None
    if simulator is not None:
        execution = simulator.execute(joints, dt)
    drawing = plane if execution is None else np.asarray(execution.end_effector)[:, 1:3]
    return Acted(plane, joints, clipped, execution,
                 None if frame is None else frame.to_teacher(drawing))


def perform(memory: Memory, model: PerceptualModel, index: int, *,
            joint_limits: tuple[np.ndarray, np.ndarray] | None = None,
            simulator: Simulator | None = None, attempt: int = 1,
            frame: TeacherFrame | None = None) -> Response:
    """The robot's answer: entry ``index`` of ``memory`` regenerated, decoded and performed.

    A free function of the network (``model``, its weights) and the memory
    (the data it regenerates from), so performing needs no clusterer and no
    teacher: :meth:`Learner.respond`, :meth:`~iloci.agent.Agent.respond` and
    :func:`iloci.drawing.draw` all call it.

    Parameters
    ----------
    memory : Memory
        With a fitted encoder.
    model : PerceptualModel
        The memory's network.
    index : int
        Entry of ``memory.entries`` to perform (the paper performs a
        concept's entry of lowest generation error:
        :meth:`Memory.performer_of`).
    joint_limits : (ndarray, ndarray), each shape (J,), optional
        Lower and upper joint limits (rad) the decoded joint path is
        clipped to (:func:`ik_joint_limits` reads them off an IK solver).
    simulator : Simulator, optional
        Executes the joint path when given.
    attempt : int
        1 for the first guess on a demonstration, 2 for the second, ...
    frame : TeacherFrame, optional
        The frame of the demonstration answered.

    Returns
    -------
    Response
        ``motion`` (T, 2): the regenerated sensory channels decoded into
        plane points (m); ``joint_path`` (T, J): the regenerated motor
        channels decoded (rad) and clipped to the joint limits (``T =
        numSteps + 1``); the simulator's
        :class:`~iloci.interfaces.Execution` of that joint path when one is
        given; ``dt`` (s) between joint-path rows; ``teacher_drawing``, the
        drawing in ``frame``, when one is given. ``extra`` holds ``entry``, ``generation_error`` and
        ``clipped`` (how many joint values were moved onto a limit).

    Raises
    ------
    NotFittedError
        The memory has no fitted encoder.
    """
    entry = memory.entries[index]
    if memory.encoder is None:
        raise NotFittedError("the memory has no fitted sensorimotor encoder.")
    seq = rehearsal.regenerate(model, [entry])[0]
    a = act(memory, seq, entry.start, entry.dt, joint_limits=joint_limits,
            simulator=simulator, frame=frame)
    return Response(concept=entry.concept, motion=a.plane, joint_path=a.joints,
                    source=entry.source, sources=tuple(entry.sources), dt=float(entry.dt),
                    teacher_drawing=a.teacher_drawing, execution=a.execution, attempt=attempt,
                    extra={"entry": index, "generation_error": entry.generation_error,
                           "clipped": a.clipped})


def perform_novel(memory: Memory, sequence: np.ndarray, start: np.ndarray, dt: float, *,
                  joint_limits: tuple[np.ndarray, np.ndarray] | None = None,
                  simulator: Simulator | None = None, attempt: int = 1,
                  familiarity: float = float("nan"),
                  frame: TeacherFrame | None = None) -> Response:
    """The novelty answer: the demonstration imitated back as something new.

    The robot performs the demonstration as it perceived it (its encoded
    ``sequence`` decoded through :func:`act`), labelled with the concept it
    would found.

    Returns
    -------
    Response
        ``novel=True``, ``concept`` the label a new concept would get,
        ``source=None``, ``sources`` every demonstration the memory stands
        for; ``extra["familiarity"]``.

    Raises
    ------
    NotFittedError
        The memory has no fitted encoder.
    """
    a = act(memory, sequence, start, dt, joint_limits=joint_limits, simulator=simulator,
            frame=frame)
    sources = tuple(dict.fromkeys(k for e in memory.entries for k in e.sources))
    return Response(concept=f"c{memory.concept_count + 1}", motion=a.plane,
                    joint_path=a.joints, source=None, sources=sources, execution=a.execution,
                    attempt=attempt, extra={"familiarity": familiarity}, novel=True,
                    dt=float(dt), teacher_drawing=a.teacher_drawing)


def ik_joint_limits(ik_solver: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """``(lower, upper)`` joint limits (rad, shape (J,) each) of an IK solver, if it has them.

    The learner clips regenerated joint paths to them before execution.
    """
    if ik_solver is None or not hasattr(ik_solver, "lower"):
        return None
    return np.asarray(ik_solver.lower), np.asarray(ik_solver.upper)

"""The agent's learning phase: one demonstration step by step, or a stream with a teacher.

:meth:`~Stepwise.observe` shows the robot a demonstration and returns the
:class:`~iloci.concepts.turn.Turn` waiting for a person's feedback (nothing
blocks: web pages, GUIs, ROS nodes); :meth:`~Stepwise.feedback` routes a
feedback by its answer's id; :meth:`~Stepwise.aobserve` is ``observe`` for
asyncio code. :meth:`~Stepwise.learn` and :meth:`~Stepwise.teach` run the
same turns with the configured teacher's feedback
(:func:`~iloci.concepts.learner.run_turn`, the one observe -> feedback loop).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
import os
import time
from typing import Any
import warnings

import numpy as np

from iloci.agent.base import AgentBase
from iloci.concepts.answers import Answer, LearnOutcome
from iloci.concepts.turn import Turn
from iloci.data import load_trajectory
from iloci.data.files import TrajectoryFile, trajectory_files
from iloci.errors import (InvalidDemonstrationError, InvalidInputError, ObserverError,
                          StaleAnswerError)
from iloci.interfaces import Demonstration
from iloci.sensorimotor.frames import TeacherFrame
from iloci.sensorimotor.pipeline import Motion

__all__ = ["Stepwise", "TeachReport", "SkippedDemonstrationWarning"]


class SkippedDemonstrationWarning(UserWarning):
    """A demonstration in a learning stream could not be used and was skipped."""


@dataclass(frozen=True)
class TeachReport:
    """What :meth:`Agent.teach` did with a stream of demonstrations.

    Attributes
    ----------
    outcomes : tuple of LearnOutcome
        One per demonstration shown, in stream order (action
        ``"already_learned"`` for one the memory had learned before).
    skipped : tuple of (str, str)
        ``(demonstration, reason)`` for each one that failed validation,
        preprocessing or IK; the memory was left untouched by it.
    seconds : float
        Wall time.
    """

    outcomes: tuple[Any, ...]
    skipped: tuple[tuple[str, str], ...]
    seconds: float

    @property
    def feedbacks(self) -> list[int]:
        """Every teacher feedback (+1/-1) in order: the reinforcement signal."""
        return [f for o in self.outcomes for f in o.feedbacks]

    @property
    def first_guess_correct(self) -> list[bool | None]:
        """Per learned demonstration: was the first guess rewarded (None: no guess)."""
        return [o.first_guess_correct for o in self.outcomes]

    @property
    def already_learned(self) -> list[str]:
        """Keys of the demonstrations the memory had learned already (not learned again)."""
        return [o.demo for o in self.outcomes if o.action == "already_learned"]

    @property
    def rehearsals(self) -> list[Any]:
        """Every RehearsalEvent, in order."""
        return [r for o in self.outcomes for r in o.rehearsals]


class Stepwise(AgentBase):
    """The learning phase of :class:`~iloci.agent.Agent` (see the module)."""

    # -- learning phase ------------------------------------------------------------
    def observe(self, demo: Demonstration, motion: Any = None) -> Turn:
        """Show the robot one demonstration: its first guess, step by step.

        The step-wise learning phase, for callers that get feedback when a
        person gives it (a web page, a GUI, a ROS node): nothing waits for
        the person. :meth:`learn` and :meth:`teach` run on it with a
        teacher object.

        Parameters
        ----------
        demo : Demonstration
        motion : Motion, optional
            ``self.motion(demo)`` when already computed (the IK runs once
            per demonstration).

        Returns
        -------
        Turn
            ``turn.answer``: the guess (concept, confidence, attempt, the
            drawing in the demonstration's frame, joint path, dt, start
            posture) to judge with ``turn.feedback(+1 | -1, turn.answer.id)``; or, for the
            first demonstration of an empty memory, ``turn.outcome`` at once
            (a new concept, nothing asked).

        Raises
        ------
        InvalidDemonstrationError, UnreachableTargetError
            The demonstration cannot be preprocessed or reached; the memory
            is untouched.
        InvalidInputError
            ``motion`` is another demonstration's; the memory is untouched.
        """
        if motion is None:
            motion = self.motion(demo)
        elif getattr(motion, "demo_key", demo.key) != demo.key:
            raise InvalidInputError(f"the motion given is that of {motion.demo_key!r}, not of "
                                    f"{demo.key!r}: pass self.motion(demo) of this "
                                    "demonstration, or leave motion out. Nothing was learned.")
        with self._lock:
            if self.memory.encoder is None:
                self.fit_encoder([motion])
            seq, start = self._encode(motion)
            frame = TeacherFrame.of(demo, motion.plane_points)
            turn = self.learner.observe(demo, seq, start, motion.dt, frame)
            self._turn = turn
        return turn

    @property
    def pending(self) -> Answer | None:
        """The answer of the last :meth:`observe` waiting for a feedback, or ``None``.

        Returns
        -------
        Answer or None
            Its :attr:`~iloci.concepts.learner.Answer.id` is what
            :meth:`feedback` must name.
        """
        turn = self._turn
        return None if turn is None else turn.answer

    def feedback(self, value: int, answer_id: Any) -> Answer | LearnOutcome:
        """Judge the answer ``answer_id`` of the last :meth:`observe`: +1 or -1.

        For event-driven stacks (buttons, ROS topics, web hooks) that keep
        no turn object: the feedback is routed by the answer's id.
        ``turn.feedback(value, answer_id)`` on the turn :meth:`observe`
        returned does the same.

        Parameters
        ----------
        value : int
            +1 (reward) or -1 (punishment).
        answer_id : str or Answer
            :attr:`Answer.id <iloci.concepts.learner.Answer.id>` of the
            answer judged.

        Returns
        -------
        Answer or LearnOutcome
            The next answer, or the demonstration's place in the memory.

        Raises
        ------
        StaleAnswerError
            ``answer_id`` is not the pending answer's (a duplicate, a late
            feedback, one for an earlier turn, or no turn is under way);
            nothing changed.
        FeedbackError
            ``value`` is not +1 or -1; nothing changed.
        """
        turn = self._turn
        if turn is None:
            shown = getattr(answer_id, "id", answer_id)
            raise StaleAnswerError(
                f"answer {shown!r} is not waiting for a feedback (no demonstration has been "
                "observed); the feedback was refused and nothing changed. Call "
                "agent.observe(demo) and judge the answer it shows.",
                answer_id=str(shown), pending=None)
        return turn.feedback(value, answer_id)

    async def aobserve(self, demo: Demonstration) -> Turn:
        """:meth:`observe` from asyncio code: runs in a thread, the event loop stays free.

        With :meth:`start_worker` the network's work runs in the worker
        process, so the thread mostly waits and the loop keeps its timing.
        """
        import asyncio
        return await asyncio.to_thread(self.observe, demo)

    def learn(self, demo: Demonstration, motion: Any = None) -> LearnOutcome:
        """Learn from one demonstration with the teacher's feedback.

        :meth:`observe`, then the configured teacher's feedback on each
        guess until the demonstration is placed.

        Parameters
        ----------
        demo : Demonstration
        motion : Motion, optional
            ``self.motion(demo)`` when already computed.

        Returns
        -------
        LearnOutcome

        Raises
        ------
        InvalidDemonstrationError, UnreachableTargetError
            The demonstration cannot be preprocessed or reached; the memory
            is untouched.
        FeedbackError
            The teacher answered something other than +1 or -1; the memory
            is untouched.
        ObserverError
            An observer hook raised after the demonstration was learned
            (its ``outcome`` says how); do not teach it again.
        """
        # the learner imports scipy: loaded when first used, so `import iloci` stays light
        from iloci.concepts.learner import run_turn
        return run_turn(self.teacher, demo, lambda: self.observe(demo, motion),
                        self.memory.labels)

    def teach(self, demos: Iterable[Any], *,
              on_change: Callable[[Any], None] | None = None) -> TeachReport:
        """Learn from a stream of demonstrations, one at a time, with feedback.

        Parameters
        ----------
        demos : iterable
            Each a :class:`~iloci.interfaces.Demonstration`, a path to a
            trajectory file (``.npy``, ``.csv``, ``.inkml``, ``.xml``), or an
            (N, 2) array. Files of one name in different folders get distinct
            keys (``circle/0``,
            ``circle/1``; see :func:`~iloci.data.files.trajectory_files`).
        on_change : callable, optional
            Called with each :class:`~iloci.concepts.learner.LearnOutcome`
            after the memory changed (e.g. to save it).

        Returns
        -------
        TeachReport

        Notes
        -----
        A demonstration that fails validation, preprocessing or IK is
        skipped with a :class:`SkippedDemonstrationWarning` naming it and
        the reason; the memory is untouched by it and the stream goes on.
        When the memory has no encoder yet, its scales are fitted on every
        usable demonstration of the stream first.

        Raises
        ------
        InvalidInputError
            ``demos`` is not an iterable of demonstrations (one demonstration,
            one path, one array) or ``on_change`` not callable; nothing learned.
        ObserverError
            An observer hook raised. The demonstration it observed is
            learned and ``on_change`` was called with its outcome (so a
            saving callback saved it); the stream stops there.
        """
        if isinstance(demos, (Demonstration, str, os.PathLike)) or not isinstance(
                demos, Iterable) or (isinstance(demos, np.ndarray) and demos.ndim != 3):
            one = isinstance(demos, (Demonstration, str, os.PathLike)) or (
                isinstance(demos, np.ndarray) and demos.ndim == 2)
            raise InvalidInputError(
                f"teach takes a sequence (or any iterable) of demonstrations, got "
                f"{type(demos).__name__}"
                + (": for one demonstration, pass [it] (or call learn(demo))" if one else "")
                + ". Nothing was learned.")
        if on_change is not None and not callable(on_change):
            raise InvalidInputError(f"on_change must be a function called with each outcome "
                                    f"(e.g. lambda outcome: agent.save(path)), got "
                                    f"{on_change!r}. Nothing was learned.")
        t0 = time.perf_counter()
        skipped: list[tuple[str, str]] = []

        numbered: dict[str, dict[str, int]] = {}  # files of one stem: distinct keys

        def prepared(items: Iterable[Any]) -> Iterator[tuple[Demonstration, Motion]]:
            for i, item in enumerate(items):
                if isinstance(item, (str, os.PathLike)) and not isinstance(item,
                                                                          TrajectoryFile):
                    item = trajectory_files([item], numbered)[0]
                name = _describe(item, i)
                try:
                    demo = _as_demonstration(item, i)
                    yield demo, self.motion(demo)
                except InvalidInputError as exc:
                    skipped.append((name, str(exc)))
                    warnings.warn(f"skipped demonstration {name}: {exc}",
                                  SkippedDemonstrationWarning, stacklevel=3)

        stream: Iterable[tuple[Demonstration, Any]] = prepared(demos)
        if self.memory.encoder is None:
            # the scales are fitted on the whole stream, so it is read first;
            # with an encoder, a live stream is consumed one demonstration at a time
            stream = list(stream)
            if stream:
                self.fit_encoder([m for _, m in stream])
        outcomes = []
        for demo, motion in stream:
            try:
                outcome = self.learn(demo, motion)
            except ObserverError as exc:  # learned, then an observer failed
                if on_change is not None:
                    on_change(exc.outcome)
                raise
            outcomes.append(outcome)
            if on_change is not None and outcome.action != "already_learned":
                on_change(outcome)
        return TeachReport(tuple(outcomes), tuple(skipped), time.perf_counter() - t0)


def _describe(item: Any, i: int) -> str:
    if isinstance(item, Demonstration):
        return repr(item.key)
    if isinstance(item, os.PathLike):  # a TrajectoryFile too: named by its path
        return repr(os.fspath(item))
    if isinstance(item, (str, os.PathLike)):
        return repr(str(item))
    return f"#{i} of the stream"


def _as_demonstration(item: Any, i: int) -> Demonstration:
    """A stream item as a Demonstration (validation errors propagate)."""
    if isinstance(item, Demonstration):
        return item
    if isinstance(item, TrajectoryFile):
        return item.load()
    if isinstance(item, (str, os.PathLike)):
        return load_trajectory(item)
    try:
        return Demonstration(np.asarray(item, dtype=np.float64), shape="stream", index=i)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InvalidInputError):
            raise
        raise InvalidDemonstrationError(f"stream item {i} is not a Demonstration, a "
                                        f"trajectory file or an (N, 2) array ({exc}).") from None



"""What a turn of the learning phase gives: the robot's answers and the outcome.

An :class:`Answer` is one thing the robot shows for a demonstration (a guess
of a known concept, a request to confirm a reward, or the novelty answer)
and carries an :attr:`~Answer.id`; a feedback names the id it judges
(:meth:`Turn.feedback <iloci.concepts.turn.Turn.feedback>`). A
:class:`LearnOutcome` is where the demonstration went in the memory.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from iloci.errors import FeedbackError, StaleAnswerError
from iloci.events import InteractionEvent, RehearsalEvent
from iloci.interfaces import Response

__all__ = ["ACTIONS", "Answer", "LearnOutcome", "check_answer_id"]

#: Actions the learner takes on a feedback (InteractionEvent.action).
ACTIONS = ("strengthen", "new_exemplar", "next_guess", "new_concept", "confirm")


@dataclass(frozen=True)
class LearnOutcome:
    """What learning one demonstration did.

    Attributes
    ----------
    demo : str
        Key of the demonstration.
    concept : str
        The robot's concept it was assigned to.
    action : str
        The final action: ``"strengthen"``, ``"new_exemplar"`` or
        ``"new_concept"``; ``"already_learned"`` when this very
        demonstration (the same key and pen positions,
        :func:`~iloci.concepts.memory.demonstration_digest`) was learned
        before: nothing was asked and the memory is unchanged.
    feedbacks : tuple of int
        Every feedback the teacher gave for it, in order (empty for the
        very first demonstration).
    events : tuple of InteractionEvent
    rehearsals : tuple of RehearsalEvent
    clustered : int
        Valid clusters replaced by their medoid.
    """

    demo: str
    concept: str
    action: str
    feedbacks: tuple[int, ...]
    events: tuple[InteractionEvent, ...]
    rehearsals: tuple[RehearsalEvent, ...] = ()
    clustered: int = 0

    @property
    def first_guess_correct(self) -> bool | None:
        """Whether the first guess was rewarded (``None`` if nothing was guessed)."""
        return self.feedbacks[0] == 1 if self.feedbacks else None


@dataclass(frozen=True)
class Answer:
    """The robot's guess for a demonstration, as a person or a controller needs it.

    Attributes
    ----------
    demo : str
        Key of the demonstration answered.
    concept : str
        The guessed concept (the robot's label, or the name given with
        :meth:`~iloci.concepts.memory.Memory.rename`).
    confidence : float
        In [0, 1]: ``1 - d_guess / d_other``, ``d_guess`` the PB distance
        from PB_obs to the nearest PB_rec of the guessed concept, ``d_other``
        the distance to the nearest PB_rec of any other concept not yet
        tried for this demonstration (1 when no other is left): the margin
        of :class:`Recognition` over the concepts still in play.
    attempt : int
        1 for the first guess on this demonstration, 2 for the next, ...
    drawing : ndarray, shape (T, 2)
        What the robot drew (:attr:`Response.drawing
        <iloci.interfaces.Response.drawing>`) in the demonstration's own
        frame: its units and orientation, scaled and centred as the
        demonstration was (see :class:`~iloci.sensorimotor.frames.TeacherFrame`),
        so it can be shown beside what was drawn. The drawing plane's
        ``(y, z)`` in m when the turn was observed without a frame.
    joint_path : ndarray, shape (T, J)
        Joint angles (rad, within the joint limits) to perform, one row
        every ``dt`` seconds.
    dt : float
        Time step of ``joint_path`` (s).
    start_posture : ndarray, shape (J,)
        ``joint_path[0]``: where the arm must be before it starts.
    response : Response
        Everything else (the generated pen path in m, the simulator's
        execution, the answering entry's sources).
    entry : int
        Index of the performed entry in ``Memory.entries``.
    distance : float
        ``d_guess``.
    id : str
        This answer's id, unique to it: ``"<turn>-<attempt>"``, where
        ``<turn>`` is a random token of the turn (8 hex digits, so an
        answer given before a restart is never taken for a new one) and
        ``<attempt>`` the attempt. A feedback names the id it judges
        (:meth:`Turn.feedback`); one naming an answer that is no longer
        pending is refused (:class:`~iloci.errors.StaleAnswerError`).
    """

    demo: str
    concept: str
    confidence: float
    attempt: int
    drawing: np.ndarray = field(repr=False)
    joint_path: np.ndarray = field(repr=False)
    dt: float
    start_posture: np.ndarray = field(repr=False)
    response: Response = field(repr=False)
    entry: int
    distance: float
    id: str = ""

    @classmethod
    def of(cls, response: Response, **fields: Any) -> Answer:
        """The answer showing ``response``: its drawing (in the teacher's frame when it
        has one), joint path and start posture taken from it; ``fields`` the rest."""
        drawing = (response.teacher_drawing if response.teacher_drawing is not None
                   else response.drawing)
        joints = np.asarray(response.joint_path, dtype=np.float64)
        return cls(drawing=np.asarray(drawing, dtype=np.float64), joint_path=joints,
                   start_posture=joints[0].copy(), response=response, **fields)


def check_answer_id(answer_id: str | Answer | None, pending: Answer | None, token: str,
                    key: str) -> str:
    """``answer_id`` (an id, or an :class:`Answer` for its id) if it is ``pending``'s.

    Parameters
    ----------
    answer_id : str or Answer or None
        What a feedback names.
    pending : Answer or None
        The answer waiting for a feedback (``None``: the turn is over).
    token : str
        The turn's token (the first part of its answers' ids).
    key : str
        The demonstration's key, for the message.

    Raises
    ------
    FeedbackError
        No id given, or not a str.
    StaleAnswerError
        Not the pending answer's id: a duplicate (an answer of this turn
        already judged), another turn's, or the turn is over.
    """
    if isinstance(answer_id, Answer):
        answer_id = answer_id.id
    if answer_id is None:
        raise FeedbackError("a feedback must name the answer it judges: "
                            "turn.feedback(+1 or -1, turn.answer.id).")
    if not isinstance(answer_id, str):
        raise FeedbackError(f"a feedback names the answer it judges by its id, a str "
                            f"(turn.answer.id), or by the Answer itself; got "
                            f"{type(answer_id).__name__}.")
    waiting = None if pending is None else pending.id
    if answer_id != waiting:
        if waiting is None:
            why = f"the turn of {key!r} is over"
        elif isinstance(answer_id, str) and answer_id.startswith(token + "-"):
            why = f"it was already judged; the answer waiting for one is {waiting!r}"
        else:
            why = (f"it is not an answer of this turn of {key!r}; the answer waiting for "
                   f"one is {waiting!r}")
        raise StaleAnswerError(
            f"answer {answer_id!r} is not waiting for a feedback ({why}); the feedback was "
            "refused and nothing changed. Send feedback with the id of the answer shown "
            "(Answer.id).", answer_id=str(answer_id), pending=waiting)
    return answer_id

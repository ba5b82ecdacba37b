"""The transport-neutral core of the ROS node: drawings in, guesses out, feedback by answer id.

A :class:`TeachingSession` wraps an :class:`iloci.Agent`'s step-wise
learning phase (:meth:`~iloci.agent.Agent.observe`,
:meth:`~iloci.concepts.learner.Turn.feedback`) for an event-driven stack,
where messages come late, twice, or out of turn:

* :meth:`TeachingSession.drawing` takes one pen path and returns the
  robot's :class:`Guess` (concept, confidence, joint path) under a fresh
  answer id, or, for the very first drawing of an empty memory, the
  :class:`Placed` outcome at once (a new concept, nothing to ask).
* :meth:`TeachingSession.feedback` takes ``(answer_id, +1 | -1)``. Only the
  answer now pending can be judged: an id that was already judged (a
  duplicate), belongs to an earlier answer or turn (late), or is unknown
  raises :class:`StaleAnswerError` and changes nothing. A new drawing
  while an answer is pending abandons that turn (the memory is unchanged,
  its answer id goes stale).

Nothing here knows about ROS: :mod:`iloci_ros.node` converts messages to and
from these calls, and an adapter for another transport (ROS 2's rclpy, a web
socket) does the same in a few dozen lines.

All methods are thread-safe (one lock): transports deliver messages on
threads of their own.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
import itertools
import os
from pathlib import Path
import secrets
import threading
import time
from typing import Any

import numpy as np

from iloci import errors
from iloci.errors import IlociError, InvalidInputError
from iloci.progress import why_not_saved

__all__ = ["Guess", "Placed", "StaleAnswerError", "TeachingSession"]


class StaleAnswerError(errors.StaleAnswerError):
    """A feedback names an answer that is not the one pending; nothing was changed.

    The kernel's :class:`iloci.errors.StaleAnswerError`, which
    :meth:`Turn.feedback <iloci.concepts.turn.Turn.feedback>` raises too.
    """


@dataclass(frozen=True)
class Guess:
    """The robot's answer to a drawing, waiting for a yes or no.

    Attributes
    ----------
    answer_id : str
        What a feedback must name to judge this answer.
    demo : str
        Key of the drawing answered.
    concept : str
    confidence : float
        In [0, 1] (:class:`iloci.concepts.learner.Answer`).
    attempt : int
        1 for the first guess on this drawing, 2 for the next, ...
    joint_names : tuple of str
    joint_path : ndarray, shape (T, J)
        Joint angles (rad), one row every ``dt`` seconds.
    dt : float
        s.
    drawing : ndarray, shape (T, 2)
        What the robot drew, in the drawing's own frame and units.
    """

    answer_id: str
    demo: str
    concept: str
    confidence: float
    attempt: int
    joint_names: tuple[str, ...]
    joint_path: np.ndarray = field(repr=False)
    dt: float
    drawing: np.ndarray = field(repr=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: every field but the arrays, plus their shapes."""
        conf = self.confidence
        return {"kind": "guess", "answer_id": self.answer_id, "demo": self.demo,
                "concept": self.concept,
                "confidence": None if conf != conf else float(conf),
                "attempt": self.attempt, "joint_names": list(self.joint_names),
                "dt": self.dt, "steps": int(len(self.joint_path))}


@dataclass(frozen=True)
class Placed:
    """A drawing's turn ended: where it went in the memory.

    Attributes
    ----------
    demo : str
    concept : str
    action : str
        ``"strengthen"``, ``"new_exemplar"`` or ``"new_concept"``.
    feedbacks : tuple of int
    entries : int
        Entries in the memory now.
    save_error : str or None
        Why the memory could not be saved (a full disk, the file taken by
        another writer): the drawing is learned in this session, not in
        the file, and the next drawing placed tries to save again.
    """

    demo: str
    concept: str
    action: str
    feedbacks: tuple[int, ...]
    entries: int
    save_error: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "placed", "demo": self.demo, "concept": self.concept,
                "action": self.action, "feedbacks": list(self.feedbacks),
                "entries": self.entries, "save_error": self.save_error}


def _identity(path: str | os.PathLike[str] | None) -> tuple[int, int, int, int] | None:
    """The file at ``path`` as the file system tells one version from another: (device,
    inode, size, modification time in ns); None when there is none."""
    if path is None:
        return None
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


class TeachingSession:
    """An agent taught by drawings and yes/no events, each answer named by an id.

    Parameters
    ----------
    agent : iloci.Agent
    save_to : path-like, optional
        Saved (atomically) after each turn that changed the memory. A file
        changed on disk by something else since the session read or saved
        it is not saved over (:meth:`_save`: the memory goes beside it, and
        :attr:`Placed.save_error` says where).
    shape : str
        Demonstration keys are ``"{shape}/{n}"``, ``n`` counting the
        drawings the memory has seen.
    clock : callable () -> float
        For :attr:`last_seconds` (default :func:`time.perf_counter`).

    Attributes
    ----------
    pending : Guess or None
        The answer waiting for feedback.
    last_seconds : float
        Wall time of the last :meth:`drawing` or :meth:`feedback` (s).
    """

    def __init__(self, agent: Any, *, save_to: str | os.PathLike[str] | None = None,
                 shape: str = "drawing",
                 clock: Callable[[], float] = time.perf_counter) -> None:
        self.agent = agent
        self.save_to = save_to
        #: What the memory file was when this session last read or wrote it
        #: (:func:`_identity`): a file changed since by something else is not saved over.
        self._on_disk = _identity(save_to)
        self.shape = shape
        self._clock = clock
        self._lock = threading.Lock()
        self._turn: Any = None
        self.pending: Guess | None = None
        # ids unique across sessions (a late message from a previous run of
        # the node must not match) and within one (a counter)
        self._nonce = secrets.token_hex(3)
        self._ids = itertools.count(1)
        self.last_seconds = 0.0

    def drawing(self, positions: Any, times: Any = None, key: str | None = None
                ) -> Guess | Placed:
        """Show the robot one drawing; its first guess (or the outcome, for a first drawing).

        Parameters
        ----------
        positions : array_like, shape (N, 2)
            Pen positions, any unit (only the shape matters).
        times : array_like, shape (N,), optional
            Strictly increasing time stamps (s).
        key : str, optional
            ``"SHAPE/INDEX"`` for the demonstration; by default
            ``"{shape}/{n}"``. A drawing that comes again (a message
            delivered twice, a bag replayed) is recognized by its key and
            positions (:func:`iloci.concepts.memory.demonstration_digest`):
            while its guess is pending, that guess is returned again (its
            answer id stays the one to judge); once learned, it is placed as
            ``already_learned`` with nothing changed, provided its key is
            the same (give one, e.g. from the message's stamp: the default
            counter moves on after each learned drawing).

        Raises
        ------
        InvalidDemonstrationError, UnreachableTargetError
            The drawing cannot be used; a pending answer stays pending.
        """
        import iloci
        t0 = self._clock()
        with self._lock:
            if key is None:
                shape, index = self.shape, int(self.agent.memory.demonstrations_seen)
            else:
                shape, _, idx = key.rpartition("/")
                if not shape or not idx.isdigit():
                    raise InvalidInputError(f"a drawing's key must be 'SHAPE/INDEX', got "
                                            f"{key!r}.")
                index = int(idx)
            demo = iloci.Demonstration(np.asarray(positions, dtype=np.float64),
                                       times=times, shape=shape, index=index)
            from iloci.concepts.memory import demonstration_digest
            if self._turn is not None and self.pending is not None and \
                    demonstration_digest(self._turn.demo) == demonstration_digest(demo):
                # the same drawing again (a duplicate delivery): its guess still waits
                self.last_seconds = self._clock() - t0
                return self.pending
            turn = self.agent.observe(demo)
            self._turn = turn          # the previous turn, if any, is abandoned
            result = self._after(turn)
        self.last_seconds = self._clock() - t0
        return result

    def feedback(self, answer_id: str, value: int) -> Guess | Placed:
        """Judge the pending answer: +1 (right) or -1 (wrong).

        Returns
        -------
        Guess
            The next guess (a new answer id) after a -1.
        Placed
            The drawing's outcome, the memory updated (and saved).

        Raises
        ------
        StaleAnswerError
            ``answer_id`` is not the pending answer's: already judged, from
            an earlier guess or drawing, or unknown. Nothing changed.
        FeedbackError
            ``value`` is not +1 or -1; the answer stays pending.
        """
        t0 = self._clock()
        with self._lock:
            pending = self.pending
            if pending is None or answer_id != pending.answer_id:
                now = ("no answer is pending" if pending is None
                       else f"the pending answer is {pending.answer_id!r}")
                raise StaleAnswerError(
                    f"feedback for answer {answer_id!r} refused: {now}. A duplicate, late "
                    "or out-of-turn feedback changes nothing; judge the answer last "
                    "published.")
            from iloci.interfaces import check_feedback
            value = check_feedback(value, "TeachingSession.feedback()")
            self._turn.feedback(value, self._turn.answer.id)
            result = self._after(self._turn)
        self.last_seconds = self._clock() - t0
        return result

    @property
    def busy(self) -> bool:
        """Whether a drawing or a feedback is being handled now (recognized, learned, saved)."""
        return self._lock.locked()

    def finish(self, timeout: float | None = None) -> bool:
        """Wait until the drawing or feedback being handled is done (learned and saved).

        A node that stops (Ctrl-C) calls this before it closes the agent, so a
        drawing whose feedback was accepted is not lost half-way through its
        rehearsal.

        Parameters
        ----------
        timeout : float, optional
            Seconds to wait at most (default: as long as it takes).

        Returns
        -------
        bool
            True when nothing is in progress any more.
        """
        if not self._lock.acquire(timeout=-1 if timeout is None else timeout):
            return False
        self._lock.release()
        return True

    def _save(self, demo: str) -> str | None:
        """Save the memory after ``demo`` was placed; why it could not be, or None.

        A memory file changed on disk since this session read or wrote it
        (copied over, replaced by another memory) is not saved over: the
        session's memory goes to a file beside it, named in the message, and
        so do the later saves of this session.
        """
        assert self.save_to is not None
        diverted = None
        now = _identity(self.save_to)
        if now is not None and now != self._on_disk:
            original = Path(self.save_to)
            stamp = time.strftime("%Y%m%d-%H%M%S")
            self.save_to = diverted = original.with_name(
                f"{original.stem}.session-{stamp}-{self._nonce}{original.suffix}")
        try:
            self.agent.save(self.save_to)
        except (OSError, IlociError) as exc:  # learned; the file could not follow
            failed = (why_not_saved(self.save_to, exc) if isinstance(exc, OSError)
                      and not isinstance(exc, IlociError) else str(exc))
            return failed + (f" {demo} is learned in this session but not saved; "
                             "the next drawing placed saves again.")
        self._on_disk = _identity(self.save_to)
        if diverted is not None:
            return (f"the memory file {original} was changed on disk since this session "
                    "read or saved it (replaced or copied over by something else); it was "
                    f"not overwritten. This session's memory, with {demo}, is saved to "
                    f"{diverted}, and so are its next drawings. Keep one of the two files, "
                    "and restart the node on it.")
        return None

    def _after(self, turn: Any) -> Guess | Placed:
        """The turn's pending answer as a Guess, or its outcome as Placed (memory saved)."""
        if turn.done:
            self.pending = None
            self._turn = None
            out = turn.outcome
            failed = None
            if self.save_to is not None:
                failed = self._save(out.demo)
            return Placed(out.demo, out.concept, out.action, tuple(out.feedbacks),
                          len(self.agent.memory), failed)
        a = turn.answer
        self.pending = Guess(
            answer_id=f"{self._nonce}-{next(self._ids)}", demo=a.demo, concept=a.concept,
            confidence=float(a.confidence), attempt=int(a.attempt),
            joint_names=tuple(self.agent.ik_solver.joint_names),
            joint_path=np.asarray(a.joint_path), dt=float(a.dt),
            drawing=np.asarray(a.drawing))
        return self.pending

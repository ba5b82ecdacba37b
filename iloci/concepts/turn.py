"""One demonstration's turn of the learning phase: a state machine, one feedback at a time.

The paper's learning phase (docs/method.md, "Learning phase"; the paper's
"Learning Phase"), for one demonstration::

    PB_obs = recognize(sequence)                   (multi-start from the stored PBs)
    tried = {}
    loop:
        untried = concepts in Mem not in tried
        none left -> new concept: the demonstration becomes its first
                     exemplar (memory rehearsal); stop
        guess   = the untried concept whose nearest PB_rec is closest to PB_obs
        respond = perform the guess's entry of lowest generationError
        +1, distance(PB_obs, nearest PB_rec) <  similarity_threshold
             -> strengthen: the nearest entry's numSamples += 1; stop
        +1, otherwise
             -> new exemplar of the guess (memory rehearsal); when the
                concept's numSamples then exceed num_threshold, cluster it
                and replace each valid cluster by its medoid (rehearsal); stop
        -1 -> tried += guess; loop

The very first demonstration (empty memory) becomes the first exemplar of
the first concept without asking the teacher.

The same procedure as a state machine
-------------------------------------
A turn is in one of four phases (:class:`Phase`); the answer shown is a
guess (``GUESS``), a request to confirm a reward (``CONFIRM``) or the
demonstration imitated back as something new (``NOVELTY``); ``DONE`` once
the demonstration is placed. Each feedback runs one action of the
transition table :data:`TRANSITIONS`; the policies
(:mod:`iloci.concepts.policies`) decide between its outcomes, and with their
defaults (the paper's protocol) only the ``GUESS`` rows are ever taken::

    start  empty memory                             -> found a concept   DONE
           novelty.at_start(familiarity)            -> novelty answer    NOVELTY
           otherwise                                -> next guess        GUESS | DONE

    phase    feedback  action          outcome
    GUESS    +1        reward          confirmation.required > given  -> ask again   CONFIRM
                                       distance < similarity_threshold -> strengthen DONE
                                       otherwise -> new exemplar (+ clustering)       DONE
    GUESS    -1        refuse          tried += guess; novelty.offer_again -> novelty NOVELTY
                                       an untried concept left -> next guess          GUESS
                                       none left -> new concept                       DONE
    CONFIRM  +1        reward          as GUESS +1, with one confirmation more given
    CONFIRM  -1        refuse          as GUESS -1 (the reward is not kept)
    NOVELTY  +1        found           new concept                                    DONE
    NOVELTY  -1        refuse_novelty  next guess (or new concept, none left)         GUESS | DONE
    DONE     any       -               refused: StaleAnswerError, nothing changes

The turn's state is its phase and its public record (:attr:`Turn.tried`,
:attr:`Turn.feedbacks`, :attr:`Turn.events`); what the policies need
(guesses refused in a row, whether the novelty answer was asked again,
confirmations given) is read off that record. The memory changes only
through its own transitions (:class:`~iloci.concepts.memory.Memory`'s
``strengthen``, ``install``, ``found_label`` and its undo, ``placed``),
and the turn uses only the learner's public face.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from enum import StrEnum
from functools import cached_property
import os
from typing import Any

import numpy as np

from iloci.concepts.answers import Answer, LearnOutcome, check_answer_id
from iloci.concepts.face import LearnerFace
from iloci.concepts.inference import regenerated_patterns
from iloci.concepts.memory import Entry, demonstration_digest
from iloci.errors import InvalidInputError
from iloci.events import InteractionEvent, RehearsalEvent
from iloci.interfaces import Demonstration, check_feedback
from iloci.sensorimotor.frames import TeacherFrame


__all__ = ["Phase", "TRANSITIONS", "Turn"]


class Phase(StrEnum):
    """What the answer shown asks (see the module docstring)."""

    GUESS = "guess"
    CONFIRM = "confirm"
    NOVELTY = "novelty"
    DONE = "done"


#: (phase, feedback) -> the action (a method ``Turn._<action>``) it runs.
TRANSITIONS: dict[tuple[Phase, int], str] = {
    (Phase.GUESS, 1): "reward",
    (Phase.GUESS, -1): "refuse",
    (Phase.CONFIRM, 1): "reward",
    (Phase.CONFIRM, -1): "refuse",
    (Phase.NOVELTY, 1): "found",
    (Phase.NOVELTY, -1): "refuse_novelty",
}


class Turn:
    """One demonstration's turn of the learning phase, driven one feedback at a time.

    Made by :meth:`Learner.observe <iloci.concepts.learner.Learner.observe>`
    (:meth:`Agent.observe <iloci.agent.Agent.observe>`): PB_obs is
    recognized once, then the turn waits. :attr:`answer` is the answer to
    judge; :meth:`feedback` with +1 or -1 and the answer's id returns the
    next :class:`~iloci.concepts.answers.Answer` or, once the demonstration
    is placed, the :class:`~iloci.concepts.answers.LearnOutcome` (kept in
    :attr:`outcome`; :attr:`answer` is then ``None``).

    Guarantees
    ----------
    * The memory changes only when the turn ends (strengthening, a new
      exemplar or a new concept), and a rehearsal's result is installed in
      one assignment of ``memory.entries`` after it has succeeded: other
      threads see the old memory or the new one. An error (a bad feedback
      value, a diverging rehearsal) leaves memory and turn as they were,
      so the same feedback can be given again.
    * A feedback names the answer it judges; one naming an answer that is
      not pending (a duplicate, a late one, one of another turn) is
      refused (:class:`~iloci.errors.StaleAnswerError`) and changes nothing.
    * A turn is bound to the memory it was observed on: if the memory
      changed since (another turn ended, a rename), :meth:`feedback`
      raises :class:`~iloci.errors.InvalidInputError`; observe the
      demonstration again. One turn at a time per memory.
    * Nothing blocks on a person: a turn holds no thread between
      feedbacks. Each call computes and returns (a rehearsal can take
      seconds: run it in a worker process with :meth:`Agent.start_worker
      <iloci.agent.Agent.start_worker>`, from asyncio with
      :meth:`afeedback`).

    Extending: a new kind of answer adds a :class:`Phase`, its rows of
    :data:`TRANSITIONS` and one method per new action.
    """

    def __init__(self, learner: LearnerFace, demo: Demonstration, sequence: np.ndarray,
                 start: np.ndarray, dt: float, frame: TeacherFrame | None = None, *,
                 learned: str | None = None) -> None:
        seq = np.asarray(sequence, dtype=np.float64)
        if seq.ndim != 2 or len(seq) < 2 or not np.all(np.isfinite(seq)):
            raise InvalidInputError(f"sequence of {demo.key!r} must be a finite (T, D) array "
                                    f"with T >= 2, got shape {seq.shape}.")
        self.learner = learner
        self.demo = demo
        self.sequence = seq
        self.start = np.asarray(start, dtype=np.float64).copy()
        self.dt = float(dt)
        self.frame = frame
        mem = learner.memory
        #: Index of the demonstration in the learning stream (memory's count so far).
        self.step = mem.demonstrations_seen
        #: Concepts guessed and refused, in order.
        self.tried: list[str] = []
        #: Every feedback taken, in order.
        self.feedbacks: list[int] = []
        self.events: list[InteractionEvent] = []
        self.rehearsals: list[RehearsalEvent] = []
        self.phase = Phase.GUESS
        self.answer: Answer | None = None
        self.outcome: LearnOutcome | None = None
        #: The turn's random token, the first part of each of its answers' ids.
        self.token = os.urandom(4).hex()
        #: The memory revision the turn was observed on.
        self.revision = mem.revision
        learner.discard_events()
        self.labels: list[str] = []
        if learned is not None:   # this very demonstration was learned (into `learned`)
            self.pb_obs, self.distances = np.zeros(0), np.zeros(0)
            self._finish(learned, "already_learned")
            return
        if not mem.entries:
            # the very first demonstration: nothing to guess, a new concept
            self.pb_obs = np.zeros(learner.model.pb_size)
            self.distances = np.zeros(0)
            self._step(self._found_concept)
            return
        policies = learner.policies
        self.pb_obs = learner.recognize_pbs([seq])[0]
        self.distances = np.linalg.norm(mem.pbs_rec - self.pb_obs, axis=1)
        self.labels = mem.concept_labels
        # what orders the guesses: PB distance (the paper) or how well each
        # entry's PB reproduces the demonstration (policy "ranking")
        self.ranking = (learner.entry_errors([seq])[0] if policies.rank_by_reproduction
                        else learner.regeneration_distances([seq])[0]
                        if policies.rank_by_regeneration else self.distances)
        if policies.novelty.at_start(lambda: self.familiarity):
            self._step(self._offer_novelty)
            return
        self._step(self._next_guess)

    # -- what the record says ---------------------------------------------------------
    @cached_property
    def familiarity(self) -> float:
        """The demonstration's familiarity (policy "familiarity"), computed once."""
        learner, seq = self.learner, self.sequence
        policies = learner.policies
        # is it like what the robot knows (path, regeneration, reproduction),
        # or can the network reproduce it at all (prediction)
        patterns = (regenerated_patterns(learner.model, learner.memory)
                    if policies.familiar_by_path or policies.familiar_by_regeneration else None)
        return float(learner.familiarities(
            [seq], learner.familiarity_scale(patterns), patterns=patterns,
            reproduction=(self.ranking[None] if policies.rank_by_reproduction else None),
            pb_obs=self.pb_obs[None])[0])

    @property
    def refused_in_a_row(self) -> int:
        """Guesses refused since the turn or the last refused novelty answer began."""
        n = 0
        for e in reversed(self.events):
            if e.extra.get("novel"):
                break
            n += e.action == "next_guess"
        return n

    @property
    def novelty_asked_again(self) -> bool:
        """The novelty answer was asked again after refused guesses, and refused."""
        return any(e.extra.get("novel") and e.tried for e in self.events)

    @property
    def confirmations(self) -> int:
        """Confirmations asked for the current guess's reward."""
        n = 0
        for e in reversed(self.events):
            if e.action != "confirm":
                break
            n += 1
        return n

    @property
    def nearest(self) -> int:
        """The entry of the guessed concept nearest to the demonstration (by the ranking)."""
        assert self.answer is not None
        guess = self.answer.concept
        return min((i for i, c in enumerate(self.labels) if c == guess),
                   key=lambda i: self.ranking[i])

    @property
    def key(self) -> str:
        """Key of the demonstration."""
        return self.demo.key

    @property
    def done(self) -> bool:
        """Whether the demonstration has been placed (:attr:`outcome` is set)."""
        return self.outcome is not None

    def __repr__(self) -> str:
        state = (f"outcome={self.outcome.action!r}" if self.outcome is not None
                 else f"answer={self.answer.id!r}" if self.answer is not None else "")
        return f"Turn({self.key!r}, {self.phase.value}, {state})"

    # -- feedback ----------------------------------------------------------------------
    def feedback(self, value: int, answer_id: str | Answer | None = None
                 ) -> Answer | LearnOutcome:
        """Judge the answer ``answer_id``: +1 (right) or -1 (wrong).

        Parameters
        ----------
        value : int
            +1 (reward) or -1 (punishment).
        answer_id : str or Answer
            The id of the answer judged (:attr:`Answer.id
            <iloci.concepts.answers.Answer.id>`; an ``Answer`` stands for its
            id). It must be the pending answer's (:attr:`answer`): a
            feedback is never applied to another answer than the one it
            judges.

        Returns
        -------
        Answer
            The next answer (a guess, a confirmation, the novelty answer).
        LearnOutcome
            The demonstration's place in the memory, with its rehearsals.

        Raises
        ------
        FeedbackError
            ``value`` is not +1 or -1, or no ``answer_id`` was given;
            nothing changed.
        StaleAnswerError
            ``answer_id`` is not the pending answer's: a duplicate of a
            feedback already taken, a late one for an answer since replaced,
            one for another turn, or the turn is over. Nothing changed.
        InvalidInputError
            The memory changed since the turn was observed.
        """
        with self.learner.lock:
            self.check_pending(answer_id)
            if self.learner.current_memory() is not self.learner.memory:
                raise InvalidInputError(f"the memory was replaced since {self.key!r} was "
                                        "observed (an undo, a start over or another memory "
                                        "loaded); observe it again.")
            if self.learner.memory.revision != self.revision:
                raise InvalidInputError(f"the memory changed since {self.key!r} was observed "
                                        "(another demonstration was learned, or a concept "
                                        "renamed); observe it again.")
            fb = check_feedback(value, "Turn.feedback()")
            action = getattr(self, "_" + TRANSITIONS[(self.phase, fb)])
            return self._step(action)

    async def afeedback(self, value: int, answer_id: str | Answer | None = None
                        ) -> Answer | LearnOutcome:
        """:meth:`feedback` from asyncio code: runs in a thread, the event loop stays free."""
        import asyncio
        return await asyncio.to_thread(self.feedback, value, answer_id)

    def check_pending(self, answer_id: str | Answer | None) -> str:
        """``answer_id`` if it is the pending answer's (see :func:`check_answer_id`)."""
        return check_answer_id(answer_id, self.answer, self.token, self.key)

    def _step(self, action: Callable[[], Answer | LearnOutcome]) -> Answer | LearnOutcome:
        """Run one action; observers hear of the turn's events once it is committed.

        An action that fails changes nothing: the memory, the network
        (:meth:`Learner.uncommitted <iloci.concepts.learner.Learner.uncommitted>`)
        and the turn are put back, and its events are dropped;
        those of earlier steps wait for the end of the turn, when they are
        delivered with its own (:meth:`Learner.deliver
        <iloci.concepts.learner.Learner.deliver>`; an observer's fault then
        raises :class:`~iloci.errors.ObserverError`, the demonstration
        learned).
        """
        # the turn's own state too: a step that fails can be given again
        saved = {k: (list(v) if isinstance(v, list) else v) for k, v in vars(self).items()}
        try:
            with self.learner.uncommitted():
                result = action()
        except BaseException:
            vars(self).update(saved)
            raise
        if self.outcome is not None:
            self.learner.deliver(self.outcome)
        return result

    # -- actions -------------------------------------------------------------------------
    def _record(self, event: InteractionEvent) -> None:
        self.events.append(event)
        self.learner.emit(event)

    def _event(self, answer: Answer, fb: int, action: str, d_cutoff: float | None = None,
               **placed: Any) -> InteractionEvent:
        """The event of a feedback on a guess; ``d_cutoff`` (when a concept was clustered)
        and ``placed`` (where the demonstration went) join its extra."""
        nearest = self.nearest
        extra = {"nearest_entry": nearest, "nearest_distance": float(self.distances[nearest]),
                 "answer_entry": answer.entry}
        if d_cutoff is not None:
            extra["d_cutoff"] = d_cutoff
        return InteractionEvent(
            demo=self.key, step=self.step, attempt=answer.attempt, guessed=answer.concept,
            tried=tuple(self.tried), answered=answer.response.source, feedback=fb,
            action=action, distance=float(self.distances[answer.entry]),
            extra={**extra, **placed})

    def _reward(self) -> Answer | LearnOutcome:
        """+1 for a guess (or a confirmation): ask to confirm it, or place the demonstration."""
        answer = self.answer
        assert answer is not None
        learner, mem, policies = self.learner, self.learner.memory, self.learner.policies
        guess, nearest = answer.concept, self.nearest
        given = self.confirmations
        # a reward after a "no" goes against the robot's own ranking, and one
        # that makes a new exemplar widens a concept: a teacher's slip there
        # would merge two concepts, so it is kept only when the teacher
        # confirms it (asked once more; twice far down the ranking, after the
        # novelty answer asked again was refused)
        strengthens = policies.placement.strengthens(self.distances[nearest])
        required = policies.confirmation.required(deep=self.novelty_asked_again,
                                                  after_no=-1 in self.feedbacks,
                                                  new_exemplar=not strengthens)
        if given < required:
            self.feedbacks.append(1)
            self._record(self._event(answer, 1, "confirm"))
            self.phase = Phase.CONFIRM
            attempt = answer.attempt + 1
            self.answer = replace(answer, attempt=attempt, id=self._answer_id(attempt),
                                  response=replace(answer.response, attempt=attempt))
            return self.answer
        clustered, extra = 0, {}
        if strengthens:
            action = "strengthen"
            mem.strengthen(nearest, self.key)
        else:
            action = "new_exemplar"
            # a failed rehearsal leaves the memory as it was: nothing recorded yet
            rehearsed = [learner.rehearse("new_exemplar", list(mem.entries),
                                          self._new_entry(guess), self.sequence)]
            if policies.placement.clusters(mem.num_samples_of(guess)):
                entries, clustered, cut = learner.cluster(guess)
                extra["d_cutoff"] = cut
                if clustered:
                    rehearsed.append(learner.rehearse("clustering", entries))
            self.rehearsals.extend(rehearsed)
        self.feedbacks.append(1)
        mem.placed(demonstration_digest(self.demo), self.key, self.demo.true_concept)
        self._record(self._event(answer, 1, action, d_cutoff=extra.get("d_cutoff"),
                                 concept=guess, entries=len(mem), clustered=clustered))
        return self._finish(guess, action, clustered)

    def _refuse(self) -> Answer | LearnOutcome:
        """-1 for a guess (or a confirmation): the guess is tried; the next answer."""
        answer = self.answer
        assert answer is not None
        self.feedbacks.append(-1)
        self._record(self._event(answer, -1, "next_guess"))
        self.tried.append(answer.concept)
        self.phase = Phase.GUESS
        novelty = self.learner.policies.novelty
        if novelty.offer_again(self.refused_in_a_row, self.novelty_asked_again,
                               any(c not in self.tried for c in self.labels)):
            # the "no"s go against the refused novelty answer (or the
            # familiarity that kept it back): asked (again) before the next
            # guess, once per demonstration
            return self._offer_novelty()
        return self._next_guess()

    def _found(self) -> LearnOutcome:
        """"Yes, that is new" to the novelty answer: the robot founds the concept."""
        self.feedbacks.append(1)
        return self._found_concept(novel=True)

    def _refuse_novelty(self) -> Answer | LearnOutcome:
        """"No" to the novelty answer: back to guessing among the known concepts."""
        assert self.answer is not None
        self.feedbacks.append(-1)
        self._record(InteractionEvent(demo=self.key, step=self.step,
                                      attempt=self.answer.attempt, guessed=None,
                                      tried=tuple(self.tried), answered=None, feedback=-1,
                                      action="next_guess",
                                      extra={"novel": True, "familiarity": self.familiarity}))
        self.phase = Phase.GUESS
        return self._next_guess()

    def _found_concept(self, novel: bool | None = None) -> LearnOutcome:
        """The demonstration founds a concept; ``novel``: after a novelty answer's "yes"
        (False when every known concept was refused; None for the very first
        demonstration, when nothing was asked)."""
        learner, mem = self.learner, self.learner.memory
        label, undo = mem.found_label()
        try:
            self.rehearsals.append(learner.rehearse(
                "new_concept", list(mem.entries), self._new_entry(label), self.sequence))
        except BaseException:
            undo()   # the label was not used
            raise
        mem.placed(demonstration_digest(self.demo), self.key, self.demo.true_concept)
        extra: dict[str, Any] = {"concept": label, "entries": len(mem)}
        if novel is not None:
            extra["novel"] = novel
        self._record(InteractionEvent(
            demo=self.key, step=self.step,
            attempt=len(self.feedbacks) if novel else len(self.feedbacks) + 1, guessed=None,
            tried=tuple(self.tried), answered=None, feedback=1 if novel else 0,
            action="new_concept", extra=extra))
        return self._finish(label, "new_concept")

    def _finish(self, concept: str, action: str, clustered: int = 0) -> LearnOutcome:
        self.phase = Phase.DONE
        self.answer = None
        self.outcome = LearnOutcome(self.key, concept, action, tuple(self.feedbacks),
                                    tuple(self.events), tuple(self.rehearsals), clustered)
        return self.outcome

    # -- answers -------------------------------------------------------------------------
    def _offer_novelty(self) -> Answer:
        """The novelty answer (policy "novelty"): the demonstration imitated back."""
        attempt = len(self.feedbacks) + 1
        response = self.learner.respond_novel(self.sequence, self.start, self.dt, attempt,
                                              self.familiarity, self.frame)
        self.phase = Phase.NOVELTY
        self.answer = self._answer(response, response.concept, float("nan"), attempt,
                                   entry=-1, distance=float("nan"), dt=self.dt)
        return self.answer

    def _next_guess(self) -> Answer | LearnOutcome:
        """The guess among untried concepts, or a new concept when none is left."""
        labels, mem = self.labels, self.learner.memory
        untried = [i for i, c in enumerate(labels) if c not in self.tried]
        if not untried:
            return self._found_concept(novel=False)
        nearest = min(untried, key=lambda i: self.ranking[i])
        guess = labels[nearest]
        performer = mem.performer_of(guess)
        attempt = len(self.feedbacks) + 1
        response = self.learner.respond(performer, attempt, self.frame)
        others = [self.distances[i] for i in untried if labels[i] != guess]
        d = float(self.distances[nearest])
        conf = 1.0 if not others else float(np.clip(
            1.0 - d / min(others), 0.0, 1.0)) if min(others) > 0 else 0.0
        self.phase = Phase.GUESS
        self.answer = self._answer(response, guess, conf, attempt, entry=performer,
                                   distance=d, dt=float(mem.entries[performer].dt))
        return self.answer

    def _answer(self, response: Any, concept: str, conf: float, attempt: int, *,
                entry: int, distance: float, dt: float) -> Answer:
        return Answer.of(response, demo=self.key, concept=concept, confidence=conf,
                         attempt=attempt, entry=entry, distance=distance, dt=dt,
                         id=self._answer_id(attempt))

    def _answer_id(self, attempt: int) -> str:
        return f"{self.token}-{attempt}"

    def _new_entry(self, label: str) -> Entry:
        return Entry.learned_from(self.sequence, self.start, self.dt, self.pb_obs, label,
                                  self.key, self.learner.policies.rehearsal.keep_patterns)

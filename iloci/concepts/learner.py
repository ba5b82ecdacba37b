"""ILoCI's learner: the learning phase's steps on a memory, and the inference phase.

The learning phase runs one demonstration at a time as a :class:`Turn`, the
state machine of :mod:`iloci.concepts.turn` (the paper's procedure and its
transition table are in that module's docstring); :meth:`Learner.observe`
starts one and :meth:`Learner.learn` drives it with a teacher object
(:func:`run_turn`). The ``[learner]`` options are read once, into the
named :class:`~iloci.concepts.policies.Policies`.

Inference (the base class :class:`~iloci.concepts.recognizer.Recognizer`):
PB_obs of each demonstration against every PB_rec, or the network's
regenerated patterns by ``[learner] decision``; the nearest entry's concept
is the answer (see :class:`Recognition` for the confidence).

This module also gives the names the learner's parts had when they lived
here (:class:`Answer`, :class:`LearnOutcome`, :func:`perform`,
:func:`familiarity`, ...).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
import contextlib
import threading
from typing import Any

import numpy as np

from iloci.concepts import rehearsal
from iloci.concepts.answers import ACTIONS, Answer, LearnOutcome
from iloci.concepts.inference import (TILT_MARGIN, Recognition, confidence, familiarity,
                                      novelty_scale, pattern_distances, regenerated_patterns,
                                      regeneration_scale)
from iloci.concepts.memory import Entry, Memory
from iloci.concepts.perform import ik_joint_limits, perform, perform_novel
from iloci.concepts.policies import Policies
from iloci.concepts.recognizer import Recognizer
from iloci.concepts.rehearsal import RehearsalProgress
from iloci.concepts.turn import Phase, Turn
from iloci.config import LearnerConfig
from iloci.errors import ObserverError
from iloci.events import InteractionEvent, RehearsalEvent
from iloci.interfaces import (Clusterer, Demonstration, PerceptualModel, Response, Simulator,
                              Teacher, check_feedback)
from iloci.sensorimotor.frames import TeacherFrame

__all__ = ["ACTIONS", "Answer", "Learner", "LearnOutcome", "Phase", "Recognition", "TILT_MARGIN",
           "Turn", "confidence", "familiarity", "ik_joint_limits", "novelty_scale", "perform",
           "pattern_distances", "regenerated_patterns", "regeneration_scale",
           "run_turn", "show_to_teacher"]


def show_to_teacher(teacher: Any, demo: Demonstration,
                    labels: Mapping[str, str] | None = None) -> None:
    """Tell a teacher with a ``show(demo)`` method which demonstration the robot is shown.

    Called before the robot answers, so a teacher that judges answers by
    the demonstrations memory entries stand for (the oracle) knows the
    founding demonstration of each concept too, which is placed without a
    question. ``labels``: the memory's :attr:`~iloci.concepts.memory.Memory.labels`,
    given to a teacher with a ``recall(labels)`` method first (the oracle: the
    demonstrations a memory learned in an earlier session). Teachers without
    these methods are left alone.
    """
    recall = getattr(teacher, "recall", None)
    if labels and callable(recall):
        recall(labels)
    show = getattr(teacher, "show", None)
    if callable(show) and isinstance(demo, Demonstration):  # others: observe's error
        show(demo)


def run_turn(teacher: Teacher, demo: Demonstration, observe: Callable[[], Turn],
             labels: Mapping[str, str] | None = None) -> LearnOutcome:
    """Learn ``demo`` with a teacher object: the one observe -> feedback loop.

    Every caller with a teacher object runs it (:meth:`Learner.learn
    <iloci.concepts.learner.Learner.learn>`, :meth:`Agent.learn
    <iloci.agent.Agent.learn>` and so :meth:`~iloci.agent.Agent.teach`,
    ``iloci teach`` with the console teacher, the evaluation): the teacher
    is shown the demonstration (:func:`show_to_teacher`; ``labels``: the
    memory's, for a teacher that recalls them), ``observe()``
    starts the turn, and each answer is judged by ``teacher.feedback(demo,
    answer.response)``, whose checked value goes to :meth:`Turn.feedback`
    with the answer's id, as an event-driven caller (the web page, a ROS
    node) gives it.

    Raises
    ------
    FeedbackError
        The teacher returned something other than +1 or -1; the memory is
        left as it was.
    ObserverError
        See :meth:`Learner.learn <iloci.concepts.learner.Learner.learn>`.
    """
    show_to_teacher(teacher, demo, labels)
    turn = observe()
    while turn.answer is not None:
        answer = turn.answer
        value = teacher.feedback(demo, answer.response)
        turn.feedback(check_feedback(value, teacher), answer.id)
    assert turn.outcome is not None
    return turn.outcome


class Learner(Recognizer):
    """Runs the learning and inference phases on a :class:`Memory`.

    Parameters
    ----------
    memory : Memory
        Modified in place. Its encoder must be fitted before
        :meth:`respond` decodes a motion.
    model : PerceptualModel
        The memory's TrajectoryNet.
    clusterer : Clusterer
    teacher : Teacher
    config : LearnerConfig
    simulator : Simulator, optional
        Executes each response when given.
    hook : pluggy hook relay, optional
        ``plugin_manager.hook``; receives ``iloci_on_interaction`` and
        ``iloci_on_rehearsal``.
    joint_limits : (ndarray, ndarray), optional
        Lower and upper joint limits (rad), each (J,). A regenerated joint
        path is clipped to them before it is performed: the network may
        overshoot a limit the arm cannot pass.
    on_progress : callable, optional
        Called with a :class:`~iloci.concepts.rehearsal.RehearsalProgress`
        as each phase of a rehearsal starts and when it ends, in the thread
        that rehearses.
    lock : lock, optional
        Held by each step of a :class:`Turn` (an agent passes its own, so
        one learning step runs at a time); a fresh ``threading.RLock`` by
        default.
    current_memory : callable, optional
        Returns the memory its owner uses now (an agent passes one: its
        ``restore``, ``start_over`` and ``replace_memory`` put another
        :class:`Memory` in place); a :class:`Turn` observed on ``memory``
        refuses feedback once that is no longer it. Default: ``memory``.
    """

    def __init__(self, memory: Memory, model: PerceptualModel, clusterer: Clusterer,
                 teacher: Teacher, config: LearnerConfig | None = None, *,
                 simulator: Simulator | None = None, hook: Any = None,
                 joint_limits: tuple[np.ndarray, np.ndarray] | None = None,
                 on_progress: Callable[[RehearsalProgress], None] | None = None,
                 lock: Any = None,
                 current_memory: Callable[[], Memory] | None = None) -> None:
        self.memory = memory
        self.current_memory = current_memory or (lambda: memory)
        self.model = model
        self.clusterer = clusterer
        self.teacher = teacher
        self.config = config or LearnerConfig()
        #: The named policies the config chooses (its one reading).
        self.policies = Policies.of(self.config)
        self.simulator = simulator
        self.hook = hook
        self.joint_limits = joint_limits
        self.on_progress = on_progress
        self.lock = lock if lock is not None else threading.RLock()
        # observer events of the turn under way, sent once it is committed
        self._pending: list[tuple[str, Any]] = []
        # the network before a step's first rehearsal, put back if the step fails
        self._net_before: dict[str, np.ndarray] | None = None
        self._in_step = False

    # -- helpers ---------------------------------------------------------------
    @property
    def rehearsal_epochs(self) -> int | None:
        """Epochs of the next rehearsal (``None``: the model's ``epochs``).

        The first consolidation trains a fresh network on one pattern, the
        cheapest training there is and the one every later rehearsal builds
        on (its pattern is regenerated from then on), so it gets the model's
        full ``epochs``; later rehearsals warm-start from trained weights and
        use ``[learner] rehearsal_epochs`` when it is set.
        """
        if not self.memory.entries:
            return None
        return self.policies.rehearsal.epochs

    @property
    def rehearsal_learning_rate(self) -> float | None:
        """The weights' learning rate of the next rehearsal (``None``: the model's own).

        As with :attr:`rehearsal_epochs`, the first consolidation trains a
        fresh network (the model's ``learning_rate``); every later one
        rehearses a trained network and takes the model's
        ``params.rehearsal_learning_rate`` when it has one (every RNNPB back
        end): restarting Adam at the first training's rate from trained
        weights kicks what they hold (docs/method.md, "The rehearsal
        learning rate").
        """
        if not self.memory.entries:
            return None
        rate = getattr(getattr(self.model, "params", None), "rehearsal_learning_rate", None)
        return None if rate is None else float(rate)

    # -- the turn's events: sent to observers once the turn is committed -----------
    @property
    def queued_events(self) -> list[tuple[str, Any]]:
        """The observer events queued for the turn under way (``(hook name, event)``).

        Sent by :meth:`deliver` once the turn is committed. A front end
        holding several turns at once (the web page: one per tab) keeps each
        turn's list and sets it back before that turn's next step.
        """
        return self._pending

    @queued_events.setter
    def queued_events(self, events: list[tuple[str, Any]]) -> None:
        self._pending = events

    def emit(self, event: InteractionEvent) -> None:
        """Queue an interaction for the observers (sent by :meth:`deliver`)."""
        self._pending.append(("iloci_on_interaction", event))

    def discard_events(self) -> None:
        """Drop every queued event (a new turn starts)."""
        self._pending = []

    @contextlib.contextmanager
    def uncommitted(self) -> Iterator[None]:
        """A step of a turn: all or nothing.

        If it raises (a rehearsal that fails, a clusterer that raises after
        a rehearsal installed the new exemplar, an interrupt), the memory is
        put back as it was (:meth:`Memory.checkpoint`), the network too when
        a rehearsal had changed it, and the events it queued are dropped.
        """
        mark = len(self._pending)
        point = self.memory.checkpoint()
        self._net_before, self._in_step = None, True
        try:
            yield
        except BaseException:
            del self._pending[mark:]
            self.memory.rollback(point)
            if self._net_before is not None:
                self.model.load_state(self._net_before)
            raise
        finally:
            self._net_before, self._in_step = None, False

    def deliver(self, outcome: LearnOutcome) -> None:
        """Send the events of one committed learning step to every observer.

        Each observer (hook implementation) gets every event, even when
        another one raised; then one :class:`~iloci.errors.ObserverError`
        names the first failing hook and plugin. Learning is committed
        before any observer runs, so a fault never leaves it half done.
        """
        pending, self._pending = self._pending, []
        if self.hook is None:
            return
        faults: list[tuple[str, str, BaseException]] = []
        for hook_name, event in pending:
            caller = getattr(self.hook, hook_name)
            impls = caller.get_hookimpls() if hasattr(caller, "get_hookimpls") else None
            if impls is None or any(getattr(i, "hookwrapper", False) or
                                    getattr(i, "wrapper", False) for i in impls):
                try:
                    caller(event=event)
                except Exception as exc:
                    faults.append((hook_name, "?", exc))
                continue
            for impl in reversed(impls):  # pluggy's calling order
                try:
                    impl.function(event=event)
                except Exception as exc:
                    faults.append((hook_name, impl.plugin_name, exc))
        if faults:
            hook_name, plugin, first = faults[0]
            raise ObserverError(hook_name, plugin, first, outcome, len(faults)) from first

    # -- the memory's changes that need the network or the clusterer ---------------
    def rehearse(self, reason: str, entries: list[Entry],
                  new_entry: Entry | None = None,
                  new_pattern: np.ndarray | None = None) -> RehearsalEvent:
        """Rehearse ``entries`` (plus a new pattern) and install the result in the memory.

        ``entries`` (and ``new_entry``) are the memory to be; the memory
        itself is replaced in one assignment only when the rehearsal has
        succeeded, so a reader in another thread sees the old memory or the
        new one, never a mix, and a failed rehearsal leaves it as it was.
        """
        if self._in_step and self._net_before is None:  # put back if the step fails
            self._net_before = {k: np.array(v, copy=True)
                                for k, v in self.model.state().items()}
        result = rehearsal.rehearse(self.model, entries, new_pattern,
                                    None if new_entry is None else new_entry.pb,
                                    epochs=self.rehearsal_epochs,
                                    learning_rate=self.rehearsal_learning_rate, reason=reason,
                                    progress=self.on_progress)
        updated = [e.copy() for e in entries] + ([] if new_entry is None else [new_entry])
        rehearsal.apply(result, updated)
        self.memory.install(updated)
        event = RehearsalEvent(entries=len(result.patterns), epochs=result.epochs or 0,
                               loss=result.loss, seconds=result.seconds, reason=reason,
                               extra={"concepts": len(self.memory.concepts())})
        self._pending.append(("iloci_on_rehearsal", event))
        return event

    def respond(self, index: int, attempt: int = 1,
                frame: TeacherFrame | None = None) -> Response:
        """The robot's answer: entry ``index`` performed (see :func:`perform`).

        ``frame``: the frame of the demonstration answered, which fills
        ``Response.teacher_drawing``.
        """
        return perform(self.memory, self.model, index, joint_limits=self.joint_limits,
                       simulator=self.simulator, attempt=attempt, frame=frame)

    def respond_novel(self, sequence: np.ndarray, start: np.ndarray, dt: float,
                      attempt: int = 1, fam: float = float("nan"),
                      frame: TeacherFrame | None = None) -> Response:
        """The novelty answer: the demonstration imitated back (see :func:`perform_novel`).

        ``fam``: the demonstration's familiarity, kept in ``extra``.
        """
        return perform_novel(self.memory, sequence, start, dt, joint_limits=self.joint_limits,
                             simulator=self.simulator, attempt=attempt, familiarity=fam,
                             frame=frame)

    # -- learning phase ------------------------------------------------------------
    def observe(self, demo: Demonstration, sequence: np.ndarray, start: np.ndarray,
                dt: float, frame: TeacherFrame | None = None) -> Turn:
        """Start learning from one demonstration: the robot's first guess, or the outcome.

        The step-wise form of the learning phase (see :class:`Turn`). With
        an empty memory the demonstration becomes the first concept at once
        (rehearsal included) and the turn is already over; otherwise the
        turn holds the first guess, waiting for :meth:`Turn.feedback`.

        Parameters
        ----------
        demo : Demonstration
        sequence : ndarray, shape (T - 1, D)
            Its encoded sequence.
        start : ndarray, shape (6,)
            Its absolute first sample ``[y, z, q1..q4]``.
        dt : float
            Time step (s) of its motion.
        frame : TeacherFrame, optional
            Maps the robot's drawings into the demonstration's frame
            (:attr:`Answer.drawing`); without it answers are shown in the
            drawing plane.

        Returns
        -------
        Turn

        Raises
        ------
        InvalidInputError
            ``sequence`` is not a finite (T, D) array with T >= 2.
        """
        return Turn(self, demo, sequence, start, dt, frame,
                    learned=self.memory.learned_concept(demo))

    def learn(self, demo: Demonstration, sequence: np.ndarray, start: np.ndarray,
              dt: float, frame: TeacherFrame | None = None) -> LearnOutcome:
        """Learn from one demonstration, asking ``self.teacher`` for each feedback.

        :meth:`observe`, then :meth:`Turn.feedback` with the teacher's
        answer until the turn is over: the one code path of the learning
        phase, driven by a teacher object.

        Returns
        -------
        LearnOutcome

        Raises
        ------
        FeedbackError
            The teacher returned something other than +1 or -1; the memory
            is left as it was.
        ObserverError
            An observer hook (``iloci_on_interaction``,
            ``iloci_on_rehearsal``) raised. Observers are called after the
            memory has been updated: the demonstration *is* learned (the
            error's ``outcome`` says how) and must not be taught again.
            Every other observer received every event.
        """
        return run_turn(self.teacher, demo,
                        lambda: self.observe(demo, sequence, start, dt, frame),
                        self.memory.labels)

    def cluster(self, concept: str) -> tuple[list[Entry], int, float]:
        """The memory's entries with ``concept``'s valid clusters replaced by their medoids.

        :meth:`Memory.clustered <iloci.concepts.memory.Memory.clustered>`
        with this learner's clusterer and the placement policy's
        ``k_cutoff`` and ``num_threshold``: copies, rehearsed by the caller
        when any cluster was replaced. Returns ``(entries, clusters
        replaced, D_cutoff)``.
        """
        placement = self.policies.placement
        stands_for = (self._stands_for(concept) if placement.condense == "consistent"
                      else None)
        return self.memory.clustered(concept, self.clusterer, k_cutoff=placement.k_cutoff,
                                     num_threshold=placement.num_threshold,
                                     stands_for=stands_for)

    def _stands_for(self, concept: str) -> Callable[[int, int], bool] | None:
        """``[learner] condense = "consistent"``: whether a medoid may replace a member.

        Entry ``member`` of ``concept`` (an index into the memory's entries)
        may be replaced by entry ``medoid`` when, in what ``[learner]
        decision`` ranks by, the member's kept demonstration (its encoded
        sequence, ``Entry.pattern``) lies nearer the medoid than every entry
        of another concept: after the merge the memory still answers that
        demonstration with its concept (the consistency of Hart's condensed
        nearest neighbour rule, Hart 1968, doi:10.1109/TIT.1968.1054155;
        docs/method.md, "Clustering").
        By PB distance (``decision = "pb_distance"``) the member's PB stands
        for its demonstration. ``None`` (every member replaced, the paper's
        rule) when an entry of the concept keeps no demonstration
        (``rehearse_from = "regenerated"``, or a memory saved without them)
        or the memory holds one concept.
        """
        entries = self.memory.entries
        labels = np.array([e.concept for e in entries])
        own = np.flatnonzero(labels == concept)
        other = labels != concept
        by_pb = self.policies.ranking == "pb_distance"
        kept = [entries[i].pattern for i in own]
        seqs = [p for p in kept if p is not None]
        if not other.any() or (not by_pb and len(seqs) < len(kept)):
            return None
        row = {int(i): k for k, i in enumerate(own)}
        found: list[tuple[np.ndarray, np.ndarray]] = []

        def distances() -> tuple[np.ndarray, np.ndarray]:
            # taken once, at the first member asked about: a concept clustered
            # without a valid cluster costs nothing
            if not found:
                if by_pb:
                    pbs = np.asarray(self.memory.pbs, dtype=np.float64)
                    d = np.sqrt(((pbs[own][:, None, :] - pbs[None, :, :]) ** 2).sum(axis=2))
                else:
                    d = (self.regeneration_distances(seqs) if self.policies.rank_by_regeneration
                         else self.entry_errors(seqs))
                found.append((d, np.where(other[None, :], d, np.inf).min(axis=1)))
            return found[0]

        def stands_for(member: int, medoid: int) -> bool:
            d, nearest_other = distances()
            k = row[member]
            return bool(d[k, medoid] < nearest_other[k])

        return stands_for

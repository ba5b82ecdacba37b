"""ILoCI's learner: the learning phase's steps on a memory, and the inference phase.

The learning phase runs one demonstration at a time as a :class:`Turn`, the
state machine of :mod:`iloci.concepts.turn` (the paper's procedure and its
transition table are in that module's docstring); :meth:`Learner.observe`
starts one and :meth:`Learner.learn` drives it with a teacher object
(:func:`run_turn`). The ``[learner]`` options are read once, into the
named :class:`~iloci.concepts.policies.Policies`.

Inference: PB_obs of each demonstration against every PB_rec; the nearest
entry's concept is the answer (see :class:`Recognition` for the
confidence).

This module also gives the names the learner's parts had when they lived
here (:class:`Answer`, :class:`LearnOutcome`, :func:`perform`,
:func:`familiarity`, ...).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
import contextlib
from dataclasses import replace
import threading
from typing import Any

import numpy as np
from scipy.spatial.distance import cdist

from iloci.concepts import rehearsal
from iloci.concepts.answers import ACTIONS, Answer, LearnOutcome
from iloci.concepts.inference import (TILT_MARGIN, Recognition, confidence, familiarity,
                                      novelty_scale, path_distances, path_scale,
                                      pattern_distances, regenerated_patterns,
                                      regeneration_scale)
from iloci.concepts.memory import Entry, Memory
from iloci.concepts.perform import ik_joint_limits, perform, perform_novel
from iloci.concepts.policies import Policies
from iloci.concepts.rehearsal import RehearsalProgress
from iloci.concepts.turn import Phase, Turn
from iloci.config import LearnerConfig
from iloci.errors import NotFittedError, ObserverError
from iloci.events import InteractionEvent, RehearsalEvent
from iloci.interfaces import (Clusterer, Demonstration, PerceptualModel, Response, Simulator,
                              Teacher, check_feedback)
from iloci.sensorimotor.frames import TeacherFrame

__all__ = ["ACTIONS", "Answer", "Learner", "LearnOutcome", "Phase", "Recognition", "TILT_MARGIN",
           "Turn", "confidence", "familiarity", "ik_joint_limits", "novelty_scale", "perform",
           "pattern_distances", "regenerated_patterns", "regeneration_scale",
           "run_turn", "show_to_teacher"]


def show_to_teacher(teacher: Any, demo: Demonstration) -> None:
    """Tell a teacher with a ``show(demo)`` method which demonstration the robot is shown.

    Called before the robot answers, so a teacher that judges answers by
    the demonstrations memory entries stand for (the oracle) knows the
    founding demonstration of each concept too, which is placed without a
    question. Teachers without ``show`` are left alone.
    """
    show = getattr(teacher, "show", None)
    if callable(show) and isinstance(demo, Demonstration):  # others: observe's error
        show(demo)


def run_turn(teacher: Teacher, demo: Demonstration, observe: Callable[[], Turn]
             ) -> LearnOutcome:
    """Learn ``demo`` with a teacher object: the one observe -> feedback loop.

    Every caller with a teacher object runs it (:meth:`Learner.learn
    <iloci.concepts.learner.Learner.learn>`, :meth:`Agent.learn
    <iloci.agent.Agent.learn>` and so :meth:`~iloci.agent.Agent.teach`,
    ``iloci teach`` with the console teacher, the evaluation): the teacher
    is shown the demonstration (:func:`show_to_teacher`), ``observe()``
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
    show_to_teacher(teacher, demo)
    turn = observe()
    while turn.answer is not None:
        answer = turn.answer
        value = teacher.feedback(demo, answer.response)
        turn.feedback(check_feedback(value, teacher), answer.id)
    assert turn.outcome is not None
    return turn.outcome


class Learner:
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
    """

    def __init__(self, memory: Memory, model: PerceptualModel, clusterer: Clusterer,
                 teacher: Teacher, config: LearnerConfig | None = None, *,
                 simulator: Simulator | None = None, hook: Any = None,
                 joint_limits: tuple[np.ndarray, np.ndarray] | None = None,
                 on_progress: Callable[[RehearsalProgress], None] | None = None,
                 lock: Any = None) -> None:
        self.memory = memory
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
        """A step of a turn: the events it queues are dropped if it raises (it changed nothing)."""
        mark = len(self._pending)
        try:
            yield
        except BaseException:
            del self._pending[mark:]
            raise

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
        result = rehearsal.rehearse(self.model, entries, new_pattern,
                                    None if new_entry is None else new_entry.pb,
                                    epochs=self.rehearsal_epochs, reason=reason,
                                    progress=self.on_progress)
        updated = [e.copy() for e in entries] + ([] if new_entry is None else [new_entry])
        rehearsal.apply(result, updated)
        self.memory.install(updated)
        event = RehearsalEvent(entries=len(result.patterns), epochs=result.epochs or 0,
                               loss=result.loss, seconds=result.seconds, reason=reason,
                               extra={"concepts": len(self.memory.concepts())})
        self._pending.append(("iloci_on_rehearsal", event))
        return event

    def recognize_pbs(self, sequences: Sequence[np.ndarray]) -> np.ndarray:
        """PB_obs of each sequence, multi-start from the stored PBs, shape (B, P)."""
        if not self.memory.entries:
            raise NotFittedError("the robot has learned nothing yet: teach it at least one "
                                 "demonstration (Agent.learn / `iloci teach`) before "
                                 "recognizing.")
        return np.asarray(self.model.recognize(list(sequences), candidate_pbs=self.memory.pbs),
                          dtype=np.float64).reshape(len(sequences), -1)

    def entry_errors(self, sequences: Sequence[np.ndarray]) -> np.ndarray:
        """How well each entry's PB reproduces each sequence, shape (B, M).

        The closed-loop prediction error (mean squared, encoded units) of
        sequence ``b`` generated from entry ``m``'s PB, starting from the
        sequence's own first step: ``[learner] decision = "reproduction"``
        answers with the entry of lowest error (one batched call of the
        model's ``prediction_error`` over every pair).
        """
        seqs = list(sequences)
        pbs = self.memory.pbs
        m = len(pbs)
        pairs = [s for s in seqs for _ in range(m)]
        errors = np.asarray(self.model.prediction_error(pairs, np.tile(pbs, (len(seqs), 1))),
                            dtype=np.float64)
        return errors.reshape(len(seqs), m)

    def regeneration_distances(self, sequences: Sequence[np.ndarray],
                               patterns: Sequence[np.ndarray] | None = None) -> np.ndarray:
        """How far each sequence lies from each entry's regenerated pattern, shape (B, M).

        :func:`~iloci.concepts.inference.pattern_distances` (with ``[learner]
        warp`` and ``compare``) of the sequences to the memory's
        :func:`~iloci.concepts.inference.regenerated_patterns` (``patterns``
        when given, e.g. computed once for several calls): ``[learner]
        decision = "regeneration"`` answers with the entry of the lowest one.
        """
        pats = regenerated_patterns(self.model, self.memory) if patterns is None else patterns
        return pattern_distances(sequences, pats, self.policies.warp, self.policies.compare)

    def tilt_scores(self, sequences: Sequence[np.ndarray]) -> np.ndarray:
        """Per sequence, how well the memory reproduces it: the tilt search's criterion.

        The best over entries of the quantity ``[learner] decision`` ranks
        by (regeneration distance, else the entry prediction error), shape (B,).
        """
        if self.policies.rank_by_regeneration:
            return self.regeneration_distances(sequences).min(axis=1)
        return self.entry_errors(sequences).min(axis=1)

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
                        lambda: self.observe(demo, sequence, start, dt, frame))

    def cluster(self, concept: str) -> tuple[list[Entry], int, float]:
        """The memory's entries with ``concept``'s valid clusters replaced by their medoids.

        :meth:`Memory.clustered <iloci.concepts.memory.Memory.clustered>`
        with this learner's clusterer and the placement policy's
        ``k_cutoff`` and ``num_threshold``: copies, rehearsed by the caller
        when any cluster was replaced. Returns ``(entries, clusters
        replaced, D_cutoff)``.
        """
        placement = self.policies.placement
        return self.memory.clustered(concept, self.clusterer, k_cutoff=placement.k_cutoff,
                                     num_threshold=placement.num_threshold)

    # -- inference phase -------------------------------------------------------------
    def recognize(self, sequences: Sequence[np.ndarray],
                  keys: Sequence[str] | None = None, *,
                  tilted: Callable[[int], Sequence[tuple[float, np.ndarray]]] | None = None
                  ) -> list[Recognition]:
        """Recognize a batch of encoded sequences (no feedback, memory unchanged).

        Parameters
        ----------
        sequences : sequence of ndarray, each (T_i, D)
        keys : sequence of str, optional
            Demonstration keys, for the results.
        tilted : callable, optional
            The tilt search (``[learner] tilts``, ``tilt_beyond``):
            ``tilted(b)`` gives ``(degrees, sequence)`` pairs, sequence
            ``b`` turned by each angle of ``tilts`` and encoded
            (:meth:`Agent.recognize <iloci.agent.Agent.recognize>` turns the
            pen path with :func:`~iloci.sensorimotor.pipeline.tilted`). It
            is called only for the sequences whose PB_obs lies further
            than ``tilt_beyond`` from every PB_rec; of a sequence's
            readings, the one with the lowest entry prediction error
            (:meth:`entry_errors`, the best over the memory's entries) is
            recognized, a turned one only when that error is below
            :data:`TILT_MARGIN` times the upright reading's.

        Returns
        -------
        list of Recognition
            With ``tilt``, the angle of the reading recognized.
        """
        # the memory's calibration, once for the readings as drawn and turned
        policies = self.policies
        patterns = (regenerated_patterns(self.model, self.memory)
                    if policies.rank_by_regeneration or policies.familiar_by_regeneration
                    or policies.familiar_by_path else None)
        scale = self.familiarity_scale(patterns)
        out = self._recognize(sequences, keys, scale, patterns)
        if tilted is None or not self.policies.inference.tilts:
            return out
        ask = [b for b, r in enumerate(out) if r.distance > self.policies.inference.tilt_beyond]
        owners: list[tuple[int, float]] = []
        turned: list[np.ndarray] = []
        for b in ask:
            for degrees, seq in tilted(b):
                owners.append((b, float(degrees)))
                turned.append(seq)
        if not turned:
            return out
        seqs = list(sequences)
        upright = self.tilt_scores([seqs[b] for b in ask])
        best = {b: (TILT_MARGIN * float(e), -1) for b, e in zip(ask, upright)}
        for j, e in enumerate(self.tilt_scores(turned)):
            b = owners[j][0]
            if e < best[b][0]:
                best[b] = (float(e), j)
        chosen = sorted({j for _, j in best.values() if j >= 0})
        if not chosen:
            return out
        recs = self._recognize([turned[j] for j in chosen],
                               [out[owners[j][0]].demo for j in chosen], scale, patterns)
        for j, r in zip(chosen, recs):
            out[owners[j][0]] = replace(r, tilt=owners[j][1])
        return out

    def familiarity_scale(self, patterns: Sequence[np.ndarray] | None = None) -> float:
        """The memory's own scale of what ``[learner] familiarity`` measures.

        :func:`~iloci.concepts.inference.path_scale` (``"path"``),
        :func:`~iloci.concepts.inference.regeneration_scale`
        (``"regeneration"``) or :func:`~iloci.concepts.inference.novelty_scale`
        (``"reproduction"``, ``"prediction"``); ``patterns``: the memory's
        :func:`~iloci.concepts.inference.regenerated_patterns` when already
        computed. NaN with fewer than two concepts.
        """
        policies = self.policies
        if policies.familiar_by_path or policies.familiar_by_regeneration:
            pats = regenerated_patterns(self.model, self.memory) if patterns is None else patterns
            labels = self.memory.concept_labels
            return (path_scale(pats, labels) if policies.familiar_by_path
                    else regeneration_scale(pats, labels, policies.warp, policies.compare))
        return novelty_scale(self.model, self.memory)

    def familiarities(self, sequences: Sequence[np.ndarray], scale: float, *,
                      patterns: Sequence[np.ndarray] | None = None,
                      regeneration: np.ndarray | None = None,
                      reproduction: np.ndarray | None = None,
                      pb_obs: np.ndarray | None = None) -> np.ndarray:
        """Each sequence's familiarity by ``[learner] familiarity``, shape (B,).

        :func:`~iloci.concepts.inference.familiarity` on ``scale``
        (:meth:`familiarity_scale`) of: the lowest
        :func:`~iloci.concepts.inference.path_distances` (``"path"``), the
        lowest :meth:`regeneration_distances` (``"regeneration"``), the
        lowest :meth:`entry_errors` (``"reproduction"``) or the prediction
        error from PB_obs (``"prediction"``). What the caller already
        computed is passed in (``patterns``; ``regeneration``,
        ``reproduction``: (B, M) distances / errors; ``pb_obs``: (B, P)).
        """
        seqs = list(sequences)
        policies = self.policies
        if policies.familiar_by_path or policies.familiar_by_regeneration:
            pats = regenerated_patterns(self.model, self.memory) if patterns is None else patterns
            if policies.familiar_by_path:
                nearest = path_distances(seqs, pats).min(axis=1)
            else:
                d = (self.regeneration_distances(seqs, pats) if regeneration is None
                     else regeneration)
                nearest = d.min(axis=1)
        elif policies.familiar_by_reproduction:
            nearest = (self.entry_errors(seqs) if reproduction is None
                       else reproduction).min(axis=1)
        else:
            pbs = self.recognize_pbs(seqs) if pb_obs is None else pb_obs
            nearest = np.asarray(self.model.prediction_error(seqs, pbs), dtype=np.float64)
        return familiarity(nearest, scale)

    def _recognize(self, sequences: Sequence[np.ndarray], keys: Sequence[str] | None,
                   scale: float, patterns: Sequence[np.ndarray] | None = None
                   ) -> list[Recognition]:
        """:meth:`recognize` of each sequence as given (no tilt search);
        ``scale``: :meth:`familiarity_scale` of the memory, ``patterns`` its
        regenerated patterns (when the policies use them)."""
        seqs = list(sequences)
        keys = list(keys) if keys is not None else [f"#{i}" for i in range(len(seqs))]
        if not seqs:
            return []
        pb_obs = self.recognize_pbs(seqs)
        errors = np.asarray(self.model.prediction_error(seqs, pb_obs), dtype=np.float64)
        pbs_rec = self.memory.pbs_rec
        dist = cdist(pb_obs, pbs_rec, "euclidean")
        labels = self.memory.concept_labels
        policies = self.policies
        reproduction = policies.familiar_by_reproduction
        below = policies.inference.unknown_below
        entry_errors = (self.entry_errors(seqs) if policies.rank_by_reproduction
                        or (below > 0 and reproduction) else None)
        regen = None
        if policies.rank_by_regeneration:
            if patterns is None:
                patterns = regenerated_patterns(self.model, self.memory)
            regen = self.regeneration_distances(seqs, patterns)
        ranking = (entry_errors if policies.rank_by_reproduction
                   else regen if policies.rank_by_regeneration else dist)
        nearest, conf = confidence(dist if ranking is None else ranking, labels)
        # "unknown" asks whether the demonstration is like anything the robot
        # knows (by default: the form of its pen path against the forms the
        # network regenerates from its entries), on the scale at which two
        # known concepts lie apart: the same quantity on both sides.
        rep = (entry_errors.min(axis=1) if entry_errors is not None
               else np.full(len(seqs), np.nan))
        if policies.familiar_by_path or policies.familiar_by_regeneration:
            fam = self.familiarities(seqs, scale, patterns=patterns, regeneration=regen)
        else:
            # the reproduction errors are a closed-loop run per (drawing,
            # entry): taken only when "unknown" is asked; else the PB_obs error
            fam = familiarity(rep if entry_errors is not None and reproduction else errors,
                              scale)
        out = []
        for b, i in enumerate(nearest):
            e = self.memory.entries[int(i)]
            out.append(Recognition(keys[b], e.concept, float(conf[b]), float(dist[b, i]),
                                   int(i), e.source, tuple(e.sources), pb_obs[b].copy(),
                                   float(errors[b]), float(fam[b]),
                                   bool(below > 0 and fam[b] < below), float(rep[b])))
        return out

"""ILoCI's learning phase, one demonstration at a time, and its inference phase.

Learning (docs/method.md, "Learning phase"; the paper's "Learning Phase")::

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

Inference: PB_obs of each demonstration against every PB_rec; the nearest
entry's concept is the answer (see :class:`Recognition` for the
confidence).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
import threading
from typing import Any

import numpy as np
from scipy.spatial.distance import cdist

from iloci.concepts import clustering, rehearsal
from iloci.concepts.memory import Entry, Memory
from iloci.concepts.rehearsal import RehearsalProgress
from iloci.config import LearnerConfig
from iloci.errors import InvalidInputError, NotFittedError
from iloci.events import InteractionEvent, RehearsalEvent
from iloci.interfaces import (Clusterer, Demonstration, PerceptualModel, Response, Simulator,
                              Teacher, check_feedback)
from iloci.sensorimotor.frames import TeacherFrame

__all__ = ["Answer", "Learner", "LearnOutcome", "Recognition", "Turn", "confidence",
           "familiarity", "ik_joint_limits", "novelty_scale", "perform"]

#: A turned reading of the tilt search (``[learner] tilts``) is recognized
#: only when its entry prediction error is below this fraction of the
#: upright reading's, so the drawing as drawn wins near ties (measured on
#: LASA's folds: docs/guide.md, "How a drawing is read").
TILT_MARGIN = 0.9

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
        ``"new_concept"``.
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
class Recognition:
    """The inference-phase answer for one demonstration.

    Attributes
    ----------
    demo : str
        Key of the demonstration.
    concept : str
        The robot's concept label of the nearest entry.
    confidence : float
        In [0, 1]: ``1 - d_best / d_other``, where ``d_best`` is the PB
        distance from PB_obs to the nearest PB_rec and ``d_other`` the
        distance to the nearest PB_rec of any *other* concept. 0 means the
        demonstration lies as close to another concept as to the answer;
        values near 1 mean it lies much closer to the answer. 1 when the
        memory holds a single concept. (The paper reports a confidence per
        answer without defining it; this margin is the project's
        definition.) With ``[learner] decision = "reproduction"`` the same
        margin is taken on the entries' prediction errors
        (:meth:`Learner.entry_errors`) instead of PB distances.
    distance : float
        PB distance from PB_obs to the answering entry's PB_rec.
    entry : int
        Index of the answering entry in ``Memory.entries`` at recognition
        time (the nearest one, or the best reproducing one).
    source : str
        Key of the demonstration the nearest entry holds.
    sources : tuple of str
        Every demonstration the nearest entry stands for.
    pb_obs : ndarray, shape (P,)
    error : float
        Closed-loop prediction error (mean squared, encoded units) of the
        sequence from PB_obs: how well the network can reproduce it at all.
    reproduction_error : float
        The lowest closed-loop prediction error of the sequence generated
        from any memory entry's PB (:meth:`Learner.entry_errors`): how well
        the nearest thing the robot *knows* reproduces it. Computed when
        ``[learner] decision = "reproduction"`` or ``unknown_below > 0``,
        else NaN.
    """

    demo: str
    concept: str
    confidence: float
    distance: float
    entry: int
    source: str
    sources: tuple[str, ...]
    pb_obs: np.ndarray = field(repr=False)
    error: float = float("nan")
    #: How well what the memory knows reproduces the demonstration against
    #: the memory's own error scale (:func:`familiarity` of
    #: ``reproduction_error`` when computed and ``[learner] familiarity`` is
    #: ``"reproduction"``, else of ``error``); NaN when the
    #: memory cannot calibrate it (fewer than two concepts).
    familiarity: float = float("nan")
    #: True when ``familiarity`` is below ``[learner] unknown_below``: the
    #: robot answers "I don't know" (``concept`` is still the nearest one).
    unknown: bool = False
    reproduction_error: float = float("nan")
    #: Degrees the drawing was turned (counter-clockwise as the teacher
    #: sees it) in the reading recognized: 0 for the drawing as drawn, else
    #: the angle of ``[learner] tilts`` whose reading the memory reproduced
    #: best (:meth:`Learner.recognize`).
    tilt: float = 0.0


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
    encoder = memory.encoder
    if encoder is None:
        raise NotFittedError("the memory has no fitted sensorimotor encoder.")
    seq = rehearsal.regenerate(model, [entry])[0]
    plane, joints = encoder.decode(seq, entry.start)
    clipped = 0
    if joint_limits is not None:
        lower, upper = (np.asarray(a, dtype=np.float64) for a in joint_limits)
        inside = np.clip(joints, lower, upper)
        clipped = int(np.count_nonzero(inside != joints))
        joints = inside
    execution = None
    if simulator is not None:
        execution = simulator.execute(joints, entry.dt)
    drawing = plane if execution is None else np.asarray(execution.end_effector)[:, 1:3]
    return Response(concept=entry.concept, motion=plane, joint_path=joints,
                    source=entry.source, sources=tuple(entry.sources), dt=float(entry.dt),
                    teacher_drawing=None if frame is None else frame.to_teacher(drawing),
                    execution=execution, attempt=attempt,
                    extra={"entry": index, "generation_error": entry.generation_error,
                           "clipped": clipped})


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


def ik_joint_limits(ik_solver: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """``(lower, upper)`` joint limits (rad, shape (J,) each) of an IK solver, if it has them.

    The learner clips regenerated joint paths to them before execution.
    """
    if ik_solver is None or not hasattr(ik_solver, "lower"):
        return None
    return np.asarray(ik_solver.lower), np.asarray(ik_solver.upper)


def novelty_scale(model: PerceptualModel, memory: Memory) -> float:
    """The memory's own prediction-error scale for "unlike everything it knows".

    Each entry's pattern is regenerated from its PB (what the network
    knows) and its closed-loop prediction error is measured under the PB
    of the nearest entry (by PB_rec) of *another* concept: how badly one
    known concept reproduces its neighbour. The median over entries is the
    scale. This is the project's calibration; the paper has none.

    Parameters
    ----------
    model : PerceptualModel
    memory : Memory

    Returns
    -------
    float
        Mean squared error, encoded units; NaN when the memory holds fewer
        than two concepts (nothing to calibrate on).
    """
    entries = memory.entries
    labels = np.asarray(memory.concept_labels)
    if len(set(labels.tolist())) < 2:
        return float("nan")
    rec = memory.pbs_rec
    d = np.linalg.norm(rec[:, None, :] - rec[None, :, :], axis=2)
    other = np.where(labels[:, None] != labels[None, :], d, np.inf).argmin(axis=1)
    patterns = rehearsal.regenerate(model, entries)
    errors = np.asarray(model.prediction_error(patterns, memory.pbs[other]), dtype=np.float64)
    errors = errors[np.isfinite(errors)]
    return float(np.median(errors)) if errors.size else float("nan")


def familiarity(error: np.ndarray | float, scale: float) -> np.ndarray:
    """``scale / (scale + error)``: near 1 for what the network reproduces, 0.5 at the scale.

    Parameters
    ----------
    error : float or ndarray
        Closed-loop prediction error of a demonstration (mean squared,
        encoded units): by default (``[learner] familiarity =
        "reproduction"``) the lowest over memory entries of the error with
        which the entry's PB reproduces it (:meth:`Learner.entry_errors`),
        else the error from its PB_obs.
    scale : float
        :func:`novelty_scale` of the memory.

    Returns
    -------
    ndarray (or 0-d)
        In (0, 1]; NaN where ``scale`` is NaN or not positive.
    """
    e = np.asarray(error, dtype=np.float64)
    if not np.isfinite(scale) or scale <= 0:
        return np.full(e.shape, np.nan)
    return scale / (scale + np.maximum(e, 0.0))


def confidence(distances: np.ndarray, labels: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Nearest entry and the margin confidence of each row of a distance matrix.

    Parameters
    ----------
    distances : ndarray, shape (B, M)
        PB distance of each observation to each entry's PB_rec.
    labels : sequence of str, length M
        Concept of each entry.

    Returns
    -------
    nearest : ndarray of int, shape (B,)
    confidence : ndarray, shape (B,)
        ``1 - d_best / d_other`` clipped to [0, 1] (see :class:`Recognition`).
    """
    d = np.asarray(distances, dtype=np.float64)
    lab = np.asarray(labels)
    nearest = np.argmin(d, axis=1)
    d_best = d[np.arange(len(d)), nearest]
    other = np.where(lab[None, :] != lab[nearest][:, None], d, np.inf)
    d_other = other.min(axis=1) if d.shape[1] else np.full(len(d), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        conf = np.where(np.isinf(d_other), 1.0,
                        np.where(d_other > 0, 1.0 - d_best / d_other, 0.0))
    return nearest, np.clip(conf, 0.0, 1.0)


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
        return self.config.rehearsal_epochs or None

    def _emit_interaction(self, event: InteractionEvent) -> None:
        self._pending.append(("iloci_on_interaction", event))

    def _deliver(self, outcome: LearnOutcome) -> None:
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
            from iloci.errors import ObserverError
            hook_name, plugin, first = faults[0]
            raise ObserverError(hook_name, plugin, first, outcome, len(faults)) from first

    def _rehearse(self, reason: str, entries: list[Entry],
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
        self.memory.entries = updated
        self.memory.revision += 1
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
        """The novelty answer: the demonstration imitated back as something new.

        The robot performs the demonstration as it perceived it (its encoded
        sequence decoded, joints clipped to the limits; executed when a
        simulator is set), labelled with the concept it would found.

        Returns
        -------
        Response
            ``novel=True``, ``source=None``, ``sources`` every demonstration
            the memory stands for; ``extra["familiarity"]``.
        """
        encoder = self.memory.encoder
        if encoder is None:
            raise NotFittedError("the memory has no fitted sensorimotor encoder.")
        plane, joints = encoder.decode(sequence, start)
        if self.joint_limits is not None:
            lower, upper = (np.asarray(a, dtype=np.float64) for a in self.joint_limits)
            joints = np.clip(joints, lower, upper)
        execution = None
        if self.simulator is not None:
            execution = self.simulator.execute(joints, dt)
        sources = tuple(dict.fromkeys(k for e in self.memory.entries for k in e.sources))
        drawing = plane if execution is None else np.asarray(execution.end_effector)[:, 1:3]
        return Response(concept=f"c{self.memory.concept_count + 1}", motion=plane,
                        joint_path=joints, source=None, sources=sources, execution=execution,
                        attempt=attempt, extra={"familiarity": fam}, novel=True,
                        dt=float(dt),
                        teacher_drawing=None if frame is None else frame.to_teacher(drawing))

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
        return Turn(self, demo, sequence, start, dt, frame)

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
        show_to_teacher(self.teacher, demo)
        turn = self.observe(demo, sequence, start, dt, frame)
        while turn.answer is not None:
            value = self.teacher.feedback(demo, turn.answer.response)
            turn.feedback(check_feedback(value, self.teacher))
        assert turn.outcome is not None
        return turn.outcome

    def _cluster(self, entries: list[Entry], concept: str
                 ) -> tuple[list[Entry], int, float]:
        """``entries`` with ``concept``'s valid clusters replaced by their medoids.

        Works on (and returns) copies; the caller rehearses them when any
        cluster was replaced. Returns ``(entries, clusters replaced, D_cutoff)``.
        """
        entries = [e.copy() for e in entries]
        idx = [i for i, e in enumerate(entries) if e.concept == concept]
        own = [entries[i] for i in idx]
        plan = clustering.plan_clusters(
            np.array([e.pb for e in own]), [e.num_samples for e in own],
            [e.exemplar for e in own], clusterer=self.clusterer,
            k_cutoff=self.config.k_cutoff, num_threshold=self.config.num_threshold)
        if not plan.valid:
            return entries, 0, plan.d_cutoff
        drop: set[int] = set()
        for members, med in zip(plan.valid, plan.medoids):
            keep = own[med]
            others = [own[j] for j in members if j != med]
            keep.num_samples = sum(own[j].num_samples for j in members)
            keep.sources = tuple(dict.fromkeys(
                list(keep.sources) + [s for o in others for s in o.sources]))
            keep.prototype = True
            drop.update(idx[j] for j in members if j != med)
        return [e for i, e in enumerate(entries) if i not in drop], len(plan.valid), plan.d_cutoff

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
        scale = novelty_scale(self.model, self.memory)
        out = self._recognize(sequences, keys, scale)
        if tilted is None or not self.config.tilts:
            return out
        ask = [b for b, r in enumerate(out) if r.distance > self.config.tilt_beyond]
        owners: list[tuple[int, float]] = []
        turned: list[np.ndarray] = []
        for b in ask:
            for degrees, seq in tilted(b):
                owners.append((b, float(degrees)))
                turned.append(seq)
        if not turned:
            return out
        seqs = list(sequences)
        upright = self.entry_errors([seqs[b] for b in ask]).min(axis=1)
        best = {b: (TILT_MARGIN * float(e), -1) for b, e in zip(ask, upright)}
        for j, e in enumerate(self.entry_errors(turned).min(axis=1)):
            b = owners[j][0]
            if e < best[b][0]:
                best[b] = (float(e), j)
        chosen = sorted({j for _, j in best.values() if j >= 0})
        if not chosen:
            return out
        recs = self._recognize([turned[j] for j in chosen],
                               [out[owners[j][0]].demo for j in chosen], scale)
        for j, r in zip(chosen, recs):
            out[owners[j][0]] = replace(r, tilt=owners[j][1])
        return out

    def _recognize(self, sequences: Sequence[np.ndarray], keys: Sequence[str] | None,
                   scale: float) -> list[Recognition]:
        """:meth:`recognize` of each sequence as given (no tilt search);
        ``scale``: :func:`novelty_scale` of the memory."""
        seqs = list(sequences)
        keys = list(keys) if keys is not None else [f"#{i}" for i in range(len(seqs))]
        if not seqs:
            return []
        pb_obs = self.recognize_pbs(seqs)
        errors = np.asarray(self.model.prediction_error(seqs, pb_obs), dtype=np.float64)
        pbs_rec = self.memory.pbs_rec
        dist = cdist(pb_obs, pbs_rec, "euclidean")
        labels = self.memory.concept_labels
        reproduction = self.config.familiarity == "reproduction"
        entry_errors = (self.entry_errors(seqs) if self.config.decision == "reproduction"
                        or (self.config.unknown_below > 0 and reproduction) else None)
        ranking = (entry_errors if entry_errors is not None
                   and self.config.decision == "reproduction" else dist)
        nearest, conf = confidence(ranking, labels)
        # "unknown" asks whether anything the robot knows reproduces the
        # demonstration (its best entry's error), on the scale at which one
        # known concept reproduces its neighbour (novelty_scale): the same
        # quantity on both sides. PB_obs's own error measures how well the
        # network reproduces it with a free PB, which generalises to shapes
        # it never learned.
        rep = (entry_errors.min(axis=1) if entry_errors is not None
               else np.full(len(seqs), np.nan))
        fam = familiarity(rep if entry_errors is not None and reproduction else errors, scale)
        below = self.config.unknown_below
        out = []
        for b, i in enumerate(nearest):
            e = self.memory.entries[int(i)]
            out.append(Recognition(keys[b], e.concept, float(conf[b]), float(dist[b, i]),
                                   int(i), e.source, tuple(e.sources), pb_obs[b].copy(),
                                   float(errors[b]), float(fam[b]),
                                   bool(below > 0 and fam[b] < below), float(rep[b])))
        return out


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


class Turn:
    """One demonstration's turn of the learning phase, driven one feedback at a time.

    Made by :meth:`Learner.observe` (:meth:`Agent.observe
    <iloci.agent.Agent.observe>`): PB_obs is recognized once, then the
    turn waits. :attr:`answer` is the guess to judge; :meth:`feedback`
    with +1 or -1 moves on, returning the next :class:`Answer` or, once
    the demonstration is placed, the :class:`LearnOutcome` (also kept in
    :attr:`outcome`; :attr:`answer` is then ``None``).

    Guarantees
    ----------
    * The memory changes only when the turn ends (strengthening, a new
      exemplar or a new concept), and a rehearsal's result is installed in
      one assignment of ``memory.entries`` after it has succeeded: other
      threads see the old memory or the new one. An error (a bad feedback
      value, a diverging rehearsal) leaves memory and turn as they were,
      so the same feedback can be given again.
    * A turn is bound to the memory it was observed on: if the memory
      changed since (another turn ended, a rename), :meth:`feedback`
      raises :class:`~iloci.errors.InvalidInputError`; observe the
      demonstration again. One turn at a time per memory.
    * Nothing blocks on a person: a turn holds no thread between
      feedbacks. Each call computes and returns (a rehearsal can take
      seconds: run it in a worker process with :meth:`Agent.start_worker
      <iloci.agent.Agent.start_worker>`, from asyncio with
      :meth:`afeedback`).

    Extending: the learner's reaction to each kind of feedback is one
    method (``_reward``, ``_punish``); a new kind of answer adds one.
    """

    def __init__(self, learner: Learner, demo: Demonstration, sequence: np.ndarray,
                 start: np.ndarray, dt: float, frame: TeacherFrame | None = None) -> None:
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
        self.step = mem.demonstrations_seen
        self.tried: list[str] = []
        self.feedbacks: list[int] = []
        self.events: list[InteractionEvent] = []
        self.rehearsals: list[RehearsalEvent] = []
        self.answer: Answer | None = None
        self.outcome: LearnOutcome | None = None
        self._revision = mem.revision
        learner._pending = []
        self.labels: list[str] = []
        if not mem.entries:
            # the very first demonstration: nothing to guess, a new concept
            self.pb_obs = np.zeros(learner.model.pb_size)
            self.distances = np.zeros(0)
            self._step(self._new_concept)
            return
        self.pb_obs = learner.recognize_pbs([seq])[0]
        self.distances = np.linalg.norm(mem.pbs_rec - self.pb_obs, axis=1)
        self.labels = mem.concept_labels
        # what orders the guesses: PB distance (the paper) or how well each
        # entry's PB reproduces the demonstration ([learner] decision)
        self.ranking = (learner.entry_errors([seq])[0]
                        if learner.config.decision == "reproduction" else self.distances)
        self._novel = False        # the current answer is the novelty answer
        self._confirming = False   # the current answer asks to confirm a reward after a no
        self._fam = float("nan")   # the demonstration's familiarity, once computed
        self._refused = 0          # guesses refused since the turn or a novelty answer began
        self._novelty_again = learner.config.novelty_after > 0   # the re-offer is unused
        self._confirmations = 0    # confirmations given for the current guess's reward
        self._deep = False         # the novelty answer asked again was refused too
        if learner.config.novelty_below > 0:
            fam = self._familiarity()
            if fam < learner.config.novelty_below:
                self._step(self._novelty)
                return
        self._step(self._next)

    def _familiarity(self) -> float:
        """The demonstration's familiarity (``[learner] familiarity``), computed once."""
        if np.isnan(self._fam):
            learner, seq = self.learner, self.sequence
            # is it like an entry the robot knows (reproduction), or can the
            # network reproduce it at all (prediction)
            if learner.config.familiarity == "reproduction":
                error = float(np.min(self.ranking if learner.config.decision == "reproduction"
                                     else learner.entry_errors([seq])[0]))
            else:
                error = float(np.asarray(learner.model.prediction_error(
                    [seq], self.pb_obs[None]))[0])
            self._fam = float(familiarity(error, novelty_scale(learner.model,
                                                               learner.memory)))
        return self._fam

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
                 else f"guess={self.answer.concept!r}" if self.answer is not None else "")
        return f"Turn({self.key!r}, attempt={len(self.feedbacks) + 1}, {state})"

    # -- steps -------------------------------------------------------------------
    def feedback(self, value: int) -> Answer | LearnOutcome:
        """Judge the current :attr:`answer`: +1 (right) or -1 (wrong).

        Returns
        -------
        Answer
            The next guess (after -1, while untried concepts remain).
        LearnOutcome
            The demonstration's place in the memory, with its rehearsals.

        Raises
        ------
        FeedbackError
            ``value`` is not +1 or -1; nothing changed.
        InvalidInputError
            The turn is over, or the memory changed since it was observed.
        """
        with self.learner.lock:
            return self._feedback(value)

    def _feedback(self, value: int) -> Answer | LearnOutcome:
        if self.outcome is not None or self.answer is None:
            raise InvalidInputError(f"the turn of {self.key!r} is over; observe a new "
                                    "demonstration.")
        if self.learner.memory.revision != self._revision:
            raise InvalidInputError(f"the memory changed since {self.key!r} was observed "
                                    "(another demonstration was learned, or a concept "
                                    "renamed); observe it again.")
        fb = check_feedback(value, "Turn.feedback()")
        if self._novel:
            return self._step(self._novel_yes if fb == 1 else self._novel_no)
        return self._step(self._reward if fb == 1 else self._punish)

    def _step(self, action: Callable[[], Answer | LearnOutcome]) -> Answer | LearnOutcome:
        """Run one step; observers hear of the turn's events once it is committed.

        The events of a step that fails are dropped (it changed nothing);
        those of earlier steps wait for the end of the turn, when they are
        delivered with its own (see ``Learner._deliver``; an observer's
        fault then raises :class:`~iloci.errors.ObserverError`, the
        demonstration learned).
        """
        pending = self.learner._pending
        mark = len(pending)
        try:
            result = action()
        except BaseException:
            del pending[mark:]
            raise
        if self.outcome is not None:
            self.learner._deliver(self.outcome)
        return result

    async def afeedback(self, value: int) -> Answer | LearnOutcome:
        """:meth:`feedback` from asyncio code: runs in a thread, the event loop stays free."""
        import asyncio
        return await asyncio.to_thread(self.feedback, value)

    # -- the learner's reactions ---------------------------------------------------
    def _common(self, answer: Answer, fb: int) -> tuple[dict[str, Any], dict[str, Any]]:
        nearest = self._nearest
        common = {"demo": self.key, "step": self.step, "attempt": answer.attempt,
                  "guessed": answer.concept, "tried": tuple(self.tried),
                  "answered": answer.response.source, "feedback": fb,
                  "distance": float(self.distances[answer.entry])}
        extra = {"nearest_entry": nearest, "nearest_distance": float(self.distances[nearest]),
                 "answer_entry": answer.entry}
        return common, extra

    def _novelty(self) -> Answer:
        """The novelty answer ([learner] novelty_below, novelty_after): the
        demonstration imitated back."""
        attempt = len(self.feedbacks) + 1
        response = self.learner.respond_novel(self.sequence, self.start, self.dt, attempt,
                                              self._familiarity(), self.frame)
        drawing = (response.teacher_drawing if response.teacher_drawing is not None
                   else response.drawing)
        joints = np.asarray(response.joint_path, dtype=np.float64)
        self._novel = True
        self.answer = Answer(demo=self.key, concept=response.concept, confidence=float("nan"),
                             attempt=attempt, drawing=np.asarray(drawing, dtype=np.float64),
                             joint_path=joints, dt=self.dt, start_posture=joints[0].copy(),
                             response=response, entry=-1, distance=float("nan"))
        return self.answer

    def _novel_yes(self) -> LearnOutcome:
        """"Yes, that is new": the robot founds the concept."""
        self.feedbacks.append(1)
        self._novel = False
        return self._new_concept(novel=True)

    def _novel_no(self) -> Answer | LearnOutcome:
        """"No": back to guessing among the known concepts."""
        assert self.answer is not None
        self.feedbacks.append(-1)
        self._novel = False
        self._refused = 0
        if not self._novelty_again and self.tried:
            # asked after refused guesses and refused too ([learner]
            # confirm_twice_after_novelty)
            self._deep = True
        ev = InteractionEvent(demo=self.key, step=self.step, attempt=self.answer.attempt,
                              guessed=None, tried=tuple(self.tried), answered=None,
                              feedback=-1, action="next_guess",
                              extra={"novel": True, "familiarity": self._fam})
        self.events.append(ev)
        self.learner._emit_interaction(ev)
        return self._next()

    def _punish(self) -> Answer | LearnOutcome:
        answer = self.answer
        assert answer is not None
        if self._confirming:
            # the reward was not confirmed: the first "yes" stands recorded
            # as given, the "no" that denies it is this attempt's feedback
            self._confirming = False
            self._confirmations = 0
        common, extra = self._common(answer, -1)
        ev = InteractionEvent(action="next_guess", extra=extra, **common)
        self.feedbacks.append(-1)
        self.events.append(ev)
        self.tried.append(answer.concept)
        self.learner._emit_interaction(ev)
        self._refused += 1
        if (self._novelty_again and self._refused >= self.learner.config.novelty_after
                and any(c not in self.tried for c in self.labels)):
            # [learner] novelty_after: the "no"s go against the refused
            # novelty answer (or the familiarity that kept it back): asked
            # (again) before the next guess, once per demonstration
            self._novelty_again = False
            return self._novelty()
        return self._next()

    def _reward(self) -> Answer | LearnOutcome:
        answer = self.answer
        assert answer is not None
        learner, mem = self.learner, self.learner.memory
        guess, nearest = answer.concept, self._nearest
        common, extra = self._common(answer, 1)
        if self._confirming:
            self._confirming = False
            self._confirmations += 1
        config = learner.config
        # a reward after a "no" goes against the robot's own ranking, and one
        # that makes a new exemplar widens a concept: a teacher's slip there
        # would merge two concepts, so it is kept only when the teacher
        # confirms it (asked once more; twice far down the ranking, after the
        # novelty answer asked again was refused)
        required = (2 if self._deep and config.confirm_twice_after_novelty
                    else 1 if ((config.confirm_rewards and -1 in self.feedbacks)
                               or (config.confirm_new_exemplars
                                   and self.distances[nearest] >= config.similarity_threshold))
                    else 0)
        if self._confirmations < required:
            ev = InteractionEvent(action="confirm", extra=extra, **common)
            self.feedbacks.append(1)
            self.events.append(ev)
            learner._emit_interaction(ev)
            self._confirming = True
            response = replace(answer.response, attempt=answer.attempt + 1)
            self.answer = replace(answer, attempt=answer.attempt + 1, response=response)
            return self.answer
        clustered = 0
        if self.distances[nearest] < learner.config.similarity_threshold:
            action = "strengthen"
            e = mem.entries[nearest]
            e.num_samples += 1
            e.sources = tuple(e.sources) + (self.key,)
            mem.revision += 1
        else:
            action = "new_exemplar"
            new = self._new_entry(self.pb_obs, guess)
            # a failed rehearsal leaves the memory as it was: nothing recorded yet
            rehearsed = [learner._rehearse("new_exemplar", list(mem.entries), new,
                                           self.sequence)]
            if mem.num_samples_of(guess) > learner.config.num_threshold:
                entries, clustered, cut = learner._cluster(mem.entries, guess)
                extra["d_cutoff"] = cut
                if clustered:
                    rehearsed.append(learner._rehearse("clustering", entries))
            self.rehearsals.extend(rehearsed)
        self.feedbacks.append(1)
        mem.demonstrations_seen += 1
        extra.update(concept=guess, entries=len(mem), clustered=clustered)
        ev = InteractionEvent(action=action, extra=extra, **common)
        self.events.append(ev)
        self.learner._emit_interaction(ev)
        return self._finish(guess, action, clustered)

    def _new_concept(self, novel: bool | None = None) -> LearnOutcome:
        """The demonstration founds a concept; ``novel``: after a novelty answer's "yes"
        (None for the very first demonstration, when nothing was asked)."""
        learner, mem = self.learner, self.learner.memory
        label = mem.new_concept_label()
        try:
            self.rehearsals.append(learner._rehearse(
                "new_concept", list(mem.entries), self._new_entry(self.pb_obs, label),
                self.sequence))
        except BaseException:
            mem.concept_count -= 1   # the label was not used
            raise
        mem.demonstrations_seen += 1
        extra: dict[str, Any] = {"concept": label, "entries": len(mem)}
        if novel is not None:
            extra["novel"] = novel
        ev = InteractionEvent(demo=self.key, step=self.step,
                              attempt=len(self.feedbacks) if novel else len(self.feedbacks) + 1,
                              guessed=None, tried=tuple(self.tried), answered=None,
                              feedback=1 if novel else 0, action="new_concept", extra=extra)
        self.events.append(ev)
        learner._emit_interaction(ev)
        return self._finish(label, "new_concept")

    def _finish(self, concept: str, action: str, clustered: int = 0) -> LearnOutcome:
        self.answer = None
        self.outcome = LearnOutcome(self.key, concept, action, tuple(self.feedbacks),
                                    tuple(self.events), tuple(self.rehearsals), clustered)
        return self.outcome

    def _next(self) -> Answer | LearnOutcome:
        """The guess among untried concepts, or a new concept when none is left."""
        labels, mem = self.labels, self.learner.memory
        untried = [i for i, c in enumerate(labels) if c not in self.tried]
        if not untried:
            return self._new_concept(novel=False)
        nearest = min(untried, key=lambda i: self.ranking[i])
        guess = labels[nearest]
        members = [i for i, c in enumerate(labels) if c == guess]
        performer = min(members, key=lambda i: mem.entries[i].generation_error)
        attempt = len(self.feedbacks) + 1
        response = self.learner.respond(performer, attempt, self.frame)
        others = [self.distances[i] for i in untried if labels[i] != guess]
        d = float(self.distances[nearest])
        conf = 1.0 if not others else float(np.clip(
            1.0 - d / min(others), 0.0, 1.0)) if min(others) > 0 else 0.0
        drawing = (response.teacher_drawing if response.teacher_drawing is not None
                   else response.drawing)
        joints = np.asarray(response.joint_path, dtype=np.float64)
        self._nearest = nearest
        self.answer = Answer(demo=self.key, concept=guess, confidence=conf, attempt=attempt,
                             drawing=np.asarray(drawing, dtype=np.float64), joint_path=joints,
                             dt=float(mem.entries[performer].dt),
                             start_posture=joints[0].copy(), response=response,
                             entry=performer, distance=d)
        return self.answer

    def _new_entry(self, pb: np.ndarray, label: str) -> Entry:
        seq, key = self.sequence, self.key
        return Entry(pb=pb.copy(), pb_rec=pb.copy(), num_samples=1, num_steps=len(seq),
                     initial_input=seq[0].copy(), start=self.start.copy(), dt=self.dt,
                     concept=label, generation_error=float("nan"), source=key,
                     sources=(key,),
                     pattern=(seq.copy() if self.learner.config.rehearse_from == "demonstrations"
                              else None))

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

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial.distance import cdist

from iloci.concepts import clustering, rehearsal
from iloci.concepts.memory import Entry, Memory
from iloci.config import LearnerConfig
from iloci.errors import InvalidInputError, NotFittedError
from iloci.events import InteractionEvent, RehearsalEvent
from iloci.interfaces import (Clusterer, Demonstration, PerceptualModel, Response, Simulator,
                              Teacher, check_feedback)

__all__ = ["Learner", "LearnOutcome", "Recognition", "confidence", "ik_joint_limits", "perform"]

#: Actions the learner takes on a feedback (InteractionEvent.action).
ACTIONS = ("strengthen", "new_exemplar", "next_guess", "new_concept")


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
        definition.)
    distance : float
        ``d_best``.
    entry : int
        Index of the nearest entry in ``Memory.entries`` at recognition time.
    source : str
        Key of the demonstration the nearest entry holds.
    sources : tuple of str
        Every demonstration the nearest entry stands for.
    pb_obs : ndarray, shape (P,)
    """

    demo: str
    concept: str
    confidence: float
    distance: float
    entry: int
    source: str
    sources: tuple[str, ...]
    pb_obs: np.ndarray = field(repr=False)


def perform(memory: Memory, model: PerceptualModel, index: int, *,
            joint_limits: tuple[np.ndarray, np.ndarray] | None = None,
            simulator: Simulator | None = None, attempt: int = 1) -> Response:
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

    Returns
    -------
    Response
        ``motion`` (T, 2): the regenerated sensory channels decoded into
        plane points (m); ``joint_path`` (T, J): the regenerated motor
        channels decoded (rad) and clipped to the joint limits (``T =
        numSteps + 1``); the simulator's
        :class:`~iloci.interfaces.Execution` of that joint path when one is
        given. ``extra`` holds ``entry``, ``generation_error`` and
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
    return Response(concept=entry.concept, motion=plane, joint_path=joints,
                    source=entry.source, sources=tuple(entry.sources),
                    execution=execution, attempt=attempt,
                    extra={"entry": index, "generation_error": entry.generation_error,
                           "clipped": clipped})


def ik_joint_limits(ik_solver) -> tuple[np.ndarray, np.ndarray] | None:
    """``(lower, upper)`` joint limits (rad, shape (J,) each) of an IK solver, if it has them.

    The learner clips regenerated joint paths to them before execution.
    """
    if ik_solver is None or not hasattr(ik_solver, "lower"):
        return None
    return np.asarray(ik_solver.lower), np.asarray(ik_solver.upper)


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
    """

    def __init__(self, memory: Memory, model: PerceptualModel, clusterer: Clusterer,
                 teacher: Teacher, config: LearnerConfig | None = None, *,
                 simulator: Simulator | None = None, hook: Any = None,
                 joint_limits: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        self.memory = memory
        self.model = model
        self.clusterer = clusterer
        self.teacher = teacher
        self.config = config or LearnerConfig()
        self.simulator = simulator
        self.hook = hook
        self.joint_limits = joint_limits
        # observer events of the learning step under way, sent once it is committed
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

    def _rehearse(self, reason: str, new_pattern: np.ndarray | None = None,
                  new_entry: Entry | None = None) -> RehearsalEvent:
        """Rehearse; on success append ``new_entry`` and update every entry."""
        result = rehearsal.rehearse(self.model, self.memory.entries, new_pattern,
                                    None if new_entry is None else new_entry.pb,
                                    epochs=self.rehearsal_epochs)
        if new_entry is not None:
            self.memory.entries.append(new_entry)
        rehearsal.apply(result, self.memory.entries)
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

    def respond(self, index: int, attempt: int = 1) -> Response:
        """The robot's answer: entry ``index`` performed (see :func:`perform`)."""
        return perform(self.memory, self.model, index, joint_limits=self.joint_limits,
                       simulator=self.simulator, attempt=attempt)

    # -- learning phase ------------------------------------------------------------
    def learn(self, demo: Demonstration, sequence: np.ndarray, start: np.ndarray,
              dt: float) -> LearnOutcome:
        """Learn from one demonstration with the teacher's feedback.

        Parameters
        ----------
        demo : Demonstration
            Shown to the teacher with each response.
        sequence : ndarray, shape (T - 1, D)
            Its encoded sequence.
        start : ndarray, shape (6,)
            Its absolute first sample ``[y, z, q1..q4]``.
        dt : float
            Time step (s) of its motion.

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
        self._pending = []
        try:
            outcome = self._learn(demo, sequence, start, dt)
        except BaseException:
            self._pending = []  # nothing was committed: nothing to observe
            raise
        self._deliver(outcome)
        return outcome

    def _learn(self, demo: Demonstration, sequence: np.ndarray, start: np.ndarray,
               dt: float) -> LearnOutcome:
        seq = np.asarray(sequence, dtype=np.float64)
        if seq.ndim != 2 or len(seq) < 2 or not np.all(np.isfinite(seq)):
            raise InvalidInputError(f"sequence of {demo.key!r} must be a finite (T, D) array "
                                    f"with T >= 2, got shape {seq.shape}.")
        mem = self.memory
        step = mem.demonstrations_seen
        key = demo.key
        events: list[InteractionEvent] = []
        rehearsals: list[RehearsalEvent] = []
        feedbacks: list[int] = []

        def new_entry(pb: np.ndarray, label: str) -> Entry:
            return Entry(pb=pb.copy(), pb_rec=pb.copy(), num_samples=1, num_steps=len(seq),
                         initial_input=seq[0].copy(), start=np.asarray(start, float).copy(),
                         dt=float(dt), concept=label, generation_error=float("nan"),
                         source=key, sources=(key,))

        if not mem.entries:
            label = mem.new_concept_label()
            rehearsals.append(self._rehearse("new_concept", seq,
                                             new_entry(np.zeros(self.model.pb_size), label)))
            mem.demonstrations_seen += 1
            ev = InteractionEvent(demo=key, step=step, attempt=1, guessed=None, tried=(),
                                  answered=None, feedback=0, action="new_concept",
                                  extra={"concept": label, "entries": len(mem)})
            self._emit_interaction(ev)
            return LearnOutcome(key, label, "new_concept", (), (ev,), tuple(rehearsals))

        pb_obs = self.recognize_pbs([seq])[0]
        distances = np.linalg.norm(mem.pbs_rec - pb_obs, axis=1)
        labels = mem.concept_labels
        tried: list[str] = []
        attempt = 0
        while True:
            untried = [i for i, c in enumerate(labels) if c not in tried]
            if not untried:
                label = mem.new_concept_label()
                rehearsals.append(self._rehearse("new_concept", seq, new_entry(pb_obs, label)))
                mem.demonstrations_seen += 1
                ev = InteractionEvent(demo=key, step=step, attempt=attempt + 1, guessed=None,
                                      tried=tuple(tried), answered=None, feedback=0,
                                      action="new_concept",
                                      extra={"concept": label, "entries": len(mem)})
                events.append(ev)
                self._emit_interaction(ev)
                return LearnOutcome(key, label, "new_concept", tuple(feedbacks), tuple(events),
                                    tuple(rehearsals))
            attempt += 1
            nearest = min(untried, key=lambda i: distances[i])
            guess = labels[nearest]
            members = [i for i, c in enumerate(labels) if c == guess]
            answer = min(members, key=lambda i: mem.entries[i].generation_error)
            response = self.respond(answer, attempt)
            fb = check_feedback(self.teacher.feedback(demo, response), self.teacher)
            feedbacks.append(fb)
            common: dict[str, Any] = {
                "demo": key, "step": step, "attempt": attempt, "guessed": guess,
                "tried": tuple(tried), "answered": mem.entries[answer].source, "feedback": fb,
                "distance": float(distances[answer])}
            extra: dict[str, Any] = {"nearest_entry": nearest,
                                     "nearest_distance": float(distances[nearest]),
                                     "answer_entry": answer}
            if fb == -1:
                ev = InteractionEvent(action="next_guess", extra=extra, **common)
                events.append(ev)
                self._emit_interaction(ev)
                tried.append(guess)
                continue
            clustered = 0
            if distances[nearest] < self.config.similarity_threshold:
                action = "strengthen"
                e = mem.entries[nearest]
                e.num_samples += 1
                e.sources = tuple(e.sources) + (key,)
            else:
                action = "new_exemplar"
                rehearsals.append(self._rehearse("new_exemplar", seq, new_entry(pb_obs, guess)))
                if mem.num_samples_of(guess) > self.config.num_threshold:
                    clustered, cut, ev_r = self._cluster(guess)
                    extra["d_cutoff"] = cut
                    if ev_r is not None:
                        rehearsals.append(ev_r)
            mem.demonstrations_seen += 1
            extra.update(concept=guess, entries=len(mem), clustered=clustered)
            ev = InteractionEvent(action=action, extra=extra, **common)
            events.append(ev)
            self._emit_interaction(ev)
            return LearnOutcome(key, guess, action, tuple(feedbacks), tuple(events),
                                tuple(rehearsals), clustered)

    def _cluster(self, concept: str) -> tuple[int, float, RehearsalEvent | None]:
        """Cluster ``concept``; replace valid clusters by their medoids (rehearsal)."""
        mem = self.memory
        idx = mem.indices_of(concept)
        entries = [mem.entries[i] for i in idx]
        plan = clustering.plan_clusters(
            np.array([e.pb for e in entries]), [e.num_samples for e in entries],
            [e.exemplar for e in entries], clusterer=self.clusterer,
            k_cutoff=self.config.k_cutoff, num_threshold=self.config.num_threshold)
        if not plan.valid:
            return 0, plan.d_cutoff, None
        drop: set[int] = set()
        for members, med in zip(plan.valid, plan.medoids):
            keep = entries[med]
            others = [entries[j] for j in members if j != med]
            keep.num_samples = sum(entries[j].num_samples for j in members)
            keep.sources = tuple(dict.fromkeys(
                list(keep.sources) + [s for o in others for s in o.sources]))
            keep.prototype = True
            drop.update(idx[j] for j in members if j != med)
        mem.entries = [e for i, e in enumerate(mem.entries) if i not in drop]
        return len(plan.valid), plan.d_cutoff, self._rehearse("clustering")

    # -- inference phase -------------------------------------------------------------
    def recognize(self, sequences: Sequence[np.ndarray],
                  keys: Sequence[str] | None = None) -> list[Recognition]:
        """Recognize a batch of encoded sequences (no feedback, memory unchanged).

        Parameters
        ----------
        sequences : sequence of ndarray, each (T_i, D)
        keys : sequence of str, optional
            Demonstration keys, for the results.

        Returns
        -------
        list of Recognition
        """
        seqs = list(sequences)
        keys = list(keys) if keys is not None else [f"#{i}" for i in range(len(seqs))]
        if not seqs:
            return []
        pb_obs = self.recognize_pbs(seqs)
        pbs_rec = self.memory.pbs_rec
        dist = cdist(pb_obs, pbs_rec, "euclidean")
        labels = self.memory.concept_labels
        nearest, conf = confidence(dist, labels)
        out = []
        for b, i in enumerate(nearest):
            e = self.memory.entries[int(i)]
            out.append(Recognition(keys[b], e.concept, float(conf[b]), float(dist[b, i]),
                                   int(i), e.source, tuple(e.sources), pb_obs[b].copy()))
        return out

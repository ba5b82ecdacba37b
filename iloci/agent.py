"""The Agent: assembled components plus the robot's memory; the library's face.

::

    agent = iloci.build("my.toml")
    report = agent.teach(iloci.data.load_lasa(["GShape", "Angle"]))  # with feedback
    answers = agent.recognize(test_demos)                           # batched inference
    agent.save("memory.npz")
    agent = iloci.Agent.load("memory.npz")                          # and keep teaching
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
import dataclasses
from dataclasses import dataclass
import os
from pathlib import Path
import threading
import time
from typing import TYPE_CHECKING, Any, overload
import warnings

import numpy as np
import pluggy

from iloci.concepts.memory import Memory, load_memory, save_memory
from iloci.concepts.policies import Policies
from iloci.concepts.rehearsal import regenerate
from iloci.config import Config, load_config
from iloci.controls import MemoryControls
from iloci.data.files import TrajectoryFile, trajectory_files
from iloci.errors import (ConfigError, InvalidDemonstrationError, InvalidInputError,
                          MemoryFileError, NotFittedError, NotLoadedError, ObserverError,
                          UnknownComponentError, UnreachableTargetError)
from iloci.interfaces import COMPONENT_KINDS, Demonstration, Response, unmet_members
from iloci.plugins import get_plugin_manager, get_registry
from iloci.progress import saving
from iloci.registry import Registry
from iloci.sensorimotor.encoding import SensorimotorEncoder, feature_names
from iloci.sensorimotor.frames import TeacherFrame
from iloci.sensorimotor.pipeline import Motion, tilted, to_motion
from iloci.sensorimotor.robots import get_robot, robot_and_ik
from iloci.worker import WorkerModel

if TYPE_CHECKING:  # the learner imports scipy: loaded when first used
    from iloci.concepts.learner import Answer, Learner, LearnOutcome, Recognition, Turn

__all__ = ["Agent", "build", "preload", "NotLoaded", "PURPOSES", "TeachReport",
           "SkippedDemonstrationWarning", "learn_and_recognize"]


#: What each use of a saved memory needs (:meth:`Agent.load`'s ``purpose``):
#: recognition encodes a demonstration's motion (the IK solver) and finds its
#: PB (the perceptual model); it never clusters, asks a teacher or executes.
PURPOSES: dict[str, tuple[str, ...]] = {
    "recognize": ("perceptual_model", "ik"),
    "learn": ("perceptual_model", "clusterer", "teacher", "ik", "simulator"),
}


class NotLoaded:
    """Stands in for a component :meth:`Agent.load` did not build for its purpose.

    Any use raises :class:`~iloci.errors.NotLoadedError` naming the section
    and what to do (load the memory for learning).
    """

    def __init__(self, section: str, purpose: str, path: str) -> None:
        self._section = section
        self._purpose = purpose
        self._path = path

    def __repr__(self) -> str:
        return f"NotLoaded({self._section!r})"

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        raise NotLoadedError(
            f"the {self._section} was not loaded: the memory {self._path} was loaded for "
            f"{self._purpose!r}, which does not need it. Load it with "
            f"iloci.Agent.load({self._path!r}) (purpose='learn') to keep learning.")


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


class Agent(MemoryControls):
    """A robot that learns concepts by imitation.

    Built by :func:`build` from a :class:`~iloci.config.Config`. Holds one
    instance of each configured component.

    Attributes
    ----------
    config : Config
    perceptual_model : PerceptualModel
    clusterer : Clusterer
    teacher : Teacher
    ik_solver : IKSolver
    simulator : Simulator or None
    plugin_manager : pluggy.PluginManager
        Observer hooks (``iloci_on_*``) are called through it.
    memory : Memory
        The robot's Mem (entries, encoder); the network is
        ``perceptual_model``. Empty until the first :meth:`learn`.
    """

    def __init__(self, config: Config, components: dict[str, Any],
                 plugin_manager: pluggy.PluginManager, registry: Registry) -> None:
        self.config = config
        self.plugin_manager = plugin_manager
        self.registry = registry
        self.perceptual_model = components["perceptual_model"]
        self.clusterer = components["clusterer"]
        self.teacher = components["teacher"]
        self.ik_solver = components["ik"]
        self.simulator = components.get("simulator")
        #: The arm (:class:`~iloci.sensorimotor.robots.Robot`): joints, frames, plane.
        self.robot = components.get("robot") or getattr(self.ik_solver, "robot", None) \
            or get_robot()
        self.memory = Memory()
        #: A :class:`~iloci.sensorimotor.pipeline.MotionCache` :meth:`motion`
        #: looks demonstrations up in (None: convert each time). Set it only
        #: to a cache filled under this agent's sensorimotor settings, robot
        #: and IK solver (an evaluation shares one between the folds a
        #: process runs).
        self.motion_cache: Any = None
        #: Called with each RehearsalProgress (see Learner); None for none.
        self.on_progress: Callable[[Any], None] | None = None
        self._worker: Any = None
        # the turn of the last observe(): Agent.feedback judges its answers
        self._turn: Any = None
        # one learning step at a time (threads, asyncio.to_thread)
        self._lock = threading.RLock()

    def __repr__(self) -> str:

        attribute = {"ik": "ik_solver"}
        parts = []
        for sec in COMPONENT_KINDS:
            obj = getattr(self, attribute.get(sec, sec))
            name = getattr(self.config, sec).name
            if sec in self.config._supplied:  # an object the caller passed: say which
                parts.append(f"{sec}={'None' if obj is None else type(obj).__name__ + '(...)'}")
            else:
                parts.append(f"{sec}={name!r}")
        return f"Agent({', '.join(parts)}, entries={len(self.memory)})"

    # -- plumbing ------------------------------------------------------------------
    @property
    def learner(self) -> Learner:
        """A :class:`~iloci.concepts.learner.Learner` over this agent's memory and components.

        Built on each access, so it always sees the current ``teacher``,
        ``simulator`` and ``memory`` attributes.
        """
        from iloci.concepts.learner import Learner, ik_joint_limits
        return Learner(self.memory, self.perceptual_model, self.clusterer, self.teacher,
                       self.config.learner, simulator=self.simulator,
                       hook=self.plugin_manager.hook,
                       joint_limits=ik_joint_limits(self.ik_solver),
                       on_progress=self._report_progress, lock=self._lock)

    def _report_progress(self, progress: Any) -> None:
        # looked up at each report, so a callback set after observe() applies to that turn
        callback = self.on_progress
        if callback is not None:
            callback(progress)

    def motion(self, demo: Demonstration) -> Motion:
        """The demonstration as the robot performs it (preprocessing + IK).

        Returns
        -------
        Motion
        """
        if not isinstance(demo, Demonstration):
            raise InvalidInputError(f"expected a Demonstration, got {type(demo).__name__}; "
                                    "wrap an (N, 2) array with iloci.Demonstration(positions).")

        def convert(d: Demonstration) -> Motion:
            return to_motion(d, self.config.sensorimotor, self.ik_solver, robot=self.robot)

        return convert(demo) if self.motion_cache is None else \
            self.motion_cache.get(demo, convert)

    def fit_encoder(self, motions: Iterable[Any]) -> None:
        """Fit the sensorimotor encoding scales on learning data (once, before learning).

        :meth:`teach` calls this with its whole stream, :meth:`learn` with
        its one demonstration, when the memory has no encoder yet. The
        scales are then kept for good (they are part of the memory), since
        every stored pattern is expressed in them.
        """
        if self.memory.encoder is not None:
            raise InvalidInputError("the memory's encoder is already fitted; its scales are "
                                    "fixed once learning has started.")
        self.memory.encoder = SensorimotorEncoder().fit(list(motions))

    def _encode(self, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
        if self.memory.encoder is None:
            raise NotFittedError("the robot has learned nothing yet: teach it at least one "
                                 "demonstration (Agent.learn / `iloci teach`) first.")
        return self.memory.encoder.encode(motion)

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
        """
        if motion is None:
            motion = self.motion(demo)
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
            from iloci.errors import StaleAnswerError
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
        from iloci.concepts.learner import run_turn
        return run_turn(self.teacher, demo, lambda: self.observe(demo, motion))

    def teach(self, demos: Iterable[Any], *,
              on_change: Callable[[Any], None] | None = None) -> TeachReport:
        """Learn from a stream of demonstrations, one at a time, with feedback.

        Parameters
        ----------
        demos : iterable
            Each a :class:`~iloci.interfaces.Demonstration`, a path to a
            ``.npy`` / ``.csv`` trajectory, or an (N, 2) array. Files of
            one name in different folders get distinct keys (``circle/0``,
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
        ObserverError
            An observer hook raised. The demonstration it observed is
            learned and ``on_change`` was called with its outcome (so a
            saving callback saved it); the stream stops there.
        """
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

    # -- inference phase -------------------------------------------------------------
    @overload
    def recognize(self, demos: Demonstration) -> Recognition: ...

    @overload
    def recognize(self, demos: Sequence[Demonstration]) -> list[Recognition]: ...

    def recognize(self, demos: Demonstration | Sequence[Demonstration]
                  ) -> Recognition | list[Recognition]:
        """Recognize demonstrations without feedback (batched; memory unchanged).

        Parameters
        ----------
        demos : Demonstration or sequence of Demonstration

        Returns
        -------
        Recognition or list of Recognition
            One per demonstration (a single one for a single demonstration):
            concept, confidence (see
            :class:`~iloci.concepts.learner.Recognition`), nearest entry.

        Raises
        ------
        NotFittedError
            Nothing has been learned yet.
        InvalidDemonstrationError, UnreachableTargetError
            A demonstration cannot be preprocessed (the error names it).
        """
        single = isinstance(demos, Demonstration)
        items: list[Demonstration] = ([demos] if isinstance(demos, Demonstration)
                                      else list(demos))
        if not self.memory.entries:
            raise NotFittedError("the robot has learned nothing yet: teach it at least one "
                                 "demonstration (Agent.learn / `iloci teach`) before "
                                 "recognizing.")
        motions = [self.motion(d) for d in items]
        seqs = [self._encode(m)[0] for m in motions]
        with self._lock:
            out = self.learner.recognize(seqs, [d.key for d in items],
                                         tilted=self.tilted_readings(motions))
        return out[0] if single else out

    def tilted_readings(self, motions: Sequence[Any]
                        ) -> Callable[[int], list[tuple[float, np.ndarray]]]:
        """The tilt search's readings of ``motions`` (``[learner] tilts``) for recognition.

        Returns
        -------
        callable
            ``f(b)``: ``(degrees, sequence)`` for each angle ``a`` of
            ``tilts``, ``+a`` then ``-a``: motion ``b``'s pen path turned
            by it (:func:`~iloci.sensorimotor.pipeline.tilted`, IK solved
            again) and encoded. A turned path the arm cannot reach is left
            out.
        """

        tilts = Policies.of(self.config.learner).inference.tilts   # [learner] read once, there
        angles = [s * float(a) for a in tilts for s in (1.0, -1.0)]

        def readings(b: int) -> list[tuple[float, np.ndarray]]:
            out = []
            for a in angles:
                try:
                    motion = tilted(motions[b], a, self.ik_solver, self.robot)
                except UnreachableTargetError:
                    continue
                out.append((a, self._encode(motion)[0]))
            return out

        return readings

    def entry_drawings(self, entries: Sequence[Any] | None = None) -> list[np.ndarray]:
        """Memory entries regenerated by the network, as pen paths in the drawing plane.

        Parameters
        ----------
        entries : sequence of Entry, optional
            Default: every entry of the memory.

        Returns
        -------
        list of ndarray, each (T_i + 1, 2)
            Pen positions (m), from :func:`~iloci.concepts.rehearsal.regenerate`
            decoded by the memory's encoder; empty before the first demonstration.
        """
        mem = self.memory
        entries = list(mem.entries if entries is None else entries)
        if not entries or mem.encoder is None:
            return []
        seqs = regenerate(self.perceptual_model, entries)
        return [mem.encoder.decode(s, e.start)[0] for s, e in zip(seqs, entries)]

    def respond(self, concept: str) -> Response:
        """Perform ``concept``: its entry of lowest generation error, as a Response.

        See :func:`~iloci.concepts.learner.perform`; executed on the
        configured simulator, if any.
        """
        from iloci.concepts.learner import ik_joint_limits, perform
        return perform(self.memory, self.perceptual_model, self.memory.performer_of(concept),
                       joint_limits=ik_joint_limits(self.ik_solver), simulator=self.simulator)

    def rename(self, concept: str, name: str) -> None:
        """Name one of the robot's concepts (``"c3"`` -> ``"circle"``); see ``Memory.rename``.

        Save the memory to keep the name: it is stored with the entries, so
        every command, report and recognition uses it.
        """
        with self._lock:
            self.memory.rename(concept, name)

    # -- worker process ------------------------------------------------------------
    def start_worker(self) -> Agent:
        """Run the network's computations in a worker process from now on.

        Recognition, generation and every rehearsal then run in one
        process of their own (:class:`~iloci.worker.WorkerModel`): the
        calling thread waits on a pipe without holding the GIL, so the rest
        of the embedding program (a control loop, an asyncio server) keeps
        its timing while the robot learns. Results are identical to
        in-process ones (the worker holds the same network). Preprocessing
        and IK stay in the caller. Idempotent; returns the agent.

        The perceptual model must pickle (both first-party back ends do).
        Stop it with :meth:`close` (or use the agent as a context manager);
        the worker's network is copied back first.
        """
        with self._lock:
            if self._worker is None:
                self._worker = WorkerModel(self.perceptual_model)
                self._local_model = self.perceptual_model
                self.perceptual_model = self._worker
        return self

    def close(self) -> None:
        """Stop the worker process, if any, keeping its network (idempotent)."""
        with self._lock:
            worker, self._worker = self._worker, None
            if worker is None:
                return
            try:
                self._local_model.load_state(worker.state())
            finally:
                self.perceptual_model = self._local_model
                worker.close()

    def __enter__(self) -> Agent:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- persistence --------------------------------------------------------------------
    def save(self, path: str | os.PathLike[str], *,
             extra: dict[str, Any] | None = None) -> Path:
        """Save the memory, the network and the config to one ``.npz`` file, atomically.

        See :mod:`iloci.concepts.memory` for the format. ``extra``: more
        JSON-able header values (``iloci teach`` keeps its progress through
        a stream there). Returns the path (a symlink's target is written
        through, the link kept).

        Raises
        ------
        MemoryLockedError
            Another process (``iloci serve``, ``iloci teach``) holds the
            memory's lock (:func:`iloci.progress.memory_lock`); nothing is
            written.
        OSError
            The file cannot be written (disk full, permissions); the file
            on disk is the previous one, untouched.
        """
        with self._lock, saving(path):
            return save_memory(path, self.memory, self.perceptual_model.state(),
                               extra={**dict(extra or {}), "config": self.config.to_dict(),
                                      "robot": _robot_record(self.robot),
                                      "needs": self.needs()})

    def needs(self) -> dict[str, dict[str, dict[str, str | None]]]:
        """What each use of this agent's memory needs: purpose -> section -> component.

        ``{"recognize": {...}, "learn": {...}}``; each component as
        ``{"name": ..., "distribution": ...}`` (the distribution that
        registered it, None for an object passed to :func:`build`).
        :meth:`save` records it in the memory file, and :meth:`load` with
        ``purpose="recognize"`` builds only the sections listed there (see
        :data:`PURPOSES`).
        """
        out: dict[str, dict[str, dict[str, str | None]]] = {}
        for purpose, sections in PURPOSES.items():
            out[purpose] = {}
            for sec in sections:
                name = getattr(self.config, sec).name
                if name == "none":
                    continue
                dist = None
                if sec not in self.config._supplied and (sec, name) in self.registry:
                    dist = self.registry.get(sec, name).distribution
                out[purpose][sec] = {"name": name, "distribution": dist}
        return out

    @classmethod
    def load(cls, path: str | os.PathLike[str], config: Any = None, *,
             plugin_manager: pluggy.PluginManager | None = None, purpose: str = "learn",
             **overrides: Any) -> Agent:
        """An agent with a saved memory, ready to recognize and to keep learning.

        Parameters
        ----------
        path : path-like
            A file written by :meth:`save`.
        config : Config, path, mapping, optional
            Config to build the components from; by default the one saved
            with the memory. Its perceptual model must have the saved
            network's sizes.
        plugin_manager : pluggy.PluginManager, optional
        purpose : {"learn", "recognize"}
            ``"learn"`` (default) builds every configured component.
            ``"recognize"`` builds only what recognition needs, as the memory
            file records it (:meth:`needs`; by default the perceptual model
            and the IK solver, :data:`PURPOSES`): the teaching-only
            components (clusterer, teacher) are not built, so their plugins
            need not be installed, and there is no simulator
            (:meth:`respond` is then not executed). Using the clusterer or
            the teacher raises :class:`~iloci.errors.NotLoadedError`, which
            says to load for learning.
        **overrides
            Component instances, as for :func:`build`.

        Raises
        ------
        InvalidInputError
            ``purpose`` is neither ``"learn"`` nor ``"recognize"``.
        MemoryFileError
            Missing, truncated, tampered with or written by a newer iloci.
        MemoryConfigError
            ``config`` changes a setting the memory's entries depend on
            (see :func:`~iloci.config.memory_conflicts`), such as
            ``[sensorimotor] steps`` or the network's sizes.
        """
        if purpose not in PURPOSES:
            raise InvalidInputError(f"purpose must be one of {', '.join(map(repr, PURPOSES))}, "
                                    f"got {purpose!r}.")
        memory, net_state, header = load_memory(path)
        saved = header.get("config")
        own_config = config is None
        if config is None:
            config = saved
            if not isinstance(config, dict):
                raise MemoryFileError(f"{path} holds no config; pass config= to load it.")
            config = _upgrade_config(config)
        if purpose != "learn":
            needed = set(PURPOSES[purpose])
            recorded = (header.get("needs") or {}).get(purpose)
            if isinstance(recorded, dict):
                needed = set(recorded) | {"perceptual_model", "ik"}
            for sec in PURPOSES["learn"]:
                if sec not in needed and sec not in overrides:
                    # recognition executes nothing: no simulator (respond() is not executed)
                    overrides[sec] = (None if sec == "simulator"
                                      else NotLoaded(sec, purpose, str(path)))
        try:
            agent = build(config, plugin_manager=plugin_manager, **overrides)
        except (ConfigError, UnknownComponentError) as exc:
            from iloci._version import __version__, is_newer
            written = header.get("iloci")
            if own_config and is_newer(written):
                raise MemoryFileError(
                    f"{path} was written by iloci {written}, this is iloci {__version__}: "
                    f"upgrade iloci (and its plugins) to {written} or later to load it; its "
                    f"saved config holds what this version does not know ({exc}). The file "
                    "is unchanged.") from None
            raise
        saved_robot = header.get("robot") or {
            "name": "nao-v32-right-arm",
            "joints": list(agent.robot.joint_names) if agent.robot.name == "nao-v32-right-arm"
            else []}
        _check_same_robot(path, saved_robot, agent.robot, memory)
        if isinstance(saved, dict) and config is not saved:
            from iloci.config import memory_conflicts
            from iloci.errors import MemoryConfigError
            conflicts = memory_conflicts(saved, agent.config)
            if conflicts:
                raise MemoryConfigError(str(path), conflicts, source=agent.config.source)
        if net_state:
            try:
                agent.perceptual_model.load_state(net_state)
            except (ValueError, KeyError, InvalidInputError) as exc:
                raise MemoryFileError(f"the network saved in {path} does not fit the "
                                      f"configured perceptual model: {exc}") from None
        agent.memory = memory
        return agent


def preload(config: Any = None, *, plugin_manager: pluggy.PluginManager | None = None
            ) -> tuple[str, ...]:
    """Import the configured components' back ends now, building nothing.

    ``import iloci`` imports no back end; :func:`build` imports the
    configured ones (torch, pinocchio, ...), and a native library's import
    holds the GIL for its whole loading (torch: 0.3 to 1 s), stalling every
    other thread of the process. A program with a control loop calls this
    before the loop starts, so that building and loading later, in any
    thread, imports nothing heavy (see docs/embedding.md, "Keeping a control
    loop on time").

    Parameters
    ----------
    config, plugin_manager
        As for :func:`build`.

    Returns
    -------
    tuple of str
        ``"section=name"`` of each component whose back end was imported.

    Raises
    ------
    ConfigError, UnknownComponentError, MissingBackendError
        As :func:`build`.
    """
    pm = plugin_manager or get_plugin_manager()
    registry = get_registry(pm)
    cfg = load_config(config, registry=registry)
    done = []
    for sec in COMPONENT_KINDS:
        name = getattr(cfg, sec).name
        if name == "none":
            continue
        registry.load_factory(registry.get(sec, name))
        done.append(f"{sec}={name}")
    return tuple(done)


def build(config: Any = None, *, plugin_manager: pluggy.PluginManager | None = None,
          **overrides: Any) -> Agent:
    """Assemble an :class:`Agent` from a config.

    Parameters
    ----------
    config : Config, path, mapping or None
        Anything :func:`~iloci.config.load_config` takes; ``None`` for the
        defaults (the paper's settings).
    plugin_manager : pluggy.PluginManager, optional
        Defaults to :func:`~iloci.plugins.get_plugin_manager`. Component
        names are resolved through its plugins.
    **overrides
        Component instances to use instead of building them from the config,
        by section name (``teacher=my_teacher``, ``ik=my_solver``): how an
        embedding robot stack plugs in its own objects. The configured name
        of a section given this way is never looked up, so it need not be
        registered nor its back end installed; the section is kept in
        ``agent.config`` as written, its other keys unvalidated. Each object
        must have the members of its protocol in :mod:`iloci.interfaces`.
        ``simulator=None`` leaves the simulator out.

    Raises
    ------
    InvalidInputError
        An override is not an instance with its protocol's members (one
        error naming every such override and what it lacks), or is ``None``
        for a component other than the simulator.
    ConfigError, UnknownComponentError
        Invalid config, or an unknown override name (before anything heavy
        is imported).
    MissingBackendError
        A configured back end, of a component not given as an object, is
        not installed (names the pip command).
    """
    unknown = set(overrides) - set(COMPONENT_KINDS)
    if unknown:
        raise ConfigError(f"build() got unknown component override(s) {sorted(unknown)}; "
                          f"valid: {', '.join(COMPONENT_KINDS)}.")
    _check_overrides({sec: obj for sec, obj in overrides.items()
                      if not isinstance(obj, NotLoaded)})
    pm = plugin_manager or get_plugin_manager()
    registry = get_registry(pm)
    cfg = load_config(config, registry=registry, supplied=overrides)

    def make(sec: str, robot: Any) -> Any:
        cc = getattr(cfg, sec)
        if cc.name == "none":
            return None
        # the robot goes to the components that draw with it
        extra = {"robot": robot} if sec in ("ik", "simulator") else {}
        return registry.build(sec, cc.name, cc.params, seed=cfg.seed,
                              **extra)

    def sized(robot: Any) -> None:  # before the plane search: fails fast
        nonlocal cfg
        cfg = size_network(cfg, robot, overrides)

    robot, ik = robot_and_ik(cfg.robot, lambda r: make("ik", r), plugin_manager=pm,
                             ik=overrides.get("ik"), before_placing=sized)
    components: dict[str, Any] = {}
    for sec in COMPONENT_KINDS:
        if sec in overrides:
            components[sec] = overrides[sec]
        elif sec == "ik":
            components[sec] = ik
        else:
            components[sec] = make(sec, robot)
    components["robot"] = robot
    return Agent(cfg, components, pm, registry)


def size_network(cfg: Config, robot: Any, overrides: Mapping[str, Any] | None = None
                 ) -> Config:
    """The config with the perceptual model's ``input_size`` set to the robot's 2 + J.

    Parameters
    ----------
    cfg : Config
    robot : Robot
    overrides : mapping, optional
        Component objects given to :func:`build`; a given perceptual model
        must take 2 + J inputs.

    Raises
    ------
    ConfigError
        ``[perceptual_model] input_size`` is set and is not the robot's
        2 + J features per step (:func:`~iloci.sensorimotor.encoding.feature_names`).
    InvalidInputError
        A given perceptual model takes another number of inputs.
    """
    overrides = overrides or {}
    names = feature_names(len(robot.joint_names))
    width = len(names)
    if "perceptual_model" in overrides:
        got = getattr(overrides["perceptual_model"], "input_size", width)
        if got != width:
            raise InvalidInputError(
                f"the perceptual model given to build() takes {got} inputs; robot "
                f"{robot.name!r} needs 2 + {len(robot.joint_names)} = {width}.")
        return cfg
    params = cfg.perceptual_model.params
    if params is None or not hasattr(params, "input_size") or params.input_size == width:
        return cfg
    default = next((f.default for f in dataclasses.fields(params)
                    if f.name == "input_size"), None)
    if params.input_size != default:
        raise ConfigError(
            f"perceptual_model.input_size is {params.input_size}, but robot {robot.name!r} "
            f"gives every encoded demonstration {width} features per step "
            f"({', '.join(names)}): set it to {width} or leave it out (it is sized "
            "from the robot).", source=cfg.source, key="perceptual_model.input_size")
    sized = dataclasses.replace(params, input_size=width)
    return dataclasses.replace(
        cfg, perceptual_model=dataclasses.replace(cfg.perceptual_model, params=sized))


def _robot_record(robot: Any) -> dict[str, Any]:
    """What a memory file records of its robot (JSON)."""
    return {"name": robot.name, "joints": list(robot.joint_names),
            "tip_frame": robot.end_effector_frame, "base_frame": robot.base_frame,
            "urdf": str(robot.urdf_path)}


def _upgrade_config(config: dict[str, Any]) -> dict[str, Any]:
    """A saved config from before the ``[robot]`` section: its robot moves there."""
    sm = config.get("sensorimotor")
    if isinstance(sm, dict) and "robot" in sm:
        config = {**config, "sensorimotor": {k: v for k, v in sm.items() if k != "robot"}}
        config.setdefault("robot", {"name": sm["robot"]})
        for sec in ("ik", "simulator"):
            if isinstance(config.get(sec), dict) and "robot" in config[sec]:
                config[sec] = {k: v for k, v in config[sec].items() if k != "robot"}
    return config


def _check_same_robot(path: Any, saved: dict[str, Any], robot: Any, memory: Any) -> None:
    """Refuse a memory learned by another robot (its patterns hold that robot's joints)."""
    joints = list(saved.get("joints") or [])
    width = 2 + len(robot.joint_names)
    enc = memory.encoder
    enc_width = None if enc is None or enc.scale_ is None else len(enc.scale_)
    if (joints and joints != list(robot.joint_names)) or \
            (enc_width is not None and enc_width != width):
        n_saved = len(joints) if joints else (enc_width or 2) - 2
        raise MemoryFileError(
            f"{path} was learned by robot {saved.get('name')!r} with {n_saved} joints "
            f"({', '.join(joints) or 'unnamed'}); the configured robot {robot.name!r} has "
            f"{len(robot.joint_names)} ({', '.join(robot.joint_names)}). A memory's patterns "
            "are that robot's joint motions: load it with its own robot (leave out config= "
            "or use the [robot] it was saved with), or teach the new robot afresh.")


def _check_overrides(overrides: dict[str, Any]) -> None:
    """Raise one InvalidInputError for every override that is not a component."""
    problems = []
    for sec, obj in overrides.items():
        kind = COMPONENT_KINDS[sec]
        protocol = kind.protocol
        where = f"iloci.interfaces.{protocol.__name__}"
        label = kind.label
        a_label = ("an " if label[0].lower() in "aeiou" else "a ") + label
        if obj is None:
            if not kind.optional:
                problems.append(f"{sec}=None: {a_label} is required (only simulator=None "
                                "is allowed)")
        elif isinstance(obj, type):
            problems.append(f"{sec}={obj.__name__} is a class; pass an instance, "
                            f"{obj.__name__}(...), implementing {where}")
        else:
            unmet = unmet_members(obj, protocol)
            if unmet:
                problems.append(f"{sec}={type(obj).__name__}(...) is not {a_label}: it lacks "
                                f"{', '.join(unmet)} (see {where})")
    if problems:
        raise InvalidInputError("build() got component object(s) it cannot use: "
                                + "; ".join(problems) + ".")


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
        from iloci.data import load_trajectory
        return load_trajectory(item)
    try:
        return Demonstration(np.asarray(item, dtype=np.float64), shape="stream", index=i)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InvalidInputError):
            raise
        raise InvalidDemonstrationError(f"stream item {i} is not a Demonstration, a "
                                        f"trajectory file or an (N, 2) array ({exc}).") from None


def learn_and_recognize(config: Any, learn: Iterable[Demonstration],
                        test: Sequence[Demonstration], *,
                        plugin_manager: pluggy.PluginManager | None = None,
                        **overrides: Any) -> tuple[Agent, TeachReport, list[Any]]:
    """One learning phase then one batched inference phase, on a fresh agent.

    What an evaluation fold does: build an agent from ``config``, teach it
    ``learn`` in order with the configured teacher, then recognize ``test``.

    Returns
    -------
    agent : Agent
    report : TeachReport
    recognitions : list of Recognition
        One per test demonstration, in order.
    """
    agent = build(config, plugin_manager=plugin_manager, **overrides)
    report = agent.teach(learn)
    return agent, report, (agent.recognize(list(test)) if len(test) else [])

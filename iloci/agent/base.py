"""What every face of the :class:`~iloci.agent.Agent` shares: its components, memory and lock.

:class:`AgentBase` holds the assembled components (see
:mod:`iloci.agent.assembly`), the robot's memory, the learning lock and the
plumbing every phase uses: a demonstration as the robot performs it
(:meth:`~AgentBase.motion`) and encoded in the memory's scales, and the
:class:`~iloci.concepts.learner.Learner` over all of it. The phases are the
other modules of :mod:`iloci.agent`: :mod:`~iloci.agent.stepwise` (the
learning phase, step by step and with a teacher), :mod:`~iloci.agent.inference`
(recognition, performing), :mod:`~iloci.agent.worker_process` (the network in
a process of its own), :mod:`~iloci.agent.persistence` (save, load).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
import threading
from typing import TYPE_CHECKING, Any

import numpy as np
import pluggy

from iloci.concepts.memory import Memory
from iloci.concepts.perform import ik_joint_limits
from iloci.config import Config
from iloci.errors import InvalidInputError, NotFittedError, ProgressCallbackWarning
from iloci.interfaces import COMPONENT_KINDS, Demonstration
from iloci.registry import Registry
from iloci.sensorimotor.encoding import SensorimotorEncoder
from iloci.sensorimotor.pipeline import Motion, to_motion
from iloci.sensorimotor.robots import get_robot

if TYPE_CHECKING:  # the learner imports scipy: loaded when first used
    from iloci.concepts.learner import Learner

__all__ = ["AgentBase"]


class AgentBase:
    """The components, memory and lock of an agent, and the plumbing its phases share.

    See :class:`~iloci.agent.Agent` for the attributes.
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
        #: Called with each RehearsalProgress (see Learner); None for none. If it
        #: raises, a ProgressCallbackWarning is issued and learning goes on.
        self.on_progress: Callable[[Any], None] | None = None
        self._worker: Any = None
        # the in-process network while a worker process holds the model
        self._local_model: Any = None
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
        # the learner imports scipy: loaded when first used, so `import iloci` stays light
        from iloci.concepts.learner import Learner
        return Learner(self.memory, self.perceptual_model, self.clusterer, self.teacher,
                       self.config.learner, simulator=self.simulator,
                       hook=self.plugin_manager.hook,
                       joint_limits=ik_joint_limits(self.ik_solver),
                       on_progress=self._report_progress, lock=self._lock,
                       current_memory=lambda: self.memory)

    def _report_progress(self, progress: Any) -> None:
        # looked up at each report, so a callback set after observe() applies to that turn
        # a callback that raises (a display's bug) loses its report, not the learning
        callback = self.on_progress
        if callback is not None:
            try:
                callback(progress)
            except Exception as exc:
                import warnings

                warnings.warn(ProgressCallbackWarning(
                    f"agent.on_progress raised {type(exc).__name__}: {exc} (at the "
                    f"{getattr(progress, 'phase', '?')!r} phase); the report was dropped and the "
                    "rehearsal goes on."), stacklevel=2)

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

    def rename(self, concept: str, name: str) -> None:
        """Name one of the robot's concepts (``"c3"`` -> ``"circle"``); see ``Memory.rename``.

        Save the memory to keep the name: it is stored with the entries, so
        every command, report and recognition uses it.
        """
        with self._lock:
            self.memory.rename(concept, name)


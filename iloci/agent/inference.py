"""The agent's inference phase: recognition without feedback, drawings, performing a concept.

Batched and read-only on the memory (:meth:`~Inference.recognize`, the tilt
search's readings, :meth:`~Inference.entry_drawings`), and
:meth:`~Inference.respond`: a concept performed on the configured
simulator, if any (the arm executor of a real robot is a simulator too, see
:class:`iloci.sensorimotor.hardware.ArmExecutor`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any, overload

import numpy as np

from iloci.agent.base import AgentBase
from iloci.concepts.entry import Entry
from iloci.concepts.inference import Recognition
from iloci.concepts.perform import ik_joint_limits, perform
from iloci.concepts.policies import Policies
from iloci.concepts.rehearsal import regenerate
from iloci.errors import InvalidInputError, NotFittedError, UnreachableTargetError
from iloci.interfaces import Demonstration, Response
from iloci.sensorimotor.pipeline import tilted

__all__ = ["Inference"]


class Inference(AgentBase):
    """The inference phase of :class:`~iloci.agent.Agent` (see the module)."""

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
        InvalidInputError
            ``demos`` is not a Demonstration or a sequence of them.
        NotFittedError
            Nothing has been learned yet.
        InvalidDemonstrationError, UnreachableTargetError
            A demonstration cannot be preprocessed (the error names it).
        """
        single = isinstance(demos, Demonstration)
        if not single and (isinstance(demos, (str, bytes, np.ndarray))
                           or not isinstance(demos, Iterable)):
            raise InvalidInputError(f"recognize takes a Demonstration or a sequence of them, "
                                    f"got {type(demos).__name__} (wrap positions as "
                                    "iloci.Demonstration(positions, times)).")
        items: list[Demonstration] = ([demos] if isinstance(demos, Demonstration)
                                      else list(demos))
        wrong = [type(d).__name__ for d in items if not isinstance(d, Demonstration)]
        if wrong:
            raise InvalidInputError(f"recognize takes Demonstrations, got {wrong[0]} among "
                                    "them (wrap positions as iloci.Demonstration(positions, "
                                    "times)).")
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
        wrong = [type(e).__name__ for e in entries if not isinstance(e, Entry)]
        if wrong:
            raise InvalidInputError(f"entry_drawings takes memory entries (agent.memory."
                                    f"entries, or some of them), got {wrong[0]}.")
        if not entries or mem.encoder is None:
            return []
        seqs = regenerate(self.perceptual_model, entries)
        return [mem.encoder.decode(s, e.start)[0] for s, e in zip(seqs, entries)]

    def respond(self, concept: str) -> Response:
        """Perform ``concept``: its entry of lowest generation error, as a Response.

        See :func:`~iloci.concepts.learner.perform`; executed on the
        configured simulator, if any.
        """
        return perform(self.memory, self.perceptual_model, self.memory.performer_of(concept),
                       joint_limits=ik_joint_limits(self.ik_solver), simulator=self.simulator)

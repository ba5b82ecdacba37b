"""The learner's public face: all a turn of the learning phase may use of its learner.

:class:`~iloci.concepts.turn.Turn` is written against this protocol, not
against :class:`~iloci.concepts.learner.Learner` itself, so the turn
depends on the learner's public methods only (and the import graph has no
circle: the learner makes turns, a turn does not import the learner).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from typing import Any, Protocol

import numpy as np

from iloci.concepts.answers import LearnOutcome
from iloci.concepts.memory import Entry, Memory
from iloci.concepts.policies import Policies
from iloci.events import InteractionEvent, RehearsalEvent
from iloci.interfaces import PerceptualModel, Response
from iloci.sensorimotor.frames import TeacherFrame

__all__ = ["LearnerFace"]


class LearnerFace(Protocol):
    """What :class:`~iloci.concepts.learner.Learner` offers a turn (see its docstrings)."""

    memory: Memory
    model: PerceptualModel
    policies: Policies
    lock: Any
    current_memory: Callable[[], Memory]

    def recognize_pbs(self, sequences: Sequence[np.ndarray]) -> np.ndarray: ...

    def entry_errors(self, sequences: Sequence[np.ndarray]) -> np.ndarray: ...

    def regeneration_distances(self, sequences: Sequence[np.ndarray],
                               patterns: Sequence[np.ndarray] | None = None
                               ) -> np.ndarray: ...

    def familiarity_scale(self, patterns: Sequence[np.ndarray] | None = None) -> float: ...

    def familiarities(self, sequences: Sequence[np.ndarray], scale: float, *,
                      patterns: Sequence[np.ndarray] | None = None,
                      regeneration: np.ndarray | None = None,
                      reproduction: np.ndarray | None = None,
                      pb_obs: np.ndarray | None = None) -> np.ndarray: ...

    def respond(self, index: int, attempt: int = 1,
                frame: TeacherFrame | None = None) -> Response: ...

    def respond_novel(self, sequence: np.ndarray, start: np.ndarray, dt: float,
                      attempt: int = 1, fam: float = float("nan"),
                      frame: TeacherFrame | None = None) -> Response: ...

    def rehearse(self, reason: str, entries: list[Entry], new_entry: Entry | None = None,
                 new_pattern: np.ndarray | None = None) -> RehearsalEvent: ...

    def cluster(self, concept: str) -> tuple[list[Entry], int, float]: ...

    def emit(self, event: InteractionEvent) -> None: ...

    def discard_events(self) -> None: ...

    def uncommitted(self) -> AbstractContextManager[None]: ...

    def deliver(self, outcome: LearnOutcome) -> None: ...

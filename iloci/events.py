"""Events passed to the observer hooks (see :mod:`iloci.hookspecs`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["InteractionEvent", "RehearsalEvent", "FoldEvent"]


@dataclass(frozen=True)
class InteractionEvent:
    """One teacher feedback in the learning phase.

    Attributes
    ----------
    demo : str
        Key of the demonstration shown (``"SHAPE/INDEX"``).
    step : int
        Index of the demonstration in the learning stream (0-based).
    attempt : int
        1 for the first guess on this demonstration, 2 for the next, ...
    guessed : str or None
        Concept guessed (``None`` when the memory held no untried concept).
    tried : tuple of str
        Concepts tried before this guess for this demonstration.
    answered : str or None
        Key of the memory entry whose motion was performed.
    feedback : int
        +1 or -1 (0 when no feedback was asked: a new concept was created).
    action : str
        What the learner did: ``"strengthen"``, ``"new_exemplar"``,
        ``"next_guess"``, ``"new_concept"``, or ``"confirm"`` (a reward
        asked once more: after a "no" with ``[learner] confirm_rewards``,
        one that would make a new exemplar with ``confirm_new_exemplars``;
        twice after the novelty answer asked again was refused, with
        ``confirm_twice_after_novelty``). ``extra["novel"]`` is true for
        the novelty answer (asked first, or again after refused guesses
        with ``novelty_after``).
    distance : float
        PB distance between the demonstration and the answering entry.
    """

    demo: str
    step: int
    attempt: int
    guessed: str | None
    tried: tuple[str, ...]
    answered: str | None
    feedback: int
    action: str
    distance: float = float("nan")
    extra: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class RehearsalEvent:
    """One memory rehearsal.

    Attributes
    ----------
    entries : int
        Memory entries trained on (consolidated ones plus the new pattern).
    epochs : int
    loss : float
        Final training loss.
    seconds : float
        Wall time of the whole rehearsal.
    reason : str
        ``"new_exemplar"``, ``"new_concept"`` or ``"clustering"``.
    """

    entries: int
    epochs: int
    loss: float
    seconds: float
    reason: str = ""
    extra: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class FoldEvent:
    """One finished evaluation fold.

    Attributes
    ----------
    fold : int
        Fold index (0-based).
    metrics : mapping
        The fold's metrics (``ccr``, ``interactions``, ``wall_seconds``, ...).
    """

    fold: int
    metrics: Mapping[str, Any] = field(default_factory=dict)

"""What a fold of the evaluation gives: one typed row per answer, one record per fold.

A fold (:mod:`iloci.evaluation.fold`) answers each test demonstration once:
an :class:`Answer` (frozen) holds everything about that answer. A
:class:`FoldResult` (frozen) holds the fold's answers and what the learning
phase left: its feedbacks, the memory's counts, the baseline's time, the
figures' details. ``folds.json`` keeps its layout (one list per answer field,
:meth:`FoldResult.to_dict`), so older outputs and tools still read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, NamedTuple

from iloci.evaluation.metrics import correct_classification_rate

__all__ = ["Answer", "Evaluation", "FOLD_KEYS", "FoldResult", "memory_counts"]


@dataclass(frozen=True)
class Answer:
    """One test demonstration of a fold, answered.

    Attributes
    ----------
    key : str
        The demonstration (``"SHAPE/INDEX"``).
    true_concept : str
        Its true concept (:class:`~iloci.data.concepts.GroundTruth`).
    taught : bool
        Was its true concept in the fold's learning set.
    predicted : str
        The true concept naming the answer's robot concept (the true concept
        of most of the demonstrations that robot concept stands for:
        :func:`~iloci.data.concepts.majority_names`); ``"unknown"`` when
        recognition answered "I don't know"; the robot's own label when its
        concept has no true name (never correct).
    robot_predicted : str
        The robot's own label.
    matched_predicted : str
        Scored with one-to-one naming of robot concepts
        (:func:`~iloci.evaluation.metrics.matched_names`).
    source_predicted : str
        True concept of the answering entry's own source demonstration.
    confidence : float
        Recognition confidence, in [0, 1].
    distance, error, reproduction_error : float
        PB distance to the nearest PB_rec; prediction error from PB_obs;
        lowest prediction error from a memory entry's PB (NaN when not
        computed, see :attr:`~iloci.concepts.learner.Recognition.reproduction_error`).
    familiarity : float
    unknown : bool
        Recognition's familiarity and whether it answered "unknown".
    baseline_predicted : str or None
        The answer of DTW 1-NN on normalised paths, the strongest baseline
        (None when it did not run).
    """

    key: str
    true_concept: str
    taught: bool
    predicted: str
    robot_predicted: str
    matched_predicted: str
    source_predicted: str
    confidence: float
    distance: float
    error: float
    reproduction_error: float
    familiarity: float
    unknown: bool
    baseline_predicted: str | None = None


#: The keys of a fold's entry of ``folds.json``, in order (:meth:`FoldResult.to_dict`).
FOLD_KEYS: tuple[str, ...] = (
    "fold", "learn", "test", "true_concepts", "predicted", "confidence", "ccr", "feedbacks",
    "first_guess", "interactions_per_demo", "exemplars", "prototypes", "entries", "concepts",
    "generation_error", "rehearsals", "rehearsal_seconds", "wall_seconds", "skipped",
    "robot_predicted", "matched_predicted", "ccr_matched", "source_predicted", "ccr_source",
    "purity", "named_concepts", "taught", "distance", "error", "reproduction_error",
    "familiarity", "unknown", "memory_other_distance", "memory_generation_error",
    "baseline_predicted", "baseline_ccr", "baseline_seconds", "baselines", "pb_points",
    "pb_concepts",
    "pb_kinds", "shapes", "robustness")

@dataclass(frozen=True)
class FoldResult:
    """Everything one fold produced; :meth:`to_dict` is its entry of ``folds.json``.

    Attributes
    ----------
    fold : int
    learn : list of str
        Keys of the learning demonstrations, in presentation order.
    answers : tuple of Answer
        One per test demonstration, in test order. The per-answer lists of
        ``folds.json`` (``test``, ``predicted``, ``confidence``...) are
        properties reading them.
    feedbacks : list of int
        Every teacher feedback (+1/-1) of the learning phase, in order.
    first_guess : list of bool
        Per learning demonstration: was the first guess rewarded.
    interactions_per_demo : float
    exemplars, prototypes, entries, concepts : int
        Of the final memory, as :func:`memory_counts` counts them.
    generation_error : float
        Mean generation error of the memory's entries.
    rehearsals : int
    rehearsal_seconds, wall_seconds : float
        Wall time of the rehearsals; of the fold's learning (building the
        agent, teaching) plus the recognition of its test set, which a
        parallel evaluation runs as a task of its own (waiting between the
        two not counted).
    skipped : list of [str, str]
        (demonstration, reason) of each learning demonstration skipped.
    purity : float
        Concept purity of the memory (:func:`~iloci.evaluation.metrics.purity`).
    named_concepts : int
        Distinct true concepts among the memory's robot concepts.
    memory_other_distance, memory_generation_error : list of float
        Per memory entry: PB_rec distance to the nearest entry of another
        concept; generation error (the memory's own scales).
    baseline_seconds : float
        Wall time of DTW 1-NN on normalised paths (the strongest baseline,
        whose answers are each answer's ``baseline_predicted``) on the fold
        (NaN when not run).
    baselines : dict
        Every baseline of :mod:`iloci.evaluation.baselines` on the same
        fold: name -> ``{"predicted", "ccr", "seconds"}`` (empty when not
        run).
    pb_points, pb_concepts, pb_kinds : lists
        Memory PB_rec with the true concept of each entry's robot concept
        and its kind (``"exemplar"``/``"prototype"``), then each test
        PB_obs (kind ``"test"``), for the PB-space figure.
    shapes : dict of str to list
        One drawing per true concept, (T, 2) as nested lists (m).
    robustness : dict
        Perturbation name -> ``{"predicted", "ccr", "baseline_predicted",
        "baseline_ccr", "baselines", "seconds"}``
        (:func:`~iloci.evaluation.robustness.robustness_suite`; empty unless
        asked).
    """

    fold: int
    learn: list[str]
    answers: tuple[Answer, ...]
    feedbacks: list[int]
    first_guess: list[bool]
    interactions_per_demo: float
    exemplars: int
    prototypes: int
    entries: int
    concepts: int
    generation_error: float
    rehearsals: int
    rehearsal_seconds: float
    wall_seconds: float
    skipped: list[list[str]] = field(default_factory=list)
    purity: float = float("nan")
    named_concepts: int = 0
    memory_other_distance: list[float] = field(default_factory=list)
    memory_generation_error: list[float] = field(default_factory=list)
    baseline_seconds: float = float("nan")
    baselines: dict[str, dict[str, Any]] = field(default_factory=dict)
    pb_points: list[list[float]] = field(default_factory=list)
    pb_concepts: list[str] = field(default_factory=list)
    pb_kinds: list[str] = field(default_factory=list)
    shapes: dict[str, list[list[float]]] = field(default_factory=dict)
    robustness: dict[str, dict[str, Any]] = field(default_factory=dict)

    # the per-answer lists of folds.json, read from the answers
    @property
    def test(self) -> list[str]:
        """Keys of the test demonstrations."""
        return [a.key for a in self.answers]

    @property
    def true_concepts(self) -> list[str]:
        return [a.true_concept for a in self.answers]

    @property
    def taught(self) -> list[bool]:
        return [a.taught for a in self.answers]

    @property
    def predicted(self) -> list[str]:
        return [a.predicted for a in self.answers]

    @property
    def robot_predicted(self) -> list[str]:
        return [a.robot_predicted for a in self.answers]

    @property
    def matched_predicted(self) -> list[str]:
        return [a.matched_predicted for a in self.answers]

    @property
    def source_predicted(self) -> list[str]:
        return [a.source_predicted for a in self.answers]

    @property
    def confidence(self) -> list[float]:
        return [a.confidence for a in self.answers]

    @property
    def distance(self) -> list[float]:
        return [a.distance for a in self.answers]

    @property
    def error(self) -> list[float]:
        return [a.error for a in self.answers]

    @property
    def reproduction_error(self) -> list[float]:
        return [a.reproduction_error for a in self.answers]

    @property
    def familiarity(self) -> list[float]:
        return [a.familiarity for a in self.answers]

    @property
    def unknown(self) -> list[bool]:
        return [a.unknown for a in self.answers]

    @property
    def baseline_ran(self) -> bool:
        """Did the baselines run on this fold."""
        return not math.isnan(self.baseline_seconds)

    @property
    def baseline_predicted(self) -> list[str]:
        """The baseline's answers (empty when it did not run)."""
        if not self.baseline_ran:
            return []
        return [str(a.baseline_predicted) for a in self.answers]

    @property
    def ccr(self) -> float:
        """Correct classification rate on the test set, in [0, 1] (NaN: no test set)."""
        return correct_classification_rate(self.true_concepts, self.predicted)

    @property
    def ccr_matched(self) -> float:
        return correct_classification_rate(self.true_concepts, self.matched_predicted)

    @property
    def ccr_source(self) -> float:
        return correct_classification_rate(self.true_concepts, self.source_predicted)

    @property
    def baseline_ccr(self) -> float:
        """The baseline's CCR on the same test set (NaN when it did not run)."""
        if not self.baseline_ran:
            return float("nan")
        return correct_classification_rate(self.true_concepts, self.baseline_predicted)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able dict: this fold's entry of ``folds.json``, keys :data:`FOLD_KEYS`."""
        return {k: _plain(getattr(self, k)) for k in FOLD_KEYS}


def _plain(x: Any) -> Any:
    return list(x) if isinstance(x, tuple) else x


class Evaluation(NamedTuple):
    """What :func:`~iloci.evaluation.evaluate.evaluate` returns: ``metrics, folds = evaluate(...)``.

    Attributes
    ----------
    metrics : dict
        The content of ``metrics.json`` (see :func:`~iloci.evaluation.summary.summarize`).
    folds : list of FoldResult
        One per fold run, in fold order.
    """

    metrics: dict[str, Any]
    folds: list[FoldResult]


def memory_counts(memory: Any) -> dict[str, int]:
    """Entries, exemplars, prototypes and concepts of a memory.

    The one count every output uses (``metrics.json``, ``report.md``,
    :meth:`~iloci.concepts.memory.Memory.summary`): see
    :class:`~iloci.concepts.memory.Memory` for what an exemplar and a
    prototype are.
    """
    return {"entries": memory.n_entries, "exemplars": memory.n_exemplars,
            "prototypes": memory.n_prototypes, "concepts": len(memory.concepts())}

"""The five folds of the paper's evaluation, made exact (docs/method.md, "Evaluation protocol").

Each shape's demonstrations are shuffled (seeded) and dealt into ``folds``
partitions; in fold ``k`` partition ``k`` is the learning set and the rest is
the test set. LASA has 7 demonstrations per shape and 5 folds, so each
shape puts 2 demonstrations in two partitions and 1 in the others; which
partitions get the second one rotates from shape to shape, so every fold
learns from about a fifth of the data (36 or 37 of the 182 demonstrations)
instead of two folds learning from 52 and three from 26.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from iloci.config import Config
from iloci.data.concepts import GroundTruth
from iloci.data.datasets import writer_folds
from iloci.errors import InvalidInputError
from iloci.interfaces import Demonstration
from iloci.validation import is_integer

__all__ = ["fold_memory_name", "fold_plan", "lasa_folds", "untaught_concepts"]


def lasa_folds(demos: Sequence[Demonstration], folds: int = 5, seed: int = 0
               ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Split demonstrations into learning and test sets, per shape.

    Parameters
    ----------
    demos : sequence of Demonstration
        E.g. ``iloci.data.load_lasa()``; grouped by ``demo.shape``.
    folds : int
        Number of partitions (and folds), ``>= 2``.
    seed : int
        Seeds the shuffle; the same seed gives the same folds.

    Returns
    -------
    list of (learn_idx, test_idx)
        One pair per fold; sorted int arrays of indices into ``demos``. The
        learning sets partition ``range(len(demos))``; each test set is the
        complement of its learning set.

    Raises
    ------
    InvalidInputError
        No demonstrations, ``folds < 2``, or a shape with fewer
        demonstrations than folds (some fold would not learn it).
    """
    if not is_integer(folds) or folds < 2:
        raise InvalidInputError(f"folds must be an integer >= 2, got {folds!r}.")
    if not is_integer(seed):
        raise InvalidInputError(f"seed must be an integer, got {seed!r}.")
    demos = list(demos)
    if not demos:
        raise InvalidInputError("lasa_folds needs at least one demonstration.")
    by_shape: dict[str, list[int]] = {}
    for i, d in enumerate(demos):
        if not isinstance(d, Demonstration):
            raise InvalidInputError(f"demos[{i}] is a {type(d).__name__}, not a "
                                    "Demonstration.")
        by_shape.setdefault(d.shape, []).append(i)
    rng = np.random.default_rng(np.random.SeedSequence(int(seed)))
    partition = np.empty(len(demos), dtype=int)
    for j, (shape, idx) in enumerate(by_shape.items()):
        n = len(idx)
        if n < folds:
            raise InvalidInputError(
                f"shape {shape!r} has {n} demonstration(s), fewer than the {folds} folds; "
                "use fewer folds or more demonstrations of it.")
        q, r = divmod(n, folds)
        sizes = np.full(folds, q)
        sizes[[(j * r + i) % folds for i in range(r)]] += 1
        order = np.asarray(idx)[rng.permutation(n)]
        partition[order] = np.repeat(np.arange(folds), sizes)
    out = []
    for k in range(folds):
        learn = np.flatnonzero(partition == k)
        test = np.flatnonzero(partition != k)
        out.append((learn, test))
    return out


def untaught_concepts(demos: Sequence[Demonstration], config: Config, fold: int) -> list[str]:
    """The concepts left out of fold ``fold``'s learning set (``[evaluation] untaught``).

    The sorted true concepts are shuffled once per seed and fold ``k``
    leaves out the ``untaught`` concepts after the first ``k * untaught``
    (cyclically), so 5 folds of 4 leave out 20 different concepts.

    Raises
    ------
    InvalidInputError
        ``untaught`` leaves fewer than two concepts to learn.
    """
    n = config.evaluation.untaught
    if not n:
        return []
    truth = GroundTruth()
    concepts = sorted({truth.of(d) for d in demos})
    if n > len(concepts) - 2:
        raise InvalidInputError(f"[evaluation] untaught = {n} leaves fewer than 2 of the "
                                f"{len(concepts)} concepts to learn; use at most "
                                f"{len(concepts) - 2}.")
    order = list(np.random.default_rng([config.evaluation.seed, 2]).permutation(concepts))
    return [str(order[(fold * n + i) % len(order)]) for i in range(n)]


def fold_plan(demos: Sequence[Demonstration], config: Config,
              samples: Sequence[Any] | None = None) -> list[tuple[list[int], list[int]]]:
    """(learning indices in presentation order, test indices) per fold.

    The split is ``[evaluation] split``: ``"concepts"`` (:func:`lasa_folds`,
    by ``demo.shape``) or ``"writers"``
    (:func:`~iloci.data.datasets.writer_folds` over ``samples``, the data
    set's :class:`~iloci.data.datasets.Sample` of each demonstration). With
    ``[evaluation] untaught``, the learning demonstrations of each fold's
    :func:`untaught_concepts` move to the end of its test set.

    Raises
    ------
    InvalidInputError
        ``split = "writers"`` without ``samples`` (LASA names no writers),
        or what the split function raises.
    """
    ev = config.evaluation
    truth = GroundTruth()
    if ev.split == "writers":
        if samples is None:
            raise InvalidInputError(
                "[evaluation] split = 'writers' needs a data set that names writers "
                "([data] path, or iloci evaluate --data PATH); LASA names none.")
        split = writer_folds(samples, ev.folds, ev.seed)
    else:
        split = lasa_folds(demos, ev.folds, ev.seed)
    plan = []
    for k, (learn, test) in enumerate(split):
        # presentation order: seeded per fold, independent of the split's draws
        rng = np.random.default_rng([ev.seed, k, 1])
        order = [int(i) for i in rng.permutation(learn)]
        if ev.order == "blocked":
            # concept by concept, in the order each concept first appears in
            # the shuffled stream (so concepts and their members stay seeded)
            concepts = list(dict.fromkeys(truth.of(demos[i]) for i in order))
            order = [i for c in concepts for i in order if truth.of(demos[i]) == c]
        test_idx = [int(i) for i in test]
        left_out = set(untaught_concepts(demos, config, k))
        if left_out:
            out = [i for i in order if truth.of(demos[i]) in left_out]
            order = [i for i in order if i not in set(out)]
            test_idx += sorted(out)
        plan.append((order, test_idx))
    return plan


def fold_memory_name(fold: int) -> str:
    """File name of fold ``fold``'s saved agent in ``--memories`` (``fold-K.npz``)."""
    return f"fold-{fold}.npz"

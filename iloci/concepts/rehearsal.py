"""Memory rehearsal: consolidate a new pattern without forgetting the old ones.

All patterns share the network's weights, so training on a new pattern alone
would damage the others (memory interference). Rehearsal, as the paper
describes it:

1. regenerate every consolidated entry closed-loop from its PB and
   initialInfo for numSteps steps, into a *temporal memory* (the robot keeps
   no raw demonstration, only what its network can reproduce);
2. add the new pattern, if any;
3. train the network on the whole temporal memory, starting from the
   current weights and the stored PBs;
4. recompute, for every pattern, its PB (from training), PB_rec
   (recognized from the pattern with the weights frozen, multi-start from
   the learned PBs) and generationError (closed-loop mean squared error of
   regenerating the pattern from its new PB).

The temporal memory is then released.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
import inspect
import time
import warnings

import numpy as np

from iloci.concepts.memory import Entry
from iloci.interfaces import PerceptualModel

__all__ = ["RehearsalProgress", "RehearsalResult", "regenerate", "rehearse", "apply",
           "takes_learning_rate"]

#: The phases of a rehearsal, in order (:attr:`RehearsalProgress.phase`).
PHASES = ("regenerate", "train", "recognize", "evaluate", "done")


@dataclass(frozen=True)
class RehearsalProgress:
    """A rehearsal entering one of its phases (passed to a ``progress`` callback).

    Attributes
    ----------
    reason : str
        Why it rehearses: ``"new_exemplar"``, ``"new_concept"`` or
        ``"clustering"``.
    phase : str
        One of :data:`PHASES`: regenerating the temporal memory, training
        the network (nearly all the time), recognizing PB_rec, measuring
        generationErrors, ``"done"``.
    patterns : int
        Patterns in the temporal memory.
    epochs : int or None
        Training epochs (``None``: the model's configured number).
    elapsed : float
        Seconds since the rehearsal started.
    fraction : float
        Of the phases done, in [0, 1] (the training phase counts for 0.9);
        the back ends report no progress inside a phase.
    """

    reason: str
    phase: str
    patterns: int
    epochs: int | None
    elapsed: float
    fraction: float


@dataclass(frozen=True)
class RehearsalResult:
    """What one rehearsal produced, one row per pattern of the temporal memory.

    The rows are the consolidated entries in order, then the new pattern.

    Attributes
    ----------
    patterns : list of ndarray, each (T_i, D)
        The temporal memory the network was trained on.
    pbs : ndarray, shape (M, P)
        Learned PBs.
    pbs_rec : ndarray, shape (M, P)
        Recognized PBs.
    generation_errors : ndarray, shape (M,)
    loss : float
        Final training loss: the model's ``train_loss_`` when it reports
        one, else the mean generation error.
    epochs : int or None
        Epochs trained (``None``: the model's configured number).
    seconds : float
        Wall time of the whole rehearsal.
    """

    patterns: list[np.ndarray]
    pbs: np.ndarray
    pbs_rec: np.ndarray
    generation_errors: np.ndarray
    loss: float
    epochs: int | None
    seconds: float


def regenerate(model: PerceptualModel, entries: Sequence[Entry]) -> list[np.ndarray]:
    """Each entry's pattern, generated closed-loop from its PB and initialInfo.

    An entry that keeps its demonstration (:attr:`Entry.pattern`,
    ``[learner] rehearse_from = "demonstrations"``) gives that pattern
    instead: regenerated patterns carry each training's residual error into
    the next rehearsal, so over a learning phase an early entry's pattern
    drifts away from what was shown (on LASA, by as much as two different
    shapes differ).

    Parameters
    ----------
    model : PerceptualModel
    entries : sequence of Entry

    Returns
    -------
    list of ndarray, each (numSteps_i, D)
    """
    if not entries:
        return []
    out: list[np.ndarray | None] = [None if e.pattern is None else
                                    np.asarray(e.pattern, dtype=np.float64) for e in entries]
    todo = [i for i, p in enumerate(out) if p is None]
    if todo:
        pbs = np.array([entries[i].pb for i in todo], dtype=np.float64)
        first = np.array([entries[i].initial_input for i in todo], dtype=np.float64)
        made = model.generate(pbs, first, [entries[i].num_steps for i in todo])
        for i, s in zip(todo, made):
            out[i] = np.asarray(s, dtype=np.float64)
    return [p for p in out if p is not None]


def takes_learning_rate(model: PerceptualModel) -> bool:
    """Whether ``model.train`` takes a keyword ``learning_rate`` (or ``**kwargs``).

    The keyword is optional in :class:`~iloci.interfaces.PerceptualModel`:
    a third-party model that reuses :class:`iloci.params.RNNPBParams` (and
    so has a ``rehearsal_learning_rate``) may still define ``train`` with
    the three arguments alone. A signature Python cannot read counts as
    taking it.
    """
    try:
        parameters = inspect.signature(model.train).parameters.values()
    except (TypeError, ValueError):
        return True
    return any(p.name == "learning_rate" and p.kind is not p.POSITIONAL_ONLY
               or p.kind is p.VAR_KEYWORD for p in parameters)


def rehearse(model: PerceptualModel, entries: Sequence[Entry],
             new_pattern: np.ndarray | None = None, new_pb: np.ndarray | None = None, *,
             epochs: int | None = None, learning_rate: float | None = None,
             reason: str = "",
             progress: Callable[[RehearsalProgress], None] | None = None) -> RehearsalResult:
    """Rehearse the memory, optionally consolidating one new pattern.

    The model's weights change; ``entries`` are not modified (apply the
    result with :func:`apply`).

    Parameters
    ----------
    model : PerceptualModel
    entries : sequence of Entry
        The consolidated entries, regenerated into the temporal memory.
    new_pattern : ndarray, shape (T, D), optional
        The new demonstration's encoded sequence.
    new_pb : ndarray, shape (P,), optional
        Starting PB of the new pattern (e.g. its PB_obs); zeros by default.
    epochs : int, optional
        Training epochs; the model's configured number when ``None``.
    learning_rate : float, optional
        The weights' learning rate of this training, passed to the model's
        ``train`` (RNNPB back ends: in place of ``params.learning_rate``,
        for this call only); ``None``: the model's own, and ``train`` is
        called without it (a model that takes no such argument).
    reason : str
        Passed on in the progress reports.
    progress : callable, optional
        Called with a :class:`RehearsalProgress` as each phase starts and
        when the rehearsal is done, in the calling thread.

    Returns
    -------
    RehearsalResult
    """
    t0 = time.perf_counter()
    size = len(entries) + (new_pattern is not None)
    done = {"regenerate": 0.0, "train": 0.02, "recognize": 0.92, "evaluate": 0.97, "done": 1.0}

    def report(phase: str) -> None:
        if progress is not None:
            progress(RehearsalProgress(reason, phase, size, epochs,
                                       time.perf_counter() - t0, done[phase]))

    report("regenerate")
    patterns = regenerate(model, entries)
    pb_init = [np.asarray(e.pb, dtype=np.float64) for e in entries]
    if new_pattern is not None:
        patterns.append(np.asarray(new_pattern, dtype=np.float64))
        pb_init.append(np.zeros(model.pb_size) if new_pb is None
                       else np.asarray(new_pb, dtype=np.float64))
    if not patterns:
        raise ValueError("rehearsal needs at least one entry or a new pattern")
    report("train")
    if learning_rate is not None and not takes_learning_rate(model):
        warnings.warn(
            f"{type(model).__name__}.train takes no learning_rate: this rehearsal trains at "
            f"the model's own learning rate, not at {learning_rate:g} "
            "([perceptual_model] rehearsal_learning_rate). To honour that setting, give "
            "train a keyword argument learning_rate (iloci.interfaces.PerceptualModel.train).",
            RuntimeWarning, stacklevel=2)
        learning_rate = None
    if learning_rate is None:
        trained = model.train(patterns, np.array(pb_init), epochs)
    else:
        trained = model.train(patterns, np.array(pb_init), epochs,  # type: ignore[call-arg]
                              learning_rate=learning_rate)
    pbs = np.asarray(trained, dtype=np.float64)
    report("recognize")
    # recognition restarts from the learned PBs, so each pattern's PB_rec is
    # found in the basin its own PB lies in rather than from zero
    pbs_rec = np.asarray(model.recognize(patterns, candidate_pbs=pbs), dtype=np.float64)
    report("evaluate")
    errors = np.asarray(model.prediction_error(patterns, pbs), dtype=np.float64)
    loss = float(getattr(model, "train_loss_", float("nan")))
    if not np.isfinite(loss):
        loss = float(errors.mean())
    if epochs is None:
        # report what the model actually ran when it says (RNNPB back ends do)
        epochs = getattr(getattr(model, "params", None), "epochs", None)
    result = RehearsalResult(patterns, pbs, pbs_rec, errors, loss, epochs,
                             time.perf_counter() - t0)
    report("done")
    return result


def apply(result: RehearsalResult, entries: Sequence[Entry]) -> None:
    """Write a rehearsal's PB, PB_rec and generationError into the entries, in order."""
    for i, e in enumerate(entries):
        e.pb = result.pbs[i].copy()
        e.pb_rec = result.pbs_rec[i].copy()
        e.generation_error = float(result.generation_errors[i])

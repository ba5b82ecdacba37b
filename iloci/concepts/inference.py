"""The inference phase's arithmetic: the answer for a demonstration and how sure it is.

Recognition (:meth:`Learner.recognize <iloci.concepts.learner.Learner.recognize>`)
takes PB_obs of each demonstration against every PB_rec; the nearest entry's
concept is the answer (the paper's inference phase), with the margin
:func:`confidence` and the :func:`familiarity` on the memory's own
:func:`novelty_scale` (the project's calibration; the paper has none).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from iloci.concepts import rehearsal
from iloci.concepts.memory import Memory
from iloci.interfaces import PerceptualModel

__all__ = ["Recognition", "TILT_MARGIN", "confidence", "familiarity", "novelty_scale"]

#: A turned reading of the tilt search (``[learner] tilts``) is recognized
#: only when its entry prediction error is below this fraction of the
#: upright reading's, so the drawing as drawn wins near ties (measured on
#: LASA's folds: docs/guide.md, "How a drawing is read").
TILT_MARGIN = 0.9


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

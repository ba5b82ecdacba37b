"""The inference phase on a memory: PB_obs, regeneration, familiarity, recognition.

:class:`Recognizer` is the base of :class:`~iloci.concepts.learner.Learner`:
the part of the learner that answers without feedback and leaves the memory
unchanged (the paper's inference phase, Sec. 3.3: PB_obs of each
demonstration against every PB_rec; with ``[learner] decision`` the
network's regenerated patterns or its reproduction of the drawing decide
instead, see :mod:`iloci.concepts.inference` and docs/method.md).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
from scipy.spatial.distance import cdist

from iloci.concepts.inference import (TILT_MARGIN, Recognition, confidence, familiarity,
                                      novelty_scale, path_distances, path_scale,
                                      pattern_distances, regenerated_patterns,
                                      regeneration_scale)
from iloci.concepts.memory import Memory
from iloci.concepts.policies import Policies
from iloci.errors import NotFittedError
from iloci.interfaces import PerceptualModel

__all__ = ["Recognizer"]


class Recognizer:
    """Recognition on :attr:`memory` by :attr:`model` under :attr:`policies`.

    The inference phase's methods of :class:`~iloci.concepts.learner.Learner`
    (its base class), which sets the three attributes.

    Attributes
    ----------
    memory : Memory
    model : PerceptualModel
        The memory's TrajectoryNet.
    policies : Policies
        The ``[learner]`` options, read once.
    """

    memory: Memory
    model: PerceptualModel
    policies: Policies


    def recognize_pbs(self, sequences: Sequence[np.ndarray]) -> np.ndarray:
        """PB_obs of each sequence, multi-start from the stored PBs, shape (B, P)."""
        if not self.memory.entries:
            raise NotFittedError("the robot has learned nothing yet: teach it at least one "
                                 "demonstration (Agent.learn / `iloci teach`) before "
                                 "recognizing.")
        return np.asarray(self.model.recognize(list(sequences), candidate_pbs=self.memory.pbs),
                          dtype=np.float64).reshape(len(sequences), -1)

    def entry_errors(self, sequences: Sequence[np.ndarray]) -> np.ndarray:
        """How well each entry's PB reproduces each sequence, shape (B, M).

        The closed-loop prediction error (mean squared, encoded units) of
        sequence ``b`` generated from entry ``m``'s PB, starting from the
        sequence's own first step: ``[learner] decision = "reproduction"``
        answers with the entry of lowest error (one batched call of the
        model's ``prediction_error`` over every pair).
        """
        seqs = list(sequences)
        pbs = self.memory.pbs
        m = len(pbs)
        pairs = [s for s in seqs for _ in range(m)]
        errors = np.asarray(self.model.prediction_error(pairs, np.tile(pbs, (len(seqs), 1))),
                            dtype=np.float64)
        return errors.reshape(len(seqs), m)

    def regeneration_distances(self, sequences: Sequence[np.ndarray],
                               patterns: Sequence[np.ndarray] | None = None) -> np.ndarray:
        """How far each sequence lies from each entry's regenerated pattern, shape (B, M).

        :func:`~iloci.concepts.inference.pattern_distances` (with ``[learner]
        warp`` and ``compare``) of the sequences to the memory's
        :func:`~iloci.concepts.inference.regenerated_patterns` (``patterns``
        when given, e.g. computed once for several calls): ``[learner]
        decision = "regeneration"`` answers with the entry of the lowest one.
        """
        pats = regenerated_patterns(self.model, self.memory) if patterns is None else patterns
        return pattern_distances(sequences, pats, self.policies.warp, self.policies.compare)

    def tilt_scores(self, sequences: Sequence[np.ndarray],
                    patterns: Sequence[np.ndarray] | None = None) -> np.ndarray:
        """Per sequence, how well the memory reproduces it: the tilt search's criterion.

        The best over entries of the quantity ``[learner] decision`` ranks
        by (regeneration distance, else the entry prediction error), shape (B,);
        ``patterns``: the memory's regenerated patterns, when already computed.
        """
        if self.policies.rank_by_regeneration:
            return self.regeneration_distances(sequences, patterns).min(axis=1)
        return self.entry_errors(sequences).min(axis=1)

    def ranking_scale(self, patterns: Sequence[np.ndarray] | None = None) -> float:
        """The memory's own scale of :meth:`tilt_scores`' quantity: how far its concepts lie apart.

        :func:`~iloci.concepts.inference.regeneration_scale` (with ``[learner]
        warp`` and ``compare``) when the decision ranks by regeneration, else
        :func:`~iloci.concepts.inference.novelty_scale` (entry prediction
        errors): for each entry, the distance from its regenerated pattern to
        the nearest entry of another concept, the median over entries.
        ``[learner] tilt_gate = "ranking"`` searches the tilts of a drawing
        whose :meth:`tilt_scores` lies beyond it. NaN (nothing searched)
        with fewer than two concepts.
        """
        policies = self.policies
        if policies.rank_by_regeneration:
            pats = regenerated_patterns(self.model, self.memory) if patterns is None else patterns
            return regeneration_scale(pats, self.memory.concept_labels, policies.warp,
                                      policies.compare)
        return novelty_scale(self.model, self.memory)

    # -- inference phase -------------------------------------------------------------
    def recognize(self, sequences: Sequence[np.ndarray],
                  keys: Sequence[str] | None = None, *,
                  tilted: Callable[[int], Sequence[tuple[float, np.ndarray]]] | None = None
                  ) -> list[Recognition]:
        """Recognize a batch of encoded sequences (no feedback, memory unchanged).

        Parameters
        ----------
        sequences : sequence of ndarray, each (T_i, D)
        keys : sequence of str, optional
            Demonstration keys, for the results.
        tilted : callable, optional
            The tilt search (``[learner] tilts``, ``tilt_gate``):
            ``tilted(b)`` gives ``(degrees, sequence)`` pairs, sequence
            ``b`` turned by each angle of ``tilts`` and encoded
            (:meth:`Agent.recognize <iloci.agent.Agent.recognize>` turns the
            pen path with :func:`~iloci.sensorimotor.pipeline.tilted`). It
            is called only for the sequences whose :meth:`tilt_scores`
            lies beyond :meth:`ranking_scale` (``tilt_gate = "ranking"``)
            or whose PB_obs lies further than ``tilt_beyond`` from every
            PB_rec (``"pb_distance"``); of a sequence's readings, the one
            with the lowest :meth:`tilt_scores` (the best over the memory's
            entries of what the decision ranks by) is recognized, a turned
            one only when that is below :data:`TILT_MARGIN` times the
            upright reading's.

        Returns
        -------
        list of Recognition
            With ``tilt``, the angle of the reading recognized.
        """
        # the memory's calibration, once for the readings as drawn and turned
        policies = self.policies
        patterns = (regenerated_patterns(self.model, self.memory)
                    if policies.rank_by_regeneration or policies.familiar_by_regeneration
                    or policies.familiar_by_path else None)
        scale = self.familiarity_scale(patterns)
        out = self._recognize(sequences, keys, scale, patterns)
        if tilted is None or not self.policies.inference.tilts:
            return out
        seqs = list(sequences)
        inference = self.policies.inference
        if inference.tilt_gate == "ranking":
            # gate, choice of reading and answer on one measure: the ranking's
            scores = self.tilt_scores(seqs, patterns)
            beyond = self.ranking_scale(patterns)
            ask = [b for b in range(len(seqs)) if np.isfinite(beyond) and scores[b] > beyond]
            upright = scores[ask]
        else:
            ask = [b for b, r in enumerate(out) if r.distance > inference.tilt_beyond]
            upright = None
        owners: list[tuple[int, float]] = []
        turned: list[np.ndarray] = []
        for b in ask:
            for degrees, seq in tilted(b):
                owners.append((b, float(degrees)))
                turned.append(seq)
        if not turned:
            return out
        if upright is None:
            upright = self.tilt_scores([seqs[b] for b in ask], patterns)
        best = {b: (TILT_MARGIN * float(e), -1) for b, e in zip(ask, upright)}
        for j, e in enumerate(self.tilt_scores(turned, patterns)):
            b = owners[j][0]
            if e < best[b][0]:
                best[b] = (float(e), j)
        chosen = sorted({j for _, j in best.values() if j >= 0})
        if not chosen:
            return out
        recs = self._recognize([turned[j] for j in chosen],
                               [out[owners[j][0]].demo for j in chosen], scale, patterns)
        for j, r in zip(chosen, recs):
            out[owners[j][0]] = replace(r, tilt=owners[j][1])
        return out

    def familiarity_scale(self, patterns: Sequence[np.ndarray] | None = None) -> float:
        """The memory's own scale of what ``[learner] familiarity`` measures.

        :func:`~iloci.concepts.inference.path_scale` (``"path"``),
        :func:`~iloci.concepts.inference.regeneration_scale`
        (``"regeneration"``) or :func:`~iloci.concepts.inference.novelty_scale`
        (``"reproduction"``, ``"prediction"``); ``patterns``: the memory's
        :func:`~iloci.concepts.inference.regenerated_patterns` when already
        computed. NaN with fewer than two concepts.
        """
        policies = self.policies
        if policies.familiar_by_path or policies.familiar_by_regeneration:
            pats = regenerated_patterns(self.model, self.memory) if patterns is None else patterns
            labels = self.memory.concept_labels
            return (path_scale(pats, labels) if policies.familiar_by_path
                    else regeneration_scale(pats, labels, policies.warp, policies.compare))
        return novelty_scale(self.model, self.memory)

    def familiarities(self, sequences: Sequence[np.ndarray], scale: float, *,
                      patterns: Sequence[np.ndarray] | None = None,
                      regeneration: np.ndarray | None = None,
                      reproduction: np.ndarray | None = None,
                      pb_obs: np.ndarray | None = None) -> np.ndarray:
        """Each sequence's familiarity by ``[learner] familiarity``, shape (B,).

        :func:`~iloci.concepts.inference.familiarity` on ``scale``
        (:meth:`familiarity_scale`) of: the lowest
        :func:`~iloci.concepts.inference.path_distances` (``"path"``), the
        lowest :meth:`regeneration_distances` (``"regeneration"``), the
        lowest :meth:`entry_errors` (``"reproduction"``) or the prediction
        error from PB_obs (``"prediction"``). What the caller already
        computed is passed in (``patterns``; ``regeneration``,
        ``reproduction``: (B, M) distances / errors; ``pb_obs``: (B, P)).
        """
        seqs = list(sequences)
        policies = self.policies
        if policies.familiar_by_path or policies.familiar_by_regeneration:
            pats = regenerated_patterns(self.model, self.memory) if patterns is None else patterns
            if policies.familiar_by_path:
                nearest = path_distances(seqs, pats).min(axis=1)
            else:
                d = (self.regeneration_distances(seqs, pats) if regeneration is None
                     else regeneration)
                nearest = d.min(axis=1)
        elif policies.familiar_by_reproduction:
            nearest = (self.entry_errors(seqs) if reproduction is None
                       else reproduction).min(axis=1)
        else:
            pbs = self.recognize_pbs(seqs) if pb_obs is None else pb_obs
            nearest = np.asarray(self.model.prediction_error(seqs, pbs), dtype=np.float64)
        return familiarity(nearest, scale)

    def _recognize(self, sequences: Sequence[np.ndarray], keys: Sequence[str] | None,
                   scale: float, patterns: Sequence[np.ndarray] | None = None
                   ) -> list[Recognition]:
        """:meth:`recognize` of each sequence as given (no tilt search);
        ``scale``: :meth:`familiarity_scale` of the memory, ``patterns`` its
        regenerated patterns (when the policies use them)."""
        seqs = list(sequences)
        keys = list(keys) if keys is not None else [f"#{i}" for i in range(len(seqs))]
        if not seqs:
            return []
        pb_obs = self.recognize_pbs(seqs)
        errors = np.asarray(self.model.prediction_error(seqs, pb_obs), dtype=np.float64)
        pbs_rec = self.memory.pbs_rec
        dist = cdist(pb_obs, pbs_rec, "euclidean")
        labels = self.memory.concept_labels
        policies = self.policies
        reproduction = policies.familiar_by_reproduction
        below = policies.inference.unknown_below
        entry_errors = (self.entry_errors(seqs) if policies.rank_by_reproduction
                        or (below > 0 and reproduction) else None)
        regen = None
        if policies.rank_by_regeneration:
            if patterns is None:
                patterns = regenerated_patterns(self.model, self.memory)
            regen = self.regeneration_distances(seqs, patterns)
        ranking = (entry_errors if policies.rank_by_reproduction
                   else regen if policies.rank_by_regeneration else dist)
        nearest, conf = confidence(dist if ranking is None else ranking, labels)
        # "unknown" asks whether the demonstration is like anything the robot
        # knows (by default: the form of its pen path against the forms the
        # network regenerates from its entries), on the scale at which two
        # known concepts lie apart: the same quantity on both sides.
        rep = (entry_errors.min(axis=1) if entry_errors is not None
               else np.full(len(seqs), np.nan))
        if policies.familiar_by_path or policies.familiar_by_regeneration:
            fam = self.familiarities(seqs, scale, patterns=patterns, regeneration=regen)
        else:
            # the reproduction errors are a closed-loop run per (drawing,
            # entry): taken only when "unknown" is asked; else the PB_obs error
            fam = familiarity(rep if entry_errors is not None and reproduction else errors,
                              scale)
        out = []
        for b, i in enumerate(nearest):
            e = self.memory.entries[int(i)]
            out.append(Recognition(keys[b], e.concept, float(conf[b]), float(dist[b, i]),
                                   int(i), e.source, tuple(e.sources), pb_obs[b].copy(),
                                   float(errors[b]), float(fam[b]),
                                   bool(below > 0 and fam[b] < below), float(rep[b])))
        return out

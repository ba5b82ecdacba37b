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
from iloci.errors import InvalidInputError
from iloci.interfaces import PerceptualModel

__all__ = ["COMPARES", "PATH_WARP", "Recognition", "TILT_MARGIN", "as_positions", "confidence",
           "familiarity", "novelty_scale", "path_distances", "path_scale", "pen_path",
           "pattern_distances", "regenerated_patterns", "regeneration_scale"]

#: A turned reading of the tilt search (``[learner] tilts``) is recognized
#: only when its entry prediction error is below this fraction of the
#: upright reading's, so the drawing as drawn wins near ties (measured on
#: LASA's folds: docs/guide.md, "How a drawing is read").
TILT_MARGIN = 0.9

#: Band half-width (steps) of the alignment of :func:`path_distances`, the
#: ``[learner] familiarity = "path"`` measure. Chosen on LASA fold 0 and
#: UNIPEN fold 0 (seed 0) among 0, 2, 4, 8, 12, 16, 25 and 50: from 8 on
#: the AUROCs (docs/method.md, "I don't know") change by at most 0.002; 0
#: (step by step) scores 0.905 / 0.824 against 0.930 / 0.871 with 8.
PATH_WARP = 8


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
        definition.) The margin is taken on what ``[learner] decision``
        ranks by: PB distances (``"pb_distance"``), the distances to the
        entries' regenerated patterns (``"regeneration"``, the default,
        :func:`pattern_distances`) or the entries' prediction errors
        (``"reproduction"``, :meth:`Learner.entry_errors`).
    distance : float
        PB distance from PB_obs to the answering entry's PB_rec.
    entry : int
        Index of the answering entry in ``Memory.entries`` at recognition
        time (the best by ``[learner] decision``).
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
    #: How like what the memory knows the demonstration is, on the memory's
    #: own scale (:func:`familiarity`, of the quantity ``[learner]
    #: familiarity`` names: by default ``"path"``, the distance of its pen
    #: path to the nearest entry's regenerated pen path,
    #: :func:`path_distances`); near 1 for the familiar, 0.5 as far as two
    #: known concepts lie apart; NaN when the memory cannot calibrate it
    #: (fewer than two concepts).
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


def regenerated_patterns(model: PerceptualModel, memory: Memory) -> list[np.ndarray]:
    """Every entry's pattern as the network regenerates it: closed-loop from its PB and initialInfo.

    Unlike :func:`iloci.concepts.rehearsal.regenerate`, never the entry's
    kept demonstration: this is what the robot's network itself makes of
    each entry (what it would perform), the ground of ``[learner] decision
    = "regeneration"``.

    Returns
    -------
    list of ndarray, each (numSteps_i, D)
        Encoded units, one per entry of ``memory`` (empty for an empty memory).
    """
    entries = memory.entries
    if not entries:
        return []
    made = model.generate(memory.pbs, _stack_rows([e.initial_input for e in entries]),
                          [e.num_steps for e in entries])
    return [np.asarray(g, dtype=np.float64) for g in made]


def _stack_rows(rows: Sequence[np.ndarray]) -> np.ndarray:
    return np.asarray(np.stack([np.asarray(r, dtype=np.float64) for r in rows]),
                      dtype=np.float64)


def _on_steps(pattern: np.ndarray, steps: int) -> np.ndarray:
    """``pattern`` (T, D) linearly resampled in time to ``steps`` rows (itself when T = steps)."""
    if len(pattern) == steps:
        return pattern
    t = np.linspace(0.0, 1.0, len(pattern))
    u = np.linspace(0.0, 1.0, steps)
    return np.stack([np.interp(u, t, pattern[:, j]) for j in range(pattern.shape[1])], axis=1)


#: What :func:`pattern_distances` compares (``[learner] compare``).
COMPARES = ("both-distances", "both", "positions", "displacements")


def as_positions(sequence: np.ndarray) -> np.ndarray:
    """An encoded sequence as the positions it moves through, centred: (T + 1, D).

    The cumulative sum of the displacement rows from a zero first row (the
    pen's position in the drawing plane and each joint's angle relative to
    where the motion starts, in encoded units: the inverse of the
    encoding's differencing, :meth:`SensorimotorEncoder.decode
    <iloci.sensorimotor.encoding.SensorimotorEncoder.decode>` without its
    scale), minus their mean over the steps (the centring of $P, Vatavu,
    Anthony and Wobbrock 2012). The size needs no normalising: every
    drawing is already fitted into the same drawing plane
    (:func:`~iloci.sensorimotor.preprocess.fit_to_plane`).
    """
    s = np.asarray(sequence, dtype=np.float64)
    p = np.vstack([np.zeros((1, s.shape[1])), np.cumsum(s, axis=0)])
    return p - p.mean(axis=0)


def pattern_distances(sequences: Sequence[np.ndarray],
                      patterns: Sequence[np.ndarray], warp: int = 0,
                      compare: str = "displacements") -> np.ndarray:
    """Mean squared difference of each encoded sequence to each regenerated pattern, (B, M).

    Over the sequence's rows and every feature (encoded units; pen
    and joints alike); a pattern of another length is first resampled
    linearly in time to the sequence's. Both sides come from the same
    preprocessing (arc-length resampling to ``[sensorimotor] steps``
    points), so step ``t`` is the same fraction of the path's length in
    both. ``compare = "displacements"`` compares the rows as encoded (the
    network's inputs: each step's displacement); ``"positions"`` first
    turns both sides into the positions they move through, centred
    (:func:`as_positions`): a difference in one step's direction then
    costs the shift it makes in the rest of the drawing, which is what
    tells two shapes apart, while jitter in the directions of single steps
    averages out (DTW on positions is the field's strongest simple
    baseline for pen gestures; docs/method.md, "Recognition by
    regeneration"). With ``warp = 0`` step ``t`` is compared with step
    ``t``; with ``warp > 0`` the steps are aligned by dynamic time warping
    (Sakoe and Chiba 1978, symmetric steps, a band of ``warp`` steps
    around the diagonal) and the squared differences along the alignment
    are summed and divided by the number of rows times ``D``: a corner
    drawn a little earlier or later along the path then costs its shape
    difference, not a shift of every later step.

    Parameters
    ----------
    sequences : sequence of ndarray, each (T_b, D)
    patterns : sequence of ndarray, each (T_m, D)
    warp : int
        Band half-width of the alignment, in steps; 0 aligns step by step.
    compare : {"displacements", "positions", "both", "both-distances"}
        ``"both"`` and ``"both-distances"`` put the centred positions, weighed,
        beside the displacements: weighed so that both halves' features
        have the same RMS over ``patterns`` (:func:`_position_weight`), or
        so that both halves' distances between the patterns have the same
        median (:func:`_distance_weight`; the default of ``[learner]
        compare``).

    Returns
    -------
    ndarray, shape (B, M)

    Raises
    ------
    InvalidInputError
        ``compare`` is not one of :data:`COMPARES`.
    """
    if compare not in COMPARES:
        raise InvalidInputError(f"compare must be one of {', '.join(COMPARES)}; got "
                                f"{compare!r}.")
    # the patterns against themselves (the memory's own scales): a symmetric matrix
    itself = sequences is patterns
    seqs = [np.asarray(s, dtype=np.float64) for s in sequences]
    pats = [np.asarray(p, dtype=np.float64) for p in patterns]
    if compare == "positions":
        seqs = [as_positions(s) for s in seqs]
        pats = [as_positions(p) for p in pats]
    elif compare in ("both", "both-distances"):
        w = (_position_weight(pats) if compare == "both"
             else _distance_weight(pats, warp))
        seqs = [np.hstack([w * as_positions(s)[1:], s]) for s in seqs]
        pats = [np.hstack([w * as_positions(p)[1:], p]) for p in pats]
    out = np.zeros((len(seqs), len(pats)), dtype=np.float64)
    if not pats:
        return out
    by_len: dict[int, list[int]] = {}
    for b, s in enumerate(seqs):
        by_len.setdefault(len(s), []).append(b)
    for n, rows in by_len.items():
        S = np.stack([seqs[b] for b in rows])                        # (b, T, D)
        P = np.stack([_on_steps(p, n) for p in pats])                # (M, T, D)
        if warp <= 0:
            out[rows] = ((S[:, None] - P[None]) ** 2).mean(axis=(2, 3))
        elif itself and len(rows) == len(pats):
            # every pattern has n steps: S is P, each pair is aligned once
            out[rows] = _warped_itself(S, int(warp)) / (n * S.shape[2])
        else:
            out[rows] = _warped(S, P, int(warp)) / (n * S.shape[2])
    return out


def _position_weight(patterns: Sequence[np.ndarray]) -> float:
    """RMS of the patterns' displacements over RMS of their centred positions (1 when flat).

    Weighs the two halves of ``compare = "both"`` equally: each, so
    scaled, has unit-comparable spread over what the memory regenerates
    (features standardised before a distance, as in Gorecki and Luczak
    2013's derivative DTW, which adds distances on a series and on its
    differences).
    """
    if not patterns:
        return 1.0
    disp = np.sqrt(np.mean(np.concatenate([p.ravel() ** 2 for p in patterns])))
    pos = np.sqrt(np.mean(np.concatenate([as_positions(p).ravel() ** 2 for p in patterns])))
    return float(disp / pos) if pos > 0 and np.isfinite(pos) and np.isfinite(disp) else 1.0


#: The last :func:`_distance_weight` computed: ``(key, weight)``, the key
#: being the band and every pattern's shape and bytes (see there).
_LAST_WEIGHT: tuple[tuple[int, tuple[tuple[int, ...], ...], bytes], float] | None = None


def _distance_weight(patterns: Sequence[np.ndarray], warp: int) -> float:
    """The positions' weight that gives both halves the same median distance over the patterns.

    Standardises the two distances rather than the features: the median,
    over every pair of the memory's regenerated patterns, of the
    displacements' distance over that of the centred positions (each by
    :func:`pattern_distances` with ``warp``), square-rooted (the distances
    are squared differences); 1 with fewer than two patterns or a zero median.

    Two M x M banded DTWs: the memory's patterns do not change between the
    rankings of one memory state (a batch's readings, the tilt search, the
    turns between two rehearsals), so the last weight is kept with the
    exact bytes of the patterns it was computed on and given again only
    for byte-identical patterns and the same ``warp``: a memory that
    changed in any way (rehearsal, new entry, other network or file)
    regenerates other patterns and gets its weight computed afresh. Same
    inputs, same arithmetic: the kept weight is the one a new computation
    would give, bit for bit.
    """
    global _LAST_WEIGHT
    pats = [np.asarray(p, dtype=np.float64) for p in patterns]
    if len(pats) < 2:
        return 1.0
    key = (int(warp), tuple(p.shape for p in pats),
           b"".join(np.ascontiguousarray(p).tobytes() for p in pats))
    last = _LAST_WEIGHT   # one read: another thread may replace it meanwhile
    if last is not None and last[0] == key:
        return last[1]
    off = ~np.eye(len(pats), dtype=bool)
    dp = float(np.median(pattern_distances(pats, pats, warp, "positions")[off]))
    dd = float(np.median(pattern_distances(pats, pats, warp, "displacements")[off]))
    w = float(np.sqrt(dd / dp)) if dp > 0 and dd > 0 and np.isfinite(dp + dd) else 1.0
    _LAST_WEIGHT = (key, w)
    return w


def _warped(S: np.ndarray, P: np.ndarray, band: int) -> np.ndarray:
    """DTW cost (summed squared differences) of every (sequence, pattern) pair, (B, M).

    ``S`` (B, T, D), ``P`` (M, T, D); cells further than ``band`` steps from
    the diagonal are not visited. Vectorised over the pairs, row by row of
    the alignment (memory: two rows of ``T + 1`` cells per pair).
    """
    b, t = S.shape[0], S.shape[1]
    m = P.shape[0]
    s2 = (S * S).sum(-1)                                              # (B, T)
    p2 = (P * P).sum(-1)                                              # (M, T)
    prev = np.full((t + 1, b, m), np.inf)
    prev[0] = 0.0
    for i in range(1, t + 1):
        lo, hi = max(1, i - band), min(t, i + band)
        # squared distance of step i of each sequence to steps lo..hi of each pattern
        cost = (s2[:, i - 1][None, :, None] + p2[:, lo - 1:hi].T[:, None, :]
                - 2.0 * np.einsum("bd,mjd->jbm", S[:, i - 1], P[:, lo - 1:hi]))
        np.maximum(cost, 0.0, out=cost)
        row = np.full((t + 1, b, m), np.inf)
        for j in range(lo, hi + 1):
            row[j] = cost[j - lo] + np.minimum(np.minimum(prev[j], row[j - 1]), prev[j - 1])
        prev = row
    return prev[t]


#: Pairs :func:`_warped_pairs` aligns together (its arrays stay within a
#: core's cache: about 20 arrays of ``T x 512`` floats).
_PAIRS_AT_ONCE = 512


def _lanes(d: int) -> tuple[list[int], list[int]]:
    """The order in which :func:`_warped`'s ``np.einsum`` adds a dot product's ``d`` terms.

    numpy's einsum sums a contiguous dot product (``sum_of_products_contig_contig_outstride0_two``,
    numpy/_core/src/multiarray/einsum_sumprod.c.src, built for the baseline
    SIMD: two float64 lanes, multiply then add, not fused) in two lanes,
    features ``k`` with ``k % 2`` equal to the lane, in blocks of 8
    (features 6, 4, 2, 0 of the block, lane by lane) and then pairs; the
    result is lane 0 + lane 1. Per lane, the features in the order added.
    """
    lanes: tuple[list[int], list[int]] = ([], [])
    k = 0
    while d - k >= 8:
        for lane in (0, 1):
            lanes[lane].extend(k + 2 * v + lane for v in (3, 2, 1, 0))
        k += 8
    for j in range(k, d):
        lanes[j % 2].append(j)
    return lanes


def _warped_itself(S: np.ndarray, band: int) -> np.ndarray:
    """:func:`_warped` of ``S`` against itself, (M, M), each unordered pair aligned once.

    The DTW of ``(a, b)`` is that of ``(b, a)`` bit for bit: the step
    costs are the same products summed in the same order, and the
    recursion takes the minimum of the same three sums (never -0: costs
    are clipped at +0), which is the same whichever order they come in.
    """
    m = S.shape[0]
    rows, cols = np.triu_indices(m)
    d = np.empty(len(rows))
    for c in range(0, len(rows), _PAIRS_AT_ONCE):
        part = slice(c, c + _PAIRS_AT_ONCE)
        d[part] = _warped_pairs(S, S, rows[part], cols[part], band)
    out = np.empty((m, m))
    out[rows, cols] = d
    out[cols, rows] = d
    return out


def _warped_pairs(S: np.ndarray, P: np.ndarray, si: np.ndarray, pi: np.ndarray,
                  band: int) -> np.ndarray:
    """:func:`_warped` of the pairs ``(S[si[k]], P[pi[k]])``, shape (K,), bit for bit.

    The same arithmetic, arranged for few Python steps: the step costs
    are computed one band diagonal at a time for every pair (the products
    and their sum in :func:`_lanes`' order, then ``(s2 + p2) - 2 dot``
    clipped at 0, as :func:`_warped` computes them), and the recursion one
    anti-diagonal of the alignment at a time (its cells depend on the two
    anti-diagonals before only). ``D[i, o + 1]`` holds the cell ``(i, j =
    i + o - band)``; columns 0 and ``2 band + 2`` stay infinite (outside the
    band), so the cells of an anti-diagonal and each of their three
    predecessors are evenly spaced in ``D``'s flat rows.
    """
    t, d = S.shape[1], S.shape[2]
    k = len(si)
    band = max(0, min(int(band), t))
    width = 2 * band + 3
    X = S[si].transpose(2, 1, 0).copy()                    # (d, T, K)
    Y = P[pi].transpose(2, 1, 0).copy()
    x2 = (S * S).sum(-1)[si].T                             # (T, K)
    y2 = (P * P).sum(-1)[pi].T
    lanes = _lanes(d)
    D = np.full((t + 1, width, k), np.inf)
    D[0, band + 1] = 0.0
    acc = np.empty((2, t, k))
    tmp = np.empty((t, k))
    for o in range(2 * band + 1):
        i0, i1 = max(1, band + 1 - o), min(t, t + band - o)
        if i0 > i1:
            continue
        n = i1 - i0 + 1
        xs, ys = slice(i0 - 1, i1), slice(i0 - 1 + o - band, i1 + o - band)
        for lane, order in enumerate(lanes):
            if order:
                a = acc[lane, :n]
                np.multiply(X[order[0], xs], Y[order[0], ys], out=a)
                for f in order[1:]:
                    np.multiply(X[f, xs], Y[f, ys], out=tmp[:n])
                    np.add(tmp[:n], a, out=a)
        dot = acc[0, :n]
        np.add(dot, acc[1, :n] if lanes[1] else 0.0, out=dot)
        cost = D[i0:i1 + 1, o + 1]
        np.add(x2[xs], y2[ys], out=cost)
        np.subtract(cost, np.multiply(dot, 2.0, out=dot), out=cost)
        np.maximum(cost, 0.0, out=cost)
    flat = D.reshape(-1, k)
    step = width - 2
    low = tmp
    for diag in range(2, 2 * t + 1):
        i0 = max(1, diag - t, (diag - band + 1) // 2)
        i1 = min(t, diag - 1, (diag + band) // 2)
        if i0 > i1:
            continue
        a, b = i0 * step + diag + band + 1, i1 * step + diag + band + 2
        cell = flat[a:b:step]
        lo = low[:len(cell)]
        # cost + min(min(D[i-1, j], D[i, j-1]), D[i-1, j-1]), as in _warped
        np.minimum(flat[a - width + 1:b - width + 1:step], flat[a - 1:b - 1:step], out=lo)
        np.minimum(lo, flat[a - width:b - width:step], out=lo)
        np.add(cell, lo, out=cell)
    return D[t, band + 1].copy()


def regeneration_scale(patterns: Sequence[np.ndarray], labels: Sequence[str],
                       warp: int = 0, compare: str = "displacements") -> float:
    """The memory's own scale for "unlike everything it knows", on regenerated patterns.

    For each entry, :func:`pattern_distances` (with ``warp`` and ``compare``)
    from its regenerated pattern to the nearest regenerated pattern of an
    entry of *another* concept (how far apart two known concepts lie); the median over entries. The
    project's calibration (the paper has none), the counterpart of
    :func:`novelty_scale` for ``[learner] familiarity = "regeneration"``.

    Returns
    -------
    float
        Mean squared difference, encoded units; NaN with fewer than two concepts.
    """
    lab = np.asarray(list(labels))
    if len(set(lab.tolist())) < 2:
        return float("nan")
    pats = list(patterns)
    d = pattern_distances(pats, pats, warp, compare)
    other = np.where(lab[:, None] != lab[None, :], d, np.inf).min(axis=1)
    other = other[np.isfinite(other)]
    return float(np.median(other)) if other.size else float("nan")


def pen_path(sequence: np.ndarray) -> np.ndarray:
    """The pen path an encoded sequence draws, centred and scaled to unit RMS radius.

    The cumulative sum of the pen displacements (the first two features,
    ``dy, dz``, encoded units) from a start at the origin, minus its mean
    point, divided by the root mean square distance of its points from
    that mean: where and how large a shape is drawn no longer counts, only
    its form. The joint features are left out: they follow from the pen
    path by inverse kinematics.

    Parameters
    ----------
    sequence : ndarray, shape (T, D), D >= 2

    Returns
    -------
    ndarray, shape (T + 1, 2)
        Unitless; all zeros for a sequence that does not move.
    """
    s = np.asarray(sequence, dtype=np.float64)
    p = np.vstack([np.zeros((1, 2)), np.cumsum(s[:, :2], axis=0)])
    p -= p.mean(axis=0)
    radius = float(np.sqrt((p * p).sum(axis=1).mean()))
    return p / radius if radius > 0 else p


def path_distances(sequences: Sequence[np.ndarray], patterns: Sequence[np.ndarray],
                   warp: int = PATH_WARP) -> np.ndarray:
    """How far each sequence's pen path lies from each pattern's, shape (B, M).

    :func:`pattern_distances` of the :func:`pen_path` of each encoded
    sequence to the :func:`pen_path` of each pattern (the entries'
    :func:`regenerated_patterns` for ``[learner] familiarity = "path"``),
    aligned by dynamic time warping in a band of ``warp`` steps
    (:data:`PATH_WARP`): the form of the shape the drawing makes against the
    form of each shape the network draws from what it knows.

    Returns
    -------
    ndarray, shape (B, M)
        Mean squared distance of aligned points (unitless, paths of unit
        RMS radius).
    """
    return pattern_distances([pen_path(s) for s in sequences],
                             [pen_path(p) for p in patterns], warp)


def path_scale(patterns: Sequence[np.ndarray], labels: Sequence[str],
               warp: int = PATH_WARP) -> float:
    """The memory's own scale for :func:`path_distances`: :func:`regeneration_scale` on pen paths.

    For each entry, :func:`path_distances` from its regenerated pattern to
    the nearest regenerated pattern of *another* concept; the median over
    entries. A drawing as far from everything known as two known concepts
    lie apart has familiarity 0.5 (:func:`familiarity`).

    Returns
    -------
    float
        Unitless; NaN with fewer than two concepts.
    """
    return regeneration_scale([pen_path(p) for p in patterns], labels, warp)


def familiarity(error: np.ndarray | float, scale: float) -> np.ndarray:
    """``scale / (scale + error)``: near 1 for what the network reproduces, 0.5 at the scale.

    Parameters
    ----------
    error : float or ndarray
        Closed-loop prediction error of a demonstration (mean squared,
        encoded units): by default (``[learner] familiarity =
        "reproduction"``) the lowest over memory entries of the error with
        which the entry's PB reproduces it (:meth:`Learner.entry_errors`),
        else the error from its PB_obs; with ``"regeneration"`` the lowest
        :func:`pattern_distances` and with ``"path"`` the lowest
        :func:`path_distances` to the entries' regenerated patterns.
    scale : float
        The memory's scale of that quantity: :func:`novelty_scale`,
        :func:`regeneration_scale` or :func:`path_scale`.

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

"""Figures of the evaluation report (matplotlib, Agg backend, PNG).

Each function takes plain arrays, writes one PNG and returns its path.
matplotlib is imported when a figure is drawn, not when iloci is imported.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
import contextlib
from pathlib import Path
import re
from typing import Any
import warnings

import numpy as np

from iloci.errors import MissingBackendError
from iloci.data.writes import write_atomic
from iloci.evaluation.metrics import backward_moving_average

__all__ = [
    "plot_matrix",
    "plot_reinforcement",
    "plot_first_guess",
    "plot_pb_space",
    "plot_shapes",
    "plot_stream",
    "plot_noisy",
    "plot_robustness",
]


def _plt() -> Any:
    try:
        import matplotlib
    except ImportError as exc:
        raise MissingBackendError("report", "figures", ["matplotlib"],
                                  "pip install matplotlib") from exc
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _save(fig: Any, path: str | Path) -> Path:
    """Write ``fig`` as PNG, whole or not at all (a full disk leaves no cut image)."""
    path = Path(path)
    try:
        write_atomic(path, lambda fh: fig.savefig(fh, format="png", dpi=110,
                                                  bbox_inches="tight"), mkdir=True)
    finally:
        _plt().close(fig)
    return path


@contextlib.contextmanager
def missing_glyphs_said_once() -> Iterator[None]:
    """Figures drawn inside say once which characters of their text the font lacks.

    matplotlib warns per character and per figure ("Glyph 20043 (...)
    missing from font(s) DejaVu Sans."), a dozen lines for one concept
    named in Chinese; inside this block they become one warning naming the
    characters. Other warnings pass as they were.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    missing: list[str] = []
    for w in caught:
        m = _NO_GLYPH.search(str(w.message))
        if m is None:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        elif chr(int(m.group(1))) not in missing:
            missing.append(chr(int(m.group(1))))
    if missing:
        warnings.warn(f"the figures' font has no glyph for "
                      f"{''.join(missing[:8])}{'...' if len(missing) > 8 else ''} (in concept "
                      "names): those characters show as boxes in the figures; the report's "
                      "text names them. A font with them (e.g. Noto Sans CJK) installed and "
                      "named in matplotlib's font.sans-serif draws them.", stacklevel=3)


#: matplotlib's warning for a character its fonts lack:
#: "Glyph 20043 (\\N{CJK UNIFIED IDEOGRAPH-4E4B}) missing from font(s) DejaVu Sans."
_NO_GLYPH = re.compile(r"Glyph (\d+) .*missing from font")


def plot_matrix(matrix: np.ndarray, concepts: Sequence[str], path: str | Path, *,
                title: str, cbar_label: str, annotate: bool = True) -> Path:
    """Heat map of a (C, C) matrix, rows = true concept, columns = predicted."""
    plt = _plt()
    n = len(concepts)
    fig, ax = plt.subplots(figsize=(0.42 * n + 2.5, 0.42 * n + 1.5))
    shown = np.ma.masked_invalid(matrix)
    im = ax.imshow(shown, vmin=0.0, vmax=1.0, cmap="viridis")
    ax.set_xticks(range(n), concepts, rotation=90, fontsize=7)
    ax.set_yticks(range(n), concepts, fontsize=7)
    ax.set_xlabel("predicted concept")
    ax.set_ylabel("true concept")
    ax.set_title(title)
    if annotate:
        for i in range(n):
            for j in range(n):
                v = matrix[i, j]
                if np.isfinite(v) and v >= 0.005:
                    ax.text(j, i, f"{100 * v:.0f}", ha="center", va="center", fontsize=5,
                            color="white" if v < 0.6 else "black")
    fig.colorbar(im, ax=ax, label=cbar_label, fraction=0.046, pad=0.04)
    return _save(fig, path)


def _pad(rows: Sequence[Sequence[float] | np.ndarray]) -> np.ndarray:
    width = max((len(r) for r in rows), default=0)
    out = np.full((len(rows), width), np.nan)
    for i, r in enumerate(rows):
        out[i, :len(r)] = r
    return out


def plot_reinforcement(signals: Sequence[Sequence[int]], path: str | Path, *,
                       window: int = 7) -> Path:
    """Reinforcement signal per interaction: backward moving average, mean over folds.

    Parameters
    ----------
    signals : list of sequences of +1/-1, one per fold (lengths may differ)
    """
    plt = _plt()
    smoothed = _pad([backward_moving_average(s, window) for s in signals])
    fig, ax = plt.subplots(figsize=(7, 3.2))
    for row in smoothed:
        ax.plot(np.arange(1, len(row) + 1), row, color="0.8", lw=0.8)
    with np.errstate(all="ignore"):
        mean = np.nanmean(smoothed, axis=0)
    ax.plot(np.arange(1, len(mean) + 1), mean, color="C0", lw=2, label="mean over folds")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_ylim(-1.05, 1.05)
    ax.set_xlabel("interaction (teacher feedback)")
    ax.set_ylabel(f"reinforcement (moving avg, w={window})")
    ax.legend(loc="lower right")
    return _save(fig, path)


def plot_first_guess(first_guess: Sequence[Sequence[bool]], path: str | Path, *,
                     window: int = 7) -> Path:
    """Whether the first guess was right, per learning demonstration, as memory grows.

    Parameters
    ----------
    first_guess : list of sequences of bool, one per fold
        Entry ``k`` is true when the first guess for the ``k``-th learning
        demonstration was rewarded (a demonstration shown to an empty
        memory, with no guess, counts as wrong).
    """
    plt = _plt()
    rows = _pad([backward_moving_average(np.asarray(f, float), window) for f in first_guess])
    fig, ax = plt.subplots(figsize=(7, 3.2))
    with np.errstate(all="ignore"):
        mean = np.nanmean(rows, axis=0)
    x = np.arange(1, rows.shape[1] + 1)
    for row in rows:
        ax.plot(x, 100 * row, color="0.8", lw=0.8)
    ax.plot(x, 100 * mean, color="C1", lw=2, label="mean over folds")
    ax.set_ylim(-2, 102)
    ax.set_xlabel("learning demonstrations seen")
    ax.set_ylabel(f"first guess right, % (moving avg, w={window})")
    ax.legend(loc="lower right")
    return _save(fig, path)


#: Most points the PB-space figure places: non-metric MDS takes time growing
#: faster than the square of the points (150: 21 s, 300: 77 s, 600: 458 s on 2
#: busy cores), and a fold of a large data set has thousands.
PB_SPACE_POINTS = 200


def pb_space_sample(kinds: Sequence[str], seed: int = 0,
                    most: int = PB_SPACE_POINTS) -> np.ndarray:
    """Indices of the points the PB-space figure shows: all of them up to ``most``.

    Beyond, a seeded sample: the memory's entries (kinds other than
    ``"test"``) up to half of ``most``, then test points up to ``most`` in all.

    Returns
    -------
    ndarray of int
        Sorted indices into ``kinds``.
    """
    n = len(kinds)
    if n <= most:
        return np.arange(n)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 7]))
    mem = np.array([i for i, k in enumerate(kinds) if k != "test"], dtype=int)
    test = np.array([i for i, k in enumerate(kinds) if k == "test"], dtype=int)
    if len(mem) > most // 2:
        mem = rng.choice(mem, most // 2, replace=False)
    if len(test) > most - len(mem):
        test = rng.choice(test, most - len(mem), replace=False)
    return np.sort(np.concatenate([mem, test]))


def plot_pb_space(pbs: np.ndarray, concepts: Sequence[str], path: str | Path, *,
                  kinds: Sequence[str] | None = None, seed: int = 0) -> Path:
    """PB vectors in 2-D by non-metric MDS, one marker per concept.

    At most :data:`PB_SPACE_POINTS` points are placed (a seeded sample of
    more, :func:`pb_space_sample`; the title says how many of how many).

    Parameters
    ----------
    pbs : ndarray, shape (M, P)
    concepts : sequence of str, length M
    kinds : sequence of str, optional
        ``"prototype"``, ``"exemplar"`` or ``"test"`` per point (drawn large,
        medium and small).
    """
    plt = _plt()
    try:
        from sklearn.manifold import MDS
    except ImportError as exc:
        raise MissingBackendError("report", "PB-space figure", ["scikit-learn"],
                                  "pip install scikit-learn") from exc
    pbs = np.asarray(pbs, dtype=np.float64)
    total = len(pbs)
    keep = pb_space_sample(list(kinds) if kinds else ["test"] * total, seed)
    pbs, concepts = pbs[keep], [concepts[i] for i in keep]
    kinds = [kinds[i] for i in keep] if kinds else None
    from scipy.spatial.distance import pdist, squareform
    d = squareform(pdist(pbs))
    mds = MDS(n_components=2, metric_mds=False, metric="precomputed", init="random",
              random_state=seed, n_init=4, max_iter=300)
    xy = mds.fit_transform(d)
    names = sorted(set(concepts))
    markers = "o^sDvP*Xh<>p"
    cmap = plt.get_cmap("tab20")
    sizes = {"prototype": 90, "exemplar": 40, "test": 12}
    fig, ax = plt.subplots(figsize=(7.5, 6))
    for k, name in enumerate(names):
        idx = [i for i, c in enumerate(concepts) if c == name]
        s = [sizes.get(kinds[i], 30) if kinds else 30 for i in idx]
        ax.scatter(xy[idx, 0], xy[idx, 1], s=s, marker=markers[k % len(markers)],
                   color=cmap((2 * k) % 20 + (k // 10) % 2), label=name, alpha=0.8,
                   edgecolors="none")
    ax.set_title("PB space (non-metric MDS)" + (
        f", a seeded sample of {len(keep)} of {total} points" if len(keep) < total else ""))
    ax.set_xticks([])
    ax.set_yticks([])
    ax.legend(fontsize=6, ncol=2, loc="center left", bbox_to_anchor=(1.0, 0.5))
    return _save(fig, path)


def plot_shapes(shapes: Mapping[str, np.ndarray], path: str | Path, *,
                title: str = "one regenerated shape per concept") -> Path:
    """A grid of drawings, start point marked; ``shapes`` maps concept -> (T, 2)."""
    plt = _plt()
    names = list(shapes)
    cols = min(6, max(1, len(names)))
    rows = int(np.ceil(len(names) / cols)) or 1
    fig, axes = plt.subplots(rows, cols, figsize=(1.8 * cols, 1.9 * rows + 0.5),
                             squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for ax, name in zip(axes.ravel(), names):
        p = np.asarray(shapes[name])
        ax.plot(p[:, 0], p[:, 1], "-", color="C0", lw=1.5)
        ax.plot(p[0, 0], p[0, 1], "o", color="C2", ms=5)
        ax.set_title(name, fontsize=8)
        ax.set_aspect("equal", adjustable="datalim")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    return _save(fig, path)


def plot_stream(correct: Sequence[bool], feedbacks: Sequence[int], path: str | Path, *,
                first_scored: int = 46, window: int = 15) -> Path:
    """The test-then-learn stream: first guess right and feedbacks per demonstration.

    Parameters
    ----------
    correct : sequence of bool
        Per demonstration, in stream order: answered right before it was taught.
    feedbacks : sequence of int
        Per demonstration: teacher feedbacks it took to teach it.
    first_scored : int
        1-based position from which the summary is taken (a vertical line).
    window : int
        Backward moving average window.
    """
    plt = _plt()
    x = np.arange(1, len(correct) + 1)
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    c = np.asarray(correct, dtype=float)
    ax.plot(x, 100 * backward_moving_average(c, window), color="C1", lw=1.5,
            label=f"moving average (w={window})")
    ax.plot(x, 100 * np.cumsum(c) / x, color="C0", lw=1.5, label="cumulative")
    ax.axvline(first_scored, color="k", lw=0.6, ls="--")
    ax.set_ylim(-2, 102)
    ax.set_ylabel("first guess right, %")
    ax.legend(loc="lower right", fontsize=8)
    f = np.asarray(feedbacks, dtype=float)
    bx.bar(x, f, color="0.75", width=1.0, label="per demonstration")
    bx.plot(x, backward_moving_average(f, window), color="C3", lw=1.5,
            label=f"moving average (w={window})")
    bx.axvline(first_scored, color="k", lw=0.6, ls="--")
    bx.set_xlabel("demonstration in the stream")
    bx.set_ylabel("teacher feedbacks")
    bx.legend(loc="upper right", fontsize=8)
    return _save(fig, path)


def plot_noisy(ps: Sequence[float], ccr: Sequence[Sequence[float]],
               feedbacks: Sequence[Sequence[float]], path: str | Path) -> Path:
    """CCR and feedbacks per learning demonstration against the teacher's error rate.

    Parameters
    ----------
    ps : sequence of float
        Error probabilities of the noisy teacher.
    ccr, feedbacks : sequence of sequences of float
        Per ``p``, one value per run (fold or seed); mean and spread are drawn.
    """
    plt = _plt()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(8, 3.2))
    p = np.asarray(ps, dtype=float)
    for axis, values, label, scale in ((ax, ccr, "CCR, %", 100.0),
                                       (bx, feedbacks, "feedbacks per learning demo", 1.0)):
        mean = np.array([np.mean(v) for v in values]) * scale
        lo = np.array([np.min(v) for v in values]) * scale
        hi = np.array([np.max(v) for v in values]) * scale
        axis.fill_between(p, lo, hi, color="C0", alpha=0.2, lw=0)
        axis.plot(p, mean, "o-", color="C0")
        axis.set_xlabel("teacher error probability p")
        axis.set_ylabel(label)
    ax.set_title("accuracy (band: min-max)")
    bx.set_title("teacher effort")
    fig.tight_layout()
    return _save(fig, path)


def plot_robustness(rob: Mapping[str, Mapping], path: str | Path) -> Path:
    """Horizontal bars: CCR per perturbation, iloci beside DTW 1-NN (mean ± std over folds).

    ``rob`` is metrics.json's ``robustness`` (see
    :func:`iloci.evaluation.robustness.summarize_robustness`).
    """
    plt = _plt()
    rows = list(rob.values())
    n = len(rows)
    y = np.arange(n)
    fig, ax = plt.subplots(figsize=(7.5, 0.32 * n + 1.2))
    ax.barh(y - 0.2, [100 * r["ccr_mean"] for r in rows], 0.38,
            xerr=[100 * r["ccr_std"] for r in rows], label="iloci", color="tab:blue")
    if all("baseline" in r for r in rows):
        ax.barh(y + 0.2, [100 * r["baseline"]["ccr_mean"] for r in rows], 0.38,
                xerr=[100 * r["baseline"]["ccr_std"] for r in rows], label="DTW 1-NN, normalised",
                color="tab:gray")
    ax.set_yticks(y, [r["label"] for r in rows], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel("CCR (%)")
    ax.set_title("recognition of perturbed test demonstrations")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=8)
    ax.grid(axis="x", alpha=0.3)
    return _save(fig, path)

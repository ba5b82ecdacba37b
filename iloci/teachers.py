"""iloci's built-in teachers, registered as an ordinary plugin.

``oracle``
    Knows the true concept of every demonstration and of the demonstration
    each memory entry stands for; rewards an answer exactly when they match.
``noisy``
    An oracle whose every feedback is flipped with probability ``p`` (seeded).
``console``
    Asks a person on the terminal, showing the guess; saves a picture of the
    robot's answer when matplotlib is installed.
"""

from __future__ import annotations

import io
import os
import re
import sys
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np

from iloci.data.files import write_atomic
from iloci.errors import FeedbackError, MissingBackendError
from iloci.hookspecs import hookimpl
from iloci.interfaces import Demonstration, Response

__all__ = ["OracleTeacher", "NoisyTeacher", "DrawingTeacher", "ConsoleTeacher"]


class OracleTeacher:
    """Rewards an answer iff its source demonstration has the shown concept.

    The oracle knows labels from the data only: a demonstration's
    ``true_concept`` (``load_lasa`` and ``iloci evaluate --data`` fill it
    in), else ``concepts[demo.shape]``; never from a LASA shape name. It
    judges an answer by the demonstration the answering memory entry stands
    for, so it must have seen that one: the learning loops
    (:meth:`Agent.learn <iloci.agent.Agent.learn>`,
    :meth:`Learner.learn <iloci.concepts.learner.Learner.learn>`) call
    :meth:`show` with every demonstration before the robot answers, the
    founding one of a concept too (which is placed without a question).

    Parameters
    ----------
    concepts : mapping of str to str, optional
        Shape name -> concept, for demonstrations without ``true_concept``.
    """

    def __init__(self, concepts: Mapping[str, str] | None = None) -> None:
        self.concepts = dict(concepts or {})
        self._seen: dict[str, str] = {}
        self._recalled: dict[str, str] = {}

    def recall(self, labels: Mapping[str, str]) -> None:
        """Know the labels of demonstrations a memory learned before (in an earlier session:
        :attr:`Memory.labels <iloci.concepts.memory.Memory.labels>`, by key), so answers
        standing for them are judged as in the session that taught them."""
        self._recalled.update(labels)

    def show(self, demo: Demonstration) -> None:
        """Record the true concept of a demonstration the robot is about to be shown.

        Raises
        ------
        FeedbackError
            The oracle does not know its concept (see :meth:`true_concept`).
        """
        self.true_concept(demo)

    def concept_of_key(self, key: str) -> str | None:
        """True concept of the demonstration ``"SHAPE/INDEX"`` shown before (or recalled from
        a memory, :meth:`recall`), else of its shape in ``concepts``, else ``None``."""
        if key in self._seen:
            return self._seen[key]
        if key in self._recalled:
            return self._recalled[key]
        return self.concepts.get(key.rsplit("/", 1)[0])

    def true_concept(self, demo: Demonstration) -> str:
        """The concept of ``demo`` from the data (recorded for :meth:`concept_of_key`).

        Raises
        ------
        FeedbackError
            ``demo`` has no ``true_concept`` and its shape is not in ``concepts``.
        """
        c = demo.true_concept or self.concepts.get(demo.shape)
        if c is None:
            raise FeedbackError(
                f"oracle teacher does not know the concept of {demo.key!r}: give the "
                "Demonstration a concept, or name it in the teacher's config, "
                f'[teacher] concepts = ["{demo.shape}=CONCEPT"] (in Python: '
                f'concepts={{"{demo.shape}": "CONCEPT"}}).')
        self._seen[demo.key] = c
        return c

    def feedback(self, demo: Demonstration, response: Response) -> int:
        """+1 iff the answer is right.

        A concept answer is right when its source demonstration has the
        demonstration's true concept; a novelty answer (``response.novel``)
        when no demonstration the robot's memory stands for
        (``response.sources``) has it.
        """
        truth = self.true_concept(demo)
        if response.novel:
            return -1 if any(self.concept_of_key(k) == truth for k in response.sources) else 1
        if response.source is None:
            raise FeedbackError("oracle teacher needs Response.source (the demonstration "
                                "the answering entry stands for).")
        return 1 if self.concept_of_key(response.source) == truth else -1


class NoisyTeacher(OracleTeacher):
    """An oracle that flips each feedback with probability ``p``.

    Whether a feedback is flipped is drawn from ``(seed, demonstration key,
    attempt)`` alone, not from a stream of draws: the same demonstration
    answered at the same attempt gets the same error, so a session resumed
    after a crash (which teaches the interrupted demonstration again from
    its first attempt) gives the same feedbacks as one never interrupted.

    Parameters
    ----------
    p : float
        Error probability in [0, 1].
    seed : int
        Seed of the error draws.
    """

    def __init__(self, p: float = 0.1, seed: int = 0,
                 concepts: Mapping[str, str] | None = None) -> None:
        super().__init__(concepts)
        self.p = float(p)
        self.seed = seed

    def flips(self, demo: Demonstration, attempt: int) -> bool:
        """Whether the feedback for ``demo`` at ``attempt`` is flipped."""
        key = zlib.crc32(demo.key.encode("utf-8"))
        return bool(np.random.default_rng([self.seed, key, int(attempt)]).random() < self.p)

    def feedback(self, demo: Demonstration, response: Response) -> int:
        value = super().feedback(demo, response)
        return -value if self.flips(demo, response.attempt) else value


class DrawingTeacher(OracleTeacher):
    """Judges only what the robot drew, as a person looking at it would.

    It knows the concept of the demonstration it showed (as the person who
    drew it does) and what each concept looks like (reference
    demonstrations), and never looks at which memory entry answered: +1
    when the robot's drawing is nearest, by dynamic time warping, to a
    reference demonstration of the shown demonstration's concept, else -1.
    The oracle judges by labels; this teacher measures whether the answers
    can be judged by eye (issue "Teach the robot in a browser", item 3).

    Both paths are resampled to ``points`` equal time steps, centred on
    their bounding box and scaled by its larger side (translation and
    scale do not matter, orientation does), then compared with
    ``dtaidistance``'s multi-dimensional DTW.

    Parameters
    ----------
    references : sequence of Demonstration
        Each with ``true_concept`` set (e.g. every LASA demonstration of the
        shapes taught: ``iloci.data.load_lasa(shapes)``).
    points : int
        Resampling length (50, the robot's sequence length).
    concepts : mapping of str to str, optional
        Shape -> concept, for shown demonstrations outside LASA.

    Raises
    ------
    MissingBackendError
        ``dtaidistance`` is not installed (the ``report`` extra).
    """

    def __init__(self, references, points: int = 50,
                 concepts: Mapping[str, str] | None = None) -> None:
        super().__init__(concepts)
        try:
            from dtaidistance import dtw_ndim
        except ImportError as exc:
            raise MissingBackendError("teacher", "drawing", ["dtaidistance"],
                                      "pip install 'iloci[report]'") from exc
        self._dtw = dtw_ndim.distance_fast
        refs = list(references)
        if not refs or any(r.true_concept is None for r in refs):
            raise FeedbackError("the drawing teacher needs reference demonstrations, each "
                                "with its true concept set.")
        self.points = int(points)
        self.reference_concepts = [str(r.true_concept) for r in refs]
        self._refs = [_normalized(_at_times(r.positions, r.times, self.points)) for r in refs]

    def nearest_concept(self, drawing: np.ndarray) -> str:
        """The concept of the reference DTW-nearest to ``drawing`` (T, 2), any frame."""
        d = np.asarray(drawing, dtype=np.float64)
        path = _normalized(_at_times(d, np.arange(len(d), dtype=np.float64), self.points))
        dist = [self._dtw(path, r) for r in self._refs]
        return self.reference_concepts[int(np.argmin(dist))]

    def feedback(self, demo: Demonstration, response: Response) -> int:
        truth = self.true_concept(demo)
        drawing = (response.teacher_drawing if response.teacher_drawing is not None
                   else response.drawing)
        return 1 if self.nearest_concept(drawing) == truth else -1


def _at_times(positions: np.ndarray, times: np.ndarray, points: int) -> np.ndarray:
    grid = np.linspace(times[0], times[-1], points)
    return np.column_stack([np.interp(grid, times, positions[:, k]) for k in range(2)])


def _normalized(path: np.ndarray) -> np.ndarray:
    lo, hi = path.min(axis=0), path.max(axis=0)
    size = float(np.max(hi - lo)) or 1.0
    return np.ascontiguousarray((path - (lo + hi) / 2) / size, dtype=np.double)


class ConsoleTeacher:
    """Asks a person whether the robot's answer is right (y/n).

    Parameters
    ----------
    picture_dir : str
        Directory for a PNG of each answer (demonstration beside the robot's
        drawing: :attr:`Response.drawing <iloci.interfaces.Response.drawing>`,
        the executed pen path when a simulator is configured, in the
        demonstration's frame on the same equal axes) when
        matplotlib is installed; ``""`` disables pictures. The pictures are
        numbered ``answer-0001.png``, ... on from the highest number already
        in the directory, so a later session (or another teacher writing
        there at the same time) adds pictures and never replaces one.
    stdin, stdout : file, optional
        For embedding and tests.
    """

    def __init__(self, picture_dir: str = "iloci-answers", stdin: TextIO | None = None,
                 stdout: TextIO | None = None,
                 ask: Callable[[str], str] | None = None) -> None:
        self.picture_dir = picture_dir
        self.stdin = stdin or sys.stdin
        self.stdout = stdout or sys.stdout
        self._ask = ask
        self._count = 0  # number of the last picture this teacher wrote

    def _picture(self, demo: Demonstration, response: Response) -> str | None:
        if not self.picture_dir:
            return None
        try:
            # a bare Figure, not pyplot: no backend switch in the host program
            from matplotlib.figure import Figure
        except ImportError:
            return None
        fig = Figure(figsize=(7, 3.5))
        in_frame = response.teacher_drawing is not None
        axes = fig.subplots(1, 2, sharex=in_frame, sharey=in_frame)
        axes[0].plot(demo.positions[:, 0], demo.positions[:, 1], "k-")
        axes[0].plot(*demo.positions[0], "go")
        axes[0].set_title(f"shown: {demo.key}")
        # with a simulator, the teacher judges what the arm drew, not what the
        # network meant to draw; shown in the demonstration's frame (its units,
        # orientation, size and place) when the learner gave it
        drawing = np.asarray(response.teacher_drawing if in_frame else response.drawing)
        axes[1].plot(drawing[:, 0], drawing[:, 1], "b-")
        axes[1].plot(*drawing[0], "go")
        drawn = "drew" if response.execution is not None else "generated"
        axes[1].set_title("robot: something new?" if response.novel
                          else f"robot {drawn}: concept {response.concept}")
        if not in_frame:  # metres in the drawing plane, not the demonstration's units
            axes[1].set_xlabel("y (m, drawing plane)")
            axes[1].set_ylabel("z (m)")
            for ax in axes:
                ax.set_aspect("equal", adjustable="datalim")
        else:
            both = np.vstack([demo.positions, drawing])
            lo, hi = both.min(axis=0), both.max(axis=0)
            pad = 0.05 * float(np.max(hi - lo))
            for ax in axes:
                ax.set_xlim(lo[0] - pad, hi[0] + pad)
                ax.set_ylim(lo[1] - pad, hi[1] + pad)
                ax.set_aspect("equal", adjustable="box")
        fig.tight_layout()
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=80)
        data = buf.getvalue()
        out = Path(self.picture_dir)
        out.mkdir(parents=True, exist_ok=True)
        number = max(self._count, _last_picture_number(out))
        while True:
            number += 1
            path = out / PICTURE_NAME.format(number)
            try:
                write_atomic(path, lambda fh: fh.write(data), overwrite=False)
            except FileExistsError:  # taken since the directory was read
                continue
            self._count = number
            return str(path)

    def feedback(self, demo: Demonstration, response: Response) -> int:
        picture = self._picture(demo, response)
        if response.novel:
            prompt = (f"\nDemonstration {demo.key}: the robot thinks it is something new, "
                      f"none of the {len(set(response.sources))} demonstration(s) it has "
                      "learned, and drew it back as it saw it")
        else:
            prompt = (f"\nDemonstration {demo.key}: the robot thinks it is concept "
                      f"{response.concept!r} (attempt {response.attempt})")
        if picture:
            prompt += f"; its drawing is in {picture}"
        prompt += (".\nIs it a new concept? [y/n] " if response.novel
                   else ".\nIs that right? [y/n] ")
        while True:
            if self._ask is not None:
                answer = self._ask(prompt)
            else:
                self.stdout.write(prompt)
                self.stdout.flush()
                answer = self.stdin.readline()
                if answer == "":
                    raise FeedbackError("console teacher: input ended (EOF) before an "
                                        "answer; answer y or n.")
            answer = answer.strip().lower()
            if answer in ("y", "yes", "+", "+1", "1"):
                return 1
            if answer in ("n", "no", "-", "-1"):
                return -1
            if self._ask is None:
                self.stdout.write("Please answer y or n.\n")


#: File name of the console teacher's n-th picture.
PICTURE_NAME = "answer-{:04d}.png"
_PICTURE_RE = re.compile(r"answer-(\d+)\.png")


def _last_picture_number(directory: Path) -> int:
    """Highest n of an ``answer-<n>.png`` in ``directory`` (0 when there is none)."""
    numbers = [int(m.group(1)) for entry in os.scandir(directory)
               if (m := _PICTURE_RE.fullmatch(entry.name))]
    return max(numbers, default=0)


@dataclass(frozen=True)
class OracleParams:
    """``oracle`` takes no tunable parameter beyond optional shape->concept pairs."""

    #: Extra shape -> concept pairs as a list of ``"shape=concept"`` strings.
    concepts: tuple[str, ...] = ()

    def validate(self) -> None:
        for item in self.concepts:
            if item.count("=") != 1:
                raise ValueError(f"concepts entries are 'shape=concept', got {item!r}")


@dataclass(frozen=True)
class NoisyParams(OracleParams):
    #: Probability that a feedback is flipped.
    p: float = 0.1

    def validate(self) -> None:
        super().validate()
        if not 0.0 <= self.p <= 1.0:
            raise ValueError(f"p must be in [0, 1], got {self.p}")


@dataclass(frozen=True)
class ConsoleParams:
    #: Directory for pictures of the robot's answers ("" for none).
    picture_dir: str = "iloci-answers"


def _pairs(items: tuple[str, ...]) -> dict[str, str]:
    return dict(item.split("=", 1) for item in items)


def _oracle(concepts: tuple[str, ...] = ()) -> OracleTeacher:
    return OracleTeacher(_pairs(concepts))


def _noisy(concepts: tuple[str, ...] = (), p: float = 0.1, seed: int = 0) -> NoisyTeacher:
    return NoisyTeacher(p=p, seed=seed, concepts=_pairs(concepts))


@hookimpl
def iloci_register_teachers(registry) -> None:
    registry.add("oracle", _oracle, params=OracleParams,
                 summary="knows every demonstration's concept")
    registry.add("noisy", _noisy, params=NoisyParams,
                 summary="oracle that errs with probability p (seeded)")
    registry.add("console", ConsoleTeacher, params=ConsoleParams,
                 summary="asks a person y/n on the terminal")

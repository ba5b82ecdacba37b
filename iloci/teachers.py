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
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np

from iloci.data.concepts import concept_of
from iloci.data.files import write_atomic
from iloci.errors import FeedbackError
from iloci.hookspecs import hookimpl
from iloci.interfaces import Demonstration, Response

__all__ = ["OracleTeacher", "NoisyTeacher", "ConsoleTeacher"]


class OracleTeacher:
    """Rewards an answer iff its source demonstration has the shown concept.

    Parameters
    ----------
    concepts : mapping of str to str, optional
        Shape name -> concept, for demonstrations outside LASA. LASA shapes
        are known already.
    """

    def __init__(self, concepts: Mapping[str, str] | None = None) -> None:
        self.concepts = dict(concepts or {})
        self._seen: dict[str, str] = {}

    def concept_of_key(self, key: str) -> str | None:
        """True concept of the demonstration ``"SHAPE/INDEX"``."""
        if key in self._seen:
            return self._seen[key]
        shape = key.rsplit("/", 1)[0]
        return self.concepts.get(shape) or concept_of(shape)

    def true_concept(self, demo: Demonstration) -> str:
        c = demo.true_concept or self.concepts.get(demo.shape) or concept_of(demo.shape)
        if c is None:
            raise FeedbackError(
                f"oracle teacher does not know the concept of {demo.key!r}: give the "
                "Demonstration a concept, or name it in the teacher's config, "
                f'[teacher] concepts = ["{demo.shape}=CONCEPT"] (in Python: '
                f'concepts={{"{demo.shape}": "CONCEPT"}}).')
        self._seen[demo.key] = c
        return c

    def feedback(self, demo: Demonstration, response: Response) -> int:
        truth = self.true_concept(demo)
        if response.source is None:
            raise FeedbackError("oracle teacher needs Response.source (the demonstration "
                                "the answering entry stands for).")
        return 1 if self.concept_of_key(response.source) == truth else -1


class NoisyTeacher(OracleTeacher):
    """An oracle that flips each feedback with probability ``p``.

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
        self._rng = np.random.default_rng(seed)

    def feedback(self, demo: Demonstration, response: Response) -> int:
        value = super().feedback(demo, response)
        return -value if self._rng.random() < self.p else value


class ConsoleTeacher:
    """Asks a person whether the robot's answer is right (y/n).

    Parameters
    ----------
    picture_dir : str
        Directory for a PNG of each answer (demonstration beside the robot's
        drawing: :attr:`Response.drawing <iloci.interfaces.Response.drawing>`,
        the executed pen path when a simulator is configured) when
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
        axes = fig.subplots(1, 2)
        axes[0].plot(demo.positions[:, 0], demo.positions[:, 1], "k-")
        axes[0].plot(*demo.positions[0], "go")
        axes[0].set_title(f"shown: {demo.key}")
        # with a simulator, the teacher judges what the arm drew, not what
        # the network meant to draw
        drawing = response.drawing
        axes[1].plot(drawing[:, 0], drawing[:, 1], "b-")
        axes[1].plot(*drawing[0], "go")
        drawn = "drew" if response.execution is not None else "generated"
        axes[1].set_title(f"robot {drawn}: concept {response.concept}")
        for ax in axes:
            ax.set_aspect("equal", adjustable="datalim")
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
        prompt = (f"\nDemonstration {demo.key}: the robot thinks it is concept "
                  f"{response.concept!r} (attempt {response.attempt})")
        if picture:
            prompt += f"; its drawing is in {picture}"
        prompt += ".\nIs that right? [y/n] "
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

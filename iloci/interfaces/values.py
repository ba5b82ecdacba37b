"""The values components exchange: a demonstration shown, a response performed, its execution.

Arrays are numpy ``float64``; shapes use the letters of :mod:`iloci.interfaces`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
import warnings
from typing import Any

import numpy as np

from iloci.errors import InvalidDemonstrationError, TimeUnitWarning
from iloci.validation import check_array, is_integer

__all__ = ["Demonstration", "Execution", "Response", "LONGEST_STROKE_S", "MAX_POSITION"]


#: Longest plausible duration of one drawn stroke (s): a person draws a
#: shape in a few seconds (LASA's take 0.6 to 6 s); longer time stamps
#: with steps of 1 or more are read as milliseconds.
LONGEST_STROKE_S = 120.0

#: Largest absolute coordinate a demonstration may have: squares of 1e100 are
#: 1e200, so a path's length, extents and DTW's squared distances stay finite
#: in float64 (max about 1.8e308). No drawing's unit comes near it: beyond, a
#: value is corrupt (the bad-data audit's 1e200 file overflowed in the spline).
MAX_POSITION = 1e100


def _check_time_unit(t: np.ndarray, label: str) -> None:
    """Warn (TimeUnitWarning) when time stamps look like milliseconds, not seconds."""
    duration = float(t[-1] - t[0])
    step = float(np.median(np.diff(t)))
    if duration > LONGEST_STROKE_S and step >= 1.0:
        warnings.warn(
            f"time stamps of {label} span {duration:.6g} s in steps of {step:.3g} s; "
            f"iloci reads seconds, and these look like milliseconds (the stroke would "
            f"last {duration / 1000:.3g} s). Divide them by 1000 (or pass times=None for "
            "sample numbers).", TimeUnitWarning, stacklevel=4)


@dataclass(frozen=True, eq=False, init=False)
class Demonstration:
    """One pen trajectory shown by the teacher, validated on creation.

    Parameters
    ----------
    positions : array_like, shape (N, 2)
        Pen positions in the teacher's frame (any unit; only the shape
        matters, it is scaled into the robot's drawing plane). ``N >= 3``.
    times : array_like, shape (N,), optional
        Time stamps (s), strictly increasing. Defaults to ``0, 1, ..., N-1``
        (sample numbers: the order, not a pace); :attr:`timed` is then
        False, and the robot draws its answer at a default pace
        (:data:`iloci.sensorimotor.pipeline.UNTIMED_PACE`), not one second
        per sample.
    shape : str
        Name of the drawn shape (e.g. ``"GShape"``), or a file name.
    index : int
        Index of this demonstration among those of its shape.
    true_concept : str or None
        The concept the demonstration really belongs to (``"Leaf"`` for
        ``Leaf_1/3``), known to an oracle teacher and to evaluation, never
        to the learner; ``None`` for a live demonstration. (*Concept* alone
        means the robot's concept label, ``"c3"``.)
    concept : str or None
        Deprecated spelling of ``true_concept`` (a DeprecationWarning).

    Raises
    ------
    InvalidDemonstrationError
        Wrong shape, NaN or inf, fewer than 3 points, zero extent, or
        non-increasing times.
    """

    positions: np.ndarray
    times: np.ndarray | None = None
    shape: str = "demo"
    index: int = 0
    true_concept: str | None = None

    def __init__(self, positions: Any, times: Any = None, shape: str = "demo",
                 index: int = 0, true_concept: str | None = None, *,
                 concept: str | None = None) -> None:
        if concept is not None:
            if true_concept is not None and true_concept != concept:
                raise InvalidDemonstrationError(
                    "give the true concept once, as true_concept= (concept= is its "
                    "deprecated spelling).")
            warnings.warn("Demonstration(concept=...) is deprecated: pass true_concept= "
                          "(concept means the robot's concept label).", DeprecationWarning,
                          stacklevel=2)
            true_concept = concept
        if not isinstance(shape, str) or not shape:
            raise InvalidDemonstrationError(f"shape must be a non-empty str (the key is "
                                            f"SHAPE/INDEX), got {shape!r}.")
        if not is_integer(index) or index < 0:
            raise InvalidDemonstrationError(f"index must be an int >= 0 (the key is "
                                            f"SHAPE/INDEX), got {index!r}.")
        if true_concept is not None and not isinstance(true_concept, str):
            raise InvalidDemonstrationError(f"true_concept must be a str or None, got "
                                            f"{true_concept!r}.")
        index = int(index)
        object.__setattr__(self, "_timed", times is not None)
        for name, value in (("positions", positions), ("times", times), ("shape", shape),
                            ("index", index), ("true_concept", true_concept)):
            object.__setattr__(self, name, value)
        self.__post_init__()

    @property
    def concept(self) -> str | None:
        """Deprecated: :attr:`true_concept` (a DeprecationWarning)."""
        warnings.warn("Demonstration.concept is deprecated: read true_concept (concept "
                      "means the robot's concept label).", DeprecationWarning, stacklevel=2)
        return self.true_concept

    def __post_init__(self) -> None:
        label = f"demonstration {self.key!r}"
        pos = check_array(self.positions, f"positions of {label}", ("N", 2), finite=False,
                          error=InvalidDemonstrationError,
                          hint=" Pass one row per sample with 2 columns.")
        if len(pos) < 3:
            raise InvalidDemonstrationError(
                f"{label} has {len(pos)} point(s); at least 3 are needed to "
                "define a motion (and to read it as a drawing, [sensorimotor] min_points, "
                "5 by default, once the pen's rests are trimmed)."
            )
        bad = ~np.isfinite(pos)
        if bad.any():
            row = int(np.argwhere(bad)[0, 0])
            raise InvalidDemonstrationError(
                f"{label} contains NaN or inf (first at row {row}); remove or "
                "interpolate missing samples before teaching."
            )
        size = np.abs(pos).max(axis=1)
        if float(size.max()) > MAX_POSITION:
            row = int(np.argmax(size))
            raise InvalidDemonstrationError(
                f"{label} has a position of {float(size[row]):.3g} (row {row}), beyond "
                f"{MAX_POSITION:.0e}: no unit of a drawing reaches that (its path's length "
                "would overflow). A corrupt value, or a unit far too small? Remove the "
                "sample or rescale the drawing.")
        extent = np.ptp(pos, axis=0)
        if not np.any(extent > 1e-12 * max(1.0, float(size.max()))):
            what = (f"all {len(pos)} points are equal, so there is no motion to imitate"
                    if not np.any(extent > 0) else
                    f"its {len(pos)} points lie within {float(extent.max()):.3g} of each other, "
                    "too close to tell apart (below 1e-12 of the drawing's unit or size); "
                    "rescale it")
            raise InvalidDemonstrationError(f"{label} has zero extent: {what}.")
        if self.times is None:
            t = np.arange(len(pos), dtype=np.float64)
        else:
            t = np.asarray(check_array(self.times, f"times of {label}", (None,), finite=False,
                                       error=InvalidDemonstrationError), dtype=np.float64)
            if t.shape != (len(pos),):
                raise InvalidDemonstrationError(
                    f"times of {label} must have shape ({len(pos)},) to match "
                    f"the positions, got {t.shape}."
                )
            if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
                raise InvalidDemonstrationError(
                    f"times of {label} must be finite and strictly increasing."
                )
            _check_time_unit(t, label)
        pos = pos.copy()
        t = t.copy()
        pos.flags.writeable = False
        t.flags.writeable = False
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "times", t)

    @property
    def timed(self) -> bool:
        """Whether time stamps were given (False: :attr:`times` are sample numbers)."""
        return bool(getattr(self, "_timed", True))

    @property
    def key(self) -> str:
        """Stable identifier, ``"SHAPE/INDEX"``."""
        return f"{self.shape}/{self.index}"

    def __len__(self) -> int:
        return len(self.positions)

    def __repr__(self) -> str:
        return (f"Demonstration({self.key!r}, N={len(self.positions)}, "
                f"true_concept={self.true_concept!r})")


@dataclass(frozen=True)
class Execution:
    """What a simulated (or real) arm actually did.

    Attributes
    ----------
    joint_path : ndarray, shape (T, J)
        Joint angles reached (rad).
    end_effector : ndarray, shape (T, 3)
        Pen-tip positions reached (m, torso frame).
    dt : float
        Time step (s).
    """

    joint_path: np.ndarray
    end_effector: np.ndarray
    dt: float


@dataclass(frozen=True)
class Response:
    """The robot's answer to a demonstration, as the teacher sees it.

    Attributes
    ----------
    concept : str
        The concept the robot guessed (its own label, e.g. ``"c3"``).
    motion : ndarray, shape (T, 2)
        The pen path the robot drew in the drawing plane (m, y-z).
    joint_path : ndarray, shape (T, J), optional
        The joint path it performed.
    source : str, optional
        Key of the demonstration the answering memory entry stands for
        (a prototype's medoid). Lets an oracle teacher judge the answer.
    sources : tuple of str
        Keys of every demonstration the answering entry stands for.
    execution : Execution, optional
        What the simulator executed, when one is configured.
    attempt : int
        1 for the first guess on this demonstration, 2 for the second, ...
    novel : bool
        The novelty answer: the robot finds the demonstration unlike every
        concept it knows and imitates it back as something new (``motion``
        is its reproduction of what it saw; ``concept`` the label the new
        concept would get; ``source`` is ``None``; ``sources`` every
        demonstration its memory stands for, i.e. what it claims the
        demonstration is none of). +1 means "yes, that is new": the robot
        founds the concept; -1 sends it back to guessing among what it
        knows.
    extra : mapping
        Back-end details (the learner's: ``entry``, ``generation_error``,
        ``clipped``).
    dt : float, optional
        Time between two rows of ``joint_path`` (s).
    teacher_drawing : ndarray, shape (T, 2), optional
        :attr:`drawing` in the frame of the demonstration answered: its
        units and orientation, scaled and centred as that demonstration
        was fitted into the drawing plane, so the two can be shown side by
        side on equal axes. ``None`` when the response answers no
        demonstration (e.g. ``Agent.respond``).
    """

    concept: str
    motion: np.ndarray
    joint_path: np.ndarray | None = None
    source: str | None = None
    sources: tuple[str, ...] = ()
    execution: Execution | None = None
    attempt: int = 1
    extra: Mapping[str, Any] = field(default_factory=dict)
    novel: bool = False
    dt: float | None = None
    teacher_drawing: np.ndarray | None = None

    @property
    def drawing(self) -> np.ndarray:
        """The pen path to show the teacher, shape (T, 2) (m, y-z in the drawing plane).

        When a simulator executed the response, what the arm actually drew:
        ``execution.end_effector`` projected on the (vertical, x = const)
        plane. Otherwise ``motion``, the path the network generated.
        """
        if self.execution is None:
            return np.asarray(self.motion, dtype=np.float64)
        return np.asarray(self.execution.end_effector, dtype=np.float64)[:, 1:3]

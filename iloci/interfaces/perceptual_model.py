"""The perceptual model's interface: an RNNPB (shared weights, one PB vector per sequence)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Protocol, runtime_checkable

import numpy as np


__all__ = ["PerceptualModel"]


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

        Notes
        -----
        A model may also take a keyword ``learning_rate`` (float): the
        weights' learning rate of this call only. The learner passes it
        to rehearse a trained network, and only to a model whose
        ``params`` has a ``rehearsal_learning_rate`` (every first-party
        RNNPB back end: ``[perceptual_model] rehearsal_learning_rate``,
        docs/method.md, "The rehearsal learning rate"); a model without
        such a field is called with the three arguments above.
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

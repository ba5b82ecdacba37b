"""Motions <-> the RNNPB's sequences of relative sensorimotor displacements.

The paper feeds the network relative displacements of the sensory and motor
data rather than absolute values, so that what is learned does not depend
on where the shape was drawn. Per step ``t`` of a motion with plane points
``(y, z)`` and joint angles ``q1..qJ`` (``J`` joints of the robot: 4 for the
Nao arm)::

    row t = ([y, z, q1, ..., qJ][t + 1] - [y, z, q1, ..., qJ][t]) / scale

a sequence of ``T - 1`` rows of ``D = 2 + J`` features (6 for the Nao).
``scale`` (one value per channel) is fitted on the learning data so that the largest displacement of
each channel maps to ``limit`` (default 0.9): inside the range of a tanh or
sigmoid-like output layer with headroom for unseen demonstrations. The
absolute first sample ``start = [y0, z0, q1_0..qJ_0]`` is kept beside the
sequence (the paper's initialInfo), and :meth:`SensorimotorEncoder.decode`
inverts the encoding exactly (a cumulative sum).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from iloci.errors import InvalidInputError, NotFittedError
from iloci.sensorimotor.pipeline import Motion
from iloci.validation import check_array

__all__ = ["FEATURES", "SensorimotorEncoder", "feature_names"]

#: Names of the ``D = 6`` features of a sequence row for the Nao arm (J = 4).
FEATURES = ("dy", "dz", "dq1", "dq2", "dq3", "dq4")


def feature_names(joints: int) -> tuple[str, ...]:
    """Names of the ``D = 2 + joints`` features of a row: dy, dz, dq1..dqJ."""
    return ("dy", "dz", *(f"dq{i + 1}" for i in range(joints)))


class SensorimotorEncoder:
    """Scaled relative displacements ``[dy, dz, dq1..dqJ]`` of a motion.

    ``J`` is fixed by the motions it is fitted on (every motion it encodes
    afterwards must have as many joints).

    Parameters
    ----------
    limit : float
        After :meth:`fit`, the largest absolute displacement of each channel
        in the learning data encodes to ``limit``.

    Attributes
    ----------
    scale_ : ndarray, shape (D,)
        Per-channel divisor (m for dy, dz; rad for dq), set by :meth:`fit`.
    """

    def __init__(self, limit: float = 0.9) -> None:
        if not (np.isfinite(limit) and limit > 0):
            raise InvalidInputError(f"limit must be a positive number, got {limit}.")
        self.limit = float(limit)
        self.scale_: np.ndarray | None = None

    def __repr__(self) -> str:
        fitted = "unfitted" if self.scale_ is None else f"scale={np.round(self.scale_, 6).tolist()}"
        return f"SensorimotorEncoder(limit={self.limit}, {fitted})"

    @property
    def width(self) -> int | None:
        """``D = 2 + J`` once fitted, else None."""
        return None if self.scale_ is None else len(self.scale_)

    def _raw(self, motion: Motion, check: bool = True) -> np.ndarray:
        if not isinstance(motion, Motion):
            raise InvalidInputError(f"expected a Motion, got {type(motion).__name__}; build one "
                                    "with iloci.sensorimotor.pipeline.to_motion.")
        J = motion.joint_path.shape[1]
        if check and self.scale_ is not None and J != len(self.scale_) - 2:
            raise InvalidInputError(f"motion {motion.demo_key!r} has {J} joints; this "
                                    f"encoding was fitted on {len(self.scale_) - 2} (another "
                                    "robot's motions).")
        if len(motion) < 2:
            raise InvalidInputError(f"motion {motion.demo_key!r} has {len(motion)} step(s); "
                                    "at least 2 are needed for a displacement.")
        return np.hstack([motion.plane_points, motion.joint_path])

    def fit(self, motions: Iterable[Motion]) -> SensorimotorEncoder:
        """Fit the per-channel scale on learning data.

        Parameters
        ----------
        motions : iterable of Motion
            At least one.

        Returns
        -------
        self
        """
        deltas = [np.diff(self._raw(m, check=False), axis=0) for m in motions]
        if not deltas:
            raise InvalidInputError("fit needs at least one motion.")
        if len({d.shape[1] for d in deltas}) > 1:
            raise InvalidInputError("fit needs motions of one robot: they have "
                                    f"{sorted({d.shape[1] - 2 for d in deltas})} joints.")
        peak = np.abs(np.vstack(deltas)).max(axis=0)
        # a channel that never moves in the learning data (a joint that cannot
        # move the pen, such as a roll about the pen's own axis) takes the
        # median scale of the moving channels of its kind, not 1: whatever the
        # network outputs there is decoded at the size of the other joints'
        # motion, not as up to ``limit`` rad per step
        scale = peak / self.limit
        for group in (slice(0, 2), slice(2, None)):
            g = scale[group]
            moving = g[g > 0]
            g[g == 0] = float(np.median(moving)) if moving.size else 1.0
        self.scale_ = scale
        return self

    def _check_fitted(self) -> np.ndarray:
        if self.scale_ is None:
            raise NotFittedError("the SensorimotorEncoder is not fitted: call fit(motions) on "
                                 "the learning data, or restore it with from_state().")
        return self.scale_

    def encode(self, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
        """Encode one motion.

        Parameters
        ----------
        motion : Motion
            ``T`` steps.

        Returns
        -------
        sequence : ndarray, shape (T - 1, D)
            Scaled ``[dy, dz, dq1..dqJ]`` per step.
        start : ndarray, shape (D,)
            Absolute first sample ``[y, z, q1..qJ]`` (m, rad).
        """
        scale = self._check_fitted()
        raw = self._raw(motion)
        return np.diff(raw, axis=0) / scale, raw[0].copy()

    def encode_all(self, motions: Iterable[Motion]) -> tuple[list[np.ndarray], np.ndarray]:
        """:meth:`encode` each motion.

        Returns
        -------
        sequences : list of ndarray, each (T_i - 1, D)
        starts : ndarray, shape (B, D)
        """
        scale = self._check_fitted()
        pairs = [self.encode(m) for m in motions]
        return [s for s, _ in pairs], np.array([st for _, st in pairs]).reshape(-1, len(scale))

    def decode(self, sequence: np.ndarray, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Invert :meth:`encode`.

        Parameters
        ----------
        sequence : ndarray, shape (T - 1, D)
            Scaled displacements (e.g. generated by the RNNPB).
        start : ndarray, shape (D,)
            Absolute first sample ``[y, z, q1..qJ]``.

        Returns
        -------
        plane_points : ndarray, shape (T, 2)
            ``(y, z)`` (m).
        joint_path : ndarray, shape (T, J)
            Joint angles (rad). Not clipped to the joint limits: a generated
            sequence may leave them, which the caller can check.
        """
        scale = self._check_fitted()
        D = len(scale)
        seq = _finite(sequence, "sequence", (None, D))
        st = _finite(start, "start", (D,))
        raw = np.vstack([st, st + np.cumsum(seq * scale, axis=0)])
        return raw[:, :2], raw[:, 2:]

    def state(self) -> dict[str, np.ndarray]:
        """The fitted encoder as a flat dict of arrays (no pickle)."""
        return {"scale": self._check_fitted().copy(), "limit": np.array(self.limit)}

    @classmethod
    def from_state(cls, state: Mapping[str, np.ndarray]) -> SensorimotorEncoder:
        """Rebuild an encoder from :meth:`state`."""
        try:
            scale = np.asarray(state["scale"], dtype=np.float64)
            limit = float(np.asarray(state["limit"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise InvalidInputError(f"encoder state needs 'scale' (D,) and 'limit' (a number); "
                                    f"{exc!r}.") from None
        if scale.ndim != 1 or len(scale) < 3 or not np.all(np.isfinite(scale)) \
                or np.any(scale <= 0):
            raise InvalidInputError(f"encoder state 'scale' must be 2 + J >= 3 positive "
                                    f"numbers, got {scale!r}.")
        enc = cls(limit)
        enc.scale_ = scale.copy()
        return enc


def _finite(a: np.ndarray, name: str, shape: tuple[int | None, ...]) -> np.ndarray:
    return check_array(a, name, shape)

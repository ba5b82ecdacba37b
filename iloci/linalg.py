"""Small float64 matrix products in one order of operations, the same bits on every CPU.

numpy's ``@`` (and ``dot``, and ``linalg.norm`` of a flat vector) hand
float64 products to OpenBLAS, which picks its kernels by CPU model at load
time: on one x86-64 machine ``OPENBLAS_CORETYPE=Haswell`` and ``SkylakeX``
give different last bits for the same product. Through the drawing's
mapping into the robot's plane, inverse kinematics and the tilt search,
those bits reached the learned memory, so the same seed learned slightly
different memories on different machines (found on 2026-12-02, the golden
session of ``tests/test_golden.py``). The products on that path are small
(a drawing's points times a 2 x 2 or 3 x 3 matrix); :func:`matmul` writes
them out: ``C[i, j] = sum_k A[i, k] B[k, j]`` from +0, ``k`` ascending,
each product rounded, then added (numpy's element-wise ``*`` and ``+``:
correctly rounded IEEE operations whatever the SIMD width).
"""

from __future__ import annotations

import numpy as np

__all__ = ["matmul"]


def matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` in float64, summed over ``k`` in ascending order from +0 (module docstring).

    Parameters
    ----------
    a : array_like, shape (..., K)
        A vector (K,) or a stack of rows (N, K).
    b : array_like, shape (K, M) or (K,)

    Returns
    -------
    ndarray of float64
        Shape (..., M), or (...) for a vector ``b``: what ``a @ b`` returns.

    Raises
    ------
    ValueError
        ``a``'s last axis and ``b``'s first differ in length.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape[-1] != b.shape[0]:
        raise ValueError(f"matmul: shapes {a.shape} and {b.shape} do not align "
                         f"({a.shape[-1]} != {b.shape[0]}).")
    acc = np.zeros(a.shape[:-1] + b.shape[1:])
    for k in range(b.shape[0]):
        term = a[..., k] if b.ndim == 1 else a[..., k, None]
        acc = acc + term * b[k]
    return acc

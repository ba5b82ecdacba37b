"""iloci.linalg.matmul: small float64 products in one order, the same bits on every CPU."""

from __future__ import annotations

import numpy as np
import pytest

from iloci.linalg import matmul


def test_matmul_sums_in_ascending_order_and_agrees_with_numpy():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(50, 3)), rng.normal(size=(3, 2))
    got = matmul(a, b)
    want = np.zeros((50, 2))
    for k in range(3):                       # +0, then k ascending, product then sum
        want = want + a[:, k:k + 1] * b[k]
    np.testing.assert_array_equal(got, want)
    np.testing.assert_allclose(got, a @ b, rtol=0, atol=1e-14)
    v = rng.normal(size=3)
    assert matmul(v, b).shape == (2,) and matmul(a, v).shape == (50,)
    assert float(matmul(v, v)) == (0.0 + v[0] * v[0]) + v[1] * v[1] + v[2] * v[2]


def test_matmul_of_misaligned_shapes_says_which():
    with pytest.raises(ValueError, match=r"\(4, 3\) and \(2, 2\)"):
        matmul(np.zeros((4, 3)), np.zeros((2, 2)))

"""The banded LU solve of the HHT Newton matrix against numpy, over sizes around its block length."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from casflex.integrators.band import BLOCK, band_lu


def _matrix(n: int, rng, shuffle: bool) -> np.ndarray:
    """A diagonally dominant, structurally symmetric, unsymmetric matrix: a chain of 3x3 node blocks
    (as a beam's), its dofs in a random order when ``shuffle`` (the solver must find the band)."""
    A = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - 5), min(n, i + 6)):
            if (i // 3) - (j // 3) in (-1, 0, 1):
                A[i, j] = rng.uniform(-1, 1)
        A[i, i] = 12.0 + rng.uniform(0, 1)
    if shuffle:
        p = rng.permutation(n)
        A = A[np.ix_(p, p)]
    return A


def _solve(A: np.ndarray, b: np.ndarray, expand: bool) -> tuple[np.ndarray, int]:
    r, c = np.nonzero(A.T)  # column-major nonzeros, as CasADi keeps them
    sp = ca.Sparsity.triplet(A.shape[0], A.shape[1], c.tolist(), r.tolist())
    lu = band_lu(sp)
    f, bw = (lu.solve.expand() if expand else lu.solve), lu.bandwidth
    nz = [A[i, j] for j, i in zip(r, c, strict=True)]
    return np.array(f(nz, b)).ravel(), bw


@pytest.mark.parametrize("n", [1, 2, 3, BLOCK - 1, BLOCK, BLOCK + 1, 3 * BLOCK + 2, 200])
@pytest.mark.parametrize("shuffle", [False, True])
def test_band_solve_matches_a_dense_solve(n, shuffle):
    rng = np.random.default_rng(n)
    A = _matrix(n, rng, shuffle)
    b = rng.normal(size=n)
    x, bw = _solve(A, b, expand=n <= BLOCK + 1)
    # 1e-13: LU of a diagonally dominant matrix (no pivoting needed), a few hundred eps of |x|
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=0, atol=1e-13 * np.abs(x).max())
    assert bw <= 5  # the chain of 3x3 blocks is found again, whatever the order

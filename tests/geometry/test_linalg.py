"""The numba Cholesky solve shared by the profiler's refinement and the arm simulator."""

import numpy as np
import pytest

from posekit.geometry import cholesky_solve


@pytest.mark.parametrize("n", [3, 6])
@pytest.mark.parametrize("ridge", [0.0, 1e-3, 10.0])
def test_matches_numpy_solve(n, ridge):
    rng = np.random.default_rng(n)
    J = rng.normal(size=(n, n + 2))
    A = J @ J.T + 0.1 * np.eye(n)
    b = rng.normal(size=n)
    x, L = np.empty(n), np.zeros((n, n))
    assert cholesky_solve(A, b, x, L, ridge)
    np.testing.assert_allclose(x, np.linalg.solve(A + ridge * np.diag(np.diag(A)), b), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.tril(L), np.linalg.cholesky(A + ridge * np.diag(np.diag(A))), rtol=1e-10)


def test_not_positive_definite_is_reported():
    A = np.diag([1.0, -2.0, 3.0])
    assert not cholesky_solve(A, np.ones(3), np.empty(3), np.zeros((3, 3)), 0.0)

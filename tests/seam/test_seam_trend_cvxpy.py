"""The trend filter (eq. 10, Clarabel's own API) against the same problem written in cvxpy.

cvxpy is not a dependency of posekit (the ``test`` extra brings it); without it this file skips.
"""

import numpy as np
import pytest

from posekit.seam.engine.trend import trend_filter

cp = pytest.importorskip("cvxpy")


def _cvxpy_trend(y, lam, eps):
    """Eq. 10 as the filter used to state it, in cvxpy, solved by Clarabel through cvxpy."""
    centre = y.mean(axis=0)
    scale = max(float(np.abs(y - centre).max()), eps)
    ys = (y - centre) / scale
    z = cp.Variable(y.shape)
    w = z[:-2] - 2 * z[1:-1] + z[2:]
    problem = cp.Problem(cp.Minimize(cp.sum_squares(ys - z) + (lam / scale) * cp.sum(cp.abs(w))),
                         [cp.abs(ys - z) <= eps / scale])
    problem.solve(solver=cp.CLARABEL)
    assert problem.status == cp.OPTIMAL
    return z.value * scale + centre, problem.value


def _objective(y, z, lam):
    w = z[:-2] - 2 * z[1:-1] + z[2:]
    return float(np.sum((y - z) ** 2) + lam * np.abs(w).sum())


def _paths():
    rng = np.random.default_rng(7)
    t = np.arange(100.0)
    corners = np.c_[t, np.interp(t, [0, 30, 60, 99], [0, 15, -5, 10]), np.interp(t, [0, 45, 99], [0, 5, 0])]
    s = np.linspace(0.0, 2 * np.pi, 300)
    arc = np.c_[400.0 + 150.0 * np.cos(s), 150.0 * np.sin(s), 300.0 + 20.0 * s]         # a helix, mm
    walk = np.cumsum(rng.normal(0.0, 0.3, size=(80, 3)), axis=0)
    return {
        "corners": (corners, 100.0, 0.01),
        "noisy corners": (corners + rng.uniform(-0.02, 0.02, size=corners.shape), 100.0, 0.05),
        "helix": (arc, 10.0, 0.02),
        "random walk": (walk, 1.0, 0.1),
        "lam 0": (walk, 0.0, 0.05),
    }


@pytest.mark.parametrize("name", list(_paths()))
def test_same_solution_as_cvxpy(name):
    y, lam, eps = _paths()[name]
    res = trend_filter(y, lam=lam, eps_mm=eps)
    z_ref, _ = _cvxpy_trend(y, lam, eps)
    assert res.status == "optimal"
    # strictly convex in z: one solution, which both reach to the solver's tolerance (< 1e-4 mm here)
    np.testing.assert_allclose(res.z, z_ref, rtol=0, atol=1e-2 * eps)
    f, f_ref = _objective(y, res.z, lam), _objective(y, z_ref, lam)
    assert f <= f_ref * (1 + 1e-6) + 1e-9
    assert res.max_error_mm <= eps * (1 + 1e-6)


def test_same_knots_as_cvxpy_on_the_corner_path():
    y, lam, eps = _paths()["corners"]
    z_ref, _ = _cvxpy_trend(y, lam, eps)
    w = z_ref[:-2] - 2 * z_ref[1:-1] + z_ref[2:]
    scale = np.abs(y - y.mean(axis=0)).max()
    knots_ref = [0, *(np.flatnonzero(np.abs(w / scale).max(axis=1) > 1e-6) + 1), len(y) - 1]
    assert trend_filter(y, lam=lam, eps_mm=eps).knots.tolist() == knots_ref == [0, 30, 45, 60, 99]

import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given
from numpy.testing import assert_allclose, assert_array_equal
from scipy.linalg import expm, logm

from posekit.errors import GeometryError
from posekit.geometry import (
    matrix_from_rotation_vector,
    se3_exp,
    se3_log,
    so3_hat,
    so3_vee,
)
from posekit.geometry._se3 import _c_coefficient, _d_coefficient
from tests.strategies import (
    FAST,
    batches,
    finite_floats,
    rotation_vectors,
    transforms,
    translations_mm,
    twists,
)

R_180_X = np.diag([1.0, -1.0, -1.0])
R_90_Z = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
# Hand-derived: a quarter turn about z with rho = x moves along the arc, V rho = (2/pi, 2/pi, 0).
QUARTER_TURN_Z = (
    np.array([1.0, 0.0, 0.0, 0.0, 0.0, np.pi / 2]),
    R_90_Z,
    [2 / np.pi, 2 / np.pi, 0.0],
)
# (twist [rho, phi], R, t): hand-derived reference values.
REFERENCE = [
    (np.zeros(6), np.eye(3), [0.0, 0.0, 0.0]),
    (np.array([1.0, 2.0, 3.0, 0.0, 0.0, 0.0]), np.eye(3), [1.0, 2.0, 3.0]),
    (np.array([0.0, 0.0, 0.0, np.pi, 0.0, 0.0]), R_180_X, [0.0, 0.0, 0.0]),
    (np.array([0.0, 0.0, 5.0, 0.0, 0.0, np.pi / 2]), R_90_Z, [0.0, 0.0, 5.0]),  # screw along z
    QUARTER_TURN_Z,
]


def twist_matrix(xi):
    """The 4x4 matrix hat(xi) = [[hat(phi), rho], [0, 0]], written out by hand."""
    (r1, r2, r3), (p1, p2, p3) = xi[:3], xi[3:]
    return np.array(
        [[0, -p3, p2, r1], [p3, 0, -p1, r2], [-p2, p1, 0, r3], [0, 0, 0, 0]], dtype=float
    )


def bernoulli_numbers(n):
    """Exact Bernoulli numbers B_0..B_n (Akiyama-Tanigawa; B_1 = +1/2, unused here)."""
    a, b = [Fraction(0)] * (n + 1), []
    for m in range(n + 1):
        a[m] = Fraction(1, m + 1)
        for j in range(m, 0, -1):
            a[j - 1] = j * (a[j - 1] - a[j])
        b.append(a[0])
    return b


# --------------------------------------------------------------------------- reference values
@pytest.mark.parametrize(("xi", "R", "t"), REFERENCE)
def test_se3_exp_and_log_reference(xi, R, t):
    T = se3_exp(xi)
    assert_allclose(T[:3, :3], R, atol=1e-15)
    assert_allclose(T[:3, 3], t, atol=1e-15)
    assert_array_equal(T[3], [0.0, 0.0, 0.0, 1.0])
    assert_allclose(se3_log(T), xi, atol=1e-14)


def test_so3_hat_and_vee_reference():
    K = np.array([[0.0, -3.0, 2.0], [3.0, 0.0, -1.0], [-2.0, 1.0, 0.0]])
    assert_array_equal(so3_hat([1.0, 2.0, 3.0]), K)
    assert_array_equal(so3_vee(K), [1.0, 2.0, 3.0])
    assert_array_equal(so3_vee(K + np.eye(3) + 5.0), [1.0, 2.0, 3.0])  # only the skew part counts


def test_series_coefficients_against_long_series():
    """C = (t - sin t) / t^3 and D = (1 - (t/2) cot(t/2)) / t^2 on both sides of the switch."""
    theta = np.array(
        [0, 1e-9, 1e-5, 1e-3, 0.05, 0.0999, 0.1, 0.1001, 0.3, 1, 2, 3, np.pi - 1e-7, np.pi]
    )
    # Exact rational series coefficients: C = sum (-1)^k t^2k / (2k+3)!,
    # D = sum_{n>=1} |B_2n| t^(2n-2) / (2n)! (Bernoulli numbers; converges for t < 2 pi).
    c_coef = [float(Fraction((-1) ** k, math.factorial(2 * k + 3))) for k in range(30)]
    b = bernoulli_numbers(80)
    d_coef = [float(abs(b[2 * n]) / math.factorial(2 * n)) for n in range(1, 41)]
    c_ref = [math.fsum(c * t ** (2 * k) for k, c in enumerate(c_coef)) for t in theta]
    d_ref = [math.fsum(d * t ** (2 * k) for k, d in enumerate(d_coef)) for t in theta]
    rtol = 2e-15 + 40 * np.finfo(float).eps / np.maximum(theta, 0.1) ** 2
    assert np.all(np.abs(_c_coefficient(theta) - c_ref) <= rtol * np.abs(c_ref))
    assert np.all(np.abs(_d_coefficient(theta) - d_ref) <= rtol * np.abs(d_ref))


# --------------------------------------------------------------------------- properties
@FAST
@given(translations_mm(), rotation_vectors(include_pi=True))
def test_se3_exp_matches_matrix_exponential(rho, phi):
    xi = np.concatenate([rho, phi])
    T, T_ref = se3_exp(xi), expm(twist_matrix(xi))
    assert_allclose(T[:3, :3], T_ref[:3, :3], atol=1e-12)
    assert_allclose(T[:3, 3], T_ref[:3, 3], atol=1e-9)
    assert_allclose(T[:3, :3], matrix_from_rotation_vector(phi), atol=1e-14)
    assert_array_equal(T[3], [0.0, 0.0, 0.0, 1.0])


@FAST
@given(twists())
def test_se3_log_of_exp_is_identity_below_pi(xi):
    xi_back = se3_log(se3_exp(xi))
    assert_allclose(xi_back[3:], xi[3:], atol=1e-13)
    assert_allclose(xi_back[:3], xi[:3], atol=1e-9)


@FAST
@given(transforms(include_pi=True))
def test_se3_exp_of_log_is_identity(T):
    xi = se3_log(T)
    assert np.linalg.norm(xi[3:]) <= np.pi + 1e-14
    assert_allclose(se3_exp(xi), T, atol=1e-9)


@FAST
@given(translations_mm(), rotation_vectors().filter(lambda v: np.linalg.norm(v) < 3.0))
def test_se3_log_matches_matrix_logarithm(rho, phi):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = matrix_from_rotation_vector(phi), rho
    L = np.real(logm(T))
    xi_ref = np.concatenate([L[:3, 3], [L[2, 1], L[0, 2], L[1, 0]]])
    assert_allclose(se3_log(T), xi_ref, atol=1e-8)


def test_se3_log_at_exactly_pi():
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R_180_X, [10.0, -20.0, 30.0]
    xi = se3_log(T)
    assert abs(xi[3]) == pytest.approx(np.pi, abs=1e-15)
    assert_allclose(xi[4:], 0.0, atol=1e-15)
    assert_allclose(se3_exp(xi), T, atol=1e-12)


@FAST
@given(rotation_vectors(include_pi=True), translations_mm())
def test_so3_hat_is_the_cross_product(v, w):
    K = so3_hat(v)
    assert_allclose(K @ w, np.cross(v, w), atol=1e-9)
    assert_array_equal(K, -K.T)
    assert_array_equal(so3_vee(K), v)


@FAST
@given(batches(twists(include_pi=True), max_size=6))
def test_batch_equals_stacked_singles(xis):
    Ts = se3_exp(xis)
    assert_allclose(Ts, np.stack([se3_exp(xi) for xi in xis]), rtol=0, atol=1e-10)
    assert_allclose(se3_log(Ts), np.stack([se3_log(T) for T in Ts]), rtol=0, atol=1e-10)
    assert_array_equal(so3_hat(xis[:, 3:]), np.stack([so3_hat(v) for v in xis[:, 3:]]))
    assert_array_equal(so3_vee(so3_hat(xis[:, 3:])), xis[:, 3:])


@FAST
@given(finite_floats(-np.pi + 1e-6, np.pi - 1e-6))
def test_leading_batch_axes_are_kept(angle):
    xis = np.zeros((2, 3, 6))
    xis[..., 5] = angle
    assert se3_exp(xis).shape == (2, 3, 4, 4)
    assert se3_log(se3_exp(xis)).shape == (2, 3, 6)
    assert so3_hat(xis[..., 3:]).shape == (2, 3, 3, 3)
    assert so3_vee(so3_hat(xis[..., 3:])).shape == (2, 3, 3)
    assert se3_exp(np.zeros((0, 6))).shape == (0, 4, 4)
    assert_allclose(se3_log(se3_exp(xis)), xis, atol=1e-14)


# --------------------------------------------------------------------------- bad input
SHAPE = r"expected an array of shape \(\.\.\., {}\), got shape \({}\)$"
BAD_INPUT = [
    (se3_exp, [0.0, 0.0, 0.0], r"^xi: " + SHAPE.format("6", "3,")),
    (
        se3_exp,
        [[0.0] * 6, [0.0, 0.0, 0.0, np.nan, 0.0, 0.0]],
        r"^xi: expected finite values, found NaN or inf at index \(1,\)",
    ),
    (se3_log, np.eye(3), r"^T: " + SHAPE.format("4, 4", "3, 3")),
    (se3_log, np.diag([1.0, 1.0, 2.0, 1.0]), r"^T\[\.\.\., :3, :3\]: expected rotation matrices"),
    (se3_log, np.ones((4, 4)), r"^T: expected last row \[0, 0, 0, 1\]"),
    (so3_hat, np.zeros((2, 2)), r"^v: " + SHAPE.format("3", "2, 2")),
    (so3_vee, np.zeros(3), r"^K: " + SHAPE.format("3, 3", "3,")),
]


@pytest.mark.parametrize(("f", "arg", "match"), BAD_INPUT)
def test_bad_input(f, arg, match):
    with pytest.raises(GeometryError, match=match):
        f(arg)

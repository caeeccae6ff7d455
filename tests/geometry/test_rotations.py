import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal
from scipy.linalg import orthogonal_procrustes
from scipy.spatial.transform import Rotation

from posekit.errors import GeometryError, PosekitError
from posekit.geometry import (
    check_rotation_matrix,
    is_rotation_matrix,
    matrix_from_quaternion,
    matrix_from_rotation_vector,
    nearest_rotation,
    quaternion_from_matrix,
    quaternion_wxyz_from_xyzw,
    quaternion_xyzw_from_wxyz,
    rotation_angle_between,
    rotation_vector_from_matrix,
)
from tests.strategies import (
    FAST,
    batches,
    finite_floats,
    rotation_angles,
    rotation_matrices,
    rotation_vectors,
    unit_quaternions,
    unit_vectors,
)

S = np.sqrt(0.5)
R_180_X = np.diag([1.0, -1.0, -1.0])
R_90_Z = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
R_120_XYZ = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # x->y->z->x

# (q_wxyz canonical, R, rotation vector), derived by hand.
REFERENCE = [
    ([1.0, 0.0, 0.0, 0.0], np.eye(3), [0.0, 0.0, 0.0]),
    ([0.0, 1.0, 0.0, 0.0], R_180_X, [np.pi, 0.0, 0.0]),
    ([0.0, 0.0, 1.0, 0.0], np.diag([-1.0, 1.0, -1.0]), [0.0, np.pi, 0.0]),
    ([0.0, 0.0, 0.0, 1.0], np.diag([-1.0, -1.0, 1.0]), [0.0, 0.0, np.pi]),
    ([S, 0.0, 0.0, S], R_90_Z, [0.0, 0.0, np.pi / 2]),
    ([0.5, 0.5, 0.5, 0.5], R_120_XYZ, np.full(3, 2 * np.pi / 3 / np.sqrt(3))),
]


def hamilton_matrix(q):
    """Rotation matrix of a unit Hamilton quaternion [w, x, y, z], written out by hand."""
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


# --------------------------------------------------------------------------- reference values
@pytest.mark.parametrize(("q", "R", "rotvec"), REFERENCE)
def test_reference_rotations(q, R, rotvec):
    assert_allclose(matrix_from_quaternion(q), R, atol=1e-15)
    assert_allclose(quaternion_from_matrix(R), q, atol=1e-15)
    assert_allclose(matrix_from_rotation_vector(rotvec), R, atol=1e-15)
    assert_allclose(rotation_vector_from_matrix(R), rotvec, atol=1e-15)


def test_180_about_x_is_0_1_0_0_with_canonical_sign():
    assert_array_equal(quaternion_from_matrix(R_180_X), [0.0, 1.0, 0.0, 0.0])
    assert_array_equal(quaternion_from_matrix(matrix_from_quaternion([0, -1, 0, 0])), [0, 1, 0, 0])


def test_90_about_z_maps_x_to_y():
    for R in (matrix_from_rotation_vector([0, 0, np.pi / 2]), matrix_from_quaternion([S, 0, 0, S])):
        assert_allclose(R @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
        assert_allclose(R @ [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], atol=1e-15)


def test_quaternion_reordering():
    assert_array_equal(quaternion_xyzw_from_wxyz([1, 2, 3, 4]), [2, 3, 4, 1])
    assert_array_equal(quaternion_wxyz_from_xyzw([2, 3, 4, 1]), [1, 2, 3, 4])
    q = np.arange(24.0).reshape(2, 3, 4)
    assert_array_equal(quaternion_wxyz_from_xyzw(quaternion_xyzw_from_wxyz(q)), q)
    assert_array_equal(quaternion_xyzw_from_wxyz(q)[..., 3], q[..., 0])


def test_nearest_rotation_of_a_reflection_is_a_proper_rotation():
    # diag(3, 2, -1): singular values 3 > 2 > 1, the smallest direction is flipped.
    assert_allclose(nearest_rotation(np.diag([3.0, 2.0, -1.0])), np.eye(3), atol=1e-15)
    assert_allclose(nearest_rotation(R_90_Z @ np.diag([3.0, 2.0, -1.0])), R_90_Z, atol=1e-15)
    assert_allclose(nearest_rotation(np.diag([1.0, 1.0, -1.0])) @ [1, 0, 0], [1, 0, 0], atol=1e-15)


def test_rotation_angle_between_reference():
    assert rotation_angle_between(np.eye(3), R_180_X) == pytest.approx(np.pi, abs=1e-15)
    assert rotation_angle_between(R_90_Z, np.eye(3)) == pytest.approx(np.pi / 2, abs=1e-15)
    assert rotation_angle_between(R_120_XYZ, R_120_XYZ) == 0.0


# --------------------------------------------------------------------------- properties
@FAST
@given(unit_quaternions())
def test_quaternion_matrix_quaternion_round_trip(q):
    R = matrix_from_quaternion(q)
    assert_allclose(R, hamilton_matrix(q), atol=1e-14)
    q_back = quaternion_from_matrix(R)
    assert q_back[0] >= 0.0
    assert min(np.abs(q_back - q).max(), np.abs(q_back + q).max()) < 1e-14


@FAST
@given(rotation_matrices())
def test_matrix_quaternion_matrix_round_trip(R):
    assert_allclose(matrix_from_quaternion(quaternion_from_matrix(R)), R, atol=1e-14)
    assert is_rotation_matrix(matrix_from_quaternion(quaternion_from_matrix(R)), tol=1e-14)


@FAST
@given(unit_quaternions(), finite_floats(1e-3, 1e3), st.sampled_from([1.0, -1.0]))
def test_matrix_from_quaternion_normalises(q, scale, sign):
    assert_allclose(matrix_from_quaternion(sign * scale * q), matrix_from_quaternion(q), atol=1e-14)


@FAST
@given(unit_vectors(), rotation_angles())
def test_rotation_vector_matches_axis_angle_quaternion(axis, angle):
    q = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])
    assert_allclose(matrix_from_rotation_vector(angle * axis), hamilton_matrix(q), atol=1e-14)


@FAST
@given(rotation_vectors())
def test_rotation_vector_round_trip_below_pi(rotvec):
    rotvec_back = rotation_vector_from_matrix(matrix_from_rotation_vector(rotvec))
    assert_allclose(rotvec_back, rotvec, atol=1e-14)


def test_rotation_vector_at_exactly_pi_has_angle_pi_and_the_axis_up_to_sign():
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    rotvec = rotation_vector_from_matrix(matrix_from_rotation_vector(np.pi * axis))
    assert np.linalg.norm(rotvec) == pytest.approx(np.pi, abs=1e-14)
    assert min(np.abs(rotvec - np.pi * axis).max(), np.abs(rotvec + np.pi * axis).max()) < 1e-14


@FAST
@given(rotation_matrices(), st.lists(finite_floats(-0.2, 0.2), min_size=9, max_size=9))
def test_nearest_rotation_matches_orthogonal_procrustes(R, noise):
    M = R + np.reshape(noise, (3, 3))
    assume(np.linalg.det(M) > 0.1)
    polar, _ = orthogonal_procrustes(np.eye(3), M)  # argmin ||Q - M|| over orthogonal Q
    assert_allclose(nearest_rotation(M), polar, atol=1e-13)
    assert_allclose(nearest_rotation(R), R, atol=1e-14)


@FAST
@given(st.lists(finite_floats(-10.0, 10.0), min_size=9, max_size=9))
def test_nearest_rotation_is_the_best_proper_rotation(entries):
    M = np.reshape(entries, (3, 3))
    s = np.linalg.svd(M, compute_uv=False)
    assume(s[2] > 1e-3 and s[1] - s[2] > 1e-3)  # a unique optimum
    R = nearest_rotation(M)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    assert is_rotation_matrix(R, tol=1e-12)
    # Wahba's problem with vectors a_i = M[:, i], b_i = e_i maximises trace(R^T M) over SO(3).
    best, _ = Rotation.align_vectors(M.T, np.eye(3))
    assert_allclose(R, best.as_matrix(), atol=1e-9)


@FAST
@given(rotation_matrices(), unit_vectors(), rotation_angles(include_pi=True))
def test_rotation_angle_between_recovers_the_relative_angle(R_a, axis, angle):
    R_b = R_a @ Rotation.from_rotvec(angle * axis).as_matrix()
    assert rotation_angle_between(R_a, R_b) == pytest.approx(angle, abs=1e-14)
    assert rotation_angle_between(R_b, R_a) == pytest.approx(angle, abs=1e-14)


# --------------------------------------------------------------------------- batches
@FAST
@given(batches(unit_quaternions(), max_size=6))
def test_batch_equals_stacked_singles(qs):
    Rs = matrix_from_quaternion(qs)
    assert_allclose(Rs, np.stack([matrix_from_quaternion(q) for q in qs]), rtol=0, atol=1e-14)
    for f in (quaternion_from_matrix, rotation_vector_from_matrix, nearest_rotation):
        assert_allclose(f(Rs), np.stack([f(R) for R in Rs]), rtol=0, atol=1e-14)
    rotvecs = rotation_vector_from_matrix(Rs)
    singles = np.stack([matrix_from_rotation_vector(v) for v in rotvecs])
    assert_allclose(matrix_from_rotation_vector(rotvecs), singles, rtol=0, atol=1e-14)
    angles = rotation_angle_between(Rs[0], Rs)  # (3, 3) against (n, 3, 3) broadcasts
    assert_allclose(angles, [rotation_angle_between(Rs[0], R) for R in Rs], rtol=0, atol=1e-14)


def test_leading_batch_axes_are_kept():
    qs = Rotation.random(6, rng=0).as_quat(scalar_first=True).reshape(2, 3, 4)
    Rs = matrix_from_quaternion(qs)
    assert Rs.shape == (2, 3, 3, 3)
    assert quaternion_from_matrix(Rs).shape == (2, 3, 4)
    assert rotation_vector_from_matrix(Rs).shape == (2, 3, 3)
    assert nearest_rotation(Rs).shape == (2, 3, 3, 3)
    assert rotation_angle_between(Rs, Rs[:, :1]).shape == (2, 3)
    assert matrix_from_quaternion(np.zeros((0, 4)) + 1).shape == (0, 3, 3)
    assert is_rotation_matrix(Rs) and is_rotation_matrix(np.zeros((0, 3, 3)))


# --------------------------------------------------------------------------- validators
def test_is_rotation_matrix():
    assert is_rotation_matrix(np.eye(3)) and is_rotation_matrix(R_90_Z)
    assert not is_rotation_matrix(np.diag([1.0, 1.0, -1.0]))  # reflection
    assert not is_rotation_matrix(2 * np.eye(3))
    assert not is_rotation_matrix(np.eye(4))
    assert not is_rotation_matrix(np.full((3, 3), np.nan))
    assert not is_rotation_matrix("eye")
    assert not is_rotation_matrix(np.stack([np.eye(3), np.diag([1.0, 1.0, -1.0])]))
    nearly = np.eye(3) + 1e-8
    assert not is_rotation_matrix(nearly) and is_rotation_matrix(nearly, tol=1e-6)


def test_check_rotation_matrix_returns_float64():
    R = check_rotation_matrix(np.eye(3, dtype=int))
    assert R.dtype == np.float64
    assert_array_equal(R, np.eye(3))


def test_geometry_error_is_a_value_error():
    assert issubclass(GeometryError, PosekitError) and issubclass(GeometryError, ValueError)


# --------------------------------------------------------------------------- bad input
BAD_ROTATION = [
    (np.diag([1.0, 1.0, -1.0]), r"R: expected rotation matrices .* det = -1$"),
    (2 * np.eye(3), r"found max \|R\^T R - I\| = 3, det = 8$"),
    (np.stack([np.eye(3), np.eye(3), 2 * np.eye(3)]), r"at index \(2,\) \(1 of 3 bad\)"),
    (np.eye(3)[:, :2], r"R: expected an array of shape \(\.\.\., 3, 3\), got shape \(3, 2\)"),
    (np.full((3, 3), np.inf), r"R: expected finite values, found NaN or inf"),
    ("not a matrix", r"R: expected a numeric array of shape \(\.\.\., 3, 3\), got str"),
]


@pytest.mark.parametrize(("R", "match"), BAD_ROTATION)
@pytest.mark.parametrize(
    "f", [check_rotation_matrix, quaternion_from_matrix, rotation_vector_from_matrix]
)
def test_bad_rotation_matrix(f, R, match):
    with pytest.raises(GeometryError, match=match):
        f(R)


def test_rotation_angle_between_bad_input():
    with pytest.raises(GeometryError, match=r"R_b: expected rotation matrices"):
        rotation_angle_between(np.eye(3), 2 * np.eye(3))
    with pytest.raises(GeometryError, match=r"R_a, R_b: expected broadcastable batch shapes"):
        rotation_angle_between(np.stack([np.eye(3)] * 2), np.stack([np.eye(3)] * 3))


@pytest.mark.parametrize(
    ("q", "match"),
    [
        (
            [0.0, 0.0, 0.0, 0.0],
            r"^q_wxyz: expected non-zero quaternions \[w, x, y, z\], found norm 0$",
        ),
        ([[1, 0, 0, 0], [0, 0, 0, 0]], r"found norm 0 at index \(1,\) \(1 of 2 bad\)"),
        ([1.0, np.nan, 0.0, 0.0], r"^q_wxyz: expected finite values, found NaN or inf$"),
        ([1.0, 0.0, 0.0], r"^q_wxyz: expected an array of shape \(\.\.\., 4\), got shape \(3,\)$"),
    ],
)
def test_matrix_from_quaternion_bad_input(q, match):
    with pytest.raises(GeometryError, match=match):
        matrix_from_quaternion(q)


def test_other_bad_input():
    with pytest.raises(GeometryError, match=r"q_wxyz: expected an array of shape \(\.\.\., 4\)"):
        quaternion_xyzw_from_wxyz([1.0, 0.0, 0.0])
    with pytest.raises(GeometryError, match=r"q_xyzw: expected an array of shape \(\.\.\., 4\)"):
        quaternion_wxyz_from_xyzw(np.zeros((4, 3)))
    with pytest.raises(GeometryError, match=r"rotvec: expected finite values"):
        matrix_from_rotation_vector([0.0, np.inf, 0.0])
    with pytest.raises(GeometryError, match=r"rotvec: expected an array of shape \(\.\.\., 3\)"):
        matrix_from_rotation_vector(np.zeros(4))
    with pytest.raises(GeometryError, match=r"M: expected finite values.* at index \(0,\)"):
        nearest_rotation(np.full((1, 3, 3), np.nan))
    with pytest.raises(GeometryError, match=r"M: expected an array of shape \(\.\.\., 3, 3\)"):
        nearest_rotation(np.eye(2))


# --------------------------------------------------------------------------- the compiled path
# quaternion_from_matrix / rotation_vector_from_matrix run the numba kernels of
# posekit.geometry._rotation_kernels; numba kernels elsewhere call the same functions inline.


@FAST
@given(rotation_matrices())
def test_compiled_conversions_match_scipy(R):
    from scipy.spatial.transform import Rotation

    q = quaternion_from_matrix(R, check=False)
    ref = Rotation.from_matrix(R).as_quat(canonical=True, scalar_first=True)
    if abs(ref[0]) > 1e-12:  # at w = 0 both are canonical by the first non-zero component
        np.testing.assert_allclose(q, ref, atol=2e-15)
    np.testing.assert_allclose(matrix_from_quaternion(q), R, atol=1e-14)
    rv = rotation_vector_from_matrix(R, check=False)
    rv_ref = Rotation.from_matrix(R).as_rotvec()
    if np.linalg.norm(rv_ref) < np.pi - 1e-6:  # at pi the axis sign is free
        np.testing.assert_allclose(rv, rv_ref, atol=1e-12)


def test_compiled_conversions_near_zero_and_pi():
    from scipy.spatial.transform import Rotation

    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    for angle in (0.0, 1e-12, 1e-9, 1e-6, 0.1, np.pi - 1e-6, np.pi - 1e-9):
        R = Rotation.from_rotvec(axis * angle).as_matrix()
        np.testing.assert_allclose(rotation_vector_from_matrix(R), axis * angle, atol=1e-12, rtol=1e-9)
    R = Rotation.from_rotvec(axis * np.pi).as_matrix()
    rv = rotation_vector_from_matrix(R)
    assert np.isclose(np.linalg.norm(rv), np.pi) and np.isclose(abs(rv @ axis), np.pi)


def test_inline_kernels_equal_the_public_converters():
    from numba import njit

    from posekit.geometry import quaternion_from_entries, rotvec_from_entries

    @njit
    def both(R):
        q = quaternion_from_entries(R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2], R[2, 0], R[2, 1], R[2, 2])
        v = rotvec_from_entries(R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2], R[2, 0], R[2, 1], R[2, 2])
        return q, v

    from scipy.spatial.transform import Rotation

    for R in Rotation.random(50, random_state=1).as_matrix():
        q, v = both(R)
        np.testing.assert_array_equal(q, quaternion_from_matrix(R))
        np.testing.assert_array_equal(v, rotation_vector_from_matrix(R))


def test_quaternion_product_reference_and_composition():
    from posekit.geometry import quaternion_product

    np.testing.assert_array_equal(quaternion_product([0, 1, 0, 0], [0, 0, 1, 0]), [0, 0, 0, 1])  # i j = k
    np.testing.assert_array_equal(quaternion_product([0, 0, 1, 0], [0, 1, 0, 0]), [0, 0, 0, -1])  # j i = -k
    from scipy.spatial.transform import Rotation

    a, b = Rotation.random(20, random_state=2), Rotation.random(20, random_state=3)
    qa, qb = a.as_quat(scalar_first=True), b.as_quat(scalar_first=True)
    np.testing.assert_allclose(matrix_from_quaternion(quaternion_product(qa, qb)), (a * b).as_matrix(), atol=1e-14)
    with pytest.raises(GeometryError, match=r"q2_wxyz: expected an array of shape \(\.\.\., 4\), got shape \(3,\)"):
        quaternion_product([1, 0, 0, 0], [1, 0, 0])


def test_numpy_conversions_match_scipy_near_zero_and_pi():
    """matrix_from_rotation_vector / matrix_from_quaternion (NumPy, no scipy at import) against
    scipy's Rotation, with angles near 0 (the series branch) and near pi."""
    rng = np.random.default_rng(7)
    axes = rng.normal(size=(60, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([[0.0, 1e-12, 1e-5, 9.99e-5, 1.01e-4, 0.3, 1.0, 2.5, np.pi - 1e-9, np.pi],
                             rng.uniform(-2 * np.pi, 2 * np.pi, 50)])
    rv = axes * angles[:, None]
    np.testing.assert_allclose(matrix_from_rotation_vector(rv), Rotation.from_rotvec(rv).as_matrix(), atol=2e-15)
    q = rng.normal(size=(40, 4)) * rng.uniform(1e-3, 1e3, (40, 1))
    np.testing.assert_allclose(matrix_from_quaternion(q), Rotation.from_quat(q, scalar_first=True).as_matrix(),
                               atol=2e-15)
    assert matrix_from_rotation_vector(np.zeros(3)).shape == (3, 3) and matrix_from_quaternion(q.reshape(2, 20, 4)).shape == (2, 20, 3, 3)

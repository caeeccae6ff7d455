"""Euler angles (posekit.geometry.euler) against scipy's Rotation, including gimbal lock."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from posekit.errors import GeometryError
from posekit.geometry import (
    euler_xyz_from_matrix,
    euler_zyx_from_matrix,
    matrix_from_euler_zyx,
    matrix_from_quaternion,
)
from posekit.geometry.euler import GIMBAL_COS

#: Reference values by hand: R = Rz(A) Ry(B) Rx(C).
RZ90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
RX180 = np.diag([1.0, -1.0, -1.0])


def test_reference_values():
    np.testing.assert_allclose(euler_zyx_from_matrix(RZ90), [np.pi / 2, 0, 0], atol=1e-15)
    np.testing.assert_allclose(euler_zyx_from_matrix(RX180), [0, 0, np.pi], atol=1e-15)
    np.testing.assert_allclose(euler_xyz_from_matrix(RX180), [np.pi, 0, 0], atol=1e-15)
    np.testing.assert_array_equal(euler_zyx_from_matrix(np.eye(3)), [0.0, 0.0, 0.0])
    assert not np.signbit(euler_zyx_from_matrix(np.eye(3))).any()       # no -0.0


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(lambda v: np.linalg.norm(v) > 0.1))
def test_against_scipy(q):
    q = np.array(q) / np.linalg.norm(q)
    R = matrix_from_quaternion(q)
    abc = euler_zyx_from_matrix(R)
    sc = Rotation.from_matrix(R)
    # back to rounding; at gimbal lock (cos B ≤ GIMBAL_COS, C = 0) to 2 cos B, the part of R that C = 0 cannot hold
    cb = np.hypot(R[0, 0], R[1, 0])
    tol = 1e-13 + (2.0 * cb if cb <= GIMBAL_COS else 0.0)
    np.testing.assert_allclose(matrix_from_euler_zyx(abc), R, rtol=0, atol=tol)
    np.testing.assert_allclose(Rotation.from_euler("ZYX", abc).as_matrix(), R, rtol=0, atol=tol)
    np.testing.assert_allclose(Rotation.from_euler("xyz", euler_xyz_from_matrix(R)).as_matrix(), R, rtol=0, atol=tol)
    # scipy's lock is wider (|B ∓ π/2| < 1e-7): within it its angles give R back to 2 cos B
    np.testing.assert_allclose(Rotation.from_euler("ZYX", sc.as_euler("ZYX")).as_matrix(), R, rtol=0,
                               atol=1e-13 + (2.0 * cb if cb < 1e-7 else 0.0))
    # scipy's own angles (same ranges), away from gimbal lock and from the ±π wrap of A, C
    ref = sc.as_euler("ZYX")
    if abs(abs(abc[1]) - np.pi / 2) > 1e-4 and np.all(np.abs(np.abs(abc[[0, 2]]) - np.pi) > 1e-9):
        np.testing.assert_allclose(abc, ref, atol=1e-9)
        np.testing.assert_allclose(euler_xyz_from_matrix(R), sc.as_euler("xyz"), atol=1e-9)
    assert -np.pi < abc[0] <= np.pi and -np.pi / 2 <= abc[1] <= np.pi / 2 and -np.pi < abc[2] <= np.pi


@pytest.mark.parametrize("b", [np.pi / 2, -np.pi / 2])
@pytest.mark.parametrize("a, c", [(0.3, 0.0), (0.3, 0.5), (-2.0, 1.2), (3.0, -3.0)])
def test_gimbal_lock(a, b, c):
    """B = ±90°: only A ∓ C is defined; C is set to 0 and the matrix is kept, as scipy does."""
    R = Rotation.from_euler("ZYX", [a, b, c]).as_matrix()
    abc = euler_zyx_from_matrix(R)
    assert abc[2] == 0.0 and abs(abc[1] - b) < 1e-7
    np.testing.assert_allclose(matrix_from_euler_zyx(abc), R, atol=1e-12)
    with pytest.warns(UserWarning, match="Gimbal lock"):
        ref = Rotation.from_matrix(R).as_euler("ZYX")
    np.testing.assert_allclose(Rotation.from_euler("ZYX", ref).as_matrix(), R, atol=1e-12)
    assert abs(ref[2]) < 1e-12 or abs(ref[0]) < 1e-12         # scipy also puts the turn into one angle
    np.testing.assert_allclose(euler_xyz_from_matrix(R), abc[::-1])


def test_batches_are_the_stacked_singles():
    R = Rotation.random(24, random_state=3).as_matrix().reshape(2, 3, 4, 3, 3)
    out = euler_zyx_from_matrix(R)
    assert out.shape == (2, 3, 4, 3)
    single = np.array([euler_zyx_from_matrix(r) for r in R.reshape(-1, 3, 3)]).reshape(out.shape)
    np.testing.assert_array_equal(out, single)
    np.testing.assert_allclose(matrix_from_euler_zyx(out), R, atol=1e-12)
    assert euler_xyz_from_matrix(R).shape == (2, 3, 4, 3)


def test_bad_input():
    with pytest.raises(GeometryError, match=r"^R: expected rotation matrices"):
        euler_zyx_from_matrix(2 * np.eye(3))
    with pytest.raises(GeometryError):
        euler_xyz_from_matrix(np.eye(4))
    np.testing.assert_allclose(euler_zyx_from_matrix(2 * np.eye(3), check=False), [0, 0, 0])


@pytest.mark.parametrize("cb", [3e-9, 1e-8, 1e-7, 1e-5])
def test_near_gimbal_lock_the_angles_give_the_matrix_back_to_rounding(cb):
    """Just outside the lock, A alone is ill-conditioned (its entries are of size cos B); C is taken from A and
    the well-sized entries, so that the pair gives R back to 1e-15 (the textbook C = atan2(R21, R22) leaves up to
    eps / cos B: 4e-8 at cos B = 3e-9)."""
    rng = np.random.default_rng(7)
    for a, c, s in zip(rng.uniform(-np.pi, np.pi, 50), rng.uniform(-np.pi, np.pi, 50), rng.choice([-1, 1], 50)):
        R = matrix_from_quaternion(Rotation.from_euler("ZYX", [a, s * (np.pi / 2 - cb), c]).as_quat()[[3, 0, 1, 2]])
        abc = euler_zyx_from_matrix(R)
        assert abc[2] != 0.0
        np.testing.assert_allclose(matrix_from_euler_zyx(abc), R, rtol=0, atol=2e-15)


def test_at_gimbal_lock_the_matrix_comes_back_to_twice_cos_b():
    """Hypothesis's example that the former 1e-9 tolerance failed on: cos B = 1.29e-9 is inside the lock."""
    R = matrix_from_quaternion([1.2864263455810659e-09, 1.0, 0.0, 1.0])
    cb = np.hypot(R[0, 0], R[1, 0])
    assert cb < GIMBAL_COS
    abc = euler_zyx_from_matrix(R)
    assert abc[2] == 0.0
    err = np.abs(matrix_from_euler_zyx(abc) - R).max()
    assert 0.5 * cb < err <= 2.0 * cb

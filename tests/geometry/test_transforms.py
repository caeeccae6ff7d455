import numpy as np
import pytest
from hypothesis import given
from numpy.testing import assert_allclose, assert_array_equal

from posekit.errors import GeometryError
from posekit.geometry import (
    apply_transform,
    check_transform,
    invert_transform,
    rotation_translation,
    transform_from,
    transform_from_quaternion,
)
from tests.strategies import FAST, batches, rotation_matrices, transforms, translations_mm

S = np.sqrt(0.5)
R_90_Z = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
Q_90_Z = [S, 0.0, 0.0, S]
# 90 degrees about z, then 5 mm along z: x_b -> y_a, and the origin of b sits at z = 5 in a.
T_90_Z_UP_5 = np.array(
    [[0.0, -1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 5.0], [0.0, 0.0, 0.0, 1.0]]
)


# --------------------------------------------------------------------------- reference values
def test_transform_from_reference():
    assert_array_equal(transform_from(R_90_Z, [0.0, 0.0, 5.0]), T_90_Z_UP_5)
    assert_allclose(transform_from_quaternion(Q_90_Z, [0.0, 0.0, 5.0]), T_90_Z_UP_5, atol=1e-15)


def test_apply_transform_reference():
    p_b = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 0.0]])
    p_a = np.array([[0.0, 1.0, 5.0], [-2.0, 0.0, 5.0], [0.0, 0.0, 5.0]])
    assert_array_equal(apply_transform(T_90_Z_UP_5, p_b), p_a)
    assert_array_equal(apply_transform(invert_transform(T_90_Z_UP_5), p_a), p_b)


def test_invert_transform_reference():
    T_b_a = invert_transform(T_90_Z_UP_5)
    assert_array_equal(T_b_a[:3, :3], R_90_Z.T)
    assert_array_equal(T_b_a[:3, 3], [0.0, 0.0, -5.0])
    assert_array_equal(T_b_a[3], [0.0, 0.0, 0.0, 1.0])


def test_rotation_translation_reference():
    R, t = rotation_translation(T_90_Z_UP_5)
    assert_array_equal(R, R_90_Z)
    assert_array_equal(t, [0.0, 0.0, 5.0])
    R[0, 0] = 7.0  # a copy, not a view
    assert T_90_Z_UP_5[0, 0] == 0.0


# --------------------------------------------------------------------------- properties
@FAST
@given(batches(transforms()))
def test_invert_transform_times_transform_is_identity(Ts):
    for T_inv, T in ((invert_transform(Ts), Ts), (Ts, invert_transform(Ts))):
        assert_allclose(T_inv @ T, np.broadcast_to(np.eye(4), Ts.shape), atol=1e-10)
    assert_allclose(invert_transform(Ts), np.linalg.inv(Ts), atol=1e-10)
    assert_allclose(invert_transform(invert_transform(Ts)), Ts, atol=1e-10)


@FAST
@given(rotation_matrices(), translations_mm())
def test_transform_from_and_rotation_translation_round_trip(R, t):
    T = transform_from(R, t)
    assert_array_equal(T[3], [0.0, 0.0, 0.0, 1.0])
    R_back, t_back = rotation_translation(T)
    assert_array_equal(R_back, R)
    assert_array_equal(t_back, t)


@FAST
@given(transforms(), transforms(), batches(translations_mm(), max_size=8))
def test_apply_transform_matches_homogeneous_product_and_composes(T_a_b, T_b_c, p_c):
    p_h = np.concatenate([p_c, np.ones((len(p_c), 1))], axis=1)
    assert_allclose(apply_transform(T_b_c, p_c), (p_h @ T_b_c.T)[:, :3], atol=1e-9)
    assert_allclose(
        apply_transform(T_a_b @ T_b_c, p_c),
        apply_transform(T_a_b, apply_transform(T_b_c, p_c)),
        atol=1e-9,
    )


@FAST
@given(batches(transforms(), max_size=4), batches(translations_mm(), max_size=4))
def test_batch_equals_stacked_singles(Ts, ps):
    n = min(len(Ts), len(ps))
    Ts, ps = Ts[:n], ps[:n]
    Rs, ts = rotation_translation(Ts)
    singles = np.stack([transform_from(R, t) for R, t in zip(Rs, ts)])
    assert_array_equal(transform_from(Rs, ts), singles)
    assert_allclose(
        invert_transform(Ts), np.stack([invert_transform(T) for T in Ts]), rtol=0, atol=1e-10
    )
    one_to_one = apply_transform(Ts, ps)  # (n, 4, 4) with (n, 3): pairwise
    assert_allclose(one_to_one, [apply_transform(T, p) for T, p in zip(Ts, ps)], rtol=0, atol=1e-10)
    one_to_many = apply_transform(Ts[0], ps)  # (4, 4) with (n, 3)
    assert_allclose(one_to_many, [apply_transform(Ts[0], p) for p in ps], rtol=0, atol=1e-10)


def test_broadcasting_shapes():
    Ts = np.broadcast_to(T_90_Z_UP_5, (2, 3, 4, 4))
    assert transform_from(R_90_Z, np.zeros((5, 3))).shape == (5, 4, 4)
    assert transform_from(np.stack([R_90_Z] * 5), [1.0, 2.0, 3.0]).shape == (5, 4, 4)
    qs = np.tile(Q_90_Z, (2, 1, 1))
    assert transform_from_quaternion(qs, np.zeros((4, 3))).shape == (2, 4, 4, 4)
    assert invert_transform(Ts).shape == (2, 3, 4, 4)
    assert apply_transform(Ts, [1.0, 0.0, 0.0]).shape == (2, 3, 3)
    assert apply_transform(Ts[:, :1], np.zeros((7, 3))).shape == (2, 7, 3)
    assert apply_transform(T_90_Z_UP_5, np.zeros((0, 3))).shape == (0, 3)
    assert [a.shape for a in rotation_translation(Ts)] == [(2, 3, 3, 3), (2, 3, 3)]


def test_check_false_skips_validation():
    T = transform_from(2 * np.eye(3), [1.0, 2.0, 3.0], check=False)
    assert_array_equal(T[:3, :3], 2 * np.eye(3))
    assert_array_equal(apply_transform(T, [1.0, 1.0, 1.0], check=False), [3.0, 4.0, 5.0])


def test_check_transform_returns_float64():
    T = check_transform(np.eye(4, dtype=int))
    assert T.dtype == np.float64
    assert_array_equal(T, np.eye(4))


# --------------------------------------------------------------------------- bad input
def _last_row_bad():
    T = np.eye(4)
    T[3, 0] = 1e-3
    return T


BAD_TRANSFORMS = [
    (
        _last_row_bad(),
        r"^T: expected last row \[0, 0, 0, 1\] within 1e-06, "
        r"found \[0\.001 0\.    0\.    1\.   \]$",
    ),
    (
        np.diag([1.0, 1.0, -1.0, 1.0]),
        r"^T\[\.\.\., :3, :3\]: expected rotation matrices .*det = -1$",
    ),
    (np.stack([np.eye(4), 2 * np.eye(4)]), r"at index \(1,\) \(1 of 2 bad\)"),
    (np.eye(3), r"^T: expected an array of shape \(\.\.\., 4, 4\), got shape \(3, 3\)$"),
    (np.full((4, 4), np.nan), r"^T: expected finite values, found NaN or inf$"),
]


@pytest.mark.parametrize(("T", "match"), BAD_TRANSFORMS)
@pytest.mark.parametrize(
    "f",
    [
        check_transform,
        rotation_translation,
        invert_transform,
        lambda T: apply_transform(T, [0.0, 0.0, 0.0]),
    ],
    ids=["check_transform", "rotation_translation", "invert_transform", "apply_transform"],
)
def test_bad_transform(f, T, match):
    with pytest.raises(GeometryError, match=match):
        f(T)


SHAPE_3 = r"expected an array of shape \(\.\.\., 3\), got shape "
BROADCAST = r"expected broadcastable batch shapes, got \(2,\) and \(3,\)$"
Q_2 = np.tile(Q_90_Z, (2, 1))
BAD_INPUT = [
    (transform_from, (2 * np.eye(3), [0.0, 0.0, 0.0]), r"^R: expected rotation matrices"),
    (transform_from, (np.eye(3), [0.0, 0.0]), r"^t: " + SHAPE_3 + r"\(2,\)$"),
    (transform_from, (np.eye(3), [0.0, np.nan, 0.0]), r"^t: expected finite values"),
    (transform_from, (np.stack([np.eye(3)] * 2), np.zeros((3, 3))), r"^R, t: " + BROADCAST),
    (transform_from_quaternion, ([0.0] * 4, [0.0] * 3), r"^q_wxyz: expected non-zero quaternions"),
    (transform_from_quaternion, ([1.0, 0, 0, 0], [np.inf, 0, 0]), r"^t: expected finite values"),
    (transform_from_quaternion, (Q_2, np.zeros((3, 3))), r"^q_wxyz, t: " + BROADCAST),
    (apply_transform, (np.eye(4), np.zeros((4, 2))), r"^p: " + SHAPE_3 + r"\(4, 2\)$"),
    (
        apply_transform,
        (np.eye(4), [[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0]]),
        r"^p: expected finite values, found NaN or inf at index \(1,\)",
    ),
    (apply_transform, (np.stack([np.eye(4)] * 2), np.zeros((3, 3))), r"^T, p: " + BROADCAST),
]


@pytest.mark.parametrize(("f", "args", "match"), BAD_INPUT)
def test_bad_rotation_translation_or_points(f, args, match):
    with pytest.raises(GeometryError, match=match):
        f(*args)

"""Forward kinematics and geometric Jacobian of DH chains, against independent references."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from posekit.robots import PRISMATIC, REVOLUTE, DHChain, hiab033, puma560

MODELS = {"puma560": puma560, "hiab033": hiab033}

#: PUMA 560 at q = 0, tool = flange: Corke's Robotics Toolbox ``p560.fkine(p560.qz)``
#: gives t = (0.4521, -0.15005, 0.4318) m and R = I. Hand check: x = a2 + a3 = 452.12,
#: y = -d3 = -150.05, z = d4 = 431.8.
PUMA_QZ_T = np.array(
    [
        [1.0, 0.0, 0.0, 452.12],
        [0.0, 1.0, 0.0, -150.05],
        [0.0, 0.0, 1.0, 431.8],
        [0.0, 0.0, 0.0, 1.0],
    ]
)


def naive_fk(chain: DHChain, q) -> np.ndarray:
    """Independent reference: eq. (24) written out per joint with math.sin/cos, then eq. (23)."""
    T = np.eye(4)
    for i in range(chain.n_joints):
        a, alpha = float(chain.a[i]), float(chain.alpha[i])
        theta, d = float(chain.theta[i]), float(chain.d[i])
        if chain.joint_types[i] == REVOLUTE:
            theta += float(q[i])
        else:
            d += float(q[i])
        ct, st_, ca, sa = (
            math.cos(theta),
            math.sin(theta),
            math.cos(alpha),
            math.sin(alpha),
        )
        A = np.array(
            [
                [ct, -st_ * ca, st_ * sa, a * ct],
                [st_, ct * ca, -ct * sa, a * st_],
                [0.0, sa, ca, d],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
        T = T @ A
    return T @ chain.T_flange_tool


def random_q(chain: DHChain, rng, size=None) -> np.ndarray:
    lo = np.where(np.isfinite(chain.q_min), chain.q_min, -np.pi)
    hi = np.where(np.isfinite(chain.q_max), chain.q_max, np.pi)
    return rng.uniform(lo, hi, size=None if size is None else (size, chain.n_joints))


def mixed_chain() -> DHChain:
    """A chain with prismatic joints, offsets and a tool, to exercise every branch."""
    T_tool = np.eye(4)
    T_tool[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    T_tool[:3, 3] = [10.0, -20.0, 150.0]
    return DHChain(
        a=[100.0, 0.0, 300.0, 0.0],
        alpha=[np.pi / 2, -np.pi / 2, 0.3, np.pi / 2],
        d=[400.0, 50.0, 0.0, 80.0],
        theta=[0.1, -0.4, 0.0, 0.7],
        joint_types=(REVOLUTE, PRISMATIC, REVOLUTE, PRISMATIC),
        q_min=[-3.0, 0.0, -3.0, -200.0],
        q_max=[3.0, 500.0, 3.0, 200.0],
        T_flange_tool=T_tool,
        name="mixed",
    )


CHAINS = {"puma560": puma560, "hiab033": hiab033, "mixed": mixed_chain}


def test_puma_zero_pose_reference():
    np.testing.assert_allclose(
        puma560().forward_kinematics(np.zeros(6)), PUMA_QZ_T, atol=1e-9
    )


def test_hiab_reach_about_5_m():
    T = hiab033().forward_kinematics(np.zeros(6))
    reach = np.hypot(T[0, 3], T[1, 3])
    assert 4500.0 < reach < 5500.0


@pytest.mark.parametrize("name", CHAINS)
def test_fk_matches_naive_dh_product(name):
    chain = CHAINS[name]()
    rng = np.random.default_rng(1)
    for q in random_q(chain, rng, 25):
        np.testing.assert_allclose(
            chain.forward_kinematics(q), naive_fk(chain, q), atol=1e-9, rtol=0
        )


@pytest.mark.parametrize("name", CHAINS)
def test_batch_fk_equals_stacked_single(name):
    chain = CHAINS[name]()
    qs = random_q(chain, np.random.default_rng(2), 50)
    Ts = chain.forward_kinematics(qs)
    assert Ts.shape == (50, 4, 4)
    np.testing.assert_array_equal(
        Ts, np.stack([chain.forward_kinematics(q) for q in qs])
    )
    flange = chain.forward_kinematics(qs, tool=False)
    np.testing.assert_allclose(flange @ chain.T_flange_tool, Ts, atol=1e-9)
    np.testing.assert_array_equal(flange, np.stack([chain.forward_kinematics(q, tool=False) for q in qs]))
    # joint i turns about z of DH frame i (frame 0 = base): the naive product of rows 0..i-1
    axes, points = chain.joint_axes(qs)
    assert axes.shape == points.shape == (50, chain.n_joints, 3)
    for k in range(0, 50, 10):
        for i in range(chain.n_joints):
            sub = DHChain(chain.a[:i + 1], chain.alpha[:i + 1], chain.d[:i + 1], chain.theta[:i + 1],
                          chain.joint_types[:i + 1])
            F = naive_fk(sub, qs[k, :i + 1]) @ np.linalg.inv(naive_fk(sub.__class__(
                sub.a[i:], sub.alpha[i:], sub.d[i:], sub.theta[i:], sub.joint_types[i:]), qs[k, i:i + 1]))
            np.testing.assert_allclose(axes[k, i], F[:3, 2], atol=1e-12)
            np.testing.assert_allclose(points[k, i], F[:3, 3], atol=1e-9)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_fk_is_rigid_transform(seed):
    chain = hiab033()
    T = chain.forward_kinematics(random_q(chain, np.random.default_rng(seed)))
    R = T[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) > 0
    np.testing.assert_array_equal(T[3], [0.0, 0.0, 0.0, 1.0])


def fd_jacobian(chain: DHChain, q, h: float = 1e-6) -> np.ndarray:
    """Central finite differences of FK: linear rows from the position, angular rows from
    the skew part of dR/dq · Rᵀ (base frame)."""
    n = chain.n_joints
    J = np.zeros((6, n))
    R0 = chain.forward_kinematics(q)[:3, :3]
    for i in range(n):
        step = h * (1.0 if chain.joint_types[i] == REVOLUTE else 100.0)
        dq = np.zeros(n)
        dq[i] = step
        Tp, Tm = chain.forward_kinematics(q + dq), chain.forward_kinematics(q - dq)
        J[:3, i] = (Tp[:3, 3] - Tm[:3, 3]) / (2 * step)
        W = (Tp[:3, :3] - Tm[:3, :3]) / (2 * step) @ R0.T
        J[3:, i] = [W[2, 1], W[0, 2], W[1, 0]]
    return J


@pytest.mark.parametrize("name", CHAINS)
def test_jacobian_matches_finite_differences(name):
    chain = CHAINS[name]()
    rng = np.random.default_rng(3)
    for q in random_q(chain, rng, 10):
        J = chain.geometric_jacobian(q)
        assert J.shape == (6, chain.n_joints)
        J_fd = fd_jacobian(chain, q)
        # Linear rows in mm/rad (up to ~5000 for the crane): FD error ~1e-6 relative.
        np.testing.assert_allclose(
            J[:3], J_fd[:3], atol=1e-5 * max(1.0, np.abs(J_fd[:3]).max())
        )
        np.testing.assert_allclose(J[3:], J_fd[3:], atol=1e-7)


@pytest.mark.parametrize("name", CHAINS)
def test_batch_jacobian_equals_stacked_single(name):
    chain = CHAINS[name]()
    qs = random_q(chain, np.random.default_rng(4), 20)
    J = chain.geometric_jacobian(qs)
    assert J.shape == (20, 6, chain.n_joints)
    np.testing.assert_allclose(
        J, np.stack([chain.geometric_jacobian(q) for q in qs]), atol=1e-12
    )


def test_prismatic_columns():
    chain = mixed_chain()
    J = chain.geometric_jacobian(random_q(chain, np.random.default_rng(5)))
    np.testing.assert_array_equal(J[3:, 1], 0.0)
    np.testing.assert_array_equal(J[3:, 3], 0.0)
    np.testing.assert_allclose(np.linalg.norm(J[:3, 1]), 1.0)


def _pytransform3d_fk(chain, q):
    """Standard DH composed with pytransform3d's own elementary transforms (an independent
    implementation): T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i), chained base -> tool."""
    pr = pytest.importorskip("pytransform3d.rotations")
    pt = pytest.importorskip("pytransform3d.transformations")
    T = np.eye(4)
    for i in range(chain.n_joints):
        theta, d = chain.theta[i], chain.d[i]
        if chain.is_revolute[i]:
            theta = theta + q[i]
        else:
            d = d + q[i]
        rz = pt.transform_from(pr.active_matrix_from_angle(2, theta), [0.0, 0.0, d])
        rx = pt.transform_from(pr.active_matrix_from_angle(0, chain.alpha[i]), [chain.a[i], 0.0, 0.0])
        # pytransform3d's concat(A2B, B2C) is A2C = B2C @ A2B: link i maps frame i into i-1
        T = pt.concat(pt.concat(rx, rz), T)
    if chain.T_flange_tool is not None:
        T = pt.concat(np.asarray(chain.T_flange_tool), T)
    return T


@pytest.mark.parametrize("make", [puma560, hiab033, mixed_chain])
def test_fk_matches_pytransform3d(make):
    """Forward kinematics against an independent library (pytransform3d), batched and single."""
    chain = make()
    qs = random_q(chain, np.random.default_rng(6), 8)
    T_ref = np.stack([_pytransform3d_fk(chain, q) for q in qs])
    np.testing.assert_allclose(chain.forward_kinematics(qs), T_ref, atol=1e-9)
    np.testing.assert_allclose(chain.forward_kinematics(qs[0]), T_ref[0], atol=1e-9)

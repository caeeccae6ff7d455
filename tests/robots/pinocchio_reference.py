"""Pinocchio as the independent reference for posekit's URDF chains (tests only)."""

import math

import numpy as np
import pytest

from posekit.robots import PRISMATIC

pin = pytest.importorskip("pinocchio")


class PinocchioChain:
    """The chain ``chain.base_link → chain.tip_link`` of a URDF file through Pinocchio (metres):
    ``T_base_tip`` in mm and ``J`` rows ``[v mm/rad; ω]`` in the base frame. Joints of the
    Pinocchio model that the posekit chain does not have stay at their neutral value."""

    def __init__(self, path, chain):
        self.model = pin.buildModelFromUrdf(str(path))
        self.data = self.model.createData()
        self.fid = self.model.getFrameId(chain.tip_link, pin.BODY)
        self.base = self.model.getFrameId(chain.base_link, pin.BODY)
        joints = [self.model.joints[self.model.getJointId(name)] for name in chain.joint_names]
        self.idx_q = [j.idx_q for j in joints]
        self.unbounded = [j.nq == 2 for j in joints]  # continuous joints: q = (cos, sin)
        self.idx_v = [j.idx_v for j in joints]
        self.prismatic = np.array([t == PRISMATIC for t in chain.joint_types])

    def __call__(self, q):
        qp = pin.neutral(self.model)
        for k, (i, value) in enumerate(zip(self.idx_q, np.where(self.prismatic, q / 1000.0, q))):
            if self.unbounded[k]:
                qp[i:i + 2] = math.cos(value), math.sin(value)
            else:
                qp[i] = value
        pin.forwardKinematics(self.model, self.data, qp)
        pin.updateFramePlacements(self.model, self.data)
        J = pin.computeFrameJacobian(self.model, self.data, qp, self.fid, pin.LOCAL_WORLD_ALIGNED)[:, self.idx_v]
        T_world_base = self.data.oMf[self.base].homogeneous
        T = np.linalg.inv(T_world_base) @ self.data.oMf[self.fid].homogeneous
        T[:3, 3] *= 1000.0
        R = T_world_base[:3, :3].T                      # world axes -> base axes
        J = np.vstack([R @ J[:3], R @ J[3:]])
        J[:3, ~self.prismatic] *= 1000.0  # m/rad -> mm/rad; prismatic columns are unitless
        return T, J


def random_q(chain, rng, n):
    """``n`` joint vectors within the chain's limits (clipped to ±π), shape (n, chain.n_joints)."""
    lo = np.clip(chain.q_min, -math.pi, math.pi)
    hi = np.clip(chain.q_max, -math.pi, math.pi)
    return rng.uniform(lo, hi, (n, chain.n_joints))


def max_differences(path, chain, qs):
    """Largest |Δ position| (mm), |Δ rotation entry| and |Δ J| (mm/rad rows, then rad/rad) between
    posekit and Pinocchio over the joint vectors ``qs``."""
    ref = PinocchioChain(path, chain)
    Ts, Js = chain.forward_kinematics_and_jacobian(qs)
    worst = np.zeros(4)
    for q, T, J in zip(qs, Ts, Js):
        T_pin, J_pin = ref(q)
        worst = np.maximum(worst, [np.abs(T[:3, 3] - T_pin[:3, 3]).max(), np.abs(T[:3, :3] - T_pin[:3, :3]).max(),
                                   np.abs(J[:3] - J_pin[:3]).max(), np.abs(J[3:] - J_pin[3:]).max()])
    return worst

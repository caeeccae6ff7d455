"""Serial manipulators from a DH table or a URDF file: one compiled forward kinematics and
geometric Jacobian for every chain, resolved-rate control, quintic point-to-point trajectories
and named robot models (DH tables and bundled vendor URDFs).

Conventions: mm and rad (mm for prismatic joints); ``T_a_b`` maps coordinates in frame b into
frame a; quaternions ``[w, x, y, z]``; batched APIs take leading batch axes (``q`` of shape
``(..., n)``).
"""

from ._kernels import fk_into, fk_jacobian_into
from .chain import PRISMATIC, REVOLUTE, KinematicChain, SerialChain
from .control import (
    RateGains,
    RateStep,
    pose_error,
    resolved_rate_step,
    resolved_rate_update,
)
from .dh import DHChain, dh_row_transform
from .models import (
    MODEL_NAMES,
    URDF_MODELS,
    bundled_robot_path,
    hiab033,
    load_robot,
    puma560,
    robot_model,
)
from .trajectory import JointSamples, quintic_trajectory
from .urdf import load_urdf

__all__ = [
    # chains
    "PRISMATIC",
    "REVOLUTE",
    "KinematicChain",
    "SerialChain",
    "DHChain",
    "dh_row_transform",
    "load_urdf",
    # compiled kernels for other numba code
    "fk_into",
    "fk_jacobian_into",
    # models
    "MODEL_NAMES",
    "URDF_MODELS",
    "bundled_robot_path",
    "hiab033",
    "load_robot",
    "puma560",
    "robot_model",
    # control
    "RateGains",
    "RateStep",
    "pose_error",
    "resolved_rate_step",
    "resolved_rate_update",
    # trajectories
    "JointSamples",
    "quintic_trajectory",
]

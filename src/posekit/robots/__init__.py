"""Serial manipulators: standard DH chains, forward kinematics, geometric Jacobian,
resolved-rate control, quintic point-to-point trajectories and named robot models.

Conventions: mm and rad; ``T_a_b`` maps coordinates in frame b into frame a; quaternions
``[w, x, y, z]``; batched APIs take a leading batch axis (``q`` of shape ``(N, n)``).
"""

from .control import RateGains, RateStep, pose_error, resolved_rate_step
from .dh import PRISMATIC, REVOLUTE, DHChain
from .models import MODEL_NAMES, hiab033, puma560, robot_model
from .trajectory import JointSamples, quintic_trajectory

__all__ = [
    # models
    "MODEL_NAMES",
    "PRISMATIC",
    "REVOLUTE",
    # chains
    "DHChain",
    # trajectories
    "JointSamples",
    # control
    "RateGains",
    "RateStep",
    "hiab033",
    "pose_error",
    "puma560",
    "quintic_trajectory",
    "resolved_rate_step",
    "robot_model",
]

"""Named robot models with their standard DH parameters (mm, rad).

Models
------
``"puma560"``
    Unimation PUMA 560, the classic 6-axis industrial arm with a spherical wrist.
    Standard DH parameters and joint limits as in P. Corke's Robotics Toolbox
    (``mdl_puma560`` / ``models.DH.Puma560``), from B. Armstrong, O. Khatib, J. Burdick,
    "The explicit dynamic model and inertial parameters of the PUMA 560 arm", ICRA 1986:

    ====  =========  ========  =========  =====  ===============
    i     a [mm]     α [rad]   d [mm]     θ₀     limits [deg]
    ====  =========  ========  =========  =====  ===============
    1     0          π/2       0          0      -160 … 160
    2     431.8      0         0          0      -45 … 225
    3     20.32      -π/2      150.05     0      -225 … 45
    4     0          π/2       431.8      0      -110 … 170
    5     0          -π/2      0          0      -100 … 100
    6     0          0         0          0      -266 … 266
    ====  =========  ========  =========  =====  ===============

``"hiab033"``
    HIAB033-like hydraulic long-reach crane with a 3-DoF wrist, the ~5 m reach laboratory
    manipulator of the long-reach manipulator paper (Table 1; six revolute joints plus
    'link 7', a fixed mock frame that aligns the last frame with the tool marker; here it
    is the tool transform ``T_flange_tool``). The paper gives the DH table only
    symbolically; **the numbers are assumptions** chosen to give a plausible geometry
    with ~5 m reach (not the laboratory's calibrated values):

    ========  =========  ========  =========  ========  =======================
    joint     a [mm]     α [rad]   d [mm]     θ₀ [rad]  limits [deg]
    ========  =========  ========  =========  ========  =======================
    rotation  a₁=300     π/2       d₁=1500    0         -170 … 170 (slewing)
    lift      a₂=2400    0         0          0         -20 … 75
    tilt      a₃=250     π/2       d₃=150     π/2       -160 … 30
    wrist 1   0          π/2       d₄=2200    0         -180 … 180
    wrist 2   0          -π/2      0          0         -120 … 120
    wrist 3   0          π/2       d₆=350     0         -180 … 180
    link 7    0          π/2       0          0         (fixed: tool transform)
    ========  =========  ========  =========  ========  =======================

    ``d₁`` is the column height, ``a₁`` the column-to-lift-joint offset, ``a₂`` the lift
    boom, ``a₃``/``d₃`` the tilt-joint offsets (along the boom / sideways), ``d₄`` the outer
    (tilt) boom with its extension held fixed, ``d₆`` the wrist-3 to tool-marker distance.
    The tilt offset ``θ₀ = π/2`` makes ``q = 0`` the stretched-out pose with both booms
    horizontal (reach ``a₁ + a₂ + d₄ + d₆ ≈ 5.25 m`` from the slewing axis).
"""

import numpy as np

from posekit.errors import ConfigError

from .dh import REVOLUTE, DHChain

__all__ = ["MODEL_NAMES", "hiab033", "puma560", "robot_model"]

_deg = np.deg2rad


def puma560() -> DHChain:
    """The PUMA 560 arm (standard DH, Corke / Armstrong et al. 1986); see the module docs."""
    return DHChain(
        a=[0.0, 431.8, 20.32, 0.0, 0.0, 0.0],
        alpha=[np.pi / 2, 0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, 0.0],
        d=[0.0, 0.0, 150.05, 431.8, 0.0, 0.0],
        theta=np.zeros(6),
        joint_types=(REVOLUTE,) * 6,
        q_min=_deg([-160.0, -45.0, -225.0, -110.0, -100.0, -266.0]),
        q_max=_deg([160.0, 225.0, 45.0, 170.0, 100.0, 266.0]),
        name="puma560",
    )


def _dh_row(a: float, alpha: float, d: float, theta: float) -> np.ndarray:
    """The fixed DH transform of eq. (24) for one row (used for the 'link 7' mock frame)."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def hiab033() -> DHChain:
    """HIAB033-like long-reach crane with a 3-DoF wrist (~5 m reach); see the module docs."""
    return DHChain(
        a=[300.0, 2400.0, 250.0, 0.0, 0.0, 0.0],
        alpha=[np.pi / 2, 0.0, np.pi / 2, np.pi / 2, -np.pi / 2, np.pi / 2],
        d=[1500.0, 0.0, 150.0, 2200.0, 0.0, 350.0],
        theta=[0.0, 0.0, np.pi / 2, 0.0, 0.0, 0.0],
        joint_types=(REVOLUTE,) * 6,
        q_min=_deg([-170.0, -20.0, -160.0, -180.0, -120.0, -180.0]),
        q_max=_deg([170.0, 75.0, 30.0, 180.0, 120.0, 180.0]),
        T_flange_tool=_dh_row(0.0, np.pi / 2, 0.0, 0.0),  # 'link 7' of Table 1
        name="hiab033",
    )


_MODELS = {"puma560": puma560, "hiab033": hiab033}
MODEL_NAMES = tuple(_MODELS)


def robot_model(name: str) -> DHChain:
    """A named robot model: one of :data:`MODEL_NAMES` (``"puma560"``, ``"hiab033"``).

    Raises
    ------
    ConfigError
        Unknown name.
    """
    try:
        return _MODELS[name]()
    except (KeyError, TypeError):
        raise ConfigError(
            f"unknown robot model {name!r}, expected one of {list(MODEL_NAMES)}"
        ) from None

"""Named robot models: two DH tables (mm, rad) and two vendor arms from bundled URDF files.

Models
------
``"puma560"``
    Unimation PUMA 560, the classic 6-axis industrial arm with a spherical wrist, in the
    standard DH parameters and joint limits of P. Corke's **MATLAB** Robotics Toolbox
    ``mdl_puma560`` (RTB 10, "params of 8/95"; after B. Armstrong, O. Khatib, J. Burdick,
    ICRA 1986, and P. Corke, B. Armstrong-Hélouvry, ICRA 1994), with one difference:
    a₃ = 20.32 mm here, 0.0203 m (20.3 mm) in ``mdl_puma560``. It is **not** the Python
    toolbox's ``roboticstoolbox.models.DH.Puma560``, whose base frame is on the floor
    (d₁ = 671.83 mm) and which has a₃ = 20.3 mm: its FK differs from this one by 672 mm in
    z. With d₁ = 0 the base frame is at the shoulder (joint 2's axis height):

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

``"abb_irb6640"``, ``"ur10"``
    ABB IRB 6640-185/2.80 and Universal Robots UR10 from their ROS-Industrial URDF
    descriptions (``examples/robots/``; sources, commits and licences in its README), loaded
    with :func:`~posekit.robots.load_urdf` from ``base_link`` to ``tool0`` / ``ee_link``.
"""

from importlib import resources
from pathlib import Path

import numpy as np

from posekit.errors import ConfigError

from .chain import KinematicChain
from .dh import REVOLUTE, DHChain, dh_row_transform
from .urdf import load_urdf

__all__ = ["MODEL_NAMES", "URDF_MODELS", "bundled_robot_path", "hiab033", "load_robot", "puma560", "robot_model"]

_deg = np.deg2rad


def puma560() -> DHChain:
    """The PUMA 560 arm (standard DH, MATLAB RTB ``mdl_puma560`` with a₃ = 20.32 mm, d₁ = 0);
    see the module docs."""
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
        T_flange_tool=dh_row_transform(0.0, np.pi / 2, 0.0, 0.0),  # 'link 7' of Table 1
        name="hiab033",
    )


#: Vendor arms shipped as URDF files under ``examples/robots/`` (attribution and licences in
#: that folder's README): name -> (file, base link, tip link).
URDF_MODELS = {
    "abb_irb6640": ("abb_irb6640_185_280.urdf", "base_link", "tool0"),
    "ur10": ("ur10.urdf", "base_link", "ee_link"),
}

_DH_MODELS = {"puma560": puma560, "hiab033": hiab033}
MODEL_NAMES = tuple(_DH_MODELS) + tuple(URDF_MODELS)


def bundled_robot_path(name: str) -> Path:
    """Path of a URDF robot shipped with posekit (``examples/robots/``), e.g. ``"ur10"``.

    Raises
    ------
    ConfigError
        Unknown name, or the file is missing from the installation.
    """
    if name not in URDF_MODELS:
        raise ConfigError(f"unknown bundled URDF robot {name!r}, expected one of {list(URDF_MODELS)}")
    file = URDF_MODELS[name][0]
    packaged = resources.files("posekit") / "_examples" / "robots" / file
    if packaged.is_file():
        return Path(str(packaged))
    repo = Path(__file__).resolve().parents[3] / "examples" / "robots" / file  # source checkout
    if repo.is_file():
        return repo
    raise ConfigError(f"bundled robot {name!r} is not installed (looked for {repo})")


def robot_model(name: str) -> KinematicChain:
    """A named robot model: one of :data:`MODEL_NAMES`.

    ``"puma560"`` and ``"hiab033"`` are DH tables (module docs); ``"abb_irb6640"`` (ABB IRB
    6640-185/2.80, 2.8 m reach, 185 kg) and ``"ur10"`` (Universal Robots UR10) are vendor URDF
    descriptions loaded with :func:`~posekit.robots.load_urdf`.

    Raises
    ------
    ConfigError
        Unknown name (the message lists the models).
    """
    if isinstance(name, str) and name in _DH_MODELS:
        return _DH_MODELS[name]()
    if isinstance(name, str) and name in URDF_MODELS:
        _, base, tip = URDF_MODELS[name]
        return load_urdf(bundled_robot_path(name), base, tip, name=name)
    raise ConfigError(f"unknown robot model {name!r}, expected one of {list(MODEL_NAMES)}")


def load_robot(spec, base_link: str | None = None, tip_link: str | None = None) -> KinematicChain:
    """A robot named the way configs and flags name one: a bundled model or a URDF file.

    Parameters
    ----------
    spec : str or Path
        One of :data:`MODEL_NAMES`, or the path of a URDF file.
    base_link, tip_link : str, optional
        The chain's ends in a URDF file (see :func:`~posekit.robots.load_urdf`).

    Raises
    ------
    ConfigError
        Neither a bundled name nor an existing file; links given for a bundled model; any
        error of :func:`~posekit.robots.load_urdf`.
    """
    text = str(spec)
    if text in MODEL_NAMES:
        if base_link is not None or tip_link is not None:
            raise ConfigError(f"robot {text!r} is a bundled model: base_link and tip_link apply to a URDF file only")
        return robot_model(text)
    path = Path(text).expanduser()
    if path.suffix.lower() != ".urdf" and not path.is_file():
        raise ConfigError(f"unknown robot {text!r}: expected a bundled model ({', '.join(MODEL_NAMES)}) "
                          "or a URDF file path")
    return load_urdf(path, base_link, tip_link)

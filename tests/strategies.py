"""Shared hypothesis strategies: rotations, translations (mm), rigid transforms, twists.

Rotations are built with scipy's ``Rotation`` directly, never with posekit, so that the
strategies stay independent of the code under test. Angles deliberately include the hard
cases: exactly 0, tiny (1e-9 rad), and within 1e-7 rad of pi.
"""

import numpy as np
from hypothesis import settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

#: Settings for property tests: few examples (the whole geometry suite stays fast), no deadline.
FAST = settings(max_examples=40, deadline=None)

#: Largest translation component drawn, in mm (a large industrial robot's reach).
REACH_MM = 2000.0


def finite_floats(lo: float, hi: float) -> st.SearchStrategy[float]:
    """Finite floats in [lo, hi]."""
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


AXES = [np.array(v, dtype=float) for v in np.vstack([np.eye(3), -np.eye(3)])]


@st.composite
def unit_vectors(draw) -> np.ndarray:
    """Unit 3-vectors (dimensionless): the six principal axes or arbitrary directions."""
    if draw(st.booleans()):
        return draw(st.sampled_from(AXES))
    v = np.array(draw(st.tuples(*[finite_floats(-1.0, 1.0)] * 3)))
    norm = np.linalg.norm(v)
    if norm < 0.1:
        return AXES[0]
    return v / norm


def rotation_angles(include_pi: bool = False) -> st.SearchStrategy[float]:
    """Rotation angles in rad in [0, pi): exactly 0, tiny, general, and within 1e-7 of pi.

    With ``include_pi`` also exactly pi (where the axis sign of a logarithm is arbitrary).
    """
    options = [
        st.just(0.0),
        st.just(1e-9),
        finite_floats(1e-12, 1e-6),
        finite_floats(0.0, np.pi - 1e-7),
        finite_floats(1e-9, 1e-7).map(lambda d: np.pi - d),
        st.just(np.pi - 1e-7),
    ]
    if include_pi:
        options.append(st.just(np.pi))
    return st.one_of(options)


@st.composite
def rotation_vectors(draw, include_pi: bool = False) -> np.ndarray:
    """Rotation vectors (unit axis times angle in rad), shape (3,); see rotation_angles."""
    return draw(unit_vectors()) * draw(rotation_angles(include_pi))


def rotation_matrices(include_pi: bool = True) -> st.SearchStrategy[np.ndarray]:
    """Rotation matrices, shape (3, 3), built by scipy from :func:`rotation_vectors`."""
    return rotation_vectors(include_pi).map(lambda v: Rotation.from_rotvec(v).as_matrix())


@st.composite
def unit_quaternions(draw) -> np.ndarray:
    """Unit Hamilton quaternions ``[w, x, y, z]`` of either sign, shape (4,).

    Either from a rotation vector (so the special angles, and ``w`` near 0, occur) or
    from four arbitrary components.
    """
    if draw(st.booleans()):
        q = Rotation.from_rotvec(draw(rotation_vectors(include_pi=True))).as_quat(
            scalar_first=True
        )
        return q if draw(st.booleans()) else -q
    q = np.array(draw(st.tuples(*[finite_floats(-1.0, 1.0)] * 4)))
    norm = np.linalg.norm(q)
    if norm < 0.1:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return q / norm


def translations_mm() -> st.SearchStrategy[np.ndarray]:
    """Translations in mm, shape (3,), components in [-REACH_MM, REACH_MM] (0 included)."""
    return st.tuples(*[finite_floats(-REACH_MM, REACH_MM)] * 3).map(np.array)


@st.composite
def transforms(draw, include_pi: bool = True) -> np.ndarray:
    """Rigid transforms ``T_a_b``, shape (4, 4), translation in mm, built without posekit."""
    T = np.eye(4)
    T[:3, :3] = draw(rotation_matrices(include_pi))
    T[:3, 3] = draw(translations_mm())
    return T


@st.composite
def twists(draw, include_pi: bool = False) -> np.ndarray:
    """Twists ``[rho (mm), phi (rad)]``, shape (6,), ``|phi| < pi`` unless ``include_pi``."""
    return np.concatenate([draw(translations_mm()), draw(rotation_vectors(include_pi))])


def batches(elements: st.SearchStrategy[np.ndarray], max_size: int = 5):
    """Stacks of 1 to ``max_size`` elements along a new leading axis."""
    return st.lists(elements, min_size=1, max_size=max_size).map(np.stack)

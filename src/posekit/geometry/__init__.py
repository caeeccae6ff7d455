"""Shared geometry: rotations, rigid transforms, SE(3) exp/log, lines, fitting.

Conventions: ``T_a_b`` maps coordinates in frame b into frame a; quaternions are Hamilton,
scalar first (``q_wxyz``); lengths in mm, angles in rad; every function takes leading batch
axes (``(..., 3, 3)``, ``(..., 4, 4)``, ``(..., 3)``).
"""

# --- rotations, rigid transforms, SE(3) (_rotations, _transforms, _se3) ----------------------
from ._rotations import (
    check_rotation_matrix,
    is_rotation_matrix,
    matrix_from_quaternion,
    matrix_from_rotation_vector,
    nearest_rotation,
    quaternion_from_matrix,
    quaternion_product,
    quaternion_wxyz_from_xyzw,
    quaternion_xyzw_from_wxyz,
    rotation_angle_between,
    rotation_vector_from_matrix,
)
from ._se3 import se3_exp, se3_log, so3_hat, so3_vee
from ._transforms import (
    apply_transform,
    check_transform,
    invert_transform,
    rotation_translation,
    transform_from,
    transform_from_quaternion,
)

__all__ = [
    # rotations
    "quaternion_from_matrix",
    "quaternion_product",
    "matrix_from_quaternion",
    "quaternion_xyzw_from_wxyz",
    "quaternion_wxyz_from_xyzw",
    "matrix_from_rotation_vector",
    "rotation_vector_from_matrix",
    "nearest_rotation",
    "is_rotation_matrix",
    "check_rotation_matrix",
    "rotation_angle_between",
    # rigid transforms
    "transform_from",
    "transform_from_quaternion",
    "rotation_translation",
    "invert_transform",
    "apply_transform",
    "check_transform",
    # SO(3) / SE(3) exp and log
    "so3_hat",
    "so3_vee",
    "se3_exp",
    "se3_log",
]

# --- lines & planes, polyline simplification, line fitting (_lines, _simplify, _fit) ---------
from ._fit import fit_line_robust, fit_line_tls, robust_line_kernel  # noqa: E402
from ._lines import (  # noqa: E402
    intersect_lines_2d,
    line_plane_intersection,
    plane_intersection,
    point_line_distance,
)
from ._simplify import rdp, rdp_mask_kernel  # noqa: E402

__all__ += [
    "plane_intersection",
    "intersect_lines_2d",
    "point_line_distance",
    "line_plane_intersection",
    "rdp",
    "rdp_mask_kernel",
    "fit_line_tls",
    "fit_line_robust",
    "robust_line_kernel",
]

# --- planar homographies: normalized DLT, refinement, RANSAC (_homography, _homography_ransac) ---
from ._homography import (  # noqa: E402
    apply_homography,
    check_correspondences,
    homography_dlt,
    normalize_homography,
    refine_homography,
)
from ._homography_ransac import homography_ransac  # noqa: E402

__all__ += [
    "homography_dlt",
    "refine_homography",
    "homography_ransac",
    "apply_homography",
    "check_correspondences",
    "normalize_homography",
]

# --- small dense solves for numba kernels (_linalg) -------------------------------------------
from ._linalg import cholesky_solve  # noqa: E402

__all__ += ["cholesky_solve"]

# --- compiled rotation conversions for other numba kernels (_rotation_kernels) ----------------
from ._rotation_kernels import quaternion_from_entries, rotvec_from_entries  # noqa: E402

__all__ += ["quaternion_from_entries", "rotvec_from_entries"]

# --- Euler angles for robot controllers (euler) -----------------------------------------------
from .euler import euler_xyz_from_matrix, euler_zyx_from_matrix, matrix_from_euler_zyx  # noqa: E402

__all__ += ["euler_zyx_from_matrix", "euler_xyz_from_matrix", "matrix_from_euler_zyx"]

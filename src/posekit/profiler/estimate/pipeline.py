"""Profile → pose, for one profile or a batch that never drops an item.

Records (JSON lines and CSV through :class:`~posekit.profiler.estimate.io.RecordWriter`) carry the
verdict of :func:`~posekit.profiler.estimate.solve.solve_pose`: ``status`` 'ok' (the data agree
with the gauge and the assumed noise), 'suspect' (an estimate exists but the consistency
test failed; ``reason`` says why) or 'error' (no estimate; ``error`` says why), with
``chi2`` and ``dof`` of the test.

Rotation output for robot controllers (:data:`ROTATIONS`; ``q_wxyz`` is always written):

``quat``
    ``q_wxyz`` only (Hamilton, scalar first).
``matrix``
    ``R``: the 3×3 rotation ``R_G_F`` (rows; columns are F's axes in G).
``euler-zyx``
    ``euler_zyx_deg = [A, B, C]``: intrinsic Z-Y'-X'' angles, ``R = Rz(A) Ry(B) Rx(C)``,
    degrees — KUKA's A, B, C (= yaw, pitch, roll about the moving axes). scipy:
    ``Rotation.from_euler("ZYX", [A, B, C], degrees=True)``.
``euler-xyz``
    ``euler_xyz_deg = [W, P, R]``: fixed-axis (extrinsic) X-Y-Z angles, rotate by W about
    G's x, then P about G's y, then R about G's z: ``R = Rz(R) Ry(P) Rx(W)`` — Fanuc's
    W, P, R and ABB's Euler angles as RobotStudio shows them. scipy:
    ``Rotation.from_euler("xyz", [W, P, R], degrees=True)``. The same matrix as euler-zyx
    with the angles in the other order: ``[W, P, R] = [C, B, A]``.

Euler angles: the first and last in (-180°, 180°], the middle one in [-90°, 90°]. At
gimbal lock (middle angle ±90°) the last angle of euler-zyx (C; W of euler-xyz) is set to
0 and the first carries the whole turn, as scipy does. A pose looking straight down at
the gauge is near C = ±180°, where C wraps from +180 to -180 between neighbouring poses.

Quaternion sign along a batch: ``q`` and ``-q`` are the same rotation. A single profile
gets the canonical sign (``w >= 0``); in a batch (:func:`estimate_batch`,
``continuous=True``) the first estimate is canonical and every later one takes the sign
whose dot product with the previous estimate's quaternion is non-negative (records
without an estimate are skipped), so a controller interpolating the stream never takes
the long way round. A sensor looking down at the gauge is near a 180° turn about x,
where ``w ≈ 0`` and the canonical sign would flip between neighbouring poses.
"""

from collections.abc import Iterator

import numpy as np

from ...errors import EstimationError, PosekitError
from .corners import CornerParams, Corners, detect_corners
from .gauge import Gauge
from .sensor import NoiseModel
from .solve import DEFAULT_SIGNIFICANCE, PoseEstimate, solve_pose

__all__ = ["estimate_pose", "estimate_batch", "ok_record", "error_record", "rotation_fields",
           "euler_zyx_from_matrix", "ROTATIONS", "DEFAULT_NOISE"]

#: Rotation formats of the records (module docstring).
ROTATIONS = ("quat", "matrix", "euler-zyx", "euler-xyz")
#: The noise the estimator assumes unless told: the LJ-X8400's repeatability (10 µm in x,
#: 5 µm in z), the simulator's default.
DEFAULT_NOISE = NoiseModel()
#: cos B below which euler-zyx is at gimbal lock (|B| within about 1e-7 deg of 90°).
_GIMBAL_COS = 2e-9


def estimate_pose(profile, gauge: Gauge, method: str = "mle", mounting: str = "auto",
                  params: CornerParams = CornerParams(), T_init=None, *, noise: NoiseModel = DEFAULT_NOISE,
                  significance: float = DEFAULT_SIGNIFICANCE) -> tuple[Corners, PoseEstimate]:
    """Corners and pose ``T_G_F`` from one laser profile, with the verdict.

    Parameters
    ----------
    profile : array_like, shape (N, 2)
        Points (x, z) in F, mm, scan order, NaN = no return.
    gauge : Gauge
    method : {'mle', 'cf'}
    mounting : {'auto', 'normal', 'reversed'}
    params : CornerParams
    T_init : ndarray, shape (4, 4), optional
        Start pose for the refinement (e.g. the previous pose of a stream).
    noise : NoiseModel
        The sensor noise the estimator assumes (``sigma_x_um``, ``sigma_z_um``); default
        the LJ-X8400's 10/5 µm. The corner covariance, the pose's standard deviations and
        the consistency test follow it.
    significance : float
        α of the consistency test (:data:`~posekit.profiler.estimate.solve.DEFAULT_SIGNIFICANCE`).

    Returns
    -------
    corners : Corners
    estimate : PoseEstimate
        ``status`` 'ok' or 'suspect' with its ``reason``.

    Raises
    ------
    ProfileError, EstimationError
    """
    corners = detect_corners(profile, gauge, params)  # the model-based detector (the gauge's section)
    return corners, solve_pose(corners, gauge, method=method, mounting=mounting, T_init=T_init, noise=noise,
                               significance=significance)


def euler_zyx_from_matrix(R) -> np.ndarray:
    """Intrinsic Z-Y'-X'' angles ``[A, B, C]`` (rad) with ``R = Rz(A) Ry(B) Rx(C)``.

    Parameters
    ----------
    R : array_like, shape (3, 3)

    Returns
    -------
    ndarray, shape (3,)
        A, C in (-π, π], B in [-π/2, π/2]; at gimbal lock (``cos B ≈ 0``) C = 0.
    """
    R = np.asarray(R, dtype=np.float64)
    cb = np.hypot(R[0, 0], R[1, 0])
    b = np.arctan2(-R[2, 0], cb)
    if cb > _GIMBAL_COS:
        a = np.arctan2(R[1, 0], R[0, 0])
        c = np.arctan2(R[2, 1], R[2, 2])
    else:                                  # B = ±90°: only A ∓ C is defined; put it all in A
        a = np.arctan2(-R[0, 1], R[1, 1])
        c = 0.0
    return np.array([a, b, c]) + 0.0


def rotation_fields(R_G_F, rotation: str = "quat") -> dict:
    """The record fields of a rotation in the format ``rotation`` (:data:`ROTATIONS`).

    Parameters
    ----------
    R_G_F : array_like, shape (3, 3)
    rotation : {'quat', 'matrix', 'euler-zyx', 'euler-xyz'}

    Returns
    -------
    dict
        ``{}`` for 'quat' (``q_wxyz`` is always in the record), ``{"R": 3×3}``,
        ``{"euler_zyx_deg": [A, B, C]}`` or ``{"euler_xyz_deg": [W, P, R]}`` (degrees).
    """
    if rotation not in ROTATIONS:
        raise EstimationError(f"unknown rotation format '{rotation}'; expected one of {', '.join(ROTATIONS)}")
    R = np.asarray(R_G_F, dtype=np.float64)
    if rotation == "matrix":
        return {"R": [[float(v) for v in row] for row in R]}
    if rotation == "quat":
        return {}
    abc = np.degrees(euler_zyx_from_matrix(R))
    if rotation == "euler-zyx":
        return {"euler_zyx_deg": [float(v) for v in abc]}
    return {"euler_xyz_deg": [float(v) for v in abc[::-1]]}


def ok_record(index: int, corners: Corners, est: PoseEstimate, rotation: str = "quat", q_prev=None) -> dict:
    """The record of an estimate, 'ok' or 'suspect' (corners in ridge order).

    Parameters
    ----------
    index : int
    corners : Corners
    est : PoseEstimate
    rotation : str
        One of :data:`ROTATIONS`: which extra rotation field the record carries.
    q_prev : array_like, shape (4,), optional
        The previous record's quaternion: ``q_wxyz`` takes the sign with ``q · q_prev >= 0``
        (canonical ``w >= 0`` without it).
    """
    pts = corners.points[::-1] if est.reversed else corners.points
    q = est.q_wxyz
    if q_prev is not None and float(np.dot(q, q_prev)) < 0:
        q = -q
    return {
        "index": int(index),
        "status": est.status,
        "t_mm": [float(v) for v in est.t_mm],
        "q_wxyz": [float(v) + 0.0 for v in q],
        **rotation_fields(est.T_G_F[:3, :3], rotation),
        "reprojection_um": float(est.reprojection_um),
        "corners_mm": [[float(x), float(z)] for x, z in pts],
        "std_t_um": [float(v) for v in est.std_t_um],
        "std_rot_deg": [float(v) for v in est.std_rot_deg],
        "chi2": float(est.chi2),
        "dof": int(est.dof),
        "reason": est.reason,
        "error": None,
    }


_ROTATION_NULLS = {"quat": {}, "matrix": {"R": None}, "euler-zyx": {"euler_zyx_deg": None},
                   "euler-xyz": {"euler_xyz_deg": None}}


def error_record(index: int, message: str, rotation: str = "quat") -> dict:
    """The record of a profile without an estimate (status 'error', the reason in ``error``)."""
    return {"index": int(index), "status": "error", "t_mm": None, "q_wxyz": None,
            **_ROTATION_NULLS.get(rotation, {}), "reprojection_um": None, "corners_mm": None, "std_t_um": None,
            "std_rot_deg": None, "chi2": None, "dof": None, "reason": None, "error": message}


def estimate_batch(profiles, gauge: Gauge, method: str = "mle", mounting: str = "auto",
                   params: CornerParams = CornerParams(), *, noise: NoiseModel = DEFAULT_NOISE,
                   significance: float = DEFAULT_SIGNIFICANCE, rotation: str = "quat",
                   continuous: bool = True) -> Iterator[tuple[dict, PoseEstimate | None]]:
    """Estimate every profile of a batch; a failure becomes an error record, never a gap.

    Parameters
    ----------
    profiles : array_like, shape (K, N, 2)
    gauge, method, mounting, params, noise, significance
        As :func:`estimate_pose`.
    rotation : str
        Extra rotation field of the records (:data:`ROTATIONS`).
    continuous : bool
        Quaternion sign continuous along the batch (module docstring); False: canonical
        ``w >= 0`` in every record.

    Yields
    ------
    record : dict
        One record per profile, in order (see :func:`ok_record`, :func:`error_record`).
    estimate : PoseEstimate or None
    """
    if rotation not in ROTATIONS:
        raise EstimationError(f"unknown rotation format '{rotation}'; expected one of {', '.join(ROTATIONS)}")
    profiles = np.asarray(profiles, dtype=np.float64)
    q_prev = None
    for k in range(profiles.shape[0]):
        try:
            corners, est = estimate_pose(profiles[k], gauge, method, mounting, params, noise=noise,
                                         significance=significance)
        except PosekitError as exc:
            yield error_record(k, str(exc), rotation), None
            continue
        rec = ok_record(k, corners, est, rotation, q_prev)
        if continuous:
            q_prev = rec["q_wxyz"]
        yield rec, est

"""Profile → pose, for one profile or a batch that never drops an item.

Records (JSON lines and CSV through :class:`~posekit.profiler.stream.records.RecordWriter`) carry the
verdict of :func:`~posekit.profiler.estimate.solve.solve_pose`: ``status`` 'ok' (the data agree
with the gauge and the assumed noise), 'suspect' (an estimate exists but the consistency
test failed; ``reason`` says why) or 'error' (no estimate; ``error`` says why), with
``chi2`` and ``dof`` of the test. One profile cannot see every gauge that differs from its
file (a face off its drawing can look like a pose shifted along y); a batch
(:func:`estimate_profiles`, :func:`estimate_batch`) also tests the gauge file against all its
profiles together (:mod:`~posekit.profiler.gauge.check`).

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

Euler angles (:mod:`posekit.geometry.euler`): the first and last in (-180°, 180°], the
middle one in [-90°, 90°]. At gimbal lock (middle angle ±90°) the last angle of euler-zyx (C; W of euler-xyz) is set to
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

from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace

import numpy as np

from ...errors import EstimationError, PosekitError
from ...geometry import euler_zyx_from_matrix
from ...verdict import Verdict, batch_exit_code, status_counts
from ..gauge.check import GaugeCheck, check_gauge_file
from ..gauge.model import Gauge
from ..sensor import NoiseModel
from .consistency import DEFAULT_SIGNIFICANCE
from .corner_params import CornerParams
from .corners import Corners, detect_corners
from .result import STD_KEYS, PoseEstimate, failed_verdict
from .solve import solve_pose

__all__ = ["estimate_pose", "estimate_batch", "estimate_profiles", "BatchResult", "ok_record", "error_record",
           "rotation_fields", "ROTATIONS", "STATUSES", "DEFAULT_NOISE"]

#: Rotation formats of the records (module docstring).
ROTATIONS = ("quat", "matrix", "euler-zyx", "euler-xyz")
#: The noise the estimator assumes unless told: the LJ-X8400's repeatability (10 µm in x,
#: 5 µm in z), the simulator's default.
DEFAULT_NOISE = NoiseModel()


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
    abc = np.degrees(euler_zyx_from_matrix(R, check=False))
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
    v = est.verdict
    return {
        "index": int(index),
        "status": v.status,
        "t_mm": [float(x) for x in est.t_mm],
        "q_wxyz": [float(x) + 0.0 for x in q],
        **rotation_fields(est.T_G_F[:3, :3], rotation),
        "reprojection_um": float(est.reprojection_um),
        "corners_mm": [[float(x), float(z)] for x, z in pts],
        "std_t_um": [v.std[k] for k in STD_KEYS[:3]],
        "std_rot_deg": [v.std[k] for k in STD_KEYS[3:]],
        "chi2": float(est.chi2),
        "dof": int(est.dof),
        "reason": v.reason or None,
        "error": None,
    }


_ROTATION_NULLS = {"quat": {}, "matrix": {"R": None}, "euler-zyx": {"euler_zyx_deg": None},
                   "euler-xyz": {"euler_xyz_deg": None}}


def error_record(index: int, message: str, rotation: str = "quat") -> dict:
    """The record of a profile without an estimate (its verdict ``Verdict.failed(message)``: status
    'error', the message in ``error``; ``reason`` stays null, as DESIGN.md's records have it)."""
    v = failed_verdict(message)
    return {"index": int(index), "status": v.status, "t_mm": None, "q_wxyz": None,
            **_ROTATION_NULLS.get(rotation, {}), "reprojection_um": None, "corners_mm": None, "std_t_um": None,
            "std_rot_deg": None, "chi2": None, "dof": None, "reason": None, "error": v.reasons[0]}


#: The status words of a profile's verdict, in the order a batch counts them.
STATUSES = ("ok", "suspect", "error")


@dataclass(frozen=True)
class BatchResult:
    """Result of :func:`estimate_profiles`.

    Attributes
    ----------
    records : list of dict
        One record per profile, in order (:func:`ok_record`, :func:`error_record`).
    estimates : list of PoseEstimate or None
        The estimate behind each record (None for an error); its ``status`` and ``reason``
        are the record's.
    gauge_check : GaugeCheck or None
        The test of the gauge file against the whole batch (None when not asked for).
    """

    records: list
    estimates: list
    gauge_check: GaugeCheck | None

    @property
    def verdicts(self) -> list[Verdict]:
        """The :class:`posekit.verdict.Verdict` of each profile, in order: the estimate's, or
        ``Verdict.failed(error)`` for a profile without one."""
        return [est.verdict if est is not None else failed_verdict(rec["error"])
                for rec, est in zip(self.records, self.estimates)]

    def status_counts(self) -> dict[str, int]:
        """How many profiles are 'ok', 'suspect' and 'error' (:func:`posekit.verdict.status_counts`)."""
        return status_counts((rec["status"] for rec in self.records), STATUSES)

    @property
    def exit_code(self) -> int:
        """The batch command's exit code (:func:`posekit.verdict.batch_exit_code`): 0 only if every
        profile is 'ok'."""
        return batch_exit_code(rec["status"] for rec in self.records)


def estimate_profiles(profiles, gauge: Gauge, method: str = "mle", mounting: str = "auto",
                      params: CornerParams = CornerParams(), *, noise: NoiseModel = DEFAULT_NOISE,
                      significance: float = DEFAULT_SIGNIFICANCE, rotation: str = "quat", continuous: bool = True,
                      check_gauge: bool = True, progress: Callable | None = None) -> BatchResult:
    """Estimate every profile of a batch, then test the gauge file against the whole batch.

    Each profile gets its own verdict (:func:`estimate_pose`). One profile cannot tell a face
    machined off its drawing from a pose shifted along the weakly observable y (see
    :mod:`~posekit.profiler.gauge.check`): such a pose reads 'ok' while it is off by
    several times its std. A batch can: with ``check_gauge`` and enough profiles at varied
    poses (:data:`~posekit.profiler.gauge.check.MIN_CHECK_PROFILES`, the laser line
    turned about its line of sight between them), a bundle adjustment of every face and every
    pose tests the file's planes within their declared ``tolerance_um`` at ``significance``;
    when the file fails, every estimate of the batch becomes 'suspect' and its reason names
    the faces, their offset in µm and ``posekit profiler calibrate-gauge``. A batch too small
    or too alike leaves the statuses alone, and ``gauge_check.checked`` is False with the why.

    Parameters
    ----------
    profiles : array_like, shape (K, N, 2)
        Points (x, z) in F, mm, scan order, NaN = no return.
    gauge, method, mounting, params, noise, significance
        As :func:`estimate_pose`.
    rotation, continuous
        As :func:`estimate_batch`.
    check_gauge : bool
        Test the gauge file against the batch (default True).
    progress : callable, optional
        Wraps the iterable of profile indices (e.g. a progress bar).

    Returns
    -------
    BatchResult
    """
    if rotation not in ROTATIONS:
        raise EstimationError(f"unknown rotation format '{rotation}'; expected one of {', '.join(ROTATIONS)}")
    profiles = np.asarray(profiles, dtype=np.float64)
    indices = range(profiles.shape[0])
    corners_all, ests, errors = [], [], []
    for k in (indices if progress is None else progress(indices)):
        try:
            corners, est = estimate_pose(profiles[k], gauge, method, mounting, params, noise=noise,
                                         significance=significance)
        except PosekitError as exc:
            corners, est = None, None
            errors.append((k, str(exc)))
        corners_all.append(corners)
        ests.append(est)
    check = None
    if check_gauge:
        check = check_gauge_file(corners_all, ests, gauge, noise=noise, significance=significance)
        if check.passed is False:
            ests = [None if e is None else replace(e, status="suspect", reasons=(*e.reasons, check.message))
                    for e in ests]
    records = []
    err = dict(errors)
    q_prev = None
    for k, (corners, est) in enumerate(zip(corners_all, ests)):
        if est is None:
            records.append(error_record(k, err[k], rotation))
            continue
        rec = ok_record(k, corners, est, rotation, q_prev)
        if continuous:
            q_prev = rec["q_wxyz"]
        records.append(rec)
    return BatchResult(records, ests, check)


def estimate_batch(profiles, gauge: Gauge, method: str = "mle", mounting: str = "auto",
                   params: CornerParams = CornerParams(), *, noise: NoiseModel = DEFAULT_NOISE,
                   significance: float = DEFAULT_SIGNIFICANCE, rotation: str = "quat",
                   continuous: bool = True, check_gauge: bool = True) -> Iterator[tuple[dict, PoseEstimate | None]]:
    """Estimate every profile of a batch; a failure becomes an error record, never a gap.

    The records of :func:`estimate_profiles` (the gauge file tested against the whole batch
    when ``check_gauge``; the first record comes after the last profile is estimated).

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
    check_gauge : bool
        As :func:`estimate_profiles`.

    Yields
    ------
    record : dict
        One record per profile, in order (see :func:`ok_record`, :func:`error_record`).
    estimate : PoseEstimate or None
    """
    res = estimate_profiles(profiles, gauge, method, mounting, params, noise=noise, significance=significance,
                            rotation=rotation, continuous=continuous, check_gauge=check_gauge)
    yield from zip(res.records, res.estimates)

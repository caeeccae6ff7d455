"""Profile → pose, for one profile or a batch that never drops an item."""

from collections.abc import Iterator

import numpy as np

from ..errors import PosekitError
from .corners import CornerParams, Corners, detect_corners
from .gauge import Gauge
from .solve import PoseEstimate, solve_pose

__all__ = ["estimate_pose", "estimate_batch", "ok_record", "error_record"]


def estimate_pose(profile, gauge: Gauge, method: str = "mle", mounting: str = "auto",
                  params: CornerParams = CornerParams(), T_init=None) -> tuple[Corners, PoseEstimate]:
    """Corners and pose ``T_G_F`` from one laser profile.

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

    Returns
    -------
    corners : Corners
    estimate : PoseEstimate

    Raises
    ------
    ProfileError, EstimationError
    """
    corners = detect_corners(profile, gauge.n_corners, params, gauge.name)
    return corners, solve_pose(corners, gauge, method=method, mounting=mounting, T_init=T_init)


def ok_record(index: int, corners: Corners, est: PoseEstimate) -> dict:
    """The record of a successful estimate (:class:`~posekit.profiler.io.RecordWriter`; corners in ridge order)."""
    pts = corners.points[::-1] if est.reversed else corners.points
    return {
        "index": int(index),
        "status": "ok",
        "t_mm": [float(v) for v in est.t_mm],
        "q_wxyz": [float(v) for v in est.q_wxyz],
        "reprojection_um": float(est.reprojection_um),
        "corners_mm": [[float(x), float(z)] for x, z in pts],
        "std_t_um": [float(v) for v in est.std_t_um],
        "std_rot_deg": [float(v) for v in est.std_rot_deg],
        "error": None,
    }


def error_record(index: int, message: str) -> dict:
    """The record of a failed profile (:class:`~posekit.profiler.io.RecordWriter`)."""
    return {"index": int(index), "status": "error", "t_mm": None, "q_wxyz": None, "reprojection_um": None,
            "corners_mm": None, "std_t_um": None, "std_rot_deg": None, "error": message}


def estimate_batch(profiles, gauge: Gauge, method: str = "mle", mounting: str = "auto",
                   params: CornerParams = CornerParams()) -> Iterator[tuple[dict, PoseEstimate | None]]:
    """Estimate every profile of a batch; a failure becomes an error record, never a gap.

    Parameters
    ----------
    profiles : array_like, shape (K, N, 2)
    gauge, method, mounting, params
        As :func:`estimate_pose`.

    Yields
    ------
    record : dict
        One record per profile, in order (see :func:`ok_record`, :func:`error_record`).
    estimate : PoseEstimate or None
    """
    profiles = np.asarray(profiles, dtype=np.float64)
    for k in range(profiles.shape[0]):
        try:
            corners, est = estimate_pose(profiles[k], gauge, method, mounting, params)
        except PosekitError as exc:
            yield error_record(k, str(exc)), None
            continue
        yield ok_record(k, corners, est), est

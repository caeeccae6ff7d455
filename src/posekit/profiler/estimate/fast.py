"""One profile → pose with its verdict, unchecked: the real-time path.

:func:`estimate_profile_unchecked` is :func:`~posekit.profiler.estimate.pipeline.estimate_pose`
without the input validation and without exceptions: the same compiled detector
(:func:`~posekit.profiler.estimate.corners.detect_corners_unchecked`) and the same solver and
verdict (:func:`~posekit.profiler.estimate.solve.estimate_from_corners`, which
:func:`~posekit.profiler.estimate.solve.solve_pose` calls too), so a streamed pose, its
covariance, χ² and status are the offline ones. It adds what a stream needs: a start pose from
the previous frame (retried from the closed form when it lands in a poor minimum) and the
detection time. A failure is a result with ``status == "error"`` and the message, never an
exception.
"""

import time
from dataclasses import dataclass

import numpy as np

from ...errors import ProfileError
from ...verdict import Verdict
from ..sensor import NoiseModel
from .consistency import DEFAULT_SIGNIFICANCE, chi2_critical
from .corner_params import CornerParams
from .corners import Corners, detect_corners_unchecked, raise_for_status
from .pipeline import DEFAULT_NOISE
from .result import PoseEstimate, failed_verdict, pose_std
from .solve import METHODS, estimate_from_corners, status_message

__all__ = ["ProfileResult", "estimate_profile_unchecked", "warm_gate"]

_ORDERS = ((False, True), (False,), (True,))        # by mounting code: auto, normal, reversed


@dataclass(frozen=True, slots=True)
class ProfileResult:
    """Result of :func:`estimate_profile_unchecked`.

    Attributes
    ----------
    status : {'ok', 'suspect', 'error'}
        As :attr:`PoseEstimate.status`; 'error' when there is no estimate.
    error : str or None
        Why there is no estimate (status 'error').
    reasons : tuple of str
        Why the estimate is suspect (:attr:`PoseEstimate.reasons`).
    T_G_F : ndarray, shape (4, 4) or None
    cov : ndarray, shape (6, 6) or None
        Pose covariance ``[δt mm, δθ rad]`` in G (:attr:`PoseEstimate.cov`).
    reprojection_um, chi2 : float or None
    dof : int or None
    reversed : bool or None
    corners : Corners or None
        Detected corners in scan order (None when detection failed).
    n_valid : int
        Points of the profile with a return (x and z finite).
    cold_restart : bool
        The start pose was retried from the closed form.
    detect_ns : int
        Time of the corner detection, ns.
    estimate : PoseEstimate or None
        The estimate itself (what :func:`~posekit.profiler.estimate.solve.solve_pose` returns).
    """

    status: str
    error: str | None = None
    reasons: tuple[str, ...] = ()
    T_G_F: np.ndarray | None = None
    cov: np.ndarray | None = None
    reprojection_um: float | None = None
    chi2: float | None = None
    dof: int | None = None
    reversed: bool | None = None
    corners: Corners | None = None
    n_valid: int = 0
    cold_restart: bool = False
    detect_ns: int = 0
    estimate: PoseEstimate | None = None

    @property
    def reason(self) -> str | None:
        """The reasons joined by ``"; "``, or None (the record's ``reason``)."""
        return "; ".join(self.reasons) or None

    @property
    def verdict(self) -> Verdict:
        """:class:`posekit.verdict.Verdict` of the profile: the estimate's (status, reasons, std), or
        ``Verdict.failed(error)`` when there is none. Built on each call: the server's hot path reads
        :attr:`status` and :attr:`reason` alone."""
        if self.estimate is not None:
            return self.estimate.verdict
        if self.status == "error":
            return failed_verdict(self.error)
        return Verdict(self.status, self.reasons, None if self.cov is None else pose_std(self.cov))

    @property
    def R(self) -> np.ndarray | None:
        """Rotation ``R_G_F`` (3, 3), or None."""
        return None if self.T_G_F is None else self.T_G_F[:3, :3]

    @property
    def t(self) -> np.ndarray | None:
        """Translation of F in G, mm, (3,), or None."""
        return None if self.T_G_F is None else self.T_G_F[:3, 3]


def warm_gate(n_corners: int) -> float:
    """Cost above which a warm start is taken for a wrong minimum: the 1e-6 tail of χ²(2n - 6)."""
    return chi2_critical(1e-6, 2 * n_corners - 6)


def estimate_profile_unchecked(points, gauge, params: CornerParams, turns, method_code: int, mounting_code: int,
                               T_init=None, rev_init: bool = False, *, noise: NoiseModel | None = DEFAULT_NOISE,
                               significance: float = DEFAULT_SIGNIFICANCE, max_iter: int = 20,
                               gate: float | None = None) -> ProfileResult:
    """Corners, pose and verdict of one profile, as :func:`~posekit.profiler.estimate.pipeline.estimate_pose`.

    No validation: the caller guarantees the types and ranges below (the server checks them
    once, at construction).

    Parameters
    ----------
    points : ndarray, shape (N, 2), float64, C-contiguous
        Points (x, z) in F, mm, scan order, NaN = no return (no infinities).
    gauge : Gauge
        A gauge that is not ambiguous with mounting 'auto'.
    params : CornerParams
    turns : ndarray
        :func:`~posekit.profiler.estimate.corners.gauge_turns` of the gauge.
    method_code, mounting_code : int
        Indices into :data:`~posekit.profiler.estimate.solve.METHODS` and
        :data:`~posekit.profiler.estimate.solve.MOUNTINGS`.
    T_init : ndarray, shape (4, 4), optional
        Start pose (the previous frame's) for the corner order ``rev_init``; the other order
        starts from the closed form.
    rev_init : bool
        The corner order ``T_init`` belongs to (the previous frame's ``reversed``).
    noise : NoiseModel or None
        The assumed noise (default the LJ-X8400's, as the offline estimator).
    significance : float
    max_iter : int
    gate : float, optional
        A start from ``T_init`` whose cost exceeds it is retried from the closed form
        (e.g. :func:`warm_gate`); None: never.

    Returns
    -------
    ProfileResult
    """
    n = gauge.n_corners
    t0 = time.perf_counter_ns()
    status, info, pts, ccov, lines, sig, npts, cand = detect_corners_unchecked(points, n, params, turns)
    detect_ns = time.perf_counter_ns() - t0
    n_valid = int(info[1])
    if status != 0:
        try:
            raise_for_status(status, info, npts, cand, n, gauge.name, gauge)
        except ProfileError as exc:
            return ProfileResult("error", error=str(exc), n_valid=n_valid, detect_ns=detect_ns)
    corners = Corners(points=pts, cov=ccov, lines=lines, sigma=sig, n_points=npts)
    orders = _ORDERS[mounting_code]
    T_inits = (None, None)
    if T_init is not None:
        T_inits = (None, T_init) if rev_init else (T_init, None)
        if rev_init and len(orders) == 2:
            orders = (True, False)          # the previous frame's order first
    est, cold = estimate_from_corners(corners, gauge, METHODS[method_code], orders, T_inits, max_iter, noise,
                                      significance, gate)
    if not isinstance(est, PoseEstimate):
        return ProfileResult("error", error=status_message(est, n), corners=corners, n_valid=n_valid,
                             cold_restart=cold, detect_ns=detect_ns)
    return ProfileResult(est.status, reasons=est.reasons, T_G_F=est.T_G_F, cov=est.cov,
                         reprojection_um=est.reprojection_um, chi2=est.chi2, dof=est.dof, reversed=est.reversed,
                         corners=corners, n_valid=n_valid, cold_restart=cold, detect_ns=detect_ns, estimate=est)

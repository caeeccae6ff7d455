"""The result of a pose estimate from one profile: the pose, its covariance and its verdict.

:class:`PoseEstimate` is what :func:`~posekit.profiler.estimate.solve.solve_pose` returns. Its
verdict is the shared :class:`posekit.verdict.Verdict` (:attr:`PoseEstimate.verdict`): the
status word ('ok' or 'suspect', from the consistency tests of
:mod:`~posekit.profiler.estimate.consistency`), the reasons, and the standard deviation of each
pose component (:data:`STD_KEYS`: translation along x, y, z of G in µm, rotation about them in
degrees). A profile without an estimate has no :class:`PoseEstimate`; its verdict is
``Verdict.failed(message)`` (:func:`failed_verdict`).
"""

import functools
from dataclasses import dataclass

import numpy as np

from ...geometry import quaternion_from_matrix
from ...verdict import Verdict

__all__ = ["PoseEstimate", "STD_KEYS", "pose_std", "failed_verdict"]

#: The components of a pose's std in :attr:`Verdict.std <posekit.verdict.Verdict.std>`, in the
#: order of the records' ``std_t_um`` then ``std_rot_deg``.
STD_KEYS = ("tx_um", "ty_um", "tz_um", "rx_deg", "ry_deg", "rz_deg")


def pose_std(cov) -> dict[str, float]:
    """1σ of each pose component from the pose covariance ``[δt mm, δθ rad]`` (6, 6): :data:`STD_KEYS` → value."""
    d = np.diag(np.asarray(cov))
    t_um = np.sqrt(d[:3]) * 1e3
    rot_deg = np.degrees(np.sqrt(d[3:]))
    return dict(zip(STD_KEYS, [float(v) for v in t_um] + [float(v) for v in rot_deg]))


def failed_verdict(message: str) -> Verdict:
    """The verdict of a profile without an estimate: status 'error' and the one reason."""
    return Verdict.failed(message)


@dataclass(frozen=True)
class PoseEstimate:
    """Result of :func:`~posekit.profiler.estimate.solve.solve_pose`.

    Attributes
    ----------
    T_G_F : ndarray, shape (4, 4)
        Pose of the profiler frame F in the gauge frame G, mm.
    cov : ndarray, shape (6, 6)
        Covariance of the pose error ``[δt (mm), δθ (rad)]`` with both parts in G
        (``t_true = t + δt``, ``R_true = Exp(δθ) R``), propagated from the corners (and
        the gauge's tolerance): for 'mle' the inverse Fisher information, for 'cf' the
        closed form's own linearisation ``J C Jᵀ`` (its error is far larger).
    reprojection_um : float
        Mean distance of the estimated 3D corners from their ridges, µm.
    cost : float
        The refinement's objective at the estimate: ``rᵀ C⁻¹ r`` with ``C`` the line fits'
        corner covariance (plus the gauge's tolerance).
    reversed : bool
        True when the corners matched the ridges in reverse order (sensor mounted the
        other way round).
    method : str
    chi2 : float
        Consistency statistic of the fit, ``rᵀ C⁻¹ r`` with ``C`` under the assumed noise
        (equal to ``cost`` for 'mle' without one; the closed form's own linearisation for
        'cf'): χ²(dof) on data that match the model.
    dof : int
        ``2n - 6``.
    status : {'ok', 'suspect'}
    reasons : tuple of str
        Why the estimate is suspect (empty when 'ok'), one sentence per failed test.
    """

    T_G_F: np.ndarray
    cov: np.ndarray
    reprojection_um: float
    cost: float
    reversed: bool
    method: str
    chi2: float = float("nan")
    dof: int = 0
    status: str = "ok"
    reasons: tuple[str, ...] = ()

    @property
    def reason(self) -> str | None:
        """The reasons joined by ``"; "`` (the records' ``reason``), or None when there are none."""
        return "; ".join(self.reasons) or None

    @functools.cached_property
    def verdict(self) -> Verdict:
        """:class:`posekit.verdict.Verdict`: the status, the reasons and the std of each pose component
        (:data:`STD_KEYS`). Built on first use (the real-time path reads :attr:`status` alone)."""
        return Verdict(self.status, self.reasons, pose_std(self.cov))

    @property
    def t_mm(self) -> np.ndarray:
        """Translation of F in G, mm, shape (3,)."""
        return self.T_G_F[:3, 3]

    @property
    def q_wxyz(self) -> np.ndarray:
        """Rotation of F in G as a unit quaternion [w, x, y, z], shape (4,)."""
        return quaternion_from_matrix(self.T_G_F[:3, :3])

    @property
    def std_t_um(self) -> np.ndarray:
        """Predicted standard deviation of the translation along x, y, z of G, µm."""
        return np.sqrt(np.diag(self.cov)[:3]) * 1e3

    @property
    def std_rot_deg(self) -> np.ndarray:
        """Predicted standard deviation of the rotation about x, y, z of G, degrees."""
        return np.degrees(np.sqrt(np.diag(self.cov)[3:]))

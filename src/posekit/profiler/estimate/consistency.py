"""The consistency tests that make a pose from one profile 'ok' or 'suspect' (DESIGN.md "Trust").

The tests read the error model of :mod:`~posekit.profiler.estimate.covariance` (the corners'
covariance under the assumed noise, the gauge's tolerance and the sensor's scale) and give
the estimate of :func:`~posekit.profiler.estimate.solve.solve_pose` its status and reasons
(:class:`~posekit.profiler.estimate.result.PoseEstimate`, whose ``verdict`` is the shared
:class:`posekit.verdict.Verdict`).

Verdict (DESIGN.md "Trust"). Every estimate carries ``status`` 'ok' or 'suspect' with a
``reason``, from a χ² test at significance α (default :data:`DEFAULT_SIGNIFICANCE`, the
rate at which good data are called suspect; split equally over the tests made):

* **fit**: ``χ² = rᵀ C⁻¹ r`` of the corner residuals at the estimate, with ``C`` the
  corners' covariance under the assumed noise plus the gauge's ``tolerance_um`` (each
  face's position uncertain by that 1σ, mapped to the corners at the estimated pose)
  plus the sensor's unknown scale (:func:`~posekit.profiler.estimate.covariance.scale_covariance`, 1σ ``noise.scale_sigma_ppm``,
  default 100 ppm, only with an assumed ``noise``), against χ²(2n - 6). The refinement
  itself is weighted by the line fits' own covariance (plus the tolerance and the scale),
  as the real-time server weights it, so the offline and streamed poses agree; on data
  that match the model the two weightings differ by sampling only. The scale term is what
  makes the std honest on a real sensor: a scale error of 100 ppm moves the corners mostly
  as a pose change would, so it biases the pose (demo-5, realistic profiles: without it
  only ~60 % of the errors lay within 2σ, rz ~10 %; with it 96 %) and, left out, also made
  ~5 % of good realistic profiles suspect (with it 2 in 10,000).
  For the closed form, r and its covariance come from the closed form's own linearisation
  (its pseudo-inverse, rank 2n - 6). It catches a wrong gauge
  file, a face machined off its drawing beyond the tolerance, a rounded or chamfered
  ridge that moves a corner, a wrong basin (a local minimum fits badly).
* **noise** (only with an assumed ``noise`` model): the scatter of the profile's points
  about the fitted faces, ``Σ RSS_j / σ_j²`` against χ²(Σ (N_j - 2)) with σ_j the assumed
  noise across face j. Noise above the sensor model's makes the covariance a lie.
* **ambiguity** (mounting 'auto'): the other corner order fits too (passes the fit test at
  a possible pose); **possibility**: the best fit would see a face from behind.

The assumed noise is explicit: ``noise=NoiseModel(...)`` (the estimator entry points in
:mod:`~posekit.profiler.estimate.pipeline` default to the LJ-X8400's 10/5 µm). With ``noise=None``
the corner covariance comes from the line fits' own residuals (the noise is estimated,
so the test sees the geometry but not the noise level) — the behaviour of the studies.

A batch adds one more test, of the gauge file against all its profiles together
(:mod:`~posekit.profiler.gauge.check`): what one profile cannot see.
"""

import functools

import numpy as np

from posekit._chi2 import chi2 as _chi2

from ...errors import EstimationError
from ..gauge.ambiguity import SEEN_FROM_BEHIND_COS, piercing_points
from ..gauge.raycast import seen_from_behind
from .corners import Corners
from .covariance import face_sigma_mm, noise_statistic
from .result import PoseEstimate

__all__ = ["DEFAULT_SIGNIFICANCE", "chi2_critical", "check_noise", "judge", "Candidate"]

#: Default significance α of the consistency test: the rate at which data that match the
#: model are called suspect. Measured on simulated good data of the bundled gauges
#: (``python -m posekit.profiler.studies.verdict_rates``, docs/data/profiler_verdict_rates.csv):
#: well under 1 % suspect.
DEFAULT_SIGNIFICANCE = 1e-3


class Candidate:
    """One corner order's solution; what only the verdict may need is computed on demand."""

    __slots__ = ("rev", "T", "cov", "reprojection_mm", "cost", "chi2", "_c", "_gauge", "_resid", "_possible")

    def __init__(self, rev, T, cov, reprojection_mm, cost, chi2, c, gauge):
        self.rev, self.T, self.cov, self.reprojection_mm, self.cost, self.chi2 = rev, T, cov, reprojection_mm, cost, chi2
        self._c = c                   # corners in ridge order
        self._gauge = gauge
        self._resid = None
        self._possible = None

    @property
    def resid_mm(self) -> np.ndarray:
        """|corner - predicted| per ridge, mm."""
        if self._resid is None:
            P = piercing_points(self._gauge, self.T[:3, :3], self.T[:3, 3])
            self._resid = (np.full(len(self._c), np.nan) if P is None
                           else np.sqrt(np.sum((self._c - P) ** 2, axis=1)))
        return self._resid

    @property
    def possible(self) -> bool:
        """Whether the pose could have produced the corners (no face seen from behind)."""
        if self._possible is None:
            self._possible = not seen_from_behind(self._gauge.normals, self.T, self._c, SEEN_FROM_BEHIND_COS)
        return self._possible


@functools.lru_cache(maxsize=4096)
def chi2_critical(alpha: float, dof: int) -> float:
    """Critical value of the χ² test: ``chi2.isf(alpha, dof)`` (0 for ``dof <= 0``), cached.

    The real-time path evaluates it per frame; SciPy's ``isf`` costs ~30 µs a call.
    """
    return float(_chi2.isf(alpha, dof)) if dof > 0 else 0.0


def _noise_verdict(corners: Corners, noise, alpha: float) -> str | None:
    """The reason why the profile is noisier than ``noise`` allows, or None."""
    stat, dof = noise_statistic(np.ascontiguousarray(corners.lines, dtype=np.float64),
                                 np.ascontiguousarray(corners.sigma, dtype=np.float64),
                                 np.ascontiguousarray(corners.n_points, dtype=np.int64),
                                 noise.sigma_x_um * 1e-3, noise.sigma_z_um * 1e-3)
    crit = chi2_critical(alpha, int(dof))
    if not stat > crit:
        return None
    stat, dof = float(stat), int(dof)
    sig = face_sigma_mm(corners, noise)
    ratio = corners.sigma / sig
    j = int(np.argmax(ratio))
    return (f"the profile scatters {np.sqrt(stat / dof):.2f}x the assumed noise about its faces (chi2 = {stat:.0f} "
            f"> {crit:.0f}, {dof} dof, worst face {j}: {corners.sigma[j] * 1e3:.1f} µm RMS, expected "
            f"{sig[j] * 1e3:.1f} µm): noisier than the sensor model (x {noise.sigma_x_um:g} µm, "
            f"z {noise.sigma_z_um:g} µm) or a face that is not flat")


def check_noise(noise) -> None:
    """Raise an :class:`~posekit.errors.EstimationError` unless ``noise`` is None or a usable noise model."""
    if noise is None:
        return
    sx = getattr(noise, "sigma_x_um", None)
    sz = getattr(noise, "sigma_z_um", None)
    if sx is None or sz is None:
        raise EstimationError(f"noise: expected a NoiseModel (sigma_x_um, sigma_z_um), got {type(noise).__name__}")
    if not (np.isfinite(sx) and np.isfinite(sz) and sx >= 0 and sz >= 0 and sx + sz > 0):
        raise EstimationError(f"noise: the assumed noise must be finite, >= 0 and not zero in both x and z, "
                              f"got x {sx:g} µm, z {sz:g} µm")


def judge(cands, corners: Corners, gauge, method: str, noise, significance: float) -> PoseEstimate:
    """The best candidate (a possible pose first, then the lower χ²) with its verdict (module docstring)."""
    n = corners.points.shape[0]
    # A possible pose first, then the lower χ²: the other candidate's possibility is only
    # looked at when it matters (the lower χ² is impossible, or the other one fits too).
    cands.sort(key=lambda c: c.chi2 if np.isfinite(c.chi2) else np.inf)
    if len(cands) == 2 and not cands[0].possible and cands[1].possible:
        cands.reverse()
    best = cands[0]

    dof = 2 * n - 6
    alpha = significance / (2 if noise is not None else 1)
    crit = chi2_critical(alpha, dof)
    reasons = []
    if not best.chi2 <= crit:
        k = int(np.nanargmax(best.resid_mm)) if np.any(np.isfinite(best.resid_mm)) else 0
        what = (f"the assumed noise (x {noise.sigma_x_um:g} µm, z {noise.sigma_z_um:g} µm)" if noise is not None
                else "the line fits' noise")
        reasons.append(f"chi2 = {best.chi2:.1f} > {crit:.1f} ({dof} dof, significance {alpha:g}): the corners do "
                       f"not fit gauge '{gauge.name}' within {what} and its tolerance ({gauge.tolerance_um:g} µm), "
                       f"largest miss at corner {k} ({best.resid_mm[k] * 1e3:.1f} µm): wrong gauge file, a face off "
                       "its drawing, a rounded or chamfered ridge, or a wrong basin")
    if noise is not None:
        why = _noise_verdict(corners, noise, alpha)
        if why is not None:
            reasons.append(why)
    if not best.possible:
        reasons.append("at the fitted pose the sensor would see a face from behind (through the gauge): no real "
                       "pose gives these corners")
    if len(cands) == 2 and cands[1].chi2 <= crit and cands[1].possible:
        reasons.append(f"the {'normal' if best.rev else 'reversed'} corner order fits too (chi2 = "
                       f"{cands[1].chi2:.1f} <= {crit:.1f}): the mounting cannot be told from this profile, "
                       "give it (--mounting normal|reversed)")
    # reasons hold no "; " of their own: the record joins them with it
    return PoseEstimate(T_G_F=best.T, cov=best.cov, reprojection_um=best.reprojection_mm * 1e3, cost=best.cost,
                        reversed=best.rev, method=method, chi2=float(best.chi2), dof=dof,
                        status="suspect" if reasons else "ok", reasons=tuple(reasons))

"""Integrity of the seam track: is the filter's pose to be believed at this step?

DESIGN.md "Trust": a tracker says ``tracking`` only when the data agree with its model. Three
consistency statistics are computed at every step and turned into a status
``tracking`` / ``degraded`` / ``lost``:

Laser innovations (normalised innovation squared, NIS)
    Before the lasers weight the particles, each particle predicts each laser reading; the
    in-plane errors ``e_i = m̂_i - pi_i`` (eq. 9) of the cloud give the predictive mean ``ē`` and
    covariance ``C = Cov_w(e) + R`` of the innovation (``R`` the readings' noise) (all sensors of the step stacked, their
    correlation through the shared pose kept). ``NIS = ēᵀ C⁻¹ ē`` is χ² with ``2 S`` degrees of
    freedom when the model holds; the sums over the last ``window`` steps are tested against
    the χ² quantiles at two levels. A robot that bends more than the filter allows pulls the
    cloud away from where the lasers see the seam: the innovations grow. A second, long window
    tests each reading component on its own (``ē_j² / C_jj``, sensor k's x and z) against the mean
    and the effective degrees of freedom the profile's own training episodes showed (``seam tune``
    fits them: on a real cell the predictive covariance is never exactly the innovations', and the
    steps are correlated). A latency nobody declared shows there, mostly in the lateral
    component of the sensor farthest ahead, long before it shows in the sum of every component.
Robot consistency
    The estimate's offset from the kinematic pose ``Fk(q + Cj(τ))``, beyond the robot density's
    plateau (eq. 8: the part outside the ball of radius ``d(f)``), against the Gaussian tails
    plus the estimate's own spread: a Mahalanobis distance per block (translation, rotation),
    χ² with 3 degrees of freedom. The plateau is the largest expected positioning error; an
    estimate outside it says the robot or the lasers are not what the model assumes.
The kinematics' offset (:mod:`posekit.seam.engine.offset_test`)
    The estimate's offset from the kinematic pose over the long window, against what the profile's training
    episodes showed: the kinematics err otherwise than when the profile was fitted.
Effective sample size
    The ESS of the update before tempering: below ``ess_min · N`` the measurements are
    unlikely under nearly every particle (the cloud is somewhere else).

The robot model's range
    The plateau ``d0 + kd ‖f‖`` is the largest positioning error measured on the robot, at the
    forces it was measured at; above ``max_force_n`` it is an extrapolation the tests above cannot
    check where the lasers do not see (25 kN on the default cell, whose plateau was measured up to
    12 kN: the truth leaves the plateau in 6 of 30 runs, up to 1.19×, and one run in ten stays
    2-3σ off in the roll for ~100 steps while every test passes). Such a step is ``degraded``.

Status: ``lost`` when a test fails at ``alpha_lost`` (or every weight vanished), ``degraded``
when one fails at ``alpha_degraded`` or the ESS collapsed, or within ``recovery`` steps after a
``lost`` step (re-acquiring), or the force is beyond the robot model's range, ``tracking``
otherwise. The filter's own walk reacts to the short tests alone (``tests_status``): a force beyond
the range says nothing about whether the cloud has lost the seam, and a wider walk would absorb the
small persistent inconsistency the long window catches (``window_long``: a latency nobody declared). One step's
NIS enters the window capped at its own ``alpha_degraded`` quantile (a step beyond its own
``alpha_lost`` quantile is ``lost`` by itself), so one wrong prior that the update corrects
does not condemn the next ``window - 1`` steps.

Limit (measured, issue 15): the tests see what the lasers and the robot measurement can
contradict. An estimate that is wrong only in directions neither constrains (inside the robot
plateau) passes them; there the verdict is only as good as the reported spread
(:mod:`posekit.seam.engine.spread_bound`). Under 25 kN, with the force range check off, every
step was ``tracking`` and the laser NIS per degree of freedom 0.83 on average (nominal 0.75),
while one run in ten stayed 2-3σ off in the roll for ~100 steps after the start: the force range
is what says the model no longer holds there. After a wrong start the filter is ``lost``, then
``degraded`` for ``recovery`` steps; the steps beyond 3σ later still ``tracking`` are tails of
the spread itself (a filter whose spread is exact has up to ~1.6 % such steps with six axes).
"""

import math
from collections import deque
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from posekit._chi2 import chi2
from posekit.seam.engine._cloud_kernels import weighted_moments_kernel
from posekit.seam.engine.densities import robot_consistency
from posekit.seam.engine.offset_test import OffsetTest
from posekit.seam.engine.window_sum import WindowSum

__all__ = [
    "STATUSES",
    "IntegrityMonitor",
    "IntegrityReport",
    "innovation_nis",
    "robot_consistency",
]

#: The three statuses, best first.
STATUSES = ("tracking", "degraded", "lost")



@lru_cache(maxsize=16384)
def _chi2_isf(alpha: float, dof: float) -> float:
    """The upper ``alpha`` quantile of a χ² with ``dof`` degrees of freedom (shared by every monitor)."""
    return float(chi2.isf(alpha, dof))

def innovation_nis(errors: np.ndarray, w: np.ndarray, noise_var, per_component: bool = False, signed: bool = False):
    """Normalised innovation squared of one step's laser readings under the predictive cloud.

    Parameters
    ----------
    errors : ndarray, shape (N, 2 S)
        Per particle, the in-plane errors ``m̂ - pi`` (mm, sensor x then z) of each of the S
        readings of the step (NaN where the particle's laser plane meets no seam).
    w : ndarray, shape (N,)
        Normalised predictive weights (the particles before the lasers weight them).
    noise_var : float or ndarray, shape (2 S,)
        Variance of each error component's noise (mm²): the laser noise plus the pose jitter through the
        sensor's lever; one value for all.

    Returns
    -------
    nis : float
        ``ēᵀ C⁻¹ ē`` with ``ē = Σ w e``, ``C = Σ w (e - ē)(e - ē)ᵀ + diag(noise_var)`` over the particles
        whose every plane meets the seam (weights renormalised); ``inf`` when those carry less
        than 1e-3 of the weight (the cloud cannot explain the readings together).
    dof : int
        ``2 S`` of the readings some particle places on the seam (a reading beyond the seam model's end,
        where every particle's plane misses it, is left out).
    components : ndarray, shape (2 S,)
        Only with ``per_component``: each component's own normalised squared innovation ``ē_j² / C_jj``
        (χ² with 1 degree of freedom when the model holds; NaN where no particle places the reading on the seam,
        or where the cloud cannot explain the readings). With ``signed``: ``ē_j / √C_jj`` instead (its square is
        that; standard normal when the model holds), what the bias test low-passes (:func:`bias_series`).
    """
    u = np.full(errors.shape[1], np.nan)
    # a reading no particle can place on the seam (beyond the seam model's end) tells nothing about the cloud
    seen = np.isfinite(errors).any(axis=0)
    if not seen.all():
        errors = errors[:, seen]
        noise_var = np.broadcast_to(noise_var, seen.shape)[seen] if np.ndim(noise_var) else noise_var
    k = errors.shape[1]
    if k == 0:
        return (0.0, 0, u) if per_component else (0.0, 0)
    mean = np.empty(k)
    C = np.empty((k, k))
    total = weighted_moments_kernel(np.ascontiguousarray(errors, dtype=np.float64),
                                       np.ascontiguousarray(w, dtype=np.float64), mean, C)
    if not total >= 1e-3:
        return (math.inf, k, u) if per_component else (math.inf, k)
    C[np.diag_indices(k)] += noise_var
    try:
        nis = float(mean @ np.linalg.solve(C, mean))
    except np.linalg.LinAlgError:
        nis = math.inf
    nis = nis if math.isfinite(nis) else math.inf
    if not per_component:
        return nis, k
    with np.errstate(divide="ignore", invalid="ignore"):
        u[seen] = mean / np.sqrt(np.diag(C)) if signed else mean * mean / np.diag(C)
    return nis, k, u


def bias_series(r: np.ndarray, window: int) -> np.ndarray:
    """Each component's squared mean signed innovation over the last ``window`` steps: the bias test's statistic.

    Parameters
    ----------
    r : ndarray, shape (T, C)
        Per step the signed normalised innovations (:func:`innovation_nis` with ``signed``; NaN: no reading).
    window : int
        Steps averaged (>= 1).

    Returns
    -------
    ndarray, shape (T, C)
        ``(mean of the readings among steps k - window + 1 .. k)²``; NaN where that stretch holds fewer than
        ``max(1, window // 2)`` readings. The monitor computes the same step by step (``IntegrityMonitor``'s
        ``bias_window``); ``seam tune`` calibrates it on the training episodes.
    """
    r = np.asarray(r, dtype=np.float64)
    seen = np.isfinite(r)
    v = np.where(seen, r, 0.0)
    cs = np.vstack([np.zeros((1, r.shape[1])), np.cumsum(v, axis=0)])
    cn = np.vstack([np.zeros((1, r.shape[1])), np.cumsum(seen, axis=0)])
    lo = np.maximum(np.arange(1, len(r) + 1) - int(window), 0)
    total = cs[1:] - cs[lo]
    count = cn[1:] - cn[lo]
    with np.errstate(divide="ignore", invalid="ignore"):
        m = total / count
    return np.where(count >= max(1, int(window) // 2), m * m, np.nan)


@dataclass
class IntegrityReport:
    """The verdict of one step.

    Attributes
    ----------
    status : str
        ``tracking``, ``degraded`` or ``lost``.
    reason : str or None
        Which test failed (None when tracking), e.g. ``"laser NIS 85.1 > 45.3 (dof 20)"``.
    nis_window : float
        Sum of the laser NIS over the window.
    dof_window : int
        Its degrees of freedom (0: no laser reading in the window).
    robot_maha_t, robot_maha_r : float
        :func:`robot_consistency` of this step.
    ess_update : float
        ESS of the update before tempering.
    tests_status : str
        The status from the consistency tests alone (without the robot model's force range):
        what the filter's walk reacts to.
    """

    status: str
    reason: str | None
    nis_window: float
    dof_window: int
    robot_maha_t: float
    robot_maha_r: float
    ess_update: float
    tests_status: str = "tracking"


class IntegrityMonitor:
    """Windowed consistency tests turned into a per-step status (see the module docstring).

    Parameters
    ----------
    n_particles : int
    window : int
        Steps whose laser NIS are summed (>= 1).
    window_long : int
        Steps of a second, longer window tested at ``alpha_degraded`` only (0: none): a small inconsistency that
        persists (a latency the filter was not told, a mount that moved) is degraded. It tests each reading
        component (sensor k's x and z) on its own, against what the profile's training episodes showed
        (``nis_mean``, ``nis_dof``), at ``alpha_degraded`` split over the components (Bonferroni).
    alpha_degraded, alpha_lost : float
        Test levels in (0, 0.5]: the probability that a consistent filter fails the test at one
        step (``alpha_lost`` < ``alpha_degraded``).
    ess_min : float
        ESS collapse threshold, fraction of ``n_particles``.
    recovery : int
        Steps after a ``lost`` step that are at most ``degraded`` (0: none): the re-acquired cloud
        has passed the tests, but its spread is that of a cloud rebuilt from few survivors
        (measured, issue 15: a start 14 mm / 5° off, 10 runs, without it 59 % of the steps
        whose error exceeds 3σ are ``tracking``, most in the 20 steps after the track is found again).
    max_force_n : float
        The largest force magnitude (N) the robot plateau was measured at; a step above it is
        ``degraded`` at best (0: no limit).
    nis_mean, nis_dof : array_like, shape (2 S,), optional
        Per reading component (sensor k's x at ``2k``, z at ``2k + 1``): the mean normalised squared innovation
        ``ē_j² / C_jj`` on the episodes the profile was fitted on, and its effective χ² degrees of freedom per
        reading (``2 / (τ var)``: below 1 when the steps are correlated or the tails heavier than Gaussian).
        Fitted by ``seam tune`` (:mod:`posekit.seam.frontend.tune_nis`); None: 1 and 1 (the model's own χ²₁).
        Over ``n`` readings of the long window the sum ``s_j`` is tested as ``s_j / (nis_mean_j) ~ χ²(ν) / ρ``
        with ``ρ = nis_dof_j`` and ``ν = ρ n``.
    degraded_reason : str, optional
        A reason that holds for every step (the profile was fitted on another cell): each step is ``degraded``
        at best, with it.
    bias_window : int
        Steps over which each component's *signed* innovation is averaged for the bias test (0: none). A latency
        nobody declared, a mount that moved, leave a bias in the innovations that changes slowly with the
        motion; squared step by step it is diluted in the noise (on the independent cell of the tests the
        lateral NIS of the sensor ahead rises 1.6×), averaged over a few steps first it stands out (its squared
        10-step mean rises 10-17×). The squared mean (:func:`bias_series`) enters the long window as a
        component of its own, tested like the NIS against the profile's ``bias_mean`` and ``bias_dof``.
    bias_mean, bias_dof : array_like, shape (2 S,), optional
        Per reading component the mean of that squared mean on the training episodes and its effective χ²
        degrees of freedom per step (``seam tune``; None: 1 / ``bias_window`` and 3 / (2 ``bias_window``), a
        white unit-variance innovation's).
    offset_mean, offset_sd, offset_samples : array_like, shape (6,), optional
        The offset test (with ``window_long``; :class:`~posekit.seam.engine.offset_test.OffsetTest`). None: no
        offset test.
    """

    def __init__(self, n_particles: int, window: int, alpha_degraded: float, alpha_lost: float, ess_min: float,
                 recovery: int, max_force_n: float, window_long: int = 0, nis_mean=None, nis_dof=None,
                 degraded_reason: str | None = None, bias_window: int = 0, bias_mean=None, bias_dof=None,
                 offset_mean=None, offset_sd=None, offset_samples=None):
        self.n = int(n_particles)
        self.degraded_reason = degraded_reason
        self.bias_window = max(0, int(bias_window))
        self._bias_mean = None if bias_mean is None else np.asarray(bias_mean, dtype=np.float64).reshape(-1)
        self._bias_dof = None if bias_dof is None else np.asarray(bias_dof, dtype=np.float64).reshape(-1)
        self._recent: deque = deque(maxlen=max(1, self.bias_window))   # the last signed innovations
        self.window_long = max(0, int(window_long))
        self._nis_mean = None if nis_mean is None else np.asarray(nis_mean, dtype=np.float64).reshape(-1)
        self._nis_dof = None if nis_dof is None else np.asarray(nis_dof, dtype=np.float64).reshape(-1)
        self._long = WindowSum(self.window_long)   # the capped components' sums (2 S,) and readings per component
        self.max_force_n = float(max_force_n)
        self.recovery = max(0, int(recovery))
        self._since_lost = None
        self.window = max(1, int(window))
        self.alpha_degraded = float(alpha_degraded)
        self.alpha_lost = float(alpha_lost)
        self.ess_min = float(ess_min)
        self._nis: deque = deque(maxlen=self.window)
        self._q_cache: dict[int, tuple[float, float]] = {}
        self._q3 = self._quantiles(3)
        self._offset = (OffsetTest(offset_mean, offset_sd, offset_samples, self.window_long, self.window,
                                   self.alpha_degraded)
                        if self.window_long and offset_sd is not None and offset_mean is not None
                        and offset_samples is not None else None)
        if self._offset is not None and not self._offset.active:
            self._offset = None

    def _quantiles(self, dof: int) -> tuple[float, float]:
        q = self._q_cache.get(dof)
        if q is None:
            q = (_chi2_isf(self.alpha_degraded, dof), _chi2_isf(self.alpha_lost, dof))
            self._q_cache[dof] = q
        return q

    @property
    def tests_offset(self) -> bool:
        """Whether the monitor has an offset test (it then wants each step's ``offset``)."""
        return self._offset is not None

    @property
    def since_lost(self) -> int | None:
        """Steps since the last ``lost`` step (None: none since reset); the filter's re-acquiring phase."""
        return self._since_lost

    def reset(self) -> None:
        """Forget the windows (a new episode)."""
        self._nis.clear()
        self._recent.clear()
        self._long.clear()
        if self._offset is not None:
            self._offset.reset()
        self._since_lost = None

    @staticmethod
    def _levels(values, n: int, default: float) -> np.ndarray:
        """One calibration value per each of ``n`` components (one x/z pair given for every sensor: repeated)."""
        if values is None:
            return np.full(n, default)
        if values.size == n:
            return values
        if values.size == 2 and n % 2 == 0:
            return np.tile(values, n // 2)
        raise ValueError(f"integrity: {values.size} innovation calibration values for {n} reading components; "
                         "expected one x/z pair per sensor or one for all")

    def _component_levels(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Means and degrees of freedom of the long window's ``n`` components: the NIS (``nis_mean``,
        ``nis_dof``), then, with a bias test, the squared means (``bias_mean``, ``bias_dof``)."""
        if not self.bias_window:
            return self._levels(self._nis_mean, n, 1.0), self._levels(self._nis_dof, n, 1.0)
        h, w = n // 2, self.bias_window
        return (np.concatenate([self._levels(self._nis_mean, h, 1.0), self._levels(self._bias_mean, h, 1.0 / w)]),
                np.concatenate([self._levels(self._nis_dof, h, 1.0), self._levels(self._bias_dof, h, 1.5 / w)]))

    def _add_long(self, components) -> None:
        """Put one step's per-component NIS into the long window (capped like the step's total)."""
        u = np.asarray(components, dtype=np.float64).reshape(-1)
        if self._long.sum is None or self._long.sum.size != u.size:
            self._c, self._rho = self._component_levels(u.size)
            self._u_cap = self._c * _chi2_isf(self.alpha_degraded, 1)
        seen = np.isfinite(u)
        self._long.add(np.minimum(np.where(seen, u, 0.0), self._u_cap), seen)

    @property
    def _long_sum(self):
        return self._long.sum

    @property
    def _long_n(self):
        return self._long.n

    def _long_test(self) -> str | None:
        """The reason the long window fails (None: it passes; see ``nis_mean``)."""
        if self._long_sum is None or self._long_sum.size == 0:   # no sensor: nothing to test
            return None
        C = self._long_sum.size
        alpha = self.alpha_degraded / C
        worst = None
        for j in range(C):
            n = int(self._long_n[j])
            if n <= self.window:    # the short window's business
                continue
            c, rho = float(self._c[j]), float(self._rho[j])
            limit = _chi2_isf(alpha, rho * n) / (rho * n)
            ratio = float(self._long_sum[j]) / (c * n)
            if ratio > limit and (worst is None or ratio / limit > worst[0]):
                h = C // 2 if self.bias_window else C      # the NIS components, then the bias test's
                k, a = (j % h) // 2 + 1, "xz"[j % 2]
                if j >= h:
                    what = (f"sensor {k}'s {a} innovations biased: their {self.bias_window}-step means over the last "
                            f"{n} readings {ratio:.3g} x the profile's bias_mean_{a} (> {limit:.3g})")
                else:
                    what = (f"sensor {k}'s {a} innovations over the last {n} readings {ratio:.3g} x the profile's "
                            f"nis_mean_{a} (> {limit:.3g})")
                worst = (ratio / limit, what)
        return None if worst is None else worst[1]

    def update(self, nis: float, dof: int, robot_maha_t: float, robot_maha_r: float, ess_update: float,
               recovered: bool = False, force_norm_n: float = 0.0, components=None,
               innovations=None, offset=None) -> IntegrityReport:
        """Add one step's statistics and return its verdict.

        Parameters
        ----------
        nis, dof : float, int
            :func:`innovation_nis` of the step (``dof`` 0: no laser reading).
        robot_maha_t, robot_maha_r : float
            :func:`robot_consistency` of the step.
        ess_update : float
            ESS of the update before tempering.
        recovered : bool
            Every weight vanished at this step (the filter was reset to uniform weights).
        force_norm_n : float
            The step's measured force magnitude, N (against ``max_force_n``).
        components : array_like, shape (2 S,), optional
            The step's per-component NIS (:func:`innovation_nis` with ``per_component``; NaN: no reading), for the
            long window (None: no long test at this step).
        innovations : array_like, shape (2 S,), optional
            The step's signed normalised innovations (:func:`innovation_nis` with ``signed``), for the bias test
            (``bias_window``; None: not at this step).
        offset : array_like, shape (6,), optional
            The step's :func:`~posekit.seam.engine.offset_test.kinematic_offset` (None: none at this step).
        """
        # one step's NIS enters the window capped at its own degraded quantile: a single failed step (a
        # wrong start the update then corrects) is lost at that step but does not fail the next
        # window-1 steps alone; a persistent inconsistency still adds up
        q_step = self._quantiles(dof) if dof > 0 else (0.0, 0.0)
        cap = q_step[1]
        capped = min(nis, q_step[0])
        self._nis.append((capped, dof))
        s = float(sum(v for v, _ in self._nis))
        d = int(sum(k for _, k in self._nis))
        if self.window_long and components is not None:
            if self.bias_window:
                r = np.full(np.size(components), np.nan) if innovations is None else np.asarray(innovations, float)
                self._recent.append(r.reshape(-1))
                components = np.concatenate([np.asarray(components, dtype=np.float64).reshape(-1),
                                             bias_series(np.array(self._recent), self.bias_window)[-1]])
            self._add_long(components)
        if self._offset is not None:
            self._offset.add(offset)
        level = 0
        reasons = []
        if dof > 0 and nis > cap:
            level = 2
            reasons.append(f"laser NIS {nis:.4g} > {cap:.4g} at this step (dof {dof})")

        def fail(lvl, text):
            nonlocal level
            level = max(level, lvl)
            reasons.append(text)

        if recovered:
            fail(2, "every particle weight vanished")
        if d > 0 and level < 2:
            q_deg, q_lost = self._quantiles(d)
            if s > q_deg:
                fail(2 if s > q_lost else 1, f"laser NIS {s:.4g} > {q_deg if s <= q_lost else q_lost:.4g} "
                                             f"(dof {d})")
        q_deg, q_lost = self._q3
        for name, m in (("translation", robot_maha_t), ("rotation", robot_maha_r)):
            if not m <= q_deg:  # NaN fails too
                fail(2 if not m <= q_lost else 1, f"{name} {m:.4g} beyond the robot plateau (chi2 3 dof)")
        if not ess_update >= self.ess_min * self.n:
            fail(1, f"ESS {ess_update:.3g} < {self.ess_min * self.n:.3g}")
        if level == 2:
            self._since_lost = 0
        elif self._since_lost is not None:
            self._since_lost += 1
            if self._since_lost <= self.recovery:
                fail(1, f"re-acquiring: lost {self._since_lost} step(s) ago")
        tests_level = level
        # a small inconsistency that persists (a latency nobody declared, an encoder offset): degraded, but the walk
        # is not widened for it (a wider walk would absorb it, and the next window would pass)
        if self.window_long and level < 1:
            why = self._long_test() or (None if self._offset is None else self._offset.test())
            if why is not None:
                fail(1, why)
        if self.max_force_n > 0.0 and not force_norm_n <= self.max_force_n:  # NaN is beyond too
            fail(1, f"force {force_norm_n / 1e3:.3g} kN beyond the {self.max_force_n / 1e3:.3g} kN the robot "
                    "plateau was fitted at (profile plateau.max_force_n)")
        if self.degraded_reason:             # the standing reason first: it holds whatever the tests say
            level = max(level, 1)
            reasons.insert(0, self.degraded_reason)
        return IntegrityReport(STATUSES[level], "; ".join(reasons) or None, s, d, robot_maha_t, robot_maha_r,
                               ess_update, STATUSES[tests_level])

"""``posekit seam tune --with-truth``: the profile from the errors against ``truth.csv`` (see :mod:`.tune`)."""

import math
from dataclasses import replace

import numpy as np
from scipy.optimize import minimize, minimize_scalar
from scipy.stats import t as student_t

from posekit.errors import EstimationError
from posekit.geometry import invert_transform, rotation_vector_from_matrix
from posekit.seam.engine import _kernels as _k
from posekit.seam.engine.densities import joint_compliance
from posekit.seam.engine.ekf import LinearisedEpisode, reading_mounts
from posekit.seam.frontend.profile import AXES, ProfileModel
from posekit.seam.frontend.tune_filter import run_filter
from posekit.seam.frontend.tune_fit import (
    FORCE_SPAN,
    PINNED,
    _curvature_std,
    _knots,
    _sensor_key,
    episode_arrays,
    local_level_fit,
)
from posekit.seam.frontend.tune_intervals import score_edge, uniform_rms

__all__ = ["fit_truth"]

def _offsets(log, cell):
    """Per step: the truth's offset from the modelled motion ``(D_k Fk(q̄_k))⁻¹ T_true,k`` in the tool frame
    ``(T, 6)`` (mm, rad), from the kinematic pose ``Fk(q + Cj(τ))`` ``(T, 3)`` translation (base) and
    rotation vector ``(T, 3)`` (base), the measured force in the base frame ``(T, 3)``, the true and nominal
    tool poses ``(T, 4, 4)`` (base, mm) and the kinematic pose ``Fk(q + Cj(τ))`` itself ``(T, 4, 4)``."""
    from posekit.seam.engine.densities import robot_measurement

    chain = cell.chain
    arr = episode_arrays(log)
    cj = joint_compliance(cell.compliance_rad_per_nm) if cell.compliance_rad_per_nm > 0.0 else None
    Tn = chain.forward_kinematics(log.qref, check=False)
    truth = np.matmul(Tn, log.truth_seam_tool)
    n = len(log.time_s)
    X = np.empty((n, 4, 4))
    K = np.empty((n, 4, 4))
    for k in range(n):
        meas = robot_measurement(chain, log.q[k], arr.force_base_n[k], joint_sigma_rad=0.0, floor_t_mm=1.0,
                                 floor_r_rad=1.0, d0_mm=0.0, kd_mm_per_n=0.0, d0_rad=0.0, kd_rad_per_n=0.0,
                                 compliance=cj)
        K[k] = meas.T_mean
        X[k] = Tn[k] if meas.T_deflection is None else meas.T_deflection @ Tn[k]
    Xi = invert_transform(X, check=False)
    rel = np.matmul(Xi, truth)
    delta = np.hstack([rel[:, :3, 3], rotation_vector_from_matrix(rel[:, :3, :3], check=False)])
    dt_base = truth[:, :3, 3] - K[:, :3, 3]
    dr_base = rotation_vector_from_matrix(truth[:, :3, :3] @ np.swapaxes(K[:, :3, :3], 1, 2), check=False)
    return delta, dt_base, dr_base, arr.force_base_n, truth, Tn, K


def _envelope(f: np.ndarray, e: np.ndarray) -> tuple[float, float]:
    """The tightest line ``d0 + kd f`` (both >= 0) above every ``(f_k, e_k)``, minimising its mean over ``f``."""
    from scipy.optimize import linprog

    res = linprog(c=[1.0, float(np.mean(f))], A_ub=np.c_[-np.ones_like(f), -f], b_ub=-e,
                  bounds=[(0.0, None), (0.0, None)], method="highs")
    if not res.success:
        return float(np.max(e)), 0.0
    return float(res.x[0]), float(res.x[1])


def _rotation_envelope(f: np.ndarray, par: np.ndarray, perp: np.ndarray, kd_fixed: float | None) -> tuple[float, float]:
    """The bending plateau ``|Δ⊥|² / (d0 + kd f)² + |Δ∥|² / d0² <= 1`` around every rotation offset, with the
    smallest ``d0 + kd f̄`` (kd given, or the least for each d0 on a scan of d0)."""
    fbar = float(np.mean(f))
    lo = max(float(np.max(par)) * (1.0 + 1e-9), 1e-9)
    hi = max(lo, float(np.max(np.hypot(par, perp)))) * 4.0 + 1e-9

    def kd_for(d0):
        room = 1.0 - (par / d0) ** 2
        need = perp / np.sqrt(np.clip(room, 1e-12, None))  # d0 + kd f >= need
        if kd_fixed is not None:
            return kd_fixed if np.all(d0 + kd_fixed * f >= need - 1e-15) else math.inf
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.where(f > 0.0, (need - d0) / f, np.where(need > d0, math.inf, 0.0))
        return max(0.0, float(np.max(k)))

    grid = np.geomspace(lo, hi, 400)
    cost = np.array([d0 + kd_for(d0) * fbar for d0 in grid])
    i = int(np.argmin(cost))
    if not np.isfinite(cost[i]):
        return float(hi), kd_fixed or 0.0
    return float(grid[i]), float(kd_for(grid[i]))


def fit_truth(logs, work: ProfileModel, share: bool, put, runs_out: list | None = None, say=None) -> float:
    """Walk, jitter, laser noise, latency and plateau from the errors against ``truth.csv``; ``say(text)`` as each
    long step starts (the walk's, which runs the particle filter over the episodes up to ten times)."""
    from posekit.seam.frontend.config import cell_from_config

    prof = replace(work.to_model(), spread_scale=np.ones(6))  # the filter's own spread until it is fitted (below)
    cell = cell_from_config(logs[0].config.cell)
    parts = [_offsets(log, cell) for log in logs]
    dts = [np.r_[0.0, np.diff(log.time_s)] for log in logs]
    dss = [np.r_[0.0, np.linalg.norm(np.diff(p[5][:, :3, 3], axis=0), axis=1)] for p in parts]
    # 1. the jitter per tool axis: the white part of a local-level model of the offset from the modelled motion
    jitter = np.zeros(6)
    for a, name in enumerate(AXES):
        q, qs, r, rs = local_level_fit([p[0][:, a] for p in parts], dss)
        k = 1.0 if a < 3 else math.degrees(1.0)
        pin_r = bool(np.isfinite(rs) and rs <= PINNED * r)
        jitter[a] = r if pin_r else 0.0
        put(f"jitter.{name}", r * k if pin_r else 0.0, rs * k if pin_r else None, True,
            "" if pin_r else "below what the data resolve: 0")
    # 2. each laser's noise and latency from its residual at the true pose
    h = float(np.median(np.concatenate([d[1:] for d in dts])))
    sig, lat = _fit_lasers_truth(logs, cell, parts, share, h, put)
    # 3. the plateau: the largest offset of the truth from the kinematics with the compliance model
    f = np.concatenate([np.linalg.norm(p[3], axis=1) for p in parts])
    et = np.concatenate([np.linalg.norm(p[1], axis=1) for p in parts])
    dr = np.concatenate([p[2] for p in parts])
    fb = np.concatenate([p[3] for p in parts])
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(f[:, None] > 0.0, fb / f[:, None], 0.0)
    par = np.abs(np.einsum("ij,ij->i", dr, u))
    perp = np.linalg.norm(dr - par[:, None] * u * np.sign(np.einsum("ij,ij->i", dr, u))[:, None], axis=1)
    span = float(np.max(f) - np.min(f)) if f.size else 0.0
    fmax = float(np.max(f)) if f.size else 0.0
    wide = fmax > 0.0 and span >= FORCE_SPAN * fmax
    if wide:
        d0, kd = _envelope(f, et)
        d0r, kdr = _rotation_envelope(f, par, perp, None)
        put("plateau.kd_mm_per_n", kd, None, True, "the envelope of the offsets over the force")
        put("plateau.kd_deg_per_n", math.degrees(kdr), None, True, "the envelope of the offsets over the force")
    else:
        kd, kdr = prof.kd_mm_per_n, prof.kd_rad_per_n
        d0 = max(0.0, float(np.max(et - kd * f)))
        d0r, _ = _rotation_envelope(f, par, perp, kdr)
        why = f"the force spans {span:.0f} of {fmax:.0f} N (less than {FORCE_SPAN:.0%}): the base profile's"
        put("plateau.kd_mm_per_n", kd, None, False, why)
        put("plateau.kd_deg_per_n", math.degrees(kdr), None, False, why)
    if len(parts) >= 2:
        # the paper's "largest expected error" of the next episode, not only of these: each episode's largest
        # offset, and the one-sided 99 % prediction bound of a next one (mean + t s sqrt(1 + 1/n)) over the largest
        # seen widens the envelope
        pt = np.array([float(np.max(np.linalg.norm(p[1], axis=1))) for p in parts])
        pr = np.array([float(np.max(np.linalg.norm(p[2], axis=1))) for p in parts])
        n = len(parts)
        t = float(student_t.ppf(0.99, n - 1)) * math.sqrt(1.0 + 1.0 / n)
        d0 += max(0.0, float(pt.mean() + t * pt.std(ddof=1) - pt.max()))
        d0r *= max(1.0, float(pr.mean() + t * pr.std(ddof=1)) / float(pr.max()))
        why = f"the largest offset of the truth from the kinematics, to the 99 % prediction bound of {n} episodes"
    else:
        why = "the largest offset of the truth from the kinematics in the one episode"
    put("plateau.d0_mm", d0, None, True, why)
    put("plateau.d0_deg", math.degrees(d0r), None, True, why)
    put("plateau.max_force_n", fmax, None, True, "the largest force in the data")
    if len(parts) >= 2:
        tail_t, tail_r = max(float(np.std(pt, ddof=1)), 1e-6), max(float(np.std(pr, ddof=1)), 1e-9)
        put("plateau.tail_mm", tail_t, None, True, "the spread of the episodes' largest offsets")
        put("plateau.tail_deg", math.degrees(tail_r), None, True, "the spread of the episodes' largest offsets")
    else:
        tail_t, tail_r = prof.tail_mm, prof.tail_rad
        put("plateau.tail_mm", prof.tail_mm, None, False, "one episode: the base profile's")
        put("plateau.tail_deg", math.degrees(prof.tail_rad), None, False, "one episode: the base profile's")
    # 4. the walk: the one whose linearised filter reports spreads its errors against the truth bear out (the
    # log score of its posterior at the truth, per axis)
    fitted = replace(prof, jitter=jitter, laser_sigma_mm=sig, latency_s=lat, d0_mm=d0, kd_mm_per_n=kd, d0_rad=d0r,
                     kd_rad_per_n=kdr, tail_mm=tail_t, tail_rad=tail_r, max_force_n=fmax)
    return _fit_walk_truth(logs, cell, fitted, parts, put, runs_out, say or (lambda text: None))


_WALK_BOUNDS = (math.log(1e-7), math.log(10.0))
#: The two-sided 95 % point of a standard normal variable.
_Z95 = 1.959964
#: Range of a fitted spread factor.
_SCALE_RANGE = (1.0, 20.0)


def _log_score(eps, Ms, truths, prof):
    """``score(x, only=None)``: per episode ``Σ_k Σ_axis ½ (e² / v + log v)`` of the linearised filter's posterior
    at the truth for the walk ``exp(x)`` (6,) (``e`` the truth in the estimate's tangent frame, ``v`` the
    filter's variance plus the jitter²): a proper scoring rule, least when the reported variance is the error's."""
    S = Ms[0].shape[1]
    sig, lat = prof.sensor_sigma_mm(S), prof.sensor_latency_s(S)
    j2 = prof.jitter ** 2

    def score(x):
        walk = np.exp(x)
        out = np.empty(len(eps))
        for i, (e, M, Tt) in enumerate(zip(eps, Ms, truths)):
            try:
                _, T_est, P = e.run(walk, sig, lat, prof.jitter, M)
            except np.linalg.LinAlgError:
                return np.full(len(eps), np.inf)
            rel = np.matmul(invert_transform(T_est, check=False), Tt)
            err = np.hstack([rel[:, :3, 3], rotation_vector_from_matrix(rel[:, :3, :3], check=False)])
            v = P + j2
            out[i] = float(np.sum(0.5 * (err * err / v + np.log(v))))
        return np.where(np.isfinite(out), out, np.inf)

    return score


def _fit_walk_truth(logs, cell, prof, parts, put, runs_out: list | None = None, say=lambda text: None) -> float:
    """The walk per tool axis whose linearised filter reports spreads its errors against the truth bear out (the
    least log score, :func:`_log_score`); its 1σ from the score's curvature or, where the episodes disagree more,
    the spread of their own slopes (:func:`_curvature_std`). The walks the score allows along an axis are those
    within one unit of log-likelihood of its best; an axis where they are unbounded on one side (the robot plateau
    bounds it: the score is flat there) is not pinned, nor one whose 1σ exceeds its value: the base profile's walk
    is kept and the note says which walks the score allows and how far above its best the kept one is. A pinned
    walk is then scaled by the particle filter's coverage, which runs with the kept ones: its 1σ also takes in the
    range it spans with those e times narrower to wider. ``runs_out`` (a list) receives the particle filter's runs
    with the final walk (every value fitted: the integrity test's calibration reads their innovations,
    :mod:`.tune_nis`)."""
    say(f"the walk: the linearised filter's score at the truth, its best and the walks within one unit of it "
        f"({len(logs)} episode(s) per evaluation)")
    eps = [LinearisedEpisode(cell, prof, episode_arrays(log), _knots(log)) for log in logs]
    lat = prof.sensor_latency_s(cell.n_sensors)
    Ms = [e.mounts(lat) for e in eps]
    score = _log_score(eps, Ms, [p[4] for p in parts], prof)

    seen: dict = {}   # the restart's last probes are the edges' first steps: each point's score once

    def total(x):
        key = np.asarray(x, dtype=np.float64).tobytes()
        if key not in seen:
            seen[key] = float(np.sum(score(x)))
        return seen[key]

    def descend(x0):
        return minimize(total, x0, method="L-BFGS-B", bounds=[_WALK_BOUNDS] * 6,
                        options={"maxiter": 200, "ftol": 1e-10, "eps": 1e-4}).x

    # on a flat stretch the optimiser can stop while a walk e times narrower or wider is better by a unit or more:
    # from there again, until no such step is (at most six times)
    x = descend(np.log(np.clip(prof.walk, 1e-6, 10.0)))
    f0 = total(x)
    for _ in range(6):
        better = None
        for a in range(6):
            for sgn in (-1.0, 1.0):
                xx = x.copy()
                xx[a] = np.clip(xx[a] + sgn, *_WALK_BOUNDS)
                if better is None and total(xx) <= f0 - 1.0:
                    better = xx
        if better is None:
            break
        x = descend(better)
        f0 = total(x)
    # the walks the score allows along each axis (the others at their best): within one unit of its best. Steep: it
    # bounds them on both sides (where it does on one side only, at the edge of a flat stretch, the optimiser's stop
    # on that stretch depends on where it started: not a walk the data pin)
    edges = np.array([[score_edge(total, x, a, side, f0 + 1.0, _WALK_BOUNDS) for side in (-1.0, 1.0)] for a in range(6)])
    steep = (edges[:, 0] > _WALK_BOUNDS[0] + 1e-9) & (edges[:, 1] < _WALK_BOUNDS[1] - 1e-9)
    allowed = np.exp(edges)
    std_log = _curvature_std(score, x, np.full(6, 0.1))
    walk = np.exp(x)
    pinned = steep & np.isfinite(std_log) & (std_log <= PINNED)
    # an axis the score does not pin keeps the base profile's walk, and says where the score stands: the walks it
    # allows and how far above its best the kept one is. Along an axis the robot plateau bounds the score can be flat
    # only about a walk near zero, while the particle filter needs a wider one to keep its particles spread there:
    # taking the score's left held-out episodes covered too little (the notes of issue 26: posekit's own yz seam with
    # the default's rz walk 0.01 -> 0.00016 deg/√mm, rz 2σ coverage 0.725; the independent cell of the tests with the
    # roll's 0.0068 -> 0.0005, ry 0.962 -> 0.876 and confident-wrong 1.36 -> 2.48 %)
    excess = np.zeros(6)
    for a in np.flatnonzero(~pinned):
        xx = x.copy()
        xx[a] = math.log(max(prof.walk[a], math.exp(_WALK_BOUNDS[0])))
        excess[a] = total(xx) - f0
    kept = prof.walk
    undecided = ~pinned
    both = bool(undecided.any() and pinned.any())   # the loop runs again with the undecided walks moved
    passes = 3 + (6 if both else 0) + 1
    say(f"the walk: scaled by the particle filter's coverage on the episodes ({passes} passes of the filter over "
        f"{len(logs)} episode(s))")
    effective = _coverage_loop(logs, prof, pinned, np.where(pinned, walk, kept))
    # that scaling runs the particle filter with the walks the score does not decide at the base profile's: a pinned
    # walk's value depends on them. The loop again with them e times narrower and wider (the range the score was
    # found flat over about its best), and the pinned walk's 1σ takes in the range it then spans (its rms about the
    # value, uniform)
    dep, span = np.zeros(6), None
    if both:
        ends = [_coverage_loop(logs, prof, pinned, np.where(pinned, walk, kept * np.where(undecided, f, 1.0)))
                for f in (1.0 / math.e, math.e)]
        span = (np.minimum.reduce([effective, *ends]), np.maximum.reduce([effective, *ends]))
        dep = np.array([uniform_rms(lo - v, hi - v) for lo, v, hi in zip(span[0], effective, span[1])])
    moved = ", ".join(f"walk.{AXES[a]}" for a in np.flatnonzero(undecided))
    for a, name in enumerate(AXES):
        k = 1.0 if a < 3 else math.degrees(1.0)
        value, sd = effective[a] * k, effective[a] * k * std_log[a]
        if pinned[a]:
            note = ""
            if dep[a] > 0.0:
                note = (f"1σ {sd:.2g} from these errors and {dep[a] * k:.2g} from the walks they do not decide ({moved} "
                        f"e times narrower to wider: {span[0][a] * k:.4g}-{span[1][a] * k:.4g})")
                sd = math.hypot(sd, dep[a] * k)
            put(f"walk.{name}", value, sd, True, note, keep_note=bool(note))
            continue
        lo, hi = (f"{v * k:.4g}" for v in allowed[a])
        lo = "0" if not edges[a, 0] > _WALK_BOUNDS[0] + 1e-9 else lo
        hi = "any wider" if not edges[a, 1] < _WALK_BOUNDS[1] - 1e-9 else hi
        within = f"the linearised filter's score is within one unit of its best from {lo} to {hi}"
        if steep[a]:
            why = f"1σ {walk[a] * k * std_log[a]:.3g} ({within}, {excess[a]:.0f} above it here): the base profile's"
        elif excess[a] <= 1.0:
            why = (f"not decided by these data: {within} (the robot plateau bounds this axis); the base profile's, "
                   "check the profile on held-out episodes")
        else:
            why = (f"the base profile's: {within} and {excess[a]:.0f} above it here; kept, as along an axis the robot "
                   "plateau bounds the particle filter with the score's walk covered held-out episodes too little "
                   "(measured); check the profile on held-out episodes")
        put(f"walk.{name}", value, None, False, why)
    # the reported spread itself, per axis: the least factor (at least 1) with which the particle filter's 2σ covers
    # 90 % of its errors on every one of these episodes (where the walk could not: an axis the lasers barely see, an
    # error that is not a walk; the episodes of one cell differ, and a factor fitted to their pool leaves some of them
    # uncovered). Where every episode needs less than 1 the filter's own spread is kept: its 1σ is then not a fit's,
    # and the report says how much of it the errors used. Except along an axis the robot plateau bounds (the errors
    # do not depend on its walk) where the kinematics alone err by less than the filter's spread: the filter reports
    # the plateau there, a bound on the largest error, and the factor is the larger of the kinematics' rms error
    # and its own over that spread (:func:`_plateau_factor`)
    runs: list = []
    z = _particle_z(logs, replace(prof, walk=effective, spread_scale=np.ones(6)), runs)
    if runs_out is not None:
        runs_out.extend(runs)
    need = np.array([np.percentile(np.abs(e), 90.0, axis=0) / 2.0 for e in z])
    scale = np.clip(need.max(axis=0), *_SCALE_RANGE)
    kin = [_kinematic_z(part, run) for part, run in zip(parts, runs)] if not steep.all() else []
    for a, name in enumerate(("x", "y", "z", "rx", "ry", "rz")):
        if need[:, a].max() < _SCALE_RANGE[0]:
            f, sd, f_kin = _plateau_factor([k[:, a] for k in kin], [e[:, a] for e in z]) if not steep[a] else (
                None, None, math.inf)
            if f_kin < 1.0:
                put(f"spread.{name}", f, sd, True,
                    f"the robot plateau bounds this axis and the kinematics err by {f_kin:.2g} of the filter's spread "
                    "there: the larger of their error's rms and the filter's", keep_note=True)
                continue
            put(f"spread.{name}", float(scale[a]), None, True,
                f"the filter's own spread: these episodes' errors need {min(need[:, a].min(), 0.99):.2g}-"
                f"{min(need[:, a].max(), 0.99):.2g}"
                " of it (a factor below 1 is not fitted)", keep_note=True)
            continue
        sd = float(np.std(need[:, a], ddof=1) / math.sqrt(len(need))) if len(need) >= 2 else None
        pinned = sd is not None and sd <= PINNED * scale[a]
        put(f"spread.{name}", float(scale[a]), sd, pinned,
            "" if pinned else "one episode: the base profile's" if sd is None else
            "the episodes disagree: the base profile's")
    return f0


def _coverage_loop(logs, prof, pinned: np.ndarray, walk: np.ndarray) -> np.ndarray:
    """The walk ``(6,)`` after the particle filter's coverage scaling: run with ``walk`` on the episodes, each
    ``pinned`` axis's walk is scaled by the ratio of its errors against the truth to its reported variance
    (:func:`_coverage_ratio`; a filter's reported variance grows about linearly with its walk), three times; the
    other axes keep ``walk``'s."""
    effective = np.array(walk, dtype=np.float64)
    for _ in range(3):
        ratio = _coverage_ratio(_particle_z(logs, replace(prof, walk=effective)))
        effective = np.where(pinned, effective * np.clip(ratio, 0.1, 100.0), effective)
    return effective


def _kinematic_z(part, run) -> np.ndarray:
    """``(T, 6)``: the error of the kinematic pose ``Fk(q + Cj(τ))`` against the truth in the seam frame (an
    estimate that learnt nothing from the lasers) over the particle filter's reported spread ``run.spread``."""
    from posekit.seam.frontend.seam_frame import seam_frame_errors

    return seam_frame_errors(part[6], part[4], run.nominal) / run.spread


def _plateau_factor(z_kin: list, z_pf: list) -> tuple[float, float | None, float]:
    """The spread factor of an axis the robot plateau bounds, its 1σ, and the kinematics' own factor.

    Parameters
    ----------
    z_kin, z_pf : list of ndarray, shape (T,)
        Per episode, the kinematic pose's error (:func:`_kinematic_z`) and the particle filter's over the filter's
        reported spread on the axis.

    Returns
    -------
    factor, std, kinematic : float, float or None, float
        ``min(1, max(rms(z_kin), rms(z_pf)))`` over every step (the spread of a filter that knows what the
        kinematics know, or the filter's own where its errors are larger); its 1σ from the spread of the episodes' own
        (log scale, over √n; None for one episode); ``rms(z_kin)``.
    """
    def rms(z):
        return float(np.sqrt(np.mean(np.square(np.concatenate(z)))))

    f_kin = rms(z_kin)
    f = min(1.0, max(f_kin, rms(z_pf)))
    if len(z_kin) < 2:
        return f, None, f_kin
    own = np.log([max(rms([k]), rms([p])) for k, p in zip(z_kin, z_pf)])
    return f, f * float(np.std(own, ddof=1)) / math.sqrt(len(z_kin)), f_kin


def _coverage_ratio(z: list) -> np.ndarray:
    """``(6,)``: per axis ``(q / 1.96)²`` with ``q`` the 95th percentile of ``|e| / s`` over every step of the
    episodes ``z`` (list of (T, 6) arrays of :func:`_particle_z`): 1 when 95 % of the errors lie within twice the
    reported spread, the coverage a user reads."""
    return (np.percentile(np.abs(np.concatenate(z)), 95.0, axis=0) / _Z95) ** 2


def _particle_z(logs, profile, runs_out: list | None = None) -> list:
    """Per episode ``e / s`` (T, 6): ``e`` the particle filter's error against the truth in the seam frame, ``s``
    its reported spread, run with ``profile`` (each episode's own filter settings and seed); the runs are appended
    to ``runs_out`` when given."""
    from posekit.seam.frontend.seam_frame import seam_frame_errors

    z2 = []
    for log in logs:
        run = run_filter(log, profile)
        if runs_out is not None:
            runs_out.append(run)
        err = seam_frame_errors(run.estimate, np.matmul(run.nominal, log.truth_seam_tool), run.nominal)
        z2.append(err / run.spread)
    return z2


def _fit_lasers_truth(logs, cell, parts, share: bool, h: float, put) -> tuple[np.ndarray, np.ndarray]:
    """Each sensor's latency (least squares of its residual at the true pose) and noise (the residual's rms)."""
    from posekit.seam.engine.seamline import SeamLine

    S = cell.n_sensors
    groups = [list(range(S))] if share else [[i] for i in range(S)]
    sig_out, lat_out = np.zeros(S), np.zeros(S)
    knots = [SeamLine(_knots(log)).points for log in logs]
    arrays = [episode_arrays(log) for log in logs]

    def residuals(sensors, L):
        out = []
        for log, part, arr, pts in zip(logs, parts, arrays, knots):
            truth, Tn = part[4], part[5]
            lat = np.zeros(S)
            lat[sensors] = L
            Ms = reading_mounts(cell.chain, cell.mounts, arr.time_s, arr.q_ref, lat, arr.reading_lag_s, Tn)
            for i in sensors:
                m = log.laser_mm[:, i]
                ok = np.isfinite(m[:, 0]) & np.isfinite(m[:, 1])
                for k in np.flatnonzero(ok):
                    E = np.empty((1, 2))
                    _k.laser_error_kernel(truth[k:k + 1], float(m[k, 0]), float(m[k, 1]), Ms[k, i], pts, 0,
                                          pts.shape[0] - 1, E)
                    out.append(E[0])
        return np.array(out).reshape(-1, 2)

    for g, sensors in enumerate(groups):
        stamped = all(log.reading_time_s is not None for log in logs)
        if stamped:
            r = residuals(sensors, 0.0)
            L, Ls = 0.0, None
            put(_sensor_key(g, "latency_s"), 0.0, None, False, "given by the log's m{k}_t_s stamps")
        else:
            def sse(L):
                r = residuals(sensors, L)
                r = r[np.isfinite(r).all(axis=1)]
                return float(np.sum(r * r)) if r.size else math.inf

            grid = np.arange(0.0, 0.0501, 0.0025)
            i = int(np.argmin([sse(L) for L in grid]))
            lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
            L = float(minimize_scalar(sse, bounds=(lo, hi), method="bounded", options={"xatol": 1e-6}).x)
            r = residuals(sensors, L)
            r = r[np.isfinite(r).all(axis=1)]
            s2 = float(np.mean(r * r))
            dL = 5e-4
            curv = (sse(L + dL) - 2.0 * sse(L) + sse(max(L - dL, 0.0))) / dL ** 2
            Ls = math.sqrt(2.0 * s2 / curv) if curv > 0.0 else math.inf
            pinned = np.isfinite(Ls) and Ls <= PINNED * h
            put(_sensor_key(g, "latency_s"), L, Ls, pinned,
                "" if pinned else f"not pinned: 1σ {Ls * 1e3:.3g} ms")
        r = r[np.isfinite(r).all(axis=1)]
        if r.shape[0] < 10:
            raise EstimationError(f"seam tune: sensor {sensors[0] + 1} has {r.shape[0]} readings; expected at least 10")
        sigma = float(np.sqrt(np.mean(r * r)))
        put(_sensor_key(g, "sigma_mm"), sigma, sigma / math.sqrt(2.0 * r.size), True)
        put(_sensor_key(g, "angle_sigma_deg"), 0.0, None, False, "not fitted: the base profile's")
        for i in sensors:
            sig_out[i], lat_out[i] = sigma, L
    if not groups:
        raise EstimationError("seam tune: no laser sensor to fit")
    return sig_out, lat_out

"""``posekit seam tune``: fit a cell's profile from recorded episodes (:mod:`posekit.seam.frontend.profile`).

Two ways, the same model as the particle filter's (:mod:`posekit.seam.engine.ekf`):

**From the laser innovations** (default; no reference needed). The particle filter's state-space model run as a
linearised filter gives the lasers' likelihood by its prediction-error decomposition; the walk per tool axis, the
laser noise and the latency per sensor maximise it (a coarse scan of the latency, then Nelder-Mead on the log of
the scales and the latencies). The walk's and noise's 1σ come from the full Hessian over every fitted parameter
(and the episodes' own gradients); each latency's from its 95 % profile-likelihood interval, under the walk as
fitted and ten times larger, since a robot error that wanders sideways with the seam looks like a latency
(:mod:`.tune_intervals`). A latency whose interval touches 0, is wider than ±5 ms or moves with the walk is not
pinned: the base profile's value is kept and that sensor's noise widened by the reading error a latency anywhere
in the interval would make (the interval's rms about the kept value times the readings' rms rate), and the
``spread`` factors are widened to the pose shift the interval's far end would make (:mod:`.tune_latency`: the
particle filter run both ways on the same episodes). The joint noise
comes from the encoders (the white part of ``q - q̄``: its second difference has variance ``6 σ²``). The plateau, its tails and
the pose jitter are about the robot's absolute error, which the lasers do not see on every axis: they are kept
from the base profile (unless the filter's estimates leave that plateau: then it is widened to them and said so).

**From the errors** (``with_truth``; ``truth.csv``, e.g. a laser tracker). The offset of the true pose from the
modelled motion, ``δ_k = log((D_k Fk(q̄_k))⁻¹ T_true,k)`` per tool axis, is a random walk plus white jitter under the
filter's model: a local-level Kalman filter per axis gives both by maximum likelihood. Each laser's noise and
latency come from its residual at the true pose (the latency minimises the residual, its 1σ from the curvature).
The plateau is the paper's "largest expected error": the tightest ``d0 + kd ‖f‖`` above every offset of the truth
from ``Fk(q + Cj(τ))`` (the rotation plateau the bending ellipsoid), widened to the one-sided 99 % prediction bound
of the next episode's largest offset; the tails are the spread of the episodes' largest offsets, ``max_force_n``
the largest force seen. The walk per axis minimises the linearised filter's log score at the truth, then is scaled
until the particle filter itself covers 95 % of its errors within 2σ on those episodes (that filter runs with the
walks the score does not decide at the base profile's, so a scaled walk's 1σ also takes in the range it spans with
those e times narrower to wider); last, the ``spread``
factor per axis (at least 1) makes its 2σ cover 90 % of the errors of every one of the episodes (the implementation
in :mod:`.tune_truth`).

Both ways end with the integrity test's calibration (:mod:`.tune_nis`): the particle filter, run with the fitted
profile on the same episodes, measures the mean and the effective degrees of freedom of each reading component's
normalised squared innovation (``sensors[k].nis_mean_x/z``, ``nis_dof_x/z``), which the long integrity window
tests against.

A value the data do not pin (its 1σ above the value itself; for a latency above the sample period (with truth) or
as above (without); with truth, a walk whose score is flat on one side, the robot plateau bounding it; kd when the
force spans less than 20 % of its largest value; one episode for the tails) keeps the base profile's value, and the
result says why. :func:`tune_profile` returns a :class:`TuneResult`; :func:`tune_report`
formats it.
"""


import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from posekit.errors import ConfigError
from posekit.geometry import rotation_vector_from_matrix
from posekit.seam.engine.ekf import LinearisedEpisode
from posekit.seam.frontend.cell_signature import fitted_cell
from posekit.seam.frontend.profile import (
    AXES,
    ProfileModel,
    episode_record,
    profile_data,
    profile_from_dict,
    resolve_profile,
)
from posekit.seam.frontend.tune_filter import run_filter
from posekit.seam.frontend.tune_fit import (
    _LAT_GRID_S,
    PINNED,
    _check_same_cell,
    _joint_sigma,
    _knots,
    _sensor_key,
    episode_arrays,
    local_level_fit,
)
from posekit.seam.frontend.tune_intervals import (
    LATENCY_HALF_WIDTH_S,
    joint_std,
    latency_interval,
    reading_rate_rms,
    uniform_rms,
)
from posekit.seam.frontend.tune_latency import latency_spread
from posekit.seam.frontend.tune_nis import fit_nis
from posekit.seam.frontend.tune_offset import fit_offset
from posekit.seam.frontend.tune_truth import fit_truth

__all__ = ["TuneResult", "TunedValue", "episode_arrays", "local_level_fit", "simulate_episodes", "tune_profile",
           "tune_report", "tune_simulated"]


@dataclass
class TunedValue:
    """One profile value as the tuner leaves it.

    Attributes
    ----------
    key : str
        Dotted profile key (``walk.z_mm``, ``sensors[0].latency_s``, ``plateau.d0_mm``).
    value, std : float
        In the key's unit; ``std`` None when kept from the base or not computable.
    pinned : bool
        Whether the data pin it (fitted) or the base profile's value was kept.
    note : str
        Why it was kept, or how it was fitted.
    interval : tuple of float, optional
        The 95 % interval (``seam tune`` without a reference, latencies: profile likelihood, the fitted value's
        even when it is not pinned).
    """

    key: str
    value: float
    std: float | None
    pinned: bool
    note: str = ""
    interval: tuple | None = None


@dataclass
class TuneResult:
    """:func:`tune_profile`'s result: the profile and every value with its uncertainty and verdict."""

    profile: ProfileModel
    values: list = field(default_factory=list)
    method: str = "innovations"
    episodes: int = 0
    steps: int = 0
    nll: float | None = None

    @property
    def unpinned(self) -> list:
        """The values the data did not pin (kept from the base profile)."""
        return [v for v in self.values if not v.pinned]


# ----------------------------------------------------------------------------------------------- data


def tune_profile(logdirs, *, with_truth: bool = False, base=None, share_sensors: bool = False,
                 command: str = "", stage=None) -> TuneResult:
    """Fit a profile from recorded episodes of one cell (see the module docstring).

    Parameters
    ----------
    logdirs : sequence of path-like
        Recorded episode folders (``setup.yaml``, ``seam.csv``, ``log.csv``, and ``truth.csv`` with
        ``with_truth``).
    with_truth : bool
        Fit from the errors against ``truth.csv`` instead of the laser innovations.
    base : ProfileModel or path, optional
        The profile whose values are kept where the data do not pin them (default: the first setup's profile,
        else the shipped default).
    share_sensors : bool
        One laser noise and one latency for every sensor (written as one sensor entry).
    command : str
        The command line, recorded in the profile.
    stage : callable, optional
        ``stage(text)`` is called as each step of the fit starts (what it is doing, for a long fit's progress).

    Returns
    -------
    TuneResult

    Raises
    ------
    ConfigError, InputFileError
        No episode, episodes of different cells, an unreadable episode; ``with_truth`` without ``truth.csv``.
    """
    from posekit.seam.frontend.logs import read_episode_log

    dirs = [Path(d) for d in logdirs]
    if not dirs:
        raise ConfigError("seam tune: expected at least one recorded episode folder, got none")
    say = stage if stage is not None else (lambda text: None)
    logs = [read_episode_log(d) for d in dirs]
    _check_same_cell(logs)
    if with_truth:
        for log in logs:
            if log.truth_seam_tool is None:
                raise ConfigError(f"{log.folder}: no truth.csv; expected one per episode with --with-truth")
    base_model = resolve_profile(base, None, "--from") if base is not None else logs[0].config.profile
    S = logs[0].config.cell.sensors.count
    if not share_sensors and len(base_model.sensors) not in (1, S):
        raise ConfigError(f"base profile: {len(base_model.sensors)} sensor entries for {S} sensors")
    if not with_truth and S == 0:
        raise ConfigError("seam tune: the episodes have no laser sensor; expected at least one to fit from")
    values: list[TunedValue] = []
    data = profile_data(base_model)
    data.pop("fitted", None)
    data.pop("notes", None)
    nS = 1 if share_sensors else S
    base_sensors = [dict(data["sensors"][min(i, len(data["sensors"]) - 1)]) for i in range(max(nS, 1))]
    data["sensors"] = base_sensors

    def put(key: str, value: float, std, pinned: bool, note: str = "", interval=None, keep_note: bool = False):
        std = None if std is None or not np.isfinite(std) else float(std)
        node, parts = data, key.replace("]", "").replace("[", ".").split(".")
        for p in parts[:-1]:
            node = node[int(p)] if p.isdigit() else node[p]
        if pinned:
            entry = {"value": float(value)}
            if std is not None:
                entry["std"] = std
            if keep_note and note:   # set by a rule rather than fitted: the profile says which
                entry["note"] = note[:300]
            node[parts[-1]] = entry
        else:  # the base profile's value is kept (and reported)
            old = node[parts[-1]]
            value = old["value"] if isinstance(old, dict) else old
            node[parts[-1]] = {"value": float(value), "note": note[:300]} if note else value
        values.append(TunedValue(key, float(value), std, pinned, note, interval))

    sj, sj_std = _joint_sigma(logs)
    if np.isfinite(sj) and sj > 0.0:
        put("joints.sigma_deg", math.degrees(sj), math.degrees(sj_std), True)
    else:
        put("joints.sigma_deg", 0.0, None, False, "no joint samples to estimate it from")
    # the spread factors are fitted against a reference only; without one the filter's own spread is reported
    data["spread"] = {a: 1.0 for a in ("x", "y", "z", "rx", "ry", "rz")}
    work = profile_from_dict({**data, "format": "posekit-seam-profile", "version": 1}, "profile")
    # the input is checked (a bad one is a one-line error before anything is said): the fit starts
    say(f"{len(logs)} episode(s), {sum(len(log.time_s) for log in logs)} samples")
    runs: list = []   # the particle filter with every value fitted (the truth fit's last pass; its innovations)
    if with_truth:
        say("fitting from the errors against truth.csv: lasers, plateau, walk, then the particle filter's spread")
        nll = fit_truth(logs, work, share_sensors, put, runs, say)
    else:
        say("fitting the walk, laser noise and latencies from the laser innovations (each latency's 95 % interval "
            "by profile likelihood)")
        nll = _fit_innovations(logs, work, share_sensors, put)
    data["format"], data["version"] = "posekit-seam-profile", 1
    if not with_truth:
        latency_spread(logs, profile_from_dict(data, "tuned profile"), values, put, say)
    # last, the integrity test's calibration: the innovations of the filter run with everything fitted above
    say("calibrating the integrity test: the lasers' innovations " + ("of the spread fit's particle filter" if runs else
        "of the particle filter over the episodes with the fitted profile"))
    fitted = profile_from_dict(data, "tuned profile").to_model()
    if not runs:
        runs = [run_filter(log, fitted) for log in logs]
    data["bias_window"] = fit_nis(logs, fitted, share_sensors, put, runs)
    # and the offset test's: where the same runs' estimates sat from the kinematic pose
    fit_offset(logs, runs, data, put, say)
    notes = [f"{v.key}: {v.note}" for v in values if not v.pinned and v.note]
    data["fitted"] = {"method": "truth" if with_truth else "innovations", "command": command[:2000],
                      "episodes": [episode_record(log.folder) for log in logs]}
    cell = fitted_cell(logs)
    if cell is not None:
        data["fitted"]["cell"] = cell.model_dump()
    else:
        notes.append("fitted.cell: the episodes come from more than one cell; seam track checks none")
    data["notes"] = notes[:100]
    model = profile_from_dict(data, "tuned profile")
    return TuneResult(model, values, "truth" if with_truth else "innovations", len(logs),
                      int(sum(len(log.time_s) for log in logs)), nll)


def _fit_innovations(logs, work: ProfileModel, share: bool, put) -> float:
    """Walk, laser noise and latency by the linearised filter's likelihood (see the module docstring)."""
    from posekit.seam.frontend.config import cell_from_config

    prof = work.to_model()
    cell = cell_from_config(logs[0].config.cell)
    S = cell.n_sensors          # at least one: tune_profile checked
    eps = [LinearisedEpisode(cell, prof, episode_arrays(log), _knots(log)) for log in logs]
    nS = 1 if share else S
    stamped = np.zeros(S, bool)
    for log in logs:
        if log.reading_time_s is not None:
            stamped |= np.all(np.isfinite(log.reading_time_s) | ~np.isfinite(log.laser_mm[..., 0]), axis=0)
    declared = np.array([s.latency_s is not None for s in cell.sensors])
    fit_lat = ~(stamped | declared)
    if share:
        fit_lat = np.array([fit_lat.all()])
    jitter = prof.jitter
    walk0 = np.maximum(prof.walk, 1e-6)
    sig0 = np.maximum(prof.sensor_sigma_mm(nS), 1e-4)
    lat0 = np.where(declared, [s.latency_s or 0.0 for s in cell.sensors], prof.sensor_latency_s(S))
    lat0 = lat0[:1] if share else lat0

    def expand(v):
        return np.full(S, float(v[0])) if share else np.asarray(v, dtype=np.float64)

    cache: dict = {}

    def total(walk, sig, lat, only=None):
        key = tuple(np.round(expand(lat), 9))
        if key not in cache:
            cache.clear()
            cache[key] = [e.mounts(expand(lat)) for e in eps]
        Ms = cache[key]
        out = 0.0
        for j, (e, M) in enumerate(zip(eps, Ms)):
            if only is not None and j != only:
                continue
            try:
                out += e.nll(walk, expand(sig), expand(lat), jitter, M)
            except np.linalg.LinAlgError:
                return np.inf
        return out

    nl = int(fit_lat.sum())

    def unpack(x):
        walk = np.exp(x[:6])
        sig = np.exp(x[6:6 + nS])
        lat = lat0.copy()
        lat[fit_lat] = x[6 + nS:6 + nS + nl]
        return walk, sig, lat

    bounds = [(math.log(1e-7), math.log(10.0))] * 6 + [(math.log(1e-5), math.log(10.0))] * nS + [(0.0, 0.2)] * nl
    lo_b, hi_b = np.array(bounds).T

    def f(x, only=None):
        if np.any(x < lo_b) or np.any(x > hi_b):
            return np.inf
        return total(*unpack(x), only=only)

    # 1. the latency scanned with the base walk and noise (the likelihood is not convex in it)
    lat_start = lat0.copy()
    if nl:
        scores = [total(walk0, sig0, np.where(fit_lat, L, lat0)) for L in _LAT_GRID_S]
        lat_start = np.where(fit_lat, _LAT_GRID_S[int(np.argmin(scores))], lat0)
    x0 = np.r_[np.log(walk0), np.log(sig0), lat_start[fit_lat]]
    # 2. all together (Nelder-Mead: the likelihood of a linearised filter has small steps where a reading's
    # knot window changes, which finite-difference gradients trip on)
    res = minimize(f, x0, method="Nelder-Mead",
                   options={"maxfev": 40 * x0.size, "xatol": 1e-3, "fatol": 1e-2, "adaptive": True})
    x = res.x
    # 3. 1σ of the walk and noise from the full Hessian (and the episodes' own gradients); each latency's interval
    # from its profile likelihood under the walk as fitted and ten times larger (:mod:`.tune_intervals`)
    steps = np.r_[np.full(6 + nS, 0.1), np.full(nl, 1e-3)]
    free = [k for k in range(x.size) if x[k] - steps[k] >= lo_b[k] and x[k] + steps[k] <= hi_b[k]]
    std = joint_std(lambda xx: np.array([f(xx, only=j) for j in range(len(eps))]), x, steps, free)
    walk, sig, lat = unpack(x)
    at_bound = [abs(x[i] - lo) < 1e-3 or abs(x[i] - hi) < 1e-3 for i, (lo, hi) in enumerate(bounds)]
    for a, name in enumerate(AXES):
        value = walk[a] if a < 3 else math.degrees(walk[a])
        s = value * std[a]
        pinned = np.isfinite(s) and s <= PINNED * value and not at_bound[a]
        put(f"walk.{name}", value, s, pinned,
            "" if pinned else "the lasers do not pin it (flat likelihood along this axis): the base profile's")
    lat_idx = list(range(6 + nS, 6 + nS + nl))
    names = [i for i in range(nS) if fit_lat[i]]
    intervals = {i: latency_interval(f, x, lat_idx[names.index(i)], lat_idx, range(6)) for i in names}
    # a latency that moves with another, unpinned one is only as pinned as the values it takes along that one's
    # interval (the shadow of their joint region)
    for _ in range(len(names)):
        changed = False
        for i in names:
            for k in names:
                band = intervals[k].others.get(lat_idx[names.index(i)])
                if k != i and not intervals[k].pinned and band is not None:
                    changed |= intervals[i].carry(*band, f"along sensors[{k}]'s unpinned latency it is "
                                                         f"{band[0] * 1e3:.1f}-{band[1] * 1e3:.1f} ms")
        if not changed:
            break
    kept = prof.sensor_latency_s(S)[:nS]
    for i in range(nS):
        s = sig[i] * std[6 + i]
        pinned = np.isfinite(s) and s <= PINNED * sig[i]
        iv = intervals.get(i)
        if pinned and iv is not None and not iv.pinned:
            # the kept latency may be off by anything in its interval: a reading then moves by (L - kept) ṁ
            rms = uniform_rms(iv.lo - kept[i], iv.hi - kept[i]) * reading_rate_rms(eps, None if share else i)
            put(_sensor_key(i, "sigma_mm"), math.hypot(sig[i], rms), s, True,
                f"{sig[i]:.4g} mm fitted, widened by {rms:.3g} mm: the latency is not pinned (rms of its interval "
                f"about the kept value times the reading's rms rate)")
            continue
        put(_sensor_key(i, "sigma_mm"), sig[i], s, pinned, "" if pinned else "not pinned by the data")
    for i in range(nS):
        if not fit_lat[i]:
            why = "given by the log's m{k}_t_s stamps" if (stamped[i] if not share else stamped.all()) else \
                "declared in setup.yaml (it applies)"
            put(_sensor_key(i, "latency_s"), float(lat[i]), None, False, why)
            continue
        iv = intervals[i]
        note = ""
        if not iv.pinned:
            moved = [f"sensors[{names[lat_idx.index(k)]}]'s {a * 1e3:.1f}-{b * 1e3:.1f} ms"
                     for k, (a, b) in iv.others.items() if b - a > LATENCY_HALF_WIDTH_S]
            note = (f"95 % interval {iv.lo * 1e3:.1f}-{iv.hi * 1e3:.1f} ms (profile likelihood; best {lat[i] * 1e3:.1f}"
                    f" ms): {iv.reason}" + (f"; it moves with {', '.join(moved)}" if moved else "")
                    + "; declare it in setup.yaml or fit with --with-truth")
        put(_sensor_key(i, "latency_s"), float(lat[i]), iv.std if iv.pinned else None, iv.pinned, note,
            interval=(iv.lo, iv.hi))
    # the plateau stays the base's unless the linearised filter's poses leave it
    _check_plateau(eps, walk, expand(sig), expand(lat), jitter, prof, put)
    for name in AXES:
        put(f"jitter.{name}", 0.0, None, False, "the lasers cannot tell it from their noise: the base profile's")
    return float(res.fun)


def _check_plateau(eps, walk, sig, lat, jitter, prof, put) -> None:
    peak_t = peak_r = 0.0
    for e in eps:
        _, T_est, _ = e.run(walk, sig, lat, jitter)
        off = np.linalg.norm(T_est[:, :3, 3] - e.K[:, :3, 3], axis=1) - e.d_t
        peak_t = max(peak_t, float(np.max(off)))
        dr = rotation_vector_from_matrix(T_est[:, :3, :3] @ np.swapaxes(e.K[:, :3, :3], 1, 2), check=False)
        peak_r = max(peak_r, float(np.max(np.linalg.norm(dr, axis=1) - e.d_r)))
    for key, over, unit, base in (("plateau.d0_mm", peak_t, 1.0, prof.d0_mm),
                                  ("plateau.d0_deg", peak_r, math.degrees(1.0), math.degrees(prof.d0_rad))):
        if over > 0.0:
            put(key, base + over * unit, None, True,
                f"the filter's poses leave the base plateau by {over * unit:.3g}: widened to them")
        else:
            put(key, base, None, False, "the lasers do not see every axis of the robot's error: the base "
                                        "profile's (fit with --with-truth to measure it)")
    for key in ("plateau.kd_mm_per_n", "plateau.kd_deg_per_n", "plateau.tail_mm", "plateau.tail_deg",
                "plateau.max_force_n"):
        put(key, 0.0, None, False, "the base profile's (fit with --with-truth to measure it)")


def tune_report(result: TuneResult) -> str:
    """The fitted values, one line each: key, value ± 1σ, and the verdict of those the data did not pin."""
    lines = [f"seam tune: {result.episodes} episode(s), {result.steps} samples, from "
             f"{'the errors against truth.csv' if result.method == 'truth' else 'the laser innovations'}"]
    for v in result.values:
        if v.key.endswith("latency_s"):
            val = f"{v.value * 1e3:.2f} ms" + (f" ± {v.std * 1e3:.2f}" if v.std is not None else "")
        else:
            val = f"{v.value:.4g}" + (f" ± {v.std:.2g}" if v.std is not None else "")
        tag = ("   [" + v.note + "]" if v.note else "") if v.pinned else "   [not pinned: " + v.note + "]"
        lines.append(f"  {v.key:<28}{val:<24}{tag}")
    return "\n".join(lines)


def tune_simulated(config, runs: int, kinds=None, seed: int | None = None, **kw) -> TuneResult:
    """:func:`tune_profile` on ``runs`` episodes of each trajectory kind simulated now (``posekit seam tune
    --simulate``: how the shipped default profile is made).

    Parameters
    ----------
    config : path or None
        The configuration of the simulated cell (None: the defaults).
    runs : int
        Episodes per kind.
    kinds : list of str, optional
        Trajectory kinds (default the configuration's).
    seed : int, optional
        Seed of the episodes (:func:`simulate_episodes`; default the configuration's ``seed``).
    **kw
        Passed to :func:`tune_profile`.
    """
    import tempfile

    from posekit.seam.frontend.config import TRAJECTORY_KINDS, apply_overrides, config_from_dict, load_config

    cfg = load_config(config) if config else config_from_dict({}, "defaults")
    kinds = [cfg.trajectory.kind] if kinds is None else list(kinds)
    seed = cfg.seed if seed is None else int(seed)
    for k in kinds:
        if k not in TRAJECTORY_KINDS:
            raise ConfigError(f"--trajectory: expected kinds among {', '.join(TRAJECTORY_KINDS)}, got '{k}'")
    if kw.get("stage") is not None:
        kw["stage"](f"simulating {runs} episode(s) of each of {', '.join(kinds)}")
    with tempfile.TemporaryDirectory(prefix="posekit-tune-") as tmp:
        dirs = []
        for k in kinds:
            dirs += simulate_episodes(apply_overrides(cfg, {"trajectory.kind": k}), runs, seed, Path(tmp) / k)
        return tune_profile(dirs, **kw)


def simulate_episodes(cfg, runs: int, seed: int, folder) -> list:
    """Simulate ``runs`` episodes of ``cfg`` (seeds of :func:`~posekit.seam.frontend.compare.episode_seeds`) and
    write each as a recorded episode with its ``truth.csv`` into ``folder/KIND-NNN``; returns the folders (the
    data ``posekit seam tune --simulate`` fits on)."""
    from posekit.seam.frontend.compare import episode_seeds
    from posekit.seam.frontend.logs import write_episode_log
    from posekit.seam.frontend.simulate import simulate_data

    folder = Path(folder)
    out = []
    for r, s in enumerate(episode_seeds(int(seed), int(runs))):
        d = folder / f"{cfg.trajectory.kind}-{r:03d}"
        d.mkdir(parents=True, exist_ok=True)
        out.append(write_episode_log(d, cfg, simulate_data(cfg, s), s))
    return out

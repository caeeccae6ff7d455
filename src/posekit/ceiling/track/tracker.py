"""Motion filter for the laser dots on the ceiling (the filter of the paper's future work).

One constant-velocity Kalman filter per dot colour in the world (ceiling) plane, mm:
state ``[x, y, vx, vy]``, continuous white-noise acceleration of spectral density
``accel_psd_mm2_s3`` (a ground robot: smooth motion, turns of a few hundred mm/s²), a
measurement covariance per detection (from the calibration's reprojection rms pushed
through the local Jacobian of the image-to-world homography, scaled up when the
measurements jitter more than that), and a Mahalanobis gate (χ², 2 dof) that rejects
outliers such as reflections. A detection that fails the gate but lies within
``gate_floor_mm`` of the prediction is a manoeuvre (the robot stopped, started or turned
abruptly), not an outlier: the covariance is inflated and the filter follows it at once.

Never ``ok`` on anything but the laser dot (DESIGN.md "Trust"): the gate never reaches
farther than the robot can move since its last accepted position (``max_speed_mm_s``),
however long the prediction ran; candidates carry the detector's verification
(``eligible``: not a learned static light, a laser-like signature) and only verified ones
start, resume or re-acquire a track; a track that coasted must see its dot moving as
predicted (or still where it was last seen) before it is ``ok`` again; a lost track (or one
whose candidates were all rejected ``reinit_after`` times) restarts only on a lone verified
candidate that has been seen moving — never on the nearest of several blobs, never on a
static one. A lone verified candidate within reach right after a sharp turn is taken in the
same frame.

Status of a frame, for the primary dot (red; its x, y are the track):

``ok``
    a dot was measured **and accepted** this frame; x, y is the filtered estimate.
``suspect``
    a dot was accepted, but another verified, moving laser-like spot is in view outside the
    gate: which of the two is the laser cannot be told (``reasons`` says where the other is).
``predicted``
    no accepted dot this frame (the dot fell into an air-conditioning hole, was occluded
    or gated out) and the last accepted one is at most ``max_predict_s`` old; x, y is the
    constant-velocity prediction, and its ``std_mm`` grows with the time coasted as the
    motion model predicts (``q t³ / 3`` per axis), with the process noise ``q`` the larger of
    the configured one and the one fitted from the track's own measurements
    (:func:`~posekit.ceiling.track.motion_noise.fitted_accel_psd`: a robot that has stopped and turned in view may do it unseen).
``lost``
    no accepted dot for longer than ``max_predict_s`` (or never): x, y are NaN
    (empty in the CSV). A lone verified detection seen moving re-initialises the filter.

A row is never ``ok`` without a dot; every row carries ``reasons``: why it is not ``ok``.
Heading (case B of the paper): the direction from the red to the green dot with its 1σ
(:mod:`~posekit.ceiling.track.heading`), never more than 3σ from what a frame's two measured
dots say; NaN with one dot, or when either dot has not been seen for ``max_predict_s``.
:class:`Tracker` works on world measurements (no video needed); the cameras' side is
:class:`~posekit.ceiling.track.cameras.MultiCameraTracker`.
"""

from collections.abc import Mapping

import numpy as np

from ...errors import GeometryError, TrajectoryError
from . import verdicts
from ._inputs import _as_candidates, _as_covariances, _as_eligible
from ._kalman import _inv_sym, _mahalanobis2, _wrap, cv_predict, kf_update  # noqa: F401 (re-exported)
from .heading import second_dot_at_separation, update_heading
from .motion_noise import extra_psd, record_measurement
from .types import CHI2_2DOF_999, STATUSES, DotState, HeadingState, TrackerConfig, TrackRow  # noqa: F401

__all__ = ["STATUSES", "TrackerConfig", "TrackRow", "DotState", "HeadingState", "Tracker", "cv_predict", "kf_update"]


# --- the world-plane tracker ---------------------------------------------------------------

class Tracker:
    """Constant-velocity Kalman tracking of the laser dot(s) in the world plane.

    Parameters
    ----------
    config : TrackerConfig, optional
        Tuning; ``config.dots`` names the tracked colours, the first is the track.

    Examples
    --------
    >>> tr = Tracker(TrackerConfig(dots=("red",)))
    >>> tr.step(0.0, {"red": [100.0, 200.0]}).status     # seen once: not yet the laser
    'lost'
    >>> tr.step(1 / 15, {"red": [120.0, 200.0]}).status  # moving: a laser on a robot
    'ok'
    >>> tr.step(0.1, {}).status                          # dropout: constant-velocity prediction
    'predicted'
    >>> tr.step(1.2, None).status                        # longer than max_predict_s
    'lost'
    """

    def __init__(self, config: TrackerConfig | None = None):
        self.config = TrackerConfig() if config is None else config
        self.reset()

    def reset(self) -> None:
        """Forget every dot and the heading (the next detection re-initialises)."""
        self.states = {c: DotState() for c in self.config.dots}
        self.heading = HeadingState()
        self._sep = (0, 0.0, 0.0)           # separation of the two dots: count, mean, sum of squares (Welford)
        self.frame = 0
        self.t_s = float("nan")
        self._pred_cache = None

    # -- queries ---------------------------------------------------------------------------
    def _alive(self, st: DotState, t_s: float) -> bool:
        return st.x is not None and t_s - st.t_meas_s <= self.config.max_predict_s + 1e-9

    def predict(self, t_s: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Predicted position of each live dot at ``t_s`` without changing the state.

        Returns
        -------
        dict
            ``{colour: (xy, cov)}`` with ``xy`` shape (2,) in mm and ``cov`` shape (2, 2)
            in mm², for every dot that is not lost at ``t_s`` (used to place the
            detector's region of interest and to choose a camera).
        """
        if self._pred_cache is not None and self._pred_cache[0] == t_s:
            return dict(self._pred_cache[1])
        out = {}
        for c, st in self.states.items():
            if self._alive(st, t_s):
                x, P = cv_predict(st.x, st.P, max(t_s - st.t_s, 0.0), self.config.accel_psd_mm2_s3)
                out[c] = (x[:2], P[:2, :2])
        self._pred_cache = (t_s, out)
        return dict(out)

    def pending(self) -> dict[str, np.ndarray]:
        """``{colour: xy (2,) mm}`` of a candidate the tracker is watching to resume a coasting
        dot (seen once, waiting to be confirmed); it is not a stray light."""
        return {c: st.pending[1].copy() for c, st in self.states.items() if st.pending is not None}

    # -- one frame -------------------------------------------------------------------------
    def step(self, t_s: float, dots_world: Mapping | np.ndarray | None,
             meas_cov: Mapping | None = None, *, frame: int | None = None,
             camera: int = -1, eligible: Mapping | None = None, moving: Mapping | None = None,
             associable: Mapping | None = None, claimed: Mapping | None = None) -> TrackRow:
        """Advance to ``t_s`` and fuse this frame's detections.

        Parameters
        ----------
        t_s : float
            Frame time, s; must not decrease from one call to the next.
        dots_world : mapping, ndarray or None
            ``{colour: xy}`` with ``xy`` shape (2,) or (K, 2): candidate positions of that
            dot in the world plane, mm (K candidates: the one closest to the prediction
            in Mahalanobis distance is used; before the first fix, the first one). A bare
            array means the primary colour; None or ``{}`` means no dot this frame.
        meas_cov : mapping, optional
            ``{colour: R}`` with ``R`` shape (2, 2) or (K, 2, 2): measurement covariance
            of each candidate, mm². Default ``config.meas_std_mm²·I``.
        frame : int, optional
            Frame index of the row (default: a counter starting at 0).
        camera : int
            Recorded in the row.
        eligible : mapping, optional
            ``{colour: (K,) bool}``: which candidates passed the detector's verification
            (not a learned static light, a laser-like signature). Only eligible candidates
            start or re-acquire a track, and only they continue one that has been coasting;
            an ineligible one continues a track only inside the χ² gate of the very next
            frame (the dot passing over a lamp). Default: all eligible.
        moving : mapping, optional
            ``{colour: (K,) bool}``: which candidates a test over several frames found moving
            (:class:`~posekit.ceiling.detect.scene.StaticLights`). When given, a lost dot is
            re-acquired only on the one eligible candidate found moving, and a track is
            ``suspect`` while another eligible moving candidate is in view outside its gate.
            Default: the tracker's own test (chained motion of at least ``min_move_mm``).
        associable : mapping, optional
            ``{colour: (K,) bool}``: the candidates the dot may be associated with this frame
            (the one that continues its image track, when the caller knows it; the one a
            several-robot assignment gave it). Default: all.
        claimed : mapping, optional
            ``{colour: (K,) bool}``: candidates that belong to other tracks (other robots):
            never associated, never rivals. Default: none.

        Returns
        -------
        TrackRow
            ``ok`` only if a primary dot was measured and accepted this frame.

        Raises
        ------
        TrajectoryError
            ``t_s`` is not finite or goes back in time.
        GeometryError
            A candidate array or covariance has the wrong shape.
        """
        cfg = self.config
        t_s = float(t_s)
        if not np.isfinite(t_s):
            raise TrajectoryError(f"Tracker.step: frame time must be finite, got {t_s}")
        if np.isfinite(self.t_s) and t_s < self.t_s:
            raise TrajectoryError(f"Tracker.step: frame time went back from {self.t_s:.6f} s to {t_s:.6f} s")
        if dots_world is None:
            dots_world = {}
        elif not isinstance(dots_world, Mapping):
            dots_world = {cfg.dots[0]: dots_world}
        unknown = set(dots_world) - set(cfg.dots)
        if unknown:
            raise GeometryError(f"Tracker.step: dot colour(s) {sorted(unknown)} are not tracked; "
                                f"tracked: {list(cfg.dots)}")
        meas_cov = {} if meas_cov is None else meas_cov
        self.t_s = t_s
        self._pred_cache = None
        frame = self.frame if frame is None else int(frame)
        self.frame = frame + 1

        measured, dots, why = {}, {}, {}
        for c in cfg.dots:
            z = _as_candidates(dots_world.get(c), c)
            R = _as_covariances(meas_cov.get(c), len(z), c, cfg.meas_std_mm, cfg.min_meas_std_mm)
            el = _as_eligible(None if eligible is None else eligible.get(c), dots_world.get(c), len(z))
            mv = None
            if moving is not None and c in moving:
                mv = _as_eligible(moving[c], dots_world.get(c), len(z)) & el
            cl = np.zeros(len(z), bool)
            if claimed is not None and c in claimed:
                cl = _as_eligible(claimed[c], dots_world.get(c), len(z))
            assoc = ~cl
            if associable is not None and c in associable:
                assoc &= _as_eligible(associable[c], dots_world.get(c), len(z))
            st = self.states[c]
            had = st.x is not None and self._alive(st, t_s)
            accepted = self._update_dot(st, t_s, z, R, el & ~cl, None if mv is None else mv & ~cl, assoc)
            free = ~cl
            if accepted is not None:
                measured[c] = accepted
                free = ~cl & np.any(z != accepted[0], axis=1)
                other = verdicts.rival(st.x, st.P, z, R, None if mv is None else mv & free, accepted[0],
                                       cfg.gate_chi2, cfg.gate_floor_mm)
                self._follow_doubt(st, t_s, z, R, el & free, other is not None)
                if st.probation is not None and (t_s <= st.probation[0] + 1e-9 or st.probation[2]):
                    why[c] = (verdicts.doubt_reason(st.probation[1], st.probation[2], cfg.max_predict_s),)
                elif other is not None:
                    why[c] = (f"another moving laser-like spot at ({other[0]:.0f}, {other[1]:.0f}) mm, outside the "
                              "gate: which is the laser cannot be told",)
            else:
                self._follow_doubt(st, t_s, z, R, el & free, False)
                why[c] = verdicts.why_not(st, t_s, len(z), had, el, mv, self._alive(st, t_s), self.config)
        self._rigid_second_dot(t_s, dots_world, meas_cov, eligible, measured, why)
        for c in cfg.dots:
            st = self.states[c]
            if c in measured:
                status = "suspect" if c in why else "ok"
            elif self._alive(st, t_s):
                status = "predicted"
                if st.alt is not None:
                    why[c] = tuple(why.get(c, ())) + ("the track's identity is in doubt (re-acquired away from its "
                                                      "prediction): the 1σ spans both hypotheses",)
            else:
                status = "lost"
                st.x = st.P = None
                st.alt = st.probation = None
            xy = st.x[:2].copy() if st.x is not None else np.full(2, np.nan)
            dots[c] = (float(xy[0]), float(xy[1]), status)

        heading, heading_std = update_heading(self.heading, self.config, t_s, measured, self.states)
        main = self.states[cfg.dots[0]]
        x, y, status = dots[cfg.dots[0]]
        std = self._std_mm(main, t_s) if main.x is not None else float("nan")
        return TrackRow(frame=frame, time_s=t_s, x=x, y=y, heading_deg=heading, status=status, std_mm=std,
                        std_heading_deg=heading_std, reasons=tuple(why.get(cfg.dots[0], ())),
                        camera=camera if measured else -1,
                        measured={c: (float(v[0]), float(v[1])) for c, (v, _) in measured.items()},
                        dots=dots)

    def _rigid_second_dot(self, t_s, dots_world, meas_cov, eligible, measured, why) -> None:
        """The second dot found at the learned separation from the first
        (:func:`~posekit.ceiling.track.heading.second_dot_at_separation`): its filter restarts there."""
        self._sep, found = second_dot_at_separation(self._sep, self.config, dots_world, meas_cov, eligible, measured)
        if found is not None:
            c1, z, R = found
            st = self.states[c1]
            self._start(st, t_s, z, R * st.noise_scale)
            measured[c1] = (z, R)
            why.pop(c1, None)

    def _coast_var(self, st: DotState, t_s: float) -> float:
        """Variance per axis (mm²) of the manoeuvre the track's own data says the robot may make
        unseen since the last accepted dot, beyond what the filter's process noise already
        predicts: ``max(q̂ - q, 0) t³ / 3`` (:func:`~posekit.ceiling.track.motion_noise.fitted_accel_psd`)."""
        since = t_s - st.t_meas_s
        if st.x is None or not np.isfinite(since) or since <= 0:
            return 0.0
        return extra_psd(st, self.config.accel_psd_mm2_s3) * since ** 3 / 3.0

    def _std_mm(self, st: DotState, t_s: float) -> float:
        """1σ of the position (largest axis), the coasting manoeuvre included, mm; while the
        identity is in doubt, that of the two-hypothesis mixture (:func:`verdicts.mixture_std`)."""
        std = float(np.sqrt(np.linalg.eigvalsh(st.P[:2, :2])[-1] + self._coast_var(st, t_s)))
        return verdicts.mixture_std(std, st.x[:2], st.alt, t_s)

    def _follow_doubt(self, st: DotState, t_s: float, z, R, usable, rival_seen: bool) -> None:
        """Carry the alternative hypothesis of a dot in probation: follow it with the usable
        candidates in its gate; a rival, or the previous dot seen again, makes the doubt last for
        the rest of the track; a probation that ends without either closes it."""
        if st.probation is None:
            return
        cfg = self.config
        until, jump, conflicted = st.probation
        if st.alt is not None and verdicts.follow_alternative(st.alt, t_s, z, R, usable, cfg.accel_psd_mm2_s3,
                                                               cfg.gate_chi2):
            conflicted = True
        conflicted = conflicted or rival_seen
        st.probation = (until, jump, conflicted)
        if not conflicted and t_s > until + 1e-9:
            st.alt = None

    def _start(self, st: DotState, t_s: float, z: np.ndarray, R: np.ndarray) -> None:
        st.pending = st.seen = st.probation = None
        st.x = np.array([z[0], z[1], 0.0, 0.0])
        st.P = np.zeros((4, 4))
        st.P[:2, :2] = R
        st.P[2:, 2:] = self.config.init_speed_std_mm_s ** 2 * np.eye(2)
        st.t_meas_s, st.n_rejected, st.last_d2 = t_s, 0, 0.0
        st.z_meas = np.array(z, dtype=float)

    def _update_dot(self, st: DotState, t_s: float, z: np.ndarray, R: np.ndarray, eligible: np.ndarray,
                    moving: np.ndarray | None = None, assoc: np.ndarray | None = None):
        """Predict ``st`` to ``t_s`` and fuse the best gated candidate; returns (z, R) or None.

        While the track is fresh (the previous frame was accepted): (1) the candidate of
        smallest Mahalanobis distance inside the χ² gate and within physical reach of the last
        accepted position; else (2) a verified candidate within ``gate_floor_mm`` of the
        prediction (a manoeuvre: the covariance is inflated); else (3) the only verified
        candidate, if within reach (a sharp turn: the filter restarts there in this frame).

        While it coasts (no dot for a while): only verified candidates inside the gate count,
        and after ``confirm_after_s`` of coasting one sighting is not enough — the next frame
        must show the candidate moving as the track was (a static lamp or glint that appears
        where the dot is expected is not the dot).

        When lost, or after ``reinit_after`` frames of rejected candidates: the one verified
        candidate that moved by at least ``min_move_mm`` (and at most the reach) since the
        previous frame's verified candidates starts the track — or the one that stayed still
        within ``gate_floor_mm`` of where the dot was last accepted (the robot stopped while
        hidden). Never a static blob elsewhere, never the nearest of several; two moving
        candidates are ambiguous and start nothing.
        """
        cfg = self.config
        if st.x is not None and not self._alive(st, t_s):
            st.x = st.P = None                      # lost: the next detection starts afresh
        dt_pred = max(t_s - st.t_s, 0.0) if np.isfinite(st.t_s) else 0.0
        if st.x is not None:
            st.x, st.P = cv_predict(st.x, st.P, dt_pred, cfg.accel_psd_mm2_s3)
        st.t_s = t_s
        if len(z) == 0:
            st.last_d2 = float("nan")
            return None
        R = R * st.noise_scale
        assoc = np.ones(len(z), bool) if assoc is None else assoc
        if st.x is None:
            return self._acquire(st, t_s, z, R, eligible & assoc, None if moving is None else moving & assoc)
        since = t_s - st.t_meas_s
        fresh = since <= 1.5 * dt_pred + 1e-9
        reach = cfg.gate_floor_mm + cfg.max_speed_mm_s * since
        dist_last = np.hypot(*(z - st.z_meas).T) if st.z_meas is not None else np.zeros(len(z))
        dist_pred = np.hypot(*(z - st.x[:2]).T)
        coast = 0.0 if fresh else self._coast_var(st, t_s)
        d2 = _mahalanobis2(z - st.x[:2], st.P[:2, :2] + R + coast * np.eye(2))
        st.last_d2 = float(d2.min())
        # inside the χ² gate and within reach; an unverified candidate (a washed-out or merged dot,
        # the dot crossing a lamp) also within gate_floor_mm of the prediction: the χ² gate of a
        # fresh track, whose velocity is barely known, is far wider than a dot moves in a frame
        in_gate = (d2 <= cfg.gate_chi2) & (dist_last <= reach) & assoc & (eligible | (dist_pred <= cfg.gate_floor_mm))
        near = eligible & assoc & (dist_pred <= cfg.gate_floor_mm)
        lone = np.flatnonzero(eligible & assoc)
        if fresh:
            if in_gate.any():
                k = int(np.argmin(np.where(in_gate, d2, np.inf)))
                self._fuse(st, z[k], R[k], t_s=t_s)
                return self._accepted(st, t_s, z[k], R[k])
            if near.any():                          # a manoeuvre: inflate until consistent
                k = int(np.argmin(np.where(near, d2, np.inf)))
                self._fuse(st, z[k], R[k], inflate=d2[k] / cfg.gate_chi2, t_s=t_s)
                return self._accepted(st, t_s, z[k], R[k])
            if len(lone) == 1 and dist_last[lone[0]] <= reach:     # a sharp turn, unambiguous
                k = int(lone[0])
                self._start(st, t_s, z[k], R[k])
                return z[k], R[k]
        else:
            rest = dist_last <= cfg.gate_floor_mm       # where the dot was last seen (the robot stopped)
            usable = (in_gate | near | rest) & eligible & assoc
            if usable.any():
                k = int(np.argmin(np.where(usable, d2, np.inf)))
                if (cfg.min_move_mm == 0 or (since <= cfg.confirm_after_s + 1e-9 and (in_gate[k] or near[k]))
                        or self._moves_with_track(st, t_s, z[k]) or self._rests_where_last_seen(st, t_s, z[k])):
                    self._fuse(st, z[k], R[k], t_s=t_s)
                    st.pending = None
                    return self._accepted(st, t_s, z[k], R[k])
                st.pending = (t_s, z[k].copy())
                return None
        st.n_rejected += 1
        if st.n_rejected < cfg.reinit_after:
            return None
        prev = verdicts.open_alternative(st.x, st.P, t_s, st.t_meas_s, extra_psd(st, cfg.accel_psd_mm2_s3))
        got = self._acquire(st, t_s, z, R, eligible & assoc, None if moving is None else moving & assoc)
        if got is not None:                     # a jump while the old dot may only be hidden: not ok yet
            st.probation = (t_s + cfg.max_predict_s, float(np.hypot(*(got[0] - prev.x[:2]))), False)
            st.alt = prev                       # the previous track: the other hypothesis
        return got

    def _accepted(self, st: DotState, t_s: float, z: np.ndarray, R: np.ndarray):
        st.t_meas_s, st.n_rejected = t_s, 0
        st.z_meas = np.array(z, dtype=float)
        return z, R

    def _moves_with_track(self, st: DotState, t_s: float, z: np.ndarray) -> bool:
        """True if the pending sighting and ``z`` move as the coasting track predicts."""
        if st.pending is None:
            return False
        t0, z0 = st.pending
        dt = t_s - t0
        if not 0 < dt <= 0.5:
            return False
        v_obs = (z - z0) / dt
        v_pred = st.x[2:]
        speed = float(np.hypot(*v_pred))
        return float(np.hypot(*(v_obs - v_pred))) <= max(self.config.min_move_mm / dt, 0.5 * speed)

    def _rests_where_last_seen(self, st: DotState, t_s: float, z: np.ndarray) -> bool:
        """True if the pending sighting and ``z`` are the same still blob, within
        ``gate_floor_mm`` of the last accepted position (the robot stopped while its dot was
        hidden, e.g. turning on the spot behind an occluder)."""
        if st.pending is None or st.z_meas is None:
            return False
        t0, z0 = st.pending
        return (0 < t_s - t0 <= 1.0 and float(np.hypot(*(z - z0))) < self.config.min_move_mm
                and float(np.hypot(*(z - st.z_meas))) <= self.config.gate_floor_mm)

    def _acquire(self, st: DotState, t_s: float, z: np.ndarray, R: np.ndarray, eligible: np.ndarray,
                 moving: np.ndarray | None = None):
        """Start the track on the one verified candidate seen moving (or still where the dot
        was last accepted) over the last second; None while there is none, or more than one.

        With ``moving`` (the caller's test over several frames), the candidates it found
        moving replace the chain test below for "moving"; "resting" is still the chain's.

        Each current candidate is chained back through the verified candidates of the
        previous frames (nearest within reach at each step, at most 1 s back); it is moving
        when the chain's far end is at least ``min_move_mm`` away (a slow robot qualifies after
        a few frames, a static lamp never), resting when the chain is at least two frames long,
        still, and within ``gate_floor_mm`` of the last accepted position.
        """
        cfg = self.config
        cand = np.flatnonzero(eligible)
        if cfg.min_move_mm == 0:                    # no confirmation asked for: a lone one starts at once
            if len(cand) != 1:
                return None
            k = int(cand[0])
            self._start(st, t_s, z[k], R[k])
            return z[k], R[k]
        hist = [h for h in (st.seen or []) if 0 < t_s - h[0] <= 1.0]
        st.seen = hist + [(t_s, z[cand].copy())]
        if len(cand) == 0 or (not hist and (moving is None or not moving.any())):
            return None
        moving_chain, resting, vel = [], [], []
        for k in cand:
            p, t_p, length = z[k], t_s, 0
            far = p
            for t_h, z_h in reversed(hist):
                if len(z_h) == 0:
                    break
                d = np.hypot(*(z_h - p).T)
                m = int(np.argmin(d))
                if d[m] > cfg.gate_floor_mm + cfg.max_speed_mm_s * (t_p - t_h):
                    break
                p, t_p, length = z_h[m], t_h, length + 1
                far = p
            move = float(np.hypot(*(z[k] - far)))
            moving_chain.append(length >= 1 and move >= cfg.min_move_mm)
            resting.append(length >= 2 and move < cfg.min_move_mm and st.z_meas is not None
                           and float(np.hypot(*(z[k] - st.z_meas))) <= cfg.gate_floor_mm)
            vel.append((z[k] - far) / max(t_s - t_p, 1e-9))
        chain = list(moving_chain)
        if moving is not None:                      # the caller's test over several frames
            moving_chain = [bool(moving[k]) for k in cand]
        ok = np.array(moving_chain) | np.array(resting)
        if np.count_nonzero(ok) != 1:
            return None
        n = int(np.flatnonzero(ok)[0])
        k = int(cand[n])
        self._start(st, t_s, z[k], R[k])
        if chain[n]:
            st.x[2:] = vel[n]
        return z[k], R[k]

    def _fuse(self, st: DotState, z: np.ndarray, R: np.ndarray, inflate: float = 1.0,
              t_s: float | None = None) -> None:
        """Kalman update (the prior covariance inflated by ``inflate`` for a manoeuvre), then the
        track's measurement statistics (:func:`~posekit.ceiling.track.motion_noise.record_measurement`:
        the noise scale and the fitted process noise)."""
        if inflate > 1.0:
            st.P = st.P * inflate
        st.x, st.P = kf_update(st.x, st.P, z, R)
        if t_s is not None:
            record_measurement(st, t_s, z, R, self.config.adapt_noise)

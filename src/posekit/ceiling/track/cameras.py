"""Several fixed cameras (the paper's case D): a camera's calibration, image size and lens,
and the tracker that picks one camera per frame and feeds one
:class:`~posekit.ceiling.track.Tracker`."""

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ...errors import ConfigError, GeometryError
from ._kalman import _mahalanobis2
from .tracker import Tracker, TrackerConfig, TrackRow

__all__ = ["Camera", "MultiCameraTracker", "homography_jacobian", "border_distance"]


def homography_jacobian(to_world, uv: np.ndarray, step_px: float = 0.5) -> np.ndarray:
    """Jacobian of an image-to-world map at image points, by central differences.

    Parameters
    ----------
    to_world : callable
        ``(N, 2) px -> (N, 2) mm`` (``Calibration.image_to_world``).
    uv : ndarray, shape (K, 2)
        Image points, px.
    step_px : float
        Half step of the differences, px (exact to O(step²) for a homography).

    Returns
    -------
    ndarray, shape (K, 2, 2)
        ``d(x, y)/d(u, v)`` in mm/px.
    """
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    e = step_px * np.eye(2)
    pts = np.concatenate([uv + e[0], uv - e[0], uv + e[1], uv - e[1]])
    w = np.asarray(to_world(pts), dtype=float).reshape(4, -1, 2)
    J = np.empty((uv.shape[0], 2, 2))
    J[:, :, 0] = (w[0] - w[1]) / (2 * step_px)
    J[:, :, 1] = (w[2] - w[3]) / (2 * step_px)
    return J


def border_distance(uv: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """Distance of image points to the nearest image border, px (negative outside).

    Parameters
    ----------
    uv : ndarray, shape (K, 2)
        Pixel coordinates (u right, v down; pixel centres at integers).
    image_size : (int, int)
        ``(width, height)``, px.
    """
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    w, h = image_size
    return np.minimum.reduce([uv[:, 0] + 0.5, w - 0.5 - uv[:, 0], uv[:, 1] + 0.5, h - 0.5 - uv[:, 1]])


@dataclass
class Camera:
    """One fixed camera of case D.

    Attributes
    ----------
    calibration : object
        Has ``image_to_world((N, 2) px) -> (N, 2) mm``, ``world_to_image`` and ``rms_px``
        (a :class:`posekit.ceiling.camera.homography.Calibration`).
    image_size : (int, int)
        ``(width, height)`` of its frames, px.
    name : str
        For messages and reports.
    detection_std_px : float
        Floor of the per-axis std of a dot detection, px; the measurement std is
        ``max(calibration.rms_px, detection_std_px)`` pushed through the homography.
    lens : object, optional
        The lens model (:class:`posekit.ceiling.camera.CameraModel`: ``undistort_points``,
        ``distort_points``): detections are undistorted before the homography (which then
        maps undistorted pixels) and predicted positions distorted back. None: no distortion.
    """

    calibration: object
    image_size: tuple[int, int]
    name: str = ""
    detection_std_px: float = 0.1
    lens: object = None

    def __post_init__(self):
        cal = self.calibration
        H = getattr(cal, "H_world_image", None)
        self._H_wi = None if H is None else np.asarray(H, dtype=float)
        H = getattr(cal, "H_image_world", None)
        self._H_iw = None if H is None else np.asarray(H, dtype=float)
        rms = float(getattr(cal, "rms_px", 0.0) or 0.0)
        if getattr(cal, "status", "ok") == "suspect":        # the points contradict the model: all of them count
            rms = max(rms, float(np.nan_to_num(getattr(cal, "rms_all_px", 0.0), nan=0.0)))
        self._std_px = max(rms, self.detection_std_px)

    def measurement(self, uv: np.ndarray, std_px: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """World positions (K, 2) mm and covariances (K, 2, 2) mm² of image points (K, 2) px.

        The covariance is ``s² J Jᵀ`` with ``s = max(calibration.rms_px, detection_std_px)``
        (or, per point, ``max(that, std_px)`` when ``std_px`` (K,) px is given: the detector's
        own uncertainty of a large, blooming or clipped blob) and ``J`` the Jacobian of the
        image-to-world homography at the point (analytic when the calibration exposes
        ``H_world_image``, central differences otherwise).
        """
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        if self.lens is not None and len(uv):
            uv = np.asarray(self.lens.undistort_points(uv), dtype=float).reshape(-1, 2)
        if self._H_wi is not None:
            H = self._H_wi
            q = uv @ H[:, :2].T + H[:, 2]
            w = q[:, 2:3]
            xy = q[:, :2] / w
            J = (H[None, :2, :2] - xy[:, :, None] * H[None, 2:3, :2]) / w[:, :, None]
        else:
            xy = np.asarray(self.calibration.image_to_world(uv), dtype=float).reshape(-1, 2)
            J = homography_jacobian(self.calibration.image_to_world, uv)
        s2 = self._std_px ** 2
        if std_px is not None:
            s2 = np.maximum(s2, np.asarray(std_px, dtype=float).reshape(-1) ** 2)[:, None, None]
        return xy, s2 * J @ np.swapaxes(J, 1, 2)

    def to_image(self, xy: np.ndarray) -> np.ndarray:
        """Image points (K, 2) px of world points (K, 2) mm (NaN behind the camera), as the
        lens shows them (distorted when ``lens`` is given)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if self._H_iw is None:
            try:
                uv = np.asarray(self.calibration.world_to_image(xy), dtype=float).reshape(-1, 2)
            except GeometryError:                 # beyond this camera's horizon
                return np.full_like(xy, np.nan)
        else:
            H = self._H_iw
            q = xy @ H[:, :2].T + H[:, 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                uv = np.where(q[:, 2:3] > 0, q[:, :2] / q[:, 2:3], np.nan)
        if self.lens is not None and len(uv):
            uv = np.asarray(self.lens.distort_points(uv), dtype=float).reshape(-1, 2)
        return uv


class MultiCameraTracker:
    """One world track from several calibrated cameras that each see part of the ceiling.

    Each frame every camera reports its detections (image pixels). Detections are mapped
    to the world plane with that camera's calibration; the primary dot of each camera is
    gated against the track's prediction. The camera used is the previous one while its
    accepted dot stays at least ``border_margin_px`` from its image border; otherwise the
    camera whose accepted dot is farthest from its border (ties: smallest measurement
    covariance). Only that camera's dots update the :class:`Tracker`; with one camera this
    is the single-camera tracker with a position-dependent measurement covariance.

    Parameters
    ----------
    cameras : sequence of Camera
    config : TrackerConfig, optional
    border_margin_px : float
        Keep the active camera while its dot is at least this far from the border.
    """

    def __init__(self, cameras: Sequence[Camera], config: TrackerConfig | None = None,
                 border_margin_px: float = 20.0):
        if len(cameras) == 0:
            raise ConfigError("MultiCameraTracker: expected at least one camera")
        self.cameras = list(cameras)
        self.tracker = Tracker(config)
        self.border_margin_px = float(border_margin_px)
        self.active = -1

    @property
    def config(self) -> TrackerConfig:
        return self.tracker.config

    def reset(self) -> None:
        self.tracker.reset()
        self.active = -1

    def predicted_uv(self, t_s: float) -> list[dict[str, tuple[float, float]]]:
        """Predicted image position of each live dot in each camera at ``t_s``.

        Returns
        -------
        list of dict
            Per camera ``{colour: (u, v)}`` px, only for dots whose prediction falls inside
            that camera's image (the detector's region of interest); empty when lost.
        """
        pred = self.tracker.predict(t_s)
        if not pred:
            return [{} for _ in self.cameras]
        colours = list(pred)
        xy = np.array([pred[c][0] for c in colours])
        out = []
        for cam in self.cameras:
            uv = cam.to_image(xy)
            inside = np.all(np.isfinite(uv), axis=1)
            inside[inside] = border_distance(uv[inside], cam.image_size) > 0
            out.append({c: (float(uv[k, 0]), float(uv[k, 1])) for k, c in enumerate(colours) if inside[k]})
        return out

    def step(self, t_s: float, dots_image: Sequence[Mapping | None], *,
             frame: int | None = None, eligible: Sequence[Mapping | None] | None = None,
             std_px: Sequence[Mapping | None] | None = None,
             moving: Sequence[Mapping | None] | None = None,
             associable: Sequence[Mapping | None] | None = None) -> TrackRow:
        """Fuse one frame of detections from every camera.

        Parameters
        ----------
        t_s : float
            Frame time, s (the cameras are assumed synchronised).
        dots_image : sequence of mapping or None
            One entry per camera: ``{colour: uv}`` with ``uv`` shape (2,) or (K, 2),
            image pixels; None when that camera was not read or saw nothing.
        eligible : sequence of mapping or None, optional
            Per camera ``{colour: (K,) bool}``, the detector's verification of each candidate
            (see :meth:`Tracker.step`); default all eligible.
        std_px : sequence of mapping or None, optional
            Per camera ``{colour: (K,) px}``: the detector's uncertainty of each candidate
            (see :meth:`Camera.measurement`).
        moving : sequence of mapping or None, optional
            Per camera ``{colour: (K,) bool}``: candidates found moving (see :meth:`Tracker.step`).
        associable : sequence of mapping or None, optional
            Per camera ``{colour: (K,) bool}``: candidates the dot may be associated with (see
            :meth:`Tracker.step`).

        Returns
        -------
        TrackRow
            With ``camera`` the index of the camera used (-1 if none).
        """
        if len(dots_image) != len(self.cameras):
            raise ConfigError(f"MultiCameraTracker.step: expected detections of {len(self.cameras)} "
                              f"camera(s), got {len(dots_image)}")
        cfg = self.tracker.config
        primary = cfg.dots[0]
        pred = self.tracker.predict(t_s)
        seen = {}                                # camera -> {colour: (xy (K, 2), R (K, 2, 2), border (K,))}
        views = []                               # (camera, primary seen, border distance, trace R)
        for i, (cam, det) in enumerate(zip(self.cameras, dots_image)):
            if not det:
                continue
            meas = {}
            for c, uv in det.items():
                if c not in cfg.dots:
                    continue
                uv = np.asarray(uv, dtype=float).reshape(-1, 2)
                fin = np.all(np.isfinite(uv), axis=1)
                uv = uv[fin]
                sp = None
                if std_px is not None and std_px[i] is not None and c in std_px[i]:
                    sp = np.asarray(std_px[i][c], dtype=float).reshape(-1)[fin]
                if len(uv):
                    xy, R = cam.measurement(uv, sp)
                    meas[c] = (xy, R, border_distance(uv, cam.image_size))
            if not meas:
                continue
            seen[i] = meas
            key = primary if primary in meas else next(iter(meas))
            xy, R, bd = meas[key]
            mv = None
            if moving is not None and moving[i] is not None and key in moving[i]:
                mv = np.asarray(moving[i][key], dtype=bool).reshape(-1)
                mv = mv[np.all(np.isfinite(np.asarray(det[key], dtype=float).reshape(-1, 2)), axis=1)]
            if key in pred:                      # keep only candidates that pass the gate
                p, Pp = pred[key]
                d2 = _mahalanobis2(xy - p, Pp + cfg.min_meas_std_mm ** 2 * np.eye(2) + R)
                ok = (d2 <= cfg.gate_chi2) | (np.hypot(*(xy - p).T) <= cfg.gate_floor_mm)
                if not ok.any():
                    continue
                k = int(np.argmin(np.where(ok, d2, np.inf)))
                starts = True
            else:                                # no track: a candidate seen moving can start one
                k = int(np.argmax(mv)) if mv is not None and mv.any() else 0
                starts = mv is None or bool(mv[k])
            views.append((i, key == primary, float(bd[k]), float(R[k, 0, 0] + R[k, 1, 1]), starts))
        if not views:
            if not seen:
                return self.tracker.step(t_s, None, frame=frame)
            # nothing passed the gate: give the tracker the detections of the active (or the
            # first seeing) camera so that its outlier and re-initialisation logic runs
            chosen = self.active if self.active in seen else next(iter(seen))
        else:
            views.sort(key=lambda v: (not v[1], not v[4], -v[2], v[3]))   # primary seen, can start, far from
            chosen = views[0][0]                                          # the border, small R
            for i, has_primary, bd, _, _ in views:
                if i == self.active and has_primary and bd >= self.border_margin_px:
                    chosen = i
                    break
            self.active = chosen
        meas = seen[chosen]
        def pick(flags):
            if flags is None or flags[chosen] is None:
                return None
            return {c: flags[chosen][c] for c in meas if c in flags[chosen]}
        return self.tracker.step(t_s, {c: m[0] for c, m in meas.items()}, {c: m[1] for c, m in meas.items()},
                                 frame=frame, camera=chosen, eligible=pick(eligible), moving=pick(moving),
                                 associable=pick(associable))

"""The tunable parameters of corner detection (:class:`CornerParams`) and their compiled form.

Both detectors of :mod:`~posekit.profiler.estimate.corners` read them; the model-based kernel of
:mod:`~posekit.profiler.estimate.faces` takes them as one read-only float vector
(:func:`param_vector`, cached per frozen :class:`CornerParams`; layout in ``faces``).
"""

from dataclasses import astuple, dataclass

import numpy as np

from ...errors import ConfigError
from . import faces

__all__ = ["CornerParams", "param_vector"]


@dataclass(frozen=True)
class CornerParams:
    """Tunable parameters of corner detection (mm unless named otherwise).

    The first six serve both detectors; ``trim`` and ``min_corner_mm`` only the RDP
    detector; the rest only the model-based one. ``face_tilt_tolerance_deg`` and
    ``scale_tolerance_ppm`` add declared systematic uncertainties (the as-built faces' tilt,
    the sensor's scale) to the model-based detector's corner covariance (0: noise only).
    """

    #: A vertex is a corner when it deviates at least this much from its chord.
    min_corner_mm: float = 0.3
    #: A return farther than this (in z) from its 5-point running median is a spike.
    spike_mm: float = 0.2
    #: Fraction of each segment's points dropped at both ends.
    trim: float = 0.1
    #: Residual rejection threshold of the robust line fit, in residual RMS.
    k_sigma: float = 4.0
    #: Smallest number of points a segment must keep for its fit.
    min_segment_points: int = 8
    #: Floor of the per-line noise σ used for the covariance, mm.
    sigma_floor_mm: float = 1e-6
    #: Segmentation tolerance: straight within this (or 6 noise σ, if more) is one segment.
    seg_tol_mm: float = 0.05
    #: The segmentation tolerance in units of the measured noise σ, if larger than seg_tol_mm.
    seg_tol_sigmas: float = 6.0
    #: Shortest segment that can be a face.
    min_face_mm: float = 2.0
    #: Returns closer than this to a ridge (along the face) are not fitted: the rounded zone.
    band_mm: float = 1.0
    #: The band grows up to this while the returns beside it lean off the face's line.
    max_band_mm: float = 5.0
    #: Neighbouring segments within this angle (deg) and a few σ of one line are one face.
    merge_deg: float = 3.0
    #: Most segments skipped between two consecutive faces.
    max_skip: int = 3
    #: Tolerance (1σ, deg) of a turn between faces against the gauge's cross-section.
    turn_sigma_deg: float = 10.0
    #: Largest deviation of a turn from the gauge's, deg.
    max_turn_dev_deg: float = 30.0
    #: Smallest turn that separates two faces, deg.
    min_turn_deg: float = 3.0
    #: How far two faces' lines may meet inside one of their segments.
    corner_inside_mm: float = 1.0
    #: Scale (1σ) and limit of the detour from one face's segment through the corner to the next.
    detour_mm: float = 1.0
    max_detour_mm: float = 10.0
    #: Cost of skipping a segment between two faces, per mm of its length.
    skip_cost_per_mm: float = 0.5
    #: Segments beside the outer faces are background unless within this of the gauge's surface.
    attach_mm: float = 3.0
    #: A long segment within this of an outer face, meeting it in a corner, is a face more
    #: than the gauge has (wrong gauge file): an error.
    extra_face_gap_mm: float = 1.5
    #: Smallest distance from a face's line at which a return is rejected.
    gate_floor_mm: float = 0.015
    #: 1σ of each as-built face's tilt from its drawing (about its middle), deg. The faces'
    #: offset tolerance is the gauge's ``tolerance_um``, which the solver adds at the pose.
    face_tilt_tolerance_deg: float = 0.0
    #: 1σ of the sensor's scale error in x and in z, ppm.
    scale_tolerance_ppm: float = 0.0
    #: Depth about which a z scale error acts (the middle of the measuring range), mm.
    scale_center_z_mm: float = 442.5
    #: Most segments in one profile before it counts as clutter.
    max_segments: int = 512

    def __post_init__(self):
        for key, value in zip(self.__dataclass_fields__, astuple(self)):
            if not np.isfinite(value) or value < 0:
                raise ConfigError(f"corner parameters: '{key}' must be a finite number >= 0, got {value}")
        if self.min_segment_points < 2 or self.max_skip > 16 or self.max_segments < 8:
            raise ConfigError("corner parameters: expected min_segment_points >= 2, max_skip <= 16 and "
                              f"max_segments >= 8, got {self.min_segment_points}, {self.max_skip}, "
                              f"{self.max_segments}")


_VECTORS: dict = {}


def param_vector(params: CornerParams) -> np.ndarray:
    """The model kernel's parameter vector (cached per CornerParams object: they are frozen)."""
    hit = _VECTORS.get(id(params))
    if hit is not None and hit[0] is params:
        return hit[1]
    if len(_VECTORS) > 256:
        _VECTORS.clear()
    v = _build_param_vector(params)
    _VECTORS[id(params)] = (params, v)
    return v


def _build_param_vector(params: CornerParams) -> np.ndarray:
    """The model kernel's parameter vector (layout in :mod:`~posekit.profiler.estimate.faces`)."""
    p = params
    v = np.empty(faces.N_PARAMS)
    v[faces.P_SPIKE] = p.spike_mm
    v[faces.P_KSIG] = p.k_sigma
    v[faces.P_MINPTS] = p.min_segment_points
    v[faces.P_SIGFLOOR] = p.sigma_floor_mm
    v[faces.P_SEGTOL] = p.seg_tol_mm
    v[faces.P_SEGSIG] = p.seg_tol_sigmas
    v[faces.P_MINFACE] = p.min_face_mm
    v[faces.P_BAND] = p.band_mm
    v[faces.P_MAXBAND] = max(p.max_band_mm, p.band_mm)
    v[faces.P_MERGEDEG] = p.merge_deg
    v[faces.P_MAXSKIP] = p.max_skip
    v[faces.P_TURNSIG] = np.radians(p.turn_sigma_deg)
    v[faces.P_TURNMAX] = np.radians(p.max_turn_dev_deg)
    v[faces.P_TURNMIN] = np.radians(p.min_turn_deg)
    v[faces.P_TOLIN] = p.corner_inside_mm
    v[faces.P_DETSIG] = p.detour_mm
    v[faces.P_DETMAX] = p.max_detour_mm
    v[faces.P_SKIPCOST] = p.skip_cost_per_mm
    v[faces.P_GATEFLOOR] = p.gate_floor_mm
    v[faces.P_FACETILT] = np.radians(p.face_tilt_tolerance_deg)
    v[faces.P_SCALE] = p.scale_tolerance_ppm
    v[faces.P_SCALEZ] = p.scale_center_z_mm
    v[faces.P_MAXVERT] = p.max_segments
    v[faces.P_ATTACH] = p.attach_mm
    v[faces.P_EXTRAGAP] = p.extra_face_gap_mm
    v.flags.writeable = False
    return v

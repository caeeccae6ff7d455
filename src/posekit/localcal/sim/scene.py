"""The work cell of a look-then-move episode: camera and tool marker on the arm, an object of
interest (OOI) marked by three ArUco markers, observation and ground truth.

Frames (mm, rad): B robot base; F the TCP frame at the end of the DH chain; C the camera
(OpenCV optical convention), rigid on F (``T_F_C``); M the tool marker (ArUco id 0), rigid
on F (``T_F_M``); O the OOI, fixed in B (``T_B_O``), the centre of three coplanar markers
with ids 1, 2, 3 at ``T_O_Oi`` (pure translations in the OOI plane). Marker frames follow
OpenCV ArUco (z out of the face).

Default layout (:func:`default_workcell`, HIAB033-like crane at its start pose)
-------------------------------------------------------------------------------
* Camera: looks along the torsion axis of the last joint, i.e. along ``-z_F`` (the TCP
  frame's z axis points back toward the arm, see ``posekit.robots.hiab033``); image x is
  ``-y_F``, image y is ``-x_F`` (:data:`R_F_C_NOMINAL`; an upright image when the arm is
  stretched out).
* Tool marker (id 0, 70 mm): at the TCP ("link 7 unifies the last frame with the tool
  marker's frame", paper Sec. 4.2), so ``T_F_M ≈ I``; the camera sees it at
  ``t_C_M = (-180, 100, 420)`` mm (lower left of the image), facing the camera, so
  ``R_C_M = R_F_C_NOMINAL^T``. With ``rng`` the mounting gets small alignment errors
  (≈1° per axis and ≈3 mm), as the paper reports; ``T_F_C`` follows from them.
* OOI: ``distance_mm`` (1 m) in front of the camera at the arm's true pose when the cell is
  made, at ``(x, y) = (170, -80)`` mm in the camera frame (upper right of the image), facing
  the camera and parallel to the tool marker (with ``rng``: ≈3° per axis of extra rotation
  and ±20 mm of extra offset). Markers 1, 2, 3 (80 mm) at ``(170, 0)``, ``(-100, 150)``,
  ``(-100, -150)`` mm in the OOI plane (above, lower left and lower right of the OOI centre
  in the image).
* So the tool marker starts (350, -180, 580) mm from the OOI in the camera frame (nominal
  layout, OOI at 1 m; the episodes put it at 0.76 m, the paper's Table 2 depth). Checked by
  rendering (seeds 0–9, OOI at 0.76, 0.8, 1.0 and 1.2 m): all four markers are
  detected at the start pose, along a 20 cm circle in the local (n, s) plane, and with the
  tool marker driven to 100 mm in front of the OOI.
"""

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from posekit._extras import lazy
from posekit.errors import ConfigError
from posekit.geometry import (
    check_transform,
    invert_transform,
    matrix_from_rotation_vector,
    rotation_vector_from_matrix,
)
from posekit.localcal.sim.camera import _one_transform, marker_corners, render_markers
from posekit.localcal.sim.marker_detector import MarkerDetector

cv2 = lazy("cv2", "vision", "the localcal camera simulator")

__all__ = [
    "GroundTruth",
    "Observation",
    "Workcell",
    "default_workcell",
    "ground_truth_errors",
    "marker_errors",
    "observe",
    "ooi_pose",
]

#: Camera axes in the TCP frame F (columns x_C, y_C, z_C): z_C = -z_F (forward along the
#: torsion axis), x_C = -y_F, y_C = -x_F.
R_F_C_NOMINAL = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
TOOL_MARKER_IN_CAMERA_MM = np.array([-180.0, 100.0, 420.0])
OOI_OFFSET_IN_CAMERA_MM = np.array([170.0, -80.0])
#: OOI marker centres in the OOI plane (x_O, y_O), mm: seen head-on they are above
#: (id 1), lower left (id 2) and lower right (id 3) of the OOI centre in the image.
OOI_MARKER_OFFSETS_MM = {1: (170.0, 0.0), 2: (-100.0, 150.0), 3: (-100.0, -150.0)}
TOOL_MARKER_SIZE_MM = 70.0
OOI_MARKER_SIZE_MM = 80.0


@dataclass(frozen=True)
class Workcell:
    """Where the camera, the tool marker and the OOI markers are.

    Parameters
    ----------
    T_F_C : array_like, shape (4, 4)
        Camera in the TCP frame, mm (unknown to the calibration methods).
    T_F_M : array_like, shape (4, 4)
        Tool marker in the TCP frame, mm.
    T_B_O : array_like, shape (4, 4)
        OOI in the robot base frame, mm.
    T_O_markers : mapping of int to array_like (4, 4)
        Each OOI marker's frame in the OOI frame, mm.
    sizes_mm : mapping of int to float
        Side of each marker's black square (tool marker and OOI markers), mm.
    tool_marker_id : int
        Id of the tool marker.
    ooi_marker_ids : tuple of int
        Ids of the OOI markers (keys of ``T_O_markers``).

    Raises
    ------
    GeometryError
        A transform that is not rigid.
    ConfigError
        A marker without a size, a size that is not > 0, ids that do not match.
    """

    T_F_C: np.ndarray
    T_F_M: np.ndarray
    T_B_O: np.ndarray
    T_O_markers: Mapping[int, np.ndarray]
    sizes_mm: Mapping[int, float]
    tool_marker_id: int = 0
    ooi_marker_ids: tuple[int, ...] = (1, 2, 3)
    _T_C_M: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        set_ = object.__setattr__
        for name in ("T_F_C", "T_F_M", "T_B_O"):
            set_(self, name, _one_transform(getattr(self, name), name))
        ids = tuple(int(i) for i in self.ooi_marker_ids)
        if not ids or len(set(ids)) != len(ids) or self.tool_marker_id in ids:
            raise ConfigError(
                f"ooi_marker_ids: expected distinct ids other than the tool marker "
                f"{self.tool_marker_id}, got {list(ids)}"
            )
        if set(self.T_O_markers) != set(ids):
            raise ConfigError(
                f"T_O_markers: expected one transform for each OOI marker {list(ids)}, "
                f"got ids {sorted(self.T_O_markers)}"
            )
        T_O = {int(i): _one_transform(T, f"T_O_markers[{i}]") for i, T in self.T_O_markers.items()}
        sizes = {}
        for i in (self.tool_marker_id,) + ids:
            if i not in self.sizes_mm:
                raise ConfigError(f"sizes_mm: unknown marker size for marker {i}")
            s = self.sizes_mm[i]
            if not (np.ndim(s) == 0 and np.isfinite(s) and s > 0):
                raise ConfigError(
                    f"sizes_mm: marker {i} has size {s!r}, expected a finite size > 0 mm"
                )
            sizes[i] = float(s)
        set_(self, "ooi_marker_ids", ids)
        set_(self, "T_O_markers", T_O)
        set_(self, "sizes_mm", sizes)
        set_(self, "_T_C_M", invert_transform(self.T_F_C, check=False) @ self.T_F_M)

    @property
    def T_C_M(self) -> np.ndarray:
        """Tool marker in the camera frame, (4, 4), mm (constant: both are rigid on F)."""
        return self._T_C_M.copy()

    def marker_poses(self, T_B_F_true) -> list[tuple[int, float, np.ndarray]]:
        """``(marker_id, size_mm, T_C_Mi)`` of all four markers seen from a true TCP pose.

        Parameters
        ----------
        T_B_F_true : array_like, shape (4, 4)
            True TCP pose in the base frame, mm.
        """
        T_B_F = _one_transform(T_B_F_true, "T_B_F_true")
        T_C_O = invert_transform(T_B_F @ self.T_F_C, check=False) @ self.T_B_O
        out = [(self.tool_marker_id, self.sizes_mm[self.tool_marker_id], self._T_C_M.copy())]
        for i in self.ooi_marker_ids:
            out.append((i, self.sizes_mm[i], T_C_O @ self.T_O_markers[i]))
        return out


def _small_rotation(rng: np.random.Generator, sigma_rad: float) -> np.ndarray:
    return matrix_from_rotation_vector(rng.normal(0.0, sigma_rad, 3))


def default_workcell(arm, rng=None, *, distance_mm: float = 1000.0) -> Workcell:
    """The documented default layout (module docs) around the arm's current true pose.

    Parameters
    ----------
    arm : LongReachArm
        The arm; its current true TCP pose places the OOI.
    rng : numpy.random.Generator or int, optional
        Randomises the mounting errors of the tool marker (≈1°, ≈3 mm) and the OOI's extra
        rotation (≈3° per axis) and offset (±20 mm); ``None`` gives the nominal layout.
    distance_mm : float
        Distance of the OOI in front of the camera at the start pose, mm (500–2000).

    Returns
    -------
    Workcell
    """
    if not (np.ndim(distance_mm) == 0 and np.isfinite(distance_mm) and 500.0 <= distance_mm <= 2000.0):
        raise ConfigError(f"distance_mm must be between 500 and 2000 mm, got {distance_mm!r}")
    T_C_M = np.eye(4)
    T_C_M[:3, :3] = R_F_C_NOMINAL.T  # R_C_M = R_C_F for T_F_M = I
    T_C_M[:3, 3] = TOOL_MARKER_IN_CAMERA_MM
    T_F_M = np.eye(4)
    T_C_O = np.eye(4)
    T_C_O[:3, :3] = T_C_M[:3, :3]
    T_C_O[:3, 3] = [*OOI_OFFSET_IN_CAMERA_MM, distance_mm]
    if rng is not None:
        rng = np.random.default_rng(rng)
        T_F_M[:3, :3] = _small_rotation(rng, np.deg2rad(1.0))
        T_F_M[:3, 3] = rng.normal(0.0, 3.0, 3)
        T_C_O[:3, :3] = T_C_O[:3, :3] @ _small_rotation(rng, np.deg2rad(3.0))
        T_C_O[:2, 3] += rng.uniform(-20.0, 20.0, 2)
    # camera pose on F from where the tool marker is seen: T_F_C = T_F_M T_M_C
    T_F_C = T_F_M @ invert_transform(T_C_M, check=False)
    T_B_C = arm.true_pose() @ T_F_C
    T_O_markers = {}
    for i, (x, y) in OOI_MARKER_OFFSETS_MM.items():
        T = np.eye(4)
        T[:2, 3] = x, y
        T_O_markers[i] = T
    sizes = {0: TOOL_MARKER_SIZE_MM, **{i: OOI_MARKER_SIZE_MM for i in OOI_MARKER_OFFSETS_MM}}
    return Workcell(T_F_C, T_F_M, T_B_C @ T_C_O, T_O_markers, sizes)


class Observation(NamedTuple):
    """What the camera measured in one image.

    T_C_M : ndarray, shape (4, 4), or None
        Tool marker in the camera frame, mm; None if not detected.
    T_C_O : ndarray, shape (4, 4), or None
        OOI in the camera frame, mm, from any detected OOI markers; None if none was seen.
    seen : tuple of int
        Detected marker ids, sorted.
    image : ndarray, shape (H, W), uint8, or None
        The rendered image (only with ``keep_image=True``).
    """

    T_C_M: np.ndarray | None
    T_C_O: np.ndarray | None
    seen: tuple[int, ...]
    image: np.ndarray | None


def ooi_pose(cell: Workcell, detector: MarkerDetector, corners: Mapping[int, np.ndarray]) -> np.ndarray | None:
    """OOI pose ``T_C_O`` from the image corners of any detected OOI markers.

    With one marker: ``T_C_Oi @ inv(T_O_Oi)`` (IPPE_SQUARE). With several: one PnP over all
    their corners (known positions in O), started from the single-marker estimate of the
    largest marker in the image and refined with Levenberg–Marquardt.

    Parameters
    ----------
    cell : Workcell
    detector : MarkerDetector
        Knows the intrinsics and marker sizes.
    corners : mapping of int to ndarray, shape (4, 2)
        Detected image corners per marker id, px (other ids are ignored).

    Returns
    -------
    T_C_O : ndarray, shape (4, 4), or None
        OOI pose in the camera frame, mm; None if no OOI marker is among ``corners``.
    """
    ids = [i for i in cell.ooi_marker_ids if i in corners]
    if not ids:
        return None
    areas = [cv2.contourArea(np.asarray(corners[i], np.float32)) for i in ids]
    best = ids[int(np.argmax(areas))]
    T_C_O = detector.pose_from_corners(best, corners[best]) @ invert_transform(
        cell.T_O_markers[best], check=False
    )
    if len(ids) == 1:
        return T_C_O
    obj = np.concatenate(
        [marker_corners(cell.sizes_mm[i]) @ cell.T_O_markers[i][:3, :3].T + cell.T_O_markers[i][:3, 3] for i in ids]
    )
    img = np.concatenate([np.asarray(corners[i], np.float64).reshape(4, 2) for i in ids])
    rvec = cv2.Rodrigues(T_C_O[:3, :3])[0]
    tvec = T_C_O[:3, 3].reshape(3, 1).copy()
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, detector.intr.K, detector.intr.dist, rvec, tvec)
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.ravel()
    return T


def observe(
    cell: Workcell, T_B_F_true, detector: MarkerDetector, rng=None, *, keep_image: bool = False
) -> Observation:
    """Render the four markers from the true camera pose and measure them.

    The camera is at ``T_B_C = T_B_F_true @ T_F_C``; the image comes from
    :func:`~posekit.localcal.sim.camera.render_markers` and the poses from ``detector``.

    Parameters
    ----------
    cell : Workcell
    T_B_F_true : array_like, shape (4, 4)
        True TCP pose in the base frame, mm (e.g. ``arm.true_pose()``).
    detector : MarkerDetector
        Must know the sizes of the cell's markers.
    rng : numpy.random.Generator or int or None
        Image noise.
    keep_image : bool
        Return the image in the observation.

    Returns
    -------
    Observation

    Raises
    ------
    ConfigError
        The detector does not know the size of one of the cell's markers.
    GeometryError
        ``T_B_F_true`` is not a rigid transform.
    """
    missing = [i for i in (cell.tool_marker_id, *cell.ooi_marker_ids) if i not in detector.sizes_mm]
    if missing:
        raise ConfigError(f"detector: unknown marker size for marker {missing[0]}")
    image = render_markers(detector.intr, cell.marker_poses(T_B_F_true), rng)
    corners = detector.detect_corners(image)
    tool = cell.tool_marker_id
    T_C_M = detector.pose_from_corners(tool, corners[tool]) if tool in corners else None
    return Observation(
        T_C_M,
        ooi_pose(cell, detector, corners),
        tuple(sorted(corners)),
        image if keep_image else None,
    )


class GroundTruth(NamedTuple):
    """True tool-marker-to-OOI error, in the camera frame.

    e_C_mm : ndarray, shape (3,)
        ``t_C_O - t_C_M``: OOI position minus tool marker position, camera frame, mm
        (``e_z`` includes the intended stand-off).
    rot_C_rad : ndarray, shape (3,)
        Rotation vector of ``R_C_O R_C_M^T`` (the paper's ``r_Δ = r_O r_T⁻¹``), rad.
    T_C_M, T_C_O : ndarray, shape (4, 4)
        True tool marker and OOI poses in the camera frame, mm.
    """

    e_C_mm: np.ndarray
    rot_C_rad: np.ndarray
    T_C_M: np.ndarray
    T_C_O: np.ndarray


def marker_errors(T_C_M, T_C_O) -> tuple[np.ndarray, np.ndarray]:
    """Position and rotation error between the tool marker and the OOI in the camera frame.

    Parameters
    ----------
    T_C_M, T_C_O : array_like, shape (..., 4, 4)
        Tool marker and OOI poses in the camera frame, mm.

    Returns
    -------
    e_C_mm : ndarray, shape (..., 3)
        ``t_C_O - t_C_M``, mm.
    rot_C_rad : ndarray, shape (..., 3)
        Rotation vector of ``R_C_O R_C_M^T``, rad.
    """
    T_C_M = np.asarray(T_C_M, dtype=np.float64)
    T_C_O = np.asarray(T_C_O, dtype=np.float64)
    e = T_C_O[..., :3, 3] - T_C_M[..., :3, 3]
    R = T_C_O[..., :3, :3] @ np.swapaxes(T_C_M[..., :3, :3], -1, -2)
    return e, rotation_vector_from_matrix(R, check=False)


def ground_truth_errors(cell: Workcell, T_B_F_true) -> GroundTruth:
    """The true tool-marker-to-OOI error for a true TCP pose (to score the methods).

    Parameters
    ----------
    cell : Workcell
    T_B_F_true : array_like, shape (4, 4) or (N, 4, 4)
        True TCP pose(s) in the base frame, mm.

    Returns
    -------
    GroundTruth
        Arrays with the leading batch axis of ``T_B_F_true``.
    """
    T_B_F = check_transform(T_B_F_true, name="T_B_F_true")
    T_C_O = invert_transform(T_B_F @ cell.T_F_C, check=False) @ cell.T_B_O
    T_C_M = np.broadcast_to(cell.T_C_M, T_C_O.shape).copy()
    e, rot = marker_errors(T_C_M, T_C_O)
    return GroundTruth(e, rot, T_C_M, T_C_O)

"""The seam cell as the filter sees it: the installation (:class:`Cell`) and how it errs (:class:`Profile`).

Plain data, no algorithm (STYLE §8): the particle filter (:mod:`posekit.seam.engine`) reads these two, the
front end builds them from a configuration or a recorded episode's ``setup.yaml``
(:mod:`posekit.seam.frontend.config`, :mod:`posekit.seam.frontend.logs`) and from a fitted profile file
(:mod:`posekit.seam.frontend.profile`, written by ``posekit seam tune``).

:class:`Cell` — what the user knows or measures of the installation: the robot with its tool (a kinematic
chain, bundled, DH or URDF), each laser seam tracker's mount ``T_tool_sensor`` and, where declared, its
latency, the force sensor (on the wrist, tool frame; optionally a 6-D wrench), and the joint compliance model
``Δq = c τ`` of the paper's eq. (5).

:class:`Profile` — the fitted parameters of the filter's densities (paper §II-C): the random walk of the pose
about its modelled motion (eq. 3) and the white jitter about it, the robot density's plateau and tails (eq. 7/8)
with the force range it was fitted over, the joint noise, and per sensor the laser noise (eq. 9) and latency.
No value here is a code default: a profile is read from a file written by ``posekit seam tune`` (the shipped
default one included, ``src/posekit/seam/profiles/default.yaml``).

Units: mm and rad; the walk in mm/√mm and rad/√mm (its variance grows linearly with the tool's travel: the
robot's error is a function of its configuration), the jitter in mm and rad per sample (white).
"""

from dataclasses import dataclass, field

import numpy as np

from posekit.robots import KinematicChain

__all__ = ["Cell", "Profile", "Sensor"]


@dataclass(frozen=True, eq=False)
class Sensor:
    """One laser seam tracker rigidly on the tool.

    Attributes
    ----------
    T_tool_sensor : ndarray, shape (4, 4)
        The mount, mm: the sensor frame in the tool frame; its x–z plane is the laser plane (x across the
        seam, z along the line of sight), its origin the desired seam crossing (paper Fig. 1).
    latency_s : float or None
        Declared latency, s: a reading in the sample at ``time_s`` was taken at ``time_s - latency_s``
        (None: not declared, the profile's applies).
    """

    T_tool_sensor: np.ndarray
    latency_s: float | None = None


@dataclass(frozen=True, eq=False)
class Cell:
    """The installation: robot with tool, laser sensors, force sensor, compliance model.

    Attributes
    ----------
    chain : KinematicChain
        The nominal robot with its tool: ``forward_kinematics(q)`` is ``T_base_tool`` (mm).
    sensors : tuple of Sensor
        The laser seam trackers, in the order of the readings.
    compliance_rad_per_nm : float
        Joint compliance model ``Cj(τ) = c τ`` (rad per N·m, diagonal; 0: none), paper eq. (5).
    angle : bool
        The sensors also read the workpiece angle about their laser-plane normal.
    label : str
        The robot's name in messages.
    """

    chain: KinematicChain
    sensors: tuple = ()
    compliance_rad_per_nm: float = 0.0
    angle: bool = False
    label: str = "robot"

    @property
    def n_sensors(self) -> int:
        """Number of laser sensors S."""
        return len(self.sensors)

    @property
    def mounts(self) -> np.ndarray:
        """``T_tool_sensor`` of every sensor, shape (S, 4, 4), mm."""
        if not self.sensors:
            return np.zeros((0, 4, 4))
        return np.stack([np.asarray(s.T_tool_sensor, dtype=np.float64) for s in self.sensors])

    def latencies(self, profile: "Profile") -> np.ndarray:
        """Latency of every sensor, shape (S,), s: the declared one, else the profile's."""
        fitted = profile.sensor_latency_s(self.n_sensors)
        return np.array([fitted[i] if s.latency_s is None else float(s.latency_s)
                         for i, s in enumerate(self.sensors)], dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Profile:
    """The fitted parameters of the filter's densities (see the module docstring).

    Attributes
    ----------
    walk : ndarray, shape (6,)
        Random walk of the pose about its modelled motion, tool frame ``x, y, z`` (mm/√mm), ``rx, ry, rz``
        (rad/√mm): over a step whose program moves the tool ``s`` mm the pose moves by ``N(0, diag(walk² s))``
        (eq. 3: the robot's error changes with its configuration).
    jitter : ndarray, shape (6,)
        White jitter of the pose about that walk, per sample (mm, rad): what no filter can follow; it adds to
        the lasers' noise through each sensor's lever and to the reported spread.
    laser_sigma_mm : ndarray, shape (S,) or (1,)
        Laser noise (std in the laser plane, mm) per sensor; one value for every sensor.
    latency_s : ndarray, shape (S,) or (1,)
        Fitted latency per sensor (s), used where the cell declares none; one value for every sensor.
    angle_sigma_rad : float
        Noise of the angle readings (rad).
    d0_mm, kd_mm_per_n, d0_rad, kd_rad_per_n : float
        Robot plateau radius ``d(f) = d0 + kd ‖f‖`` in translation (mm) and rotation (rad): the largest
        positioning error of the kinematics with the compliance model (eq. 7). The rotation plateau is
        ``d0 + kd ‖f‖`` about axes across the force and ``d0`` about it.
    tail_mm, tail_rad : float
        Std of the Gaussian tails beyond the plateau (added to the joint noise through the Jacobian).
    joint_sigma_rad : float
        Joint encoder noise (std, rad).
    max_force_n : float
        The largest force magnitude the plateau was fitted at (N); beyond it the verdict is ``degraded`` at
        best (0: no limit).
    spread_scale : ndarray, shape (6,)
        Factor per tool axis on the filter's spread (cloud or bound, before the jitter is added): fitted so that
        the particle filter's 2σ covers 95 % of its errors on episodes with a reference (1: none fitted).
    nis_mean, nis_dof : ndarray, shape (S, 2) or (1, 2)
        Per sensor, its x and z reading's mean normalised squared innovation on the training episodes and the
        effective χ² degrees of freedom per reading (:mod:`posekit.seam.engine.integrity`'s long window; 1: as
        the model says, none fitted).
    bias_window : int
        Steps the integrity monitor averages each component's signed innovation over for its bias test (0: no
        bias test).
    bias_mean, bias_dof : ndarray, shape (S, 2) or (1, 2)
        Per sensor, the mean of that average squared on the training episodes and its effective χ² degrees of
        freedom per step (both fitted by ``seam tune`` with ``bias_window``).
    offset_mean, offset_sd, offset_samples : ndarray, shape (6,) or None
        The integrity monitor's offset test: per tool axis (mm, rad) the mean of the estimate's offset from the
        kinematic pose over the long window on the training episodes, the spread of those window means, and the
        effective number of independent windows behind it (``seam tune``; None: no offset test).
    """

    walk: np.ndarray
    jitter: np.ndarray
    laser_sigma_mm: np.ndarray
    latency_s: np.ndarray
    angle_sigma_rad: float
    d0_mm: float
    kd_mm_per_n: float
    d0_rad: float
    kd_rad_per_n: float
    tail_mm: float
    tail_rad: float
    joint_sigma_rad: float
    max_force_n: float
    spread_scale: np.ndarray = field(default_factory=lambda: np.ones(6))
    nis_mean: np.ndarray = field(default_factory=lambda: np.ones((1, 2)))
    nis_dof: np.ndarray = field(default_factory=lambda: np.ones((1, 2)))
    bias_window: int = 0
    bias_mean: np.ndarray = field(default_factory=lambda: np.ones((1, 2)))
    bias_dof: np.ndarray = field(default_factory=lambda: np.ones((1, 2)))
    offset_mean: np.ndarray | None = None
    offset_sd: np.ndarray | None = None
    offset_samples: np.ndarray | None = None

    def _per_sensor(self, values: np.ndarray, n: int, what: str) -> np.ndarray:
        v = np.asarray(values, dtype=np.float64).reshape(-1)
        if v.size == 1:
            return np.full(n, float(v[0]))
        if v.size != n:
            raise ValueError(f"profile: {v.size} {what} values for {n} sensors; expected one per sensor or one for all")
        return v.copy()

    def sensor_sigma_mm(self, n: int) -> np.ndarray:
        """Laser noise of each of ``n`` sensors (mm), shape (n,)."""
        return self._per_sensor(self.laser_sigma_mm, n, "laser sigma")

    def sensor_latency_s(self, n: int) -> np.ndarray:
        """Fitted latency of each of ``n`` sensors (s), shape (n,)."""
        return self._per_sensor(self.latency_s, n, "latency")

    def sensor_nis(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """``nis_mean`` and ``nis_dof`` of ``n`` sensors as ``(2 n,)`` each (sensor k's x at ``2k``, z at ``2k + 1``)."""
        return self._pairs(((self.nis_mean, "innovation mean"), (self.nis_dof, "innovation dof")), n)

    def sensor_bias(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """``bias_mean`` and ``bias_dof`` of ``n`` sensors as ``(2 n,)`` each (as :meth:`sensor_nis`)."""
        return self._pairs(((self.bias_mean, "innovation bias mean"), (self.bias_dof, "innovation bias dof")), n)

    @staticmethod
    def _pairs(items, n: int) -> tuple[np.ndarray, np.ndarray]:
        out = []
        for v, what in items:
            v = np.asarray(v, dtype=np.float64).reshape(-1, 2)
            if len(v) == 1:
                v = np.repeat(v, n, axis=0)
            elif len(v) != n:
                raise ValueError(f"profile: {len(v)} {what} pairs for {n} sensors; expected one per sensor or one for all")
            out.append(v.reshape(-1).copy())
        return out[0], out[1]

"""Real-time pose server: profile frames in over TCP, one pose record per frame out.

The processing unit of the paper's architecture (§II-A, Fig. 1a): the profiler
controller pushes each triggered profile over TCP; the server detects the corners,
solves the pose, optionally asks a controller for a correction, and sends one JSON line
per frame to the robot interface over TCP.

Threads and buffers::

    sensors ──TCP──▶ receiver ──▶ one deque(maxlen=queue_size) ──▶ worker ──TCP──▶ robot
                     (hello, decode,   per sensor, drop-oldest,      (the queues in turn)
                      rate limit,      never blocks                  CD → PC → controller → send
                      timeouts)

- The **receiver** serves every sensor connection at once from one thread (non-blocking
  sockets, :mod:`selectors`) and decodes frames
  (:class:`~posekit.profiler.stream.protocol.FrameDecoder`), so one stalled client never blocks
  another. Each connection has a read timeout (a frame, or the hello, once begun must be
  complete within ``read_timeout_s``) and an idle timeout (no complete frame for
  ``idle_timeout_s``); a connection that exceeds one is closed and logged. With a
  ``token``, a client must first send a hello carrying it
  (:func:`~posekit.profiler.stream.protocol.encode_hello`), compared in constant time; a wrong
  or missing one closes the connection. A connection counts as a sensor only once it has
  proved itself (the hello with the token; without a token, a well-formed hello or frame) within
  ``hello_timeout_s``: until then it is *pending*, has a limit of its own (``max_pending``)
  and never displaces a sensor; an active sensor is closed for a newcomer only when it has
  sent nothing for ``hello_timeout_s`` (see :mod:`~posekit.profiler.stream.server_receiver`).
  Each sensor may send ``max_rate_hz`` frames per second; beyond it the receiver stops
  reading it for a while (TCP slows it down). The receiver never waits for the worker: each
  sensor has its own buffer of ``queue_size`` frames, and when it is full that sensor's
  *oldest* frame is dropped (and counted), so the pose that goes out is always from the
  newest profile and the sensor is never blocked; the worker takes the sensors' buffers in
  turn, so a flooding sensor delays another by at most one of its own frames. After a
  disconnect (also mid-frame) it logs it and discards the partial frame.
- The **worker** takes one frame at a time: corners, pose and verdict
  (:func:`~posekit.profiler.estimate.fast.estimate_profile_unchecked`, the estimator's own
  path, so the pose, its covariance, χ² and status are those of the offline
  :func:`~posekit.profiler.estimate.pipeline.estimate_pose`; warm-started from the previous
  pose and falling back to the closed form when that fails or lands in a poor minimum),
  the NaN-storm check, the controller, and the record to the robot. A bad profile becomes
  a record with ``status: "error"``, never an exception.

Timing of each processed frame, ms, on the clock of :func:`time.perf_counter_ns` (on
Linux ``CLOCK_MONOTONIC``, system-wide; a sensor process on the same machine stamps its
frames with it, so DT is meaningful): **DT** = receive time of the frame's last byte −
sensor stamp (the paper's data transmission, Table III); **CD** = corner detection; **PC** =
pose computation, covariance, verdict, NaN-storm check and the controller. ``QW``, the
time a frame waited in the buffer, is kept as well (it grows when the worker falls
behind). The sensor stamp is not trusted: DT is only computed when the stamp lies within
``max_dt_s`` before the receive time and not before the connection's previous believed
stamp; otherwise DT is unknown (null in the record, NaN in :meth:`PoseServer.timings`)
and the frame is counted in ``bad_stamps`` (it is still processed).

Record sent to the robot (one JSON line per processed frame, and for a NaN storm)::

    {"seq", "t_sensor_ns", "status": "ok"|"suspect"|"error", "t_mm": [3], "q_wxyz": [4],
     "std_t_um": [3], "std_rot_deg": [3], "reprojection_um", "reversed",
     "chi2", "dof", "reason": str|null,
     "command": <controller dict or null>, "filter": <filtered pose or null>,
     "timing_ms": {"DT" (null: stamp not trusted), "QW", "CD", "PC"}, "error": str|null}

``status`` is the verdict of DESIGN.md "Trust", as in the offline records: ``ok`` when the
corners fit the gauge within the assumed ``noise`` and the gauge's tolerance (χ² test of
the fit, ``chi2`` against χ²(``dof`` = 2n - 6), and the noise test), ``suspect`` when a pose
exists but a test failed (``reason`` says why: wrong gauge file, a face off its drawing, a
noisier profile than the sensor model, an impossible pose, an ambiguous mounting) and
``error`` when there is no pose (``error`` says why). Pose fields, ``chi2``, ``dof`` and
``reason`` are null when the profile failed; the standard deviations are null when the
covariance is not finite (for the closed form, ``method="cf"``, they come from its own
linearisation, far larger than the refinement's). A suspect pose is still sent, filtered and
given to the controller: the robot side decides what to do with it. ``filter`` is the output of the
``pose_filter`` (:meth:`~posekit.profiler.stream.pose_filter.FilteredPose.to_record`: the filtered
pose with its 6×6 covariance), null without one or when the profile failed. The same
records go to the ``record_sink`` (files, stdout), from a thread of its own.

Frames can also come from the same process: :meth:`PoseServer.submit` queues a profile (from
any :class:`~posekit.profiler.stream.sources.ProfileSource`, e.g. a vendor SDK) as if it had
arrived over TCP.
"""

import gc
import logging
import threading
import time
from collections import Counter, deque

import numpy as np

from ...errors import ConfigError, ProfileError
from ...geometry import quaternion_from_matrix
from ..estimate.consistency import DEFAULT_SIGNIFICANCE
from ..estimate.corner_params import CornerParams
from ..estimate.corners import gauge_turns
from ..estimate.fast import warm_gate
from ..estimate.pipeline import DEFAULT_NOISE
from ..estimate.solve import METHODS
from ..gauge.model import MOUNTINGS, Gauge
from .protocol import MAX_POINTS, Frame
from .server_options import check_options
from .server_receiver import SensorReceiver
from .server_stats import TIMING_KEYS, ServerStats
from .server_support import Counts, LogLimiter, check_address, listen_socket, token_digest
from .server_worker import PoseWorker

__all__ = ["PoseServer"]


class PoseServer(SensorReceiver, PoseWorker, ServerStats):
    """Streams profile frames in, sends one pose record per frame to the robot.

    Parameters
    ----------
    gauge : Gauge
        The gauge in view.
    listen : (str, int)
        Address to accept the sensor on; port 0 picks a free port (see :meth:`start`).
    robot : (str, int), optional
        Robot interface to send the JSON records to (a TCP server); None: no sending.
    controller : callable, optional
        ``controller(seq, t_s, T_G_F, cov) -> dict | None`` called for each good pose:
        ``t_s`` the sensor stamp in s, ``T_G_F`` (4, 4) mm, ``cov`` (6, 6) the pose
        covariance ``[mm, rad]`` in G (NaN for the closed form). Its dict goes out as the
        record's ``command``; an exception makes the record an error. It gets the pose of
        this profile, not the filtered one (e.g.
        :class:`~posekit.profiler.loop.control.TargetCompensator`).
    pose_filter : object, optional
        ``pose_filter.update(t_s, T_G_F, cov) -> FilteredPose`` called for each good pose
        (:class:`~posekit.profiler.stream.pose_filter.ConstantVelocityFilter` or
        :class:`~posekit.profiler.stream.pose_filter.WindowFusion`); its output is the record's
        ``filter``. Needs ``method='mle'`` (the closed form has no covariance).
    record_sink : object, optional
        ``record_sink.put(record)`` gets every record (e.g.
        :class:`~posekit.profiler.stream.server_records.RecordSink`); it must not block.
    queue_size : int
        Frames buffered per sensor between receiver and worker; when full that sensor's
        oldest is dropped.
    method : {'mle', 'cf'}
    mounting : {'auto', 'normal', 'reversed'}
    log : logging.Logger, optional
        Default ``logging.getLogger("posekit.server")``. Rejections, disconnects and
        failed profiles are logged at most once per second per kind, with a count of
        the ones held back.
    allow_remote : bool
        Accept a non-loopback ``listen`` or ``robot`` address; needs a ``token``.
    token : str or bytes, optional
        Shared secret every sensor must present first (see
        :func:`~posekit.profiler.stream.protocol.encode_hello`); required with ``allow_remote``.
        1 to ``MAX_TOKEN_BYTES`` bytes; :func:`~posekit.profiler.stream.server_support.read_token_file` reads one
        from a file.
    idle_timeout_s : float
        A connection that delivers no complete frame for this long is closed, s.
    read_timeout_s : float
        A frame (or the hello) whose first byte arrived must be complete within this, s.
    max_dt_s : float
        A sensor stamp older than this at receipt (or in the future, or earlier than the
        previous one) is not believed: DT unknown, counted in ``bad_stamps``.
    max_connections : int
        Sensors served at once (connections that proved themselves: the token, or a frame).
        A sensor beyond it is refused, unless one of them has sent nothing for
        ``hello_timeout_s``: that one is closed for it.
    max_pending : int
        Connections that have not proved themselves yet; a new one beyond it closes the
        oldest of them (never a sensor).
    hello_timeout_s : float
        A connection must prove itself (the hello with the token; without a token, a
        well-formed hello or frame) within this of connecting, s.
    max_rate_hz : float
        Frames per second one sensor may send (bursts of ``rate_burst``); beyond it the
        server reads it more slowly.
    rate_burst : int
        Frames a sensor may send at once above its rate.
    max_accept_hz : float
        New connections accepted per second (bursts of 64); more wait in the kernel's backlog,
        so a storm of connections cannot take the receiver's time from the sensors.
    params : CornerParams
    noise : NoiseModel or None
        The sensor noise the verdict assumes (default the LJ-X8400's 10/5 µm, as
        :func:`~posekit.profiler.estimate.pipeline.estimate_pose`); None: the line fits' own
        residuals (no noise test).
    significance : float
        α of the consistency test (:data:`~posekit.profiler.estimate.solve.DEFAULT_SIGNIFICANCE`).
    nan_storm_fraction : float
        A frame with more than this fraction of NaN points (or no points) is rejected
        as ``nan_storm``.
    history : int
        Timings kept for :meth:`timings` (the most recent ones).
    freeze_gc : bool
        :meth:`start` calls :func:`gc.freeze` after the warm-up, so that Python's full
        garbage collections no longer scan the ~10⁵ objects of NumPy, SciPy and numba: a
        full collection otherwise stops every thread for 50–150 ms on a 2-core machine,
        which at 1 kHz drops frames. Process-wide; objects alive at that moment are never
        collected afterwards.

    Examples
    --------
    >>> from posekit.profiler import bundled_gauge
    >>> with PoseServer(bundled_gauge("demo-5")) as server:   # doctest: +SKIP
    ...     host, port = server.address                        # stream frames to it
    """

    def __init__(self, gauge: Gauge, *, listen=("127.0.0.1", 0), robot=None, controller=None,
                 queue_size: int = 4, method: str = "mle", mounting: str = "auto",
                 log: logging.Logger | None = None, allow_remote: bool = False,
                 params: CornerParams = CornerParams(), nan_storm_fraction: float = 0.95,
                 history: int = 100_000, freeze_gc: bool = True, token: str | bytes | None = None,
                 idle_timeout_s: float = 30.0, read_timeout_s: float = 2.0, max_dt_s: float = 10.0,
                 max_connections: int = 16, pose_filter=None, record_sink=None, noise=DEFAULT_NOISE,
                 significance: float = DEFAULT_SIGNIFICANCE, max_pending: int = 64, hello_timeout_s: float = 2.0,
                 max_rate_hz: float = 4000.0, rate_burst: int = 64, max_accept_hz: float = 100.0):
        check_options(gauge, method=method, mounting=mounting, significance=significance, noise=noise,
                      queue_size=queue_size, history=history, nan_storm_fraction=nan_storm_fraction,
                      controller=controller, pose_filter=pose_filter, record_sink=record_sink,
                      idle_timeout_s=idle_timeout_s, read_timeout_s=read_timeout_s, max_dt_s=max_dt_s,
                      hello_timeout_s=hello_timeout_s, max_connections=max_connections, max_pending=max_pending,
                      rate_burst=rate_burst, max_rate_hz=max_rate_hz, max_accept_hz=max_accept_hz,
                      allow_remote=allow_remote, token=token)
        self._digest = None if token is None else token_digest(token)
        self.gauge = gauge
        self.method = method
        self.mounting = mounting
        self.params = params
        self.noise = noise
        self.significance = float(significance)
        self._turns = gauge_turns(gauge)  # the model-based corner detector's view of the section
        self.controller = controller
        self.pose_filter = pose_filter
        self.record_sink = record_sink
        self.queue_size = queue_size
        self.nan_storm_fraction = float(nan_storm_fraction)
        self.allow_remote = bool(allow_remote)
        self.freeze_gc = bool(freeze_gc)
        self.idle_timeout_s = float(idle_timeout_s)
        self.read_timeout_s = float(read_timeout_s)
        self.max_dt_s = float(max_dt_s)
        self.max_connections = max_connections
        self.max_pending = max_pending
        self.hello_timeout_s = float(hello_timeout_s)
        self.max_rate_hz = float(max_rate_hz)
        self.rate_burst = int(rate_burst)
        self.max_accept_hz = float(max_accept_hz)
        self._listen_family, self._listen_addr = check_address(listen, "listen address", self.allow_remote)
        self._robot = None if robot is None else check_address(robot, "robot address", self.allow_remote)
        self.log = log if log is not None else logging.getLogger("posekit.server")
        self._limiter = LogLimiter(self.log)

        self._method_code = METHODS.index(method)
        self._mounting_code = MOUNTINGS.index(mounting)
        # A warm start whose χ² (2n - 6 dof) exceeds its 1e-6 tail went to a wrong minimum.
        self._chi2_gate = warm_gate(gauge.n_corners)

        self._queues: dict = {}            # sensor key -> deque(maxlen=queue_size) of (Frame, dt_ns)
        self._ready: deque = deque()       # keys with queued frames, in the worker's turn
        self._cond = threading.Condition(threading.Lock())
        self._stats_lock = threading.Lock()
        self._counts = Counts()
        self._reasons: Counter = Counter()
        self._tim = np.zeros((history, len(TIMING_KEYS)))
        self._tim_n = 0
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._lsock = None
        self._n_conns = 0
        self._address = None
        self._last_T = None
        self._last_rev = False
        self._n_suspect = 0
        self._submit_lock = threading.Lock()
        self._submit_seq = 0
        self._submit_last_ns = None

    # ------------------------------------------------------------------ lifecycle

    @property
    def address(self) -> tuple[str, int] | None:
        """Bound ``(host, port)`` once started, else None."""
        return self._address

    def start(self) -> tuple[str, int]:
        """Bind, listen and start the receiver and worker threads.

        Returns
        -------
        (host, port)
            The bound address (the actual port when ``listen`` asked for port 0).

        Raises
        ------
        ConfigError
            If the address cannot be bound, or the server was already started.
        """
        if self._threads:
            raise ConfigError("PoseServer.start: the server is already running (one start per server)")
        self._warm_up()
        if self.freeze_gc:
            gc.freeze()
        sock = listen_socket(self._listen_family, self._listen_addr)
        self._lsock = sock
        self._address = sock.getsockname()[:2]
        self._stop.clear()
        self._threads = [
            threading.Thread(target=self._receive_loop, name="posekit-receiver", daemon=True),
            threading.Thread(target=self._work_loop, name="posekit-worker", daemon=True),
        ]
        for t in self._threads:
            t.start()
        self.log.info("listening for sensors on %s:%d (%s)", *self._address,
                      "token required" if self._digest is not None else "no token")
        return self._address

    def _warm_up(self) -> None:
        """Run the pipeline once on a simulated profile: load the compiled kernels now,
        not on the first real frame (that costs 0.1-1 s and would drop frames)."""
        from ..sensor import NoiseModel
        from ..sim.poses import nominal_pose
        from ..sim.render import render_profiles

        prof = render_profiles(self.gauge, nominal_pose(self.gauge), NoiseModel(), rng=0)
        last = None
        for _ in range(2):                      # cold, then warm from the first pose
            res = self._estimate(np.ascontiguousarray(prof), last)
            if res.T_G_F is None:               # the nominal pose always sees the gauge; be safe anyway
                return
            quaternion_from_matrix(res.T_G_F[:3, :3], check=False)
            last = (res.T_G_F, res.reversed)

    def stop(self, timeout_s: float = 1.0) -> None:
        """Stop both threads, close every socket; returns within about ``timeout_s``.

        Frames still buffered are discarded. Held-back log lines are flushed.
        """
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        deadline = time.monotonic() + timeout_s
        for t in self._threads:
            t.join(max(0.0, deadline - time.monotonic()))
        if self._lsock is not None:
            self._lsock.close()
            self._lsock = None
        self._limiter.flush()

    @property
    def running(self) -> bool:
        """True while the receiver and worker threads are alive."""
        return bool(self._threads) and all(t.is_alive() for t in self._threads) and not self._stop.is_set()

    def __enter__(self):
        if not self._threads:
            self.start()
        return self

    def __exit__(self, *exc):
        self.stop()

    # ------------------------------------------------------------------ frames from this process

    def submit(self, points_xz, t_sensor_ns: int | None = None) -> int:
        """Queue one profile from this process (e.g. a vendor SDK), as if it had arrived over TCP.

        It takes the same path as a received frame: the buffer (drop-oldest), the worker,
        the record to the robot and the sink. Thread-safe.

        Parameters
        ----------
        points_xz : array_like, shape (N, 2)
            Points (x, z) in F, mm, scan order; NaN = no return; ``N <= MAX_POINTS``.
        t_sensor_ns : int, optional
            The profile's stamp on the clock of :func:`time.perf_counter_ns`; default now
            (DT 0). A stamp that cannot be believed (see ``max_dt_s``) leaves DT unknown.

        Returns
        -------
        int
            The frame's ``seq``: 0, 1, 2, ... over the submitted frames (mod 2³²).

        Raises
        ------
        ConfigError
            If the server is not running.
        ProfileError
            If the points are not an (N, 2) numeric array of at most ``MAX_POINTS`` rows.

        Examples
        --------
        >>> from posekit.profiler import bundled_gauge, nominal_pose, render_profiles
        >>> g = bundled_gauge("demo-5")
        >>> with PoseServer(g, freeze_gc=False) as server:                 # doctest: +SKIP
        ...     seq = server.submit(render_profiles(g, nominal_pose(g), rng=0))
        """
        if not self.running:
            raise ConfigError("PoseServer.submit: the server is not running (call start() first)")
        try:
            pts = np.array(points_xz, dtype=np.float64, order="C")
        except (TypeError, ValueError):
            raise ProfileError("PoseServer.submit: expected an (N, 2) array of (x, z) in mm, got non-numeric data") \
                from None
        if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] > MAX_POINTS:
            raise ProfileError(f"PoseServer.submit: expected an (N, 2) array of (x, z) in mm with N <= {MAX_POINTS}, "
                               f"got shape {pts.shape}")
        now = time.perf_counter_ns()
        stamp = now if t_sensor_ns is None else int(t_sensor_ns)
        with self._submit_lock:
            seq = self._submit_seq
            self._submit_seq = (seq + 1) % 2**32
            dt_ns = now - stamp
            if 0 <= dt_ns <= self.max_dt_s * 1e9 and (self._submit_last_ns is None or stamp >= self._submit_last_ns):
                self._submit_last_ns = stamp
            else:
                dt_ns = None
        if dt_ns is None:
            with self._stats_lock:
                self._counts.bad_stamps += 1
        self._enqueue(Frame(seq, stamp, pts, now), dt_ns)
        return seq

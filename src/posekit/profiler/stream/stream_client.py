"""Both ends around a :class:`~posekit.profiler.stream.server.PoseServer`: a sensor and a robot stub.

:class:`SensorClient` plays the profiler controller: it connects to the server and sends
frames (:func:`~posekit.profiler.stream.protocol.encode_frame`), one at a time or paced at a
fixed rate by :meth:`SensorClient.stream`, or as they come from any
:class:`~posekit.profiler.stream.sources.ProfileSource` (a vendor SDK, a file, the simulator) by
:meth:`SensorClient.send_source`. :class:`RobotInterfaceStub` plays the robot
interface: a TCP server that accepts the pose server's connection and stores the JSON
records it receives. Both are for simulations and tests.
"""

import select
import socket
import threading
import time
from dataclasses import dataclass

import numpy as np

from ...errors import ConfigError
from .lines import LineDecoder
from .protocol import encode_frame, encode_hello

__all__ = ["SensorClient", "StreamReport", "RobotInterfaceStub"]

_POLL_S = 0.05


@dataclass(frozen=True)
class StreamReport:
    """Outcome of :meth:`SensorClient.stream`.

    Attributes
    ----------
    sent : int
        Frames sent.
    elapsed_s : float
        From the first scheduled send to the last actual send, s.
    rate_hz : float
        Achieved rate, ``(sent - 1) / elapsed_s``.
    late_ms : ndarray, shape (sent,)
        How late each send started against its schedule, ms (>= 0).
    """

    sent: int
    elapsed_s: float
    rate_hz: float
    late_ms: np.ndarray


class SensorClient:
    """A TCP client that sends profile frames, as a profiler controller would.

    Parameters
    ----------
    host, port
        The :class:`~posekit.profiler.stream.server.PoseServer` address.
    timeout_s : float
        Connect timeout, and the longest a send may block, s.
    token : str or bytes, optional
        The server's shared secret (``--token-file``), sent first in a hello
        (:func:`~posekit.profiler.stream.protocol.encode_hello`); a server without a token skips it.

    Raises
    ------
    ConfigError
        If the server cannot be reached, or the token is empty or too long.
    """

    def __init__(self, host: str, port: int, timeout_s: float = 5.0, token: str | bytes | None = None):
        hello = None if token is None else encode_hello(token)
        try:
            self._sock = socket.create_connection((host, int(port)), timeout=timeout_s)
        except OSError as exc:
            raise ConfigError(f"sensor client: cannot connect to {host}:{port} ({exc.strerror or exc})") from None
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.address = (host, int(port))
        if hello is not None:
            try:
                self._sock.sendall(hello)
            except OSError as exc:
                self._sock.close()
                raise ConfigError(f"sensor client: {host}:{port} closed the connection before the hello "
                                  f"({exc.strerror or exc})") from None

    def send_profile(self, seq: int, points_xz, t_sensor_ns: int | None = None) -> int:
        """Send one profile frame.

        Parameters
        ----------
        seq : int
            Sequence number, ``0 <= seq < 2**32``.
        points_xz : array_like, shape (N, 2)
            Points (x, z) in F, mm, scan order; NaN = no return.
        t_sensor_ns : int, optional
            Stamp; default :func:`time.perf_counter_ns` now (the server's clock).

        Returns
        -------
        int
            The stamp sent, ns.
        """
        if t_sensor_ns is None:
            t_sensor_ns = time.perf_counter_ns()
        self._sock.sendall(encode_frame(seq, t_sensor_ns, points_xz))
        return t_sensor_ns

    def send_bytes(self, data: bytes) -> None:
        """Send raw bytes (for tests of malformed frames)."""
        self._sock.sendall(data)

    def stream(self, profiles, rate_hz: float, *, count: int | None = None, duration_s: float | None = None,
               first_seq: int = 0) -> StreamReport:
        """Send profiles at a fixed rate, cycling through them.

        Frame k is due at ``t0 + k / rate_hz`` on :func:`time.perf_counter` (an absolute
        schedule: a late frame does not delay the ones after it; frames that fell behind
        are sent at once, as a sensor's buffered frames would be). Each frame carries
        ``seq = first_seq + k`` (mod 2³²) and is stamped when it is sent. For steady
        pacing, call :func:`gc.freeze` in the sending process once its imports are done: a
        full garbage collection over NumPy/SciPy/numba objects stalls it for 10-70 ms.

        Parameters
        ----------
        profiles : array_like, shape (K, N, 2)
            Profiles to cycle through, mm.
        rate_hz : float
        count : int, optional
            Frames to send; or
        duration_s : float, optional
            Send for this long (``round(duration_s * rate_hz)`` frames).

        Returns
        -------
        StreamReport
        """
        profiles = np.asarray(profiles, dtype=np.float32)
        if profiles.ndim != 3 or profiles.shape[2] != 2 or profiles.shape[0] == 0:
            raise ConfigError(f"stream: profiles must have shape (K, N, 2) with K >= 1, got {profiles.shape}")
        if not rate_hz > 0:
            raise ConfigError(f"stream: rate_hz must be > 0, got {rate_hz}")
        if (count is None) == (duration_s is None):
            raise ConfigError("stream: give exactly one of count and duration_s")
        total = int(count) if count is not None else round(duration_s * rate_hz)
        period = 1.0 / rate_hz
        late = np.zeros(total)
        t0 = time.perf_counter()
        t_last = t0
        for k in range(total):
            due = t0 + k * period
            now = time.perf_counter()
            if now < due:
                time.sleep(due - now)
                now = time.perf_counter()
            late[k] = (now - due) * 1e3
            self.send_profile((first_seq + k) % 2**32, profiles[k % len(profiles)])
            t_last = now
        elapsed = t_last - t0
        rate = (total - 1) / elapsed if total > 1 and elapsed > 0 else float("nan")
        return StreamReport(sent=total, elapsed_s=elapsed, rate_hz=rate, late_ms=late)

    def send_source(self, source, *, count: int | None = None, first_seq: int = 0) -> int:
        """Send the profiles of a source as they come (no pacing: the source sets the pace).

        Parameters
        ----------
        source : ProfileSource
            Yields ``(t_s, points (N, 2) mm)``; each frame is stamped when it is sent (the
            server's clock on this machine), its ``t_s`` is not sent.
        count : int, optional
            Stop after this many frames; default: until the source ends.
        first_seq : int

        Returns
        -------
        int
            Frames sent.
        """
        sent = 0
        for _, points in source:
            if count is not None and sent >= count:
                break
            self.send_profile((first_seq + sent) % 2**32, points)
            sent += 1
        return sent

    def peer_closed(self, wait_s: float = 0.0) -> bool:
        """True if the server has closed the connection (it answers nothing otherwise).

        A server that refuses the hello (wrong token) closes the connection, but sends
        that are already under way may still succeed: call this after the last frame.

        Parameters
        ----------
        wait_s : float
            How long to wait for the close, s.
        """
        try:
            readable, _, _ = select.select([self._sock], [], [], max(0.0, wait_s))
            if readable:
                return self._sock.recv(1, socket.MSG_PEEK) == b""
        except OSError:
            return True
        return False

    def close(self) -> None:
        """Close the connection (the server sees a disconnect)."""
        try:
            self._sock.close()
        except OSError:
            pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class RobotInterfaceStub:
    """A loopback TCP server that stores the JSON records a pose server sends.

    One connection at a time (the pose server's); when it drops, the next is accepted.

    Parameters
    ----------
    host : str
    port : int
        0 picks a free port; :meth:`start` returns the bound address.

    Attributes
    ----------
    connections : int
        Connections accepted so far.
    decoder : LineDecoder
        Counts malformed lines in ``decoder.errors``.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 0):
        self._bind = (host, int(port))
        self._records: list[dict] = []
        self._lock = threading.Lock()
        self._cond = threading.Condition(self._lock)
        self._stop = threading.Event()
        self._thread = None
        self._lsock = None
        self._conn = None
        self.connections = 0
        self.decoder = LineDecoder()
        self.address = None

    def start(self) -> tuple[str, int]:
        """Bind, listen and start the reading thread; returns ``(host, port)``."""
        family = socket.AF_INET6 if ":" in self._bind[0] else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind(self._bind)
            sock.listen(64)
        except OSError as exc:
            sock.close()
            raise ConfigError(f"robot stub: cannot bind {self._bind[0]}:{self._bind[1]} "
                              f"({exc.strerror or exc})") from None
        sock.settimeout(_POLL_S)
        self._lsock = sock
        self.address = sock.getsockname()[:2]
        self._thread = threading.Thread(target=self._run, name="posekit-robot-stub", daemon=True)
        self._thread.start()
        return self.address

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._lsock.accept()
            except TimeoutError:
                continue
            except OSError:
                break
            conn.settimeout(_POLL_S)
            self._conn = conn
            self.connections += 1
            self.decoder = LineDecoder()
            try:
                while not self._stop.is_set():
                    try:
                        data = conn.recv(1 << 16)
                    except TimeoutError:
                        continue
                    except OSError:
                        break
                    if not data:
                        break
                    recs = self.decoder.feed(data)
                    if recs:
                        with self._cond:
                            self._records.extend(recs)
                            self._cond.notify_all()
            finally:
                self._conn = None
                conn.close()

    @property
    def connected(self) -> bool:
        """True while a pose server is connected."""
        return self._conn is not None

    @property
    def records(self) -> list[dict]:
        """A copy of the records received so far, in arrival order."""
        with self._lock:
            return list(self._records)

    def wait_for(self, count: int, timeout_s: float = 5.0) -> bool:
        """Wait until at least ``count`` records arrived; False on timeout."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while len(self._records) < count:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
        return True

    def drop_connection(self) -> None:
        """Close the current connection (to test the pose server's reconnection)."""
        conn = self._conn
        if conn is not None:
            try:
                conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def stop(self) -> None:
        """Stop the thread and close the sockets (within about a second)."""
        self._stop.set()
        self.drop_connection()
        if self._thread is not None:
            self._thread.join(1.0)
        if self._lsock is not None:
            self._lsock.close()
            self._lsock = None

    def __enter__(self):
        if self._thread is None:
            self.start()
        return self

    def __exit__(self, *exc):
        self.stop()

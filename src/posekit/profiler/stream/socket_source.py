"""The receiving end of the PKPF stream as a profile source (no pose server attached).

:class:`SocketSource` is the :class:`~posekit.profiler.stream.sources.ProfileSource` of the binary
stream of :mod:`~posekit.profiler.stream.protocol`: it accepts sensors with the rules of
:class:`~posekit.profiler.stream.server.PoseServer` (loopback unless ``allow_remote`` with a token,
read and idle timeouts, resynchronisation) and yields their profiles to whoever iterates.
"""

import logging
import selectors
import time
from collections.abc import Iterator

import numpy as np

from ...errors import ConfigError
from .protocol import MAX_FRAME_BYTES, Frame
from .server_support import LogLimiter, SensorConnection, check_address, listen_socket, token_digest

__all__ = ["SocketSource"]

_POLL_S = 0.05


class SocketSource:
    """The receiving end of the PKPF stream as a profile source (no pose server attached).

    Accepts sensors on ``listen`` (loopback unless ``allow_remote``, which needs a
    ``token``), decodes their frames (:mod:`~posekit.profiler.stream.protocol`) with the server's
    rules — hello and token, read and idle timeouts, resynchronisation after malformed bytes —
    and yields ``(t_sensor_ns * 1e-9, points)`` of every frame, in arrival order, from the
    thread that iterates. :meth:`frames` yields the :class:`~posekit.profiler.stream.protocol.Frame`
    objects themselves (with ``seq``).

    Parameters
    ----------
    listen : (str, int)
        Port 0 picks a free one; :meth:`start` returns the bound address.
    token : str or bytes, optional
    allow_remote : bool
    idle_timeout_s, read_timeout_s : float
        As :class:`~posekit.profiler.stream.server.PoseServer`.
    max_connections : int
    end_when_idle_s : float, optional
        Iteration ends when no frame has arrived for this long (s); None: only :meth:`close` ends it.

    Attributes
    ----------
    counts : dict
        ``frames``, ``rejected`` (malformed stretches), ``refused`` (bad hello), ``timeouts``,
        ``connections``.
    """

    def __init__(self, listen=("127.0.0.1", 0), *, token: str | bytes | None = None, allow_remote: bool = False,
                 idle_timeout_s: float = 30.0, read_timeout_s: float = 2.0, max_connections: int = 16,
                 end_when_idle_s: float | None = None, log: logging.Logger | None = None):
        if allow_remote and token is None:
            raise ConfigError("SocketSource: allow_remote=True needs a token that every sensor must present")
        self._family, self._addr = check_address(listen, "listen address", allow_remote)
        self._digest = None if token is None else token_digest(token)
        self.idle_ns = int(idle_timeout_s * 1e9)
        self.read_ns = int(read_timeout_s * 1e9)
        self.max_connections = int(max_connections)
        self.end_when_idle_s = end_when_idle_s
        self.log = log if log is not None else logging.getLogger("posekit.sources")
        self._limiter = LogLimiter(self.log)
        self._lsock = None
        self._closed = False
        self.address = None
        self.counts = {"frames": 0, "rejected": 0, "refused": 0, "timeouts": 0, "connections": 0}

    def start(self) -> tuple[str, int]:
        """Bind and listen; returns ``(host, port)``."""
        if self._lsock is None:
            sock = listen_socket(self._family, self._addr)
            self._lsock = sock
            self.address = sock.getsockname()[:2]
        return self.address

    def close(self) -> None:
        """End the iteration (within ~50 ms, from any thread) and close the sockets."""
        self._closed = True

    def __iter__(self) -> Iterator[tuple[float, np.ndarray]]:
        for f in self.frames():
            yield f.t_sensor_ns * 1e-9, f.points

    def frames(self) -> Iterator[Frame]:
        """Every decoded frame, in arrival order."""
        self.start()
        sel = selectors.DefaultSelector()
        sel.register(self._lsock, selectors.EVENT_READ, None)
        conns: dict = {}
        view = memoryview(bytearray(4 * MAX_FRAME_BYTES))
        t_last = time.monotonic()
        try:
            while not self._closed:
                for key, _ in sel.select(_POLL_S):
                    c = key.data
                    if c is None:
                        self._accept(sel, conns)
                        continue
                    if c.sock not in conns:
                        continue
                    for item in self._read(c, view, sel, conns):
                        t_last = time.monotonic()
                        yield item
                now = time.perf_counter_ns()
                for c in list(conns.values()):
                    why = c.expired(now, self.idle_ns, self.read_ns)
                    if why is not None:
                        self.counts["timeouts"] += 1
                        self._drop(c, sel, conns, why)
                if self.end_when_idle_s is not None and time.monotonic() - t_last > self.end_when_idle_s:
                    break
        finally:
            for c in list(conns.values()):
                c.close()
            sel.close()
            self._lsock.close()
            self._lsock = None
            self._limiter.flush()

    def _accept(self, sel, conns: dict) -> None:
        try:
            sock, addr = self._lsock.accept()
        except OSError:
            return
        if len(conns) >= self.max_connections:
            oldest = min(conns.values(), key=lambda c: c.t_progress_ns)
            self._drop(oldest, sel, conns, "evicted to make room for a new sensor")
        sock.setblocking(False)
        c = SensorConnection(sock, f"{addr[0]}:{addr[1]}", time.perf_counter_ns(), self._digest)
        conns[sock] = c
        sel.register(sock, selectors.EVENT_READ, c)
        self.counts["connections"] += 1

    def _read(self, c: SensorConnection, view, sel, conns: dict) -> list:
        try:
            n = c.sock.recv_into(view)
        except (BlockingIOError, InterruptedError):
            return []
        except OSError as exc:
            self._drop(c, sel, conns, f"connection error ({exc})")
            return []
        if n == 0:
            self._drop(c, sel, conns, "closed by the sensor")
            return []
        items, refused = c.feed(view[:n], time.perf_counter_ns())
        if refused is not None:
            self.counts["refused"] += 1
            self._drop(c, sel, conns, f"refused: {refused}")
            return []
        frames = [f for f in items if isinstance(f, Frame)]
        for err in items:
            if not isinstance(err, Frame):
                self.counts["rejected"] += 1
                self._limiter.event(err.reason, logging.WARNING, f"sensor {c.peer}: rejected ({err.reason}): "
                                    f"{err.detail}")
        self.counts["frames"] += len(frames)
        return frames

    def _drop(self, c: SensorConnection, sel, conns: dict, why: str) -> None:
        partial = c.detach(sel, conns)
        if partial is not None:
            self.counts["rejected"] += 1
            why += f", mid-frame: {partial.detail}"
        self._limiter.event("disconnect", logging.INFO, f"sensor {c.peer} disconnected ({why})")

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.close()
        if self._lsock is not None:          # never iterated
            self._lsock.close()
            self._lsock = None

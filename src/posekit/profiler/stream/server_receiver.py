"""The receiving half of :class:`~posekit.profiler.stream.server.PoseServer`: every sensor
connection served from one thread (non-blocking sockets, :mod:`selectors`), frames decoded,
timed out, authenticated and queued (drop-oldest) for the worker.

:class:`SensorReceiver` is a mixin: it holds no state of its own and uses the server's
(``_lsock``, ``_stop``, ``_cond``, ``_queue``, ``_counts``, ``_stats_lock``, ``_limiter``,
``_reasons``, ``_digest``, the timeouts and limits); the behaviour is documented on
:mod:`~posekit.profiler.stream.server`.
"""

import logging
import selectors
import socket
import time

from .protocol import MAX_FRAME_BYTES, Frame
from .server_support import SensorConnection

__all__ = ["SensorReceiver"]

_POLL_S = 0.05                 # how often blocked threads look at the stop flag


class SensorReceiver:
    """The receiver thread's methods of :class:`~posekit.profiler.stream.server.PoseServer`."""

    def _reject(self, reason: str, detail: str) -> None:
        with self._stats_lock:
            self._counts.rejected += 1
            self._reasons[reason] += 1
        self._limiter.event(reason, logging.WARNING, f"rejected frame ({reason}): {detail}")

    def _receive_loop(self) -> None:
        buf = bytearray(4 * MAX_FRAME_BYTES)
        view = memoryview(buf)
        sel = selectors.DefaultSelector()
        sel.register(self._lsock, selectors.EVENT_READ, None)
        conns: dict = {}
        idle_ns = int(self.idle_timeout_s * 1e9)
        read_ns = int(self.read_timeout_s * 1e9)
        next_check = 0
        try:
            while not self._stop.is_set():
                try:
                    events = sel.select(_POLL_S)
                except OSError:                     # e.g. EINTR storms; look at the stop flag
                    events = []
                for key, _ in events:
                    c = key.data
                    if c is None:
                        self._accept(sel, conns)
                    elif c.sock in conns:           # not closed earlier in this round
                        try:
                            self._read(c, view, sel, conns)
                        except Exception as exc:    # a bug, never bad input (the decoders take any bytes)
                            self.log.exception("receiver: internal error, dropping the connection")
                            self._close(c, sel, conns, f"internal error ({type(exc).__name__}: {exc})")
                now = time.perf_counter_ns()
                if now >= next_check:               # deadlines: ~20 times a second is enough
                    next_check = now + 50_000_000
                    expired = [(c, c.expired(now, idle_ns, read_ns)) for c in conns.values()]
                    for c, why in expired:
                        if why is not None:
                            with self._stats_lock:
                                self._counts.timeouts += 1
                            self._close(c, sel, conns, why, "timeout", logging.WARNING)
                    self._limiter.flush_due()
        finally:
            for c in list(conns.values()):
                c.close()
            conns.clear()
            with self._stats_lock:
                self._n_conns = 0
            sel.close()

    def _accept(self, sel, conns: dict) -> None:
        """Accept every pending connection (the listening socket is non-blocking)."""
        for _ in range(64):
            try:
                sock, addr = self._lsock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:        # e.g. out of file descriptors: try again later
                self._limiter.event("accept_failed", logging.WARNING, f"cannot accept a sensor connection ({exc})")
                time.sleep(_POLL_S)
                return
            now = time.perf_counter_ns()
            if len(conns) >= self.max_connections:
                oldest = min(conns.values(), key=lambda c: c.t_progress_ns)
                with self._stats_lock:
                    self._counts.evictions += 1
                self._close(oldest, sel, conns, f"evicted: {self.max_connections} connections open and it had "
                            f"the oldest complete frame", "evicted", logging.WARNING)
            sock.setblocking(False)
            try:
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            except OSError:
                pass
            peer = f"{addr[0]}:{addr[1]}"
            c = SensorConnection(sock, peer, now, self._digest)
            conns[sock] = c
            sel.register(sock, selectors.EVENT_READ, c)
            with self._stats_lock:
                self._counts.connections += 1
                self._n_conns = len(conns)
            self._limiter.event("connect", logging.INFO, f"sensor connected from {peer}")

    def _read(self, c: SensorConnection, view, sel, conns: dict) -> None:
        """One ``recv`` on a readable connection; decode, enqueue, or close it."""
        try:
            n = c.sock.recv_into(view)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self._close(c, sel, conns, f"connection error ({exc})")
            return
        t_recv = time.perf_counter_ns()
        if n == 0:
            self._close(c, sel, conns, "closed by the sensor")
            return
        items, refused = c.feed(view[:n], t_recv)
        if refused is not None:
            with self._stats_lock:
                self._counts.auth_failures += 1
            self._close(c, sel, conns, f"refused: {refused}", "auth", logging.WARNING)
            return
        max_ns = int(self.max_dt_s * 1e9)
        for item in items:
            if isinstance(item, Frame):
                dt_ns, why = c.transmission_ns(item.t_sensor_ns, item.t_recv_ns, max_ns)
                if why is not None:
                    with self._stats_lock:
                        self._counts.bad_stamps += 1
                    self._limiter.event("bad_stamp", logging.WARNING,
                                        f"sensor {c.peer}: seq {item.seq}: {why}; DT not measured for this frame")
                self._enqueue(item, dt_ns)
            else:
                self._reject(item.reason, item.detail)

    def _close(self, c: SensorConnection, sel, conns: dict, why: str, key: str = "disconnect",
               level: int = logging.INFO) -> None:
        """Close one connection, count and log it (once, rate-limited by kind)."""
        partial = c.detach(sel, conns)
        with self._stats_lock:
            self._counts.disconnects += 1
            self._n_conns = len(conns)
        if partial is not None:
            self._reject(partial.reason, partial.detail)
            why += f", mid-frame: {partial.detail}; the partial frame was discarded"
            level = max(level, logging.WARNING)
        self._limiter.event(key, level, f"sensor {c.peer} disconnected ({why})")

    def _enqueue(self, frame: Frame, dt_ns: int | None) -> None:
        with self._cond:
            dropped = len(self._queue) == self.queue_size
            self._queue.append((frame, dt_ns))  # a full deque drops its oldest item
            self._cond.notify()
        with self._stats_lock:
            self._counts.received += 1
            self._counts.dropped += dropped
        if dropped:
            self._limiter.event("dropped", logging.WARNING,
                                f"worker behind: dropped the oldest buffered frame (queue_size={self.queue_size})")

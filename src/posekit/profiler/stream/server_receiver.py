"""The receiving half of :class:`~posekit.profiler.stream.server.PoseServer`: every sensor
connection served from one thread (non-blocking sockets, :mod:`selectors`), frames decoded,
timed out, authenticated, rate-limited and queued (per connection, drop-oldest) for the worker.

A connection is *pending* until it proves itself a sensor — its hello carries the token, or, on
a server without a token, it sends a well-formed hello or frame — within ``hello_timeout_s`` of its
accept (and in at most :data:`PENDING_BYTES` bytes); then it is *active*. Pending connections
have their own limit (``max_pending``: the oldest pending one is closed for a newer one) and
never take the place of an active sensor. ``max_connections`` counts active sensors only: when
a connection proves itself while they are all taken, the active one idle longest is closed for
it only if that one has delivered no frame for ``hello_timeout_s``; otherwise the newcomer is
refused. At most ``max_accept_hz`` connections are accepted per second (more wait in the
kernel's backlog). Each active connection may send ``max_rate_hz`` frames per second (a bucket of
``rate_burst``): beyond it the receiver stops reading it until it may send again (the sender
is slowed by TCP, its frames are not decoded faster than they may be processed), so one
client cannot flood the worker; the worker takes the connections' queues in turn.

:class:`SensorReceiver` is a mixin: it holds no state of its own and uses the server's
(``_lsock``, ``_stop``, ``_cond``, ``_queues``, ``_ready``, ``_counts``, ``_stats_lock``,
``_limiter``, ``_reasons``, ``_digest``, the timeouts and limits); the behaviour is documented
on :mod:`~posekit.profiler.stream.server`.
"""

import heapq
import logging
import selectors
import socket
import time
from collections import deque

from .protocol import HELLO_HEADER_SIZE, MAX_FRAME_BYTES, MAX_TOKEN_BYTES, Frame
from .server_support import SensorConnection

__all__ = ["SensorReceiver", "PENDING_BYTES"]

_POLL_S = 0.05                 # how often blocked threads look at the stop flag
_RECV_BYTES = 65536            # one read per readable connection and round: the rounds stay short
#: Most bytes a pending connection may send before it has proved itself a sensor (a hello and
#: a frame of the largest size, twice over).
PENDING_BYTES = 2 * (HELLO_HEADER_SIZE + MAX_TOKEN_BYTES + MAX_FRAME_BYTES)
LOCAL_KEY = 0                  # the queue of frames submitted from this process
_ACCEPT_BURST = 64             # connections accepted at once above max_accept_hz


class SensorReceiver:
    """The receiver thread's methods of :class:`~posekit.profiler.stream.server.PoseServer`."""

    def _reject(self, reason: str, detail: str) -> None:
        with self._stats_lock:
            self._counts.rejected += 1
            self._reasons[reason] += 1
        self._limiter.event(reason, logging.WARNING, f"rejected frame ({reason}): {detail}")

    def _receive_loop(self) -> None:
        buf = bytearray(_RECV_BYTES)
        view = memoryview(buf)
        sel = selectors.DefaultSelector()
        sel.register(self._lsock, selectors.EVENT_READ, None)
        conns: dict = {}
        paused: list = []                   # heap of (resume_ns, key, connection)
        self._accept_tokens = float(_ACCEPT_BURST)
        self._accept_t_ns = time.perf_counter_ns()
        self._accept_resume_ns = None       # the listening socket is not read until then
        idle_ns = int(self.idle_timeout_s * 1e9)
        read_ns = int(self.read_timeout_s * 1e9)
        hello_ns = int(self.hello_timeout_s * 1e9)
        next_check = 0
        try:
            while not self._stop.is_set():
                timeout = _POLL_S
                due = [t for t in ((paused[0][0] if paused else None), self._accept_resume_ns) if t is not None]
                if due:
                    timeout = min(timeout, max(0.0, (min(due) - time.perf_counter_ns()) * 1e-9))
                try:
                    events = sel.select(timeout)
                except OSError:                     # e.g. EINTR storms; look at the stop flag
                    events = []
                for key, _ in events:
                    c = key.data
                    if c is None:
                        self._accept(sel, conns)
                    elif c.sock in conns and not c.paused:      # not closed earlier in this round
                        try:
                            self._read(c, view, sel, conns, paused)
                        except Exception as exc:    # a bug, never bad input (the decoders take any bytes)
                            self.log.exception("receiver: internal error, dropping the connection")
                            self._close(c, sel, conns, f"internal error ({type(exc).__name__}: {exc})")
                now = time.perf_counter_ns()
                if self._accept_resume_ns is not None and now >= self._accept_resume_ns:
                    self._accept_resume_ns = None
                    sel.register(self._lsock, selectors.EVENT_READ, None)
                while paused and paused[0][0] <= now:
                    _, _, c = heapq.heappop(paused)
                    if c.sock in conns:
                        self._resume(c, sel, conns, paused, now)
                if now >= next_check:               # deadlines: ~20 times a second is enough
                    next_check = now + 50_000_000
                    expired = [(c, c.expired(now, idle_ns, read_ns, hello_ns)) for c in conns.values()]
                    for c, why in expired:
                        if why is not None and c.sock in conns:
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

    # ------------------------------------------------------------------ connections

    def _accept(self, sel, conns: dict) -> None:
        """Accept the waiting connections (the listening socket is non-blocking), at most
        ``max_accept_hz`` per second: beyond it the listening socket is not read for a while, so a
        storm of connections waits in the kernel's backlog (and its SYNs are retried) instead of
        taking the receiver's time from the sensors."""
        now = time.perf_counter_ns()
        self._accept_tokens = min(_ACCEPT_BURST, self._accept_tokens
                                  + (now - self._accept_t_ns) * 1e-9 * self.max_accept_hz)
        self._accept_t_ns = now
        for _ in range(64):
            if self._accept_tokens < 1.0:
                sel.unregister(self._lsock)
                self._accept_resume_ns = now + int((1.0 - self._accept_tokens) / self.max_accept_hz * 1e9) + 1
                with self._stats_lock:
                    self._counts.accept_limited += 1
                return
            try:
                sock, addr = self._lsock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:        # e.g. out of file descriptors: try again later
                self._limiter.event("accept_failed", logging.WARNING, f"cannot accept a sensor connection ({exc})")
                time.sleep(_POLL_S)
                return
            self._accept_tokens -= 1.0
            now = time.perf_counter_ns()
            pending = [c for c in conns.values() if not c.active]
            if len(pending) >= self.max_pending:       # never an active sensor: the oldest unproven one
                oldest = min(pending, key=lambda c: c.t_accept_ns)
                with self._stats_lock:
                    self._counts.shed += 1
                self._close(oldest, sel, conns, f"shed: {self.max_pending} connections waiting to prove they are "
                            "sensors and it is the oldest", "shed", logging.WARNING)
            sock.setblocking(False)
            try:
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            except OSError:
                pass
            peer = f"{addr[0]}:{addr[1]}"
            c = SensorConnection(sock, peer, now, self._digest, self.max_rate_hz, self.rate_burst)
            conns[sock] = c
            sel.register(sock, selectors.EVENT_READ, c)
            with self._stats_lock:
                self._counts.connections += 1
                self._n_conns = sum(1 for x in conns.values() if x.active)
            self._limiter.event("connect", logging.INFO, f"connection from {peer}")

    def _promote(self, c: SensorConnection, sel, conns: dict, now: int) -> bool:
        """Make ``c`` an active sensor if there is room (or an idle sensor to close); False if refused."""
        active = [x for x in conns.values() if x.active]
        if len(active) >= self.max_connections:
            idle = min(active, key=lambda x: x.t_progress_ns)
            idle_s = (now - idle.t_progress_ns) * 1e-9
            if idle_s < self.hello_timeout_s:
                with self._stats_lock:
                    self._counts.shed += 1
                self._close(c, sel, conns, f"refused: {self.max_connections} sensors connected and streaming",
                            "full", logging.WARNING)
                return False
            with self._stats_lock:
                self._counts.evictions += 1
            self._close(idle, sel, conns, f"evicted for a new sensor: {self.max_connections} sensors connected "
                        f"and it had sent no frame for {idle_s:.1f} s", "evicted", logging.WARNING)
        c.active = True
        with self._stats_lock:
            self._n_conns = sum(1 for x in conns.values() if x.active)
        self._limiter.event("sensor", logging.INFO, f"sensor {c.peer} connected")
        return True

    def _read(self, c: SensorConnection, view, sel, conns: dict, paused: list) -> None:
        """One ``recv`` on a readable connection; decode (within its rate), enqueue, or close it."""
        now = time.perf_counter_ns()
        allowed = int(c.refill(now)) if c.active else 1
        if allowed < 1:
            self._pause(c, sel, paused, now)
            return
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
        items, refused = c.feed(view[:n], t_recv, allowed)
        if refused is not None:
            with self._stats_lock:
                self._counts.auth_failures += 1
            self._close(c, sel, conns, f"refused: {refused}", "auth", logging.WARNING)
            return
        if not c.active:
            proved = c.said_hello or (self._digest is None and any(isinstance(i, Frame) for i in items))
            if proved:
                if not self._promote(c, sel, conns, t_recv):
                    return
            elif c.received_bytes > PENDING_BYTES:
                with self._stats_lock:
                    self._counts.shed += 1
                self._close(c, sel, conns, f"not a sensor: {c.received_bytes} bytes without "
                            + ("the hello with the token" if self._digest is not None else "a well-formed hello or frame"),
                            "shed", logging.WARNING)
                return
        self._deliver(c, items)
        if c.active and (c.decoder.has_frame() or c.tokens < 1):
            self._pause(c, sel, paused, time.perf_counter_ns())

    def _deliver(self, c: SensorConnection, items: list) -> None:
        """Queue the frames of ``items`` (their stamps checked), count the malformed stretches."""
        max_ns = int(self.max_dt_s * 1e9)
        frames = 0
        for item in items:
            if isinstance(item, Frame):
                frames += 1
                dt_ns, why = c.transmission_ns(item.t_sensor_ns, item.t_recv_ns, max_ns)
                if why is not None:
                    with self._stats_lock:
                        self._counts.bad_stamps += 1
                    self._limiter.event("bad_stamp", logging.WARNING,
                                        f"sensor {c.peer}: seq {item.seq}: {why}; DT not measured for this frame")
                self._enqueue(item, dt_ns, c.key)
            else:
                self._reject(item.reason, item.detail)
        c.tokens -= frames

    def _pause(self, c: SensorConnection, sel, paused: list, now: int) -> None:
        """Stop reading ``c`` until its bucket holds a token again (TCP slows the sender meanwhile)."""
        if not c.paused:
            try:
                sel.unregister(c.sock)
            except (KeyError, ValueError, OSError):
                pass
            c.paused = True
            with self._stats_lock:
                self._counts.rate_limited += 1
        heapq.heappush(paused, (c.next_token_ns(now), c.key, c))

    def _resume(self, c: SensorConnection, sel, conns: dict, paused: list, now: int) -> None:
        """Decode what ``c`` has buffered within its rate; read it again once the buffer holds no whole frame."""
        allowed = int(c.refill(now))
        if allowed < 1:
            heapq.heappush(paused, (c.next_token_ns(now), c.key, c))
            return
        if c.decoder.has_frame():
            items, _ = c.feed(b"", now, allowed)
            self._deliver(c, items)
            if c.decoder.has_frame() or c.tokens < 1:
                heapq.heappush(paused, (c.next_token_ns(time.perf_counter_ns()), c.key, c))
                return
        c.paused = False
        try:
            sel.register(c.sock, selectors.EVENT_READ, c)
        except (KeyError, ValueError, OSError):
            self._close(c, sel, conns, "connection lost while rate-limited")

    def _close(self, c: SensorConnection, sel, conns: dict, why: str, key: str = "disconnect",
               level: int = logging.INFO) -> None:
        """Close one connection, count and log it (once, rate-limited by kind)."""
        was_active = c.active
        partial = c.detach(sel, conns)
        c.paused = True                      # (never read again)
        with self._stats_lock:
            self._counts.disconnects += 1
            self._n_conns = sum(1 for x in conns.values() if x.active)
        if partial is not None:
            self._reject(partial.reason, partial.detail)
            why += f", mid-frame: {partial.detail}; the partial frame was discarded"
            level = max(level, logging.WARNING)
        self._limiter.event(key, level, f"{'sensor' if was_active else 'connection'} {c.peer} disconnected ({why})")

    # ------------------------------------------------------------------ the worker's queues

    def _enqueue(self, frame: Frame, dt_ns: int | None, key: int = LOCAL_KEY) -> None:
        """Append to the queue of connection ``key`` (its oldest frame dropped when full); the
        worker serves the queues in turn."""
        with self._cond:
            q = self._queues.get(key)
            if q is None:
                q = self._queues[key] = deque(maxlen=self.queue_size)
            dropped = len(q) == self.queue_size
            q.append((frame, dt_ns))             # a full deque drops its oldest item
            if not dropped and len(q) == 1:
                self._ready.append(key)
            self._cond.notify()
        with self._stats_lock:
            self._counts.received += 1
            self._counts.dropped += dropped
        if dropped:
            self._limiter.event("dropped", logging.WARNING,
                                f"worker behind: dropped a sensor's oldest buffered frame (queue_size={self.queue_size})")

    def _next_frame(self):
        """The worker's next ``(frame, dt_ns)``: the oldest frame of the next queue in turn (under ``_cond``)."""
        key = self._ready.popleft()
        q = self._queues[key]
        item = q.popleft()
        if q:
            self._ready.append(key)
        else:
            del self._queues[key]
        return item

"""Plumbing of the pose server: addresses and the listening socket, the token, one sensor
connection, rate-limited logging, counters, the robot link."""

import hashlib
import hmac
import ipaddress
import logging
import select
import socket
import threading
import time
from collections import Counter
from dataclasses import dataclass

from ...errors import ConfigError, InputFileError
from .protocol import MAX_TOKEN_BYTES, NO_HELLO, TRUNCATED, FrameDecoder, FrameError, decode_hello

__all__ = ["parse_address", "check_address", "listen_socket", "read_token_file", "token_digest", "SensorConnection",
           "LogLimiter", "Counts", "RobotLink"]

_LOG_INTERVAL_S = 1.0          # at most one log line per kind of event per interval
_TOKEN_FILE_BYTES = 4096       # a token file is a line of text; anything larger is the wrong file


# --------------------------------------------------------------------------- addresses


def parse_address(text: str, what: str = "address") -> tuple[str, int]:
    """``'127.0.0.1:5000'`` or ``'[::1]:5000'`` → ``(host, port)``.

    Raises
    ------
    ConfigError
        If the text is not ``HOST:PORT`` with a port in 0..65535.
    """
    text = str(text).strip()
    host, sep, port_text = text.rpartition(":")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if not sep or not host:
        raise ConfigError(f"{what} '{text}': expected HOST:PORT, e.g. 127.0.0.1:5000")
    try:
        port = int(port_text)
    except ValueError:
        raise ConfigError(f"{what} '{text}': port '{port_text}' is not a number") from None
    if not 0 <= port <= 65535:
        raise ConfigError(f"{what} '{text}': port must be in 0..65535, got {port}")
    return host, port


def check_address(address, what: str = "address", allow_remote: bool = False):
    """Resolve ``(host, port)``; refuse a non-loopback host unless ``allow_remote``.

    Returns
    -------
    family : int
        ``socket.AF_INET`` or ``socket.AF_INET6``.
    sockaddr : tuple
        The first resolved socket address.

    Raises
    ------
    ConfigError
        If the address is malformed, does not resolve, or is not a loopback address
        (127.0.0.0/8, ::1) and ``allow_remote`` is False.
    """
    try:
        host, port = address
        port = int(port)
    except (TypeError, ValueError):
        raise ConfigError(f"{what}: expected (host, port), got {address!r}") from None
    if not 0 <= port <= 65535:
        raise ConfigError(f"{what} {host}:{port}: port must be in 0..65535")
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError) as exc:
        raise ConfigError(f"{what} {host}:{port}: cannot resolve host ({exc})") from None
    if not allow_remote:
        for info in infos:
            try:
                loop = ipaddress.ip_address(info[4][0].split("%")[0]).is_loopback
            except ValueError:
                loop = False
            if not loop:
                raise ConfigError(f"{what} {host}:{port} is not a loopback address (127.0.0.0/8, ::1); "
                                  "allow_remote=True (--allow-remote, with a token: --token-file) permits other hosts")
    return infos[0][0], infos[0][4]


def listen_socket(family: int, sockaddr) -> socket.socket:
    """A non-blocking TCP socket bound to ``sockaddr`` (from :func:`check_address`) and listening.

    Raises
    ------
    ConfigError
        ``listen address HOST:PORT: cannot bind (REASON)``.
    """
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(sockaddr)
        sock.listen(64)         # a small backlog drops SYNs of quick reconnects (1 s retries)
        sock.setblocking(False)
    except OSError as exc:
        sock.close()
        raise ConfigError(f"listen address {sockaddr[0]}:{sockaddr[1]}: "
                          f"cannot bind ({exc.strerror or exc})") from None
    return sock


# --------------------------------------------------------------------------- the token


def read_token_file(path) -> str:
    """The shared secret in a token file: UTF-8 text, surrounding whitespace stripped.

    Parameters
    ----------
    path : str or Path
        A small text file (at most 4 KiB) holding the token, e.g. one line made by
        ``python -c "import secrets; print(secrets.token_urlsafe(32))" > token``.

    Returns
    -------
    str
        The token, 1 to ``MAX_TOKEN_BYTES`` bytes in UTF-8.

    Raises
    ------
    InputFileError
        If the file is missing, unreadable, larger than 4 KiB, not UTF-8 text, empty (or only
        whitespace), or holds a token longer than ``MAX_TOKEN_BYTES`` bytes.
    """
    from ...io import read_text

    expected = "a token file (one line of UTF-8 text, the shared secret)"
    text = read_text(path, expected=expected, limit=_TOKEN_FILE_BYTES).strip()
    if not text:
        raise InputFileError(f"{path}: empty (only whitespace); expected {expected}")
    size = len(text.encode("utf-8"))
    if size > MAX_TOKEN_BYTES:
        raise InputFileError(f"{path}: the token is {size} bytes long; expected at most {MAX_TOKEN_BYTES}")
    return text


def token_digest(token: str | bytes) -> bytes:
    """SHA-256 of the token, the form the server keeps and compares (in constant time)."""
    if isinstance(token, str):
        token = token.encode("utf-8")
    return hashlib.sha256(token).digest()


# --------------------------------------------------------------------------- one sensor connection


class SensorConnection:
    """The receiver's state for one sensor connection: hello, frame decoder, deadlines, stamps.

    Times are ns on :func:`time.perf_counter_ns`.

    Parameters
    ----------
    sock : socket.socket
        The accepted, non-blocking socket.
    peer : str
        ``host:port`` of the sensor, for messages.
    t_ns : int
        Accept time.
    digest : bytes or None
        :func:`token_digest` of the token every client must present first; None: a hello
        is optional and its token is not checked.

    Attributes
    ----------
    t_progress_ns : int
        When the connection last delivered a complete frame (at first: the accept).
    t_partial_ns : int or None
        When the first byte of the incomplete frame (or hello) arrived; None between frames.
    greeted : bool
        True once the hello phase is over (frames are decoded from then on).
    said_hello : bool
        True when the connection began with a well-formed hello (with the right token, on a
        server that has one).
    active : bool
        True once the connection has proved itself a sensor: its hello carried the token (or,
        on a server without one, it sent a well-formed hello or frame). Only active connections count
        against ``max_connections``, get their frames processed and are never closed for a
        newcomer that has not.
    key : int
        The connection's number (its frames' queue).
    tokens : float
        Frames it may still send now (its rate limit's bucket).
    received_bytes : int
        Bytes received so far.
    """

    _next_key = 0

    def __init__(self, sock, peer: str, t_ns: int, digest: bytes | None = None, rate_hz: float = 4000.0,
                 burst: int = 64):
        self.sock = sock
        self.peer = peer
        self.decoder = FrameDecoder()
        self.t_accept_ns = t_ns
        self.t_progress_ns = t_ns
        self.t_partial_ns = t_ns if digest is not None else None     # the hello is due at once
        self.greeted = False
        self.said_hello = False
        self.active = False
        SensorConnection._next_key += 1
        self.key = SensorConnection._next_key
        self.rate_hz = float(rate_hz)
        self.burst = float(burst)
        self.tokens = float(burst)
        self._t_tokens_ns = t_ns
        self.received_bytes = 0
        self.paused = False
        self._digest = digest
        self._hello = bytearray()
        self._last_stamp = None

    def refill(self, now_ns: int) -> float:
        """Add the tokens earned since the last refill (at most ``burst``); the tokens now."""
        self.tokens = min(self.burst, self.tokens + (now_ns - self._t_tokens_ns) * 1e-9 * self.rate_hz)
        self._t_tokens_ns = now_ns
        return self.tokens

    def next_token_ns(self, now_ns: int) -> int:
        """When the bucket holds a whole token again."""
        return now_ns + int(max(0.0, 1.0 - self.tokens) / self.rate_hz * 1e9) + 1

    def feed(self, data, t_recv_ns: int, max_frames: int | None = None) -> tuple[list, str | None]:
        """Decode ``data``, just received (at most ``max_frames`` frames; the rest stays buffered).

        Returns
        -------
        items : list of Frame and FrameError
            As :meth:`FrameDecoder.feed`, in stream order.
        refused : str or None
            Why the connection must be closed now (a missing, malformed or wrong hello),
            else None.
        """
        self.received_bytes += len(data)
        if not self.greeted:
            self._hello += data
            got = decode_hello(self._hello)
            if got is None:
                if self.t_partial_ns is None:
                    self.t_partial_ns = t_recv_ns
                return [], None
            refused = None
            if isinstance(got, FrameError):
                if self._digest is not None and got.reason == NO_HELLO:
                    refused = "sent no hello with the token"
                elif got.reason != NO_HELLO:
                    refused = f"bad hello ({got.detail})"
                start = 0                             # no hello: these bytes are frames
            else:
                if self._digest is not None and not hmac.compare_digest(token_digest(got.token), self._digest):
                    refused = "wrong token"
                start = got.size
                self.said_hello = refused is None
            if refused is not None:
                self._hello = bytearray()             # nothing of a refused stream is decoded
                return [], refused
            data = self._hello
            self.greeted = True
            self._hello = bytearray()
            self.t_partial_ns = None
            data = memoryview(data)[start:]
        items = self.decoder.feed(data, t_recv_ns, max_frames)
        if any(not isinstance(item, FrameError) for item in items):
            self.t_progress_ns = t_recv_ns
        if not self.decoder.mid_frame:
            self.t_partial_ns = None
        elif self.t_partial_ns is None or items:
            self.t_partial_ns = t_recv_ns     # approximately: the chunk that started the frame
        return items, None

    def expired(self, now_ns: int, idle_ns: int, read_ns: int, hello_ns: int | None = None) -> str | None:
        """Why the connection has timed out at ``now_ns``, or None.

        A connection times out when it has not proved itself a sensor (the hello with the
        token, or without a token a well-formed hello or frame) within ``hello_ns`` of its accept, when
        a frame (or the hello) it started has not been completed within ``read_ns`` (the read
        timeout), or when it has delivered no complete frame for ``idle_ns`` (the idle timeout:
        a silent sensor, or one sending only bytes that never make a frame).
        """
        if not self.active and hello_ns is not None and now_ns - self.t_accept_ns > hello_ns:
            what = "hello with the token" if self._digest is not None else "well-formed hello or frame"
            return f"not a sensor: no {what} within {hello_ns * 1e-9:g} s of connecting"
        if self.t_partial_ns is not None and now_ns - self.t_partial_ns > read_ns:
            what = "a frame" if self.greeted else "the hello" if self._digest is not None else "a hello or frame"
            got = len(self._hello) if not self.greeted else self.decoder.buffered
            return (f"read timeout: {got} bytes of {what} in {(now_ns - self.t_partial_ns) * 1e-9:.1f} s, "
                    f"the rest not within {read_ns * 1e-9:g} s")
        if now_ns - self.t_progress_ns > idle_ns:
            return f"idle timeout: no complete frame for {(now_ns - self.t_progress_ns) * 1e-9:.1f} s"
        return None

    def transmission_ns(self, t_sensor_ns: int, t_recv_ns: int, max_ns: int) -> tuple[int | None, str | None]:
        """DT of a frame if its sensor stamp can be believed: ``(dt_ns, None)`` or ``(None, why)``.

        A stamp is believed when it lies on the server's clock in ``[t_recv - max_ns, t_recv]``
        and is not earlier than the last believed stamp of this connection; only believed
        stamps move that reference, so one wild stamp does not spoil the ones after it.
        """
        dt = t_recv_ns - t_sensor_ns
        if dt < 0:
            return None, f"stamp {-dt * 1e-6:.3f} ms ahead of the server's clock"
        if dt > max_ns:
            return None, f"stamp {dt * 1e-9:.6g} s old (more than {max_ns * 1e-9:g} s)"
        if self._last_stamp is not None and t_sensor_ns < self._last_stamp:
            return None, f"stamp {(self._last_stamp - t_sensor_ns) * 1e-6:.3f} ms before the previous frame's"
        self._last_stamp = t_sensor_ns
        return dt, None

    def close(self) -> FrameError | None:
        """Close the socket; the incomplete frame (or hello) it leaves (``truncated``), if any."""
        try:
            self.sock.close()
        except OSError:
            pass
        if self._hello:
            n, self._hello = len(self._hello), bytearray()
            return FrameError(TRUNCATED, f"stream ended {n} bytes into its first message (a hello or frame)", 0)
        return self.decoder.flush()

    def detach(self, sel, conns: dict) -> FrameError | None:
        """Unregister from the selector ``sel``, leave ``conns`` (socket → connection) and close;
        the incomplete frame it leaves, if any (:meth:`close`)."""
        try:
            sel.unregister(self.sock)
        except (KeyError, ValueError, OSError):
            pass
        conns.pop(self.sock, None)
        return self.close()


# --------------------------------------------------------------------------- helpers


class LogLimiter:
    """Logs the first event of each kind at once, then at most one line per interval."""

    def __init__(self, log: logging.Logger, interval_s: float = _LOG_INTERVAL_S):
        self._log = log
        self._interval = interval_s
        self._lock = threading.Lock()
        self._last: dict = {}
        self._held: Counter = Counter()

    def event(self, key: str, level: int, message: str) -> None:
        now = time.monotonic()
        with self._lock:
            last = self._last.get(key)
            if last is not None and now - last < self._interval:
                self._held[key] += 1
                return
            self._last[key] = now
            held = self._held.pop(key, 0)
        suffix = f" (and {held} more '{key}' in the last {now - last:.1f} s)" if held else ""
        self._log.log(level, "%s%s", message, suffix)

    def flush_due(self) -> None:
        """Log the held-back count of every kind whose interval has passed."""
        now = time.monotonic()
        with self._lock:
            due = [k for k, n in self._held.items() if n and now - self._last.get(k, 0.0) >= self._interval]
            held = {k: self._held.pop(k) for k in due}
            for k in due:
                self._last[k] = now
        for key, n in held.items():
            self._log.warning("%d more '%s' event(s) in the last %.1f s", n, key, self._interval)

    def flush(self) -> None:
        with self._lock:
            held, self._held = self._held, Counter()
        for key, n in held.items():
            self._log.warning("%d more '%s' event(s) not logged individually", n, key)


@dataclass
class Counts:
    received: int = 0
    processed: int = 0
    ok: int = 0
    errors: int = 0
    dropped: int = 0
    rejected: int = 0
    disconnects: int = 0
    connections: int = 0
    cold_restarts: int = 0
    sent: int = 0
    unsent: int = 0
    robot_connects: int = 0
    robot_failures: int = 0
    timeouts: int = 0
    auth_failures: int = 0
    evictions: int = 0
    bad_stamps: int = 0
    shed: int = 0
    rate_limited: int = 0
    accept_limited: int = 0


class RobotLink:
    """The TCP client to the robot interface, reconnecting with exponential back-off.

    Lives in the worker thread; :meth:`send` never blocks longer than ``timeout_s``.
    """

    def __init__(self, family, sockaddr, counts: Counts, lock, limiter: LogLimiter, timeout_s: float = 0.2):
        self._lock = lock
        self._family = family
        self._addr = sockaddr
        self._counts = counts
        self._limiter = limiter
        self._timeout = timeout_s
        self._sock = None
        self._next_try = 0.0
        self._backoff = 0.05

    def _connect(self) -> bool:
        now = time.monotonic()
        if now < self._next_try:
            return False
        sock = socket.socket(self._family, socket.SOCK_STREAM)
        try:
            sock.settimeout(self._timeout)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.connect(self._addr)
        except OSError as exc:
            sock.close()
            self._next_try = now + self._backoff
            self._limiter.event("robot_unreachable", logging.WARNING,
                                f"robot interface {self._addr[0]}:{self._addr[1]} unreachable ({exc}); "
                                f"retrying in {self._backoff:.2f} s")
            self._backoff = min(2.0 * self._backoff, 2.0)
            return False
        self._sock = sock
        self._backoff = 0.05
        with self._lock:
            self._counts.robot_connects += 1
        self._limiter.event("robot_connect", logging.INFO,
                            f"connected to robot interface {self._addr[0]}:{self._addr[1]}")
        return True

    def _peer_closed(self) -> bool:
        """True if the robot side closed (readable with EOF); its own bytes are discarded."""
        try:
            readable, _, _ = select.select([self._sock], [], [], 0)
            if readable:
                return self._sock.recv(65536, socket.MSG_DONTWAIT) == b""
        except BlockingIOError:
            return False
        except OSError:
            return True
        return False

    def send(self, data: bytes) -> bool:
        if self._sock is None and not self._connect():
            return False
        try:
            if self._peer_closed():
                raise ConnectionResetError("robot interface closed the connection")
            self._sock.sendall(data)
            return True
        except OSError as exc:       # includes the send timeout: a partial line dies with the socket
            with self._lock:
                self._counts.robot_failures += 1
            self._limiter.event("robot_lost", logging.WARNING,
                                f"lost robot interface {self._addr[0]}:{self._addr[1]} ({exc}); reconnecting")
            self.close()
            return False

    def close(self) -> None:
        if self._sock is not None:
            try:
                self._sock.close()
            finally:
                self._sock = None


# --------------------------------------------------------------------------- server

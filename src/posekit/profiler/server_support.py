"""Plumbing of the pose server: addresses, rate-limited logging, counters, the robot link."""

import ipaddress
import logging
import select
import socket
import threading
import time
from collections import Counter
from dataclasses import dataclass

from ..errors import ConfigError

__all__ = ["parse_address", "check_address", "LogLimiter", "Counts", "RobotLink"]

_LOG_INTERVAL_S = 1.0          # at most one log line per kind of event per interval


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
                                  "allow_remote=True (--allow-remote) permits other hosts")
    return infos[0][0], infos[0][4]


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

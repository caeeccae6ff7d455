"""A pose server under attack: good sensors streaming while hostile clients misbehave.

:func:`run_soak` starts a :class:`~posekit.profiler.stream.server.PoseServer` in this process,
``sensors`` good sensors at ``rate_hz`` each (hello with the token, then one frame per period,
stamped on :func:`time.perf_counter_ns` just before it is sent) in one child process, and
``hostile`` misbehaving clients in another (separate processes: their Python threads do not
share this process's interpreter lock with the server). The hostile kinds, in turn:

``silent``
    connects and sends nothing; reconnects as soon as it is closed.
``bad_token``
    sends a hello with a wrong token, then frames; reconnects when closed.
``flood``
    sends valid frames without any hello as fast as the socket takes them; reconnects.
``garbage``
    sends random bytes as fast as the socket takes them; reconnects.
``empty``
    an insider: the right token, then empty frames (no points) as fast as it can.

It reports what a deployment needs to know: the share of the good sensors' frames that got
a record, the latency of those records (sensor stamp to the record reaching the record sink,
ms), and how many connections the server evicted. ``posekit bench server`` runs it longer;
the test suite runs it for a few seconds.
"""

import logging
import multiprocessing
import os
import socket
import threading
import time
from dataclasses import dataclass

import numpy as np

from .protocol import encode_frame, encode_hello

__all__ = ["SoakResult", "run_soak", "HOSTILE_KINDS", "GOOD_SEQ_LIMIT"]

HOSTILE_KINDS = ("silent", "bad_token", "flood", "garbage", "empty")
#: Good sensors number their frames below this (sensor k: ``k * 10**6 + i``); hostile ones above.
GOOD_SEQ_LIMIT = 2**31
_TOKEN = "soak-test-token"


@dataclass(frozen=True)
class SoakResult:
    """Outcome of :func:`run_soak`.

    Attributes
    ----------
    sent : int
        Frames the good sensors sent.
    processed : int
        Of those, frames that got a record (any status).
    delivered : float
        ``processed / sent``.
    latency_ms : ndarray, shape (processed,)
        Sensor stamp to the record reaching the record sink, per processed good frame, ms.
    p50_ms, p99_ms : float
        Median and 99th percentile of ``latency_ms``.
    evictions : int
        Connections the server closed to make room for others.
    hostile_connects : int
        Connections the hostile clients opened.
    send_failures : int
        Good sensors' sends that failed (their connection was closed), each followed by a reconnect.
    skipped : int
        Good frames not sent because the sensors' process was not scheduled in time (a busy machine).
    stats : dict
        :meth:`PoseServer.stats` at the end.
    duration_s : float
    """

    sent: int
    processed: int
    delivered: float
    latency_ms: np.ndarray
    p50_ms: float
    p99_ms: float
    evictions: int
    hostile_connects: int
    send_failures: int
    skipped: int
    stats: dict
    duration_s: float

    def summary(self) -> str:
        return (f"{self.processed} of {self.sent} good frames processed ({100 * self.delivered:.2f} %), latency p50 "
                f"{self.p50_ms:.2f} ms, p99 {self.p99_ms:.2f} ms; {self.evictions} evictions, "
                f"{self.hostile_connects} hostile connections, {self.send_failures} failed sends of good sensors, "
                f"{self.skipped} not sent in time")


class _LatencySink:
    """Record sink: the time each good sensor's record arrives, against its stamp."""

    def __init__(self):
        self._lock = threading.Lock()
        self.latency_ns = []

    def put(self, rec):
        now = time.perf_counter_ns()
        if rec.get("seq") is not None and rec["seq"] < GOOD_SEQ_LIMIT:
            with self._lock:
                self.latency_ns.append(now - rec["t_sensor_ns"])


def _connect(address, timeout_s=2.0):
    s = socket.create_connection(address, timeout=timeout_s)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def _sensors(address, token, n, rate_hz, duration_s, points, ready, go, start, out):
    """Child process: ``n`` good sensors, one frame each per period, in one thread. A frame whose
    time has passed by a whole period (this process was not scheduled) is skipped, not sent late
    in a burst, as a sensor's trigger would."""
    socks = [None] * n
    sent = failures = skipped = 0
    period_ns = int(1e9 / rate_hz)

    def connect(k):
        s = _connect(address)
        if token is not None:
            s.sendall(encode_hello(token))
        return s

    for k in range(n):
        socks[k] = connect(k)
    ready.set()
    go.wait()
    start_ns = start.value
    while time.perf_counter_ns() < start_ns:
        time.sleep(0.001)
    end_ns = start_ns + int(duration_s * 1e9)
    i = 0
    while True:
        base = start_ns + i * period_ns
        if base >= end_ns:
            break
        for k in range(n):
            due = base + k * period_ns // n             # the sensors spread over the period
            delay = (due - time.perf_counter_ns()) * 1e-9
            if delay > 0:
                time.sleep(delay)
            elif -delay * 1e9 > period_ns:
                skipped += 1
                continue
            frame = encode_frame(k * 10**6 + i, time.perf_counter_ns(), points)
            try:
                socks[k].sendall(frame)
                sent += 1
            except OSError:
                failures += 1
                try:
                    socks[k].close()
                    socks[k] = connect(k)
                except OSError:
                    pass
        i += 1
    time.sleep(0.2)
    for s in socks:
        try:
            s.close()
        except OSError:
            pass
    out.put({"sent": sent, "failures": failures, "skipped": skipped})


def _hostile_client(kind, address, points, stop, counter, seed):
    rng = np.random.default_rng(seed)
    garbage = rng.integers(0, 256, 65536, dtype=np.uint8).tobytes()
    frame = encode_frame(GOOD_SEQ_LIMIT + 1, 0, points)
    empty = b"".join(encode_frame(GOOD_SEQ_LIMIT + 2, 0, np.zeros((0, 2))) for _ in range(2000))
    while not stop.is_set():
        try:
            s = _connect(address)
        except OSError:
            time.sleep(0.01)
            continue
        counter[kind] = counter.get(kind, 0) + 1
        try:
            s.settimeout(0.5)
            if kind == "silent":
                while not stop.is_set():            # until the server closes it
                    try:
                        if s.recv(1) == b"":
                            break
                    except TimeoutError:
                        continue
            elif kind == "bad_token":
                s.sendall(encode_hello("not-the-token"))
                while not stop.is_set():
                    s.sendall(frame)
            elif kind == "flood":
                while not stop.is_set():
                    s.sendall(frame)
            elif kind == "garbage":
                while not stop.is_set():
                    s.sendall(garbage)
            elif kind == "empty":
                s.sendall(encode_hello(_TOKEN))
                while not stop.is_set():
                    s.sendall(empty)
        except OSError:
            pass
        finally:
            s.close()


def _hostile(address, n, points, duration_s, ready, go, start, out):
    """Child process: ``n`` hostile clients, kinds in turn, each in a thread. It runs at the lowest
    priority: it stands for other machines, whose CPU is not the server's (on one machine a
    flooding process would otherwise measure the competition for the cores, not the server)."""
    try:
        os.nice(19)
    except OSError:
        pass
    stop = threading.Event()
    counter: dict = {}
    threads = [threading.Thread(target=_hostile_client, args=(HOSTILE_KINDS[k % len(HOSTILE_KINDS)], address, points,
                                                               stop, counter, k), daemon=True) for k in range(n)]
    ready.set()
    go.wait()
    start_ns = start.value
    while time.perf_counter_ns() < start_ns - 300_000_000:   # the attack begins just before the sensors
        time.sleep(0.001)
    for t in threads:
        t.start()
    time.sleep(max(0.0, (start_ns - time.perf_counter_ns()) * 1e-9 + duration_s + 0.2))
    stop.set()
    for t in threads:
        t.join(2.0)
    out.put(dict(counter))


def run_soak(*, sensors: int = 16, rate_hz: float = 25.0, hostile: int = 20, duration_s: float = 3.0,
             gauge=None, seed: int = 0, server_kwargs: dict | None = None) -> SoakResult:
    """Stream ``sensors`` good sensors at ``rate_hz`` into a pose server with a token while
    ``hostile`` clients attack it (module docstring), for ``duration_s``.

    Parameters
    ----------
    sensors : int
        Good sensors (each authenticates with the token).
    rate_hz : float
        Frames per second of each good sensor.
    hostile : int
        Hostile clients, their kinds in :data:`HOSTILE_KINDS` in turn.
    duration_s : float
        How long the good sensors stream, s.
    gauge : Gauge, optional
        Default the bundled ``demo-5``; the good frames are its nominal profile.
    seed : int
        Noise of the good profile and the hostile clients' bytes.
    server_kwargs : dict, optional
        More keyword arguments of the :class:`PoseServer` (``max_connections``, ``log``, ...;
        its log is silent by default).

    Returns
    -------
    SoakResult
    """
    from ..gauge.model import bundled_gauge
    from ..sensor import NoiseModel
    from ..sim.poses import nominal_pose
    from ..sim.render import render_profiles
    from .server import PoseServer

    gauge = bundled_gauge("demo-5") if gauge is None else gauge
    points = render_profiles(gauge, nominal_pose(gauge), NoiseModel(), rng=seed).astype(np.float32)
    sink = _LatencySink()
    quiet = logging.getLogger("posekit.soak")           # the attack would log thousands of lines
    if not quiet.handlers:
        quiet.addHandler(logging.NullHandler())
        quiet.propagate = False
    kwargs = {"token": _TOKEN, "record_sink": sink, "freeze_gc": False, "log": quiet, **(server_kwargs or {})}
    server = PoseServer(gauge, **kwargs)
    address = server.start()
    ctx = multiprocessing.get_context("spawn")
    q_good, q_bad = ctx.Queue(), ctx.Queue()
    go, start = ctx.Event(), ctx.Value("q", 0)
    readies = [ctx.Event() for _ in range(2 if hostile else 1)]
    procs = [ctx.Process(target=_sensors, args=(address, _TOKEN, sensors, rate_hz, duration_s, points, readies[0], go,
                                                start, q_good), daemon=True)]
    if hostile:
        procs.append(ctx.Process(target=_hostile, args=(address, hostile, points, duration_s, readies[1], go, start,
                                                        q_bad), daemon=True))
    try:
        for p in procs:
            p.start()
        for r in readies:                                   # both children imported and connected
            if not r.wait(120):
                raise RuntimeError("soak: a client process did not start within 120 s")
        start.value = time.perf_counter_ns() + 500_000_000
        go.set()
        good = q_good.get(timeout=duration_s + 60)
        bad = q_bad.get(timeout=duration_s + 60) if hostile else {}
        deadline = time.monotonic() + 5.0
        while server.stats()["queued"] and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.1)
        stats = server.stats()
    finally:
        server.stop()
        for p in procs:
            p.join(5.0)
            if p.is_alive():
                p.kill()
    lat = np.asarray(sink.latency_ns, dtype=np.float64) * 1e-6
    sent = int(good["sent"])
    processed = int(lat.size)
    return SoakResult(sent=sent, processed=processed, delivered=processed / sent if sent else float("nan"),
                      latency_ms=lat, p50_ms=float(np.median(lat)) if lat.size else float("nan"),
                      p99_ms=float(np.percentile(lat, 99)) if lat.size else float("nan"),
                      evictions=int(stats["evictions"]), hostile_connects=int(sum(bad.values())),
                      send_failures=int(good["failures"]), skipped=int(good["skipped"]), stats=stats,
                      duration_s=duration_s)

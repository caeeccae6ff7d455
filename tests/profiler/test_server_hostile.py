"""The pose server under hostile or broken clients: stalled connections, tokens, wild stamps.

Every socket is on 127.0.0.1; every wait is bounded; the stalled clients are threads that stop
when the test ends.
"""

import argparse
import logging
import socket
import threading
import time

import numpy as np
import pytest

from posekit.errors import ConfigError, InputFileError
from posekit.profiler import NoiseModel, bundled_gauge, nominal_pose, render_profiles
from posekit.profiler.stream.protocol import (
    HELLO_HEADER,
    HELLO_MAGIC,
    MAX_TOKEN_BYTES,
    NO_HELLO,
    OVERSIZED,
    UNKNOWN_VERSION,
    Hello,
    decode_hello,
    encode_frame,
    encode_hello,
)
from posekit.profiler.stream.server import PoseServer
from posekit.profiler.stream.server_support import read_token_file
from posekit.profiler.stream.stream_client import SensorClient
from tests.profiler.server_helpers import wait_until

SERVE_WITHIN_S = 1.0           # a new sensor's first record, with a stalled client connected
IDLE_S = 2.5                   # the timeouts of these tests (the defaults are 30 s and 2 s)
READ_S = 1.5
WAIT_S = 10.0
TOKEN = "correct horse battery staple"


@pytest.fixture(scope="module")
def gauge():
    return bundled_gauge("demo-5")


@pytest.fixture(scope="module")
def profiles(gauge):
    T = np.repeat(nominal_pose(gauge)[None], 8, axis=0)
    return render_profiles(gauge, T, NoiseModel(), rng=3)




class _Stalled:
    """A client that connects and then stalls in one of several ways, in its own thread.

    kinds: ``silent`` (connected, sends nothing), ``trickle`` (a frame, one byte per second),
    ``partial`` (10,000 bytes of a frame, then nothing), ``garbage`` (a byte per second that
    never makes a frame), ``hello_trickle`` (a hello, one byte per second).
    """

    def __init__(self, kind, address, frame):
        self.kind = kind
        self.sock = socket.create_connection(address, timeout=2.0)
        self.port = self.sock.getsockname()[1]
        self._frame = frame
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        try:
            if self.kind == "partial":
                self.sock.sendall(self._frame[:10_000])
            elif self.kind in ("trickle", "garbage", "hello_trickle"):
                data = {"trickle": self._frame, "garbage": b"x" * 60,
                        "hello_trickle": encode_hello(TOKEN)}[self.kind]
                for b in data[:60]:                    # at most a minute, stopped long before
                    self.sock.sendall(bytes([b]))
                    if self._stop.wait(1.0):
                        break
        except OSError:                                # the server closed it: that is the point
            pass

    def closed_by_server(self, timeout_s=WAIT_S):
        """True once the server has closed the connection (EOF or reset)."""
        self.sock.settimeout(timeout_s)
        try:
            return self.sock.recv(1) == b""
        except ConnectionResetError:
            return True
        except TimeoutError:
            return False

    def close(self):
        self._stop.set()
        self._thread.join(2.0)
        self.sock.close()


def _first_record_delay(stub, client, profile, seq=0):
    """Send one frame; seconds until its record reached the robot stub (inf if not within 1 s + slack)."""
    n0 = len(stub.records)
    t0 = time.perf_counter()
    client.send_profile(seq, profile)
    if not stub.wait_for(n0 + 1, SERVE_WITHIN_S + 1.0):
        return float("inf")
    return time.perf_counter() - t0


# --- stalled clients never block the others -----------------------------------------------------

@pytest.mark.parametrize("kind, timeout", [
    ("silent", "not a sensor: no well-formed hello or frame within 2.5 s of connecting"),
    ("trickle", "read timeout"),
    ("partial", "read timeout"),
    ("garbage", "not a sensor: no well-formed hello or frame within 2.5 s of connecting"),
])
def test_a_stalled_client_does_not_block_a_new_sensor(gauge, profiles, stub, caplog, kind, timeout):
    """A client that never sends a whole frame is never a sensor: it does not count against
    max_connections and is closed by the hello deadline (or the read timeout of a frame begun)."""
    server = PoseServer(gauge, robot=stub.address, idle_timeout_s=IDLE_S, read_timeout_s=READ_S,
                        hello_timeout_s=IDLE_S, freeze_gc=False)
    host, port = server.start()
    stalled = _Stalled(kind, (host, port), encode_frame(99, time.perf_counter_ns(), profiles[0]))
    try:
        with caplog.at_level(logging.INFO, logger="posekit.server"):
            assert wait_until(lambda: server.stats()["connections"] == 1)
            time.sleep(0.3)                            # the stalled client has begun stalling
            assert server.stats()["connected"] == 0    # not a sensor (yet)
            with SensorClient(host, port) as good:
                delay = _first_record_delay(stub, good, profiles[1])
                st = server.stats()
                print(f"{kind}: first record of the new sensor after {1e3 * delay:.1f} ms")
                assert delay <= SERVE_WITHIN_S, f"{kind}: new sensor served after {delay:.3f} s"
                assert st["connected"] == 1 and st["timeouts"] == 0      # the stalled one is still there
                for k in range(2, 6):
                    good.send_profile(k, profiles[k])
                assert stub.wait_for(5, WAIT_S)
            # ... and the stalled one is closed by its timeout, logged once.
            assert stalled.closed_by_server(IDLE_S + 3.0)
            assert wait_until(lambda: server.stats()["timeouts"] == 1)
    finally:
        stalled.close()
        server.stop()
    st = server.stats()
    assert st["timeouts"] == 1 and st["connections"] == 2 and st["disconnects"] == 2
    assert [r["status"] for r in stub.records] == ["ok"] * 5
    assert [r["seq"] for r in stub.records] == [0, 2, 3, 4, 5]
    lines = [r.getMessage() for r in caplog.records if f"127.0.0.1:{stalled.port} disconnected" in r.getMessage()]
    assert len(lines) == 1 and timeout in lines[0], lines
    if kind in ("trickle", "partial"):                 # the partial frame is counted, not processed
        assert st["reasons"]["truncated"] == 1


def test_silent_clients_never_take_a_sensors_place(gauge, profiles, stub):
    """Issue 28: 16 silent connects used to evict the sensors (and make `profiler replay` exit 1).
    Silent clients are pending, never sensors: a sensor connecting after 6 of them (4 places) is
    served, and the oldest pending ones are shed beyond max_pending, never a sensor."""
    server = PoseServer(gauge, robot=stub.address, max_connections=4, max_pending=3, freeze_gc=False)
    host, port = server.start()
    stalled = [_Stalled("silent", (host, port), b"") for _ in range(6)]
    try:
        assert wait_until(lambda: server.stats()["connections"] == 6)
        with SensorClient(host, port) as good:
            assert _first_record_delay(stub, good, profiles[0]) <= SERVE_WITHIN_S
            st = server.stats()
            assert st["connected"] == 1 and st["evictions"] == 0 and st["shed"] == 4     # 7 pending, 3 kept
            more = [_Stalled("silent", (host, port), b"") for _ in range(6)]
            try:
                good.send_profile(1, profiles[1])
                assert stub.wait_for(2, WAIT_S)
                assert server.stats()["connected"] == 1 and server.stats()["evictions"] == 0
            finally:
                for s in more:
                    s.close()
    finally:
        for s in stalled:
            s.close()
        server.stop()
    assert [r["status"] for r in stub.records] == ["ok", "ok"]


def test_a_sensor_is_never_evicted_for_an_unproven_or_silent_one(gauge, profiles, stub):
    """With a token: 2 places, both sensors streaming. A third client with the right token is
    refused (the two are busy), clients with a wrong or no token are refused, and a sensor that
    fell silent for hello_timeout_s is the only one a newcomer may replace."""
    server = PoseServer(gauge, robot=stub.address, token=TOKEN, max_connections=2, hello_timeout_s=0.5,
                        freeze_gc=False)
    host, port = server.start()
    a, b = SensorClient(host, port, token=TOKEN), SensorClient(host, port, token=TOKEN)
    try:
        a.send_profile(0, profiles[0])
        b.send_profile(1, profiles[1])
        assert stub.wait_for(2, WAIT_S) and server.stats()["connected"] == 2
        for token in (TOKEN, "wrong", None):
            c = socket.create_connection((host, port), timeout=2.0)
            if token is not None:
                c.sendall(encode_hello(token))
            c.sendall(encode_frame(9, time.perf_counter_ns(), profiles[2]))
            assert _Stalled.closed_by_server(argparse.Namespace(sock=c), WAIT_S)
            c.close()
            a.send_profile(2, profiles[2])                 # both sensors keep streaming
            b.send_profile(3, profiles[3])
        st = server.stats()
        assert st["connected"] == 2 and st["evictions"] == 0 and st["shed"] == 1 and st["auth_failures"] == 2
        # b falls silent; a newcomer with the token replaces it after hello_timeout_s
        time.sleep(0.7)
        a.send_profile(4, profiles[4])
        with SensorClient(host, port, token=TOKEN) as c:
            n0 = len(stub.records)
            c.send_profile(5, profiles[5])
            assert stub.wait_for(n0 + 1, WAIT_S)
            assert server.stats()["evictions"] == 1 and server.stats()["connected"] == 2
    finally:
        a.close()
        b.close()
        server.stop()


def test_a_flooding_sensor_is_slowed_and_the_others_served_in_turn(gauge, profiles, stub):
    """An insider (the right token) floods empty frames: it is read at max_rate_hz, its frames
    are checked without an estimate, and a streaming sensor keeps every frame."""
    server = PoseServer(gauge, robot=stub.address, token=TOKEN, max_rate_hz=500.0, rate_burst=8, freeze_gc=False)
    host, port = server.start()
    flood = socket.create_connection((host, port), timeout=2.0)
    flood.sendall(encode_hello(TOKEN))
    empty = encode_frame(7, time.perf_counter_ns(), np.zeros((0, 2))) * 4000
    stop = threading.Event()

    def pour():
        try:
            while not stop.is_set():
                flood.sendall(empty)
        except OSError:
            pass

    t = threading.Thread(target=pour, daemon=True)
    t.start()
    try:
        with SensorClient(host, port, token=TOKEN) as good:
            t0 = time.monotonic()
            for k in range(20):
                good.send_profile(1000 + k, profiles[k % 8])
                time.sleep(0.05)
            elapsed = time.monotonic() - t0
            assert wait_until(lambda: sum(r["seq"] >= 1000 for r in stub.records) == 20)
        st = server.stats()
    finally:
        stop.set()
        flood.close()
        t.join(2.0)
        server.stop()
    good_records = [r for r in stub.records if r["seq"] >= 1000]
    assert [r["status"] for r in good_records] == ["ok"] * 20
    storms = st["reasons"]["nan_storm"]
    assert st["rate_limited"] > 0 and storms <= 500 * (elapsed + 1.0) + 8      # the flood read at <= 500 Hz


def test_default_timeouts_are_sane(gauge):
    server = PoseServer(gauge, freeze_gc=False)
    assert server.idle_timeout_s == 30.0 and server.read_timeout_s == 2.0 and server.max_dt_s == 10.0
    for bad in (dict(idle_timeout_s=0.0), dict(read_timeout_s=float("nan")), dict(max_dt_s=-1.0),
                dict(idle_timeout_s=1e9)):
        with pytest.raises(ConfigError, match=r"must be a number of seconds in \[0\.05, 86400\]"):
            PoseServer(gauge, **bad)
    with pytest.raises(ConfigError, match="max_connections must be an integer >= 1, got 0"):
        PoseServer(gauge, max_connections=0)
    assert server.hello_timeout_s == 2.0 and server.max_pending == 64 and server.max_rate_hz == 4000.0
    with pytest.raises(ConfigError, match="max_pending must be an integer >= 1, got True"):
        PoseServer(gauge, max_pending=True)
    with pytest.raises(ConfigError, match=r"max_rate_hz must be a number in \[1, 1e6\] Hz, got 0"):
        PoseServer(gauge, max_rate_hz=0)
    with pytest.raises(ConfigError, match=r"hello_timeout_s must be a number of seconds in \[0\.05, 86400\]"):
        PoseServer(gauge, hello_timeout_s=0.0)


# --- the token ----------------------------------------------------------------------------------

def test_hello_wire_format():
    data = encode_hello(TOKEN)
    assert data[:4] == HELLO_MAGIC and len(data) == 12 + len(TOKEN)
    assert decode_hello(data + b"PKPF...") == Hello(TOKEN.encode(), len(data))
    for k in range(len(data)):                          # any prefix: wait for more
        assert decode_hello(data[:k]) is None
    assert decode_hello(b"PKPF").reason == NO_HELLO and decode_hello(b"x").reason == NO_HELLO
    assert decode_hello(HELLO_HEADER.pack(HELLO_MAGIC, 2, 0, 5)).reason == UNKNOWN_VERSION
    assert decode_hello(HELLO_HEADER.pack(HELLO_MAGIC, 1, 0, 2**32 - 1)).reason == OVERSIZED
    assert decode_hello(HELLO_HEADER.pack(HELLO_MAGIC, 1, 0, 0)).reason == OVERSIZED
    with pytest.raises(ConfigError, match="token must be 1..1024 bytes, got 0"):
        encode_hello("")
    with pytest.raises(ConfigError, match="token must be 1..1024 bytes, got 1025"):
        encode_hello(b"a" * (MAX_TOKEN_BYTES + 1))


def test_token_good_bad_missing(gauge, profiles, stub, caplog):
    server = PoseServer(gauge, robot=stub.address, token=TOKEN, read_timeout_s=READ_S, freeze_gc=False)
    host, port = server.start()
    try:
        with caplog.at_level(logging.WARNING, logger="posekit.server"):
            with SensorClient(host, port, token=TOKEN) as good:
                assert _first_record_delay(stub, good, profiles[0], seq=0) <= SERVE_WITHIN_S
            refused = []
            for token in ("wrong horse battery staple", TOKEN[:-1], TOKEN + "x", None):
                bad = SensorClient(host, port, token=token)
                try:
                    bad.send_profile(1, profiles[1])            # the server has closed it, or will at once
                except OSError:
                    pass
                refused.append(bad)
            assert wait_until(lambda: server.stats()["auth_failures"] == 4)
            for bad in refused:
                bad._sock.settimeout(2.0)
                try:
                    assert bad._sock.recv(1) == b""
                except ConnectionResetError:
                    pass
                bad.close()
            # a malformed hello and a hello that never completes are refused too
            raw = socket.create_connection((host, port), timeout=2.0)
            raw.sendall(HELLO_HEADER.pack(HELLO_MAGIC, 1, 0, 10**9))
            assert wait_until(lambda: server.stats()["auth_failures"] == 5)
            raw.close()
            slow = _Stalled("hello_trickle", (host, port), b"")
            assert slow.closed_by_server(READ_S + 3.0)
            slow.close()
            with SensorClient(host, port, token=TOKEN.encode()) as again:      # bytes work as well
                again.send_profile(2, profiles[2])
                assert stub.wait_for(2, WAIT_S)
    finally:
        server.stop()
    st = server.stats()
    assert st["auth_failures"] == 5 and st["timeouts"] == 1
    assert st["reasons"] == {"truncated": 1}                  # the hello cut short by the read timeout
    assert [r["seq"] for r in stub.records] == [0, 2]       # nothing from the refused clients
    text = "\n".join(r.getMessage() for r in caplog.records)
    assert "refused: wrong token" in text and "more 'auth' event(s)" in text     # rate-limited
    assert TOKEN not in text                                  # the secret is never logged


def test_loopback_default_needs_no_token_and_skips_one(gauge, profiles, stub):
    server = PoseServer(gauge, robot=stub.address, freeze_gc=False)
    host, port = server.start()
    try:
        with SensorClient(host, port) as plain, SensorClient(host, port, token="anything") as greeting:
            plain.send_profile(0, profiles[0])
            greeting.send_profile(1, profiles[1])
            assert stub.wait_for(2, WAIT_S)
    finally:
        server.stop()
    assert sorted(r["seq"] for r in stub.records) == [0, 1]
    assert server.stats()["auth_failures"] == 0 and server.stats()["rejected"] == 0


def test_remote_needs_a_token(gauge, profiles, stub):
    with pytest.raises(ConfigError, match=r"allow_remote=True \(--allow-remote\) needs a token"):
        PoseServer(gauge, allow_remote=True)
    with pytest.raises(ConfigError, match="token must be 1..1024 bytes"):
        PoseServer(gauge, allow_remote=True, token="")
    # allowed with one (bound on loopback here: a test opens no port to the network)
    server = PoseServer(gauge, robot=stub.address, allow_remote=True, token=TOKEN, freeze_gc=False)
    host, port = server.start()
    try:
        with SensorClient(host, port, token=TOKEN) as c:
            c.send_profile(0, profiles[0])
            assert stub.wait_for(1, WAIT_S)
    finally:
        server.stop()


def test_token_file(tmp_path):
    f = tmp_path / "token"
    f.write_text(f"  {TOKEN}\n\n")
    assert read_token_file(f) == TOKEN
    f.write_bytes(b"\xef\xbb\xbfs\xc3\xa9cret\r\n")           # BOM and CRLF: UTF-8 still
    assert read_token_file(f) == "s\u00e9cret"
    cases = [
        (b"", "empty"),
        (b" \n\t\n", "empty"),
        (b"\xff\xfe" + "secret".encode("utf-16-le"), "UTF-16"),
        (b"s\xe9cret\n", "not UTF-8"),
        (b"a" * 2000, "the token is 2000 bytes long; expected at most 1024"),
        (b"a" * 5000, "limit for a token file"),
    ]
    for data, needle in cases:
        f.write_bytes(data)
        with pytest.raises(InputFileError, match=needle):
            read_token_file(f)
    with pytest.raises(InputFileError, match="no such file"):
        read_token_file(tmp_path / "missing")
    with pytest.raises(InputFileError, match="is a folder"):
        read_token_file(tmp_path)


# --- DT does not trust the sensor's stamps --------------------------------------------------------

def test_wild_stamps_keep_dt_sane(gauge, profiles):
    """Stamps that jump backwards and forwards wildly: DT stays within [0, wall time], the
    wild ones are counted and their DT is unknown; the poses are still computed."""
    rng = np.random.default_rng(11)
    t_start = time.perf_counter_ns()
    server = PoseServer(gauge, queue_size=1000, freeze_gc=False)
    host, port = server.start()
    n, wild, last_fresh = 200, 0, None
    try:
        with SensorClient(host, port) as c:
            for k in range(n):
                now = time.perf_counter_ns()
                kind = rng.choice(["fresh", "past", "future", "zero", "max", "back"], p=[.5, .1, .1, .1, .1, .1])
                if kind == "back" and last_fresh is None:
                    kind = "fresh"
                stamp = {"fresh": now,
                         "past": now - int(rng.uniform(11, 1e6) * 1e9),        # older than max_dt_s
                         "future": now + int(rng.uniform(1, 1e6) * 1e9),
                         "zero": 0,
                         "max": 2**64 - 1,
                         "back": (last_fresh or 0) - int(rng.integers(1, 10**6))}[kind]
                stamp = max(0, stamp)
                if kind == "fresh":
                    last_fresh = stamp
                else:
                    wild += 1
                c.send_profile(k, profiles[k % len(profiles)], t_sensor_ns=stamp)
        assert wait_until(lambda: server.stats()["processed"] == n)
    finally:
        server.stop()
    wall_ms = (time.perf_counter_ns() - t_start) * 1e-6
    st, dt = server.stats(), server.timings()["DT"]
    assert st["ok"] == n and st["bad_stamps"] == wild and wild > 50
    good = dt[np.isfinite(dt)]
    assert len(good) == n - wild
    assert np.all(good >= 0) and np.all(good <= wall_ms)
    assert 0 <= np.mean(good) <= wall_ms


# --- CLI --------------------------------------------------------------------------------------------

def _serve_args(*argv):
    from posekit.cli.profiler_serve import add_serve_parser
    p = argparse.ArgumentParser(prog="posekit profiler")
    add_serve_parser(p.add_subparsers(dest="verb"))
    return p.parse_args(["serve", "--gauge", "demo-5", "--listen", "127.0.0.1:0", *argv])


@pytest.mark.parametrize("argv, error, needle", [
    (["--status-every-s", "0.01"], ConfigError, "--status-every-s must be between 0.1 and 86400 seconds, got 0.01"),
    (["--status-every-s", "nan"], ConfigError, "--status-every-s must be between 0.1 and 86400 seconds, got nan"),
    (["--idle-timeout-s", "0"], ConfigError, "--idle-timeout-s must be between 0.05 and 86400 seconds, got 0"),
    (["--read-timeout-s", "-1"], ConfigError, "--read-timeout-s must be between 0.05 and 86400 seconds, got -1"),
    (["--allow-remote"], ConfigError, "--allow-remote needs --token-file FILE"),
    (["--allow-remote", "--token-file", "/nonexistent/token"], InputFileError, "no such file"),
])
def test_cli_serve_bad_flags_are_one_line_errors(argv, error, needle):
    args = _serve_args(*argv)
    with pytest.raises(error, match=needle) as info:
        args.func(args)
    assert "\n" not in str(info.value)


def test_cli_serve_with_a_token_file(profiles, stub, tmp_path, capsys):
    (tmp_path / "token").write_text(TOKEN + "\n")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    args = _serve_args("--token-file", str(tmp_path / "token"), "--duration-s", "1.5", "--status-every-s", "0.5",
                       "--robot", f"{stub.address[0]}:{stub.address[1]}", "--idle-timeout-s", "5", "--queue", "64")
    args.listen = f"127.0.0.1:{port}"

    def sensor():
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline:
            try:
                client = SensorClient("127.0.0.1", port, timeout_s=0.5, token=TOKEN)
                break
            except ConfigError:
                time.sleep(0.05)
        else:
            return
        with client:
            for k in range(5):
                client.send_profile(k, profiles[k])
        try:
            SensorClient("127.0.0.1", port, token="guess").send_profile(9, profiles[0])
        except (ConfigError, OSError):
            pass

    t = threading.Thread(target=sensor, daemon=True)
    t.start()
    assert args.func(args) == 0
    t.join(5.0)
    out = capsys.readouterr().out
    assert "sensors must present the token" in out
    assert "processed 5 (ok 5, errors 0)" in out and "refused 1" in out
    assert sorted(r["seq"] for r in stub.records) == list(range(5))

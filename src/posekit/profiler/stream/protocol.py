"""Wire formats of the real-time stream: binary profile frames in, JSON lines out.

The paper's architecture (§II-A): the profiler controller forwards each triggered
profile to the processing unit over TCP; the processing unit answers the robot
controller over TCP. posekit speaks two formats:

**Profile frame** (sensor → :class:`~posekit.profiler.stream.server.PoseServer`), all fields
little-endian, a 24-byte header followed by the points:

======  =====  ==============  ========================================================
offset  bytes  field           meaning
======  =====  ==============  ========================================================
0       4      magic           ``b"PKPF"``; a frame starts here (resynchronisation key)
4       2      version         u16, ``1``; any other value is rejected
6       2      flags           u16, reserved: sent as 0, ignored by a version-1 decoder
8       4      seq             u32 sequence number of the profile (wraps at 2³²)
12      8      t_sensor_ns     u64 time stamp of the profile, ns (see below)
20      4      point_count     u32 number N of points, ``0 <= N <= MAX_POINTS``
24      8·N    points          N × (x, z) float32, mm, in F, scan order; NaN = no return
======  =====  ==============  ========================================================

A frame is ``24 + 8 N`` bytes: 25,624 bytes for the 3,200 points of an LJ-X8400
profile. ``t_sensor_ns`` is read on the clock of :func:`time.perf_counter_ns` (on Linux
``CLOCK_MONOTONIC``, shared by every process of the machine), so a sensor process on the
same machine can stamp it and the server can subtract it from its own receive time; a
remote sensor's stamps are only meaningful after a clock offset is applied.

:class:`FrameDecoder` turns a byte stream cut at arbitrary points into frames. On a bad
magic, an unknown version or an oversized point count it reports one
:class:`FrameError` and skips bytes until the next magic (resynchronisation); the bytes
it skips are part of that one error, not new ones. It never holds more than one frame
(``24 + 8 * MAX_POINTS`` bytes) plus the chunk being fed. A frame shorter than its header
announces cannot be told from the start of the next one: it swallows the head of the next
frame, whose tail then fails the magic check (one error, two frames lost).

**Hello** (sensor → server, once, the first bytes of a connection): the shared secret of a
server that requires one (``--token-file``; always when it accepts remote sensors). A
12-byte header and the token:

======  =====  ==============  ========================================================
offset  bytes  field           meaning
======  =====  ==============  ========================================================
0       4      magic           ``b"PKHI"``
4       2      version         u16, ``1``
6       2      flags           u16, reserved: sent as 0, ignored
8       4      token_length    u32 number L of token bytes, ``1 <= L <= MAX_TOKEN_BYTES``
12      L      token           the token, UTF-8
======  =====  ==============  ========================================================

The server does not answer: with the right token the frames that follow are served; with
a wrong or missing one it closes the connection (the sensor's next send fails). A server
without a token skips a hello, so a sensor configured with one works with both. The token
is a password sent in the clear, not encryption: anyone on the path can read it.
:func:`decode_hello` reads it.

**Robot records** (server → robot interface): one JSON object per line, UTF-8,
``\\n``-terminated: :mod:`~posekit.profiler.stream.lines`.
"""

import struct
import time
from dataclasses import dataclass

import numpy as np

from ...errors import ConfigError, ProfileError

__all__ = ["MAGIC", "VERSION", "HEADER", "HEADER_SIZE", "MAX_POINTS", "MAX_FRAME_BYTES",
           "BAD_MAGIC", "UNKNOWN_VERSION", "OVERSIZED", "TRUNCATED",
           "Frame", "FrameError", "FrameDecoder", "encode_frame",
           "HELLO_MAGIC", "HELLO_HEADER", "HELLO_HEADER_SIZE", "MAX_TOKEN_BYTES", "NO_HELLO",
           "Hello", "encode_hello", "decode_hello"]

MAGIC = b"PKPF"
VERSION = 1
#: ``struct`` layout of the header: magic, version, flags, seq, t_sensor_ns, point_count.
HEADER = struct.Struct("<4sHHIQI")
HEADER_SIZE = HEADER.size                                  # 24
#: Largest point count a frame may announce; more is an ``oversized`` frame.
MAX_POINTS = 8192
MAX_FRAME_BYTES = HEADER_SIZE + 8 * MAX_POINTS
_U32 = 2**32
_U64 = 2**64
_POINT_DTYPE = np.dtype("<f4")

# Reasons of a FrameError (the server adds "nan_storm" for frames it refuses to process).
BAD_MAGIC = "bad_magic"
UNKNOWN_VERSION = "unknown_version"
OVERSIZED = "oversized"
TRUNCATED = "truncated"


@dataclass(frozen=True, eq=False)
class Frame:
    """One decoded profile frame.

    Attributes
    ----------
    seq : int
        Sequence number (u32).
    t_sensor_ns : int
        The sensor's time stamp, ns (the clock of :func:`time.perf_counter_ns`).
    points : ndarray, shape (N, 2), float64, C-contiguous
        Points (x, z) in the profiler frame F, mm, scan order; NaN = no return.
    t_recv_ns : int
        :func:`time.perf_counter_ns` when the chunk holding the frame's last byte
        arrived.
    """

    seq: int
    t_sensor_ns: int
    points: np.ndarray
    t_recv_ns: int


@dataclass(frozen=True)
class FrameError:
    """A malformed stretch of the byte stream, reported by :meth:`FrameDecoder.feed`.

    Attributes
    ----------
    reason : str
        ``bad_magic``, ``unknown_version``, ``oversized`` or ``truncated`` (the stream
        ended inside a frame).
    detail : str
        One line for a log: what arrived and what was expected.
    offset : int
        Position of the malformed bytes in the stream since the decoder was created.
    """

    reason: str
    detail: str
    offset: int


def encode_frame(seq: int, t_sensor_ns: int, points_xz) -> bytes:
    """Encode one profile as a version-1 frame.

    Parameters
    ----------
    seq : int
        Sequence number, ``0 <= seq < 2**32``.
    t_sensor_ns : int
        Time stamp, ns, ``0 <= t < 2**64`` (the clock of :func:`time.perf_counter_ns`).
    points_xz : array_like, shape (N, 2)
        Points (x, z) in F, mm, scan order; NaN = no return; ``N <= MAX_POINTS``.
        Sent as float32 (about 0.5 µm resolution at 600 mm).

    Returns
    -------
    bytes
        ``24 + 8 N`` bytes.

    Raises
    ------
    ProfileError
        If the points are not an (N, 2) numeric array or N exceeds ``MAX_POINTS``.
    ConfigError
        If ``seq`` or ``t_sensor_ns`` does not fit its field.

    Examples
    --------
    >>> data = encode_frame(7, 1_000, [[0.0, 400.0], [float("nan"), float("nan")]])
    >>> len(data), data[:4]
    (40, b'PKPF')
    >>> [f.seq for f in FrameDecoder().feed(data)]
    [7]
    """
    try:
        pts = np.asarray(points_xz, dtype=_POINT_DTYPE)
    except (TypeError, ValueError):
        raise ProfileError("frame points: expected an (N, 2) array of (x, z) in mm, got non-numeric data") from None
    if pts.ndim != 2 or pts.shape[1] != 2:
        if pts.size == 0:
            pts = pts.reshape(0, 2)
        else:
            raise ProfileError(f"frame points: expected shape (N, 2) of (x, z) in mm, got {pts.shape}")
    if pts.shape[0] > MAX_POINTS:
        raise ProfileError(f"frame points: {pts.shape[0]} points exceed the protocol's MAX_POINTS = {MAX_POINTS}")
    if not 0 <= int(seq) < _U32:
        raise ConfigError(f"frame seq must be in [0, 2**32), got {seq}")
    if not 0 <= int(t_sensor_ns) < _U64:
        raise ConfigError(f"frame t_sensor_ns must be in [0, 2**64), got {t_sensor_ns}")
    return HEADER.pack(MAGIC, VERSION, 0, int(seq), int(t_sensor_ns), pts.shape[0]) + pts.tobytes()


class FrameDecoder:
    """Incremental decoder of a stream of frames, robust to any recv boundaries.

    Feed it whatever ``recv`` returned; it returns the frames completed by that chunk and
    a :class:`FrameError` for each malformed stretch, in stream order. Its buffer never
    holds more than ``MAX_FRAME_BYTES`` between calls, unless ``max_frames`` stopped a call
    early (then it also holds the rest of that chunk, decoded by the next call).

    Attributes
    ----------
    bytes_fed : int
        Bytes fed since creation.
    bytes_discarded : int
        Bytes skipped while resynchronising.
    """

    def __init__(self):
        self._buf = bytearray()
        self._base = 0                 # stream offset of _buf[0]
        self._resync = False           # skipping bytes of an already reported error
        self.bytes_fed = 0
        self.bytes_discarded = 0

    @property
    def buffered(self) -> int:
        """Bytes held waiting for the rest of a frame."""
        return len(self._buf)

    def has_frame(self) -> bool:
        """True when the buffer starts with a complete, well-formed frame (left by ``max_frames``)."""
        buf = self._buf
        if self._resync or len(buf) < HEADER_SIZE or buf[:4] != MAGIC:
            return False
        _, version, _flags, _seq, _t, count = HEADER.unpack_from(buf, 0)
        return version == VERSION and count <= MAX_POINTS and len(buf) >= HEADER_SIZE + 8 * count

    @property
    def mid_frame(self) -> bool:
        """True when the buffer holds the start of an incomplete frame."""
        return bool(self._buf) and not self._resync

    def feed(self, data, t_recv_ns: int | None = None, max_frames: int | None = None) -> list:
        """Decode the frames completed by ``data``.

        Parameters
        ----------
        data : bytes-like
            The next bytes of the stream (any length, including 0: decode what is buffered).
        t_recv_ns : int, optional
            Arrival time of ``data`` (:func:`time.perf_counter_ns`); default: now.
        max_frames : int, optional
            Decode at most this many frames; the bytes after the last one stay buffered
            (the server's per-connection rate limit: a flood is not decoded faster than it
            is allowed to be processed).

        Returns
        -------
        list of Frame and FrameError
            In stream order.
        """
        if t_recv_ns is None:
            t_recv_ns = time.perf_counter_ns()
        buf = self._buf
        buf += data
        self.bytes_fed += len(data)
        out = []
        pos = 0
        end = len(buf)
        budget = -1 if max_frames is None else int(max_frames)
        while pos < end and budget != 0:
            if self._resync:
                i = buf.find(MAGIC, pos)
                if i < 0:
                    # Keep a tail that may be the start of a magic split across chunks.
                    keep = 0
                    for k in (3, 2, 1):
                        if end - pos >= k and buf[end - k:end] == MAGIC[:k]:
                            keep = k
                            break
                    self.bytes_discarded += end - keep - pos
                    pos = end - keep
                    break
                self.bytes_discarded += i - pos
                pos = i
                self._resync = False
            avail = end - pos
            n = min(avail, 4)
            if buf[pos:pos + n] != MAGIC[:n]:
                out.append(FrameError(BAD_MAGIC, f"expected magic {MAGIC!r}, got {bytes(buf[pos:pos + n])!r}",
                                      self._base + pos))
                self._resync = True
                pos += 1
                continue
            if avail < HEADER_SIZE:
                break
            _, version, _flags, seq, t_sensor, count = HEADER.unpack_from(buf, pos)
            if version != VERSION:
                out.append(FrameError(UNKNOWN_VERSION, f"frame version {version}, this decoder reads {VERSION}",
                                      self._base + pos))
                self._resync = True
                pos += 4
                continue
            if count > MAX_POINTS:
                out.append(FrameError(OVERSIZED, f"frame announces {count} points, at most {MAX_POINTS} allowed",
                                      self._base + pos))
                self._resync = True
                pos += 4
                continue
            size = HEADER_SIZE + 8 * count
            if avail < size:
                break
            pts = np.frombuffer(buf, dtype=_POINT_DTYPE, count=2 * count, offset=pos + HEADER_SIZE)
            with np.errstate(invalid="ignore"):          # signalling NaNs in the data are NaN too
                points = pts.astype(np.float64).reshape(count, 2)
            del pts                    # release the export of buf before it is resized
            out.append(Frame(seq, t_sensor, points, t_recv_ns))
            pos += size
            budget -= 1
        if pos:
            del buf[:pos]
            self._base += pos
        return out

    def flush(self) -> FrameError | None:
        """End of stream: report an incomplete frame (``truncated``) and reset the buffer.

        Returns
        -------
        FrameError or None
            None when the stream ended on a frame boundary (or inside bytes already
            reported).
        """
        err = None
        if self._buf and not self._resync:
            err = FrameError(TRUNCATED, f"stream ended {len(self._buf)} bytes into a frame", self._base)
        self.bytes_discarded += len(self._buf)
        self._base += len(self._buf)
        self._buf.clear()
        self._resync = False
        return err


# --------------------------------------------------------------------------- hello

HELLO_MAGIC = b"PKHI"
#: ``struct`` layout of the hello header: magic, version, flags, token_length.
HELLO_HEADER = struct.Struct("<4sHHI")
HELLO_HEADER_SIZE = HELLO_HEADER.size                      # 12
#: Longest token a hello may carry, bytes.
MAX_TOKEN_BYTES = 1024
#: Reason of a :class:`FrameError` from :func:`decode_hello`: the stream does not start with a hello.
NO_HELLO = "no_hello"


@dataclass(frozen=True)
class Hello:
    """A decoded hello.

    Attributes
    ----------
    token : bytes
        The token as sent (UTF-8).
    size : int
        Bytes of the stream the hello took; the first frame starts there.
    """

    token: bytes
    size: int


def _token_bytes(token) -> bytes:
    if isinstance(token, str):
        token = token.encode("utf-8")
    if not isinstance(token, bytes | bytearray):
        raise ConfigError(f"token must be a str or bytes, got {type(token).__name__}")
    if not 1 <= len(token) <= MAX_TOKEN_BYTES:
        raise ConfigError(f"token must be 1..{MAX_TOKEN_BYTES} bytes, got {len(token)}")
    return bytes(token)


def encode_hello(token: str | bytes) -> bytes:
    """The hello carrying ``token``: send it first on a connection.

    Parameters
    ----------
    token : str or bytes
        The shared secret (a str is sent as UTF-8), 1 to ``MAX_TOKEN_BYTES`` bytes.

    Raises
    ------
    ConfigError
        If the token is empty, too long, or neither str nor bytes.

    Examples
    --------
    >>> data = encode_hello("s3cret")
    >>> data[:4], len(data)
    (b'PKHI', 18)
    >>> decode_hello(data)
    Hello(token=b's3cret', size=18)
    """
    tok = _token_bytes(token)
    return HELLO_HEADER.pack(HELLO_MAGIC, VERSION, 0, len(tok)) + tok


def decode_hello(data) -> Hello | FrameError | None:
    """Read a hello at the start of ``data`` (the first bytes of a connection).

    Parameters
    ----------
    data : bytes-like
        The bytes received so far.

    Returns
    -------
    Hello
        A complete hello; its ``size`` bytes are consumed.
    FrameError
        ``no_hello`` (the stream starts with something else), ``unknown_version`` or
        ``oversized`` (a token length outside ``1..MAX_TOKEN_BYTES``), decided from the
        first bytes that show it, without waiting for more.
    None
        More bytes are needed (never more than ``HELLO_HEADER_SIZE + MAX_TOKEN_BYTES``).

    Examples
    --------
    >>> decode_hello(b"PKH") is None
    True
    >>> decode_hello(b"PKPF").reason
    'no_hello'
    """
    n = min(len(data), 4)
    if bytes(data[:n]) != HELLO_MAGIC[:n]:
        return FrameError(NO_HELLO, f"expected a hello {HELLO_MAGIC!r} first, got {bytes(data[:n])!r}", 0)
    if len(data) < HELLO_HEADER_SIZE:
        return None
    _, version, _flags, length = HELLO_HEADER.unpack_from(data, 0)
    if version != VERSION:
        return FrameError(UNKNOWN_VERSION, f"hello version {version}, this decoder reads {VERSION}", 0)
    if not 1 <= length <= MAX_TOKEN_BYTES:
        return FrameError(OVERSIZED, f"hello announces a {length}-byte token, expected 1..{MAX_TOKEN_BYTES}", 0)
    size = HELLO_HEADER_SIZE + length
    if len(data) < size:
        return None
    return Hello(bytes(data[HELLO_HEADER_SIZE:size]), size)

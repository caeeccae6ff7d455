"""Wire formats of the real-time stream: frame round trips, arbitrary splits, resync, JSON lines."""

import itertools
import json
import struct

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from posekit.errors import ConfigError, ProfileError
from posekit.profiler.stream.lines import LineDecoder, encode_command
from posekit.profiler.stream.protocol import (
    BAD_MAGIC,
    HEADER,
    HEADER_SIZE,
    MAGIC,
    MAX_FRAME_BYTES,
    MAX_POINTS,
    OVERSIZED,
    TRUNCATED,
    UNKNOWN_VERSION,
    Frame,
    FrameDecoder,
    FrameError,
    encode_frame,
)

PROPS = settings(max_examples=40, deadline=None)
KNOWN_REASONS = {BAD_MAGIC, UNKNOWN_VERSION, OVERSIZED, TRUNCATED}

# Reference bytes, derived by hand from the header table: seq 1, t 2 ns, one point (1.0, -2.0).
ONE_POINT_FRAME = (b"PKPF" + b"\x01\x00" + b"\x00\x00" + b"\x01\x00\x00\x00" + b"\x02" + b"\x00" * 7
                   + b"\x01\x00\x00\x00" + b"\x00\x00\x80\x3f" + b"\x00\x00\x00\xc0")


def _points(n, seed, nan_fraction=0.2):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-150.0, 600.0, (n, 2))
    pts[rng.random(n) < nan_fraction] = np.nan
    return pts


def _frames(items):
    return [i for i in items if isinstance(i, Frame)]


def _errors(items):
    return [i for i in items if isinstance(i, FrameError)]


def _decode_all(chunks):
    dec = FrameDecoder()
    out = []
    for c in chunks:
        out += dec.feed(c)
    return dec, out


def _scrub(garbage: bytes) -> bytes:
    """Random bytes that contain no magic (so they are garbage, not a fake frame)."""
    return garbage.replace(MAGIC, b"pkpf")


# --- reference layout -------------------------------------------------------------------

def test_header_layout_matches_the_documented_table():
    assert HEADER_SIZE == 24
    assert encode_frame(1, 2, [[1.0, -2.0]]) == ONE_POINT_FRAME
    assert MAX_FRAME_BYTES == 24 + 8 * 8192


def test_lj_x8400_profile_is_25624_bytes():
    assert len(encode_frame(0, 0, np.zeros((3200, 2)))) == 25_624


# --- round trips ------------------------------------------------------------------------

@PROPS
@given(seq=st.integers(0, 2**32 - 1), t=st.integers(0, 2**64 - 1), n=st.integers(0, MAX_POINTS),
       seed=st.integers(0, 2**32 - 1), nan_fraction=st.sampled_from([0.0, 0.3, 1.0]))
@example(seq=0, t=0, n=0, seed=0, nan_fraction=0.0)
@example(seq=2**32 - 1, t=2**64 - 1, n=MAX_POINTS, seed=1, nan_fraction=0.3)
def test_frame_round_trip(seq, t, n, seed, nan_fraction):
    pts = _points(n, seed, nan_fraction)
    data = encode_frame(seq, t, pts)
    assert len(data) == HEADER_SIZE + 8 * n
    dec, out = _decode_all([data])
    assert len(out) == 1 and isinstance(out[0], Frame)
    f = out[0]
    assert (f.seq, f.t_sensor_ns) == (seq, t)
    assert f.points.shape == (n, 2) and f.points.dtype == np.float64 and f.points.flags.c_contiguous
    np.testing.assert_array_equal(f.points, pts.astype(np.float32).astype(np.float64))   # NaNs in place
    assert dec.buffered == 0


@PROPS
@given(sizes=st.lists(st.integers(0, 300), min_size=1, max_size=6), cuts=st.lists(st.integers(0, 20_000), max_size=12))
def test_any_chunking_gives_the_same_frames(sizes, cuts):
    data = b"".join(encode_frame(k, 1000 + k, _points(n, k)) for k, n in enumerate(sizes))
    bounds = sorted({min(c, len(data)) for c in cuts} | {0, len(data)})
    chunks = [data[a:b] for a, b in itertools.pairwise(bounds)]
    _, out = _decode_all(chunks)
    assert not _errors(out)
    assert [f.seq for f in out] == list(range(len(sizes)))
    assert [f.points.shape[0] for f in out] == sizes


def test_every_split_point_of_two_frames():
    a = encode_frame(10, 111, _points(3, 0))
    b = encode_frame(11, 222, _points(5, 1))
    data = a + b
    for i in range(len(data) + 1):
        _, out = _decode_all([data[:i], data[i:]])
        assert [(f.seq, f.t_sensor_ns) for f in out] == [(10, 111), (11, 222)], i
    for i in range(len(data) + 1):                       # and every pair of split points
        for j in range(i, len(data) + 1):
            _, out = _decode_all([data[:i], data[i:j], data[j:]])
            assert [f.seq for f in out] == [10, 11], (i, j)


def test_byte_by_byte():
    data = encode_frame(1, 5, _points(4, 2)) + encode_frame(2, 6, _points(0, 3))
    _, out = _decode_all([data[i:i + 1] for i in range(len(data))])
    assert [f.seq for f in out] == [1, 2]


def test_t_recv_is_the_arrival_of_the_last_byte():
    data = encode_frame(1, 5, _points(4, 2))
    dec = FrameDecoder()
    assert dec.feed(data[:-1], t_recv_ns=100) == []
    (f,) = dec.feed(data[-1:], t_recv_ns=200)
    assert f.t_recv_ns == 200


# --- malformed streams ------------------------------------------------------------------

def test_resync_after_garbage():
    good1 = encode_frame(1, 1, _points(6, 1))
    good2 = encode_frame(2, 2, _points(7, 2))
    garbage = b"hello, this is not a frame" + b"PKP"       # ends in a partial magic
    _, out = _decode_all([garbage + good1 + b"\x00" * 100 + good2])
    assert [type(i) for i in out] == [FrameError, Frame, FrameError, Frame]
    assert [e.reason for e in _errors(out)] == [BAD_MAGIC, BAD_MAGIC]
    assert _errors(out)[0].offset == 0
    assert _errors(out)[1].offset == len(garbage) + len(good1)
    assert [f.seq for f in _frames(out)] == [1, 2]


def test_resync_with_the_magic_split_across_chunks():
    good = encode_frame(9, 9, _points(3, 3))
    stream = b"xyz" + good
    for i in range(len(stream) + 1):
        _, out = _decode_all([stream[:i], stream[i:]])
        assert [e.reason for e in _errors(out)] == [BAD_MAGIC], i
        assert [f.seq for f in _frames(out)] == [9], i


def test_unknown_version_is_one_error_and_its_payload_is_skipped():
    bad = bytearray(encode_frame(5, 5, _points(50, 5)))
    struct.pack_into("<H", bad, 4, 2)
    good = encode_frame(6, 6, _points(5, 6))
    _, out = _decode_all([bytes(bad) + good])
    (err,) = _errors(out)
    assert err.reason == UNKNOWN_VERSION and "version 2" in err.detail
    assert [f.seq for f in _frames(out)] == [6]


def test_oversized_count_is_reported_without_waiting_for_its_payload():
    header = HEADER.pack(MAGIC, 1, 0, 7, 7, MAX_POINTS + 1)
    good = encode_frame(8, 8, _points(5, 8))
    dec = FrameDecoder()
    out = dec.feed(header)
    assert [e.reason for e in out] == [OVERSIZED] and str(MAX_POINTS + 1) in out[0].detail
    out = dec.feed(b"\x00" * 4000 + good)                # its would-be payload, then a frame
    assert [f.seq for f in _frames(out)] == [8] and not _errors(out)
    header = HEADER.pack(MAGIC, 1, 0, 7, 7, 2**32 - 1)
    assert [e.reason for e in FrameDecoder().feed(header)] == [OVERSIZED]


def test_max_points_is_not_oversized():
    header = HEADER.pack(MAGIC, 1, 0, 7, 7, MAX_POINTS)
    dec = FrameDecoder()
    assert dec.feed(header) == []
    assert dec.mid_frame


def test_short_frame_swallows_the_head_of_the_next_and_resyncs():
    """A frame with fewer points than announced: documented loss of the next frame, then resync."""
    short = encode_frame(1, 1, _points(10, 1))[:-8 * 4]       # 4 points missing
    nxt = encode_frame(2, 2, _points(10, 2))
    after = encode_frame(3, 3, _points(10, 3))
    _, out = _decode_all([short + nxt + after])
    assert [f.seq for f in _frames(out)] == [1, 3]
    assert [e.reason for e in _errors(out)] == [BAD_MAGIC]


def test_back_to_back_garbage_is_one_error():
    """Stretches without a valid magic between them cannot be told apart: one error."""
    bad = bytearray(encode_frame(1, 1, _points(5, 1)))
    bad[0] = ord("X")
    _, out = _decode_all([b"junk" + bytes(bad) + b"more junk" + encode_frame(2, 2, _points(5, 2))])
    assert [e.reason for e in _errors(out)] == [BAD_MAGIC]
    assert [f.seq for f in _frames(out)] == [2]


def test_flush_reports_a_truncated_frame_only():
    data = encode_frame(1, 1, _points(10, 1))
    dec = FrameDecoder()
    dec.feed(data[:30])
    assert dec.mid_frame
    err = dec.flush()
    assert err.reason == TRUNCATED and "30 bytes" in err.detail
    assert dec.buffered == 0 and dec.flush() is None
    dec.feed(data)                                   # a boundary: nothing pending
    assert dec.flush() is None
    dec.feed(b"garbage")                             # already reported as bad_magic
    assert dec.flush() is None
    assert [f.seq for f in _frames(dec.feed(data))] == [1]


def test_buffer_bounded_under_a_stream_of_garbage():
    rng = np.random.default_rng(0)
    dec = FrameDecoder()
    errors = []
    for _ in range(64):                                # 4 MiB of garbage in 64 KiB chunks
        out = dec.feed(_scrub(rng.bytes(65536)))
        errors += out
        assert dec.buffered <= 3
    assert [e.reason for e in errors] == [BAD_MAGIC]     # one garbage run, one error
    assert dec.bytes_discarded >= 64 * 65536 - 3
    (f,) = dec.feed(encode_frame(1, 1, _points(3, 0)))  # and it still decodes afterwards
    assert f.seq == 1


def test_buffer_bounded_under_fake_headers():
    """Garbage full of magics announcing MAX_POINTS: never more than one frame buffered."""
    fake = HEADER.pack(MAGIC, 1, 0, 0, 0, MAX_POINTS)
    rng = np.random.default_rng(1)
    dec = FrameDecoder()
    for _ in range(40):
        dec.feed(fake + _scrub(rng.bytes(20_000)))
        assert dec.buffered <= MAX_FRAME_BYTES


@PROPS
@given(data=st.binary(max_size=3000), cuts=st.lists(st.integers(0, 3000), max_size=8),
       magic_at=st.lists(st.integers(0, 3000), max_size=4))
def test_arbitrary_bytes_never_raise(data, cuts, magic_at):
    data = bytearray(data)
    for i in magic_at:                                # plant magics to reach the header checks
        data[i:i] = MAGIC
    bounds = sorted({min(c, len(data)) for c in cuts} | {0, len(data)})
    dec = FrameDecoder()
    for a, b in itertools.pairwise(bounds):
        for item in dec.feed(bytes(data[a:b])):
            assert isinstance(item, Frame) or item.reason in KNOWN_REASONS
        assert dec.buffered <= MAX_FRAME_BYTES
    err = dec.flush()
    assert err is None or err.reason == TRUNCATED


# --- bad input at the encoder -------------------------------------------------------------

def test_encode_frame_bad_input():
    with pytest.raises(ProfileError, match=r"expected shape \(N, 2\).*\(4, 3\)"):
        encode_frame(0, 0, np.zeros((4, 3)))
    with pytest.raises(ProfileError, match="8193 points exceed the protocol's MAX_POINTS = 8192"):
        encode_frame(0, 0, np.zeros((MAX_POINTS + 1, 2)))
    with pytest.raises(ProfileError, match="non-numeric"):
        encode_frame(0, 0, [["a", "b"]])
    with pytest.raises(ConfigError, match=r"seq must be in \[0, 2\*\*32\), got -1"):
        encode_frame(-1, 0, np.zeros((1, 2)))
    with pytest.raises(ConfigError, match=r"seq must be in \[0, 2\*\*32\), got 4294967296"):
        encode_frame(2**32, 0, np.zeros((1, 2)))
    with pytest.raises(ConfigError, match="t_sensor_ns"):
        encode_frame(0, 2**64, np.zeros((1, 2)))
    assert len(encode_frame(0, 0, [])) == HEADER_SIZE           # an empty profile is a valid frame


# --- JSON lines ---------------------------------------------------------------------------

RECORDS = [{"seq": 1, "status": "ok", "t_mm": [1.5, -2.25, 300.0], "error": None},
           {"seq": 2, "status": "error", "t_mm": None, "error": "missing corner: x = [1.0] mm\nsecond line"},
           {"seq": 3, "command": {"dq": [0.0] * 6}, "text": "ünïcödé"}]


def test_command_lines_round_trip_at_every_split():
    data = b"".join(encode_command(r) for r in RECORDS)
    assert data.count(b"\n") == len(RECORDS)            # newlines inside strings are escaped
    for i in range(len(data) + 1):
        dec = LineDecoder()
        assert dec.feed(data[:i]) + dec.feed(data[i:]) == RECORDS, i


def test_encode_command_bad_input():
    with pytest.raises(ConfigError, match="not JSON-serialisable.*NaN|Out of range float"):
        encode_command({"t_mm": [float("nan"), 0.0, 0.0]})
    with pytest.raises(ConfigError, match="must be a dict, got list"):
        encode_command([1, 2])
    with pytest.raises(ConfigError, match="not JSON-serialisable"):
        encode_command({"T": np.eye(4)})


def test_line_decoder_counts_malformed_lines():
    dec = LineDecoder(max_line_bytes=100)
    data = b'{"a": 1}\nnot json\n[1, 2]\n\n' + b'{"b": "' + b"x" * 500 + b'"}\n' + b'{"c": 3}\n'
    out = []
    for i in range(0, len(data), 37):
        out += dec.feed(data[i:i + 37])
    assert out == [{"a": 1}, {"c": 3}]
    assert dec.errors == {"not_json": 1, "not_object": 1, "too_long": 1}
    assert json.loads(encode_command({"c": 3})) == {"c": 3}

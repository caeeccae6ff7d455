"""Wire format of the robot side of the stream: one JSON object per line.

The pose server answers the robot interface (and writes its ``--jsonl`` stream) with one JSON
object per line, UTF-8, ``\\n``-terminated, no NaN (:func:`encode_command`); the robot side reads
them with :class:`LineDecoder`. The binary profile frames of the sensor side are
:mod:`~posekit.profiler.stream.protocol`'s.
"""

import json
from collections import Counter

from ...errors import ConfigError

__all__ = ["encode_command", "LineDecoder", "MAX_LINE_BYTES"]


_JSON = json.JSONEncoder(separators=(",", ":"), allow_nan=False)


#: A line longer than this is rejected by :class:`LineDecoder` (``too_long``).
MAX_LINE_BYTES = 1 << 20


def encode_command(obj: dict) -> bytes:
    """One JSON object as a ``\\n``-terminated UTF-8 line.

    Parameters
    ----------
    obj : dict
        JSON-serialisable; floats must be finite (JSON has no NaN: use None).

    Raises
    ------
    ConfigError
        If ``obj`` is not a dict or holds something JSON cannot carry.

    Examples
    --------
    >>> encode_command({"seq": 1, "t_mm": [0.5, 0, 1]})
    b'{"seq":1,"t_mm":[0.5,0,1]}\\n'
    """
    if not isinstance(obj, dict):
        raise ConfigError(f"robot record must be a dict, got {type(obj).__name__}")
    try:
        text = _JSON.encode(obj)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"robot record is not JSON-serialisable: {exc}") from None
    return text.encode() + b"\n"


class LineDecoder:
    """Incremental decoder of JSON lines (the robot side of :func:`encode_command`).

    Malformed lines are skipped and counted in :attr:`errors` by reason: ``not_json``,
    ``not_object`` (valid JSON but not an object), ``too_long`` (over ``max_line_bytes``,
    skipped up to its newline). The buffer never exceeds ``max_line_bytes`` plus the
    chunk being fed.
    """

    def __init__(self, max_line_bytes: int = MAX_LINE_BYTES):
        self._buf = bytearray()
        self._skipping = False
        self.max_line_bytes = int(max_line_bytes)
        self.errors: Counter = Counter()

    def feed(self, data) -> list[dict]:
        """The JSON objects completed by ``data``, in order."""
        buf = self._buf
        buf += data
        out = []
        start = 0
        while True:
            i = buf.find(b"\n", start)
            if i < 0:
                break
            line = bytes(buf[start:i])
            start = i + 1
            if self._skipping:
                self._skipping = False
                continue
            if len(line) > self.max_line_bytes:
                self.errors["too_long"] += 1
                continue
            if not line.strip():
                continue
            try:
                obj = json.loads(line)
            except (UnicodeDecodeError, ValueError):
                self.errors["not_json"] += 1
                continue
            if not isinstance(obj, dict):
                self.errors["not_object"] += 1
                continue
            out.append(obj)
        del buf[:start]
        if len(buf) > self.max_line_bytes:
            if not self._skipping:
                self.errors["too_long"] += 1
            self._skipping = True
            buf.clear()
        return out

"""Where the pose server's records go besides the robot: JSON lines and CSV files.

:class:`RecordSink` takes each record from the server's worker without blocking it (a
bounded hand-off) and writes it from a thread of its own, to any number of outputs:

- a **stream** (``posekit profiler serve --jsonl FILE|-``): JSON lines written and flushed
  as each record arrives, so another program can follow the file (or stdout) live;
- a **file** (``--out FILE.jsonl|FILE.csv``): written under a temporary name and renamed
  into place when the server stops, so it is never seen half-written.

JSON lines carry the record as sent to the robot (see :mod:`~posekit.profiler.stream.server`).
The CSV has one row per record with the columns :data:`SERVE_CSV_COLUMNS`: the pose, its
standard deviations, the filtered pose (``f_``), the controller's ``command_mm`` and the
stage times; the filter's full covariance is only in the JSON lines.
"""

import csv
import sys
import threading
from collections import deque
from dataclasses import dataclass
from pathlib import Path

from ...errors import ConfigError
from ...io import atomic_file, open_stream
from .lines import encode_command

__all__ = ["SERVE_CSV_COLUMNS", "RecordOutput", "RecordSink", "record_csv_row", "output_format"]

_AXES = ("x", "y", "z")
SERVE_CSV_COLUMNS = (
    ["seq", "t_sensor_ns", "status", "tx", "ty", "tz", "qw", "qx", "qy", "qz"]
    + [f"std_t{a}_um" for a in _AXES] + [f"std_r{a}_deg" for a in _AXES]
    + ["reprojection_um", "reversed", "f_status", "f_tx", "f_ty", "f_tz", "f_qw", "f_qx", "f_qy", "f_qz"]
    + [f"f_std_t{a}_um" for a in _AXES] + [f"f_std_r{a}_deg" for a in _AXES]
    + [f"cmd_{a}_mm" for a in _AXES] + ["DT_ms", "QW_ms", "CD_ms", "PC_ms", "error"])
_MAX_QUEUE = 100_000


def _cells(values, n: int) -> list:
    return [None] * n if values is None else list(values)


def record_csv_row(rec: dict) -> list:
    """The :data:`SERVE_CSV_COLUMNS` cells of one server record (None for an empty cell)."""
    f = rec.get("filter") or {}
    cmd = rec.get("command")
    cmd_mm = cmd.get("command_mm") if isinstance(cmd, dict) else None
    if not (isinstance(cmd_mm, list) and len(cmd_mm) == 3):
        cmd_mm = None
    tim = rec.get("timing_ms") or {}
    return [rec.get("seq"), rec.get("t_sensor_ns"), rec.get("status"),
            *_cells(rec.get("t_mm"), 3), *_cells(rec.get("q_wxyz"), 4),
            *_cells(rec.get("std_t_um"), 3), *_cells(rec.get("std_rot_deg"), 3),
            rec.get("reprojection_um"), rec.get("reversed"), f.get("status"),
            *_cells(f.get("t_mm"), 3), *_cells(f.get("q_wxyz"), 4),
            *_cells(f.get("std_t_um"), 3), *_cells(f.get("std_rot_deg"), 3),
            *_cells(cmd_mm, 3), *(tim.get(k) for k in ("DT", "QW", "CD", "PC")), rec.get("error") or ""]


def _text(v) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return str(v)


@dataclass(frozen=True)
class RecordOutput:
    """One output of a :class:`RecordSink`.

    Attributes
    ----------
    target : str
        A file name, or ``-`` for stdout (a stream only).
    fmt : {'jsonl', 'csv'}
    stream : bool
        True: written and flushed per record (``--jsonl``); False: written to a temporary
        name and renamed when the sink closes (``--out``).
    flag : str
        The option that named it, for messages.
    """

    target: str
    fmt: str = "jsonl"
    stream: bool = False
    flag: str = "--out"


class _Writer:
    def __init__(self, out: RecordOutput):
        self.out = out
        self.error = None
        self._atomic = None
        self._own = False
        self._wrote = False
        if out.target == "-":
            if not out.stream:
                raise ConfigError(f"{out.flag} -: stdout is only for a stream (--jsonl -)")
            self.fh = sys.stdout
        elif out.stream:              # an existing FILE is only emptied by the first record
            self.fh = open_stream(out.target, flag=out.flag)
            self._own = True
        else:
            self._atomic = atomic_file(out.target, "w", flag=out.flag, encoding="utf-8", newline="")
            self.fh = self._atomic.__enter__()
        self._csv = None
        if out.fmt == "csv":
            self._csv = csv.writer(self.fh)
            self._csv.writerow(SERVE_CSV_COLUMNS)

    def write(self, rec: dict) -> None:
        if self.error is not None:
            return
        try:
            if self._csv is not None:
                self._csv.writerow([_text(v) for v in record_csv_row(rec)])
            else:
                self.fh.write(encode_command(rec).decode("utf-8"))
            if self.out.stream:
                self.fh.flush()
            self._wrote = True
        except (OSError, ValueError, ConfigError) as exc:     # disk full, closed pipe, ...
            self.error = f"{self.out.flag} {self.out.target}: cannot write ({getattr(exc, 'strerror', None) or exc})"

    def close(self, discard: bool = False) -> None:
        if self._atomic is not None:
            atomic, self._atomic = self._atomic, None
            try:
                if self.error is None and not discard:
                    atomic.__exit__(None, None, None)
                else:
                    atomic.__exit__(OSError, OSError(self.error or "discarded"), None)
            except OSError as exc:
                self.error = self.error or f"{self.out.flag} {self.out.target}: cannot write ({exc.strerror or exc})"
        elif self._own:
            try:
                self.fh.close(discard=discard)   # the run never started: a file it created is removed
            except OSError as exc:
                self.error = self.error or f"{self.out.flag} {self.out.target}: cannot write ({exc.strerror or exc})"
        else:
            try:
                self.fh.flush()
            except (OSError, ValueError):
                pass


class RecordSink:
    """Writes server records to files and streams from a thread of its own.

    Parameters
    ----------
    outputs : list of RecordOutput
        Opened at once (a file that cannot be written is a :class:`ConfigError` here,
        before the server starts).
    max_queue : int
        Records waiting to be written; beyond it a record is counted in ``unwritten``
        instead of held (a stalled stdout never grows the server's memory without bound).

    Attributes
    ----------
    written : int
        Records handed to every output.
    unwritten : int
        Records dropped because the queue was full.
    """

    def __init__(self, outputs, max_queue: int = _MAX_QUEUE):
        self._writers = []
        try:
            for out in outputs:
                if out.fmt not in ("jsonl", "csv"):
                    raise ConfigError(f"{out.flag} {out.target}: unknown format '{out.fmt}'; expected jsonl or csv")
                self._writers.append(_Writer(out))
        except BaseException:
            for w in self._writers:
                w.close(discard=True)
            raise
        self.max_queue = int(max_queue)
        self._queue: deque = deque()
        self._cond = threading.Condition()
        self._closing = False
        self.written = 0
        self.unwritten = 0
        self._thread = threading.Thread(target=self._run, name="posekit-records", daemon=True)
        self._thread.start()

    @property
    def targets(self) -> list[str]:
        """The outputs' targets, in order."""
        return [w.out.target for w in self._writers]

    @property
    def errors(self) -> list[str]:
        """One line per output that failed (it stopped receiving records then)."""
        return [w.error for w in self._writers if w.error is not None]

    def put(self, rec: dict) -> None:
        """Hand over one record (never blocks; the record must not be changed afterwards)."""
        with self._cond:
            if len(self._queue) >= self.max_queue:
                self.unwritten += 1
                return
            self._queue.append(rec)
            self._cond.notify()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._queue and not self._closing:
                    self._cond.wait()
                if not self._queue:
                    return
                batch = list(self._queue)
                self._queue.clear()
            for rec in batch:
                for w in self._writers:
                    w.write(rec)
            with self._cond:
                self.written += len(batch)

    def close(self, timeout_s: float = 10.0, discard: bool = False) -> None:
        """Write what is queued, then close every output: the ``--out`` files are renamed into
        place, or with ``discard`` (the run failed) removed."""
        with self._cond:
            self._closing = True
            self._cond.notify()
        self._thread.join(timeout_s)
        for w in self._writers:
            w.close(discard)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close(discard=exc[0] is not None)


def output_format(path: str, flag: str) -> str:
    """``jsonl`` or ``csv`` from the suffix of an ``--out`` file; a ConfigError for anything else."""
    suffix = Path(path).suffix.lower()
    if suffix in (".jsonl", ".csv"):
        return suffix[1:]
    raise ConfigError(f"{flag} {path}: unknown suffix {suffix[:20]!r}; expected FILE.jsonl (JSON lines) or FILE.csv")

"""Where track rows go as they are produced: the track CSV, JSON lines, UDP datagrams.

``posekit ceiling track`` writes every row the moment its frame is done, so a user reading a
live camera sees poses as they come and an interrupted run loses nothing:

* the CSV (``--out``) is written row by row into a temporary file beside the target and
  renamed into place when the run ends — normally, on Ctrl-C or on SIGTERM — so the target is
  either absent or complete (whole rows, the header first), never half-written;
* ``--jsonl FILE|-`` writes one JSON object per frame
  ``{"frame", "time_s", "x", "y", "heading_deg", "status", "std_mm", "std_heading_deg",
  "reason"}`` (``null`` for an empty value; ``"robot"`` added with several robots) and flushes
  it at once; when its reader goes away (``| head``), the run stops within the frame
  (:class:`ReaderGone`);
* ``--udp HOST:PORT`` sends the same object as one UTF-8 datagram per frame, to a loopback
  address unless ``allow_remote``.
"""

from __future__ import annotations

import csv
import ipaddress
import json
import socket
import sys
from pathlib import Path

from ...errors import ConfigError
from ...io import atomic_file, open_stream

__all__ = ["TrackOutputs", "ReaderGone", "parse_udp_target", "row_record"]


class ReaderGone(Exception):
    """The reader of ``--jsonl -`` (or of a FIFO given as ``--jsonl``) closed its end: the run
    stops (raised from :meth:`TrackOutputs.write`, out of the tracking loop)."""


def row_record(row, robot: int | None = None) -> dict:
    """The JSON object of a :class:`~posekit.ceiling.track.TrackRow` (with ``robot`` when given)."""
    rec = row.json_record()
    if robot is not None:
        rec["robot"] = int(robot)
    return rec


def parse_udp_target(text: str, allow_remote: bool = False) -> tuple[str, int]:
    """``HOST:PORT`` → (IP address, port); a host that is not loopback needs ``allow_remote``.

    Raises
    ------
    ConfigError
        One line naming ``--udp``: no port, a port outside 1..65535, a host that does not
        resolve, or a remote host without ``allow_remote``.
    """
    host, sep, port = str(text).rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise ConfigError(f"--udp {text}: expected HOST:PORT with a port in 1..65535 (e.g. 127.0.0.1:5005)")
    try:
        infos = socket.getaddrinfo(host, int(port), type=socket.SOCK_DGRAM)
    except (OSError, UnicodeError):
        raise ConfigError(f"--udp {text}: host '{host}' does not resolve") from None
    addr = infos[0][4][0]
    if not ipaddress.ip_address(addr.split("%")[0]).is_loopback and not allow_remote:
        raise ConfigError(f"--udp {text}: {addr} is not a loopback address; pass --allow-remote to send poses "
                          "to another machine")
    return addr, int(port)


class TrackOutputs:
    """The outputs of one track run, written per row.

    Parameters
    ----------
    csv_path : path, optional
        The track CSV (``frame,time_s,x,y,heading_deg,status,std_mm``, plus ``robot`` when
        ``robots`` > 1), renamed into place by :meth:`close`.
    jsonl : str or path, optional
        ``-`` for stdout, or a file; flushed per row.
    udp : str, optional
        ``HOST:PORT``.
    allow_remote : bool
        Allow a UDP host that is not loopback.
    robots : int
        Number of robots (> 1 adds the ``robot`` column / key).

    Attributes
    ----------
    counts : dict
        Rows written per status.
    frames : int
        Rows written (over every robot).
    errors : list of str
        Write failures (the first one is raised by :meth:`close`).
    """

    def __init__(self, csv_path=None, jsonl=None, udp=None, *, allow_remote: bool = False, robots: int = 1):
        from .pipeline import TRACK_COLUMNS

        self.robots = int(robots)
        self.counts = {"ok": 0, "suspect": 0, "predicted": 0, "lost": 0}
        self.frames = 0
        self.errors: list[str] = []
        self._udp = None
        self._sock = None
        if udp is not None:
            self._udp = parse_udp_target(udp, allow_remote)
        self._atomic = self._csv_fh = self._csv = None
        self._jsonl = None
        self._own_jsonl = False
        self.csv_path = None if csv_path is None else Path(csv_path)
        try:
            if self.csv_path is not None:
                self._atomic = atomic_file(self.csv_path, "w", flag="--out", encoding="utf-8", newline="")
                self._csv_fh = self._atomic.__enter__()
                self._csv = csv.writer(self._csv_fh)
                self._csv.writerow(TRACK_COLUMNS + (("robot",) if self.robots > 1 else ()))
                self._csv_fh.flush()
            if jsonl is not None:
                if str(jsonl) == "-":
                    self._jsonl = sys.stdout
                else:
                    self._jsonl = open_stream(jsonl, flag="--jsonl")
                    self._own_jsonl = True
            if self._udp is not None:
                family = socket.AF_INET6 if ":" in self._udp[0] else socket.AF_INET
                self._sock = socket.socket(family, socket.SOCK_DGRAM)
        except BaseException:
            self.close(discard=True)
            raise
        self.jsonl_target = None if jsonl is None else str(jsonl)

    @property
    def to_stdout(self) -> bool:
        """True when the JSON lines go to stdout (messages must then go to stderr)."""
        return self.jsonl_target == "-"

    def write(self, row, robot: int | None = None) -> None:
        """Write one row to every output, flushed."""
        self.frames += 1
        self.counts[row.status] = self.counts.get(row.status, 0) + 1
        multi = self.robots > 1
        if self._csv is not None:
            try:
                self._csv.writerow(row.csv_fields() + ([str(int(robot or 0))] if multi else []))
                self._csv_fh.flush()
            except (OSError, ValueError) as exc:
                self._fail(f"--out {self.csv_path}: cannot write ({getattr(exc, 'strerror', None) or exc})")
        if self._jsonl is not None or self._sock is not None:
            line = json.dumps(row_record(row, robot if multi else None), allow_nan=False) + "\n"
            if self._jsonl is not None:
                try:
                    self._jsonl.write(line)
                    self._jsonl.flush()
                except BrokenPipeError:
                    fh, self._jsonl = self._jsonl, None     # nothing more can go there, not even a flush
                    if self._own_jsonl:
                        try:
                            fh.close()
                        except OSError:
                            pass
                    raise ReaderGone(f"the reader of --jsonl {self.jsonl_target} closed after "
                                     f"{self.frames - 1} rows") from None
                except (OSError, ValueError) as exc:
                    self._fail(f"--jsonl {self.jsonl_target}: cannot write "
                               f"({getattr(exc, 'strerror', None) or exc})")
            if self._sock is not None:
                try:
                    self._sock.sendto(line.encode("utf-8"), self._udp)
                except OSError:
                    pass                              # UDP is best effort: nobody listening is fine

    def _fail(self, message: str) -> None:
        if message not in self.errors:
            self.errors.append(message)

    def close(self, discard: bool = False) -> None:
        """Finish: the CSV renamed into place (removed instead if ``discard``), files closed.

        Raises
        ------
        ConfigError
            The first write failure, after everything was closed.
        """
        if self._atomic is not None:
            atomic, self._atomic = self._atomic, None
            try:
                if discard:
                    atomic.__exit__(ConfigError, ConfigError("discarded"), None)
                else:
                    atomic.__exit__(None, None, None)
            except ConfigError:
                pass
            except OSError as exc:
                self._fail(f"--out {self.csv_path}: cannot write ({exc.strerror or exc})")
        if self._own_jsonl and self._jsonl is not None:
            self._jsonl.close(discard=discard)
        self._jsonl = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        if self.errors and not discard:
            raise ConfigError(self.errors[0])

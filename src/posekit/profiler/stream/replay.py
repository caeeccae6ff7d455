"""Stream recorded profiles to a pose server, as a sensor would: the library behind
``posekit profiler replay``.

:func:`replay` reads a profile file (:class:`~posekit.profiler.stream.sources.FileSource`), connects
to the server (retrying for ``wait_s``), sends frame 0 alone and waits briefly (a server that
refuses the token closes the connection at once), then streams the rest paced at ``rate_hz``
with ``seq`` counting from 0 in file order, cycling when ``count`` exceeds the file.
"""

import gc
import time
from dataclasses import dataclass

import numpy as np

from ...errors import ConfigError, InputFileError
from .protocol import MAX_POINTS
from .reading import ReadOptions
from .server_support import parse_address, read_token_file
from .sources import FileSource
from .stream_client import SensorClient, StreamReport

__all__ = ["replay", "Replay", "DEFAULT_RATE_HZ"]

#: Frames per second unless told: the paper's 12 ms control cycle.
DEFAULT_RATE_HZ = 1.0 / 0.012
#: Wait after frame 0 for a server that refuses the connection, s.
_PROBE_S = 0.3


@dataclass(frozen=True)
class Replay:
    """Result of :func:`replay`.

    Attributes
    ----------
    host : str
    port : int
    count : int
        Frames sent.
    profiles : int
        Profiles in the file.
    points : int
        Points per profile.
    report : StreamReport or None
        Pacing of frames 1..count-1 (None when only frame 0 was sent).
    """

    host: str
    port: int
    count: int
    profiles: int
    points: int
    report: StreamReport | None


def _connect(host: str, port: int, token, wait_s: float) -> SensorClient:
    deadline = time.monotonic() + wait_s
    while True:
        try:
            return SensorClient(host, port, timeout_s=5.0, token=token)
        except ConfigError as exc:
            if time.monotonic() >= deadline:
                text = str(exc)
                reason = text[text.rfind("(") + 1:-1] if text.endswith(")") else text
                tried = f" for {wait_s:g} s" if wait_s > 0 else ""
                raise ConfigError(f"--to {host}:{port}: cannot connect{tried} ({reason}); is 'posekit profiler "
                                  "serve' listening there?") from None
            time.sleep(0.1)


def replay(input, to, *, rate_hz: float = DEFAULT_RATE_HZ, count: int | None = None, token_file=None,
           wait_s: float = 0.0, read: ReadOptions = ReadOptions()) -> Replay:
    """Send the profiles of a file to a pose server as binary frames, stamped when sent.

    Parameters
    ----------
    input : str or Path
        ``.npz`` with ``profiles`` (K, N, 2) (as ``posekit profiler simulate`` writes), ``.npy``
        (N, 2) or a CSV ``x,z`` (mm).
    to : str ``HOST:PORT`` or (host, port)
        The server's listen address.
    rate_hz : float
        Frames per second.
    count : int, optional
        Frames to send, cycling through the file (default: each profile once).
    token_file : str or Path, optional
        The server's shared secret, sent first.
    wait_s : float
        Keep trying to connect this long, s (a server still starting).
    read : ReadOptions
        How to read a CSV and the region of interest.

    Returns
    -------
    Replay

    Raises
    ------
    ConfigError
        When the server cannot be reached, refuses the token or closes the connection.
    InputFileError
        For a bad file, or profiles longer than a frame carries.
    """
    host, port = parse_address(to, "--to") if isinstance(to, str) else tuple(to)
    if not 1 <= port <= 65535:
        raise ConfigError(f"--to '{to}': expected the server's port, 1..65535, got {port}")
    token = read_token_file(token_file) if token_file else None
    profiles = FileSource(input, read).profiles
    if profiles.shape[1] > MAX_POINTS:
        raise InputFileError(f"{input}: profiles of {profiles.shape[1]} points; a stream frame carries at most "
                             f"{MAX_POINTS} (posekit.profiler.stream.protocol.MAX_POINTS)")
    count = len(profiles) if count is None else count
    client = _connect(host, port, token, wait_s)
    refused = (f"--to {host}:{port}: the server closed the connection at once: it wants a token and this one "
               "(--token-file) is wrong or missing")
    gc.freeze()                                     # steady pacing: no full collections over NumPy/SciPy objects
    try:
        try:
            # Frame 0 alone first: a server that refuses the hello (or its absence) closes the
            # connection within milliseconds, while sends into the socket buffer still succeed.
            client.send_profile(0, profiles[0])
            if client.peer_closed(wait_s=_PROBE_S):
                raise ConfigError(refused)
            report = client.stream(np.roll(profiles, -1, axis=0), rate_hz, count=count - 1,   # from profile 1 on
                                   first_seq=1) if count > 1 else None
        except OSError as exc:
            raise ConfigError(f"--to {host}:{port}: the server closed the connection while frames were sent "
                              f"({exc.strerror or exc})") from None
    finally:
        client.close()
        gc.unfreeze()
    return Replay(host=host, port=port, count=count, profiles=len(profiles), points=profiles.shape[1], report=report)

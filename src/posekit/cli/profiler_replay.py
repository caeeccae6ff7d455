"""``posekit profiler replay``: stream recorded profiles to a pose server, as a sensor would.

Also the profile-reading flags shared with ``posekit profiler estimate``
(:func:`add_read_arguments`, :func:`read_options`): ``--columns``, ``--delimiter``,
``--roi-x``, ``--roi-z``, turned into one :class:`~posekit.profiler.stream.sources.ReadOptions`.
"""

import time

from ._flags import bounded_float, bounded_int, check_flags

__all__ = ["add_replay_parser", "run_replay", "add_read_arguments", "read_options"]

_RATE_HZ = (0.01, 20_000.0)
_MAX_FRAMES = 10**9
_PROBE_S = 0.3                 # wait after frame 0 for a server that refuses the connection


def add_read_arguments(p) -> None:
    """The profile-reading flags (``estimate``, ``replay``)."""
    p.add_argument("--columns", metavar="X,Z",
                   help="CSV: header names of the x and z columns, e.g. x,z for a file 'x,z,intensity' "
                        "(default: the header must be exactly x,z)")
    p.add_argument("--delimiter", metavar="C",
                   help="CSV: the character between cells, e.g. ';' or tab (default ',')")
    p.add_argument("--roi-x", metavar="A:B",
                   help="region of interest in x, mm: points outside become no return (NaN)")
    p.add_argument("--roi-z", metavar="A:B",
                   help="region of interest in z (depth), mm: points outside become no return (NaN)")


def read_options(args):
    """The :class:`~posekit.profiler.stream.sources.ReadOptions` of the reading flags (one-line errors)."""
    from ..profiler.stream.reading import ReadOptions, parse_columns, parse_delimiter, parse_roi

    return ReadOptions(columns=parse_columns(args.columns), delimiter=parse_delimiter(args.delimiter),
                       roi_x_mm=parse_roi(args.roi_x, "--roi-x"), roi_z_mm=parse_roi(args.roi_z, "--roi-z"))


def add_replay_parser(verbs):
    """Add the ``replay`` verb to the ``posekit profiler`` sub-parsers ``verbs``."""
    p = verbs.add_parser(
        "replay", help="stream recorded profiles to a pose server (posekit profiler serve), as a sensor would",
        description="Send the profiles of a file (.npz 'profiles' as written by 'posekit profiler simulate', "
                    ".npy or CSV) to a pose server as binary frames, paced at --rate, stamped when sent; "
                    "seq counts from 0 in file order (cycling when --count exceeds the file).")
    p.add_argument("input", help="profile file: .npz 'profiles' (K, N, 2), .npy (N, 2) or CSV 'x,z' (mm)")
    p.add_argument("--to", required=True, metavar="HOST:PORT", help="the server's --listen address")
    p.add_argument("--rate", type=bounded_float(*_RATE_HZ, "Hz"), default=1.0 / 0.012, metavar="HZ",
                   help=f"frames per second, {_RATE_HZ[0]:g}..{_RATE_HZ[1]:g} (default 83.3, the paper's "
                        "12 ms cycle)")
    p.add_argument("--count", type=bounded_int(1, _MAX_FRAMES, "frames"), default=None, metavar="N",
                   help="frames to send, cycling through the file (default: each profile once)")
    p.add_argument("--token-file", metavar="FILE",
                   help="file holding the server's shared secret (its --token-file), sent first")
    p.add_argument("--wait-s", type=bounded_float(0.0, 3600.0, "s"), default=0.0, metavar="S",
                   help="keep trying to connect for S seconds (a server still starting); default 0")
    add_read_arguments(p)
    p.set_defaults(func=run_replay)
    return p


def _connect(host: str, port: int, token, wait_s: float):
    from ..errors import ConfigError
    from ..profiler.stream.stream_client import SensorClient

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


def run_replay(args) -> int:
    import gc

    import numpy as np

    from ..errors import ConfigError, InputFileError
    from ..profiler.stream.protocol import MAX_POINTS
    from ..profiler.stream.server_support import parse_address, read_token_file
    from ..profiler.stream.sources import FileSource

    check_flags(args)
    host, port = parse_address(args.to, "--to")
    if not 1 <= port <= 65535:
        raise ConfigError(f"--to '{args.to}': expected the server's port, 1..65535, got {port}")
    options = read_options(args)
    token = read_token_file(args.token_file) if args.token_file else None
    source = FileSource(args.input, options)
    profiles = source.profiles
    if profiles.shape[1] > MAX_POINTS:
        raise InputFileError(f"{args.input}: profiles of {profiles.shape[1]} points; a stream frame carries at most "
                             f"{MAX_POINTS} (posekit.profiler.stream.protocol.MAX_POINTS)")
    count = len(profiles) if args.count is None else args.count
    client = _connect(host, port, token, args.wait_s)
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
            report = client.stream(np.roll(profiles, -1, axis=0), args.rate, count=count - 1,   # from profile 1 on
                                   first_seq=1) if count > 1 else None
        except OSError as exc:
            raise ConfigError(f"--to {host}:{port}: the server closed the connection while frames were sent "
                              f"({exc.strerror or exc})") from None
    finally:
        client.close()
        gc.unfreeze()
    if report is None:
        print(f"replayed 1 frame of {args.input} to {host}:{port}", flush=True)
        return 0
    late = report.late_ms
    rate = f"{report.rate_hz:.1f} Hz" if np.isfinite(report.rate_hz) else "-"
    print(f"replayed {count} frames of {args.input} ({len(profiles)} profiles, {profiles.shape[1]} points) "
          f"to {host}:{port}: frames 1-{count - 1} in {report.elapsed_s:.2f} s, {rate} (asked {args.rate:g} Hz); "
          f"sends started late by median {np.median(late):.3f} ms, max {late.max():.3f} ms", flush=True)
    return 0

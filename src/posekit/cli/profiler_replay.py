"""``posekit profiler replay``: stream recorded profiles to a pose server, as a sensor would.

Also the profile-reading flags shared with ``posekit profiler estimate``
(:func:`add_read_arguments`, :func:`read_options`): ``--columns``, ``--delimiter``,
``--roi-x``, ``--roi-z``, turned into one :class:`~posekit.profiler.stream.sources.ReadOptions`.
"""

from ._common import add_deprecated
from ._config import add_config_arguments
from ._flags import bounded_float, bounded_int, check_flags

__all__ = ["add_replay_parser", "run_replay", "add_read_arguments", "read_options"]

_RATE_HZ = (0.01, 20_000.0)
_RATE = bounded_float(*_RATE_HZ, "Hz", flag="--rate-hz")
#: ``posekit.profiler.stream.replay.DEFAULT_RATE_HZ`` (not imported: the parser stays light; a test keeps
#: them equal).
HELP_RATE_HZ = 1.0 / 0.012
_MAX_FRAMES = 10**9


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
    p.add_argument("--rate-hz", dest="rate", type=_RATE, default=HELP_RATE_HZ, metavar="HZ",
                   help=f"frames per second, {_RATE_HZ[0]:g}..{_RATE_HZ[1]:g} (default 83.3, the paper's "
                        "12 ms cycle)")
    add_deprecated(p, "--rate", "--rate-hz", "rate", _RATE)
    p.add_argument("--count", type=bounded_int(1, _MAX_FRAMES, "frames"), default=None, metavar="N",
                   help="frames to send, cycling through the file (default: each profile once)")
    p.add_argument("--token-file", metavar="FILE",
                   help="file holding the server's shared secret (its --token-file), sent first")
    p.add_argument("--wait-s", type=bounded_float(0.0, 3600.0, "s"), default=0.0, metavar="S",
                   help="keep trying to connect for S seconds (a server still starting); default 0")
    add_read_arguments(p)
    add_config_arguments(p)
    p.set_defaults(func=run_replay)
    return p


def run_replay(args) -> int:
    import numpy as np

    from ..profiler.stream.replay import replay

    check_flags(args)
    r = replay(args.input, args.to, rate_hz=args.rate, count=args.count, token_file=args.token_file,
               wait_s=args.wait_s, read=read_options(args))
    if r.report is None:
        print(f"replayed 1 frame of {args.input} to {r.host}:{r.port}", flush=True)
        return 0
    report = r.report
    late = report.late_ms
    rate = f"{report.rate_hz:.1f} Hz" if np.isfinite(report.rate_hz) else "-"
    print(f"replayed {r.count} frames of {args.input} ({r.profiles} profiles, {r.points} points) "
          f"to {r.host}:{r.port}: frames 1-{r.count - 1} in {report.elapsed_s:.2f} s, {rate} (asked {args.rate:g} Hz); "
          f"sends started late by median {np.median(late):.3f} ms, max {late.max():.3f} ms", flush=True)
    return 0

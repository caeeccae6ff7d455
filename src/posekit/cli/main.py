"""Entry point of the ``posekit`` command.

Exit codes: 0 success, 1 a :class:`~posekit.errors.PosekitError` (message only, one line
on stderr) or a batch with failed items, 2 usage. Tracebacks only with ``--debug``.
"""

import argparse
import sys

from .. import __version__

__all__ = ["main", "build_parser"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="posekit", description="Precise robot pose from laser and vision sensors.")
    parser.add_argument("--version", action="version", version=f"posekit {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    from . import bench, ceiling, demo, localcal, profiler, seam
    demo.add_parser(sub)
    profiler.add_parser(sub)
    ceiling.add_parser(sub)
    localcal.add_parser(sub)
    seam.add_parser(sub)
    bench.add_parser(sub)
    return parser


def main(argv=None) -> int:
    """Run ``posekit`` with ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:          # argparse: usage errors exit 2, --help/--version exit 0
        return int(exc.code or 0)
    from ..errors import PosekitError
    try:
        return int(args.func(args) or 0)
    except PosekitError as exc:
        if args.debug:
            raise
        print(f"posekit: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("posekit: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 1
    except Exception as exc:  # a bug, not bad input: still one line unless --debug
        if args.debug:
            raise
        print(f"posekit: internal error: {type(exc).__name__}: {exc} (rerun with --debug for the traceback)",
              file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

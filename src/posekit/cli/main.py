"""Entry point of the ``posekit`` command.

Exit codes: 0 success, 1 a :class:`~posekit.errors.PosekitError` (message only, one line
on stderr, at most 300 characters) or a batch with failed items, 2 usage, 130 / 143 interrupted
by SIGINT (Ctrl-C) / SIGTERM. Tracebacks only with ``--debug``.

A signal at any moment (start-up, a Dask study, the middle of writing ``--out``) ends the run
through the same clean-up as an error: temporary folders and files are removed, ``--out`` keeps
its previous contents, one line ``posekit: interrupted`` / ``posekit: terminated`` is printed.
A full disk (ENOSPC and the like) while writing is one line and exit 1.

Global options are accepted anywhere on the line (``posekit seam simulate --out d --debug``):
``--debug``, ``--max-input-mb N`` (largest decoded array / text file read, default 1024 /
256 MiB) and ``--max-image-mp N`` (largest image, megapixels, default 100). Warnings from
NumPy or OpenCV are not printed (they would come before the one error line) unless ``--debug``.
"""

import argparse
import contextlib
import math
import re
import signal
import sys
import threading
import warnings

from .. import __version__

__all__ = ["main", "build_parser"]


_CHOICE = re.compile(r"invalid choice: '([^']*)' \(choose from (.*)\)$")


class _Parser(argparse.ArgumentParser):
    """argparse with "did you mean" for a mistyped sub-command or flag (Python 3.11's argparse has
    no ``suggest_on_error``). Sub-command parsers inherit the class (``add_subparsers``)."""

    def parse_known_args(self, args=None, namespace=None):
        self._argv = list(sys.argv[1:] if args is None else args)
        return super().parse_known_args(args, namespace)

    def error(self, message):
        super().error(message + _suggestion(self, message))


def _suggestion(parser: argparse.ArgumentParser, message: str) -> str:
    """``"; did you mean 'X'?"`` for an invalid choice or an unknown ``--flag``, or ``""``."""
    m = _CHOICE.search(message)
    if m:
        choices = [c.strip().strip("'") for c in m.group(2).split(",")]
        close = _close(m.group(1), choices)
        return f"; did you mean '{close}'?" if close else ""
    if message.startswith("unrecognized arguments: "):
        flags = _flags_of_command(parser, getattr(parser, "_argv", []))
        unknown = [a.split("=", 1)[0] for a in message.split(": ", 1)[1].split() if a.startswith("--")]
        hints = [(a, close) for a in unknown if (close := _close(a, flags))]
        if len(hints) == 1:
            return f"; did you mean {hints[0][1]}?"
        return ("; did you mean " + ", ".join(f"{good} (for {bad})" for bad, good in hints) + "?") if hints else ""
    return ""


def _close(word: str, candidates: list[str]) -> str | None:
    """The candidate closest to ``word`` (difflib ratio >= 0.6) that starts with the same letter
    (a typo rarely changes the first one: 'icp' is not 'cpd'), or None."""
    import difflib

    first = word.lstrip("-")[:1]
    same = [c for c in candidates if c.lstrip("-")[:1] == first]
    close = difflib.get_close_matches(word, same, n=1, cutoff=0.6)
    return close[0] if close else None


def _flags_of_command(parser: argparse.ArgumentParser, argv: list[str]) -> list[str]:
    """Every ``--flag`` of the (sub-)command that ``argv`` selects, and the global ones."""
    flags = []
    while True:
        flags += [o for a in parser._actions for o in a.option_strings if o.startswith("--")]
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        word = next((w for w in argv if subs and w in subs[0].choices), None)
        if word is None:
            return flags
        parser = subs[0].choices[word]
        argv = argv[argv.index(word) + 1:]


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="posekit", description="Precise robot pose from laser and vision sensors.")
    parser.add_argument("--version", action="version", version=f"posekit {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks of errors and warnings (anywhere on "
                        "the line)")
    parser.add_argument("--max-input-mb", type=float, default=None, metavar="N",
                        help="largest array (.npy/.npz) or text file read, MiB (default 1024 for arrays, 256 for "
                             "text; anywhere on the line)")
    parser.add_argument("--max-image-mp", type=float, default=None, metavar="N",
                        help="largest image read, megapixels (default 100; anywhere on the line)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    from . import bench, ceiling, demo, localcal, profiler, seam, warmup
    demo.add_parser(sub)
    profiler.add_parser(sub)
    ceiling.add_parser(sub)
    localcal.add_parser(sub)
    seam.add_parser(sub)
    bench.add_parser(sub)
    warmup.add_parser(sub)
    _describe_verbs(parser)
    return parser


def _describe_verbs(parser: argparse.ArgumentParser) -> None:
    """Give every verb without a description its one-line help as description (``--help``)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            for name, sub in action.choices.items():
                if not sub.description and helps.get(name):
                    sub.description = helps[name][0].upper() + helps[name][1:] + "."
                _describe_verbs(sub)


_NEGATIVE = re.compile(r"^-(\d|\.\d)")


def _join_negative_values(argv: list[str]) -> list[str]:
    """``--tilts-deg -60:60:15`` -> ``--tilts-deg=-60:60:15``: a value that starts with a minus
    sign is not an option (argparse would take it for one unless it is a plain number)."""
    out = []
    i = 0
    while i < len(argv):
        a = argv[i]
        if (a.startswith("--") and "=" not in a and a != "--" and i + 1 < len(argv)
                and _NEGATIVE.match(argv[i + 1])):
            out.append(f"{a}={argv[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


_GLOBAL_VALUED = ("--max-input-mb", "--max-image-mp")


def _split_globals(argv: list[str]) -> tuple[list[str], dict]:
    """Take the global options out of ``argv`` wherever they are: ``(rest, options)``."""
    rest, found = [], {}
    i = 0
    while i < len(argv):
        a = argv[i]
        if a == "--":
            rest.extend(argv[i:])
            break
        if a == "--debug":
            found["debug"] = True
        elif a in _GLOBAL_VALUED:
            if i + 1 >= len(argv):
                raise _Usage(f"{a}: expected a value")
            found[a] = argv[i + 1]
            i += 1
        elif a.startswith(tuple(f"{g}=" for g in _GLOBAL_VALUED)):
            key, value = a.split("=", 1)
            found[key] = value
        else:
            rest.append(a)
        i += 1
    return rest, found


class _Usage(Exception):
    pass


def _limits(found: dict) -> dict:
    """``posekit.io.set_limits`` keywords from the global size options (validated)."""
    from ..errors import ConfigError

    changes = {}
    for flag, ranges in (("--max-input-mb", (1.0, 1e6)), ("--max-image-mp", (0.01, 1e5))):
        if flag not in found:
            continue
        try:
            value = float(found[flag])
        except ValueError:
            raise ConfigError(f"{flag}: expected a number, got '{found[flag][:40]}'") from None
        lo, hi = ranges
        if not (math.isfinite(value) and lo <= value <= hi):
            unit = "MiB" if flag == "--max-input-mb" else "megapixels"
            raise ConfigError(f"{flag}: expected {lo:g} to {hi:g} {unit}, got {found[flag][:40]}")
        if flag == "--max-input-mb":
            changes["array_bytes"] = changes["text_bytes"] = int(value * 2**20)
            changes["rows"] = max(1000, int(value * 2**20) // 128)
        else:
            changes["image_pixels"] = int(value * 1e6)
    return changes


class Terminated(BaseException):
    """SIGTERM (or SIGHUP) received: raised in the main thread so that every ``with`` block
    cleans up (not an ``Exception``: no ``except Exception`` swallows it)."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


#: The signal that ended the run (a library may turn the exception it raised into another one,
#: e.g. an ImportError of an interrupted import: the exit still says what happened). A verb that
#: catches the interrupt as its own stop request (``profiler serve``, a live ``ceiling track``)
#: returns normally, and its exit code stands.
_received: int | None = None


def _on_signal(signum, frame):
    # The first signal ends the run; further ones are ignored so that the clean-up finishes. Not
    # with SIG_IGN: a process started during the clean-up (a Dask nanny restarting a worker the
    # Ctrl-C ended) would inherit it and could then not be terminated; a handler is not inherited.
    global _received
    if _lost_if_raised_in(frame):
        # Python only prints an exception raised here (a weakref callback, e.g. importlib's module-lock
        # clean-up while posekit starts, or a finaliser): the run would go on. The handler stays, and the
        # signal comes again in a moment, from ordinary code.
        import os

        threading.Timer(_REDELIVER_S, os.kill, args=(os.getpid(), signum)).start()
        return
    _received = signum
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(s, _ignore)
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(signum)


#: How soon a signal that arrived where its exception would be lost is sent again, s.
_REDELIVER_S = 0.005


def _lost_if_raised_in(frame) -> bool:
    """Whether an exception raised in ``frame`` (or a frame it was called from) would be printed and
    dropped rather than end the run: a finaliser (``__del__``) or importlib's module-lock callback."""
    while frame is not None:
        code = frame.f_code
        if code.co_name == "__del__" or (code.co_name == "cb" and code.co_filename.startswith("<frozen importlib")):
            return True
        frame = frame.f_back
    return False


def _ignore(signum, frame):
    """A later signal during the clean-up: nothing to do (the run is already ending)."""


@contextlib.contextmanager
def _signals():
    """SIGINT, SIGTERM and SIGHUP raise in the main thread for the duration of the command."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    for s in previous:
        if previous[s] is not signal.SIG_IGN:        # nohup / a parent that ignores it: keep that
            signal.signal(s, _on_signal)
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)


_PREFIX = "posekit: error: "


def _error_line(exc) -> str:
    from ..errors import one_line

    return _PREFIX + one_line(exc, 300 - len(_PREFIX))


def main(argv=None) -> int:
    """Run ``posekit`` with ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    global _received
    _received = None
    debug = "--debug" in (sys.argv[1:] if argv is None else argv)
    try:
        with _signals():
            code = _main(argv)
    except (KeyboardInterrupt, Terminated, Exception):
        if debug or _received is None and not isinstance(sys.exc_info()[1], KeyboardInterrupt | Terminated):
            raise
        code = None
    if code is not None:      # the verb returned: it took the signal as its stop request (serve, a live track)
        return code
    signum = _received if _received is not None else signal.SIGINT
    _quiet_print("posekit: interrupted" if signum == signal.SIGINT else "posekit: terminated")
    _exit_within(EXIT_GRACE_S, 128 + signum)
    return 128 + signum


#: After a signal, the most the interpreter's own shutdown may take (a library's threads or exit
#: hooks, e.g. a Dask cluster interrupted while it started) before the process exits anyway, s.
EXIT_GRACE_S = 15.0


def _exit_within(seconds: float, code: int) -> None:
    """Make sure an interrupted process ends: exit with ``code`` after ``seconds`` if it is still
    shutting down (a daemon timer: it never delays a shutdown that finishes)."""
    import os

    if threading.current_thread() is not threading.main_thread():
        return
    t = threading.Timer(seconds, os._exit, args=(code,))
    t.daemon = True
    t.start()


def _quiet_print(line: str) -> None:
    try:
        print(line, file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass


def _main(argv) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        argv, found = _split_globals(argv)
    except _Usage as exc:
        print(f"posekit: error: {exc}", file=sys.stderr)
        return 2
    debug = bool(found.get("debug"))
    argv = _join_negative_values(argv)
    parser = build_parser()
    from ..errors import PosekitError
    from ._config import apply_config, dump_config, wants_dump
    try:
        apply_config(parser, argv)     # a verb's --config FILE: its defaults (defaults < file < flags)
    except PosekitError as exc:
        print(_error_line(exc), file=sys.stderr)
        return 1
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:          # argparse: usage errors exit 2, --help/--version exit 0
        return int(exc.code or 0)
    if wants_dump(args):
        sys.stdout.write(dump_config(parser, argv, args))
        return 0
    args.debug = debug or args.debug
    from .. import _jit  # only now: --help and usage errors import no numpy, numba or scipy
    from ..io import set_limits, write_error

    _jit.enable_compile_notice("profiler" if args.command == "demo" else args.command)
    previous = None
    try:
        with warnings.catch_warnings():
            if not args.debug:
                warnings.simplefilter("ignore")
            previous = set_limits(**_limits(found))
            return int(args.func(args) or 0)
    except PosekitError as exc:
        if args.debug or _received is not None:
            raise
        print(_error_line(exc), file=sys.stderr)
        return 1
    except BrokenPipeError:
        return 1
    except OSError as exc:
        if args.debug or _received is not None:
            raise
        if write_error(exc):           # a full disk outside any --out (a figure, a cache): one line
            where = f"{exc.filename}: " if exc.filename else ""
            print(_error_line(f"{where}cannot write ({exc.strerror}); free some space or write elsewhere"),
                  file=sys.stderr)
        else:
            print(_internal(exc), file=sys.stderr)
        return 1
    except Exception as exc:  # a bug, not bad input: still one line unless --debug
        if args.debug or _received is not None:
            raise
        print(_internal(exc), file=sys.stderr)
        return 1
    finally:
        if previous is not None:
            set_limits(**vars(previous))


def _internal(exc) -> str:
    from ..errors import one_line

    return (f"posekit: internal error: {type(exc).__name__}: {one_line(exc, 160)} (rerun with --debug for the "
            "traceback)")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

"""Helpers shared by the sub-command modules."""

import argparse
import sys
from pathlib import Path

from .._numbers import parse_number
from ..errors import ConfigError

__all__ = ["overwrite_flag", "replace_own_flag", "progress", "parse_triplet", "out_folder", "add_overwrite", "OVERWRITE_HELP", "staged",
           "add_deprecated", "add_dask_args", "check_dask_args", "check_scheduler", "check_workspace", "local_scheduler", "SCHEDULER_HELP"]

#: Help of ``--scheduler`` on the verbs that run their episodes through :func:`posekit.sweep.run_tasks`.
SCHEDULER_HELP = ("where to run: a Dask scheduler address tcp://HOST:PORT, or 'serial' (this process); default "
                  "local: a Dask cluster on this machine's cores, or this process without Dask")

#: Help of ``--overwrite``, the same on every verb that writes a folder.
OVERWRITE_HELP = ("replace an existing non-empty --out folder, files posekit did not write included (the old one "
                  "is removed only after the new run is complete)")


def add_overwrite(parser, out_default: str | None = None) -> None:
    """Add ``--overwrite`` to a verb that writes a run's folder to ``--out``; a verb with a default
    folder (``out_default``) replaces that one on every run while posekit wrote everything in it."""
    parser.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    parser.set_defaults(out_default=out_default)


def progress(iterable, total=None, desc=None, unit: str = "profile"):
    """A tqdm progress bar on a terminal (stderr), the bare iterable otherwise."""
    if not sys.stderr.isatty():
        return iterable
    from tqdm import tqdm
    return tqdm(iterable, total=total, desc=desc, unit=unit, leave=False)


def parse_triplet(text: str, name: str) -> tuple[float, float, float]:
    """'10,10,40' → (10.0, 10.0, 40.0); a ConfigError naming the option otherwise."""
    try:
        vals = tuple(parse_number(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"--{name}: expected three comma-separated numbers, got '{text}'") from None
    if len(vals) != 3:
        raise ConfigError(f"--{name}: expected three comma-separated numbers, got '{text}'")
    return vals


def out_folder(args) -> Path:
    """Check ``args.out`` before the (long) runs: a new or empty folder (or ``--overwrite``, or the
    verb's default folder holding only an earlier posekit run) whose parent is writable; a one-line
    ConfigError otherwise. The run then writes through :func:`posekit.io.staged_folder`, so the
    folder appears whole or not at all."""
    from ..io import check_out_folder

    return check_out_folder(args.out, overwrite=overwrite_flag(args), replace_own=replace_own_flag(args))


def overwrite_flag(args) -> bool:
    """``--overwrite``: replace the ``--out`` folder whatever it holds."""
    return bool(getattr(args, "overwrite", False))


def replace_own_flag(args) -> bool:
    """The verb's own default folder (a demo's ``posekit-demo``) is in use: each run replaces it
    while everything in it was written by posekit (its marker says so)."""
    default = getattr(args, "out_default", None)
    return default is not None and str(args.out) == default


def staged(args):
    """``posekit.io.staged_folder`` for ``args.out`` / ``args.overwrite``: a temporary folder
    that becomes ``--out`` when the block succeeds."""
    from ..io import staged_folder

    return staged_folder(args.out, overwrite=overwrite_flag(args), replace_own=replace_own_flag(args))


class _Deprecated(argparse.Action):
    """An old spelling of a flag: works for one release, with a note on stderr."""

    def __init__(self, option_strings, dest, new: str, **kw):
        self.new = new
        super().__init__(option_strings, dest, **kw)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"posekit: note: {option_string} is deprecated and will be removed; use {self.new}", file=sys.stderr)
        setattr(namespace, self.dest, values)


def add_deprecated(parser, old: str, new: str, dest: str, type=None) -> None:
    """Keep ``old`` as a hidden, deprecated alias of ``new`` (same ``dest``)."""
    parser.add_argument(old, dest=dest, type=type, action=_Deprecated, new=new, help=argparse.SUPPRESS,
                        default=argparse.SUPPRESS)


def add_dask_args(parser) -> None:
    """Add ``--scheduler`` (a Dask address or ``serial``; default a local cluster) and ``--workers``
    (processes of that local cluster) to a verb that runs its episodes on Dask."""
    from ._flags import workers

    parser.add_argument("--scheduler", default=None, help=SCHEDULER_HELP)
    parser.add_argument("--workers", type=workers, default=None,
                        help="worker processes of the local cluster, 1..256 (default: one per core)")


def check_dask_args(args) -> None:
    """One-line :class:`ConfigError` when ``--workers`` (the local cluster's size) comes with ``--scheduler``."""
    if args.workers is not None and args.scheduler is not None:
        raise ConfigError("--workers sets the size of the local cluster; it cannot be combined with --scheduler")


def check_scheduler(text: str | None) -> None:
    """A one-line ConfigError for a ``--scheduler`` that is not 'serial' or ``SCHEME://HOST:PORT`` with a
    port in 1..65535 (before a 5 s connection timeout, or a connection to a port that cannot exist)."""
    import re

    if text is None or text == "serial":
        return
    m = re.fullmatch(r"(tcp|tls|ws|wss|ucx)://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+):(\d{1,5})", text)
    if m is None or not 1 <= int(m.group(3)) <= 65535:
        raise ConfigError(f"--scheduler: expected 'serial' or a Dask address tcp://HOST:PORT with a port in "
                          f"1..65535, got '{text[:80]}'")


def local_scheduler(args):
    """The scheduler for :func:`posekit.sweep.run_tasks`: ``--scheduler`` when given; by default a
    local Dask cluster, or this process (``'serial'``, with a one-line note) when Dask (the
    'studies' extra) is not installed, so the default invocation needs no Dask."""
    if args.scheduler is not None or getattr(args, "workers", None) is not None:
        return args.scheduler
    try:
        import distributed  # noqa: F401
    except ImportError:
        from .._extras import install_hint
        print(f"posekit: note: running in this process; Dask would use every core ({install_hint('studies')})",
              file=sys.stderr)
        return "serial"
    return None


def check_workspace(ws, args) -> None:
    """The workspace half-ranges within 0..1000 mm and 0..180 deg (``Workspace`` checks >= 0)."""
    from ._flags import check_range

    for flag, text, values, hi, unit in (("--translation-mm", args.translation_mm, ws.translation_mm, 1e3, "mm"),
                                         ("--rotation-deg", args.rotation_deg, ws.rotation_deg, 180.0, "deg")):
        for v in values:
            check_range(flag, v, 0.0, hi, unit, what="three numbers", shown=repr(text))

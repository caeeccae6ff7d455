"""Helpers shared by the sub-command modules."""

import os
import sys
from pathlib import Path

from ..errors import ConfigError

__all__ = ["resolve_gauge", "progress", "parse_triplet", "out_folder"]


def resolve_gauge(arg: str):
    """Load a gauge from a path, or a bundled one by name (``demo-5``)."""
    from ..profiler.gauge import BUNDLED_GAUGES, bundled_gauge, load_gauge
    path = Path(arg)
    if not path.exists() and arg in BUNDLED_GAUGES:
        return bundled_gauge(arg)
    return load_gauge(path)


def progress(iterable, total=None, desc=None, unit: str = "profile"):
    """A tqdm progress bar on a terminal (stderr), the bare iterable otherwise."""
    if not sys.stderr.isatty():
        return iterable
    from tqdm import tqdm
    return tqdm(iterable, total=total, desc=desc, unit=unit, leave=False)


def parse_triplet(text: str, name: str) -> tuple[float, float, float]:
    """'10,10,40' → (10.0, 10.0, 40.0); a ConfigError naming the option otherwise."""
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"--{name}: expected three comma-separated numbers, got '{text}'") from None
    if len(vals) != 3:
        raise ConfigError(f"--{name}: expected three comma-separated numbers, got '{text}'")
    return vals


def out_folder(out) -> Path:
    """Create the output folder before the (long) runs; a one-line ConfigError if it cannot be written."""
    folder = Path(out)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--out {folder}: cannot create the output folder ({exc.strerror or exc})") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ConfigError(f"--out {folder}: the output folder is not writable")
    return folder

"""Output that is never half-written: a run's folder appears whole or not at all, a file is
written under a temporary name and renamed.

:func:`staged_folder` gives the run a fresh temporary folder beside ``--out`` and moves it into
place only when the run succeeds; an existing non-empty ``--out`` is an error unless
``overwrite`` (``--overwrite``), and then the old folder is replaced only after the new one is
complete, so a failed rerun never leaves old figures beside new metrics. :func:`atomic_file`
does the same for a single file.
"""

import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

from posekit.errors import ConfigError

__all__ = ["atomic_file", "check_out_folder", "staged_folder", "write_text_atomic"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_out_folder(out, *, overwrite: bool = False, flag: str = "--out") -> Path:
    """Check ``out`` can receive a run's folder (before any work starts); return it as a Path.

    Raises
    ------
    ConfigError
        ``out`` is a file, a non-empty folder without ``overwrite``, or its parent cannot be
        created or written.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"{flag} {out}: exists and is not a folder; expected a folder name")
    if out.is_dir():
        try:
            non_empty = any(out.iterdir())
        except OSError as exc:
            raise ConfigError(f"{flag} {out}: cannot list the folder ({exc.strerror or exc})") from None
        if non_empty and not overwrite:
            raise ConfigError(f"{flag} {out}: the folder exists and is not empty; expected a new or empty "
                              "folder (pass --overwrite to replace it)")
    parent = out.absolute().parent
    blocker = next((p for p in (parent, *parent.parents) if p.exists()), None)
    if blocker is not None and not blocker.is_dir():
        raise ConfigError(f"{flag} {out}: {blocker} is a file, not a folder; expected a folder path")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"{flag} {out}: cannot create the parent folder ({exc.strerror or exc})") from None
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ConfigError(f"{flag} {out}: the folder {parent} is not writable")
    return out


@contextmanager
def staged_folder(out, *, overwrite: bool = False, flag: str = "--out"):
    """Yield a temporary folder beside ``out``; move it to ``out`` when the block succeeds.

    On an exception the temporary folder is removed and ``out`` is left as it was.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> root = pathlib.Path(tempfile.mkdtemp())
    >>> with staged_folder(root / "run") as tmp:
    ...     _ = (tmp / "metrics.json").write_text("{}")
    >>> sorted(p.name for p in (root / "run").iterdir())
    ['metrics.json']
    """
    out = check_out_folder(out, overwrite=overwrite, flag=flag)
    parent = out.absolute().parent
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=parent))
    except OSError as exc:
        raise ConfigError(f"{flag} {out}: cannot create a folder in {parent} ({exc.strerror or exc})") from None
    os.chmod(tmp, 0o777 & ~_umask())
    try:
        yield tmp
    except OSError as exc:  # a full disk, a permission change: one line, the old run untouched
        shutil.rmtree(tmp, ignore_errors=True)
        raise ConfigError(f"{flag} {out}: cannot write the results ({exc.strerror or exc}); "
                          "the previous contents are unchanged") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    try:
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=parent))
            os.rename(out, old / "previous")
            os.rename(tmp, out)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(tmp, out)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise ConfigError(f"{flag} {out}: cannot move the finished run into place ({exc.strerror or exc})") from None


@contextmanager
def atomic_file(path, mode: str = "w", *, flag: str = "--out", **open_kwargs):
    """Open a temporary file beside ``path`` for writing; rename it to ``path`` when the block
    succeeds, remove it on an exception (``path`` is then untouched)."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"{flag} {path}: is a folder; expected a file name")
    parent = path.absolute().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=parent)
    except OSError as exc:
        raise ConfigError(f"{flag} {path}: cannot write in {parent} ({exc.strerror or exc})") from None
    os.chmod(tmp, 0o666 & ~_umask())
    try:
        with os.fdopen(fd, mode, **open_kwargs) as fh:
            yield fh
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def write_text_atomic(path, text: str, *, flag: str = "--out", error=ConfigError) -> Path:
    """Write ``text`` (UTF-8) to ``path`` under a temporary name and rename it into place.

    Raises ``error`` (one line naming ``flag`` and the file) when the folder cannot be written.
    """
    path = Path(path)
    try:
        with atomic_file(path, "w", flag=flag, encoding="utf-8", newline="") as fh:
            fh.write(text)
    except ConfigError as exc:
        raise error(str(exc)) from None
    except OSError as exc:
        raise error(f"{flag} {path}: cannot write ({exc.strerror or exc})") from None
    return path

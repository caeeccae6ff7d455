"""Output that is never half-written and never destroys what posekit did not write.

- :func:`staged_folder` gives a run a fresh temporary folder beside ``--out`` and moves it into
  place only when the run succeeds. The finished folder carries a marker (:data:`MARKER`) that
  lists every file and folder the run wrote. An existing non-empty ``--out`` is an error unless
  ``overwrite`` (the user's ``--overwrite`` for that folder) — or, with ``replace_own`` (a verb's
  default folder such as ``posekit-demo``), unless the marker shows that everything in it was
  written by posekit. The error says what would be lost. The old folder is replaced only after
  the new one is complete, so a failed rerun never leaves old figures beside new metrics; what
  cannot be replaced at all (``/``, a mount point, the current folder or one of its parents) is
  refused before any work starts.
- :func:`atomic_file` does the same for a single file, and writes *into* what is there when
  ``--out`` names a character device (``/dev/null``, a terminal) or a named pipe (a FIFO: after
  waiting up to :data:`FIFO_WAIT_S` for its reader): such a file is never replaced by a regular
  one. A socket or a block device is refused. A symbolic link is followed: the file it points
  to is written (replaced, for a regular file), and the link stays a link.
- :func:`open_stream` opens a ``--jsonl FILE`` stream (written and flushed as items are
  produced) with the same rules; an existing regular file is only emptied when the first line
  is written, so a run that fails to start leaves it as it was.
"""

import errno
import fcntl
import json
import os
import shutil
import stat
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

from posekit.errors import ConfigError

from ._limits import quote

__all__ = ["MARKER", "FIFO_WAIT_S", "atomic_file", "check_out_folder", "open_stream", "staged_folder",
           "write_text_atomic", "write_error"]

#: Name of the marker file in every run folder: the files and folders that run wrote.
MARKER = ".posekit-run.json"
#: Seconds :func:`atomic_file` / :func:`open_stream` wait for the reader of a named pipe.
FIFO_WAIT_S = 10.0
#: Most entries of an existing folder looked at to decide whether posekit wrote it all.
_MAX_SCAN = 20_000
#: ``errno`` values of a failed write (disk full, quota, file too large, I/O error, read-only).
_WRITE_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EROFS}


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _why(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


def write_error(exc: BaseException) -> bool:
    """True when ``exc`` is an ``OSError`` of a failed write (ENOSPC, EDQUOT, EFBIG, EIO, EROFS)."""
    return isinstance(exc, OSError) and exc.errno in _WRITE_ERRNOS


# --------------------------------------------------------------------------- what a path names


def _kind(path: Path, flag: str) -> str:
    """What ``path`` is now, links followed: ``new``, ``regular``, ``folder``, ``fifo``, ``chardev``.

    Raises ConfigError for a socket, a block device, a link loop or an unreadable path.
    """
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return "new"          # (also a dangling link: the file it points to is created)
    except NotADirectoryError as exc:
        raise ConfigError(f"{flag} {path}: cannot write in {path.absolute().parent} ({_why(exc)})") from None
    except OSError as exc:
        raise ConfigError(f"{flag} {path}: cannot write ({_why(exc)})") from None
    mode = st.st_mode
    if stat.S_ISREG(mode):
        return "regular"
    if stat.S_ISDIR(mode):
        return "folder"
    if stat.S_ISFIFO(mode):
        return "fifo"
    if stat.S_ISCHR(mode):
        return "chardev"
    what = "a socket" if stat.S_ISSOCK(mode) else "a block device" if stat.S_ISBLK(mode) else "a special file"
    raise ConfigError(f"{flag} {path}: is {what}; expected a file name (a new or regular file, a named pipe or "
                      "a character device such as /dev/null)")


def _real(path: Path) -> Path:
    """The file a symbolic link leads to (``path`` itself when it is not a link)."""
    return Path(os.path.realpath(path)) if path.is_symlink() else path


def _open_special(path: Path, kind: str, flag: str) -> int:
    """A write descriptor on an existing named pipe or character device, never truncating or
    replacing it; a pipe's reader is waited for up to :data:`FIFO_WAIT_S`."""
    if kind == "chardev":
        try:
            return os.open(path, os.O_WRONLY | os.O_NOCTTY | os.O_CLOEXEC)
        except OSError as exc:
            raise ConfigError(f"{flag} {path}: cannot write ({_why(exc)})") from None
    deadline = time.monotonic() + FIFO_WAIT_S
    while True:
        try:
            fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK | os.O_CLOEXEC)
            break
        except OSError as exc:
            if exc.errno != errno.ENXIO:             # ENXIO: nobody reads the pipe (yet)
                raise ConfigError(f"{flag} {path}: cannot write ({_why(exc)})") from None
            if time.monotonic() >= deadline:
                raise ConfigError(f"{flag} {path}: a named pipe that nobody reads (waited {FIFO_WAIT_S:g} s); "
                                  "start its reader first") from None
            time.sleep(0.05)
    fcntl.fcntl(fd, fcntl.F_SETFL, fcntl.fcntl(fd, fcntl.F_GETFL) & ~os.O_NONBLOCK)
    return fd


# --------------------------------------------------------------------------- single files


@contextmanager
def atomic_file(path, mode: str = "w", *, flag: str = "--out", **open_kwargs):
    """Open ``path`` for writing so that it is never seen half-written and nothing is replaced
    that is not a regular file.

    A new or regular file (also behind a symbolic link, which stays a link) is written under a
    temporary name beside it and renamed into place when the block succeeds; on an exception
    the temporary file is removed and ``path`` is untouched. An existing named pipe or
    character device is written directly (never replaced). A failed write (a full disk) inside
    the block is a one-line :class:`ConfigError` naming ``flag`` and the file.
    """
    path = Path(path)
    kind = _kind(path, flag)
    if kind == "folder":
        raise ConfigError(f"{flag} {path}: is a folder; expected a file name")
    if kind in ("fifo", "chardev"):
        fd = _open_special(path, kind, flag)
        try:
            with os.fdopen(fd, mode, **open_kwargs) as fh:
                yield fh
        except OSError as exc:
            if write_error(exc):
                raise ConfigError(f"{flag} {path}: cannot write ({_why(exc)})") from None
            raise
        return
    target = _real(path)
    parent = target.absolute().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".partial", dir=parent)
    except OSError as exc:
        raise ConfigError(f"{flag} {path}: cannot write in {parent} ({_why(exc)})") from None
    try:
        old_mode = os.stat(target).st_mode & 0o7777 if kind == "regular" else 0o666 & ~_umask()
        os.chmod(tmp, old_mode)
        with os.fdopen(fd, mode, **open_kwargs) as fh:
            yield fh
        os.replace(tmp, target)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if write_error(exc):
            raise ConfigError(f"{flag} {path}: cannot write ({_why(exc)}); "
                              + ("the previous file is unchanged" if kind == "regular" else "nothing was written")) \
                from None
        raise


def write_text_atomic(path, text: str, *, flag: str = "--out", error=ConfigError) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through :func:`atomic_file`.

    Raises ``error`` (one line naming ``flag`` and the file) when it cannot be written.
    """
    path = Path(path)
    try:
        with atomic_file(path, "w", flag=flag, encoding="utf-8", newline="") as fh:
            fh.write(text)
    except ConfigError as exc:
        raise error(str(exc)) from None
    except OSError as exc:
        raise error(f"{flag} {path}: cannot write ({_why(exc)})") from None
    return path


class StreamFile:
    """A ``--jsonl FILE`` stream from :func:`open_stream`: a text file written and flushed line by
    line. An existing regular file is emptied at the first :meth:`write`, not before."""

    def __init__(self, path: Path, flag: str):
        self.path = path
        self.flag = flag
        kind = _kind(path, flag)
        if kind == "folder":
            raise ConfigError(f"{flag} {path}: is a folder; expected a file name or -")
        self._created = kind == "new"
        self._pending_truncate = kind == "regular"
        if kind in ("fifo", "chardev"):
            fd = _open_special(path, kind, flag)
        else:
            flags = os.O_WRONLY | os.O_CLOEXEC | (os.O_CREAT | os.O_EXCL if kind == "new" else 0)
            try:
                fd = os.open(path, flags, 0o666)
            except OSError as exc:
                raise ConfigError(f"{flag} {path}: cannot write ({_why(exc)})") from None
        self._fh = os.fdopen(fd, "w", encoding="utf-8", newline="")
        self.wrote = False

    def write(self, text: str) -> None:
        if self._pending_truncate:
            self._fh.seek(0)
            self._fh.truncate()
            self._pending_truncate = False
        self._fh.write(text)
        self.wrote = True

    def flush(self) -> None:
        self._fh.flush()

    def close(self, discard: bool = False) -> None:
        """Close; with ``discard`` and nothing written, remove the file if this stream created it."""
        try:
            self._fh.close()
        finally:
            if discard and self._created and not self.wrote:
                try:
                    os.unlink(self.path)
                except OSError:
                    pass


def open_stream(path, *, flag: str = "--jsonl") -> StreamFile:
    """Open ``path`` as a stream of lines (``--jsonl FILE``): a new or existing regular file (emptied
    when the first line is written), a named pipe (its reader waited for) or a character device.

    Raises
    ------
    ConfigError
        A folder, a socket, a block device, or a file that cannot be written.
    """
    return StreamFile(Path(path), flag)


# --------------------------------------------------------------------------- run folders


def _scan(folder: Path) -> tuple[dict, list, bool]:
    """``(files, dirs, complete)`` under ``folder``: ``{relpath: [size, mtime_ns]}`` of every
    non-folder entry (links not followed), the sub-folders, and False when the scan stopped
    at :data:`_MAX_SCAN` entries."""
    files, dirs, n = {}, [], 0
    for root, subdirs, names in os.walk(folder):
        rel = Path(root).relative_to(folder)
        for d in subdirs:
            dirs.append(str(rel / d))
        for name in names:
            n += 1
            if n > _MAX_SCAN:
                return files, dirs, False
            p = Path(root) / name
            try:
                st = os.lstat(p)
            except OSError:
                continue
            files[str(rel / name)] = [st.st_size, st.st_mtime_ns]
    return files, dirs, True


def _write_marker(folder: Path) -> None:
    from posekit import __version__

    files, dirs, _ = _scan(folder)
    doc = {"written_by": f"posekit {__version__}", "note": "the files and folders this posekit run wrote; "
           "posekit replaces this folder without --overwrite only while they are all that is in it",
           "files": files, "dirs": sorted(dirs)}
    (folder / MARKER).write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")


def _foreign(folder: Path) -> list[str]:
    """What in ``folder`` posekit did not write (per its marker): relative paths, sorted."""
    own_files, own_dirs, valid = {}, set(), False
    try:
        doc = json.loads((folder / MARKER).read_text(encoding="utf-8"))
        if isinstance(doc.get("files"), dict) and isinstance(doc.get("dirs"), list):
            own_files, own_dirs, valid = doc["files"], {str(d) for d in doc["dirs"]}, True
    except (OSError, ValueError, TypeError, AttributeError):
        pass
    files, dirs, complete = _scan(folder)
    foreign = [d + "/" for d in dirs if d not in own_dirs]
    foreign += [f for f, sig in files.items() if (f != MARKER or not valid) and own_files.get(f) != sig]
    if not complete:
        foreign.append(f"(more than {_MAX_SCAN} entries)")
    return sorted(foreign)


def _names(items: list[str], k: int = 3) -> str:
    shown = ", ".join(quote(s, 40) for s in items[:k])
    return shown + (f" and {len(items) - k} more" if len(items) > k else "")


def _unreplaceable(out: Path) -> str | None:
    """Why the existing folder ``out`` cannot be renamed away (root, mount point, the current
    folder or one of its parents, the home folder), or None."""
    real = Path(os.path.realpath(out))
    if real == real.parent:
        return "is the root folder"
    if os.path.ismount(real):
        return "is a mount point"
    try:
        cwd = Path(os.getcwd()).resolve()
    except OSError:
        cwd = None
    if cwd is not None and (real == cwd or real in cwd.parents):
        return "is the current folder" if real == cwd else "holds the current folder"
    try:
        if real == Path.home().resolve():
            return "is the home folder"
    except (RuntimeError, OSError):
        pass
    return None


def check_out_folder(out, *, overwrite: bool = False, flag: str = "--out", replace_own: bool = False,
                     hint: str | None = None) -> Path:
    """Check that ``out`` can receive a run's folder, before any work starts; return it as a Path.

    Parameters
    ----------
    out : str or Path
        The folder (a symbolic link to a folder is followed).
    overwrite : bool
        The user asked to replace this folder (``--overwrite``): whatever it holds is replaced.
    flag : str
        The option that named it, for messages.
    replace_own : bool
        Replace a non-empty folder without ``overwrite`` when its marker shows that posekit wrote
        everything in it (a verb's default folder such as ``posekit-demo``).
    hint : str, optional
        What to suggest instead of ``--overwrite`` when the folder holds files posekit did not
        write (for a folder that ``--overwrite`` does not name, e.g. ``--save-log``).

    Raises
    ------
    ConfigError
        ``out`` is a file, a non-empty folder that may not be replaced (the message names what
        posekit did not write in it), a folder that cannot be replaced at all (root, a mount
        point, the current folder or a parent of it), or its parent cannot be created or written.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"{flag} {out}: exists and is not a folder; expected a folder name")
    if out.is_dir():
        try:
            non_empty = any(out.iterdir())
        except OSError as exc:
            raise ConfigError(f"{flag} {out}: cannot list the folder ({_why(exc)})") from None
        if non_empty and not overwrite:
            foreign = _foreign(out)
            if foreign or not replace_own:
                n = len(foreign)
                what = (f" and holds {n} {'entry' if n == 1 else 'entries'} posekit did not write ({_names(foreign)})"
                        if foreign else " (an earlier posekit run)")
                lose = f", deleting {'it' if n == 1 else 'them'}" if foreign else ""
                advice = hint if (hint and foreign) else f"pass --overwrite to replace it{lose}"
                raise ConfigError(f"{flag} {out}: the folder exists and is not empty{what}; expected a new or empty "
                                  f"folder ({advice})")
        why = _unreplaceable(out)
        if why is not None:
            raise ConfigError(f"{flag} {out}: {why} and cannot be replaced by a run's folder; expected a new folder "
                              "(e.g. a sub-folder of it)")
    parent = _real(out).absolute().parent
    blocker = next((p for p in (parent, *parent.parents) if p.exists()), None)
    if blocker is not None and not blocker.is_dir():
        raise ConfigError(f"{flag} {out}: {blocker} is a file, not a folder; expected a folder path")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"{flag} {out}: cannot create the parent folder ({_why(exc)})") from None
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ConfigError(f"{flag} {out}: the folder {parent} is not writable")
    return out


@contextmanager
def staged_folder(out, *, overwrite: bool = False, flag: str = "--out", replace_own: bool = False,
                  hint: str | None = None):
    """Yield a temporary folder beside ``out``; move it to ``out`` when the block succeeds.

    The rules of :func:`check_out_folder` apply (checked again here). The finished folder gets
    the :data:`MARKER` listing what it holds. On an exception the temporary folder is removed
    and ``out`` is left as it was; a failed write (a full disk) is a one-line ConfigError.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> root = pathlib.Path(tempfile.mkdtemp())
    >>> with staged_folder(root / "run") as tmp:
    ...     _ = (tmp / "metrics.json").write_text("{}")
    >>> sorted(p.name for p in (root / "run").iterdir() if p.name != MARKER)
    ['metrics.json']
    """
    out = check_out_folder(out, overwrite=overwrite, flag=flag, replace_own=replace_own, hint=hint)
    real = _real(out)
    parent = real.absolute().parent
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{real.name}.", suffix=".partial", dir=parent))
    except OSError as exc:
        raise ConfigError(f"{flag} {out}: cannot create a folder in {parent} ({_why(exc)})") from None
    os.chmod(tmp, 0o777 & ~_umask())
    try:
        yield tmp
        _write_marker(tmp)
    except OSError as exc:  # a full disk, a permission change: one line, the old run untouched
        shutil.rmtree(tmp, ignore_errors=True)
        raise ConfigError(f"{flag} {out}: cannot write the results ({_why(exc)}); "
                          "the previous contents are unchanged") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    try:
        if real.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{real.name}.", suffix=".old", dir=parent))
            os.rename(real, old / "previous")
            try:
                os.rename(tmp, real)
            except OSError:
                os.rename(old / "previous", real)            # put the old run back
                raise
        else:
            os.rename(tmp, real)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        if old is not None and not (old / "previous").exists():
            shutil.rmtree(old, ignore_errors=True)
        raise ConfigError(f"{flag} {out}: cannot move the finished run into place ({_why(exc)})") from None
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)

"""Reading a file's bytes or text safely: existence, permissions, size, encoding, in one line.

One rule for text everywhere: UTF-8, with or without a byte-order mark; anything else (latin-1,
UTF-16, a binary file) is an error that says so. Every failure is the caller's
:class:`~posekit.errors.PosekitError` subclass with ``FILE: what was wrong; what was expected``.
"""

import os
import stat
from pathlib import Path

from posekit.errors import InputFileError

from ._limits import get_limits, mib

__all__ = ["check_input_file", "read_bytes", "read_text", "sniff"]

_BOMS = {b"\xff\xfe": "UTF-16 (little-endian)", b"\xfe\xff": "UTF-16 (big-endian)"}


def _special(mode: int) -> str:
    """What a non-regular file is, for messages."""
    for test, what in ((stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return f"is {what}"
    return "is a special file"


def check_input_file(path, *, expected: str, error=InputFileError) -> int:
    """Check that ``path`` is an existing, readable regular file (a link is followed: to a named
    pipe or a device it is refused); return its size in bytes.

    Parameters
    ----------
    path : str or Path
    expected : str
        What the file should be, for messages (``"a gauge YAML file"``).
    error : type
        The PosekitError subclass to raise.
    """
    path = Path(path)
    try:
        st = path.stat()
    except FileNotFoundError:
        raise error(f"{path}: no such file; expected {expected}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror or type(exc).__name__}); expected {expected}") from None
    if path.is_dir():
        raise error(f"{path}: is a folder; expected {expected}")
    if not stat.S_ISREG(st.st_mode):      # a pipe would block a reader forever, /dev/zero never end
        raise error(f"{path}: {_special(st.st_mode)}, not a regular file; expected {expected}")
    if not os.access(path, os.R_OK):
        raise error(f"{path}: permission denied (not readable); expected {expected}")
    return st.st_size


def read_bytes(path, *, expected: str, error=InputFileError, limit: int | None = None) -> bytes:
    """The bytes of a file after :func:`check_input_file` and a size check.

    Parameters
    ----------
    limit : int, optional
        Largest accepted size in bytes; the text limit in force by default.
    """
    path = Path(path)
    size = check_input_file(path, expected=expected, error=error)
    own = limit is not None                  # a reader's own limit is not raised by --max-input-mb
    limit = get_limits().text_bytes if limit is None else limit
    if size > limit:
        raise error(f"{path}: {mib(size)}, above the {mib(limit)} limit for {expected}"
                    + ("" if own else " (raise it with --max-input-mb)"))
    try:
        return path.read_bytes()
    except PermissionError:
        raise error(f"{path}: permission denied (not readable); expected {expected}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror or type(exc).__name__}); expected {expected}") from None


def read_text(path, *, expected: str, error=InputFileError, limit: int | None = None) -> str:
    """The text of a UTF-8 file (a leading byte-order mark is dropped), or a one-line error.

    Raises
    ------
    error
        Missing, unreadable, too large, empty of text, not UTF-8 (latin-1, UTF-16, binary).
    """
    path = Path(path)
    data = read_bytes(path, expected=expected, error=error, limit=limit)
    kind = sniff(data[:16])
    if kind is not None:
        raise error(f"{path}: the contents are {kind}, not text; expected {expected}")
    for bom, name in _BOMS.items():
        if data.startswith(bom):
            raise error(f"{path}: {name} text; expected {expected} in UTF-8")
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    if b"\x00" in data[:65536]:
        raise error(f"{path}: binary data (NUL bytes); expected {expected} (UTF-8 text)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise error(f"{path}: line {line}: byte 0x{data[exc.start]:02x} is not UTF-8; "
                    f"expected {expected} in UTF-8 (save it as UTF-8)") from None


#: Leading bytes of the binary formats posekit reads, for naming a suffix/content mismatch.
_MAGIC = [
    (b"\x93NUMPY", "a .npy (NumPy array)"),
    (b"PK\x03\x04", "a .npz (zip archive)"),
    (b"PK\x05\x06", "a .npz (empty zip archive)"),
    (b"\x89PNG\r\n\x1a\n", "a .png image"),
    (b"\xff\xd8\xff", "a .jpg image"),
    (b"GIF8", "a .gif image"),
    (b"\x1f\x8b", "gzip data"),
]


def sniff(head: bytes) -> str | None:
    """What the leading bytes of a file look like (``'.npz (zip archive)'``), or None."""
    for magic, name in _MAGIC:
        if head.startswith(magic):
            return name
    if head.startswith(b"BM") and head[6:10] == b"\x00\x00\x00\x00":  # BMP: size, then 4 reserved zeros
        return "a .bmp image"
    return None

"""NumPy ``.npy`` files and ``.npz`` archive members, checked before anything is allocated.

The header of a ``.npy`` (alone or inside a ``.npz``) declares its dtype and shape; the decoded
size ``prod(shape) × itemsize`` is checked against the array limit before the data is read, so
a 144-byte file claiming 10¹⁰ × 2 values or a small ``.npz`` that inflates to gigabytes is a
one-line error, not a ``MemoryError``. The contents are sniffed: a ``.npz`` named ``.npy`` (and
the reverse) is named as such. Object arrays (pickles) are refused.
"""

import io
import zipfile
from pathlib import Path

import numpy as np
from numpy.lib import format as npformat

from posekit.errors import InputFileError

from ._files import check_input_file, sniff
from ._limits import get_limits, mib

__all__ = ["load_npy", "load_npz_member", "npz_members"]

_NPY_MAGIC = b"\x93NUMPY"
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")


def _head(path: Path, error) -> bytes:
    try:
        with path.open("rb") as fh:
            return fh.read(16)
    except PermissionError:
        raise error(f"{path}: permission denied (not readable)") from None
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror or type(exc).__name__})") from None


def _read_header(fh, source: str, error):
    """``(shape, fortran_order, dtype)`` from an open ``.npy`` stream, or a one-line error."""
    try:
        version = npformat.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = npformat.read_array_header_1_0(fh)
        elif version in ((2, 0), (3, 0)):
            shape, fortran, dtype = npformat.read_array_header_2_0(fh)
        else:
            raise ValueError(f"unsupported format version {version}")
    except Exception as exc:  # numpy raises ValueError, SyntaxError, tokenize.TokenError, ...
        raise error(f"{source}: malformed .npy header ({type(exc).__name__}: {str(exc)[:60]}); "
                    "expected a NumPy .npy array") from None
    if dtype.hasobject:
        raise error(f"{source}: holds Python objects (dtype {dtype}); expected a numeric array")
    return shape, fortran, dtype


def _check_size(shape, dtype, source: str, error, what: str) -> None:
    if any(int(s) < 0 for s in shape):
        raise error(f"{source}: negative dimension in shape {shape}")
    n = 1
    for s in shape:
        n *= int(s)
    nbytes = n * dtype.itemsize
    limit = get_limits().array_bytes
    if nbytes > limit:
        raise error(f"{source}: {what} of shape {tuple(shape)} ({dtype}) would take {mib(nbytes)}, above the "
                    f"{mib(limit)} limit (raise it with --max-input-mb)")


def _read_body(fh, shape, fortran, dtype, source: str, error) -> np.ndarray:
    n = 1
    for s in shape:
        n *= int(s)
    arr = np.empty(n, dtype=dtype)
    view = memoryview(arr.view(np.uint8))
    got = 0
    while got < view.nbytes:  # read into the array itself: no second copy of the data
        k = fh.readinto(view[got:])
        if not k:
            raise error(f"{source}: truncated: shape {tuple(shape)} needs {view.nbytes} bytes of data, found {got}")
        got += k
    return arr.reshape(shape[::-1]).T if fortran else arr.reshape(shape)


def load_npy(path, *, error=InputFileError) -> np.ndarray:
    """A ``.npy`` file's array after the header, size and content checks."""
    path = Path(path)
    check_input_file(path, expected="a NumPy .npy file", error=error)
    head = _head(path, error)
    if not head.startswith(_NPY_MAGIC):
        kind = sniff(head)
        if kind is not None:
            raise error(f"{path}: the contents are {kind}, not a .npy array; rename it or pass the right file")
        raise error(f"{path}: not a NumPy .npy file (no '\\x93NUMPY' header)")
    try:
        with path.open("rb") as fh:
            shape, fortran, dtype = _read_header(fh, str(path), error)
            _check_size(shape, dtype, str(path), error, "the array")
            return _read_body(fh, shape, fortran, dtype, str(path), error)
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror or type(exc).__name__})") from None


def _zip(path: Path, error) -> zipfile.ZipFile:
    check_input_file(path, expected="a NumPy .npz archive", error=error)
    head = _head(path, error)
    if not head.startswith(_ZIP_MAGIC):
        kind = sniff(head)
        if kind is not None:
            raise error(f"{path}: the contents are {kind}, not a .npz archive; rename it or pass the right file")
        raise error(f"{path}: not a NumPy .npz archive (no zip header)")
    try:
        return zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise error(f"{path}: not a valid .npz archive ({str(exc)[:80]})") from None


def npz_members(path, *, error=InputFileError) -> list[str]:
    """Array names in a ``.npz`` archive (member names without ``.npy``)."""
    with _zip(Path(path), error) as zf:
        return [n[:-4] if n.endswith(".npy") else n for n in zf.namelist()]


def load_npz_member(path, name: str, *, error=InputFileError) -> np.ndarray | None:
    """The array ``name`` of a ``.npz`` archive, or None when it has no such member.

    Checks before decoding: the member's compression method (stored or deflate), the
    encryption flag, its ``.npy`` header and the declared size against the array limit.
    """
    path = Path(path)
    with _zip(path, error) as zf:
        member = name + ".npy"
        try:
            info = zf.getinfo(member)
        except KeyError:
            return None
        source = f"{path}: member '{member}'"
        if info.flag_bits & 0x1:
            raise error(f"{source} is encrypted; expected a plain .npz archive")
        if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
            raise error(f"{source} uses compression method {info.compress_type}; expected stored or deflate "
                        "(np.savez / np.savez_compressed)")
        try:
            with zf.open(info) as raw:
                fh = io.BufferedReader(raw)
                head = fh.peek(6)[:6]
                if not head.startswith(_NPY_MAGIC):
                    raise error(f"{source} is not NumPy .npy data")
                shape, fortran, dtype = _read_header(fh, source, error)
                _check_size(shape, dtype, source, error, "the array")
                return _read_body(fh, shape, fortran, dtype, source, error)
        except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError, RuntimeError) as exc:
            # (the compression method and the encryption flag were checked above)
            raise error(f"{source}: cannot be decompressed ({type(exc).__name__}: {str(exc)[:60]})") from None
        except Exception as exc:  # zlib.error and friends from a corrupt stream
            if isinstance(exc, error):
                raise
            raise error(f"{source}: corrupt data ({type(exc).__name__}: {str(exc)[:60]})") from None

"""Reading profile files with the options a real sensor's export needs: named columns, another
delimiter, a region of interest, and a check that the profile is in mm, not metres.

:func:`read_profile_file` is the one reader behind ``posekit profiler estimate`` and
``posekit profiler replay``; :func:`read_profiles` reads CSV (through :func:`read_csv` with the
default options), ``.npy`` and ``.npz`` files as they are. File safety (size, encoding, array headers)
is :mod:`posekit.io`'s.
"""

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import ConfigError, InputFileError
from ...io import check_input_file, check_rows, load_npy, load_npz_member, npz_members, parse_number, quote, read_text

__all__ = ["ReadOptions", "read_csv", "read_profiles", "read_profile_file", "check_units", "units_hint", "apply_roi",
           "parse_columns", "parse_delimiter", "parse_roi", "METRES_LIMIT", "METRES_SPAN"]

#: A profile whose every |x|, |z| is below this (and that spans less than METRES_SPAN) is in metres.
METRES_LIMIT = 2.0
METRES_SPAN = 1.0
#: Most points of the one profile a CSV holds (an LJ-X8400 profile has 3,200; the stream protocol's
#: frames at most 8,192): counted before any row is parsed.
MAX_CSV_POINTS = 100_000


@dataclass(frozen=True)
class ReadOptions:
    """How to read a profile file.

    Attributes
    ----------
    columns : (str, str) or None
        Header names of the x and z columns of a CSV (case and surrounding spaces ignored);
        None: the header must be exactly ``x,z``.
    delimiter : str
        One character between the cells of a CSV (``','``, ``';'``, ``'\\t'``).
    roi_x_mm, roi_z_mm : (float, float) or None
        Region of interest in F, mm: points with x (z) outside ``[a, b]`` become no-return
        (NaN). None: no limit.
    check_units : bool
        Refuse profiles that look like metres (:func:`check_units`).
    """

    columns: tuple[str, str] | None = None
    delimiter: str = ","
    roi_x_mm: tuple[float, float] | None = None
    roi_z_mm: tuple[float, float] | None = None
    check_units: bool = True

    def __post_init__(self):
        if self.columns is not None and (len(self.columns) != 2 or not all(str(c).strip() for c in self.columns)):
            raise ConfigError(f"ReadOptions: columns must be two header names (x, z), got {self.columns!r}")
        if not (isinstance(self.delimiter, str) and len(self.delimiter) == 1 and self.delimiter not in "\"\r\n"):
            raise ConfigError(f"ReadOptions: delimiter must be one character (not a quote or newline), "
                              f"got {self.delimiter!r}")
        for name in ("roi_x_mm", "roi_z_mm"):
            roi = getattr(self, name)
            if roi is not None and not (len(roi) == 2 and all(math.isfinite(v) for v in roi) and roi[0] < roi[1]):
                raise ConfigError(f"ReadOptions: {name} must be (a, b) in mm with a < b, got {roi!r}")


def parse_columns(text: str | None) -> tuple[str, str] | None:
    """``'x,z'`` (``--columns``) → ``('x', 'z')``; None → None."""
    if text is None:
        return None
    names = [c.strip() for c in str(text).split(",")]
    if len(names) != 2 or not all(names) or names[0].lower() == names[1].lower():
        raise ConfigError(f"--columns: expected two different header names X,Z (e.g. x,z), got {quote(text)}")
    return names[0], names[1]


def parse_delimiter(text: str | None) -> str:
    """``--delimiter``: one character, or ``tab`` / ``\\t``; None → ``','``."""
    if text is None:
        return ","
    value = {"tab": "\t", "\\t": "\t", "space": " "}.get(str(text).lower(), str(text))
    if len(value) != 1 or value in "\"\r\n":
        raise ConfigError(f"--delimiter: expected one character (e.g. ';', or tab), got {quote(text)}")
    return value


def parse_roi(text: str | None, flag: str) -> tuple[float, float] | None:
    """``'A:B'`` (``--roi-x``, ``--roi-z``, mm) → ``(A, B)`` with A < B; None → None."""
    if text is None:
        return None
    parts = str(text).split(":")
    try:
        a, b = (parse_number(p) for p in parts)
        good = math.isfinite(a) and math.isfinite(b) and a < b
    except ValueError:
        good = False
    if len(parts) != 2 or not good:
        raise ConfigError(f"{flag}: expected A:B in mm with A < B (e.g. -40:40), got {quote(text)}")
    return a, b


# --------------------------------------------------------------------------- files


def _csv_expected(opts: ReadOptions) -> str:
    header = "x,z" if opts.columns is None else opts.delimiter.join(opts.columns)
    return f"a profile CSV with header '{header}' and rows of mm values"


def _header_hint(names: list[str], opts: ReadOptions) -> str:
    low = [n.lower() for n in names]
    if len(names) == 1 and opts.delimiter == ",":
        for d in (";", "\t", " "):
            if len([c for c in names[0].split(d) if c.strip()]) >= 2:
                shown = "tab" if d == "\t" else "' '" if d == " " else f"'{d}'"
                return f" (the cells look separated by {shown}: give --delimiter {shown})"
    if "x" in low and "z" in low:
        return " (other columns too: pick two by name with --columns x,z)"
    return " (name the x and z columns with --columns X,Z)" if len(names) > 2 else ""


def read_csv(path: Path, opts: ReadOptions) -> np.ndarray:
    expected = _csv_expected(opts)
    text = read_text(path, expected=expected)
    check_rows(text, str(path), "points (one profile)", error=InputFileError, limit=MAX_CSV_POINTS + 1)
    try:
        reader = csv.reader(io.StringIO(text, newline=""), delimiter=opts.delimiter)
        numbered = [(reader.line_num, r) for r in reader]
    except csv.Error as exc:
        raise InputFileError(f"{path}: line {reader.line_num}: {str(exc)[:80]}; expected {expected}") from None
    # Blank lines are skipped; a row of empty cells (",") is a point with no return.
    numbered = [(line, r) for line, r in numbered if r and not (len(r) == 1 and not r[0].strip())]
    if not numbered:
        raise InputFileError(f"{path}: file is empty; expected {expected}")
    first_line, header = numbered[0]
    while len(header) > 1 and not header[-1].strip():           # a trailing delimiter
        header = header[:-1]
    names = [c.strip() for c in header]
    low = [n.lower() for n in names]
    shown = quote(opts.delimiter.join(header))
    if opts.columns is None:
        if low != ["x", "z"]:
            raise InputFileError(f"{path}: line {first_line}: expected header 'x,z', got {shown}"
                                 + _header_hint(names, opts))
        cols = (0, 1)
    else:
        cols = []
        for want in opts.columns:
            hits = [i for i, n in enumerate(low) if n == want.strip().lower()]
            if len(hits) != 1:
                why = "no column" if not hits else f"{len(hits)} columns"
                raise InputFileError(f"{path}: line {first_line}: {why} named {quote(want.strip())} in the header "
                                     f"{shown}; expected --columns to name two of its columns")
            cols.append(hits[0])
        cols = tuple(cols)
    if len(numbered) == 1:
        raise InputFileError(f"{path}: no data rows after the header {shown}")
    width = len(header)
    label = ",".join(names)
    out = np.empty((len(numbered) - 1, 2))
    for i, (line, row) in enumerate(numbered[1:]):
        if len(row) > width and not any(c.strip() for c in row[width:]):     # trailing delimiters
            row = row[:width]
        if len(row) != width:
            raise InputFileError(f"{path}: line {line}: expected {width} values ({label}), got {len(row)}")
        for j, c in enumerate(cols):
            cell = row[c].strip()
            if cell == "" or cell.lower() == "nan":
                out[i, j] = np.nan
                continue
            try:
                out[i, j] = parse_number(cell)
            except ValueError:
                hint = " (a decimal comma? posekit reads a decimal point)" if "," in cell else ""
                raise InputFileError(f"{path}: line {line}: {quote(cell)} is not a number (mm) or empty/nan"
                                     + hint) from None
            if math.isinf(out[i, j]):
                raise InputFileError(f"{path}: line {line}: infinite value; use an empty cell or nan for no return")
    return out[None]


def units_hint(points) -> str | None:
    """Why a profile looks like metres, or None.

    Parameters
    ----------
    points : array_like, shape (N, 2)
        One profile (x, z); NaN = no return.

    Returns
    -------
    str or None
        ``'looks like metres (every |x|, |z| < 2 and it spans 0.15 x 0.02); posekit expects
        mm (multiply by 1000)'`` when every finite coordinate is below :data:`METRES_LIMIT` in
        magnitude and both spans are below :data:`METRES_SPAN`; None otherwise (also with
        no finite point).
    """
    p = np.asarray(points, dtype=float)
    ok = np.isfinite(p).all(axis=-1)
    if not ok.any():
        return None
    q = p[ok]
    if np.abs(q).max() >= METRES_LIMIT:
        return None
    span = q.max(axis=0) - q.min(axis=0)
    if span.max() >= METRES_SPAN:
        return None
    return (f"looks like metres (every |x|, |z| < {METRES_LIMIT:g} and it spans {span[0]:.3g} x {span[1]:.3g}); "
            "posekit expects mm (multiply by 1000)")


def check_units(profiles, source: str, error=InputFileError) -> None:
    """Raise ``error`` when a profile of a batch looks like metres (see :func:`units_hint`).

    Parameters
    ----------
    profiles : array_like, shape (K, N, 2)
    source : str
        Names the input in the message (a file name).
    """
    profiles = np.asarray(profiles, dtype=float)
    finite = np.isfinite(profiles).all(axis=-1)
    with np.errstate(invalid="ignore"):
        mag = np.where(finite[..., None], np.abs(profiles), 0.0).max(axis=(1, 2))
    suspects = np.flatnonzero(finite.any(axis=1) & (mag < METRES_LIMIT))
    bad = [k for k in suspects if units_hint(profiles[k]) is not None]
    if not bad:
        return
    k = bad[0]
    what = "the profile" if len(profiles) == 1 else f"profile {k}" + (f" (and {len(bad) - 1} more)" if len(bad) > 1 else "")
    raise error(f"{source}: {what} {units_hint(profiles[k])}")


def apply_roi(profiles, roi_x_mm=None, roi_z_mm=None) -> np.ndarray:
    """Points outside the region of interest become no-return (NaN).

    Parameters
    ----------
    profiles : array_like, shape (..., N, 2)
        (x, z) in F, mm.
    roi_x_mm, roi_z_mm : (float, float) or None
        Inclusive ranges of x and z, mm; None: no limit on that axis.

    Returns
    -------
    ndarray, shape (..., N, 2)
        A copy (float64).
    """
    out = np.array(profiles, dtype=np.float64)
    outside = np.zeros(out.shape[:-1], dtype=bool)
    with np.errstate(invalid="ignore"):
        for j, roi in ((0, roi_x_mm), (1, roi_z_mm)):
            if roi is not None:
                outside |= (out[..., j] < roi[0]) | (out[..., j] > roi[1])
    out[outside] = np.nan
    return out


def _check_array(arr, path: Path, what: str) -> np.ndarray:
    if not np.issubdtype(arr.dtype, np.number):
        raise InputFileError(f"{path}: {what} must hold numbers, got dtype {arr.dtype}")
    arr = np.asarray(arr, dtype=np.float64)
    if np.any(np.isinf(arr)):
        raise InputFileError(f"{path}: {what} holds infinite values; use NaN for no return")
    return arr


def read_profiles(path) -> np.ndarray:
    """Read one profile or a batch from a CSV, .npy or .npz file.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    profiles : ndarray, shape (K, N, 2)
        Points (x, z) in the profiler frame F, mm; NaN = no return. K = 1 for a CSV or
        .npy file.

    Raises
    ------
    InputFileError
        If the file is missing, empty, malformed or has the wrong shape; the message
        names the file (and line for a CSV).
    """
    path = Path(path)
    expected = "a .csv (header 'x,z'), .npy or .npz profile file"
    size = check_input_file(path, expected=expected)
    suffix = path.suffix.lower()
    if size == 0:
        raise InputFileError(f"{path}: file is empty; expected {expected}")
    if suffix == ".csv":
        return read_csv(path, ReadOptions(check_units=False))
    if suffix == ".npy":
        arr = load_npy(path)
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise InputFileError(f"{path}: expected an array of shape (N, 2) of (x, z) in mm, got {arr.shape}")
        return _check_array(arr, path, "profile")[None]
    if suffix == ".npz":
        arr = load_npz_member(path, "profiles")
        if arr is None:
            files = npz_members(path)
            raise InputFileError(f"{path}: expected an array 'profiles' of shape (K, N, 2), "
                                 f"found {', '.join(files) or 'no arrays'}")
        if arr.ndim != 3 or arr.shape[2] != 2:
            raise InputFileError(f"{path}: expected 'profiles' of shape (K, N, 2), got {arr.shape}")
        if arr.shape[0] == 0:
            raise InputFileError(f"{path}: 'profiles' holds no profile (K = 0)")
        return _check_array(arr, path, "'profiles'")
    raise InputFileError(f"{path}: unknown file type {quote(path.suffix, 20)}; expected .csv, .npy or .npz")


def read_profile_file(path, options: ReadOptions = ReadOptions()) -> np.ndarray:
    """Read one profile or a batch from a CSV, ``.npy`` or ``.npz`` file, with reading options.

    Parameters
    ----------
    path : str or Path
        CSV (header ``x,z`` or the :attr:`ReadOptions.columns`), ``.npy`` (N, 2) or ``.npz``
        with ``profiles`` (K, N, 2); mm, NaN (or an empty CSV cell) = no return.
    options : ReadOptions

    Returns
    -------
    profiles : ndarray, shape (K, N, 2)
        (x, z) in F, mm; K = 1 for a CSV or ``.npy``; outside the region of interest NaN.

    Raises
    ------
    InputFileError
        If the file is missing, malformed, of the wrong shape, or in metres; one line naming
        the file (and the line of a CSV).
    """
    path = Path(path)
    if path.suffix.lower() == ".csv":
        size = check_input_file(path, expected=_csv_expected(options))
        if size == 0:
            raise InputFileError(f"{path}: file is empty; expected {_csv_expected(options)}")
        profiles = read_csv(path, options)
    else:
        profiles = read_profiles(path)
    if options.check_units:
        check_units(profiles, str(path))
    if options.roi_x_mm is not None or options.roi_z_mm is not None:
        profiles = apply_roi(profiles, options.roi_x_mm, options.roi_z_mm)
    return profiles

"""What the trajectory readers share: numeric rows parsed with the malformed line named, the
tolerances (:data:`QUATERNION_NORM_TOL`, :data:`MAX_POSITION_M`), the record checks (finite values,
unit quaternions, plausible positions, time order) and the conversion of metres and
``[w, x, y, z]`` quaternions into a millimetre :class:`Trajectory`."""

import numpy as np

from posekit.errors import InputFileError
from posekit.geometry import transform_from_quaternion
from posekit.io import check_rows, parse_number
from posekit.localcal.model.trajectory import Trajectory

__all__ = ["QUATERNION_NORM_TOL", "MAX_POSITION_M", "parse_numbers", "parse_lines", "trajectory_from_rows"]

#: Largest accepted deviation of a file quaternion's norm from 1 (files keep 4-9 decimals).
QUATERNION_NORM_TOL = 1e-2

#: Largest position a trajectory file may hold, m (beyond it the numbers are not metres, and
#: squaring them overflows).
MAX_POSITION_M = 1e9


def parse_numbers(path, text: str, n_fields: int, what: str, *, at_least: bool = False,
                  separator: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Numeric rows of a text file, skipping blank lines and ``#`` comments.

    Parameters
    ----------
    path : Path
        The file, for messages.
    text : str
        Its contents.
    n_fields : int
        Numbers expected per row (the first ``n_fields`` are kept when ``at_least``).
    what : str
        The row layout for messages, e.g. ``"12 numbers 'r11 r12 r13 tx ... r33 tz'"``.
    separator : str, optional
        Field separator; whitespace (and commas) by default.

    Returns
    -------
    rows : ndarray, shape (N, n_fields)
    lines : ndarray, shape (N,)
        1-based line number of each row.

    Raises
    ------
    InputFileError
        ``FILE:LINE: expected ..., found ...`` for the first malformed row, or no rows at all.
    """
    check_rows(text, str(path), "poses (one per line)", error=InputFileError)
    fast = _parse_fast(text, n_fields, at_least, separator)
    if fast is not None:
        return fast
    return parse_lines(path, text, n_fields, what, at_least=at_least, separator=separator)


def parse_lines(path, text: str, n_fields: int, what: str, *, at_least: bool = False,
                separator: str | None = None, field_hints: dict[int, str] | None = None,
                expected_lines: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`parse_numbers` line by line in Python, naming the first malformed line.

    For a reader that tried a fast path of its own first
    (:func:`~posekit.localcal.registration.formats.tum.read_tum`). The parameters and results are
    those of :func:`parse_numbers` (without its line-count bound), and:

    Parameters
    ----------
    field_hints : dict of int to str, optional
        Text appended to the message of a row with that many fields (e.g. that 12 numbers look
        like a KITTI file).
    expected_lines : str, optional
        What the lines should hold, in the message of a text without rows; default
        ``"of " + what``.
    """
    rows, lines = [], []
    for number, raw in enumerate(text.splitlines(), start=1):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        fields = ([f.strip() for f in s.split(separator)] if separator
                  else s.replace(",", " ").split())
        if len(fields) < n_fields or (not at_least and len(fields) != n_fields):
            hint = (field_hints or {}).get(len(fields), "")
            raise InputFileError(f"{path}:{number}: expected {what}, found {len(fields)} fields{hint}")
        try:
            rows.append([parse_number(f) for f in fields[:n_fields]])
        except ValueError:
            bad = next(f for f in fields[:n_fields] if not _is_float(f))
            shown = bad if len(bad) <= 40 else bad[:37] + "..."
            raise InputFileError(f"{path}:{number}: expected {what}, found '{shown}'") from None
        lines.append(number)
    if not rows:
        expected = f"of {what}" if expected_lines is None else expected_lines
        raise InputFileError(f"{path}: no poses found (expected lines {expected})")
    return np.asarray(rows, dtype=np.float64), np.asarray(lines)


def _is_float(text: str) -> bool:
    try:
        parse_number(text)
    except ValueError:
        return False
    return True


def _parse_fast(text: str, n_fields: int, at_least: bool, separator: str | None):
    """``(rows, lines)`` of a well-formed text parsed in C (``np.loadtxt``: 2e6 rows in seconds and
    a few hundred MB instead of half a minute and 1.6 GB); None when anything is unusual, so that
    the line-by-line parser names the line."""
    import io
    import warnings

    if not text.isascii() or "_" in text or (separator is None and "," in text):
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            a = np.loadtxt(io.StringIO(text), comments="#", delimiter=separator, ndmin=2, dtype=np.float64)
    except ValueError:
        return None
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] < n_fields or (a.shape[1] != n_fields and not at_least):
        return None
    lines = np.array([k for k, raw in enumerate(text.splitlines(), start=1)
                      if raw.strip() and not raw.lstrip().startswith("#")])
    if lines.size != a.shape[0]:
        return None
    return np.ascontiguousarray(a[:, :n_fields]), lines


def trajectory_from_rows(path, t_s, p_m, q_wxyz, records: list[str] | np.ndarray, *,
                         check_order: bool = True) -> Trajectory:
    """A :class:`Trajectory` (mm) from timestamps, positions in metres and quaternions.

    Parameters
    ----------
    path : Path
        The source, for messages.
    t_s : ndarray, shape (N,)
        Timestamps, s.
    p_m : ndarray, shape (N, 3)
        Positions of the body in the world frame, m.
    q_wxyz : ndarray, shape (N, 4)
        Orientations ``q_world_body`` ``[w, x, y, z]``; the norm must be 1 within 1e-2.
    records : sequence of str, length N
        How each record is named in a message (``"3"`` for line 3 gives ``FILE:3:``,
        ``" message 3 on /pose"`` is used as is after ``FILE:``).
    check_order : bool
        Refuse decreasing timestamps (naming the record) instead of accepting them.

    Raises
    ------
    InputFileError
        The first record with a NaN/infinite value, a non-unit quaternion or a timestamp earlier
        than the previous one.
    """
    t_s = np.asarray(t_s, dtype=np.float64)
    p_m = np.asarray(p_m, dtype=np.float64).reshape(-1, 3)
    q = np.asarray(q_wxyz, dtype=np.float64).reshape(-1, 4)

    def fail(k, what):
        return InputFileError(f"{path}:{records[k]}: {what}")

    finite = np.isfinite(t_s) & np.isfinite(p_m).all(axis=1) & np.isfinite(q).all(axis=1)
    if not finite.all():
        raise fail(int(np.flatnonzero(~finite)[0]), "expected finite numbers, found NaN or infinity")
    big = np.abs(p_m).max(axis=1) > MAX_POSITION_M
    if big.any():
        k = int(np.flatnonzero(big)[0])
        raise fail(k, f"position {np.abs(p_m[k]).max():.3g} m is implausible; expected metres")
    norm = np.linalg.norm(q, axis=1)
    bad = np.abs(norm - 1.0) > QUATERNION_NORM_TOL
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise fail(k, f"expected a unit quaternion, found norm {norm[k]:.4g}")
    if check_order:
        back = np.diff(t_s) < 0
        if back.any():
            k = int(np.flatnonzero(back)[0]) + 1
            raise fail(k, f"timestamps must not decrease: {t_s[k]:.6f} s after {t_s[k - 1]:.6f} s")
    return Trajectory(t_s, transform_from_quaternion(q, p_m * 1000.0))

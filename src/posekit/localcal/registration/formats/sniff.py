"""Which trajectory format a text file holds, from its rows (not its suffix).

The three text formats tell themselves apart by their rows:

* **KITTI** — 12 numbers per row whose columns 1–3, 5–7, 9–11 form a rotation matrix;
* **EuRoC** — at least 8 comma-separated numbers, the first an integer time in nanoseconds
  (≥ 1e12: 17 minutes after 1970 in ns), or the EuRoC header ``#timestamp [ns],p_RS_R_x [m],...``;
* **TUM** — 8 numbers per row (spaces, or commas with a time in seconds), a unit quaternion last.

:func:`sniff_format` looks at the first :data:`SNIFF_ROWS` data rows. A file the rows do not
identify keeps the format its suffix gives (:func:`..formats.detect_format`).
"""

from pathlib import Path

import numpy as np

__all__ = ["SNIFF_BYTES", "SNIFF_ROWS", "sniff_format"]

#: Data rows looked at.
SNIFF_ROWS = 20
#: Bytes read from the head of a file to sniff it.
SNIFF_BYTES = 64 * 1024
#: An integer first column at least this large is a time in ns (EuRoC).
_NS_MIN = 1e12


def _numbers(fields):
    try:
        return [float(f) for f in fields]
    except ValueError:
        return None


def _kitti_row(v) -> bool:
    R = np.array([v[0:3], v[4:7], v[8:11]])
    return bool(np.all(np.isfinite(R)) and np.abs(R @ R.T - np.eye(3)).max() < 1e-2)


def _tum_row(v) -> bool:
    return bool(np.all(np.isfinite(v)) and abs(np.linalg.norm(v[4:8]) - 1.0) < 1e-2)


def sniff_format(path) -> str | None:
    """``'tum'``, ``'kitti'`` or ``'euroc'`` when the first rows of a text file say which, else None.

    Parameters
    ----------
    path : str or Path
        A regular file (a folder, a missing or unreadable file, or a binary one give None).
    """
    path = Path(path)
    try:
        if not path.is_file():
            return None
        with open(path, "rb") as fh:
            head = fh.read(SNIFF_BYTES)
    except OSError:
        return None
    try:
        text = head.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = head[: head.rfind(b"\n") + 1].decode("utf-8-sig", errors="replace") if b"\n" in head else ""
    lines = text.splitlines()
    if len(head) == SNIFF_BYTES and lines:
        lines = lines[:-1]                                   # the last one may be cut
    votes = []
    for raw in lines:
        s = raw.strip()
        if not s:
            continue
        if s.startswith("#"):
            if s.lower().startswith("#timestamp [ns]") or "p_rs_r_x" in s.lower():
                return "euroc"
            continue
        commas = "," in s
        fields = [f.strip() for f in s.split(",")] if commas else s.split()
        v = _numbers(fields)
        if v is None:
            if not votes and s[0].isalpha():                 # a header of column names
                continue
            return None
        if len(v) == 12 and not commas and _kitti_row(v):
            votes.append("kitti")
        elif commas and len(v) >= 8 and "." not in fields[0] and abs(v[0]) >= _NS_MIN:
            votes.append("euroc")
        elif len(v) == 8 and _tum_row(v):
            votes.append("tum")
        else:
            return None
        if len(votes) >= SNIFF_ROWS:
            break
    if votes and all(x == votes[0] for x in votes):
        return votes[0]
    return None

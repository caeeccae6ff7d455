"""Writing pose records: the output of ``posekit profiler estimate``.

Records go out as JSON lines or CSV (:class:`RecordWriter`; the fields and columns are DESIGN.md's
contract). The profile files are read by :mod:`~posekit.profiler.stream.reading`; the truth of a
simulation is written by :mod:`~posekit.profiler.sim.simulate`.
"""

import csv
import json

import numpy as np

from ...errors import InputFileError
from ...io import atomic_file

__all__ = ["RecordWriter", "RECORD_CSV_COLUMNS", "ROTATION_CSV_COLUMNS", "record_to_json"]

RECORD_CSV_COLUMNS = ["index", "status", "tx", "ty", "tz", "qw", "qx", "qy", "qz", "reprojection_um", "error",
                      "std_tx_um", "std_ty_um", "std_tz_um", "std_rx_deg", "std_ry_deg", "std_rz_deg",
                      "chi2", "dof", "reason"]
#: Extra CSV columns (after ``reason``) and the record field they come from, per rotation format.
ROTATION_CSV_COLUMNS = {
    "quat": ([], None),
    "matrix": (["r11", "r12", "r13", "r21", "r22", "r23", "r31", "r32", "r33"], "R"),
    "euler-zyx": (["a_deg", "b_deg", "c_deg"], "euler_zyx_deg"),
    "euler-xyz": (["w_deg", "p_deg", "r_deg"], "euler_xyz_deg"),
}


def _num(v):
    return None if v is None or not np.isfinite(v) else float(v)


def _cell(v) -> str:
    """A float CSV cell: exact round trip, empty for NaN/inf (as JSON writes null)."""
    return repr(float(v)) if np.isfinite(v) else ""


def record_to_json(rec: dict) -> str:
    """One JSON line of a pose record (NaN written as null)."""
    def clean(v):
        if isinstance(v, float):
            return _num(v)
        if isinstance(v, (list, tuple)):
            return [clean(x) for x in v]
        return v
    return json.dumps({k: clean(v) for k, v in rec.items()})


class RecordWriter:
    """Streams pose records as JSON lines or CSV (columns: :data:`RECORD_CSV_COLUMNS`).

    Parameters
    ----------
    out : path or None
        File to write; None writes to ``stream``.
    fmt : {'jsonl', 'csv'} or None
        None: from the suffix of ``out`` (``.csv`` → CSV), JSON lines otherwise.
    stream : text stream, optional
        Where to write when ``out`` is None (e.g. ``sys.stdout``).
    rotation : {'quat', 'matrix', 'euler-zyx', 'euler-xyz'}
        CSV only: the extra rotation columns after ``reason``
        (:data:`ROTATION_CSV_COLUMNS`: ``r11..r33`` row-major, ``a_deg,b_deg,c_deg`` or
        ``w_deg,p_deg,r_deg``). JSON lines write whatever fields the record has.

    Records are dicts with keys ``index, status, t_mm, q_wxyz, reprojection_um,
    corners_mm, std_t_um, std_rot_deg, chi2, dof, reason, error`` (and the rotation field);
    see :mod:`posekit.profiler.estimate.pipeline`.
    """

    def __init__(self, out=None, fmt=None, stream=None, rotation: str = "quat"):
        if fmt is None:
            fmt = "csv" if out is not None and str(out).lower().endswith(".csv") else "jsonl"
        if fmt not in ("jsonl", "csv"):
            raise InputFileError(f"unknown output format '{fmt}'; expected jsonl or csv")
        if rotation not in ROTATION_CSV_COLUMNS:
            raise InputFileError(f"unknown rotation format '{rotation}'; expected one of "
                                 f"{', '.join(ROTATION_CSV_COLUMNS)}")
        self.fmt = fmt
        self._rot_columns, self._rot_key = ROTATION_CSV_COLUMNS[rotation]
        self._own = out is not None
        self._atomic = None
        if out is not None:  # a temporary file renamed into place on a clean close
            self._atomic = atomic_file(out, "w", newline="")
            try:
                self._fh = self._atomic.__enter__()
            except OSError as exc:
                raise InputFileError(f"{out}: cannot write ({exc.strerror or exc})") from None
        else:
            self._fh = stream
        self._csv = csv.writer(self._fh) if fmt == "csv" else None
        if self._csv is not None:
            self._csv.writerow(RECORD_CSV_COLUMNS + self._rot_columns)

    def write(self, rec: dict) -> None:
        if self._csv is None:
            self._fh.write(record_to_json(rec) + "\n")
            self._fh.flush()
            return
        t = rec["t_mm"] or [None] * 3
        q = rec["q_wxyz"] or [None] * 4
        std = (rec.get("std_t_um") or [None] * 3) + (rec.get("std_rot_deg") or [None] * 3)
        vals = [rec["index"], rec["status"], *t, *q, rec["reprojection_um"], rec["error"] or "",
                *std, rec.get("chi2"), rec.get("dof"), rec.get("reason") or ""]
        if self._rot_key is not None:
            rot = rec.get(self._rot_key)
            vals += list(np.ravel(rot)) if rot is not None else [None] * len(self._rot_columns)
        self._csv.writerow(["" if v is None else (_cell(v) if isinstance(v, (float, np.floating)) else v)
                            for v in vals])

    def close(self, exc_info=(None, None, None)) -> None:
        """Finish the output: rename the file into place, or (after an exception) drop it."""
        if self._atomic is not None:
            atomic, self._atomic = self._atomic, None
            atomic.__exit__(*exc_info)
        elif not self._own:
            self._fh.flush()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close(exc)

"""Recorded episodes: what a real welding cell logs, in the folder format of DESIGN.md.

A recorded episode is a folder:

``setup.yaml`` (the cell)
    ``robot`` (a bundled name, or ``{urdf: PATH, base_link: NAME, tip_link: NAME}`` with PATH
    relative to the folder), ``tool`` (4×4 ``T_flange_tool``, mm), ``sensors`` (one entry per
    sensor: a 4×4 ``T_tool_sensor``, mm, the sensor's x–z plane being its laser plane, or
    ``{T_tool_sensor: 4x4, latency_s: s}``: a reading in the row at ``time_s`` was taken at
    ``time_s - latency_s``), ``compliance_rad_per_nm`` (the joint compliance model, 0: none),
    ``angle`` (the log carries angle readings), ``seam_normal`` (the workpiece normal in the base
    frame, for the angle), ``seed`` (the filter's seed), ``noise`` (the cell's sensor noise,
    informational: ``joint_deg``, ``laser_mm``, ``force_n``), optionally ``filter`` (the algorithm's
    keys, as in a seam configuration) and ``profile`` (a profile file relative to the folder, or
    values replacing the default profile's; ``seam track --profile`` overrides it). A setup in the
    layout before issue 26 (a ``filter`` of the old keys) is mapped with a one-line note.
``seam.csv``
    ``x_mm,y_mm,z_mm``: the nominal seam in the robot base frame, in travel order.
``log.csv``
    One row per sample: ``time_s``, ``qref_1..qref_n`` (rad, the program's reference joints),
    ``q_1..q_n`` (rad, measured), ``fx_n,fy_n,fz_n`` (force on the tool, tool frame of the
    measured pose), optionally ``mx_nm,my_nm,mz_nm`` (the torque of a 6-D wrench, N·m, same
    frame), and for each sensor k ``m{k}_x_mm,m{k}_z_mm`` (the seam's crossing of its laser
    plane in the sensor frame; empty = no reading), optionally ``m{k}_angle_rad`` and ``m{k}_t_s``
    (the reading's own time stamp, same clock as ``time_s``, at most ``time_s``: it overrides the
    sensor's latency). A row with empty joints is a laser sample at its own time: its joints (and
    an empty force) are interpolated linearly in time from the neighbouring rows.
``truth.csv`` (optional; simulated episodes)
    ``time_s`` and ``T_seam_tool`` as ``tx_mm,ty_mm,tz_mm,qw,qx,qy,qz``, one row per log row.
    The seam frame of a step is the nominal tool pose ``Fk(qref)`` there (x across, y along
    the travel, z along the tool axis): the frame in which ``posekit seam simulate`` reports
    its errors.

:func:`write_episode_log` writes a simulated episode in this format; :func:`read_episode_log`
reads and checks one (every failure one line: ``FILE line N: what was wrong; what was
expected``).
"""

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from posekit.errors import InputFileError
from posekit.geometry import invert_transform, quaternion_from_matrix, transform_from_quaternion
from posekit.io import parse_number
from posekit.seam.frontend.config import (
    MAX_STEPS,
    SeamConfig,
)
from posekit.seam.frontend.logs_setup import LogSetup, read_setup, setup_profile

__all__ = [
    "LOG_FILES",
    "MAX_SEAM_POINTS",
    "EpisodeLog",
    "log_columns",
    "read_episode_log",
    "write_episode_log",
]

#: The files of a recorded episode (truth.csv optional).
LOG_FILES = ("setup.yaml", "seam.csv", "log.csv", "truth.csv")
#: Most points of ``seam.csv`` (10 m at 0.01 mm).
MAX_SEAM_POINTS = 1_000_000
TRUTH_COLUMNS = ("time_s", "tx_mm", "ty_mm", "tz_mm", "qw", "qx", "qy", "qz")


@dataclass
class EpisodeLog:
    """A recorded episode read by :func:`read_episode_log`.

    Attributes
    ----------
    folder : Path
    setup : LogSetup
    config : SeamConfig
        The configuration the filter runs with (:meth:`LogSetup.seam_config`).
    seam_mm : ndarray, shape (K, 3)
        Nominal seam, robot base frame, mm.
    time_s : ndarray, shape (T,)
    qref, q : ndarray, shape (T, n)
        Reference and measured joints, rad (interpolated on laser-only rows).
    force_tool_n : ndarray, shape (T, 3)
        Force on the tool in the tool frame, N.
    torque_tool_nm : ndarray, shape (T, 3) or None
        Torque of the wrench, tool frame, N·m (None: the log has no torque).
    laser_mm : ndarray, shape (T, S, 2)
        Laser readings ``(x, z)`` in each sensor frame, mm; NaN = no reading.
    angle_rad : ndarray, shape (T, S) or None
    reading_time_s : ndarray, shape (T, S) or None
        The readings' own stamps (``m{k}_t_s``, s; NaN: none, the sensor's latency applies).
    interpolated : ndarray of bool, shape (T,)
        Rows whose joints were interpolated (laser samples at their own time).
    truth_seam_tool : ndarray, shape (T, 4, 4) or None
        ``T_seam_tool`` from ``truth.csv`` (seam frame = ``Fk(qref)`` of the row), mm.
    """

    folder: Path
    setup: LogSetup
    config: SeamConfig
    seam_mm: np.ndarray
    time_s: np.ndarray
    qref: np.ndarray
    q: np.ndarray
    force_tool_n: np.ndarray
    torque_tool_nm: np.ndarray | None
    laser_mm: np.ndarray
    angle_rad: np.ndarray | None
    reading_time_s: np.ndarray | None
    interpolated: np.ndarray
    truth_seam_tool: np.ndarray | None


def log_columns(n_joints: int, n_sensors: int, *, torque: bool = False, angle: bool = False,
                stamps: bool = False) -> list[str]:
    """The columns of ``log.csv`` for ``n_joints`` joints and ``n_sensors`` sensors, in order."""
    cols = ["time_s", *(f"qref_{j + 1}" for j in range(n_joints)), *(f"q_{j + 1}" for j in range(n_joints)),
            "fx_n", "fy_n", "fz_n"]
    if torque:
        cols += ["mx_nm", "my_nm", "mz_nm"]
    for k in range(1, n_sensors + 1):
        cols += ([f"m{k}_x_mm", f"m{k}_z_mm"] + ([f"m{k}_angle_rad"] if angle else [])
                 + ([f"m{k}_t_s"] if stamps else []))
    return cols


def _fmt(v: float) -> str:
    """A number for a log file: exact (``repr``), empty for NaN."""
    return "" if not math.isfinite(v) else repr(float(v))


def _write_rows(path: Path, header, rows) -> None:
    lines = [",".join(header)]
    lines += [",".join(_fmt(v) for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def _matrix(T) -> list:
    return [[float(v) for v in row] for row in np.asarray(T, dtype=np.float64)]


def write_episode_log(folder, cfg: SeamConfig, data, seed: int) -> Path:
    """Write a simulated episode as a recorded one (the format of the module docstring).

    Parameters
    ----------
    folder : path-like
        An existing (empty) folder; the CLI passes a staged one.
    cfg : SeamConfig
        The episode's configuration.
    data : SimulatedData
        :func:`~posekit.seam.frontend.simulate.simulate_data` of ``(cfg, seed)``.
    seed : int
        The episode seed (the filter of :func:`posekit.seam.frontend.tracker.track_log` then
        draws the same numbers as :func:`~posekit.seam.frontend.episode.run_episode`).

    Returns
    -------
    Path
        ``folder``.
    """
    folder = Path(folder)
    nt = data.nominal
    robot = {k: v for k, v in cfg.cell.robot.model_dump(mode="python").items()
             if k in ("model", "urdf", "base_link", "tip_link") and v is not None}
    lat = cfg.cell.sensors.latency_s
    sensors = [_matrix(M) if lat is None or lat[i] is None else {"T_tool_sensor": _matrix(M), "latency_s": lat[i]}
               for i, M in enumerate(cfg.cell.sensors.resolved_mounts())]
    sim = cfg.simulation
    setup = {
        "robot": robot,
        "tool": _matrix(cfg.cell.robot.tool_matrix()),
        "sensors": sensors,
        "compliance_rad_per_nm": float(cfg.cell.compliance_rad_per_nm),
        "angle": bool(cfg.cell.sensors.angle),
        "seam_normal": [float(v) for v in nt.seam_normal],
        "seed": int(seed),
        "noise": {"joint_deg": float(sim.joint_noise_deg), "laser_mm": float(sim.laser_noise_mm),
                  "force_n": float(sim.force_sensor_noise_n)},
        "filter": cfg.filter.model_dump(mode="json"),
    }
    (folder / "setup.yaml").write_text("# posekit seam recorded episode (simulated)\n"
                                       + yaml.safe_dump(setup, sort_keys=False, default_flow_style=None), encoding="utf-8")
    _write_rows(folder / "seam.csv", ("x_mm", "y_mm", "z_mm"), nt.seam)
    # the force in the tool frame of the measured pose (what a wrist force sensor reports)
    R_meas = nt.chain.forward_kinematics(data.q_meas)[:, :3, :3]
    f_tool = np.matmul(np.swapaxes(R_meas, 1, 2), data.force_meas_n[..., None])[..., 0]
    S = data.laser_mm.shape[1]
    angle = bool(cfg.cell.sensors.angle)
    cols = log_columns(nt.q.shape[1], S, angle=angle)
    parts = [nt.t_s[:, None], nt.q, data.q_meas, f_tool]
    for k in range(S):
        parts.append(data.laser_mm[:, k])
        if angle:
            parts.append(data.angle_rad[:, k:k + 1])
    _write_rows(folder / "log.csv", cols, np.hstack(parts))
    T_seam_tool = np.matmul(invert_transform(nt.T_nominal), data.truth)
    q = np.asarray(quaternion_from_matrix(T_seam_tool[:, :3, :3]), dtype=np.float64).reshape(-1, 4)
    _write_rows(folder / "truth.csv", TRUTH_COLUMNS, np.hstack([nt.t_s[:, None], T_seam_tool[:, :3, 3], q]))
    return folder


# ------------------------------------------------------------------------------- reading


def _csv_rows(path: Path, expected: str, max_rows: int):
    """``(header, [(line number, fields)])`` of a small CSV (comma-separated, ``#`` comments)."""
    from posekit.io import check_rows, read_text

    text = read_text(path, expected=expected, error=InputFileError)
    check_rows(text, str(path), "lines (rows, comments and blank lines)", error=InputFileError,
               limit=2 * max_rows + 1000)          # before splitting: comments and blank lines leave room
    header, rows = None, []
    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        fields = [f.strip() for f in s.split(",")]
        if header is None:
            header = fields
            continue
        if len(rows) == max_rows:
            raise InputFileError(f"{path} line {lineno}: more than {max_rows:,} rows; expected at most {max_rows:,}")
        rows.append((lineno, fields))
    if header is None:
        raise InputFileError(f"{path}: file is empty; expected {expected}")
    return header, rows


def _number(path: Path, lineno: int, name: str, field: str, *, empty_ok: bool) -> float:
    if field == "":
        if empty_ok:
            return math.nan
        raise InputFileError(f"{path} line {lineno}: {name} is empty; expected a number")
    try:
        v = parse_number(field)
    except ValueError:
        raise InputFileError(f"{path} line {lineno}: {name} is '{field[:30]}'; expected a number") from None
    if not math.isfinite(v):
        raise InputFileError(f"{path} line {lineno}: {name} is '{field[:30]}'; expected a finite number")
    limit, unit = _magnitude(name)
    if abs(v) > limit:
        raise InputFileError(f"{path} line {lineno}: {name} is {v:g}; expected a magnitude of at most "
                             f"{limit:g}{' ' + unit if unit else ''}")
    return v


def _magnitude(name: str) -> tuple[float, str]:
    """Largest plausible magnitude of column ``name`` and its unit: beyond it a value is not in
    the column's unit (or is garbage), and the filter would turn it into a confident wrong pose."""
    if name == "time_s":
        return 1e9, "s"
    if name.startswith(("q_", "qref_")) or name.endswith("_rad"):
        return 1e3, "rad"
    if name.endswith("_mm"):
        return 1e7, "mm"
    if name.endswith("_nm"):
        return 1e6, "N·m"
    if name.endswith("_n"):
        return 1e6, "N"
    return 1e9, ""


def _table(path: Path, header, rows, *, empty_ok=()) -> np.ndarray:
    out = np.empty((len(rows), len(header)))
    for i, (lineno, fields) in enumerate(rows):
        if len(fields) != len(header):
            raise InputFileError(f"{path} line {lineno}: {len(fields)} values; expected {len(header)} "
                                 f"({','.join(header)[:80]})")
        for j, (name, field) in enumerate(zip(header, fields)):
            out[i, j] = _number(path, lineno, name, field, empty_ok=name in empty_ok)
    return out


def _interpolate(path: Path, lines, t: np.ndarray, cols: np.ndarray, what: str) -> np.ndarray:
    """Fill the NaN rows of ``cols (T, m)`` linearly in time from the rows that have values."""
    have = np.all(np.isfinite(cols), axis=1)
    if have.all():
        return cols
    if not have.any():
        raise InputFileError(f"{path}: no row has {what}; expected at least the first and the last sample")
    first, last = np.flatnonzero(have)[[0, -1]]
    for i in (0, len(t) - 1):
        if not have[i]:
            raise InputFileError(f"{path} line {lines[i]}: {what} empty on the {'first' if i == 0 else 'last'} "
                                 f"sample; expected values there (empty rows are interpolated between samples)")
    out = cols.copy()
    for j in range(cols.shape[1]):
        out[~have, j] = np.interp(t[~have], t[have], cols[have, j])
    return out


def read_episode_log(folder, profile=None) -> EpisodeLog:
    """Read and check a recorded episode folder (see the module docstring).

    ``profile``: a profile file or :class:`~posekit.seam.frontend.profile.ProfileModel` the filter runs with
    (default: the setup's ``profile``, else the shipped default).

    Raises
    ------
    InputFileError
        A missing file, a wrong column, a value that is not a number, times that do not
        increase, a joint row half empty, ...: one line naming the file and the line.
    ConfigError
        An impossible filter parameter in ``setup.yaml`` (naming the key).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputFileError(f"{folder}: not a folder; expected a recorded episode (setup.yaml, seam.csv, log.csv)")
    setup = read_setup(folder)
    if profile is not None:
        from posekit.seam.frontend.profile import resolve_profile

        profile = resolve_profile(profile, None, "--profile")
    cfg = setup.seam_config(str(folder / "setup.yaml"), profile=profile or setup_profile(setup, folder))
    from posekit.seam.frontend.trajectories import tool_chain

    n = tool_chain(cfg.cell.robot).n_joints
    S = len(setup.sensors)
    # seam.csv
    path = folder / "seam.csv"
    header, rows = _csv_rows(path, "the nominal seam 'x_mm,y_mm,z_mm', one point per line", MAX_SEAM_POINTS)
    if header != ["x_mm", "y_mm", "z_mm"]:
        raise InputFileError(f"{path} line 1: expected the header 'x_mm,y_mm,z_mm', got '{','.join(header)[:60]}'")
    seam = _table(path, header, rows)
    if seam.shape[0] < 2:
        raise InputFileError(f"{path}: {seam.shape[0]} seam points; expected at least 2")
    # log.csv
    path = folder / "log.csv"
    header, rows = _csv_rows(path, "one sample per line: time_s, qref_*, q_*, fx_n.., m{k}_x_mm..", MAX_STEPS)
    torque = "mx_nm" in header
    angle = any(h.endswith("_angle_rad") for h in header)
    stamps = any(h.endswith("_t_s") for h in header)
    expected = log_columns(n, S, torque=torque, angle=angle, stamps=stamps)
    if header != expected:
        missing = [c for c in expected if c not in header]
        extra = [c for c in header if c not in expected]
        what = (f"missing {','.join(missing[:4])}" if missing else
                f"unexpected {','.join(extra[:4])}" if extra else "columns out of order")
        raise InputFileError(f"{path} line 1: {what}; expected the columns {','.join(expected)[:200]} "
                             f"({n} joints of {cfg.cell.robot.label}, {S} sensor(s) in setup.yaml)")
    if not rows:
        raise InputFileError(f"{path}: no samples; expected one row per sample after the header")
    empty = set(expected) - {"time_s"}
    data = _table(path, header, rows, empty_ok=empty)
    lines = [ln for ln, _ in rows]
    t = data[:, 0]
    bad = np.flatnonzero(np.diff(t) <= 0.0)
    if bad.size:
        i = bad[0] + 1
        raise InputFileError(f"{path} line {lines[i]}: time_s {t[i]:g} after {t[i - 1]:g}; expected strictly "
                             f"increasing times")
    col = {c: i for i, c in enumerate(header)}

    def block(names):
        return data[:, [col[c] for c in names]]

    def check_whole(names, what):
        b = block(names)
        fin = np.isfinite(b)
        part = np.flatnonzero(fin.any(axis=1) & ~fin.all(axis=1))
        if part.size:
            raise InputFileError(f"{path} line {lines[part[0]]}: {what} partly empty; expected all of "
                                 f"{names[0]}..{names[-1]} or none")
        return b

    joints = check_whole([f"qref_{j + 1}" for j in range(n)] + [f"q_{j + 1}" for j in range(n)], "joints")
    interpolated = ~np.all(np.isfinite(joints), axis=1)
    joints = _interpolate(path, lines, t, joints, "joints")
    force = _interpolate(path, lines, t, check_whole(["fx_n", "fy_n", "fz_n"], "force"), "force fx_n,fy_n,fz_n")
    torque_nm = (_interpolate(path, lines, t, check_whole(["mx_nm", "my_nm", "mz_nm"], "torque"), "torque")
                 if torque else None)
    laser = np.full((len(t), S, 2), np.nan)
    for k in range(S):
        laser[:, k] = check_whole([f"m{k + 1}_x_mm", f"m{k + 1}_z_mm"], f"sensor {k + 1}'s reading")
    angles = block([f"m{k + 1}_angle_rad" for k in range(S)]) if angle else None
    stamp = None
    if stamps:
        stamp = block([f"m{k + 1}_t_s" for k in range(S)])
        late = np.flatnonzero(np.any(stamp > t[:, None] + 1e-9 * np.maximum(1.0, np.abs(t[:, None])), axis=1))
        if late.size:
            i = late[0]
            k = int(np.flatnonzero(stamp[i] > t[i])[0])
            raise InputFileError(f"{path} line {lines[i]}: m{k + 1}_t_s {stamp[i, k]:g} after time_s {t[i]:g}; "
                                 "expected the reading's own time, at most the row's")
    # truth.csv
    truth = None
    path = folder / "truth.csv"
    if path.exists():
        header, rows = _csv_rows(path, "time_s and T_seam_tool per log row", MAX_STEPS)
        if header != list(TRUTH_COLUMNS):
            raise InputFileError(f"{path} line 1: expected the header '{','.join(TRUTH_COLUMNS)}', "
                                 f"got '{','.join(header)[:80]}'")
        tr = _table(path, header, rows)
        if tr.shape[0] != len(t):
            raise InputFileError(f"{path}: {tr.shape[0]} rows; expected one per log.csv sample ({len(t)})")
        off = np.flatnonzero(np.abs(tr[:, 0] - t) > 1e-9 * np.maximum(1.0, np.abs(t)))
        if off.size:
            i = off[0]
            raise InputFileError(f"{path} line {rows[i][0]}: time_s {tr[i, 0]:g}; expected {t[i]:g} as in log.csv")
        qn = np.linalg.norm(tr[:, 4:], axis=1)
        badq = np.flatnonzero(np.abs(qn - 1.0) > 1e-6)
        if badq.size:
            i = badq[0]
            raise InputFileError(f"{path} line {rows[i][0]}: quaternion norm {qn[i]:.6g}; expected a unit quaternion")
        truth = transform_from_quaternion(tr[:, 4:] / qn[:, None], tr[:, 1:4])
    return EpisodeLog(folder, setup, cfg, seam, t, joints[:, :n], joints[:, n:], force, torque_nm, laser, angles,
                      stamp, interpolated, truth)

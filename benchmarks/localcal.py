"""Benchmark behind ``posekit bench localcal``.

Times ``posekit localcal match CAMERA.tum KINEMATIC.tum --out R.json`` (timestamps: clock offset
estimated, association, robust Umeyama, verdict and uncertainty) against evo, the tool a user
would otherwise pick for aligning a SLAM trajectory with its ground truth, on the same two TUM
files in the same run. The evo side is what ``evo_ape tum KINEMATIC CAMERA -a`` computes, called
through its Python API (``file_interface.read_tum_trajectory_file`` twice,
``sync.associate_trajectories(max_diff=0.01)``, ``align`` (Umeyama, SE(3)) and the APE
translation statistics) — without evo's command-line start-up, so evo's time is a lower bound.

Each side runs in a fresh Python process (imports included, timed from process start), so its
peak memory (``ru_maxrss``) is its own. Passes alternate ours / evo; medians are reported. The
files: a smooth 3D path with turning orientations, ``rows`` poses each at 100 Hz (camera stamps
3 ms late), 1 mm noise, written once into a temporary folder. Before timing counts, both results
must agree (rotation 0.01 deg, translation 0.5 mm; our clock offset is estimated, evo's is 0).

Default size 200,000 + 200,000 rows (a few seconds per side); the issue's size is
``posekit bench localcal --rows 1000000`` (targets: ours no slower than evo, peak <= 1 GB).
``count`` is the number of passes (default 3; 1 at 1e6 rows).
"""

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DEFAULT_ROWS = 200_000
RATE_HZ = 100.0
TARGET_PEAK_MB = 1024.0
TOL_ROT_DEG = 0.01
TOL_T_MM = 0.5
PEER = "evo (read_tum_trajectory_file x2, associate_trajectories, align SE(3) Umeyama, APE stats)"

_OURS = r"""
import json, resource, sys, time
t0 = time.perf_counter()
from posekit.cli.main import main
rc = main(["localcal", "match", sys.argv[1], sys.argv[2], "--out", sys.argv[3]])
dt = time.perf_counter() - t0
print(json.dumps({"rc": rc, "s": dt, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""

_EVO = r"""
import json, resource, sys, time
t0 = time.perf_counter()
from evo.core import metrics, sync
from evo.tools import file_interface
ref = file_interface.read_tum_trajectory_file(sys.argv[2])
est = file_interface.read_tum_trajectory_file(sys.argv[1])
ref, est = sync.associate_trajectories(ref, est, max_diff=0.01)
r, t, s = est.align(ref, correct_scale=False)
ape = metrics.APE(metrics.PoseRelation.translation_part)
ape.process_data((ref, est))
rmse = ape.get_statistic(metrics.StatisticsType.rmse)
dt = time.perf_counter() - t0
print(json.dumps({"s": dt, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "R": r.tolist(), "t_mm": (t * 1000).tolist(), "rmse_mm": rmse * 1000, "n": est.num_poses}))
"""


def have_evo() -> bool:
    """True when evo is importable (it is the peer; ``pip install evo``)."""
    import importlib.util
    return importlib.util.find_spec("evo") is not None


def write_pair(folder: Path, rows: int, seed: int = 0):
    """Two TUM files (camera in W, kinematic in B) of one smooth path; returns their paths and T_B_W."""
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(seed)
    t = np.arange(rows) / RATE_HZ
    w = 2 * np.pi * np.array([0.013, 0.021, 0.008])
    p = np.c_[0.4 * np.sin(w[0] * t), 0.3 * np.sin(w[1] * t + 1), 0.2 * np.sin(w[2] * t + 2)]     # m
    rot = Rotation.from_rotvec(np.c_[0.3 * np.sin(0.05 * t), 0.2 * np.cos(0.07 * t), 0.1 * np.sin(0.03 * t)])
    R_BW = Rotation.from_euler("xyz", [20, -30, 50], degrees=True).as_matrix()
    t_BW = np.array([0.5, -0.2, 0.3])
    fmt = "%.6f %.6f %.6f %.6f %.7f %.7f %.7f %.7f"
    kin, cam = folder / "kinematic.tum", folder / "camera.tum"
    np.savetxt(kin, np.column_stack([t, p + rng.normal(0, 0.001, p.shape), rot.as_quat()]), fmt=fmt)
    pw = (p - t_BW) @ R_BW
    rw = Rotation.from_matrix(R_BW.T) * rot
    np.savetxt(cam, np.column_stack([t + 0.003, pw + rng.normal(0, 0.001, p.shape), rw.as_quat()]), fmt=fmt)
    return cam, kin


def _child(code, *args):
    env = dict(os.environ)
    src = str(HERE.parent / "src")
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    out = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, env=env)
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
    if out.returncode != 0 or not lines:
        from posekit.errors import ConfigError
        raise ConfigError(f"benchmark child failed (exit {out.returncode}): "
                          f"{(out.stderr.strip().splitlines() or ['no output'])[-1]}")
    return json.loads(lines[-1])


def run(count=None, verbose=True, rows=None):
    """Run the benchmark; returns the JSON rows (``posekit bench`` contract).

    ``rows``: poses per file (default 200,000; the issue's size is 1,000,000). ``count``: passes
    (default 3, or 1 from 500,000 rows on).
    """
    rows = DEFAULT_ROWS if rows is None else int(rows)
    passes = (3 if rows < 500_000 else 1) if count is None else max(int(count), 1)
    evo = have_evo()
    if verbose and not evo:
        print("posekit bench localcal: evo is NOT installed (pip install evo): timing posekit only, no comparison",
              file=sys.stderr)
    ours, peer = [], []
    with tempfile.TemporaryDirectory(prefix="posekit-bench-localcal-") as tmp:
        cam, kin = write_pair(Path(tmp), rows)
        out = Path(tmp) / "result.json"
        for _ in range(passes):
            ours.append(_child(_OURS, cam, kin, out))
            if evo:
                peer.append(_child(_EVO, cam, kin))
        res = json.loads(out.read_text())
    row = {"name": "localcal.match.tum", "rows": rows, "passes": passes,
           "ours_ms": float(np.median([o["s"] for o in ours]) * 1e3),
           "ours_peak_mb": float(max(o["peak_mb"] for o in ours)),
           "status": res["status"], "exit": ours[-1]["rc"]}
    row["realtime_factor"] = (1e3 / RATE_HZ) / (row["ours_ms"] / rows)
    if evo:
        import evo as evo_mod
        from scipy.spatial.transform import Rotation
        R_e, t_e = np.array(peer[-1]["R"]), np.array(peer[-1]["t_mm"])
        d_rot = float(np.rad2deg(Rotation.from_matrix(np.array(res["R"]) @ R_e.T).magnitude()))
        d_t = float(np.linalg.norm(np.array(res["t_mm"]) - t_e))
        if d_rot > TOL_ROT_DEG or d_t > TOL_T_MM:
            from posekit.errors import ConfigError
            raise ConfigError(f"posekit and evo disagree: {d_rot:.4f} deg, {d_t:.3f} mm (tolerance "
                              f"{TOL_ROT_DEG} deg, {TOL_T_MM} mm)")
        row.update({"baseline": f"evo {evo_mod.__version__}: {PEER}",
                    "baseline_ms": float(np.median([p["s"] for p in peer]) * 1e3),
                    "baseline_peak_mb": float(max(p["peak_mb"] for p in peer)),
                    "agree_rot_deg": d_rot, "agree_t_mm": d_t})
        row["speedup"] = row["baseline_ms"] / row["ours_ms"]
    else:
        row.update({"baseline": "evo (not installed: pip install evo)", "baseline_ms": None, "speedup": None})
    if verbose:
        print(f"posekit bench localcal: `posekit localcal match` vs {row['baseline']}; {rows:,} + {rows:,} TUM rows, "
              f"each side a fresh process (imports included), median of {passes} pass(es)")
        print(f"  posekit: {row['ours_ms'] / 1e3:8.2f} s, peak {row['ours_peak_mb']:7.0f} MB, verdict {row['status']}")
        if evo:
            print(f"  evo:     {row['baseline_ms'] / 1e3:8.2f} s, peak {row['baseline_peak_mb']:7.0f} MB")
            print(f"  evo / posekit time {row['speedup']:.2f} (target >= 1: "
                  f"{'met' if row['speedup'] >= 1 else 'NOT met'}); peak <= {TARGET_PEAK_MB:.0f} MB: "
                  f"{'met' if row['ours_peak_mb'] <= TARGET_PEAK_MB else 'NOT met'}; agreement "
                  f"{row['agree_rot_deg']:.1e} deg, {row['agree_t_mm']:.3f} mm")
        else:
            print("  evo: not installed (pip install evo) — no comparison made")
    return [row]


if __name__ == "__main__":  # pragma: no cover
    sys.path.insert(0, str(HERE.parent / "src"))
    from posekit.errors import PosekitError
    try:
        run(rows=int(sys.argv[1]) if len(sys.argv) > 1 else None)
    except PosekitError as exc:
        print(f"posekit: error: {exc}", file=sys.stderr)
        sys.exit(1)

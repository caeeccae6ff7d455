"""Benchmark behind ``posekit bench profiler``.

Times, per profile on one thread, corner detection (CD) and posture computation (PC) of
posekit over >= 2,000 simulated LJ-X8400-like profiles of the bundled 5-corner gauge,
and in the same run the peers a user would otherwise pick:

* the camera pipeline of the paper's Table III: an 8-bit 2590×1942 image of a chessboard
  with 3×4 inner corners through OpenCV ``findChessboardCorners`` (default flags) +
  ``cornerSubPix`` (CD) and ``solvePnP`` SQPNP (PC);
* for the refinement alone, ``scipy.optimize.least_squares`` (LM) on the same
  maximum-likelihood problem, started from the same closed form.

Corner detection is timed three ways: the RDP detector (``detect_corners(profile, n)``,
the paper's pipeline) on ideal profiles (``profiler.cd``), and the model-based detector
(``detect_corners(profile, gauge)``) on the same ideal profiles (``profiler.cd.model``) and
on realistic ones (``profiler.cd.model.realistic``: ``RealismModel.realistic()`` — rounded
and chamfered ridges, plate and fixture in view, multipath, machining and scale error,
dropouts), where the RDP detector fails. Target: model-based CD median <= 30 µs on
realistic profiles.

``profiler.server_frame.pc`` is the pose server's per-frame PC (pose, covariance, verdict with
both corner orders, the record: ``timing_ms.PC`` of a streamed record) on a smooth trajectory.

Medians and p99 are reported; the machines are shared and noisy, so compare ratios.
"""

import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SENSOR_PERIOD_MS = 1.0       # LJ-X8400 at its maximum rate, 1 kHz


def _time_ours(profiles, gauge):
    from posekit.profiler.estimate.corner_params import CornerParams
    from posekit.profiler.estimate.corners import detect_corners_unchecked
    from posekit.profiler.estimate.solve import _solve_raw  # the raw kernels, as the paper times them

    params = CornerParams()
    n = gauge.n_corners
    cd = np.empty(len(profiles))
    pc = np.empty(len(profiles))
    failures = 0
    for k, prof in enumerate(profiles):
        t0 = time.perf_counter_ns()
        r = detect_corners_unchecked(prof, n, params)
        t1 = time.perf_counter_ns()
        if r[0] != 0:
            failures += 1
            cd[k] = pc[k] = np.nan
            continue
        s = _solve_raw(r[2], r[3], gauge, 1, 0)
        t2 = time.perf_counter_ns()
        failures += s.status != 0
        cd[k] = (t1 - t0) * 1e-6
        pc[k] = (t2 - t1) * 1e-6
    return cd[np.isfinite(cd)], pc[np.isfinite(pc)], failures


def _time_cd(profiles, gauge, model: bool):
    """Corner detection alone (unchecked path), per profile; ``(ms, failures)``."""
    from posekit.profiler.estimate.corner_params import CornerParams
    from posekit.profiler.estimate.corners import detect_corners_unchecked, gauge_turns

    params = CornerParams()
    turns = gauge_turns(gauge) if model else None
    n = gauge.n_corners
    ts = np.empty(len(profiles))
    failures = 0
    for k, prof in enumerate(profiles):
        t0 = time.perf_counter_ns()
        r = detect_corners_unchecked(prof, n, params, turns)
        ts[k] = (time.perf_counter_ns() - t0) * 1e-6
        failures += r[0] != 0
    return ts, failures


def _time_api(profiles, gauge, count=300):
    from posekit.profiler import estimate_pose

    ts = np.empty(min(count, len(profiles)))
    for k in range(len(ts)):
        t0 = time.perf_counter_ns()
        estimate_pose(profiles[k], gauge)
        ts[k] = (time.perf_counter_ns() - t0) * 1e-6
    return ts


def _time_server(gauge, count=1000, passes=3):
    """The pose server's per-frame pose computation (PC: pose, covariance, verdict, record; the
    ``timing_ms.PC`` of a streamed record) on a smooth closed trajectory, as at 1 kHz."""
    from posekit.profiler import NoiseModel, render_profiles
    from posekit.profiler.sim.poses import loop_poses
    from posekit.profiler.stream.protocol import Frame
    from posekit.profiler.stream.server import PoseServer

    Ts = loop_poses(gauge, count)
    profiles = render_profiles(gauge, Ts, NoiseModel(), rng=5).astype(np.float32).astype(np.float64)
    server = PoseServer(gauge)              # not started: the worker's step alone, in this thread
    pc = []
    seq = 0
    for rep in range(passes + 1):
        for prof in profiles:
            rec = server._process(Frame(seq, time.perf_counter_ns(), prof, time.perf_counter_ns()))
            seq += 1
            if rep > 0:                     # the first pass warms up
                pc.append(rec["timing_ms"]["PC"])
    return np.asarray(pc)


def _time_scipy(profiles, gauge, count=200):
    """scipy least_squares (LM) on the ML reprojection problem, same start and weights."""
    from scipy.optimize import least_squares

    from posekit.geometry import invert_transform, se3_exp
    from posekit.profiler import closed_form, detect_corners

    def residual(xi, T0, corners, L_inv):
        T = se3_exp(xi) @ T0
        q = gauge.ridge_q @ T[:3, :3].T + T[:3, 3]
        s = gauge.ridge_s @ T[:3, :3].T
        p = q - (q[:, 1] / s[:, 1])[:, None] * s
        return L_inv @ (corners - p[:, [0, 2]]).ravel()

    ts = np.empty(min(count, len(profiles)))
    for k in range(len(ts)):
        c = detect_corners(profiles[k], gauge.n_corners)
        L_inv = np.linalg.inv(np.linalg.cholesky(c.cov))
        t0 = time.perf_counter_ns()
        T0 = invert_transform(closed_form(c.points, gauge))
        least_squares(residual, np.zeros(6), args=(T0, c.points, L_inv), method="lm")
        ts[k] = (time.perf_counter_ns() - t0) * 1e-6
    return ts


def _stats(a):
    return float(np.median(a)), float(np.percentile(a, 99))


def run(count=None, verbose=True):
    """Run the benchmark; returns the JSON rows (DESIGN.md ``posekit bench`` contract)."""
    from posekit.profiler import NoiseModel, bundled_gauge, render_profiles, sample_poses
    from posekit.profiler.sim.realism import RealismModel

    count = 2000 if count is None else max(int(count), 100)
    gauge = bundled_gauge("demo-5")
    rng = np.random.default_rng(0)
    Ts = sample_poses(gauge, count, rng)
    profiles = np.ascontiguousarray(render_profiles(gauge, Ts, NoiseModel(), rng))
    realistic = np.ascontiguousarray(render_profiles(gauge, Ts, NoiseModel(), rng, realism=RealismModel.realistic()))
    # Warm-up: load the kernels, then keep the core busy for ~2 s (on this VM the first few
    # hundred calls after an idle spell run at half speed while the vCPU gets scheduled).
    t_end = time.perf_counter() + 2.0
    while time.perf_counter() < t_end:
        _time_ours(profiles[:200], gauge)
        _time_cd(realistic[:100], gauge, True)
    passes = [_time_ours(profiles, gauge) for _ in range(3)]   # 3 passes: the VM is noisy
    cd_model = [_time_cd(profiles, gauge, True) for _ in range(3)]
    cd_real = [_time_cd(realistic, gauge, True) for _ in range(3)]
    cd_real_rdp = _time_cd(realistic, gauge, False)
    cd = np.concatenate([p[0] for p in passes])
    pc = np.concatenate([p[1] for p in passes])
    failures = sum(p[2] for p in passes)
    total = cd + pc
    api = _time_api(profiles, gauge)
    server_pc = _time_server(gauge)
    sp = _time_scipy(profiles, gauge)
    from posekit.profiler.loop.camera_peer import time_camera_pipeline  # OpenCV only after our timing
    cam = time_camera_pipeline(n_images=10, repeats=3, seed=0)
    cam_cd, cam_pc = np.asarray(cam["cd_ms"]), np.asarray(cam["pc_ms"])
    cam_total = cam_cd + cam_pc

    rows = []

    def row(name, ours, baseline, base):
        m, p99 = _stats(ours)
        b = float(np.median(base))
        rows.append({"name": name, "ours_ms": m, "ours_p99_ms": p99, "baseline": baseline, "baseline_ms": b,
                     "speedup": b / m, "realtime_factor": SENSOR_PERIOD_MS / m, "samples": int(len(ours))})

    cam_name = "OpenCV chessboard 2590x1942, 3x4 inner corners"
    row("profiler.cd", cd, f"{cam_name}: findChessboardCorners + cornerSubPix", cam_cd)
    row("profiler.cd.model", np.concatenate([p[0] for p in cd_model]),
        f"{cam_name}: findChessboardCorners + cornerSubPix", cam_cd)
    row("profiler.cd.model.realistic", np.concatenate([p[0] for p in cd_real]),
        f"{cam_name}: findChessboardCorners + cornerSubPix", cam_cd)
    rows[-1]["failures"] = int(cd_real[0][1])
    rows[-1]["rdp_failures"] = int(cd_real_rdp[1])
    row("profiler.pc", pc, f"{cam_name}: solvePnP SQPNP", cam_pc)
    row("profiler.cd+pc", total, f"{cam_name}: CD + PC", cam_total)
    row("profiler.pc.vs_scipy", pc, "scipy.optimize.least_squares(lm) on the same ML problem", sp)
    row("profiler.estimate_pose_api", api, f"{cam_name}: CD + PC", cam_total)
    row("profiler.server_frame.pc", server_pc, f"{cam_name}: solvePnP SQPNP", cam_pc)

    if verbose:
        print(f"posekit bench profiler: 3 passes over {count} profiles of gauge '{gauge.name}' (3200 points, 5 µm noise), "
              f"one thread; {failures} failures; camera: {len(cam_cd)} runs on "
              f"{cam.get('n_images', 10)} rendered images")
        print(f"{'stage':<30}{'ours median':>12}{'p99':>10}   {'peer median':>12}  ratio   peer")
        for r in rows:
            print(f"{r['name']:<30}{r['ours_ms'] * 1e3:>10.1f}µs{r['ours_p99_ms'] * 1e3:>8.1f}µs   "
                  f"{r['baseline_ms']:>10.3f}ms  {r['speedup']:>6.0f}x  {r['baseline']}")
        real = next(r for r in rows if r["name"] == "profiler.cd.model.realistic")
        print(f"model-based CD on {count} realistic profiles: {real['failures']} failures (RDP detector: "
              f"{real['rdp_failures']}); target: median <= 30 µs -> measured {real['ours_ms'] * 1e3:.1f} µs")
        total_row = next(r for r in rows if r["name"] == "profiler.cd+pc")
        print(f"target: CD + PC median <= 50 µs per profile -> measured {total_row['ours_ms'] * 1e3:.1f} µs "
              f"(paper: 0.11 + 0.26 ms on an i9-12900KF); real-time factor at 1 kHz: "
              f"{total_row['realtime_factor']:.0f}x")
        if "t_err_mm" in cam:
            print(f"camera pose accuracy on the renders: median {np.median(cam['t_err_mm']):.3f} mm, "
                  f"{np.median(cam['rot_err_deg']):.4f} deg")
    return rows


if __name__ == "__main__":  # pragma: no cover
    sys.path.insert(0, str(HERE.parent / "src"))
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    run()

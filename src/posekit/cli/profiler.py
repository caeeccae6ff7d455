"""``posekit profiler estimate|simulate|calibrate-gauge``."""

import sys
from pathlib import Path

from ..errors import ConfigError
from ._common import add_overwrite, check_workspace, parse_triplet, progress
from ._config import add_config_arguments
from ._flags import MAX_NOISE_UM, MAX_PROFILES, bounded_float, bounded_int, check_flags, seed

__all__ = ["add_parser"]


def add_parser(sub):
    p = sub.add_parser("profiler", help="6-DoF pose from a 2D laser profile of a multi-plane gauge")
    verbs = p.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True

    e = verbs.add_parser("estimate", help="pose of each profile in a CSV, .npy or .npz file")
    e.add_argument("input", help="profile file: CSV 'x,z' (mm), .npy (N, 2) or .npz 'profiles' (K, N, 2)")
    e.add_argument("--gauge", required=True, help="gauge YAML file (or a bundled name: demo-4/5/7/10)")
    e.add_argument("--method", choices=["cf", "mle"], default="mle",
                   help="cf: closed form eq. (9)-(14); mle: refined (default)")
    e.add_argument("--mounting", choices=["auto", "normal", "reversed"], default="auto",
                   help="scan order of the corners vs the ridges (default: auto-detect; a gauge whose "
                        "profiles cannot tell the two apart needs normal or reversed)")
    e.add_argument("--rotation", choices=["quat", "matrix", "euler-zyx", "euler-xyz"], default="quat",
                   help="extra rotation output besides q_wxyz (whose sign is continuous along a batch): "
                        "matrix R_G_F; euler-zyx [A,B,C] deg, intrinsic Z-Y'-X'' R = Rz(A) Ry(B) Rx(C) "
                        "(KUKA A,B,C); euler-xyz [W,P,R] deg, fixed axes X-Y-Z R = Rz(R) Ry(P) Rx(W) "
                        "(Fanuc/ABB W,P,R). Default quat: q_wxyz only")
    e.add_argument("--noise-um", type=bounded_float(0.0, MAX_NOISE_UM, "µm"), default=5.0,
                   help="noise the estimator assumes in z, µm (default 5, the LJ-X8400's repeatability)")
    e.add_argument("--noise-x-um", type=bounded_float(0.0, MAX_NOISE_UM, "µm"), default=None,
                   help="noise assumed in x, µm (default: twice --noise-um, the LJ-X8400's 10/5 µm)")
    e.add_argument("--significance", type=bounded_float(0.0, 1.0, lo_open=True, hi_open=True), default=None,
                   help="significance of the consistency test: the rate at which good data are called "
                        "suspect (default 0.001)")
    e.add_argument("--scale-sigma-ppm", type=bounded_float(0.0, 1e4, "ppm"), default=None,
                   help="1 sigma of the sensor's unknown x and z scale errors the estimator allows for, ppm "
                        "(default 100, an uncalibrated sensor; a sensor calibrated against a reference gives "
                        "what is left): in every pose's std and test, and in the batch test of the gauge file")
    e.add_argument("--out", help="FILE.jsonl or FILE.csv (default: JSON lines on stdout)")
    from .profiler_replay import add_read_arguments
    add_read_arguments(e)               # --columns, --delimiter, --roi-x, --roi-z (shared with replay)
    add_config_arguments(e)
    e.set_defaults(func=run_estimate)

    s = verbs.add_parser("simulate", help="simulate profiles of a gauge at random poses")
    s.add_argument("--gauge", required=True, help="gauge YAML file (or a bundled name)")
    s.add_argument("--count", type=bounded_int(1, MAX_PROFILES, "profiles"), default=100,
                   help=f"number of profiles, 1..{MAX_PROFILES} (default 100)")
    s.add_argument("--noise-um", type=bounded_float(0.0, MAX_NOISE_UM, "µm"), default=5.0,
                   help="Gaussian noise in z, 0..10000 µm (default 5)")
    s.add_argument("--noise-x-um", type=bounded_float(0.0, MAX_NOISE_UM, "µm"), default=None,
                   help="Gaussian noise in x, µm (default: twice --noise-um, as the LJ-X8400's 10/5 µm)")
    # >= 0 is checked with the other noise values (run_simulate)
    s.add_argument("--outliers", type=bounded_float(None, 0.5), default=0.0,
                   help="fraction of returns that are spikes, 0..0.5")
    s.add_argument("--dropouts", type=bounded_float(0.0, 100.0, "runs per profile"), default=0.0,
                   help="mean number of dropout runs per profile, 0..100")
    s.add_argument("--translation-mm", default="10,10,40", help="workspace half-ranges x,y,z in G, 0..1000 mm")
    s.add_argument("--rotation-deg", default="4,4,8",
                   help="workspace half-ranges of rotation about F's x,y,z, 0..180 deg")
    s.add_argument("--standoff-mm", type=bounded_float(1.0, 1e4, "mm"), default=None,
                   help="nominal depth of the gauge, 1..10000 mm (default: mid-range)")
    s.add_argument("--realistic", action="store_true",
                   help="simulate a real cell: one as-built gauge with rounded and chamfered ridges and "
                        "machining error, its mounting plate and a fixture in view, multipath near valleys, "
                        "scale error and dropouts on steep faces (RealismModel.realistic())")
    s.add_argument("--seed", type=seed, default=0, help="random seed (same seed, same profiles)")
    s.add_argument("--out", required=True, help="output folder: profiles.npz and truth.csv")
    add_overwrite(s)
    add_config_arguments(s)
    s.set_defaults(func=run_simulate)

    cg = verbs.add_parser("calibrate-gauge", help="the as-built gauge (every face plane) from profiles taken at "
                          "unknown, varied poses")
    cg.add_argument("input", help="profiles: .npz with 'profiles' (K, N, 2), K >= 50, the laser line turned and "
                    "tilted by several degrees between them")
    cg.add_argument("--gauge", required=True, help="the nominal gauge YAML file (the drawing; or a bundled name)")
    cg.add_argument("--mounting", choices=["auto", "normal", "reversed"], default="auto",
                    help="scan order of the corners vs the ridges (default: auto-detect)")
    cg.add_argument("--out", required=True, help="ASBUILT.yaml: the as-built gauge, with tolerance_um")
    cg.set_defaults(func=run_calibrate_gauge)

    from .profiler_loop import add_loop_parser
    from .profiler_replay import add_replay_parser
    from .profiler_serve import add_serve_parser
    from .profiler_study import add_study_parser
    add_study_parser(verbs)
    add_serve_parser(verbs)
    add_replay_parser(verbs)
    add_loop_parser(verbs)

    a = verbs.add_parser("accuracy", help="accuracy of the estimator on simulated profiles of a gauge")
    from .demo import add_accuracy_arguments, run_accuracy
    add_accuracy_arguments(a)
    a.set_defaults(func=run_accuracy)


def run_estimate(args) -> int:
    from ..profiler.gauge.check import MIN_CHECK_PROFILES
    from ..profiler.stream.files import assumed_noise, estimate_file
    from .profiler_replay import read_options

    special = args.out is not None and Path(args.out).exists() and not Path(args.out).is_file() \
        and not Path(args.out).is_dir()          # /dev/null, /dev/stdout, a named pipe: JSON lines by default
    if args.out is not None and Path(args.out).suffix.lower() not in (".jsonl", ".csv") and not special:
        raise ConfigError(f"--out {args.out}: unknown suffix '{Path(args.out).suffix[:20]}'; expected FILE.jsonl "
                          "(JSON lines) or FILE.csv")
    check_flags(args)
    noise = assumed_noise(args.noise_um, args.noise_x_um, args.scale_sigma_ppm)
    if noise.sigma_x_um + noise.sigma_z_um <= 0:
        raise ConfigError("--noise-um, --noise-x-um: the assumed noise must not be zero in both x and z")
    res = estimate_file(args.input, args.gauge, method=args.method, mounting=args.mounting, rotation=args.rotation,
                        noise_um=args.noise_um, noise_x_um=args.noise_x_um, significance=args.significance,
                        scale_sigma_ppm=args.scale_sigma_ppm, read=read_options(args), out=args.out,
                        stream=sys.stdout if args.out is None else None,
                        progress=lambda it: progress(it, total=len(it), desc="estimate"))
    total = len(res.records)
    counts = res.status_counts()
    reversed_count = sum(bool(est is not None and est.reversed and rec["status"] == "ok")
                         for rec, est in zip(res.records, res.estimates))
    check = res.gauge_check
    if check.passed is False:
        print(f"posekit: {check.message}; every pose of the batch is marked suspect", file=sys.stderr)
    elif check.passed or total >= MIN_CHECK_PROFILES:   # a batch too small to check it is no news
        print(f"posekit: note: {check.message}", file=sys.stderr)
    if reversed_count:
        print(f"posekit: note: {reversed_count} of {total} profiles had their corners in reverse "
              "order (sensor mounted the other way round?)", file=sys.stderr)
    if counts["error"]:
        print(f"posekit: {counts['error']} of {total} profiles failed; their records have status 'error'",
              file=sys.stderr)
    if counts["suspect"]:
        print(f"posekit: {counts['suspect']} of {total} profiles are suspect (the data disagree with the "
              "gauge or the assumed noise); their records have status 'suspect' and the reason", file=sys.stderr)
    return res.exit_code


def run_simulate(args) -> int:
    import numpy as np

    from ..profiler.sim.poses import Workspace
    from ..profiler.sim.simulate import simulate

    if args.count < 1:
        raise ConfigError(f"--count must be >= 1, got {args.count}")
    for flag, value in (("--noise-um", args.noise_um), ("--noise-x-um", args.noise_x_um),
                        ("--outliers", args.outliers), ("--dropouts", args.dropouts)):
        if value is not None and not (np.isfinite(value) and value >= 0):
            raise ConfigError(f"{flag} must be a finite number >= 0, got {value:g}")
    check_flags(args)
    ws = Workspace(translation_mm=parse_triplet(args.translation_mm, "translation-mm"),
                   rotation_deg=parse_triplet(args.rotation_deg, "rotation-deg"), standoff_mm=args.standoff_mm)
    check_workspace(ws, args)
    sim = simulate(args.gauge, args.count, noise_um=args.noise_um, noise_x_um=args.noise_x_um,
                   outliers=args.outliers, dropouts=args.dropouts, translation_mm=ws.translation_mm,
                   rotation_deg=ws.rotation_deg,
                   standoff_mm=args.standoff_mm, realistic=args.realistic, seed=args.seed, out=args.out,
                   overwrite=args.overwrite)
    out = Path(args.out)
    print(f"wrote {args.count} {'realistic ' if args.realistic else ''}profiles of gauge '{sim.gauge.name}' "
          f"({sim.profiles.shape[1]} points each, {100 * sim.returns:.1f} % returns) to {out / 'profiles.npz'} and "
          f"the poses to {out / 'truth.csv'}")
    return 0


def run_calibrate_gauge(args) -> int:
    from ..profiler.stream.files import calibrate_gauge_file

    out = Path(args.out)
    if out.suffix.lower() not in (".yaml", ".yml"):
        raise ConfigError(f"--out {args.out}: expected a gauge file ASBUILT.yaml")
    if Path(args.gauge).exists() and out.exists() and out.resolve() == Path(args.gauge).resolve():
        raise ConfigError(f"--out {args.out}: is the nominal gauge file; write the as-built gauge to another file")
    cal = calibrate_gauge_file(args.input, args.gauge, mounting=args.mounting, out=out)
    for index, reason in cal.skipped[:5]:
        print(f"posekit: note: profile {index} left out: {reason}", file=sys.stderr)
    if len(cal.skipped) > 5:
        print(f"posekit: note: {len(cal.skipped) - 5} more profiles left out", file=sys.stderr)
    print(f"as-built gauge '{cal.gauge.name}' from {len(cal.used)} of {len(cal.used) + len(cal.skipped)} profiles "
          f"in {cal.seconds:.2f} s: faces {cal.face_shift_um.min():.1f}-{cal.face_shift_um.max():.1f} µm and "
          f"{cal.face_tilt_deg.min():.4f}-{cal.face_tilt_deg.max():.4f}° off the drawing; 1σ face position "
          f"{cal.face_sigma_um.min():.2f}-{cal.face_sigma_um.max():.2f} µm (tolerance_um); corner residual RMS "
          f"{cal.rms_um:.2f} µm, χ²/dof {cal.chi2 / max(cal.dof, 1):.2f}")
    print(f"wrote {out}")
    return 0

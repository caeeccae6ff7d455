"""``posekit profiler estimate|simulate``."""

import sys
from pathlib import Path

from ..errors import ConfigError
from ._common import add_overwrite, out_folder, parse_triplet, progress, resolve_gauge, staged

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
                   help="scan order of the corners vs the ridges (default: auto-detect)")
    e.add_argument("--out", help="FILE.jsonl or FILE.csv (default: JSON lines on stdout)")
    e.set_defaults(func=run_estimate)

    s = verbs.add_parser("simulate", help="simulate profiles of a gauge at random poses")
    s.add_argument("--gauge", required=True, help="gauge YAML file (or a bundled name)")
    s.add_argument("--count", type=int, default=100, help="number of profiles (default 100)")
    s.add_argument("--noise-um", type=float, default=5.0, help="Gaussian noise in z, µm (default 5)")
    s.add_argument("--noise-x-um", type=float, default=None,
                   help="Gaussian noise in x, µm (default: twice --noise-um, as the LJ-X8400's 10/5 µm)")
    s.add_argument("--outliers", type=float, default=0.0, help="fraction of returns that are spikes")
    s.add_argument("--dropouts", type=float, default=0.0, help="mean number of dropout runs per profile")
    s.add_argument("--translation-mm", default="10,10,40", help="workspace half-ranges x,y,z in G, mm")
    s.add_argument("--rotation-deg", default="4,4,8", help="workspace half-ranges of rotation about F's x,y,z, deg")
    s.add_argument("--standoff-mm", type=float, default=None, help="nominal depth of the gauge, mm (mid-range)")
    s.add_argument("--seed", type=int, default=0, help="random seed (same seed, same profiles)")
    s.add_argument("--out", required=True, help="output folder: profiles.npz and truth.csv")
    add_overwrite(s)
    s.set_defaults(func=run_simulate)

    from .profiler_loop import add_loop_parser
    from .profiler_serve import add_serve_parser
    from .profiler_study import add_study_parser
    add_study_parser(verbs)
    add_serve_parser(verbs)
    add_loop_parser(verbs)

    a = verbs.add_parser("accuracy", help="accuracy of the estimator on simulated profiles of a gauge")
    from .demo import add_accuracy_arguments, run_accuracy
    add_accuracy_arguments(a)
    a.set_defaults(func=run_accuracy)


def run_estimate(args) -> int:
    from ..profiler.estimate import estimate_batch
    from ..profiler.io import RecordWriter, read_profiles

    if args.out is not None and Path(args.out).suffix.lower() not in (".jsonl", ".csv"):
        raise ConfigError(f"--out {args.out}: unknown suffix '{Path(args.out).suffix[:20]}'; expected FILE.jsonl "
                          "(JSON lines) or FILE.csv")
    gauge = resolve_gauge(args.gauge)
    profiles = read_profiles(args.input)
    failed = 0
    reversed_count = 0
    with RecordWriter(args.out, stream=sys.stdout) as writer:
        for rec, est in progress(estimate_batch(profiles, gauge, args.method, args.mounting),
                                 total=len(profiles), desc="estimate"):
            writer.write(rec)
            failed += rec["status"] != "ok"
            reversed_count += bool(est is not None and est.reversed)
    if reversed_count:
        print(f"posekit: note: {reversed_count} of {len(profiles)} profiles had their corners in reverse "
              "order (sensor mounted the other way round?)", file=sys.stderr)
    if failed:
        print(f"posekit: {failed} of {len(profiles)} profiles failed; their records have status 'error'",
              file=sys.stderr)
        return 1
    return 0


def run_simulate(args) -> int:
    import numpy as np

    from ..errors import ConfigError
    from ..geometry import quaternion_from_matrix
    from ..profiler.io import write_truth_csv
    from ..profiler.sensor import NoiseModel, Workspace, render_profiles, sample_poses

    if args.count < 1:
        raise ConfigError(f"--count must be >= 1, got {args.count}")
    for flag, value in (("--noise-um", args.noise_um), ("--noise-x-um", args.noise_x_um),
                        ("--outliers", args.outliers), ("--dropouts", args.dropouts)):
        if value is not None and not (np.isfinite(value) and value >= 0):
            raise ConfigError(f"{flag} must be a finite number >= 0, got {value:g}")
    gauge = resolve_gauge(args.gauge)
    noise = NoiseModel(
        sigma_x_um=2.0 * args.noise_um if args.noise_x_um is None else args.noise_x_um,
        sigma_z_um=args.noise_um, outlier_rate=args.outliers, dropouts_per_profile=args.dropouts)
    ws = Workspace(translation_mm=parse_triplet(args.translation_mm, "translation-mm"),
                   rotation_deg=parse_triplet(args.rotation_deg, "rotation-deg"), standoff_mm=args.standoff_mm)
    out_folder(args)
    rng = np.random.default_rng(args.seed)
    Ts = sample_poses(gauge, args.count, rng, ws)
    profiles = render_profiles(gauge, Ts, noise, rng)
    out = Path(args.out)
    with staged(args) as tmp:
        np.savez_compressed(tmp / "profiles.npz", profiles=profiles.astype(np.float64), T_G_F=Ts)
        write_truth_csv(tmp / "truth.csv", Ts, quaternion_from_matrix(Ts[:, :3, :3]))
    valid = np.isfinite(profiles[..., 0]).mean()
    print(f"wrote {args.count} profiles of gauge '{gauge.name}' ({profiles.shape[1]} points each, "
          f"{100 * valid:.1f} % returns) to {out / 'profiles.npz'} and the poses to {out / 'truth.csv'}")
    return 0

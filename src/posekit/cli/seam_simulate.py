"""``posekit seam simulate`` and ``posekit seam demo``: simulated seam tracking with figures.

Precedence of settings: defaults < ``--config`` file < flags.
"""

import functools
import sys
import time

from ..errors import ConfigError
from ._common import add_overwrite, out_folder, staged
from ._common import progress as _progress
from ._flags import bounded_int, check_flags, seed

__all__ = ["DEMO_PARTICLES", "DEMO_STEPS", "add_demo_parser", "add_simulate_parser", "build_config", "rmse_table"]

#: The trajectory kinds (``posekit.seam.frontend.config.TRAJECTORY_KINDS``, not imported here: the parser stays light).
TRAJECTORIES = ("xy", "yz", "line", "bend")
#: The demo's episode: shorter and with fewer particles than the paper's 500 steps × 500.
DEMO_STEPS = 300
DEMO_PARTICLES = 300
#: ``posekit.seam.frontend.config.MAX_STEPS`` / ``MAX_PARTICLES`` (not imported: the parser stays light; a test
#: keeps them equal). The configuration also bounds steps × particles and steps × seam points.
MAX_STEPS, MAX_PARTICLES = 100_000, 1_000_000
#: Most Monte-Carlo episodes of one command.
MAX_RUNS = 10_000
#: Most episode-steps kept in memory for the metrics and figures (runs × steps, × 6 with
#: --compare or in the demo): about 1 KB each, so 1 GiB at the limit.
MAX_KEPT_STEPS = 1_000_000
#: Most recorded particle poses for Fig. 5 (steps × --record-particles, 48 bytes each: 96 MB).
MAX_RECORDED = 2_000_000
#: Particles recorded per step by default (fewer on a long episode, within MAX_RECORDED).
RECORD_DEFAULT = 200
_STEPS = bounded_int(2, MAX_STEPS)
_PARTICLES = bounded_int(1, MAX_PARTICLES)
_RUNS = bounded_int(1, MAX_RUNS)


#: Progress over episodes: a tqdm bar on a terminal, silent otherwise.
progress = functools.partial(_progress, unit="episode")

AXES = ("x", "y", "z", "rx", "ry", "rz")


def _rmse_values(m, prefix: str = "") -> list[float]:
    """RMSE per axis ``[x, y, z mm, rx, ry, rz deg]`` from a metrics dict (``prefix='kinematic_'``: FK only)."""
    return [m[f"{prefix}rmse_mm"][a] for a in AXES[:3]] + [m[f"{prefix}rmse_deg"][a] for a in AXES[3:]]


def rmse_table(rows, decimals: int = 3) -> str:
    """Plain-text RMSE table: a header, then one line per ``(label, values (6,))`` row.

    Values are ``[x, y, z (mm), rx, ry, rz (deg)]`` printed with ``decimals`` fixed decimals
    (µm and millidegree resolution by default), right-aligned in columns of 10 characters (wider
    when a value needs it, so columns never run together); labels in a column of at least 24.
    """
    width = max([24, *(len(label) + 1 for label, _ in rows)])
    cells = [[f"{v:.{decimals}f}" for v in values] for _, values in rows]
    col = max([10, *(len(c) + 1 for row in cells for c in row)])
    head = f"{'configuration':<{width}}" + "".join(f"{a + (' mm' if i < 3 else ' deg'):>{col}}"
                                                   for i, a in enumerate(AXES))
    return "\n".join([head, *(f"{label:<{width}}" + "".join(f"{c:>{col}}" for c in row)
                              for (label, _), row in zip(rows, cells))])


def _episode_flags(p):
    p.add_argument("--config", default=None, help="YAML configuration (every parameter; see examples/seam/)")
    p.add_argument("--profile", default=None, metavar="PROFILE.yaml",
                   help="the filter's fitted profile (posekit seam tune; overrides the configuration's)")
    p.add_argument("--trajectory", choices=TRAJECTORIES, default=None,
                   help="seam/trajectory kind (overrides trajectory.kind)")
    p.add_argument("--sensors", type=int, choices=(0, 1, 2, 3, 4), default=None,
                   help="laser sensors ahead of the tool, 0..4 (overrides sensors.count)")
    p.add_argument("--particles", type=_PARTICLES, default=None,
                   help=f"particle count, 1..{MAX_PARTICLES} (overrides filter.particles)")
    p.add_argument("--steps", type=_STEPS, default=None,
                   help=f"time steps per episode, 2..{MAX_STEPS} (overrides trajectory.steps)")
    p.add_argument("--seed", type=seed, default=None, help="seed (overrides seed; same seed, same numbers)")


def add_simulate_parser(verbs):
    """Add ``simulate`` to the ``posekit seam`` sub-parsers."""
    p = verbs.add_parser("simulate", help="simulate seam tracking episodes: metrics.json, estimates.csv, "
                                          "figures, report.html")
    _episode_flags(p)
    p.add_argument("--runs", type=_RUNS, default=1,
                   help=f"Monte-Carlo episodes, 1..{MAX_RUNS}; runs × steps at most {MAX_KEPT_STEPS:,} (default 1)")
    p.add_argument("--compare", action="store_true",
                   help="also run trajectories xy, yz with 0, 1, 2 sensors for Fig. 8 (same filter)")
    p.add_argument("--record-particles", type=bounded_int(0, 10_000), default=None,
                   help=f"particles recorded per step in run 0 for Fig. 5, 0..10000 and steps × this at most "
                        f"{MAX_RECORDED:,} (default {RECORD_DEFAULT}, fewer on a long episode; 0: no Fig. 5)")
    p.add_argument("--save-log", default=None, metavar="DIR",
                   help="also write run 0 as a recorded episode (setup.yaml, seam.csv, log.csv, truth.csv) "
                        "for `posekit seam track`")
    p.add_argument("--dump-config", action="store_true", help="print the effective configuration and exit")
    p.add_argument("--out", default=None, help="output folder (required unless --dump-config)")
    add_overwrite(p)
    p.set_defaults(func=run_simulate)
    return p


def add_demo_parser(verbs):
    """Add ``demo`` to the ``posekit seam`` sub-parsers."""
    p = verbs.add_parser("demo", help=f"quick look: 0, 1, 2 sensors on the xy and yz seams "
                                      f"({DEMO_STEPS} steps, {DEMO_PARTICLES} particles), RMSE per axis")
    p.add_argument("--seed", type=seed, default=0, help="seed (default 0)")
    p.add_argument("--runs", type=_RUNS, default=1, help=f"episodes per configuration, 1..{MAX_RUNS} (default 1)")
    p.add_argument("--steps", type=_STEPS, default=DEMO_STEPS,
                   help=f"time steps per episode, 2..{MAX_STEPS} (default {DEMO_STEPS})")
    p.add_argument("--particles", type=_PARTICLES, default=DEMO_PARTICLES,
                   help=f"particle count, 1..{MAX_PARTICLES} (default {DEMO_PARTICLES})")
    p.add_argument("--out", default=None, help="also write figures, metrics.json and report.html here")
    add_overwrite(p)
    p.set_defaults(func=run_demo)
    return p


def build_config(args):
    """The effective :class:`~posekit.seam.frontend.config.SeamConfig`: defaults < ``--config`` < flags."""
    from ..seam.frontend.compare import with_sensors
    from ..seam.frontend.config import apply_overrides, config_from_dict, load_config

    with layout_notes():
        cfg = load_config(args.config) if args.config else config_from_dict({}, "defaults")
    cfg = with_profile(cfg, getattr(args, "profile", None))
    for flag, value, low in (("--particles", args.particles, 1), ("--steps", args.steps, 2),
                             ("--seed", args.seed, 0)):
        if value is not None and value < low:
            raise ConfigError(f"{flag}: expected an integer >= {low}, got {value}")
    check_flags(args, ("particles", "steps", "seed"))
    cfg = apply_overrides(cfg, {"trajectory.kind": args.trajectory, "filter.particles": args.particles,
                                "trajectory.steps": args.steps, "seed": args.seed})
    if args.sensors is not None:
        cfg = with_sensors(cfg, args.sensors)
    return cfg


def with_profile(cfg, path):
    """``cfg`` with the profile file ``path`` (``--profile``) in place of its own; unchanged for None."""
    if path is None:
        return cfg
    from ..seam.frontend.config import config_from_dict
    from ..seam.frontend.profile import load_profile

    data = _config_data(cfg)
    data["profile"] = load_profile(path).model_dump(mode="python", exclude_none=True)
    return config_from_dict(data, "--profile")


class layout_notes:
    """A context: the configuration layout notes (:class:`~posekit.seam.frontend.config.LayoutNote`) raised inside
    are printed as one ``note: ...`` line each on stderr."""

    def __enter__(self):
        import warnings

        self._ctx = warnings.catch_warnings(record=True)
        self._rec = self._ctx.__enter__()
        warnings.simplefilter("always")
        return self

    def __exit__(self, *exc):
        from ..seam.frontend.config import LayoutNote

        self._ctx.__exit__(*exc)
        for w in self._rec:
            if issubclass(w.category, LayoutNote):
                print(f"note: {w.message}", file=sys.stderr)
        return False


def _config_data(cfg) -> dict:
    """A configuration as the mapping that validates back into it (the profile whole, with its values)."""
    data = cfg.model_dump(mode="python")
    data["profile"] = cfg.profile.model_dump(mode="python", exclude_none=True)
    return data


def _check_runs(runs):
    if runs < 1:
        raise ConfigError(f"--runs: expected an integer >= 1, got {runs}")


def _check_kept(runs: int, steps: int, configurations: int = 1) -> None:
    """At most :data:`MAX_KEPT_STEPS` episode-steps held for the metrics and figures."""
    kept = runs * steps * configurations
    if kept > MAX_KEPT_STEPS:
        times = f" × {configurations} configurations" if configurations > 1 else ""
        raise ConfigError(f"--runs {runs} × {steps} steps{times} = {kept:,} episode-steps kept for the metrics and "
                          f"figures; expected at most {MAX_KEPT_STEPS:,} (1 GiB): fewer --runs or --steps")


def _record_count(args, steps: int) -> int:
    """``--record-particles``, or its default within :data:`MAX_RECORDED`; a one-line error for a
    given value over it."""
    if args.record_particles is None:
        return min(RECORD_DEFAULT, MAX_RECORDED // steps)
    if steps * args.record_particles > MAX_RECORDED:
        raise ConfigError(f"--record-particles {args.record_particles} × {steps} steps = "
                          f"{steps * args.record_particles:,} recorded particle poses; expected at most "
                          f"{MAX_RECORDED:,} (96 MB): at most {MAX_RECORDED // steps} per step, or 0 (no Fig. 5)")
    return args.record_particles


def _save_log_rules(args) -> dict:
    """``--overwrite`` names the ``--out`` folder: it replaces a ``--save-log`` folder only while
    posekit wrote everything in it (never files of the user's)."""
    return {"replace_own": bool(args.overwrite),
            "hint": "--overwrite replaces it only if posekit wrote all of it; remove them or pick another folder"}


def run_simulate(args) -> int:
    from ..seam.frontend.config import dump_config

    cfg = build_config(args)
    if args.dump_config:
        sys.stdout.write(dump_config(cfg))
        return 0
    if not args.out:
        raise ConfigError("--out: an output folder is required (or use --dump-config)")
    _check_runs(args.runs)
    if args.record_particles is not None and args.record_particles < 0:
        raise ConfigError(f"--record-particles: expected an integer >= 0, got {args.record_particles}")
    check_flags(args)
    _check_kept(args.runs, cfg.trajectory.steps, 6 if args.compare else 1)
    record = _record_count(args, cfg.trajectory.steps)
    out_folder(args)
    if args.save_log:
        from ..io import check_out_folder

        if str(args.save_log) == str(args.out):
            raise ConfigError("--save-log: expected a folder other than --out")
        check_out_folder(args.save_log, flag="--save-log", **_save_log_rules(args))
    from ..seam.frontend.compare import compare_configurations, run_episodes
    from ..seam.frontend.report import write_simulation
    from ..seam.frontend.simulate import metrics

    results = run_episodes(cfg, args.runs, record_particles=record, progress=progress,
                           desc="episodes")
    m = metrics(results)
    comparison = (compare_configurations(cfg, args.runs, progress=progress, reuse=(cfg, results))
                  if args.compare else None)
    with staged(args) as tmp:
        paths = write_simulation(tmp, results, m, dump_config(cfg), comparison=comparison)
    if args.save_log:
        from ..io import staged_folder
        from ..seam.frontend.logs import write_episode_log
        from ..seam.frontend.simulate import simulate_data

        seed0 = results[0].seed
        with staged_folder(args.save_log, flag="--save-log", **_save_log_rules(args)) as tmp:
            write_episode_log(tmp, cfg, simulate_data(cfg, seed0), seed0)
    count = cfg.cell.sensors.count
    label = f"{cfg.trajectory.kind}, {count} sensor{'s' if count != 1 else ''}"
    rows = [(label, _rmse_values(m))]
    if comparison:
        rows += [(s.label, _rmse_values(s.metrics)) for s in comparison if s.label != label]
    else:
        rows.append((f"{label} (FK only)", _rmse_values(m, "kinematic_")))
    print(f"seam simulate: {args.runs} run(s) × {cfg.trajectory.steps} steps, {cfg.filter.particles} particles, "
          f"filter step median {m['step_ms_median']:.3f} ms")
    print("RMSE per axis in the seam frame (mm, deg):")
    print(rmse_table(rows))
    if "status_counts" in m:
        print("status: " + ", ".join(f"{k} {v}" for k, v in m["status_counts"].items()))
    if m.get("outside_plateau_runs", 0.0) > 0.0:
        plateau_warning("the simulated robot", f"in {100 * m['outside_plateau_runs']:.0f} % of the runs",
                        m["plateau_ratio_max"])
    print(f"wrote {args.out}: {', '.join(p.name for p in paths.values())}")
    if args.save_log:
        print(f"wrote {args.save_log}: setup.yaml, seam.csv, log.csv, truth.csv (run 0, seed {results[0].seed})")
    return 0


def plateau_warning(who: str, where: str, peak) -> None:
    """One stderr line: ``who`` left the filter's robot plateau ``where``, up to ``peak`` (None: inf) radii."""
    size = "inf" if peak is None else f"{peak:.2f}"
    print(f"warning: {who} left the filter's robot plateau {where} (up to {size} times its radius): the filter's "
          "model does not describe this robot and its spread cannot be trusted; fit the profile's plateau on "
          "episodes of this robot (posekit seam tune --with-truth; paper eq. 7)", file=sys.stderr)


def _status_text(counts: dict, long: bool = False) -> str:
    keys = ("tracking", "degraded", "lost")
    if long:
        return ", ".join(f"{k} {counts.get(k, 0)}" for k in keys)
    return "/".join(str(counts.get(k, 0)) for k in keys)


def demo_verdict(sets) -> str:
    """The demo's verdict line: on each seam, on how many of the six axes two sensors beat the robot's
    kinematics (the paper's Fig. 8: two sensors give the smallest error; expected on every axis)."""
    parts = []
    for kind in dict.fromkeys(s.trajectory for s in sets):
        two = next((s for s in sets if s.trajectory == kind and s.sensors == 2), None)
        if two is None:
            continue
        ours, fk = _rmse_values(two.metrics), _rmse_values(two.metrics, "kinematic_")
        parts.append(f"{kind} {sum(a < b for a, b in zip(ours, fk))}/6")
    return ("verdict: two sensors beat the kinematics on " + ", ".join(parts) + " axes (the paper's Fig. 8: two "
            "sensors give the smallest error; expected 6/6; fewer sensors leave some axes unobserved)")


def run_demo(args) -> int:
    from ..seam.frontend.compare import compare_configurations
    from ..seam.frontend.config import apply_overrides, config_from_dict, dump_config
    from ..seam.frontend.report import write_simulation

    _check_runs(args.runs)
    for flag, value, low in (("--particles", args.particles, 1), ("--steps", args.steps, 2),
                             ("--seed", args.seed, 0)):
        if value < low:
            raise ConfigError(f"{flag}: expected an integer >= {low}, got {value}")
    check_flags(args)
    _check_kept(args.runs, args.steps, 6)
    if args.out:
        out_folder(args)
    cfg = apply_overrides(config_from_dict({}, "defaults"),
                          {"trajectory.steps": args.steps, "filter.particles": args.particles, "seed": args.seed})
    t0 = time.perf_counter()
    record = min(RECORD_DEFAULT, MAX_RECORDED // args.steps) if args.out else 0
    sets = compare_configurations(cfg, args.runs, record_particles=record, progress=progress)
    print(f"seam demo: {args.runs} run(s) × {args.steps} steps, {args.particles} particles, sensors 20/40 mm ahead "
          f"({time.perf_counter() - t0:.1f} s)")
    print("RMSE per axis of the tool pose in the seam frame against the simulated truth (mm, deg; lower is "
          "better); FK only = the robot's kinematics without the filter; status = steps tracking/degraded/lost")
    rows = [(s.label, _rmse_values(s.metrics)) for s in sets]
    # the kinematics-only pose does not depend on the sensors: one row, from the first set
    rows.append((f"{sets[0].trajectory}, FK only", _rmse_values(sets[0].metrics, "kinematic_")))
    table = rmse_table(rows).split("\n")
    counts = [_status_text(s.metrics.get("status_counts", {})) for s in sets] + [""]
    print("\n".join([table[0] + "   status", *(line + f"   {c}" for line, c in zip(table[1:], counts))]))
    print(demo_verdict(sets))
    total = {k: sum(s.metrics.get("status_counts", {}).get(k, 0) for s in sets) for k in ("tracking", "degraded", "lost")}
    print(f"status over all configurations: {_status_text(total, long=True)}")
    main = next(s for s in sets if s.trajectory == "xy" and s.sensors == 2)
    print(f"filter step median: {main.metrics['step_ms_median']:.3f} ms ({main.label}, {args.particles} particles; "
          f"the paper's sensor period is 10 ms)")
    if args.out:
        with staged(args) as tmp:
            paths = write_simulation(tmp, main.results, main.metrics, dump_config(main.config), comparison=sets,
                                     title="Seam tracking demo")
        print(f"wrote {args.out}: {', '.join(p.name for p in paths.values())}")
    return 0

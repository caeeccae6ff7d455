"""``posekit seam simulate`` and ``posekit seam demo``: simulated seam tracking with figures.

Precedence of settings: defaults < ``--config`` file < flags.
"""

import functools
import sys

from ..errors import ConfigError
from ._common import add_overwrite, out_folder, staged
from ._common import progress as _progress
from ._config import add_config_arguments
from ._flags import bounded_int, check_flags, seed

__all__ = ["DEMO_PARTICLES", "DEMO_STEPS", "add_demo_parser", "add_simulate_parser", "build_config", "rmse_table"]

#: The trajectory kinds (``posekit.seam.frontend.config.TRAJECTORY_KINDS``, not imported here: the parser stays light).
TRAJECTORIES = ("xy", "yz", "line", "bend")
#: ``posekit.seam.frontend.commands``' DEMO_*, MAX_KEPT_STEPS, MAX_RECORDED, RECORD_DEFAULT (not imported: the
#: parser stays light; a test keeps them equal).
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
    add_config_arguments(p)
    p.set_defaults(func=run_demo)
    return p


def build_config(args):
    """The effective :class:`~posekit.seam.frontend.config.SeamConfig`: defaults < ``--config`` < flags
    (:func:`posekit.seam.frontend.commands.episode_config`)."""
    from ..seam.frontend.commands import episode_config

    for flag, value, low in (("--particles", args.particles, 1), ("--steps", args.steps, 2),
                             ("--seed", args.seed, 0)):
        if value is not None and value < low:
            raise ConfigError(f"{flag}: expected an integer >= {low}, got {value}")
    check_flags(args, ("particles", "steps", "seed"))
    with layout_notes():
        return episode_config(args.config, profile=getattr(args, "profile", None), trajectory=args.trajectory,
                              sensors=args.sensors, particles=args.particles, steps=args.steps, seed=args.seed)


def with_profile(cfg, path):
    """``cfg`` with the profile file ``path`` (``--profile``) in place of its own; unchanged for None."""
    from ..seam.frontend.commands import with_profile as _with_profile

    return _with_profile(cfg, path)


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


def _save_log_rules(args) -> dict:
    """``--overwrite`` names the ``--out`` folder: it replaces a ``--save-log`` folder only while
    posekit wrote everything in it (never files of the user's)."""
    return {"replace_own": bool(args.overwrite),
            "hint": "--overwrite replaces it only if posekit wrote all of it; remove them or pick another folder"}


def run_simulate(args) -> int:
    from ..seam.frontend.commands import check_kept, record_count, simulate_episodes
    from ..seam.frontend.config import dump_config

    cfg = build_config(args)
    if args.dump_config:
        sys.stdout.write(dump_config(cfg))
        return 0
    if not args.out:
        raise ConfigError("--out: an output folder is required (or use --dump-config)")
    if args.runs < 1:
        raise ConfigError(f"--runs: expected an integer >= 1, got {args.runs}")
    if args.record_particles is not None and args.record_particles < 0:
        record_count(args.record_particles, 1)          # its one-line error
    check_flags(args)
    check_kept(args.runs, cfg.trajectory.steps, 6 if args.compare else 1)
    record_count(args.record_particles, cfg.trajectory.steps)
    out_folder(args)
    if args.save_log:
        from ..io import check_out_folder

        if str(args.save_log) == str(args.out):
            raise ConfigError("--save-log: expected a folder other than --out")
        check_out_folder(args.save_log, flag="--save-log", **_save_log_rules(args))
    with staged(args) as tmp:
        if args.save_log:
            from ..io import staged_folder

            with staged_folder(args.save_log, flag="--save-log", **_save_log_rules(args)) as log_tmp:
                sim = simulate_episodes(cfg, tmp, runs=args.runs, compare=args.compare,
                                        record_particles=args.record_particles, save_log=log_tmp, progress=progress)
        else:
            sim = simulate_episodes(cfg, tmp, runs=args.runs, compare=args.compare,
                                    record_particles=args.record_particles, progress=progress)
    m, comparison, results, paths = sim.metrics, sim.comparison, sim.results, sim.paths
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
    kinematics (:func:`posekit.seam.frontend.commands.two_sensor_wins`)."""
    from ..seam.frontend.commands import two_sensor_wins

    parts = [f"{kind} {n}/6" for kind, n in two_sensor_wins(sets).items()]
    return ("verdict: two sensors beat the kinematics on " + ", ".join(parts) + " axes (the paper's Fig. 8: two "
            "sensors give the smallest error; expected 6/6; fewer sensors leave some axes unobserved)")


def run_demo(args) -> int:
    from ..seam.frontend.commands import check_kept, demo

    if args.runs < 1:
        raise ConfigError(f"--runs: expected an integer >= 1, got {args.runs}")
    for flag, value, low in (("--particles", args.particles, 1), ("--steps", args.steps, 2),
                             ("--seed", args.seed, 0)):
        if value < low:
            raise ConfigError(f"{flag}: expected an integer >= {low}, got {value}")
    check_flags(args)
    check_kept(args.runs, args.steps, 6)
    if args.out:
        out_folder(args)
        with staged(args) as tmp:
            run = demo(seed=args.seed, runs=args.runs, steps=args.steps, particles=args.particles, out=tmp,
                       progress=progress)
    else:
        run = demo(seed=args.seed, runs=args.runs, steps=args.steps, particles=args.particles, progress=progress)
    sets, main = run.sets, run.main
    print(f"seam demo: {args.runs} run(s) × {args.steps} steps, {args.particles} particles, sensors 20/40 mm ahead "
          f"({run.wall_s:.1f} s)")
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
    print(f"filter step median: {main.metrics['step_ms_median']:.3f} ms ({main.label}, {args.particles} particles; "
          f"the paper's sensor period is 10 ms)")
    if args.out:
        print(f"wrote {args.out}: {', '.join(p.name for p in run.paths.values())}")
    return 0

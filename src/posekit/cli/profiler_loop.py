"""``posekit profiler loop``: the closed-loop experiment of §IV-C over loopback sockets."""

import importlib.util
import sys

from .._numbers import parse_number
from ._common import add_deprecated, add_overwrite, out_folder, overwrite_flag, progress, replace_own_flag
from ._config import add_config_arguments
from ._flags import MAX_NOISE_UM, bounded_float, bounded_int, check_flags, seed

#: Most runs per axis, step and mode; most step sizes and axes; most closed-loop runs in all
#: (axes × steps × 2 modes × runs: about 0.4 s each in lock-step, so at most about 15 minutes).
MAX_RUNS, MAX_STEPS, MAX_AXES, MAX_TOTAL_RUNS = 100, 10, 10, 2000
_RUNS = bounded_int(1, MAX_RUNS, flag="--runs")
#: ``posekit.profiler.loop.closed_loop.MAX_STEP_MM`` for the help (not imported: the parser stays light;
#: tests/cli/test_cli_library.py keeps them equal).
HELP_MAX_STEP_MM = 50.0

__all__ = ["add_loop_parser", "run_loop"]


def add_loop_parser(verbs):
    p = verbs.add_parser("loop", help="closed-loop step responses: sensor sim -> server -> PD -> robot sim")
    add_loop_arguments(p)
    p.set_defaults(func=run_loop)


def add_loop_arguments(p, out_default=None):
    p.add_argument("--gauge", default="demo-5", help="gauge YAML file or bundled name (default demo-5)")
    p.add_argument("--out", required=out_default is None, default=out_default,
                   help="output folder: table3.csv, table4.csv, figures, report.html"
                        + (f" (default {out_default}, replaced on each run while it holds only posekit's files)" if out_default else ""))
    add_overwrite(p, out_default)
    p.add_argument("--runs", dest="repeats", type=_RUNS, default=3,
                   help=f"runs per axis, step and mode, 1..{MAX_RUNS} (default 3)")
    add_deprecated(p, "--repeats", "--runs", "repeats", _RUNS)
    p.add_argument("--axes", default="x,y,z,xyz", help=f"step directions, at most {MAX_AXES} (default x,y,z,xyz)")
    p.add_argument("--steps-mm", default="1,2",
                   help=f"step sizes, at most {MAX_STEPS}, each non-zero within ±{HELP_MAX_STEP_MM:g} mm (default 1,2)")
    p.add_argument("--noise-um", type=bounded_float(0.0, MAX_NOISE_UM, "µm"), default=5.0,
                   help="profiler noise in z, 0..10000 µm (x: twice); default 5")
    p.add_argument("--seed", type=seed, default=0, help="random seed (default 0)")
    p.add_argument("--realtime", action="store_true", help="pace the cycles at 83.3 Hz instead of lock-step")
    p.add_argument("--linear", action="store_true", help="linear robot model (no amplitude-dependent damping)")
    p.add_argument("--no-camera", action="store_true", help="skip timing the camera pipeline for Table III")
    add_config_arguments(p)


def run_loop(args) -> int:
    import numpy as np

    from ..errors import ConfigError
    from ..profiler.gauge.model import resolve_gauge
    from ..profiler.loop.closed_loop import MAX_STEP_MM, closed_loop
    from ..profiler.loop.loop_report import format_table3, format_table4

    try:
        steps = tuple(parse_number(v) for v in args.steps_mm.split(","))
    except ValueError:
        raise ConfigError(f"--steps-mm: expected comma-separated numbers, got '{args.steps_mm}'") from None
    if not all(np.isfinite(s) and s != 0 for s in steps):
        raise ConfigError(f"--steps-mm: steps must be finite and non-zero, got '{args.steps_mm}'")
    if not (np.isfinite(args.noise_um) and args.noise_um >= 0):
        raise ConfigError(f"--noise-um must be a finite number >= 0, got {args.noise_um:g}")
    if any(abs(s) > MAX_STEP_MM for s in steps):
        raise ConfigError(f"--steps-mm: expected non-zero step sizes in -{MAX_STEP_MM:g}..{MAX_STEP_MM:g} mm, "
                          f"got '{args.steps_mm[:80]}'")
    axes = tuple(a.strip() for a in args.axes.split(","))
    for flag, n, most in (("--steps-mm", len(steps), MAX_STEPS), ("--axes", len(axes), MAX_AXES)):
        if n > most:
            raise ConfigError(f"{flag}: expected 1..{most} comma-separated values, got {n}")
    check_flags(args)
    total = len(axes) * len(steps) * 2 * args.repeats
    if total > MAX_TOTAL_RUNS:
        raise ConfigError(f"--runs {args.repeats} × {len(steps)} step sizes × {len(axes)} axes × 2 modes = {total} "
                          f"closed-loop runs; expected at most {MAX_TOTAL_RUNS} (about 15 minutes)")
    gauge = resolve_gauge(args.gauge)
    out_folder(args)
    camera = not args.no_camera
    if camera and importlib.util.find_spec("cv2") is None:
        from .._extras import install_hint
        print("posekit: note: Table III without the OpenCV camera pipeline, which needs the 'vision' extra: "
              f"{install_hint('vision')}", file=sys.stderr)
        camera = False
    print(f"closed loop on gauge '{gauge.name}': steps {', '.join(f'{s:g}' for s in steps)} mm along "
          f"{', '.join(axes)}, open vs closed, {args.repeats} repeats, "
          f"{'real time (83.3 Hz)' if args.realtime else 'lock-step'} over loopback TCP")
    exp, paths = closed_loop(gauge, runs=args.repeats, axes=axes, steps_mm=steps, noise_um=args.noise_um,
                             seed=args.seed, realtime=args.realtime, linear=args.linear, camera=camera,
                             out=args.out, overwrite=overwrite_flag(args), replace_own=replace_own_flag(args),
                             progress=lambda it: progress(it, total=len(it), desc="runs"))
    print()
    from ..profiler.loop.loop_verdict import table3_verdict, table4_verdicts
    print("Table IV: step responses of the robot's flange, open loop (robot alone) and closed loop (posekit's pose "
          "feeding the PD correction); mean ± std over repeats; the paper's values at the right")
    print("  Mp: overshoot, % of the step; zeta: damping ratio (1 = no oscillation); Mf: amplitude of the 10 Hz "
          "oscillation about the target, um (spectrum peak over 1 s after arrival); improv.: closed vs open")
    print(format_table4(exp))
    for line in table4_verdicts(exp.table4):
        print(line)
    print()
    print("Table III: time per stage and frame, ms (DT data transfer, CD corner detection / chessboard corners, "
          "PC pose computation); camera = 2590x1942 chessboard image through OpenCV; the paper's at the right")
    print(format_table3(exp))
    verdict = table3_verdict(exp.table3)
    if verdict:
        print(verdict)
    st = exp.server_stats or {}
    missed = sum(r.missed for r in exp.runs)
    res = exp.resonance or {}
    print()
    print(f"server: {st.get('received', 0)} frames received, {st.get('processed', 0)} processed, "
          f"{st.get('dropped', 0)} dropped, {st.get('rejected', 0)} rejected, {st.get('errors', 0)} failed; "
          f"{missed} missed cycles; resonance from the impulse: {res.get('f_natural_hz', float('nan')):.2f} Hz")
    print(f"wall time {exp.wall_s:.1f} s; wrote {paths['table3']}, {paths['table4']} and {paths['report']}")
    return 0

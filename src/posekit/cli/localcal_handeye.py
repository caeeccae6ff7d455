"""``posekit localcal handeye``: the camera mount (camera-to-tool) and the camera's world frame in
the robot base, together, for a camera that is not at the tool point."""

from ._config import add_config_arguments
from ._flags import bounded_float, check_flags
from .localcal_inputs import add_pair_args, add_trajectory_args, print_result, read_options

__all__ = ["add_handeye_parser", "run_handeye"]


def add_handeye_parser(verbs):
    """Add the ``handeye`` verb to the ``localcal`` sub-parsers ``verbs``."""
    p = verbs.add_parser(
        "handeye", help="camera-to-tool transform and camera-world-to-base transform from pose pairs",
        description="Hand-eye calibration (A X = Z B) from a camera trajectory (VO/SLAM, T_world_camera) and "
                    "the kinematic tool trajectory (T_base_tool) of the same motion. Writes {R_tool_camera, "
                    "t_tool_camera_mm, R, t_mm, rmse_mm, status, reasons, std_rot_deg, std_t_mm, ...}: "
                    "p_tool = R_tool_camera p_camera + t_tool_camera_mm and p_base = R p_world + t_mm; the std "
                    "keys are 1 sigma of the camera mount (std_world_* of R, t_mm). Exit 1 when suspect. "
                    "The tool must rotate about at least two non-parallel axes.")
    add_pair_args(p, kinematic_help="tool (TCP/flange) poses in the robot base frame", out_metavar="HANDEYE.json")
    p.add_argument("--max-dt", type=bounded_float(0.0, 10.0, "s", lo_open=True), default=0.02, metavar="S",
                   help="largest time difference of an associated pose pair, (0, 10] s (default 0.02)")
    p.add_argument("--time-offset", type=bounded_float(-1e10, 1e10, "s"), default=None, metavar="S",
                   help="known clock offset t_kinematic - t_camera, -1e10..1e10 s (default: estimated)")
    p.add_argument("--max-offset", type=bounded_float(0.0, 100.0, "s"), default=1.0, metavar="S",
                   help="search the clock offset within +-S seconds, 0..100 (default 1; beyond, give --time-offset)")
    p.add_argument("--noise-mm", type=bounded_float(0.0, 1e5, "mm", lo_open=True), default=2.0, metavar="MM",
                   help="expected per-pose position noise of the camera, (0, 1e5] mm (default 2)")
    p.add_argument("--noise-deg", type=bounded_float(0.0, 90.0, "deg", lo_open=True), default=0.5, metavar="DEG",
                   help="expected per-pose rotation noise of the camera, (0, 90] deg (default 0.5)")
    p.add_argument("--max-std-mm", type=bounded_float(0.0, 1e5, "mm", lo_open=True), default=5.0, metavar="MM",
                   help="suspect when the camera mount's translation std exceeds this, (0, 1e5] mm (default 5)")
    p.add_argument("--max-std-deg", type=bounded_float(0.0, 180.0, "deg", lo_open=True), default=0.5, metavar="DEG",
                   help="suspect when the camera mount's rotation std exceeds this, (0, 180] deg (default 0.5)")
    add_trajectory_args(p)
    add_config_arguments(p)
    p.set_defaults(func=run_handeye)
    return p


def run_handeye(args) -> int:
    """Run ``posekit localcal handeye`` (:func:`posekit.localcal.handeye_files`); returns the exit code
    (0 ok, 1 suspect)."""
    import numpy as np

    from ..geometry import rotation_angle_between
    from ..localcal.commands import handeye_files

    check_flags(args)
    run = handeye_files(args.camera, args.kinematic, args.out, camera_read=read_options(args, "camera"),
                        kinematic_read=read_options(args, "kinematic"), max_dt_s=args.max_dt,
                        time_offset_s=args.time_offset, max_offset_s=args.max_offset, noise_mm=args.noise_mm,
                        noise_deg=args.noise_deg, max_std_t_mm=args.max_std_mm, max_std_rot_deg=args.max_std_deg)
    res = run.result
    X, Z = res.T_tool_camera, res.T_base_world
    ax = np.rad2deg(float(rotation_angle_between(np.eye(3), X[:3, :3], check=False)))
    az = np.rad2deg(float(rotation_angle_between(np.eye(3), Z[:3, :3], check=False)))
    offset = ("a clock offset the data do not determine (paired at 0)" if res.time_offset_source == "undetermined"
              else f"a clock offset of {res.time_offset_s * 1000:+.1f} ms")
    return print_result(run.written["json"], res, [
        f"hand-eye from {res.n_pairs} pose pairs ({int(res.inliers.sum())} inliers) at {offset}",
        f"camera in tool: {ax:.3f} deg rotation, t [{X[0, 3]:.2f}, {X[1, 3]:.2f}, {X[2, 3]:.2f}] mm "
        f"(|t| {np.linalg.norm(X[:3, 3]):.2f} mm); std " + ", ".join(f"{v:.3g}" for v in res.std_rot_deg)
        + " deg, " + ", ".join(f"{v:.3g}" for v in res.std_t_mm) + " mm",
        f"world in base: {az:.3f} deg rotation, t [{Z[0, 3]:.2f}, {Z[1, 3]:.2f}, {Z[2, 3]:.2f}] mm; "
        f"rmse {res.rmse_mm:.2f} mm, {res.rms_rot_deg:.3f} deg",
        *[f"note: {n}" for n in res.notes],
    ], "hand-eye")

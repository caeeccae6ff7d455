"""The configuration keys of issue 15: sensors as 4×4 mounts, the tool as a 4×4 transform, the
tool following the seam tangent."""

import math

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.geometry import matrix_from_rotation_vector
from posekit.seam.frontend.config import apply_overrides, config_from_dict, dump_config, load_config


def _mount(rz_deg, t):
    M = np.eye(4)
    M[:3, :3] = matrix_from_rotation_vector(np.array([0.0, 0.0, math.radians(rz_deg)]))
    M[:3, 3] = t
    return M.tolist()


def test_distances_are_pure_y_shift_mounts():
    cfg = config_from_dict({"cell": {"sensors": {"count": 3, "distances_mm": [20, 35, 50]}}})
    M = cfg.cell.sensors.resolved_mounts()
    assert M.shape == (3, 4, 4)
    assert np.allclose(M[:, :3, :3], np.eye(3)) and np.allclose(M[:, :3, 3], [[0, 20, 0], [0, 35, 0], [0, 50, 0]])


def test_mounts_round_trip_and_give_distances(tmp_path):
    mounts = [_mount(30.0, [5.0, 25.0, -3.0]), _mount(0.0, [0.0, 60.0, 0.0])]
    cfg = config_from_dict({"cell": {"sensors": {"count": 2, "mounts": mounts},
                                     "robot": {"tool": _mount(0.0, [0, 0, 120])}}})
    assert cfg.cell.sensors.resolved_distances_mm() == (25.0, 60.0)
    assert np.allclose(cfg.cell.sensors.resolved_mounts(), mounts)
    assert np.allclose(cfg.cell.robot.tool_matrix()[:3, 3], [0, 0, 120])
    (tmp_path / "c.yaml").write_text(dump_config(cfg))
    again = load_config(tmp_path / "c.yaml")
    assert again == cfg
    one = apply_overrides(cfg, {"cell.sensors.count": 1})          # fewer sensors keep the first mount
    assert np.allclose(one.cell.sensors.resolved_mounts(), mounts[:1])
    # without a tool matrix the tool is tool_length_mm along the flange z axis
    tool = config_from_dict({"cell": {"robot": {"tool_length_mm": 90}}}).cell.robot.tool_matrix()
    assert np.allclose(tool[:3, 3], [0, 0, 90])


@pytest.mark.parametrize("sensors, message", [
    ({"count": 1, "mounts": [[[1, 0, 0, 0], [0, 1, 0, 20], [0, 0, 1, 0], [0, 0, 1, 1]]]},
     "cell.sensors.mounts: mounts[0] (T_tool_sensor): expected the last row [0, 0, 0, 1], got [0.0, 0.0, 1.0, 1.0]"),
    ({"count": 1, "mounts": [[[2, 0, 0, 0], [0, 1, 0, 20], [0, 0, 1, 0], [0, 0, 0, 1]]]},
     "cell.sensors.mounts: mounts[0] (T_tool_sensor): expected a rotation (orthonormal, det +1) in the upper-left 3x3, "
     "off by 3"),
    ({"count": 1, "mounts": [[[-1, 0, 0, 0], [0, 1, 0, 20], [0, 0, 1, 0], [0, 0, 0, 1]]]}, "(a reflection)"),
    ({"count": 2, "mounts": [_mount(0, [0, 20, 0])]}, "cell.sensors: count is 2 but mounts has 1 entries"),
    ({"count": 1, "mounts": [_mount(0, [0, 20, 0])], "distances_mm": [20]},
     "cell.sensors: give either distances_mm or mounts"),
    ({"count": 1, "mounts": [_mount(10, [0, 20, 0])], "angle": True},
     "cell.sensors: angle: the angle measurement needs sensor axes parallel to the tool's"),
    ({"count": 1, "mounts": [[[1, 0, 0], [0, 1, 0], [0, 0, 1]]]}, "cell.sensors.mounts.0"),
])
def test_bad_mounts_are_one_line(sensors, message):
    with pytest.raises(ConfigError) as info:
        config_from_dict({"cell": {"sensors": sensors}}, "cfg.yaml")
    text = str(info.value)
    assert "\n" not in text and text.startswith("cfg.yaml: ")
    assert message in text, text


def test_tangent_tool_turns_with_a_right_angle_corner():
    """The 90° bend with the tool following the tangent: before the corner the tool's y is the
    start travel direction, after it (past turn_mm) the travel is turned by 90° about the tool
    axis; the program is met by the inverse kinematics and the seam stays in the tool's y–z plane."""
    from posekit.seam.frontend.trajectories import nominal_trajectory

    cfg = config_from_dict({"trajectory": {"kind": "bend", "bend_deg": 90, "tool_orientation": "tangent",
                                           "turn_mm": 10.0, "steps": 201}})
    nt = nominal_trajectory(cfg.trajectory, cfg.cell.robot)
    assert nt.ik_max_error_mm < 1e-3
    y0 = nt.T_nominal[0, :3, 1]
    y_end = nt.T_nominal[-1, :3, 1]
    assert np.allclose(y0, [0, 1, 0], atol=1e-6)
    assert np.allclose(y_end, [-1, 0, 0], atol=1e-6)              # T0's x is base -x: turned +90° in T0
    assert np.allclose(nt.T_nominal[:, :3, 2], [0, 0, -1], atol=1e-6)   # the tool axis stays down
    # halfway through the turn (at the corner) the heading is at 45°
    k = int(np.argmin(np.abs(nt.u_mm - 100.0)))
    assert abs(math.degrees(math.atan2(-nt.T_nominal[k, 0, 1], nt.T_nominal[k, 1, 1])) - 45.0) < 3.0
    # the fixed tool keeps its orientation through the corner
    fixed = nominal_trajectory(config_from_dict({"trajectory": {"kind": "bend", "bend_deg": 90, "steps": 201}})
                               .trajectory, cfg.cell.robot)
    assert np.allclose(fixed.T_nominal[:, :3, :3], fixed.T_nominal[0, :3, :3], atol=1e-6)

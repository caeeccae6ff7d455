"""``posekit localcal simulate --robot``: a user's long-reach arm from a URDF file.

The HIAB033-like crane is written here as a URDF file by a generator of this test's own (DH
rows -> joint origins with scipy's extrinsic xyz = URDF rpy, 'link 7' as a fixed joint), so
the run on the URDF arm must reproduce the run on the bundled DH model.
"""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from posekit.cli.main import main
from posekit.localcal.studies.episode_config import START_Q
from posekit.robots import hiab033, load_urdf

#: The crane's DH rows (a mm, alpha rad, d mm, theta0 rad) and limits (deg), from models.py's docs.
CRANE_DH = [(300.0, np.pi / 2, 1500.0, 0.0), (2400.0, 0.0, 0.0, 0.0), (250.0, np.pi / 2, 150.0, np.pi / 2),
            (0.0, np.pi / 2, 2200.0, 0.0), (0.0, -np.pi / 2, 0.0, 0.0), (0.0, np.pi / 2, 350.0, 0.0)]
CRANE_LIMITS_DEG = [(-170, 170), (-20, 75), (-160, 30), (-180, 180), (-120, 120), (-180, 180)]


def _row(a, alpha, d, theta):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("ZX", [theta, alpha]).as_matrix()  # Rot_z(theta) Rot_x(alpha)
    T[:3, 3] = [a * np.cos(theta), a * np.sin(theta), d]
    return T


def _origin(T):
    xyz = " ".join(repr(float(v)) for v in T[:3, 3] / 1000.0)
    rpy = " ".join(repr(float(v)) for v in Rotation.from_matrix(T[:3, :3]).as_euler("xyz"))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def crane_urdf() -> str:
    lines = ['<robot name="my_crane">'] + [f'<link name="l{i}"/>' for i in range(8)]
    prev = np.eye(4)
    for i, (row, (lo, hi)) in enumerate(zip(CRANE_DH, CRANE_LIMITS_DEG)):
        lines.append(f'<joint name="q{i + 1}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
                     f'{_origin(prev)}<axis xyz="0 0 1"/>'
                     f'<limit lower="{float(np.radians(lo))!r}" upper="{float(np.radians(hi))!r}" effort="1" velocity="1"/></joint>')
        prev = _row(*row)
    lines.append(f'<joint name="link7" type="fixed"><parent link="l6"/><child link="l7"/>'
                 f'{_origin(prev @ _row(0.0, np.pi / 2, 0.0, 0.0))}</joint>')
    return "\n".join(lines + ["</robot>"])


@pytest.fixture(scope="module")
def crane(tmp_path_factory):
    path = tmp_path_factory.mktemp("crane") / "my_crane.urdf"
    path.write_text(crane_urdf())
    return path


def test_generated_crane_is_the_dh_crane(crane):
    chain, dh = load_urdf(crane), hiab033()
    qs = np.random.default_rng(0).uniform(-2.0, 2.0, (50, 6))
    np.testing.assert_allclose(chain.forward_kinematics(qs), dh.forward_kinematics(qs), atol=1e-9)
    np.testing.assert_allclose(chain.q_min, dh.q_min, atol=1e-12)


def test_simulate_on_a_urdf_arm_reproduces_the_bundled_crane(crane, tmp_path, capsys):
    start = ",".join(repr(float(v)) for v in np.degrees(START_Q))
    common = ["localcal", "simulate", "--method", "trajectory", "--runs", "1", "--seed", "2", "--plot-hz", "0"]
    assert main([*common, "--out", str(tmp_path / "dh")]) == 0
    assert main([*common, "--robot", str(crane), "--start-q-deg", start, "--out", str(tmp_path / "urdf")]) == 0
    a = json.loads((tmp_path / "dh" / "results.json").read_text())["tables"]
    b = json.loads((tmp_path / "urdf" / "results.json").read_text())["tables"]
    assert a.keys() == b.keys()
    for key in a:
        for ra, rb in zip(a[key], b[key]):
            for col, value in ra.items():
                if isinstance(value, float):
                    assert rb[col] == pytest.approx(value, abs=1e-6), (key, col)
    # the trajectory method's result, not just equal: sub-centimetre x, y after two updates
    second = a["table4"][0]
    assert abs(second["ex_2_mm"]) < 10.0 and abs(second["ey_2_mm"]) < 10.0


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--robot", "kuka"], "unknown robot 'kuka': expected a bundled model (puma560, hiab033, abb_irb6640, ur10) "
                              "or a URDF file path"),
        (["--robot", "ur10"], "--start-q-deg: required for --robot ur10 (the crane's start pose fits only the crane); "
                              "give its 6 start joint values in deg (chain base_link → ee_link)"),
        (["--robot", "ur10", "--start-q-deg", "1,2"], "--start-q-deg: expected 6 values for ur10, got 2"),
        (["--robot", "ur10", "--start-q-deg", "1,a,3"], "--start-q-deg: expected comma-separated numbers, got '1,a,3'"),
        (["--robot", "ur10", "--start-q-deg", "1,2,3,4,5,nan"], "--start-q-deg: expected finite values, got '1,2,3,4,5,nan'"),
        (["--robot", "hiab033", "--tip-link", "x"], "robot 'hiab033' is a bundled model: base_link and tip_link apply "
                                                    "to a URDF file only"),
        (["--robot", "missing.urdf"], "missing.urdf: no such URDF file"),
    ],
)
def test_bad_robot_flags(tmp_path, capsys, argv, message):
    rc = main(["localcal", "simulate", "--method", "line", "--runs", "1", *argv, "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 1
    assert err.strip() == f"posekit: error: {message}"
    assert not (tmp_path / "o").exists()

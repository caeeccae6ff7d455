"""Every reader refuses a named pipe and a device in one line (issue 28, deliverable 11).

A bag path that was a named pipe used to block forever, one linked to /dev/zero grew past 3 GB,
and ``--format rosbag`` on /dev/zero was an internal error. Here each reader gets a FIFO and a
link to /dev/zero under the name it expects. A watchdog opens the FIFO for writing after 20 s,
so a reader that would block forever fails the test instead of hanging it.
"""

import os
import threading
from pathlib import Path

import pytest

from posekit.ceiling.camera import load_camera
from posekit.ceiling.camera.homography import load_calibration
from posekit.ceiling.camera.points import read_points_csv
from posekit.ceiling.track.sources import open_frames
from posekit.errors import PosekitError
from posekit.io import read_image
from posekit.localcal.registration.formats import read_euroc, read_kitti, read_rosbag, read_tum
from posekit.profiler.gauge.model import load_gauge
from posekit.profiler.stream.reading import read_profile_file
from posekit.profiler.stream.server_support import read_token_file
from posekit.robots import load_urdf
from posekit.seam import load_config
from posekit.seam.frontend.logs import read_episode_log
from tests.cli_helpers import assert_one_line_error, run_cli

READERS = {
    "profile.csv": read_profile_file,
    "profile.npy": read_profile_file,
    "profiles.npz": read_profile_file,
    "gauge.yaml": load_gauge,
    "seam.yaml": load_config,
    "cal.json": load_calibration,
    "points.csv": read_points_csv,
    "camera.json": load_camera,
    "poses.tum": read_tum,
    "poses.csv": read_euroc,
    "poses.txt": lambda p: read_kitti(p, 10.0),
    "poses.bag": read_rosbag,
    "poses.db3": read_rosbag,
    "poses.mcap": read_rosbag,
    "arm.urdf": load_urdf,
    "frame.png": read_image,
    "video.mp4": lambda p: list(open_frames(p)),
    "token.txt": read_token_file,
}
WHAT = {"fifo": "is a named pipe (FIFO), not a regular file", "zero": "is a character device, not a regular file"}


def _special(tmp_path, name, kind):
    path = tmp_path / name
    if kind == "fifo":
        os.mkfifo(path)
        guard = threading.Timer(20.0, lambda: os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
                                if _has_reader(path) else None)
        guard.daemon = True
        guard.start()
    else:
        path.symlink_to("/dev/zero")
    return path


def _has_reader(path):
    try:
        os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
        return True
    except OSError:
        return False


@pytest.mark.parametrize("kind", ["fifo", "zero"])
@pytest.mark.parametrize("name", list(READERS))
def test_reader_refuses_a_pipe_or_a_device(tmp_path, name, kind):
    path = _special(tmp_path, name, kind)
    with pytest.raises(PosekitError) as err:
        READERS[name](path)
    msg = str(err.value)
    assert msg.startswith(str(path)) and WHAT[kind] in msg, msg
    assert "\n" not in msg and len(msg) <= 300


@pytest.mark.parametrize("kind", ["fifo", "zero"])
def test_a_bag_folder_with_a_special_storage_file(tmp_path, kind):
    folder = tmp_path / "bag"
    folder.mkdir()
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n"
                                          "  relative_file_paths: [x.db3]\n")
    _special(folder, "x.db3", kind)
    with pytest.raises(PosekitError, match=rf"bag/x.db3: {WHAT[kind]}".replace("(", r"\(").replace(")", r"\)")):
        read_rosbag(folder)


def test_seam_episode_with_a_piped_setup(tmp_path):
    folder = tmp_path / "ep"
    folder.mkdir()
    for name in ("seam.csv", "log.csv"):
        (folder / name).write_text("x\n")
    _special(folder, "setup.yaml", "fifo")
    with pytest.raises(PosekitError, match="setup.yaml: is a named pipe"):
        read_episode_log(folder)


def test_rosbag_format_on_dev_zero_from_the_cli(capsys):
    rc, out, err = run_cli(capsys, "localcal", "match", "/dev/zero", "/dev/zero", "--format", "rosbag",
                           "--out", "/dev/null")
    assert_one_line_error(rc, out, err, "/dev/zero: is a character device, not a regular file; expected a ROS bag")
    assert Path("/dev/zero").is_char_device()

"""Writes the fuzz corpus's binary seed inputs into tests/fuzz/seeds/ (committed; rerun to refresh):

    python tests/fuzz/make_seeds.py

Small valid files of each binary format a reader takes: a profile (.npy), a batch (.npz), ROS 1
and ROS 2 bags (.bag, .db3, .mcap) with a PoseStamped topic, a PNG and a JPEG frame, and an
MJPG .avi of 8 frames. The text seeds (gauges, configs, URDFs, trajectories, JSON) are written
by :mod:`tests.fuzz.corpus` itself or taken from examples/.
"""

import io
import shutil
import tempfile
from pathlib import Path

import numpy as np

SEEDS = Path(__file__).resolve().parent / "seeds"


def _poses(n=12):
    t = 100.0 + np.arange(n) / 10.0
    p = np.column_stack([np.sin(t), np.cos(t), 0.1 * t]) * 0.5
    return t, p


def _bag(path: Path, ros: int, storage: str = "sqlite3") -> Path:
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros == 1 else Stores.ROS2_HUMBLE)
    ty = ts.types
    kind = "geometry_msgs/msg/PoseStamped"
    writer = Writer1(path) if ros == 1 else Writer2(path, version=9, storage_plugin=(
        StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3))
    with writer:
        conn = writer.add_connection("/pose", kind, typestore=ts)
        for k, (t, p) in enumerate(zip(*_poses())):
            sec = int(t)
            stamp = ty["builtin_interfaces/msg/Time"](sec=sec, nanosec=int((t - sec) * 1e9))
            extra = {"seq": k} if "seq" in ty["std_msgs/msg/Header"].__dataclass_fields__ else {}
            header = ty["std_msgs/msg/Header"](**extra, stamp=stamp, frame_id="world")
            pose = ty["geometry_msgs/msg/Pose"](position=ty["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
                                                orientation=ty["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0,
                                                                                               w=1.0))
            msg = ty[kind](header=header, pose=pose)
            raw = ts.serialize_ros1(msg, kind) if ros == 1 else ts.serialize_cdr(msg, kind)
            writer.write(conn, int(t * 1e9), raw)
    return path


def main() -> None:
    import cv2

    from posekit.profiler import NoiseModel, bundled_gauge, nominal_pose, render_profiles, sample_poses

    SEEDS.mkdir(exist_ok=True)
    gauge = bundled_gauge("demo-5")
    prof = render_profiles(gauge, nominal_pose(gauge), NoiseModel(), rng=0)[::4]      # 800 points
    np.save(SEEDS / "profile.npy", prof)
    batch = render_profiles(gauge, sample_poses(gauge, 3, rng=1), NoiseModel(), rng=1)[:, ::4]
    buf = io.BytesIO()
    np.savez_compressed(buf, profiles=batch)
    (SEEDS / "profiles.npz").write_bytes(buf.getvalue())
    (SEEDS / "pose.bag").unlink(missing_ok=True)          # (the bag writer does not overwrite)
    _bag(SEEDS / "pose.bag", 1)
    with tempfile.TemporaryDirectory() as tmp:
        for storage, suffix in (("sqlite3", ".db3"), ("mcap", ".mcap")):
            folder = _bag(Path(tmp) / storage, 2, storage)
            data = next(folder.glob(f"*{suffix}"))
            shutil.copy(data, SEEDS / f"pose{suffix}")
            if storage == "sqlite3":              # a bag folder: this metadata beside pose.db3 as sqlite3.db3
                shutil.copy(folder / "metadata.yaml", SEEDS / "bag2_metadata.yaml")
    img = np.zeros((48, 64, 3), np.uint8)
    cv2.circle(img, (20, 30), 4, (40, 40, 255), -1)
    cv2.circle(img, (44, 18), 4, (40, 255, 40), -1)
    cv2.imwrite(str(SEEDS / "frame.png"), img)
    cv2.imwrite(str(SEEDS / "frame.jpg"), img, [cv2.IMWRITE_JPEG_QUALITY, 60])
    w = cv2.VideoWriter(str(SEEDS / "video.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (64, 48))
    for k in range(8):
        w.write(np.roll(img, k, axis=1))
    w.release()
    for p in sorted(SEEDS.iterdir()):
        print(f"{p.name}: {p.stat().st_size} bytes")


if __name__ == "__main__":
    main()

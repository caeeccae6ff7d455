"""A bounded fuzz suite over every reader and config model: mutated valid files and random
bytes either load or fail with a one-line PosekitError — never another exception.

Each reader gets a valid seed file; hypothesis flips, truncates, duplicates and inserts bytes
(or writes arbitrary bytes). The whole module runs in a few seconds (few examples per reader,
no deadline) so that it stays in CI.
"""

import io
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from posekit.ceiling.camera.homography import load_calibration
from posekit.ceiling.camera.points import read_points_csv
from posekit.errors import PosekitError
from posekit.localcal.registration.formats.tum import read_tum
from posekit.profiler.gauge.model import bundled_gauge_path, load_gauge
from posekit.profiler.stream.reading import read_profiles
from posekit.robots import bundled_robot_path, load_urdf
from posekit.seam import config_from_dict, load_config

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
FUZZ = settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)


def _npy_bytes():
    buf = io.BytesIO()
    np.save(buf, np.column_stack([np.linspace(-10, 10, 50), np.linspace(400, 420, 50)]))
    return buf.getvalue()


def _npz_bytes():
    buf = io.BytesIO()
    np.savez_compressed(buf, profiles=np.zeros((2, 20, 2)))
    return buf.getvalue()


CAL_JSON = (b'{"H_image_world": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "H_world_image": [[1, 0, 0], [0, 1, 0], '
            b'[0, 0, 1]], "rms_px": 0.1, "rms_world": 0.2}')
POINTS_CSV = b"X,Y,u,v\n0,0,10,10\n1000,0,500,12\n1000,1000,510,480\n0,1000,8,470\n500,500,260,240\n"
TUM = b"# t tx ty tz qx qy qz qw\n" + b"".join(
    f"{0.1 * i:.2f} {0.01 * i:.3f} {0.02 * i:.3f} 0.5 0 0 0 1\n".encode() for i in range(12))

#: (reader, suffix, seed bytes)
READERS = {
    "profile-csv": (read_profiles, ".csv", b"x,z\n" + b"".join(f"{i},{400 + i % 7}\n".encode() for i in range(40))),
    "profile-npy": (read_profiles, ".npy", _npy_bytes()),
    "profile-npz": (read_profiles, ".npz", _npz_bytes()),
    "gauge-yaml": (load_gauge, ".yaml", bundled_gauge_path("demo-5").read_bytes()),
    "seam-config": (load_config, ".yaml", (EXAMPLES / "seam" / "default.yaml").read_bytes()),
    "calibration-json": (load_calibration, ".json", CAL_JSON),
    "points-csv": (read_points_csv, ".csv", POINTS_CSV),
    "tum": (read_tum, ".txt", TUM),
    "urdf": (load_urdf, ".urdf", bundled_robot_path("ur10").read_bytes()),
}


@st.composite
def mutated(draw, seed: bytes):
    data = bytearray(seed)
    for _ in range(draw(st.integers(1, 6))):
        kind = draw(st.sampled_from(["flip", "truncate", "insert", "delete", "duplicate", "random"]))
        if not data:
            data = bytearray(draw(st.binary(max_size=64)))
            continue
        i = draw(st.integers(0, len(data) - 1))
        if kind == "flip":
            data[i] = draw(st.integers(0, 255))
        elif kind == "truncate":
            del data[i:]
        elif kind == "insert":
            data[i:i] = draw(st.sampled_from([b"\x00", b"\n", b"[", b"{", b"nan", b"1e309", b"-", b"\xff\xfe",
                                              b"9" * 40, b"&", b"<", b'"', b",", b":", b"  "]))
        elif kind == "delete":
            del data[i:i + draw(st.integers(1, 20))]
        elif kind == "duplicate":
            j = draw(st.integers(i, min(len(data), i + 200)))
            data[j:j] = data[i:j] * draw(st.integers(1, 3))
        else:
            return draw(st.binary(max_size=512))
    return bytes(data)


def _check(reader, suffix: str, data: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"input{suffix}"
        path.write_bytes(data)
        try:
            reader(path)
        except PosekitError as exc:
            msg = str(exc)
            assert msg and "\n" not in msg and len(msg) < 600, msg
            assert str(path) in msg or "input" in msg or msg.startswith(("unknown", "config")), msg


@pytest.mark.parametrize("name", READERS)
def test_reader_survives_mutations(name):
    reader, suffix, seed = READERS[name]
    reader_check = _check  # keep hypothesis' closure small

    @FUZZ
    @given(data=mutated(seed))
    def run(data):
        reader_check(reader, suffix, data)

    run()


@FUZZ
@given(st.recursive(st.none() | st.booleans() | st.integers(-10**40, 10**40) | st.floats() | st.text(max_size=8),
                    lambda c: st.lists(c, max_size=4) | st.dictionaries(st.sampled_from(
                        ["seed", "trajectory", "robot", "filter", "sensors", "process", "steps", "particles",
                         "kind", "model", "urdf", "noise_mm", "count", "force_n"]), c, max_size=4),
                    max_leaves=12))
def test_seam_config_model_survives_any_document(doc):
    try:
        config_from_dict(doc, "fuzz")
    except PosekitError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("fuzz")

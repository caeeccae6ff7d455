"""The fuzz corpus of issue 28: mutated inputs for every reader, generated from a seed.

Each reader has one or more valid seed inputs (tests/fuzz/seeds/, examples/, or text written
here). Case ``k`` of reader ``name`` is the seed input mutated by
``numpy.random.default_rng([SEED, reader_index, k])``: byte flips, truncations, deletions,
duplications (a line 1,000 times, a block up to 4 times), insertions of hostile tokens (NaN,
1e309, 40-digit numbers, NUL, BOMs, YAML tags and aliases, XML entities, Unicode digits, a
megabyte of one byte), numbers replaced by extremes, and splices of another seed — one to six
of them per case. Nothing of the corpus is stored: the same seed gives the same 10,000 inputs.

:func:`run_case` writes the input under the name the reader expects, calls the reader and says
what happened: ``ok`` (it read), ``error`` (a one-line :class:`~posekit.errors.PosekitError` of
at most 300 characters), ``crash`` (any other exception, or a message that is not one line),
``slow`` (more than :data:`SLOW_S`) or ``hang`` (stopped by the alarm after :data:`HANG_S`).
"""

import os
import re
import shutil
import signal
import tempfile
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from posekit.errors import MAX_MESSAGE, PosekitError

__all__ = ["readers", "mutate", "case_input", "run_case", "run_corpus", "summary", "Outcome"]

ROOT = Path(__file__).resolve().parents[2]
SEEDS = Path(__file__).resolve().parent / "seeds"
EXAMPLES = ROOT / "examples"
SEED = 28
#: A case slower than this is reported (none is expected: every input is small).
SLOW_S = 5.0
#: A case still running after this is stopped and counted as a hang.
HANG_S = 30.0

TOKENS = [b"\x00", b"\n", b"\r\n", b"[", b"{", b"]", b"}", b"nan", b"NaN", b"inf", b"-inf", b"1e309", b"-1e309",
          b"9" * 40, b"-", b"+", b".", b",", b":", b";", b"#", b"&a ", b"*a", b"<<: *a", b"!!int ", b"!!float ",
          b"!!binary ", b"!!python/object:os.system ", b"!custom ", b"<", b">", b"</", b'"', b"'", b"\\",
          b"\xff\xfe", b"\xef\xbb\xbf", b"\xfe\xff", b"\x80", b"\xc3\x28", "\u0661\u0662".encode(),
          "\uff15".encode(), b"1_000", b"true", b"null", b"0x1F", b"1e-320", b"-0", b"  ", b"\t", b"\x1b[2J",
          b"<!ENTITY x SYSTEM 'file:///etc/passwd'>", b"&x;", b"${x}", b"PKPF", b"\x93NUMPY", b"PK\x03\x04",
          b"\x89PNG\r\n\x1a\n", b"A" * 1000]
EXTREMES = [b"1e308", b"-1e308", b"nan", b"inf", b"0", b"-1", b"1e-320", b"99999999999999999999", b"2147483648",
            b"4294967296", b"-0", b"1.5", b"true", "\u0661".encode(), b"1_0", b"", b"1e6", b"-1e6", b"65535"]
_NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


# --------------------------------------------------------------------------- seed inputs


def _text_seeds() -> dict:
    """The text seed inputs written here (name -> bytes)."""
    tum = b"# t tx ty tz qx qy qz qw\n" + b"".join(      # a helix: a 3D path, a rotation about z
        f"{0.1 * i:.2f} {np.cos(0.4 * i):.4f} {np.sin(0.4 * i):.4f} {0.05 * i:.3f} 0 0 {np.sin(0.2 * i):.5f} "
        f"{np.cos(0.2 * i):.5f}\n".encode() for i in range(20))
    kitti = b"".join(f"1 0 0 {0.01 * i:.3f} 0 1 0 {0.02 * i:.3f} 0 0 1 0.5\n".encode() for i in range(15))
    euroc = b"#timestamp, p_x, p_y, p_z, q_w, q_x, q_y, q_z\n" + b"".join(
        f"{1403636579758555392 + i * 5000000},{0.01 * i:.3f},{0.02 * i:.3f},0.5,1,0,0,0\n".encode() for i in range(15))
    cal = (b'{"H_image_world": [[0.5, 0.01, 10], [0.0, 0.48, 12], [0, 0, 1]], "H_world_image": [[2.0, -0.04166667, '
           b'-19.5], [0.0, 2.08333333, -25.0], [0, 0, 1]], "rms_px": 0.1, "rms_world": 0.2, "n_points": 5}')
    camera = (b'{"K": [[520.0, 0.0, 320.0], [0.0, 518.0, 240.0], [0.0, 0.0, 1.0]], "dist": [-0.21, 0.05, 0.001, '
              b'-0.0005, 0.0], "image_size": [640, 480], "rms_px": 0.21}')
    points = b"X,Y,u,v\n0,0,10,10\n1000,0,500,12\n1000,1000,510,480\n0,1000,8,470\n500,500,260,240\n250,750,130,360\n"
    profile_csv = b"x,z\n" + b"".join(f"{-40 + 0.5 * i:.2f},{400 + (i % 17) * 0.3:.3f}\n".encode()
                                      for i in range(160)) + b",\nnan,nan\n"
    scene = b"dist: [-0.2, 0.05, 0, 0, 0]\nbloom: 0.5\noccluders: 1\nstray_lights: 2\nnoise_std: 2.0\n"
    return {"tum": tum, "kitti": kitti, "euroc": euroc, "cal": cal, "camera": camera, "points": points,
            "profile_csv": profile_csv, "scene": scene, "token": b"correct horse battery staple\n"}


def _episode_seed() -> dict:
    """A recorded seam episode of 12 steps (file name -> bytes), made by posekit's writer."""
    from posekit.seam.frontend.config import config_from_dict
    from posekit.seam.frontend.logs import write_episode_log
    from posekit.seam.frontend.simulate import simulate_data

    cfg = config_from_dict({"trajectory": {"steps": 12}, "filter": {"particles": 20}})
    with tempfile.TemporaryDirectory() as tmp:
        write_episode_log(Path(tmp), cfg, simulate_data(cfg, 1), 1)
        return {p.name: p.read_bytes() for p in Path(tmp).iterdir() if p.name != "truth.csv"}


# --------------------------------------------------------------------------- readers


def _scene(path):
    """``posekit ceiling simulate --config PATH``'s scene settings (the parser's defaults), not the render."""
    from posekit.ceiling.sim.simulation import scene_config
    from posekit.cli.ceiling_simulate import simulate_options
    from posekit.cli.main import build_parser

    args = build_parser().parse_args(["ceiling", "simulate", "--config", str(path), "--out", str(path) + ".out"])
    options = simulate_options(args)
    options.pop("frames_png")
    return scene_config(**{**options, "dots": "red,green"})


def _consumers():
    """Readers followed by what the CLI does next with what they read (estimate, match, kinematics,
    undistort, map): an input that reads must not crash the step after it either."""
    from posekit.ceiling.camera import load_camera
    from posekit.ceiling.camera.homography import load_calibration
    from posekit.geometry import apply_homography
    from posekit.localcal.registration.formats.tum import read_tum
    from posekit.localcal.registration.match import match_trajectories
    from posekit.profiler import bundled_gauge, estimate_pose, estimate_profiles, nominal_pose, render_profiles
    from posekit.profiler.gauge.model import load_gauge
    from posekit.profiler.stream.reading import read_profile_file
    from posekit.robots import load_urdf

    d5 = bundled_gauge("demo-5")
    profile = render_profiles(d5, nominal_pose(d5), rng=0)
    grid = np.stack(np.meshgrid(np.linspace(0, 640, 9), np.linspace(0, 480, 7)), -1).reshape(-1, 2)
    with tempfile.TemporaryDirectory() as tmp:
        ref_path = Path(tmp) / "ref.tum"
        ref_path.write_bytes(_text_seeds()["tum"])
        reference = read_tum(ref_path)

    def profiles(p):
        data = read_profile_file(p)
        return estimate_profiles(data if data.ndim == 3 else data[None], d5)

    def gauge(p):
        return estimate_pose(profile, load_gauge(p, mounting="normal"))

    def match(p):
        return match_trajectories(read_tum(p), reference)

    def urdf(p):
        chain = load_urdf(p)
        q = np.zeros(chain.n_joints)
        return chain.forward_kinematics(q), chain.geometric_jacobian(q)

    return {"profiles": profiles, "gauge": gauge, "match": match, "urdf": urdf,
            "camera": lambda p: load_camera(p).undistort_points(grid),
            "calibration": lambda p: apply_homography(load_calibration(p).H_world_image, grid, invalid="nan")}


def _readers() -> dict:
    """name -> (reader(path), file name or folder layout, list of seed inputs)."""
    from posekit.ceiling.camera import load_camera
    from posekit.ceiling.camera.homography import load_calibration
    from posekit.ceiling.camera.points import read_points_csv
    from posekit.ceiling.track.sources import open_frames
    from posekit.io import read_image
    from posekit.localcal.registration.formats import read_euroc, read_kitti, read_rosbag, read_tum
    from posekit.profiler.gauge.model import load_gauge
    from posekit.profiler.stream.reading import read_profile_file
    from posekit.profiler.stream.server_support import read_token_file
    from posekit.robots import load_urdf
    from posekit.seam import load_config
    from posekit.seam.frontend.logs import read_episode_log
    from posekit.seam.frontend.profile import load_profile

    t = _text_seeds()
    gauges = [(EXAMPLES / "gauges" / f"demo-{n}.yaml").read_bytes() for n in (4, 5, 7, 10)]
    # the example configurations that stand alone (the others name a profile file beside them), and the profiles
    seam_yaml = sorted((EXAMPLES / "seam").glob("*.yaml"))
    seam_profiles = [p.read_bytes() for p in seam_yaml if p.name.endswith("-profile.yaml")]
    seam_cfgs = [p.read_bytes() for p in seam_yaml
                 if not p.name.endswith("-profile.yaml") and b"-profile.yaml" not in p.read_bytes()]
    urdfs = [p.read_bytes() for p in sorted((EXAMPLES / "robots").glob("*.urdf"))]
    seed = {p.name: p.read_bytes() for p in SEEDS.iterdir()}
    episode = _episode_seed()
    bag_meta = seed["bag2_metadata.yaml"]
    use = _consumers()
    return {
        "profile-csv+estimate": (use["profiles"], "profile.csv", [t["profile_csv"]]),
        "profile-npy+estimate": (use["profiles"], "profile.npy", [seed["profile.npy"]]),
        "profile-npz+estimate": (use["profiles"], "profiles.npz", [seed["profiles.npz"]]),
        "gauge+estimate": (use["gauge"], "gauge.yaml", gauges[1:2]),          # demo-5, whose profile it reads
        "tum+match": (use["match"], "poses.tum", [t["tum"]]),
        "urdf+kinematics": (use["urdf"], "robot.urdf", urdfs),
        "camera-json+undistort": (use["camera"], "camera.json", [t["camera"]]),
        "calibration-json+map": (use["calibration"], "cal.json", [t["cal"]]),
        "profile-csv": (read_profile_file, "profile.csv", [t["profile_csv"]]),
        "profile-npy": (read_profile_file, "profile.npy", [seed["profile.npy"]]),
        "profile-npz": (read_profile_file, "profiles.npz", [seed["profiles.npz"]]),
        "profile-npz-member+estimate": (use["profiles"], ("npz", "profiles.npz"), [_npz_member(seed["profiles.npz"])]),
        "gauge": (load_gauge, "gauge.yaml", gauges),
        "seam-config": (load_config, "seam.yaml", seam_cfgs),
        "seam-profile": (load_profile, "profile.yaml", seam_profiles),
        "seam-episode-setup": (read_episode_log, ("ep", "setup.yaml", episode), [episode["setup.yaml"]]),
        "seam-episode-log": (read_episode_log, ("ep", "log.csv", episode), [episode["log.csv"]]),
        "seam-episode-seam": (read_episode_log, ("ep", "seam.csv", episode), [episode["seam.csv"]]),
        "ceiling-scene": (_scene, "scene.yaml", [t["scene"]]),
        "calibration-json": (load_calibration, "cal.json", [t["cal"]]),
        "camera-json": (load_camera, "camera.json", [t["camera"]]),
        "points-csv": (read_points_csv, "points.csv", [t["points"]]),
        "tum": (read_tum, "poses.tum", [t["tum"]]),
        "kitti": (lambda p: read_kitti(p, 10.0), "poses.txt", [t["kitti"]]),
        "euroc": (read_euroc, "poses.csv", [t["euroc"]]),
        "bag-ros1": (read_rosbag, "pose.bag", [seed["pose.bag"]]),
        "bag-db3": (read_rosbag, "pose.db3", [seed["pose.db3"]]),
        "bag-mcap": (read_rosbag, "pose.mcap", [seed["pose.mcap"]]),
        "bag-folder": (read_rosbag, ("bag", "metadata.yaml", {"sqlite3.db3": seed["pose.db3"]}), [bag_meta]),
        "urdf": (load_urdf, "robot.urdf", urdfs),
        "image-png": (read_image, "frame.png", [seed["frame.png"]]),
        "image-jpg": (read_image, "frame.jpg", [seed["frame.jpg"]]),
        "video": (lambda p: sum(1 for _ in open_frames(p)), "video.avi", [seed["video.avi"]]),
        "token": (read_token_file, "token.txt", [t["token"]]),
    }


def _npz_member(data: bytes) -> bytes:
    import io
    import zipfile

    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        return zf.read("profiles.npy")


_CACHE: dict = {}


def readers() -> dict:
    """The registry of :func:`_readers`, built once."""
    if not _CACHE:
        _CACHE.update(_readers())
    return _CACHE


# --------------------------------------------------------------------------- mutations


def mutate(data: bytes, rng: np.random.Generator, others=()) -> bytes:
    """One to six random mutations of ``data`` (``others``: inputs to splice from)."""
    data = bytearray(data)
    for _ in range(int(rng.choice([1, 1, 1, 2, 2, 3, 4, 6]))):      # mostly one: deep into the valid structure
        n = len(data)
        kind = rng.choice(["flip", "byte", "truncate", "delete", "duplicate", "lines", "insert", "number",
                           "splice", "zeros"], p=[.14, .1, .08, .1, .08, .06, .2, .16, .04, .04])
        if n == 0:
            data = bytearray(rng.integers(0, 256, int(rng.integers(0, 64)), dtype=np.uint8).tobytes())
            continue
        i = int(rng.integers(0, n))
        if kind == "flip":
            data[i] ^= 1 << int(rng.integers(0, 8))
        elif kind == "byte":
            data[i] = int(rng.choice([0, 0xFF, 0x7F, 0x80, 0x20, 0x0A, 0x2D, 0x39]))
        elif kind == "truncate":
            del data[i:]
        elif kind == "delete":
            del data[i:i + int(rng.integers(1, 64))]
        elif kind == "duplicate":
            j = min(n, i + int(rng.integers(1, 512)))
            data[j:j] = data[i:j] * int(rng.integers(1, 5))
        elif kind == "lines":                       # one line many times: counts and sizes
            lines = bytes(data).split(b"\n")
            k = int(rng.integers(0, len(lines)))
            lines[k:k + 1] = [lines[k]] * int(rng.choice([10, 100, 1000]))
            data = bytearray(b"\n".join(lines))
        elif kind == "insert":
            tok = TOKENS[int(rng.integers(0, len(TOKENS)))]
            if rng.random() < 0.02:
                tok = tok * 1000
            data[i:i] = tok
        elif kind == "number":
            nums = list(_NUMBER.finditer(bytes(data)))
            if nums:
                m = nums[int(rng.integers(0, len(nums)))]
                data[m.start():m.end()] = EXTREMES[int(rng.integers(0, len(EXTREMES)))]
        elif kind == "splice" and others:
            other = others[int(rng.integers(0, len(others)))]
            j = int(rng.integers(0, len(other) + 1))
            data = data[:i] + bytearray(other[j:])
        elif kind == "zeros":
            data[i:i + 8] = bytes(8)
    return bytes(data)


def case_input(name: str, k: int) -> bytes:
    """The mutated input of case ``k`` of reader ``name`` (deterministic)."""
    names = sorted(readers())
    _, _, seeds = readers()[name]
    rng = np.random.default_rng([SEED, names.index(name), k])
    base = seeds[int(rng.integers(0, len(seeds)))]
    others = [s for r in readers().values() for s in r[2]]
    return mutate(base, rng, others)


# --------------------------------------------------------------------------- running a case


@dataclass
class Outcome:
    reader: str
    case: int
    kind: str            # ok, error, crash, slow, hang
    seconds: float
    detail: str = ""


class _Hang(BaseException):
    pass


def _alarm(signum, frame):
    raise _Hang


def _place(tmp: Path, layout, data: bytes) -> Path:
    """Write ``data`` where the reader looks for it; the path to give the reader."""
    if isinstance(layout, str):
        path = tmp / layout
        path.write_bytes(data)
        return path
    if layout[0] == "npz":                     # the mutated bytes are the archive's member, zipped intact
        import zipfile

        path = tmp / layout[1]
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("profiles.npy", data)
        return path
    folder, name, rest = layout
    path = tmp / folder
    path.mkdir()
    for other, content in rest.items():
        (path / other).write_bytes(content)
    (path / name).write_bytes(data)
    return path


def run_case(name: str, k: int, data: bytes | None = None) -> Outcome:
    """Run case ``k`` of reader ``name`` (or ``data`` instead of its mutated input)."""
    reader, layout, _ = readers()[name]
    data = case_input(name, k) if data is None else data
    old = signal.signal(signal.SIGALRM, _alarm)
    tmp = Path(tempfile.mkdtemp(prefix="posekit-fuzz-"))
    t0 = time.perf_counter()
    try:
        path = _place(tmp, layout, data)
        signal.setitimer(signal.ITIMER_REAL, HANG_S)
        try:
            reader(path)
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
        kind, detail = "ok", ""
    except _Hang:
        kind, detail = "hang", f"stopped after {HANG_S:g} s"
    except PosekitError as exc:
        msg = str(exc)
        if "\n" in msg or len(msg) > MAX_MESSAGE or not msg:
            kind, detail = "crash", f"message not one line of <= {MAX_MESSAGE} characters: {msg[:400]!r}"
        else:
            kind, detail = "error", msg
    except Exception as exc:  # noqa: BLE001 -- that is what the corpus looks for
        tb = traceback.extract_tb(exc.__traceback__)
        where = "; ".join(f"{Path(f.filename).name}:{f.lineno}" for f in tb[-3:])
        kind, detail = "crash", f"{type(exc).__name__}: {str(exc)[:200]} ({where})"
    finally:
        signal.signal(signal.SIGALRM, old)
        shutil.rmtree(tmp, ignore_errors=True)
    seconds = time.perf_counter() - t0
    if kind in ("ok", "error") and seconds > SLOW_S:
        kind, detail = "slow", f"{seconds:.1f} s; {detail}"
    return Outcome(name, k, kind, seconds, detail)


def check_seeds() -> list[str]:
    """The readers whose unmutated seed inputs do not read (the corpus starts from valid inputs)."""
    bad = []
    for name, (_, _, seeds) in sorted(readers().items()):
        for k, data in enumerate(seeds):
            o = run_case(name, -1 - k, data)
            if o.kind != "ok":
                bad.append(f"{name} seed {k}: {o.kind}: {o.detail}")
    return bad


def run_corpus(count_per_reader: int, start: int = 0, names=None, progress=None) -> list[Outcome]:
    """Cases ``start .. start + count_per_reader - 1`` of every reader (or of ``names``)."""
    out = []
    for name in sorted(names or readers()):
        for k in range(start, start + count_per_reader):
            out.append(run_case(name, k))
            if progress is not None:
                progress(out[-1])
    return out


def summary(outcomes) -> str:
    """Per reader: cases, read, one-line errors, crashes, slow, hangs, and the slowest case."""
    rows = {}
    for o in outcomes:
        r = rows.setdefault(o.reader, {"ok": 0, "error": 0, "crash": 0, "slow": 0, "hang": 0, "n": 0, "max": 0.0})
        r[o.kind] += 1
        r["n"] += 1
        r["max"] = max(r["max"], o.seconds)
    lines = [f"{'reader':20s} {'cases':>6s} {'read':>6s} {'error':>6s} {'crash':>6s} {'slow':>5s} {'hang':>5s} "
             f"{'max s':>6s}"]
    for name, r in sorted(rows.items()):
        lines.append(f"{name:20s} {r['n']:6d} {r['ok']:6d} {r['error']:6d} {r['crash']:6d} {r['slow']:5d} "
                     f"{r['hang']:5d} {r['max']:6.2f}")
    return "\n".join(lines)


def main(argv=None) -> int:
    """``python -m tests.fuzz.corpus [COUNT_PER_READER] [START] [READER ...]``: run and summarise."""
    import sys

    argv = sys.argv[1:] if argv is None else argv
    count = int(argv[0]) if argv else 20
    start = int(argv[1]) if len(argv) > 1 else 0
    names = argv[2:] or None
    bad = []

    def show(o):
        if o.kind not in ("ok", "error"):
            bad.append(o)
            print(f"{o.kind}: {o.reader} case {o.case} ({o.seconds:.1f} s): {o.detail}", flush=True)

    outcomes = run_corpus(count, start, names, show)
    print(summary(outcomes))
    print(f"{len(outcomes)} cases, {len(bad)} crashes/slow/hangs")
    return 1 if bad else 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONWARNINGS", "ignore")
    raise SystemExit(main())


"""End to end on loopback: ``posekit profiler simulate`` -> ``replay`` -> ``serve`` -> records files,
checked against ``truth.csv``; the controller's commands, the pose filter, bad flags, in-process frames.

Every run is bounded: the server stops after ``--count`` frames (``--duration-s`` caps it), the
replay waits at most ``--wait-s`` for the server to listen, every socket is on 127.0.0.1.
"""

import csv
import json
import socket
import threading

import numpy as np
import pytest

from posekit.cli.main import main
from posekit.errors import ConfigError
from posekit.geometry import matrix_from_quaternion, rotation_vector_from_matrix
from posekit.profiler import NoiseModel, bundled_gauge, nominal_pose, render_profiles
from posekit.profiler.sim.simulate import read_truth_csv
from posekit.profiler.stream.pose_filter import ConstantVelocityFilter
from posekit.profiler.stream.server import PoseServer
from posekit.profiler.stream.server_records import SERVE_CSV_COLUMNS

CAP_S = "60"              # --duration-s of every server: an upper bound, the runs end by --count


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _serve(argv):
    """Run ``posekit profiler serve`` in a thread; returns (thread, result dict with 'rc')."""
    result = {}

    def target():
        result["rc"] = main(["profiler", "serve", "--gauge", "demo-5", "--duration-s", CAP_S, "--status-every-s", "30",
                             "--queue", "256", *map(str, argv)])

    t = threading.Thread(target=target, daemon=True)
    t.start()
    return t, result


def _simulate(tmp_path, name, *flags):
    out = tmp_path / name
    assert main(["profiler", "simulate", "--gauge", "demo-5", "--out", str(out), *map(str, flags)]) == 0
    return out


def _rot_err(q_wxyz, R_true):
    """Rotation vector of R R_trueᵀ (rad, in G), shape (K, 3)."""
    R = matrix_from_quaternion(np.asarray(q_wxyz, dtype=float))
    return rotation_vector_from_matrix(R @ np.swapaxes(R_true, -1, -2))


def test_replay_to_serve_with_the_controller_token_and_records(tmp_path, capsys):
    sim = _simulate(tmp_path, "sim", "--count", 20, "--seed", 2)
    (tmp_path / "token").write_text("correct horse\n")
    (tmp_path / "wrong").write_text("battery staple\n")
    port = _free_port()
    out_csv = tmp_path / "records.csv"
    thread, result = _serve(["--listen", f"127.0.0.1:{port}", "--count", 40, "--out", out_csv, "--jsonl", "-",
                             "--controller", "pd", "--token-file", tmp_path / "token"])
    replay = ["profiler", "replay", str(sim / "profiles.npz"), "--to", f"127.0.0.1:{port}", "--rate-hz", "300",
              "--wait-s", "30"]
    # A sensor with the wrong token: refused at once, and told so.
    assert main([*replay, "--token-file", str(tmp_path / "wrong")]) == 1
    err = capsys.readouterr().err
    assert err.endswith(f"posekit: error: --to 127.0.0.1:{port}: the server closed the connection at once: it wants "
                        "a token and this one (--token-file) is wrong or missing\n")
    # The right one: 40 frames, cycling through the 20 profiles.
    assert main([*replay, "--token-file", str(tmp_path / "token"), "--count", "40"]) == 0
    thread.join(30.0)
    assert not thread.is_alive() and result["rc"] == 0
    out, err = capsys.readouterr()
    assert f"replayed 40 frames of {sim / 'profiles.npz'} (20 profiles, 3200 points) to 127.0.0.1:{port}" in out
    assert "processed 40 (ok 40, errors 0)" in err and "refused 1" in err    # status lines on stderr
    assert "records: 40 written to" in err

    # --jsonl -: one JSON record per line on stdout, nothing else there but the replay's line.
    lines = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    assert [r["seq"] for r in lines] == list(range(40))
    for r in lines:
        cmd = r["command"]
        assert r["status"] == "ok" and cmd is not None
        assert len(cmd["command_mm"]) == 3 and all(np.isfinite(cmd["command_mm"]))
        # The PD (clipped at 2 mm) works against the measured displacement from the target.
        assert all(abs(c) <= 2.0 + 1e-9 for c in cmd["command_mm"])
        assert r["filter"] is None

    # --out records.csv against truth.csv.
    with open(out_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == SERVE_CSV_COLUMNS and len(rows) == 40
    idx, t_true, q_true = read_truth_csv(sim / "truth.csv")
    seq = np.array([int(r["seq"]) for r in rows])
    assert seq.tolist() == list(range(40)) and all(r["status"] == "ok" for r in rows)
    k = seq % 20
    t = np.array([[float(r[c]) for c in ("tx", "ty", "tz")] for r in rows])
    std_t = np.array([[float(r[f"std_t{a}_um"]) for a in "xyz"] for r in rows]) * 1e-3
    err_t = t - t_true[k]
    assert np.all(np.abs(err_t) <= 5 * std_t + 2e-3), np.abs(err_t / std_t).max(axis=0)   # float32 on the wire
    assert np.abs(err_t[:, [0, 2]]).max() < 0.1 and np.abs(err_t[:, 1]).max() < 1.5          # mm
    q = np.array([[float(r[c]) for c in ("qw", "qx", "qy", "qz")] for r in rows])
    err_r = np.degrees(np.linalg.norm(_rot_err(q, matrix_from_quaternion(q_true[k])), axis=1))
    assert err_r.max() < 0.1                                                              # degrees
    # The same profile gives the same pose (to the warm start's convergence: µm in the weak y).
    np.testing.assert_allclose(t[20:], t[:20], atol=0.01)
    cmd = np.array([[float(r[f"cmd_{a}_mm"]) for a in "xyz"] for r in rows])
    assert np.all(np.isfinite(cmd)) and np.abs(cmd).max() > 0.1  # random poses: the controller acts
    assert all(r["PC_ms"] and float(r["PC_ms"]) > 0 for r in rows)


def test_filter_on_a_static_pose_through_the_stream(tmp_path, capsys):
    sim = _simulate(tmp_path, "static", "--count", 200, "--seed", 4, "--translation-mm", "0,0,0",
                    "--rotation-deg", "0,0,0")
    port = _free_port()
    out = tmp_path / "rec.jsonl"
    thread, result = _serve(["--listen", f"127.0.0.1:{port}", "--count", 200, "--jsonl", out, "--filter", "cv"])
    assert main(["profiler", "replay", str(sim / "profiles.npz"), "--to", f"127.0.0.1:{port}", "--rate-hz", "500",
                 "--wait-s", "30"]) == 0
    thread.join(30.0)
    assert not thread.is_alive() and result["rc"] == 0
    capsys.readouterr()
    recs = [json.loads(line) for line in out.read_text().splitlines()]
    assert [r["seq"] for r in recs] == list(range(200)) and all(r["status"] == "ok" for r in recs)
    _, t_true, q_true = read_truth_csv(sim / "truth.csv")
    R_true = matrix_from_quaternion(q_true[0])
    settled = recs[60:]
    raw_y = np.array([r["t_mm"][1] for r in settled]) - t_true[0, 1]
    f_y = np.array([r["filter"]["t_mm"][1] for r in settled]) - t_true[0, 1]
    raw_rx = _rot_err([r["q_wxyz"] for r in settled], R_true)[:, 0]
    f_rx = _rot_err([r["filter"]["q_wxyz"] for r in settled], R_true)[:, 0]
    assert raw_y.var() / f_y.var() > 4.0, (raw_y.std(), f_y.std())
    assert raw_rx.var() / f_rx.var() > 4.0, (raw_rx.std(), f_rx.std())
    f_std_y = np.array([r["filter"]["std_t_um"][1] for r in settled]) * 1e-3
    assert np.mean(np.abs(f_y) <= 2 * f_std_y) > 0.85                 # its covariance is honest
    cov = np.array(settled[-1]["filter"]["cov"])
    assert cov.shape == (6, 6) and cov[1, 3] < 0                      # y and rx: the anti-correlated pair
    assert {r["filter"]["status"] for r in recs} == {"init", "ok"}
    assert all(r["command"] is None for r in recs)                    # no --controller


@pytest.mark.parametrize("flags, message", [
    (["--kp", "-0.3"], "--kp needs --controller pd"),
    (["--controller", "pd", "--kp", "1,2"], "--kp: expected one number or three comma-separated numbers X,Y,Z, "
                                            "got '1,2'"),
    (["--target-mm", "0,0,400"], "--target-mm needs --controller pd (or open)"),
    (["--controller", "pd", "--target-q-wxyz", "2,0,0,0"],
     "--target-q-wxyz: expected a unit quaternion W,X,Y,Z, got '2,0,0,0' (norm 2)"),
    (["--controller", "pd", "--limit-mm", "0"], "--limit-mm: expected a number > 0 and <= 100 mm, got 0"),
    (["--filter-window", "5"], "--filter-window needs --filter window"),
    (["--filter", "cv", "--method", "cf"],
     "--filter cv needs --method mle (the closed form 'cf' gives no covariance to filter with)"),
    (["--filter", "window", "--filter-window", "0"], "--filter-window: expected an integer in 1..10000 estimates, "
                                                     "got 0"),
    (["--count", "0"], "--count: expected an integer in 1..1000000000 frames, got 0"),
])
def test_serve_bad_flags_are_one_line_errors(capsys, flags, message):
    rc = main(["profiler", "serve", "--gauge", "demo-5", "--listen", "127.0.0.1:0", *flags])
    out, err = capsys.readouterr()
    assert (rc, out, err) == (1, "", f"posekit: error: {message}\n")


def test_serve_bad_out_leaves_nothing(capsys, tmp_path):
    rc = main(["profiler", "serve", "--gauge", "demo-5", "--listen", "127.0.0.1:0", "--out", str(tmp_path / "r.txt")])
    assert (rc, capsys.readouterr().err) == (1, f"posekit: error: --out {tmp_path / 'r.txt'}: unknown suffix '.txt'; "
                                                "expected FILE.jsonl (JSON lines) or FILE.csv\n")
    # A server that cannot start (port taken) removes its half-begun --out file.
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        rc = main(["profiler", "serve", "--gauge", "demo-5", "--listen", f"127.0.0.1:{port}",
                   "--out", str(tmp_path / "r.csv"), "--jsonl", str(tmp_path / "r.jsonl")])
    assert rc == 1 and "cannot bind" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("flags, message", [
    (["--to", "localhost"], "--to 'localhost': expected HOST:PORT, e.g. 127.0.0.1:5000"),
    (["--to", "127.0.0.1:0"], "--to '127.0.0.1:0': expected the server's port, 1..65535, got 0"),
    (["--to", "127.0.0.1:9", "--rate-hz", "0"], "--rate-hz: expected a number in 0.01..20000 Hz, got 0"),
    (["--to", "127.0.0.1:9", "--count", "0"], "--count: expected an integer in 1..1000000000 frames, got 0"),
    (["--to", "127.0.0.1:9", "--roi-x", "3:1"], "--roi-x: expected A:B in mm with A < B (e.g. -40:40), got '3:1'"),
])
def test_replay_bad_flags_are_one_line_errors(capsys, tmp_path, flags, message):
    np.save(tmp_path / "p.npy", np.zeros((10, 2)))
    rc = main(["profiler", "replay", str(tmp_path / "p.npy"), *flags])
    out, err = capsys.readouterr()
    assert (rc, out, err) == (1, "", f"posekit: error: {message}\n")


def test_replay_without_a_server(capsys, tmp_path):
    gauge = bundled_gauge("demo-5")
    np.save(tmp_path / "p.npy", render_profiles(gauge, nominal_pose(gauge), rng=0))
    port = _free_port()
    rc = main(["profiler", "replay", str(tmp_path / "p.npy"), "--to", f"127.0.0.1:{port}"])
    err = capsys.readouterr().err
    assert rc == 1 and err.startswith(f"posekit: error: --to 127.0.0.1:{port}: cannot connect (")
    assert err.endswith("); is 'posekit profiler serve' listening there?\n") and err.count("\n") == 1


class _Collect:
    """A record sink that keeps the records (PoseServer's record_sink interface)."""

    def __init__(self):
        self.records = []
        self.done = threading.Event()
        self.want = 0

    def put(self, rec):
        self.records.append(rec)
        if len(self.records) >= self.want:
            self.done.set()


def test_submit_in_process_with_filter_and_the_metres_hint():
    gauge = bundled_gauge("demo-5")
    T = nominal_pose(gauge)
    profiles = render_profiles(gauge, np.repeat(T[None], 6, axis=0), NoiseModel(), rng=7)
    sink = _Collect()
    sink.want = 7
    with PoseServer(gauge, pose_filter=ConstantVelocityFilter(), record_sink=sink, freeze_gc=False,
                    queue_size=64) as server:
        seqs = [server.submit(p) for p in profiles]
        seqs.append(server.submit(profiles[0] / 1000.0))               # a profile in metres
        assert sink.done.wait(10.0)
        with pytest.raises(Exception, match=r"expected an \(N, 2\) array"):
            server.submit(np.zeros((3, 3)))
    assert seqs == list(range(7))
    recs = sorted(sink.records, key=lambda r: r["seq"])
    assert all(r["status"] == "ok" and r["filter"] is not None for r in recs[:6])
    assert [r["filter"]["status"] for r in recs[:6]] == ["init"] + ["ok"] * 5
    assert recs[6]["status"] == "error" and recs[6]["filter"] is None
    assert recs[6]["error"].endswith("; the profile looks like metres (every |x|, |z| < 2 and it spans 0.11 x "
                                     "0.011); posekit expects mm (multiply by 1000)")
    with pytest.raises(ConfigError, match="the server is not running"):
        server.submit(profiles[0])


def test_record_sink_files_and_an_error_record(tmp_path):
    from posekit.profiler.stream.server_records import RecordOutput, RecordSink

    err = {"seq": 3, "t_sensor_ns": 10, "status": "error", "t_mm": None, "q_wxyz": None, "std_t_um": None,
           "std_rot_deg": None, "reprojection_um": None, "reversed": None, "command": None, "filter": None,
           "timing_ms": {"DT": None, "QW": 0.5, "CD": 0.25, "PC": 0.0}, "error": "seq 3: no corners"}
    with RecordSink([RecordOutput(str(tmp_path / "r.csv"), "csv"),
                     RecordOutput(str(tmp_path / "r.jsonl"), "jsonl", stream=True, flag="--jsonl")]) as sink:
        sink.put(err)
        assert not (tmp_path / "r.csv").exists()                       # renamed into place at the end
    assert sink.written == 1 and sink.errors == []
    rows = list(csv.reader(open(tmp_path / "r.csv", newline="")))
    assert rows[0] == SERVE_CSV_COLUMNS
    row = dict(zip(rows[0], rows[1]))
    assert (row["seq"], row["status"], row["error"], row["tx"], row["f_status"], row["cmd_x_mm"]) == \
        ("3", "error", "seq 3: no corners", "", "", "")
    assert (row["DT_ms"], row["QW_ms"], row["CD_ms"], row["PC_ms"]) == ("", "0.5", "0.25", "0.0")
    assert json.loads((tmp_path / "r.jsonl").read_text()) == err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv", "r.jsonl"]     # no temporary left

"""Ceiling and seam: each verb is one library function with the same arguments (same files),
``--config``/``--dump-config`` on the verbs with more than a few parameters (seam's own ``--config``,
the cell's YAML, kept where it was), one spelling per concept (old spellings work, with one note)."""

import dataclasses
import json

import pytest
import yaml

from posekit.ceiling import SceneConfig, plan_track, scene_config, simulate
from posekit.cli.main import main
from posekit.errors import ConfigError
from posekit.seam import demo as seam_demo
from posekit.seam import dump_profile, episode_config, simulate_episodes, track_episode, tune

#: Ceiling and seam verbs with --config/--dump-config: command words and required arguments
#: (test_cli_library.py's test_dump_config_round_trips runs them with the profiler's). Their parameters
#: are their flags, except ceiling simulate's: its file is the scene (SceneConfig keys).
CONFIG_VERBS = {
    "ceiling simulate": (["ceiling", "simulate"], ["--seed", "7", "--duration-s", "2.5", "--frame-rate-hz", "10",
                                                   "--dots", "red,green", "--no-holes", "--realistic",
                                                   "--distortion", "0.1,0,0,0", "--occluders", "0", "--out", "d"]),
    "ceiling track": (["ceiling", "track"], ["v.avi", "--calibration", "a.json", "--input2", "w.avi",
                                             "--calibration", "b.json", "--camera", "lens.json", "--out", "t.csv",
                                             "--frame-rate-hz", "12.5", "--max-frames", "9"]),
    "ceiling demo": (["ceiling", "demo"], ["--dots", "line", "--duration-s", "4", "--seed", "3"]),
    "ceiling calibrate": (["ceiling", "calibrate"], ["p.csv", "--out", "c.json", "--no-ransac", "--no-refine",
                                                     "--grid", "600,600"]),
    "ceiling learn-scene": (["ceiling", "learn-scene"], ["v.avi", "--calibration", "c.json", "--out", "s.json"]),
    "ceiling camera": (["ceiling", "camera"], ["a.png", "b.png", "--board", "9x6", "--square-mm", "25",
                                               "--out", "cam.json", "--k3"]),
    "seam track": (["seam", "track"], ["logs", "--out", "d", "--jsonl", "-"]),
    "seam demo": (["seam", "demo"], ["--steps", "40", "--particles", "20", "--runs", "2"]),
}


def test_repeated_and_either_or_flags_in_a_config(tmp_path, capsys):
    """A repeated flag is a list in the file and the line's list replaces it; --ransac/--no-ransac
    are keyed by their flag (true = given)."""
    main(["ceiling", "track", "v.avi", "--calibration", "a.json", "--input2", "w.avi", "--calibration", "b.json",
          "--out", "t.csv", "--dump-config"])
    p = yaml.safe_load(capsys.readouterr().out)
    assert (p["calibration"], p["input2"], p["camera"]) == (["a.json", "b.json"], ["w.avi"], None)
    (tmp_path / "t.yaml").write_text(yaml.safe_dump(p))
    main(["ceiling", "track", "--config", str(tmp_path / "t.yaml"), "--calibration", "c.json", "--dump-config"])
    assert yaml.safe_load(capsys.readouterr().out)["calibration"] == ["c.json"]
    for flag, ransac, no_ransac in (("--ransac", True, False), ("--no-ransac", False, True), (None, False, False)):
        main(["ceiling", "calibrate", "p.csv", "--out", "c.json", *([flag] if flag else []), "--dump-config"])
        p = yaml.safe_load(capsys.readouterr().out)
        assert (p["ransac"], p["no_ransac"]) == (ransac, no_ransac)


def test_flags_win_over_the_file(tmp_path, capsys):
    (tmp_path / "d.yaml").write_text("steps: 50\nparticles: 30\nseed: 4\n")
    assert main(["seam", "demo", "--config", str(tmp_path / "d.yaml"), "--steps", "60", "--dump-config"]) == 0
    p = yaml.safe_load(capsys.readouterr().out)
    assert (p["steps"], p["particles"], p["seed"], p["runs"]) == (60, 30, 4, 1)


@pytest.mark.parametrize("argv, text, message", [
    (["ceiling", "track", "v.avi", "--calibration", "c.json", "--out", "t.csv"], "fps: 10\n",
     "unknown key 'fps'; expected one of allow_remote, calibration, camera, dots, frame_rate_hz, input, input2, "
     "jsonl, line_method, live, loop, max_frames, max_predict_s, out, robots, scene, udp"),
    (["ceiling", "track", "v.avi", "--calibration", "c.json", "--out", "t.csv"], "frame_rate_hz: 0\n",
     "'frame_rate_hz': expected a number in 0.01..10000 Hz, got 0"),
    (["ceiling", "demo", "--out", "d"], "realistic: yes please\n", "'realistic': expected true or false, got 'yes please'"),
    (["seam", "demo"], "particles: 0\n", "'particles': expected an integer in 1..1000000, got 0"),
    (["seam", "track", "logs", "--out", "d"], "- logs\n",
     "expected a mapping of the command's parameters (key: value), got list"),
])
def test_bad_config_is_one_line_naming_file_and_key(tmp_path, capsys, argv, text, message):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    rc = main([*argv, "--config", str(path)])
    err = capsys.readouterr().err
    assert rc == 1 and err == f"posekit: error: {path}: {message}\n"


@pytest.mark.parametrize("old, new, argv, key, value", [
    ("--fps", "--frame-rate-hz", ["ceiling", "track", "v.avi", "--calibration", "c.json", "--out", "t.csv",
                                  "--fps", "10"], "frame_rate_hz", 10.0),
    ("--fps", "--frame-rate-hz", ["ceiling", "learn-scene", "v.avi", "--calibration", "c.json", "--out", "s.json",
                                  "--fps", "7"], "frame_rate_hz", 7.0),
    ("--seconds", "--duration-s", ["ceiling", "demo", "--seconds", "5"], "duration_s", 5.0),
])
def test_old_spellings_still_work_with_one_note(capsys, old, new, argv, key, value):
    assert main([*argv, "--dump-config"]) == 0
    out, err = capsys.readouterr()
    assert err == f"posekit: note: {old} is deprecated and will be removed; use {new}\n"
    assert yaml.safe_load(out)[key] == value


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A 4-frame realistic ceiling video by the command, with the old spellings of two flags."""
    out = tmp_path_factory.mktemp("ceiling") / "sim"
    assert main(["ceiling", "simulate", "--seed", "5", "--duration-s", "1", "--fps", "4", "--noise-std", "6",
                 "--realistic", "--occluders", "0", "--codec", "mjpg", "--out", str(out)]) == 0
    return out


def test_ceiling_simulate_is_one_library_call(rendered, tmp_path, capsys):
    sim = simulate(tmp_path / "lib", seed=5, duration_s=1, fps=4, noise_grey=6, realistic=True, occluders=0,
                   codec="mjpg")
    assert (sim.config.noise_std, sim.config.fps, sim.config.occluders, sim.paths.n_frames) == (6.0, 4.0, 0, 4)
    for name in ("truth.csv", "calibration_points.csv", "camera.json", "stray_lights.csv", "reference.png",
                 "video.avi"):
        assert (rendered / name).read_bytes() == (tmp_path / "lib" / name).read_bytes(), name


def test_ceiling_simulate_old_spellings_print_one_note_each(tmp_path, capsys):
    assert main(["ceiling", "simulate", "--seed", "5", "--duration-s", "0.5", "--fps", "2", "--noise-std", "6",
                 "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert "posekit: note: --noise-std is deprecated and will be removed; use --noise-grey" in err
    assert "posekit: note: --fps is deprecated and will be removed; use --frame-rate-hz" in err


def test_the_scene_rules_live_in_the_library(tmp_path):
    assert scene_config(dots="red, green").dots == ("red", "green")
    assert scene_config(realistic=True).noise_std == 3.0 and scene_config().noise_std == 2.0
    assert scene_config(distortion=(0.1, 0, 0, 0)).dist == (0.1, 0.0, 0.0, 0.0, 0.0)
    with pytest.raises(ConfigError, match=r"^--duration-s 3600 × --frame-rate-hz 60 = 216000 frames; expected at "
                                          r"most 54000$"):
        scene_config(duration_s=3600, fps=60)
    with pytest.raises(ConfigError, match="^--dots: expected one of red | red,green | red,red | line, got 'blue'$"):
        scene_config(dots="blue")


def test_ceiling_simulate_dump_config_is_the_scene_read_back(rendered, tmp_path, capsys):
    """--dump-config prints every SceneConfig key; --config reads it back to the same scene and the same
    video (the fixture's, rendered from flags)."""
    flags = ["--seed", "5", "--duration-s", "1", "--frame-rate-hz", "4", "--noise-grey", "6", "--realistic",
             "--occluders", "0", "--codec", "mjpg"]
    assert main(["ceiling", "simulate", *flags, "--dump-config"]) == 0
    dumped = capsys.readouterr().out
    path = tmp_path / "scene.yaml"
    path.write_text(dumped)
    assert list(yaml.safe_load(dumped)) == [f.name for f in dataclasses.fields(SceneConfig)]
    expected = scene_config(seed=5, duration_s=1, fps=4, noise_grey=6, realistic=True, occluders=0, codec="mjpg")
    assert scene_config(config=path) == expected
    assert main(["ceiling", "simulate", "--config", str(path), "--out", str(tmp_path / "sim")]) == 0
    for name in ("truth.csv", "calibration_points.csv", "camera.json", "video.avi"):
        assert (tmp_path / "sim" / name).read_bytes() == (rendered / name).read_bytes(), name


def test_ceiling_simulate_flags_win_over_the_file_and_keep_what_they_do_not_give(tmp_path, capsys):
    """A flag not given keeps the file's value (it used to be its argparse default); one given wins."""
    path = tmp_path / "scene.yaml"
    path.write_text("seed: 4\nduration_s: 5\nfps: 10\ndots: red,green\nholes: false\nbloom: 0.5\n")
    assert main(["ceiling", "simulate", "--config", str(path), "--seed", "9", "--frame-rate-hz", "12",
                 "--dump-config"]) == 0
    dumped = capsys.readouterr().out
    p = yaml.safe_load(dumped)
    assert (p["seed"], p["fps"], p["duration_s"], p["dots"], p["holes"], p["bloom"], p["noise_std"]) == (
        9, 12.0, 5, ["red", "green"], False, 0.5, 2.0)
    assert scene_config(config=path, seed=9, fps=12) == SceneConfig(seed=9, fps=12.0, duration_s=5,
                                                                   dots=("red", "green"), holes=False, bloom=0.5)
    (tmp_path / "back.yaml").write_text(dumped)
    assert main(["ceiling", "simulate", "--config", str(tmp_path / "back.yaml"), "--dump-config"]) == 0
    assert capsys.readouterr().out == dumped
    assert main(["ceiling", "simulate", "--config", str(tmp_path / "back.yaml"), "--holes", "--dots", "red",
                 "--dump-config"]) == 0
    p = yaml.safe_load(capsys.readouterr().out)
    assert (p["holes"], p["dots"], p["seed"]) == (True, ["red"], 9)


@pytest.mark.parametrize("text, message", [
    ("duration_s: 0\n", "{path}: duration_s: expected a positive number of seconds, got 0"),
    ("dots: blue\n", "{path}: dots: expected one of red | red,green | red,red | line, got 'blue'"),
    ("duration_s: 3600\nfps: 60\n", "--duration-s 3600 × --frame-rate-hz 60 = 216000 frames; expected at most 54000"),
    ("bloom: lots\n", "{path}: must be real number, not str; expected each setting as in SceneConfig (numbers, "
                      "lists of numbers, names)"),
    ("seeed: 1\n", "{path}: unknown setting 'seeed'; expected keys of SceneConfig (e.g. dist, bloom, occluders, "
                    "stray_lights, codec, focal_px)"),
    ("- 1\n", "{path}: expected a mapping of scene settings (e.g. 'bloom: 1')"),
])
def test_ceiling_simulate_bad_scene_file_is_one_line(tmp_path, capsys, text, message):
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    for extra in (["--out", str(tmp_path / "o")], ["--dump-config"]):
        rc = main(["ceiling", "simulate", "--config", str(path), *extra])
        out, err = capsys.readouterr()
        assert (rc, out, err) == (1, "", f"posekit: error: {message.format(path=path)}\n")
    assert not (tmp_path / "o").exists()
    rc = main(["ceiling", "simulate"])
    assert (rc, capsys.readouterr().err) == (1, "posekit: error: --out: an output folder is required (or use "
                                                "--dump-config)\n")


def test_the_track_rules_live_in_the_library(tmp_path):
    plan = plan_track("v.avi", "c.json", dots="red,red", out=tmp_path / "t.csv")
    assert (plan.robots, plan.dots, plan.inputs) == (2, ("red",), ("v.avi",))
    plan = plan_track("v.avi", ["a.json", "b.json"], input2=["w.avi"], camera=["l.json"], udp="127.0.0.1:9")
    assert (plan.calibrations, plan.camera) == (("a.json", "b.json"), "l.json")
    for kwargs, message in (
            (dict(dots="red,red", robots=3, out="t.csv"), "--dots red,red means two robots; got --robots 3"),
            (dict(calibration=["a", "b"], out="t.csv"), "--calibration given 2 time(s) for 1 input(s); give one "
                                                        "calibration per camera, in the order INPUT, --input2 ..."),
            (dict(), "no output: give --out TRACK.csv, --jsonl FILE|- or --udp HOST:PORT"),
            (dict(robots=2, dots="red,green", out="t.csv"),
             "--robots: several robots are tracked with one red dot each (--dots red) and one camera")):
        args = {"calibration": "c.json", **kwargs}
        with pytest.raises(ConfigError) as exc:
            plan_track("v.avi", args.pop("calibration"), **args)
        assert str(exc.value) == message


def test_ceiling_track_is_one_library_call(rendered, tmp_path, capsys):
    from posekit.ceiling import track_input

    assert main(["ceiling", "calibrate", str(rendered / "calibration_points.csv"), "--camera",
                 str(rendered / "camera.json"), "--out", str(tmp_path / "cal.json")]) == 0
    argv = [str(rendered / "video.avi"), "--calibration", str(tmp_path / "cal.json"), "--camera",
            str(rendered / "camera.json")]
    assert main(["ceiling", "track", *argv, "--out", str(tmp_path / "cli.csv")]) == 0
    run = track_input(rendered / "video.avi", tmp_path / "cal.json", camera=rendered / "camera.json",
                out=tmp_path / "lib.csv")
    assert run.exit_code == 0 and run.frames == 4 and sum(run.counts.values()) == 4
    assert (tmp_path / "cli.csv").read_bytes() == (tmp_path / "lib.csv").read_bytes()


def test_seam_constants_quoted_by_the_parsers_are_the_librarys():
    from posekit.cli import seam_design, seam_simulate, seam_study, seam_tune
    from posekit.seam.frontend import commands, commands_batch

    for name in ("DEMO_STEPS", "DEMO_PARTICLES", "MAX_KEPT_STEPS", "MAX_RECORDED", "RECORD_DEFAULT"):
        assert getattr(seam_simulate, name) == getattr(commands, name), name
    assert seam_study.MAX_STUDY_EPISODES == commands_batch.MAX_STUDY_EPISODES
    assert seam_design.MAX_DESIGN_EPISODES == commands_batch.MAX_DESIGN_EPISODES
    assert seam_tune.MAX_SIMULATED == commands_batch.MAX_SIMULATED


@pytest.fixture(scope="module")
def seam_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("seam")
    assert main(["seam", "simulate", "--steps", "30", "--particles", "30", "--runs", "2", "--seed", "3",
                 "--out", str(root / "sim"), "--save-log", str(root / "log")]) == 0
    return root


def _csv_without_times(path):
    """The rows of a CSV without its measured-time columns (``step_ms``)."""
    import csv

    rows = list(csv.reader(path.open(newline="")))
    keep = [i for i, h in enumerate(rows[0]) if not h.endswith("_ms")]
    return [[r[i] for i in keep] for r in rows]


def _without_times(path):
    m = json.loads(path.read_text())
    return {k: v for k, v in m.items() if "ms" not in k and "wall" not in k and "_s" not in k[-2:]}


def test_seam_simulate_is_one_library_call(seam_run, tmp_path):
    cfg = episode_config(steps=30, particles=30, seed=3)
    sim = simulate_episodes(cfg, tmp_path / "sim", runs=2, save_log=tmp_path / "log")
    assert _without_times(seam_run / "sim" / "metrics.json") == _without_times(tmp_path / "sim" / "metrics.json")
    assert sim.metrics["rmse_mm"] == json.loads((seam_run / "sim" / "metrics.json").read_text())["rmse_mm"]
    assert _csv_without_times(seam_run / "sim" / "estimates.csv") == _csv_without_times(tmp_path / "sim" / "estimates.csv")
    assert (seam_run / "sim" / "config.yaml").read_bytes() == (tmp_path / "sim" / "config.yaml").read_bytes()
    for name in ("setup.yaml", "seam.csv", "log.csv", "truth.csv"):
        assert (seam_run / "log" / name).read_bytes() == (tmp_path / "log" / name).read_bytes(), name


@pytest.mark.slow
def test_seam_track_and_tune_are_one_library_call_each(seam_run, tmp_path, capsys):
    assert main(["seam", "track", str(seam_run / "log"), "--out", str(tmp_path / "cli")]) == 0
    run = track_episode(seam_run / "log", tmp_path / "lib")
    assert run.exit_code == 0 and run.metrics["steps"] == 30
    assert _csv_without_times(tmp_path / "cli" / "estimates.csv") == _csv_without_times(tmp_path / "lib" / "estimates.csv")
    assert main(["seam", "tune", str(seam_run / "log"), "--out", str(tmp_path / "cli.yaml")]) == 0
    tune(str(tmp_path / "lib.yaml"), [str(seam_run / "log")])
    cli, lib = (tmp_path / "cli.yaml").read_text(), (tmp_path / "lib.yaml").read_text()
    assert cli.replace("cli.yaml", "lib.yaml") == lib
    with pytest.raises(ConfigError, match=r"^seam tune: expected LOGDIRs or --simulate RUNS, not both$"):
        tune(tmp_path / "x.yaml", [seam_run / "log"], simulate=2)


def test_seam_demo_is_one_library_call(tmp_path, capsys):
    assert main(["seam", "demo", "--steps", "30", "--particles", "20", "--seed", "2"]) == 0
    printed = capsys.readouterr().out
    run = seam_demo(steps=30, particles=20, seed=2)
    assert len(run.sets) == 6 and run.main.sensors == 2 and run.main.trajectory == "xy"
    fk = run.sets[0].metrics["kinematic_rmse_mm"]["x"]
    assert f"{fk:.3f}" in printed
    for s in run.sets:
        assert f"{s.metrics['rmse_mm']['y']:.3f}" in printed


#: seam verbs whose --config is the cell's YAML (DESIGN.md): the verb's arguments with overrides, the
#: command that reads the dump back (--config FILE --dump-config appended), and what the dump must hold.
CELL_CONFIG_VERBS = {
    "simulate": (["simulate", "--trajectory", "yz", "--seed", "4", "--particles", "33"], ["simulate"],
                 {("trajectory", "kind"): "yz", ("seed",): 4, ("filter", "particles"): 33}),
    "study": (["study", "--steps", "40", "--sensors", "1"], ["study"],
              {("trajectory", "steps"): 40, ("cell", "sensors", "count"): 1}),
    "design": (["design", "--particles", "33"], ["design"], {("filter", "particles"): 33}),
    "tune --simulate": (["tune", "--simulate", "2", "--trajectory", "yz", "--seed", "7"], ["tune", "--simulate", "2"],
                        {("trajectory", "kind"): "yz", ("seed",): 7}),
    "tune LOGDIR": (["tune", "LOG", "--from", "PRIOR", "--with-truth", "--share-sensors"], ["tune", "--simulate", "1"],
                    {("seed",): 2834126987, ("cell", "sensors", "count"): 2}),
}


@pytest.mark.parametrize("verb", CELL_CONFIG_VERBS)
def test_seam_verbs_dump_the_cell_configuration_they_read_back(verb, tmp_path, capsys, request):
    """seam's --config is the cell's YAML (DESIGN.md); --dump-config prints it with the overrides, and the
    verb itself and ``seam simulate --config`` read it back to the same configuration."""
    from posekit.seam import load_profile
    from posekit.seam.frontend.profile import PRIOR_PROFILE

    argv, readback, holds = CELL_CONFIG_VERBS[verb]
    if "LOG" in argv:
        log = request.getfixturevalue("seam_log")
        capsys.readouterr()                                 # what the fixture's simulate printed
        argv = [str(log) if a == "LOG" else str(PRIOR_PROFILE) if a == "PRIOR" else a for a in argv]
    assert main(["seam", *argv, "--dump-config"]) == 0
    dumped = capsys.readouterr().out
    (tmp_path / "c.yaml").write_text(dumped)
    for again in (readback, ["simulate"]):
        assert main(["seam", *again, "--config", str(tmp_path / "c.yaml"), "--dump-config"]) == 0
        assert capsys.readouterr().out == dumped, again
    data = yaml.safe_load(dumped)
    for path, value in holds.items():
        node = data
        for key in path:
            node = node[key]
        assert node == value, path
    if "--from" in argv:                                    # the profile the tuner starts from
        assert data["profile"]["walk"] == yaml.safe_load(dump_profile(load_profile(PRIOR_PROFILE)))["walk"]


@pytest.fixture(scope="module")
def seam_log(tmp_path_factory):
    """A recorded episode (simulate --save-log, seed 2: run 0's episode seed 2834126987)."""
    root = tmp_path_factory.mktemp("seamlog")
    assert main(["seam", "simulate", "--steps", "20", "--particles", "20", "--seed", "2", "--out", str(root / "sim"),
                 "--save-log", str(root / "log")]) == 0
    return root / "log"


def test_seam_tune_dump_config_simulates_the_episodes_tune_fits_on(tmp_path, capsys):
    """``seam tune --simulate R --config C --trajectory K --seed S --dump-config``, read by ``seam simulate
    --config``, simulates the very episode the tuner fits on (the tuner's own simulate_episodes, same bytes)."""
    from posekit.seam.frontend.config import apply_overrides, load_config
    from posekit.seam.frontend.tune import simulate_episodes as tune_episodes

    (tmp_path / "tiny.yaml").write_text("trajectory: {steps: 25}\nfilter: {particles: 20}\n")
    assert main(["seam", "tune", "--simulate", "1", "--config", str(tmp_path / "tiny.yaml"), "--trajectory", "bend",
                 "--seed", "11", "--dump-config"]) == 0
    (tmp_path / "c.yaml").write_text(capsys.readouterr().out)
    assert main(["seam", "simulate", "--config", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "sim"),
                 "--save-log", str(tmp_path / "log")]) == 0
    cfg = apply_overrides(load_config(tmp_path / "tiny.yaml"), {"trajectory.kind": "bend"})
    (fitted,) = tune_episodes(cfg, 1, 11, tmp_path / "tune")
    for name in ("seam.csv", "log.csv", "truth.csv"):
        assert (fitted / name).read_bytes() == (tmp_path / "log" / name).read_bytes(), name


@pytest.mark.parametrize("argv, message", [
    (["tune", "--simulate", "2", "--trajectory", "xy,yz"],
     "--dump-config: --trajectory names 2 kinds (xy, yz); a configuration holds one trajectory.kind: dump one kind at "
     "a time (the cell is the same)"),
    (["tune", "--trajectory", "xy"], "seam tune: expected at least one LOGDIR (or --simulate RUNS)"),
    (["tune", "--simulate", "2", "--trajectory", "zz"], "--trajectory: expected kinds among xy, yz, line, bend, got 'zz'"),
])
def test_seam_tune_dump_config_refuses_in_one_line(argv, message, capsys):
    assert main(["seam", *argv, "--dump-config"]) == 1
    assert capsys.readouterr().err == f"posekit: error: {message}\n"


def test_seam_verbs_need_out_unless_dump_config(capsys):
    rc = main(["seam", "design", "--particles", "33"])
    err = capsys.readouterr().err
    assert rc == 1 and err == "posekit: error: --out: an output folder is required (or use --dump-config)\n"
    rc = main(["seam", "tune", "--simulate", "1"])
    err = capsys.readouterr().err
    assert rc == 1 and err == "posekit: error: --out: a profile file is required (or use --dump-config)\n"


def test_ceiling_calibrate_is_one_library_call(rendered, tmp_path, capsys):
    """The same CAL.json; a point moved 40 px is rejected by RANSAC and named as off the fit."""
    from posekit.ceiling import calibrate_file

    lines = (rendered / "calibration_points.csv").read_text().splitlines()
    x, y, u, v = (float(t) for t in lines[3].split(","))
    lines[3] = f"{x:g},{y:g},{u + 40:g},{v:g}"
    (tmp_path / "p.csv").write_text("\n".join(lines) + "\n")
    argv = [str(tmp_path / "p.csv"), "--camera", str(rendered / "camera.json"), "--residuals", "none"]
    assert main(["ceiling", "calibrate", *argv, "--out", str(tmp_path / "cli.json")]) == 0
    printed = capsys.readouterr().out
    run = calibrate_file(tmp_path / "p.csv", tmp_path / "lib.json", camera=rendered / "camera.json")
    assert (tmp_path / "cli.json").read_bytes() == (tmp_path / "lib.json").read_bytes()
    assert run.exit_code == 0 and run.ransac_used and list(run.rejected) == [2]     # line 4 of the file
    assert run.rejected_lens == 0 and not run.too_many_rejected and run.residual_px[2] > 30
    assert f"RANSAC rejected 1 of {len(lines) - 1} points" in printed and "1 are off the fit alone" in printed

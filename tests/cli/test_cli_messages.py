"""Errors that name the cause: exact one-line messages for the mistakes a newcomer makes.

(Before/after of each message: docs/notes/issue-30.md.)
"""

from pathlib import Path

import numpy as np
import pytest
import yaml

from posekit.cli.main import main
from posekit.errors import GaugeError, ProfileError
from posekit.profiler import bundled_gauge, detect_corners, load_gauge, render_profiles, sample_poses

DEMO5 = Path(__file__).resolve().parents[2] / "examples" / "gauges" / "demo-5.yaml"


def _run(capsys, *argv):
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


def _usage_error(capsys, *argv) -> str:
    """The last stderr line of a usage error (exit 2)."""
    rc, _, err = _run(capsys, *argv)
    assert rc == 2
    return err.strip().splitlines()[-1]


@pytest.fixture(scope="module")
def profile_demo5():
    gauge = bundled_gauge("demo-5")
    return render_profiles(gauge, sample_poses(gauge, 1, rng=0)[0], rng=0)


def _csv(path, profile):
    np.savetxt(path, profile, delimiter=",", header="x,z", comments="", fmt="%.6f")
    return str(path)


# ----------------------------------------------------------------------------- did you mean


def test_mistyped_command_gets_a_suggestion(capsys):
    assert _usage_error(capsys, "profilr") == (
        "posekit: error: argument COMMAND: invalid choice: 'profilr' (choose from 'demo', 'profiler', 'ceiling', "
        "'localcal', 'seam', 'bench', 'warmup'); did you mean 'profiler'?")


def test_mistyped_verb_gets_a_suggestion(capsys):
    assert _usage_error(capsys, "localcal", "mach", "a.tum", "b.tum") == (
        "posekit localcal: error: argument VERB: invalid choice: 'mach' (choose from 'match', 'handeye', "
        "'simulate', 'demo'); did you mean 'match'?")


def test_mistyped_choice_gets_a_suggestion(capsys):
    assert _usage_error(capsys, "profiler", "estimate", "p.csv", "--gauge", "demo-5", "--method", "mel") == (
        "posekit profiler estimate: error: argument --method: invalid choice: 'mel' (choose from 'cf', 'mle'); "
        "did you mean 'mle'?")


def test_mistyped_flag_gets_the_flag_of_that_verb(capsys):
    assert _usage_error(capsys, "profiler", "estimate", "p.csv", "--gauge", "demo-5", "--methd", "cf") == (
        "posekit: error: unrecognized arguments: --methd cf; did you mean --method?")
    # --partcles exists on seam simulate only: it is found under the verb given
    assert _usage_error(capsys, "seam", "simulate", "--partcles", "3", "--out", "x") == (
        "posekit: error: unrecognized arguments: --partcles 3; did you mean --particles?")


def test_two_mistyped_flags_each_get_one(capsys):
    assert _usage_error(capsys, "profiler", "estimate", "p.csv", "--gauge", "demo-5", "--methd", "cf",
                        "--nosie-um=3") == (
        "posekit: error: unrecognized arguments: --methd cf --nosie-um=3; did you mean --method (for --methd), "
        "--noise-um (for --nosie-um)?")


def test_no_suggestion_when_nothing_is_close(capsys):
    assert _usage_error(capsys, "profiler", "estimate", "p.csv", "--gauge", "demo-5", "--zzz") == (
        "posekit: error: unrecognized arguments: --zzz")
    assert _usage_error(capsys, "qqq") == (
        "posekit: error: argument COMMAND: invalid choice: 'qqq' (choose from 'demo', 'profiler', 'ceiling', "
        "'localcal', 'seam', 'bench', 'warmup')")


# ----------------------------------------------------------------------------- metres


def test_gauge_in_metres_is_named(tmp_path, capsys, profile_demo5):
    doc = yaml.safe_load(DEMO5.read_text())
    for plane in doc["planes"]:
        plane["offset"] /= 1000.0
    doc["extent"] = {k: [v / 1000.0 for v in vs] for k, vs in doc["extent"].items()}
    path = tmp_path / "gauge_m.yaml"
    path.write_text(yaml.safe_dump(doc))
    expected = (f"{path}: gauge 'demo-5': looks like metres (every offset and ridge within 2 of the origin, the "
                "ridges span 0.08 in x); posekit expects mm (multiply offset and extent by 1000)")
    with pytest.raises(GaugeError) as info:
        load_gauge(path)
    assert str(info.value) == expected
    rc, _, err = _run(capsys, "profiler", "estimate", _csv(tmp_path / "p.csv", profile_demo5), "--gauge", str(path))
    assert (rc, err) == (1, f"posekit: error: {expected}\n")


def test_the_same_gauge_in_mm_loads():
    assert load_gauge(DEMO5).n_corners == 5


def test_profile_in_metres_is_named(tmp_path, capsys, profile_demo5):
    path = _csv(tmp_path / "p_m.csv", profile_demo5 / 1000.0)
    rc, out, err = _run(capsys, "profiler", "estimate", path, "--gauge", "demo-5")
    assert (rc, out) == (1, "")
    assert err.startswith(f"posekit: error: {path}: the profile looks like metres (every |x|, |z| < 2 and it spans ")
    assert err.endswith("posekit expects mm (multiply by 1000)\n")


# ----------------------------------------------------------------------------- wrong gauge


def test_wrong_gauge_is_named_when_the_corners_fit_no_run_of_its_ridges(profile_demo5):
    with pytest.raises(ProfileError) as info:
        detect_corners(profile_demo5, bundled_gauge("demo-10"))
    assert str(info.value) == (
        "expected 10 corners for gauge 'demo-10', found 5 (at x = [-45.0, -25.1, -3.6, 18.0, 32.1] mm); the 5 "
        "corners found fit no 5 consecutive ridges of gauge 'demo-10' with the rest out of view (the returns span "
        "x = -60.1..50.8 mm): wrong gauge file?")


def test_corners_out_of_view_are_still_called_missing(profile_demo5):
    """The right gauge with its last ridge cut out of the profile: missing corners, not a wrong gauge."""
    gauge = bundled_gauge("demo-5")
    corners = detect_corners(profile_demo5, gauge).points
    cut = profile_demo5.copy()
    cut[cut[:, 0] > corners[-1, 0] - 3.0] = np.nan
    with pytest.raises(ProfileError, match=r"missing corner\(s\): the returns span .* out of the measuring range"):
        detect_corners(cut, gauge)


def test_wrong_gauge_in_the_cli_record(tmp_path, capsys, profile_demo5):
    rc, out, err = _run(capsys, "profiler", "estimate", _csv(tmp_path / "p.csv", profile_demo5), "--gauge", "demo-10")
    assert rc == 1
    assert out.count('"status": "error"') == 1 and "wrong gauge file?" in out
    assert err == "posekit: 1 of 1 profiles failed; their records have status 'error'\n"


# ----------------------------------------------------------------------------- quiet one-profile estimate


def test_one_profile_estimate_prints_no_note(tmp_path, capsys, profile_demo5):
    rc, out, err = _run(capsys, "profiler", "estimate", _csv(tmp_path / "p.csv", profile_demo5), "--gauge", "demo-5")
    assert (rc, err) == (0, "")
    assert out.count('"status": "ok"') == 1

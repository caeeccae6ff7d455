"""Issue 26: a profile names the cell it was fitted on, and a cell tracked with another cell's profile is never
``tracking`` (posekit.seam.frontend.cell_signature).

On the independent cell of the tests (tests/seam/independent_cell.py: its own UR10-like arm, two lasers 13 / 17
ms late, data posekit's simulator did not make), the shipped default profile (fitted on posekit's simulated
PUMA) was ``tracking`` on every step with 66-77 % of the steps more than 3σ off (measured before this check,
seeds 100-105): a newcomer's first ``seam track`` on their own cell, before any ``seam tune``.
"""

import csv
import math

import numpy as np
import pytest

from posekit.cli.main import main
from posekit.seam.frontend.cell_signature import (
    CellSignature,
    cell_difference,
    cell_signature,
    config_mismatch,
    fitted_cell,
    mismatch_reason,
)
from posekit.seam.frontend.config_cell import cell_from_config
from posekit.seam.frontend.logs import read_episode_log
from posekit.seam.frontend.profile import DEFAULT_PROFILE, PRIOR_PROFILE, load_profile, merge_profile, write_profile
from posekit.seam.frontend.tracker import track_log
from tests.seam import independent_cell as ic
from tests.seam.test_seam_independent_cell import PROFILE

FIX = "fit one for this cell with posekit seam tune EPISODE [EPISODE ...] --out PROFILE.yaml"


@pytest.fixture(scope="module")
def held_out(tmp_path_factory):
    cell = ic.Cell()
    ep = ic.episode(cell, 100)
    return ic.write_episode(tmp_path_factory.mktemp("ic") / "held100", cell, ep, declare_latency=False), ep


def test_another_cell_s_profile_is_never_tracking_and_says_why(held_out):
    folder, ep = held_out
    rows = []
    r = track_log(read_episode_log(folder), on_step=lambda k, e: rows.append(e.raw.reason))   # the default profile
    assert set(r.status) == {"degraded"}
    want = "the profile was fitted on another cell (robot cell.urdf (6 joints), the profile's puma560 (6 joints)): "
    # (other tests may fail beside it: then their reasons follow, after "; ")
    assert all(x.startswith(want) and x.split("; ")[0].endswith(FIX) for x in rows), rows[0]
    assert ic.scores(r.estimate, r.spread, r.status, ep)["confident_wrong"] == 0.0
    # the cell's own profile (seam tune --with-truth on its training episodes) names this cell: tracked
    own = track_log(read_episode_log(folder, profile=PROFILE))
    assert np.mean(np.asarray(own.status) == "tracking") >= 0.9


def test_seam_track_says_it_before_the_run_and_beside_each_step(held_out, tmp_path, capsys):
    folder, _ = held_out
    rc = main(["seam", "track", str(folder), "--out", str(tmp_path / "tr")])
    out, err = capsys.readouterr()
    assert rc == 0, err
    warn = [line for line in err.splitlines() if line.startswith("warning: the profile was fitted on another cell")]
    assert warn == [warn[0]] and warn[0].endswith(FIX + "; every step is degraded at best"), err
    assert "status: degraded 400" in out
    with (tmp_path / "tr" / "estimates.csv").open() as f:
        assert {row["reason"].split(" (")[0] for row in csv.DictReader(f)} == {"the profile was fitted on another cell"}
        # (here the bias test also sees the undeclared latency on some steps: its reason follows)


def test_the_signature_survives_setup_yaml_and_the_profile_file(held_out, tmp_path):
    """``seam tune`` read the training episodes' setup.yaml (written by the independent generator) and wrote the
    cell into the profile; read back, a held-out episode's setup.yaml gives the same cell."""
    folder, _ = held_out
    fitted = load_profile(PROFILE).fitted.cell
    here = cell_signature(cell_from_config(read_episode_log(folder).config.cell))
    assert cell_difference(fitted, here) is None
    assert fitted.robot == "cell.urdf" and fitted.joints == 6 and len(fitted.mounts_mm) == 2
    # the second laser: 1.5 mm aside, 55 mm ahead, turned -4 deg about z (the generator's numbers)
    M = np.reshape(fitted.mounts_mm[1], (3, 4))
    assert M[:, 3] == pytest.approx([1.5, 55.0, 0.0]) and M[0, 0] == pytest.approx(math.cos(math.radians(4.0)), abs=1e-6)
    # and through a file written here
    again = load_profile(write_profile(tmp_path / "p.yaml", load_profile(PROFILE)))
    assert again.fitted.cell == fitted
    assert fitted_cell([read_episode_log(folder)] * 2) == here


def _moved(sig: CellSignature, k: int, dt=(0.0, 0.0, 0.0), yaw_deg=0.0) -> CellSignature:
    M = np.vstack([np.reshape(sig.mounts_mm[k], (3, 4)), [0.0, 0.0, 0.0, 1.0]])
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    R = np.array([[c, -s, 0.0, dt[0]], [s, c, 0.0, dt[1]], [0.0, 0.0, 1.0, dt[2]], [0.0, 0.0, 0.0, 1.0]])
    mounts = list(sig.mounts_mm)
    mounts[k] = tuple((M @ R)[:3].ravel())
    return sig.model_copy(update={"mounts_mm": tuple(mounts)})


def test_what_differs_is_named():
    sig = load_profile(PROFILE).fitted.cell
    assert cell_difference(sig, sig) is None
    assert cell_difference(sig, _moved(sig, 1, (0.0, 0.0, 4e-6))) is None       # a written-and-read round trip
    assert cell_difference(sig, _moved(sig, 1, (0.3, 0.4, 0.0))) == "sensor 2's mount 0.5 mm / 0 deg from the profile's"
    assert cell_difference(sig, _moved(sig, 0, yaw_deg=2.0)) == "sensor 1's mount 0 mm / 2 deg from the profile's"
    assert cell_difference(sig, sig.model_copy(update={"mounts_mm": sig.mounts_mm[:1]})) == "1 sensors, the profile's 2"
    assert (cell_difference(sig, sig.model_copy(update={"robot": "ur10"}))
            == "robot ur10 (6 joints), the profile's cell.urdf (6 joints)")
    tcp = list(sig.tcp_zero_mm)
    tcp[3] += 2.0
    assert (cell_difference(sig, sig.model_copy(update={"tcp_zero_mm": tuple(tcp)}))
            == "the tool centre point at zero joints 2 mm / 0 deg from the profile's")
    assert (cell_difference(sig, sig.model_copy(update={"compliance_rad_per_nm": 8e-7}))
            == "compliance 8e-07 rad/(N m), the profile's 7e-07")
    assert cell_difference(sig, sig.model_copy(update={"angle": True})) == "sensors.angle true, the profile's false"


def test_a_profile_that_names_no_cell_is_not_checked(held_out):
    folder, _ = held_out
    cell = cell_from_config(read_episode_log(folder).config.cell)
    assert load_profile(PRIOR_PROFILE).fitted.cell is None and mismatch_reason(None, cell) is None
    # a profile edited by merging values (a configuration's ``profile: {...}``) is no longer the fitted one
    assert merge_profile(load_profile(DEFAULT_PROFILE), {"plateau": {"d0_mm": 3.0}}).fitted is None
    # (and the default profile on this cell does not)
    assert config_mismatch(read_episode_log(folder).config).startswith("the profile was fitted on another cell (robot cell.urdf")

"""Optional dependencies: a command that needs a missing extra says in one line which to install.

A missing package is simulated with ``sys.modules[name] = None`` (then ``import name`` raises
ModuleNotFoundError), so these tests run in the full test environment.
"""

import sys

import numpy as np
import pytest

from posekit._extras import require
from posekit.cli.main import main
from posekit.errors import ConfigError, MissingExtraError
from posekit.sweep import run_tasks


def _hide(monkeypatch, *modules):
    """Make ``import m`` fail for each dotted name and its top-level package."""
    for m in modules:
        for name in {m, m.split(".")[0]}:
            monkeypatch.setitem(sys.modules, name, None)


def _one_line_error(capsys, argv) -> str:
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    return err.strip()


def test_require_returns_the_module():
    assert require("math", "studies", "nothing").sqrt(9.0) == 3.0


def test_require_names_the_extra_and_is_a_config_error(monkeypatch):
    _hide(monkeypatch, "statsmodels.api")
    with pytest.raises(MissingExtraError, match=r'^the OLS needs the \'studies\' extra: '
                                                r'pip install -e "\.\[studies\]" \(or do without\)$') as info:
        require("statsmodels.api", "studies", "the OLS", alternative="do without")
    assert isinstance(info.value, ConfigError)


def test_require_shows_the_failing_import_when_the_package_itself_is_there(monkeypatch, tmp_path):
    """The package is installed but one of its own imports fails: the message says which."""
    pkg = tmp_path / "posekit_fake_optional"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("import posekit_missing_dependency_xyz\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(MissingExtraError) as info:
        require("posekit_fake_optional", "urdf", "x")
    assert str(info.value) == ('x needs the \'urdf\' extra: pip install -e ".[urdf]"; '
                               "No module named 'posekit_missing_dependency_xyz'")


def test_seam_study_without_statsmodels(monkeypatch, capsys, tmp_path):
    _hide(monkeypatch, "statsmodels.api")
    err = _one_line_error(capsys, ["seam", "study", "--runs", "2", "--scheduler", "serial",
                                   "--out", str(tmp_path / "s")])
    assert err == 'posekit: error: posekit seam study needs the \'studies\' extra: pip install -e ".[studies]"'


def test_profiler_study_without_dask_runs_in_this_process(monkeypatch, capsys, tmp_path):
    """The default invocation needs no Dask: without it the study runs here and says so in one line."""
    _hide(monkeypatch, "distributed")
    assert main(["profiler", "study", "corners", "--corners", "5", "--gauges", "1", "--count", "3",
                 "--out", str(tmp_path / "c")]) == 0
    err = capsys.readouterr().err
    assert err.splitlines()[0] == ('posekit: note: running in this process; Dask would use every core '
                                   '(pip install -e ".[studies]")')
    assert (tmp_path / "c" / "report.html").exists()


def test_profiler_study_local_cluster_without_dask(monkeypatch, capsys, tmp_path):
    """Asking for the local cluster's size without Dask names the extra."""
    _hide(monkeypatch, "distributed")
    err = _one_line_error(capsys, ["profiler", "study", "corners", "--workers", "2", "--out", str(tmp_path / "c")])
    assert err == ('posekit: error: corners study on Dask needs the \'studies\' extra: '
                   'pip install -e ".[studies]" (or run it in this process with --scheduler serial)')
    assert not (tmp_path / "c" / "report.html").exists()


def _square(x):
    return x * x


def test_serial_runs_need_no_dask(monkeypatch):
    _hide(monkeypatch, "distributed")
    assert run_tasks(_square, [1, 2, 3], scheduler="serial") == [1, 4, 9]
    with pytest.raises(MissingExtraError, match=r"^a parallel run on Dask needs the 'studies' extra"):
        run_tasks(_square, [1, 2, 3], scheduler=None)
    with pytest.raises(MissingExtraError, match=r"^squares on Dask needs the 'studies' extra"):
        run_tasks(_square, [1], scheduler="tcp://127.0.0.1:1", desc="squares")


@pytest.mark.parametrize("hidden", ["lxml.etree", "yourdfpy"])
def test_urdf_robot_without_the_urdf_extra(monkeypatch, capsys, tmp_path, hidden):
    _hide(monkeypatch, hidden)
    err = _one_line_error(capsys, ["localcal", "simulate", "--robot", "ur10", "--method", "line", "--runs", "1",
                                   "--out", str(tmp_path / "l")])
    assert err == ('posekit: error: reading the URDF file ur10.urdf needs the \'urdf\' extra: '
                   'pip install -e ".[urdf]"')


def test_dh_robots_need_no_urdf_extra(monkeypatch):
    _hide(monkeypatch, "lxml.etree", "yourdfpy")
    from posekit.robots import load_robot

    chain = load_robot("puma560")
    assert np.all(np.isfinite(chain.forward_kinematics(np.zeros(6))))


def test_vision_commands_without_opencv(monkeypatch, capsys, tmp_path):
    """Without OpenCV the vision commands say which extra to install; modules still import."""
    _hide(monkeypatch, "cv2")
    import importlib

    import posekit.ceiling.detect.dots as detect
    import posekit.localcal.sim.camera as camera
    import posekit.localcal.sim.marker_detector as marker_detector

    importlib.reload(detect)  # the module-level name is a lazy stand-in: importing works
    importlib.reload(camera)
    importlib.reload(marker_detector)  # it holds camera's cv2 stand-in: the reloaded one
    try:
        cal = tmp_path / "cal.json"
        cal.write_text('{"H_image_world": [[1,0,0],[0,1,0],[0,0,1]], "H_world_image": [[1,0,0],[0,1,0],[0,0,1]], '
                       '"rms_px": 0.1, "rms_world": 0.1}')
        (tmp_path / "frames").mkdir()
        (tmp_path / "frames" / "0001.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(64))
        err = _one_line_error(capsys, ["ceiling", "track", str(tmp_path / "frames"), "--calibration", str(cal),
                                       "--out", str(tmp_path / "t.csv")])
        assert err.endswith("needs the 'vision' extra: pip install -e \".[vision]\""), err
        err = _one_line_error(capsys, ["localcal", "simulate", "--method", "line", "--runs", "1",
                                       "--out", str(tmp_path / "l")])
        assert "needs the 'vision' extra" in err, err
    finally:
        monkeypatch.undo()
        importlib.reload(detect)
        importlib.reload(camera)
        importlib.reload(marker_detector)


def test_install_hint_fits_how_posekit_was_installed(monkeypatch):
    """A checkout (these tests run in one) gets the editable form; an installed package the index form."""
    import posekit._extras as extras

    assert extras.install_hint("vision") == 'pip install -e ".[vision]"'
    monkeypatch.setattr(extras, "_checkout", lambda: False)
    assert extras.install_hint("vision") == 'pip install "posekit[vision]"'
    _hide(monkeypatch, "statsmodels.api")
    with pytest.raises(MissingExtraError) as info:
        require("statsmodels.api", "studies", "posekit seam study")
    assert str(info.value) == 'posekit seam study needs the \'studies\' extra: pip install "posekit[studies]"'

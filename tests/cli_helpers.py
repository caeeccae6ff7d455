"""Helpers shared by CLI tests that run ``posekit`` in process through ``main(argv)``."""

from posekit.cli.main import main


def run_cli(capsys, *argv):
    """``(exit code, stdout, stderr)`` of ``posekit *argv`` (arguments turned into str)."""
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def assert_one_line_error(rc, out, err, *needles):
    """Exit 1, nothing on stdout, one ``posekit: error: ...`` line naming every needle, no traceback."""
    assert rc == 1, err
    assert out == ""
    assert err.startswith("posekit: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err and "internal error" not in err, err
    for needle in needles:
        assert needle in err, f"{needle!r} not in {err!r}"

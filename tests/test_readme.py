"""Every ```bash and ```python block of README.md runs, in order, as a user would run it after the
README's first command (``pip install -e ".[all]" && posekit demo``).

The blocks share one folder, as a user's terminal would: it holds links to the repository's
``examples/`` and ``tests/`` (the README's commands are run from a clone) and receives every
output. A bash line ``posekit ARGS`` runs in-process through ``main(argv)`` (globs expanded as
the shell would) and must exit 0; a python block is executed as written. The first bash block
(the two set-up commands) is what the test environment already is, so it is not run; the docs
build (a ```text block) is run by ``.ci/run``.
"""

import glob
import re
import shlex
from pathlib import Path

import pytest

from posekit.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
_BLOCK = re.compile(r"^```(python|bash)[ \t]*\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)
MAX_LINES = 250


def blocks(text: str) -> list[tuple[str, int, str]]:
    """``(language, line number, code)`` of every fenced python or bash block of ``text``."""
    return [(m.group(1), text.count("\n", 0, m.start()) + 1, m.group(2)) for m in _BLOCK.finditer(text)]


def commands(code: str) -> list[list[str]]:
    """The argv of each command line of a bash block (comments and blank lines dropped)."""
    return [argv for argv in (shlex.split(line, comments=True) for line in code.splitlines()) if argv]


TEXT = README.read_text(encoding="utf-8")
ALL = blocks(TEXT)
SETUP, RUN = ALL[0], ALL[1:]


def test_readme_is_short():
    assert TEXT.count("\n") <= MAX_LINES


def test_first_block_is_the_two_setup_commands():
    lang, _, code = SETUP
    assert lang == "bash"
    assert [" ".join(a) for a in commands(code)] == ['pip install -e .[all] && posekit demo',
                                                     'pip install -e .[test] && pytest']


def test_ci_runs_the_readme_test_command():
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert 'pip install -e ".[test]"' in ci and "\npytest" in ci


def test_block_extraction():
    text = "x\n```python\na = 1\n```\n```bash\nls  # list\n\n```\n```text\nno\n```\n"
    assert blocks(text) == [("python", 2, "a = 1\n"), ("bash", 5, "ls  # list\n\n")]
    assert commands("ls  # list\n\nposekit demo --out 'a b'\n") == [["ls"], ["posekit", "demo", "--out", "a b"]]


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """The user's terminal: a folder with the checkout's examples/ and tests/ data in reach."""
    folder = tmp_path_factory.mktemp("readme")
    for name in ("examples", "tests"):
        (folder / name).symlink_to(ROOT / name, target_is_directory=True)
    return folder


def _expand(arg: str, cwd: Path) -> list[str]:
    if any(c in arg for c in "*?["):
        found = sorted(glob.glob(arg, root_dir=cwd))
        assert found, f"{arg}: the glob matches nothing"
        return found
    return [arg]


@pytest.mark.slow
def test_readme_blocks_run_in_order(workdir, monkeypatch, capsys):
    """One test, not one per block: a block uses what the blocks before it wrote (a parametrized
    test per block could run a later block first, on another pytest-xdist worker)."""
    monkeypatch.chdir(workdir)
    for lang, line, code in RUN:
        if lang == "python":
            # Padded with blank lines so that a traceback gives the line number in README.md.
            exec(compile("\n" * line + code, str(README), "exec"), {"__name__": "__readme__"})
            continue
        for argv in commands(code):
            assert argv[0] == "posekit", f"README.md:{line}: only posekit commands are run here: {argv}"
            args = [a for arg in argv[1:] for a in _expand(arg, workdir)]
            rc = main(args)
            err = capsys.readouterr().err
            assert rc == 0, f"README.md:{line}: {' '.join(argv)} exited {rc}: {err[-500:]}"

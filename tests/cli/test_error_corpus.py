"""One line means one line (issue 28, deliverable 6): every error the CLI prints is one line of
at most 300 characters, whatever the input — collected here over the whole command tree.

For every verb of ``posekit``, taken from the parser itself: each positional argument given a
path that does not exist (250 characters long, with a newline and a terminal escape in it), each
numeric flag given a value out of its range and a number in another script, and each file flag a
missing long path. The fuzz corpus (tests/fuzz) checks the same rule over its readers' messages.
"""

import argparse

import pytest

from posekit.cli.main import build_parser
from tests.cli_helpers import run_cli

LONG = "/tmp/" + "nested-folder-with-a-long-name/" * 7 + "in\nput\x1b[2J.csv"
SKIP_VERBS = {("profiler", "serve"), ("profiler", "replay"), ("ceiling", "track"), ("bench",)}


def _verbs(parser, prefix=()):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _verbs(sub, prefix + (name,))
            return
    yield prefix, parser


def _cases():
    cases = []
    for path, parser in _verbs(build_parser()):
        if path in SKIP_VERBS or path[:1] in SKIP_VERBS:
            continue
        positionals = [a for a in parser._actions if not a.option_strings and a.dest != "help"]
        if not positionals:          # flags alone fail only when wrong: a bad file flag stands in
            files = [a for a in parser._actions if a.option_strings and a.type is None and a.nargs is None
                     and any(k in a.dest for k in ("gauge", "config"))]
            if not files:
                continue
            base = [files[0].option_strings[-1], LONG]
        else:
            base = [LONG for _ in positionals]
        cases.append((path, tuple(base)))
        for a in parser._actions:
            if not a.option_strings or a.nargs == 0 or a.dest == "help" or a.help == argparse.SUPPRESS:
                continue
            flag = a.option_strings[-1]
            bounds = getattr(a.type, "bounds", None)
            if bounds is not None:
                cases.append((path, (*base, flag, "1e300")))
                cases.append((path, (*base, flag, "\u0661\u0662")))
            elif a.type is None and any(k in a.dest for k in ("gauge", "config", "calibration", "camera", "profile")):
                cases.append((path, (*base, flag, LONG)))
    return cases


CASES = _cases()


def test_the_corpus_covers_the_command_tree():
    verbs = {p for p, _ in CASES}
    assert len(verbs) >= 15 and len(CASES) >= 80, (len(verbs), len(CASES))


@pytest.mark.parametrize("path, args", CASES, ids=[" ".join(p) + " " + " ".join(a[-2:])[:30] for p, a in CASES])
def test_every_error_is_one_line_of_at_most_300_characters(capsys, tmp_path, monkeypatch, path, args):
    monkeypatch.chdir(tmp_path)
    argv = [*path, *args]
    rc, out, err = run_cli(capsys, *argv, "--out", tmp_path / "o") if _takes_out(path) else run_cli(capsys, *argv)
    assert rc in (1, 2), (rc, err)
    assert "Traceback" not in err and "internal error" not in err, err
    lines = err.splitlines()
    if rc == 1:
        assert len(lines) == 1 and lines[0].startswith("posekit: error: "), err
        assert len(lines[0]) <= 300, (len(lines[0]), lines[0])
        assert "\x1b" not in err
    assert not (tmp_path / "o").exists()


_OUT = {}


def _takes_out(path) -> bool:
    if path not in _OUT:
        parser = dict(_verbs(build_parser()))[path]
        _OUT[path] = any("--out" in a.option_strings for a in parser._actions)
    return _OUT[path]

"""The shared verdict type: its vocabulary, its levels and the exit rule."""

import doctest

import pytest

import posekit.verdict as verdict_module
from posekit.verdict import STATUS_LEVELS, Level, Verdict, batch_exit_code, level_of, status_counts, track_exit_code


def test_every_systems_word_has_its_level():
    assert {w for w, lvl in STATUS_LEVELS.items() if lvl is Level.OK} == {"ok", "tracking"}
    assert {w for w, lvl in STATUS_LEVELS.items() if lvl is Level.SUSPECT} == {"suspect", "predicted", "degraded"}
    assert {w for w, lvl in STATUS_LEVELS.items() if lvl is Level.FAILED} == {"error", "lost"}


def test_unknown_word_is_refused_with_the_vocabulary():
    with pytest.raises(ValueError, match=r"unknown status 'fine'; expected one of ok, tracking, suspect"):
        level_of("fine")
    with pytest.raises(ValueError, match="unknown status"):
        Verdict("fine")


def test_verdict_round_trip_and_reason():
    v = Verdict("degraded", ["laser 2 innovation 4.1 sigma", "force 12 kN above range"], {"x_mm": 0.05})
    assert v.reasons == ("laser 2 innovation 4.1 sigma", "force 12 kN above range")
    assert v.reason == "laser 2 innovation 4.1 sigma; force 12 kN above range"
    assert v.level is Level.SUSPECT and not v.is_ok
    assert v.to_dict() == {"status": "degraded", "reasons": list(v.reasons), "std": {"x_mm": 0.05}}
    assert Verdict("ok").reason == "" and Verdict("tracking").is_ok


def test_failed_verdict_has_no_numbers_and_a_failed_word():
    v = Verdict.failed("no overlapping timestamps")
    assert (v.status, v.reasons, v.std) == ("error", ("no overlapping timestamps",), None)
    assert Verdict.failed("dot out of view", status="lost").level is Level.FAILED
    with pytest.raises(ValueError, match="needs a FAILED status, not 'suspect'"):
        Verdict.failed("x", status="suspect")


def test_reasons_must_not_be_a_bare_string():
    with pytest.raises(TypeError, match="not one str"):
        Verdict("suspect", "fit failed")


def test_status_counts_keeps_the_vocabulary_order_and_zeros():
    assert status_counts(["lost", "ok", "ok"], ("ok", "predicted", "lost")) == {"ok": 2, "predicted": 0, "lost": 1}
    assert status_counts(["suspect", "ok", "suspect"]) == {"suspect": 2, "ok": 1}


def test_exit_rules():
    assert batch_exit_code(["ok", "tracking"]) == 0
    assert batch_exit_code(["ok", "predicted"]) == 1
    assert batch_exit_code([]) == 0
    assert track_exit_code(True) == 0 and track_exit_code(False) == 1


def test_docstring_examples():
    assert doctest.testmod(verdict_module).failed == 0

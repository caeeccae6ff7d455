"""The fuzz corpus (issue 28, deliverable 12): mutated inputs for every reader, and for what the
CLI does next with what they read, give a result or a one-line error: no traceback, no hang.

The default run takes cases 0-3 of each of the 33 readers (a few seconds); the whole corpus,
310 cases per reader (10,230 inputs, about a minute), is marked full_corpus: ``pytest --full-corpus
tests/fuzz`` or ``python -m tests.fuzz.corpus 310``. The inputs are generated from the seed
:data:`tests.fuzz.corpus.SEED` and the seed inputs in tests/fuzz/seeds/ (``python
tests/fuzz/make_seeds.py`` writes them).
"""

import pytest

from tests.fuzz import corpus

FULL_CASES = 310            # per reader: 33 readers, 10,230 inputs
SAMPLE_CASES = 4


def _bad(outcomes):
    return [f"{o.reader} case {o.case}: {o.kind}: {o.detail}" for o in outcomes if o.kind not in ("ok", "error")]


def test_seed_inputs_read():
    """The corpus starts from valid inputs: every seed reads (and estimates, matches, ...)."""
    assert corpus.check_seeds() == []


def test_mutations_are_reproducible():
    assert corpus.case_input("gauge", 7) == corpus.case_input("gauge", 7)
    assert corpus.case_input("gauge", 7) != corpus.case_input("gauge", 8)


def test_fuzz_sample():
    outcomes = corpus.run_corpus(SAMPLE_CASES)
    assert len(outcomes) == SAMPLE_CASES * len(corpus.readers()) >= 4 * 33
    assert _bad(outcomes) == []
    assert {o.kind for o in outcomes} == {"ok", "error"}          # both kinds of input occur


@pytest.mark.full_corpus
def test_fuzz_full_corpus():
    outcomes = corpus.run_corpus(FULL_CASES)
    print(corpus.summary(outcomes))
    assert len(outcomes) >= 10_000
    assert _bad(outcomes) == []

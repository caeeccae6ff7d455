"""Both error rates of the verdict on the bundled gauges, at the default significance.

The cases (good data called suspect, bad data called ok; the defects made in gauge files, not by
the simulator's realism) and the full table behind the default significance are
:mod:`posekit.profiler.studies.verdict_rates` (checked in as ``docs/data/profiler_verdict_rates.csv``).
Here 200 profiles per case: with the test at α = 1e-3 a good case has about 0.2 suspect
profiles, and 3 or more (1.5 %) come with probability 1.1e-3 (binomial), so ``<= 1 %`` fails a
correct estimator about once in 900 cases; a bad case that the tests see is ok at a rate far
below that (2,000 per case: 0.00 %).
"""

import pytest

from posekit.profiler.studies.verdict_rates import error_rate, measure


@pytest.mark.slow
def test_error_rates_at_the_default_significance(tmp_path):
    cases = measure(200, folder=tmp_path)
    for case, (kind, counts) in cases.items():
        rate = error_rate(kind, counts)
        if kind == "good":
            assert rate <= 0.01, (case, counts)                 # <= 1 % of good data suspect
        elif kind == "bad":
            assert rate <= 0.01, (case, counts)                 # <= 1 % of detectable bad data ok
        if "random-5" in case or "3x" in case:
            assert counts["ok"] == 0, (case, counts)

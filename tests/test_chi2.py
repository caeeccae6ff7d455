"""posekit._chi2 against scipy.stats.chi2 (the library it stands in for at start-up)."""

import subprocess
import sys

import numpy as np
from scipy import stats

from posekit._chi2 import chi2

DOF = np.array([1, 2, 3, 4, 5, 7, 10, 17, 30, 61, 100, 250, 1000, 5000, 20000])
# The upper tail that tests use (significance levels) down to 1e-300, and the median; not
# probabilities within 1e-3 of 1 (the lower tail, where Q = 1 - P cancels).
Q = np.array([1e-300, 1e-50, 1e-12, 1e-6, 1e-4, 5e-4, 1e-3, 0.01, 0.05, 0.25, 0.5, 0.9, 0.999])


def test_isf_matches_scipy_stats():
    q, df = np.meshgrid(Q, DOF)
    np.testing.assert_allclose(chi2.isf(q, df), stats.chi2.isf(q, df), rtol=1e-10)
    np.testing.assert_allclose(chi2.isf(0.05, 1), 3.841458820694124, rtol=1e-12)   # the textbook 5 % value
    np.testing.assert_allclose(chi2.isf(0.01, [0.5, 1.5, 2.7]), stats.chi2.isf(0.01, [0.5, 1.5, 2.7]), rtol=1e-10)
    assert isinstance(chi2.isf(0.001, 4), np.float64)
    assert (chi2.isf(0.0, 3), chi2.isf(1.0, 3)) == (np.inf, 0.0) and np.isnan(chi2.isf(0.1, 0))


def test_sf_and_median_match_scipy_stats():
    x, df = np.meshgrid(np.array([1e-6, 0.01, 0.5, 1.0, 3.84, 10.0, 50.0, 200.0, 1e3, 2e4]), DOF)
    np.testing.assert_allclose(chi2.sf(x, df), stats.chi2.sf(x, df), rtol=1e-10, atol=1e-300)
    np.testing.assert_allclose(chi2.median(DOF), stats.chi2.median(DOF), rtol=1e-11)
    np.testing.assert_allclose(chi2.sf(chi2.isf(Q, 6), 6), Q, rtol=1e-9)                # round trip
    assert chi2.sf(0.0, 3) == 1.0 and chi2.sf(np.inf, 3) == 0.0 and np.isnan(chi2.sf(np.nan, 3))


def test_import_needs_no_scipy():
    code = "import sys, posekit._chi2; print(sorted(m for m in sys.modules if m.startswith('scipy')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"

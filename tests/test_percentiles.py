"""Constant-memory percentiles against numpy's exact ones."""

from __future__ import annotations

import numpy as np
import pytest

from common.percentiles import StreamingPercentiles


def test_percentiles_within_the_stated_precision_of_numpy():
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.lognormal(0.0, 1.0, 20000), rng.uniform(5.0, 500.0, 200)])  # ms, heavy tail
    sp = StreamingPercentiles(precision=0.01)
    for v in x:
        sp.add(float(v))
    assert sp.count == len(x) and sp.max == x.max()
    for q in (1, 50, 90, 99, 99.9):
        exact = np.percentile(x, q, method="inverted_cdf")
        assert sp.percentile(q) == pytest.approx(exact, rel=0.006), q


def test_empty_tiny_and_huge_values():
    sp = StreamingPercentiles(lo=1e-3, hi=1e3)
    assert sp.percentile(50) is None
    for v in (0.0, 1e-6, 5e5):
        sp.add(v)
    assert sp.percentile(10) == pytest.approx(1e-3) and sp.max == 5e5
    assert sp.percentile(100) == 5e5 and len(sp.counts) < 2_500   # bins fixed by lo, hi and precision

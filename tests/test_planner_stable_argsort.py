"""planner._tree._stable_argsort, the choose-parent fallback's sort: the permutation of numpy's stable
argsort (the trees depend on it; it replaced ``np.argsort(kind="mergesort")`` to cut the cold compile)."""

import numpy as np

from planner._tree import _stable_argsort


def test_stable_argsort_is_numpys_stable_argsort_ties_inf_and_nan_included():
    rng = np.random.default_rng(7)
    for t in range(2000):
        m = int(rng.integers(0, 90))
        keys = rng.integers(0, 6, size=m + 4).astype(float)   # many ties; the tail beyond m is ignored
        if t % 3 == 0:
            keys[rng.integers(0, m + 4, size=2)] = np.nan
        if t % 5 == 0:
            keys[rng.integers(0, m + 4, size=2)] = np.inf
        got = _stable_argsort(keys, np.int64(m))
        assert np.array_equal(got, np.argsort(keys[:m], kind="mergesort")), keys[:m]


def test_stable_argsort_compiles_one_specialisation():
    _stable_argsort(np.zeros(3), np.int64(3))
    assert len(_stable_argsort.signatures) == 1

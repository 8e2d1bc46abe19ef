import warnings

import numpy as np

from hope_rs.kernels.search import (
    SearchConfig,
    _projected,
    nearest_candidates,
    nearest_descriptor,
)
from hope_rs.pipeline import initial


def test_inverted_file_search_finds_most_true_neighbours():
    rng = np.random.default_rng(0)
    centres = rng.normal(size=(40, 16))
    db = (centres[rng.integers(0, 40, 3000)] + 0.3 * rng.normal(size=(3000, 16))).astype(np.float32)
    da = db[rng.permutation(3000)[:1000]] + 0.01 * rng.normal(size=(1000, 16)).astype(np.float32)
    exact_idx, _ = initial.nearest_candidates(da, db, 8)
    inverted_file = SearchConfig(exact_search_limit=100)
    idx, d = initial.nearest_candidates(da, db, 8, inverted_file)
    assert idx.shape == exact_idx.shape and np.all(np.diff(d, axis=1) >= -1e-4)
    assert np.mean(idx[:, 0] == exact_idx[:, 0]) > 0.9
    recall = np.mean([np.isin(idx[i], exact_idx[i]).mean() for i in range(len(idx))])
    assert recall > 0.8
    again = initial.nearest_candidates(da, db, 8, inverted_file)[0]
    np.testing.assert_array_equal(idx, again)  # deterministic
    g = initial.initial_map(da, db, search=inverted_file)
    assert np.unique(g).size == g.size


def _descriptors(n: int, d: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).random((n, d), dtype=np.float32)


def test_nearest_descriptor_is_the_exact_nearest_of_the_projected_rows():
    # Against a float64 brute force on the same projected rows: equal wherever the two nearest
    # are not within float32 rounding of each other.
    da, db = _descriptors(700, 352, 1), _descriptors(900, 352, 2)
    cfg = SearchConfig()
    got = nearest_descriptor(da, db, cfg)
    pa, pb = (x.astype(np.float64) for x in _projected(da, db, cfg))
    d2 = ((pa[:, None, :] - pb[None, :, :]) ** 2).sum(axis=2)
    want = d2.argmin(axis=1)
    two = np.sort(d2, axis=1)[:, :2]
    clear = two[:, 1] - two[:, 0] > 1e-5 * two[:, 1]
    assert clear.mean() > 0.95
    np.testing.assert_array_equal(got[clear], want[clear])


def test_nearest_descriptor_breaks_exact_ties_by_the_lowest_index():
    db = _descriptors(300, 352, 3)
    db[250] = db[40]  # two identical descriptors (e.g. the zero rows of isolated vertices)
    db[120] = db[7]
    da = db[[250, 40, 7, 120, 5]]
    assert nearest_descriptor(da, db).tolist() == [40, 40, 7, 7, 5]


def test_nearest_descriptor_without_tie_decision_is_the_search_own_nearest():
    da, db = _descriptors(200, 40, 4), _descriptors(300, 40, 5)
    one = nearest_descriptor(da, db, SearchConfig(decide_ties=False))
    np.testing.assert_array_equal(one, nearest_candidates(da, db, 1)[0][:, 0])
    np.testing.assert_array_equal(nearest_descriptor(da, db), one)  # no near ties here


def test_inverted_file_search_with_empty_cells_warns_nothing():
    # Many repeated rows leave k-means cells empty; such a cell has no members and the search
    # stays right, so nothing reaches the user.
    rng = np.random.default_rng(1)
    db = np.repeat(rng.normal(size=(30, 8)), 100, axis=0).astype(np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        idx, _ = nearest_candidates(db[::7], db, 4, SearchConfig(exact_search_limit=100))
    assert np.all(np.all(db[idx[:, 0]] == db[::7], axis=1))

import numpy as np

from hope_rs.kernels.search import SearchConfig
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

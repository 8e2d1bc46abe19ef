import numpy as np

from hope_rs import initial


def test_inverted_file_search_finds_most_true_neighbours(monkeypatch):
    rng = np.random.default_rng(0)
    centres = rng.normal(size=(40, 16))
    db = (centres[rng.integers(0, 40, 3000)] + 0.3 * rng.normal(size=(3000, 16))).astype(np.float32)
    da = db[rng.permutation(3000)[:1000]] + 0.01 * rng.normal(size=(1000, 16)).astype(np.float32)
    exact_idx, _ = initial.nearest_candidates(da, db, 8)
    monkeypatch.setattr(initial, "EXACT_SEARCH_LIMIT", 100)
    idx, d = initial.nearest_candidates(da, db, 8)
    assert idx.shape == exact_idx.shape and np.all(np.diff(d, axis=1) >= -1e-4)
    assert np.mean(idx[:, 0] == exact_idx[:, 0]) > 0.9
    recall = np.mean([np.isin(idx[i], exact_idx[i]).mean() for i in range(len(idx))])
    assert recall > 0.8
    np.testing.assert_array_equal(idx, initial.nearest_candidates(da, db, 8)[0])  # deterministic
    g = initial.initial_map(da, db)
    assert np.unique(g).size == g.size

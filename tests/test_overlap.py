import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from meshes import inverse, relabel
from strategies import maps, symmetric_patterns

import hope_rs


def reference(nbrs_a, nbrs_b, f, w):
    n_a, n_b = nbrs_a.shape[0], nbrs_b.shape[0]
    a = (nbrs_a != 0).astype(np.int64)
    b = (nbrs_b != 0).astype(np.int64)
    sel = sp.csr_matrix((w.astype(np.int64), (np.arange(n_a), f)), shape=(n_a, n_b))
    return (a @ sel @ b.T).tocsr()


def corrupted_map(n, frac, rng):
    f = np.arange(n)
    idx = rng.choice(n, int(frac * n), replace=False)
    f[idx] = rng.permutation(f[idx])
    return f, ~np.isin(np.arange(n), idx)


@pytest.mark.parametrize("k", [1, 3, 6])
def test_exact_against_sparse_product_on_faust(faust_pair, k):
    a, b = faust_pair
    na = hope_rs.khop_neighbourhoods(a.faces, k)
    nb = hope_rs.khop_neighbourhoods(b.faces, k)
    f, w = corrupted_map(a.n_vertices, 0.2, np.random.default_rng(k))
    got = hope_rs.overlap_cost(na, nb, f, w)
    want = reference(na, nb, f, w)
    want.eliminate_zeros()
    assert got.shape == want.shape
    assert got.has_sorted_indices
    assert got.nnz == want.nnz
    assert (got.astype(np.int64) != want).nnz == 0


@st.composite
def overlap_problem(draw):
    n_a = draw(st.integers(1, 30))
    n_b = draw(st.integers(1, 30))
    na, nb = draw(symmetric_patterns(n_a)), draw(symmetric_patterns(n_b))
    f = draw(maps(n_a, n_b))
    w = np.array(draw(st.lists(st.booleans(), min_size=n_a, max_size=n_a)))
    return na, nb, f, w


@settings(max_examples=150, deadline=None)
@given(overlap_problem(), st.integers(1, 6))
def test_random_patterns_and_top_k(problem, top_k):
    na, nb, f, w = problem
    want = reference(na, nb, f, w).toarray()
    got = hope_rs.overlap_cost(na, nb, f, w).toarray()
    np.testing.assert_array_equal(got, want)
    keep = np.arange(na.shape[0]) % nb.shape[0]
    top = hope_rs.overlap_cost(na, nb, f, w, top_k=top_k, keep=keep)
    for p in range(na.shape[0]):
        cols = top.indices[top.indptr[p] : top.indptr[p + 1]]
        vals = top.data[top.indptr[p] : top.indptr[p + 1]]
        assert keep[p] in cols
        np.testing.assert_array_equal(vals, want[p, cols])
        others = cols[cols != keep[p]]
        assert others.size <= top_k
        dropped = np.setdiff1d(np.arange(nb.shape[0]), cols)
        if dropped.size and others.size:
            assert want[p, dropped].max() <= want[p, others].min()
        # Only the forced column may be stored with a zero count.
        assert np.all(vals[cols != keep[p]] > 0)


def test_relabelling_both_shapes_permutes_the_cost(faust_pair):
    a, b = faust_pair
    rng = np.random.default_rng(7)
    pa, pb = rng.permutation(a.n_vertices), rng.permutation(b.n_vertices)
    f, w = corrupted_map(a.n_vertices, 0.3, rng)
    k = 2
    cost = hope_rs.overlap_cost(
        hope_rs.khop_neighbourhoods(a.faces, k), hope_rs.khop_neighbourhoods(b.faces, k), f, w
    )
    f_new = inverse(pb)[f[pa]]
    cost_new = hope_rs.overlap_cost(
        hope_rs.khop_neighbourhoods(relabel(a.faces, pa), k),
        hope_rs.khop_neighbourhoods(relabel(b.faces, pb), k),
        f_new,
        w[pa],
    )
    assert (cost_new != cost[pa][:, pb]).nnz == 0


def test_bad_inputs():
    nb = hope_rs.khop_neighbourhoods([[0, 1, 2]], 1)
    ok_f, ok_w = np.array([0, 1, 2]), np.ones(3, bool)
    with pytest.raises(ValueError, match="length 3"):
        hope_rs.overlap_cost(nb, nb, [0, 1], ok_w)
    with pytest.raises(ValueError, match=r"\[0, 3\)"):
        hope_rs.overlap_cost(nb, nb, [0, 1, 3], ok_w)
    with pytest.raises(ValueError, match=r"\[0, 3\)"):
        hope_rs.overlap_cost(nb, nb, [0, -1, 2], ok_w)
    with pytest.raises(TypeError, match="integer"):
        hope_rs.overlap_cost(nb, nb, [0.0, 1.0, 2.0], ok_w)
    with pytest.raises(ValueError, match="witnesses"):
        hope_rs.overlap_cost(nb, nb, ok_f, np.ones(4, bool))
    with pytest.raises(TypeError, match="scipy.sparse"):
        hope_rs.overlap_cost(nb.toarray(), nb, ok_f, ok_w)
    with pytest.raises(ValueError, match="square"):
        hope_rs.overlap_cost(nb[:2], nb, ok_f, ok_w)
    with pytest.raises(ValueError, match="top_k"):
        hope_rs.overlap_cost(nb, nb, ok_f, ok_w, top_k=0)
    with pytest.raises(ValueError, match="n_vertices must be >= 0, got -1"):
        hope_rs.khop_neighbourhoods([[0, 1, 2]], 1, n_vertices=-1)
    # A malformed index array is refused before scipy's own routines read it (they would
    # corrupt the process's memory).
    falling = sp.csr_matrix((np.ones(2), [0, 1], [0, 3, 2, 2]), shape=(3, 3))
    with pytest.raises(ValueError, match="nbrs_a is not a valid sparse matrix.*non-decreasing"):
        hope_rs.overlap_cost(falling, nb, ok_f, ok_w)
    outside = sp.csr_matrix((np.ones(2), [0, 7], [0, 1, 2, 2]), shape=(3, 3))
    with pytest.raises(ValueError, match="nbrs_b is not a valid sparse matrix"):
        hope_rs.overlap_cost(nb, outside, ok_f, ok_w)
    # Witnesses may also be given as vertex indices.
    got = hope_rs.overlap_cost(nb, nb, ok_f, [0])
    assert got.toarray().sum() == 9

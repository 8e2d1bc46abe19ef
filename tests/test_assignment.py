import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment
from scipy.sparse.csgraph import min_weight_full_bipartite_matching
from strategies import dense_costs, sparse_costs

import hope_rs


def value(cost, g):
    rows = np.flatnonzero(g >= 0)
    if sp.issparse(cost):
        return float(np.asarray(cost.tocsr()[rows, g[rows]]).sum())
    return float(np.asarray(cost)[rows, g[rows]].sum())


def check_valid(g, n_rows, n_cols):
    assert g.dtype == np.int64 and g.shape == (n_rows,)
    used = g[g >= 0]
    assert np.unique(used).size == used.size, "a column is used twice"
    assert used.size == min(n_rows, n_cols), "the smaller side is not covered"
    assert np.all(used < n_cols)


@settings(max_examples=300, deadline=None)
@given(dense_costs(), st.booleans())
def test_dense_value_equals_scipy(cost, maximize):
    g = hope_rs.auction_assignment(cost, maximize=maximize)
    check_valid(g, *cost.shape)
    r, c = linear_sum_assignment(cost, maximize=maximize)
    want = float(cost[r, c].sum())
    tol = 1e-9 * max(1.0, float(np.abs(cost).max())) * cost.shape[0]
    assert value(cost, g) == pytest.approx(want, abs=tol)


@settings(max_examples=300, deadline=None)
@given(sparse_costs())
def test_sparse_value_equals_scipy(cost):
    n_rows, n_cols = cost.shape
    small_is_rows = n_rows <= n_cols
    ref_cost = cost if small_is_rows else cost.T.tocsr()
    try:
        # scipy minimises; explicit zeros must survive as allowed pairs, so shift values.
        shifted = ref_cost.copy()
        shifted.data = -shifted.data + (np.abs(shifted.data).max() + 1.0)
        r, c = min_weight_full_bipartite_matching(shifted)
        feasible = True
    except ValueError:
        feasible = False
    if not feasible:
        with pytest.raises(ValueError, match="no full assignment"):
            hope_rs.auction_assignment(cost)
        return
    g = hope_rs.auction_assignment(cost)
    check_valid(g, n_rows, n_cols)
    want = float(np.asarray(ref_cost[r, c]).sum())
    tol = 1e-9 * max(1.0, float(np.abs(cost.data).max())) * min(cost.shape)
    assert value(cost, g) == pytest.approx(want, abs=tol)
    # Every chosen pair must be an allowed (stored) pair.
    rows = np.flatnonzero(g >= 0)
    pattern = cost.tocsr().copy()
    pattern.data = np.ones_like(pattern.data)
    assert rows.size == 0 or np.asarray(pattern[rows, g[rows]]).min() == 1


def test_explicit_zero_is_allowed_and_missing_is_forbidden():
    cost = sp.csr_matrix(
        (np.array([0, 5, 1]), np.array([0, 0, 1]), np.array([0, 1, 3])), shape=(2, 2)
    )
    # Row 0 may only take column 0 (with value 0), so row 1 must take column 1.
    np.testing.assert_array_equal(hope_rs.auction_assignment(cost), [0, 1])


def test_equivariance_under_row_and_column_permutation():
    rng = np.random.default_rng(3)
    n = 60
    cost = rng.integers(0, 10**6, (n, n))  # wide range: the optimum is unique with near certainty
    g = hope_rs.auction_assignment(cost)
    pr, pc = rng.permutation(n), rng.permutation(n)
    g2 = hope_rs.auction_assignment(cost[pr][:, pc])
    inv_c = np.empty(n, int)
    inv_c[pc] = np.arange(n)
    np.testing.assert_array_equal(g2, inv_c[g[pr]])


def test_infeasible_reports_uncovered_rows_quickly():
    n = 100_000
    # Every row's only candidate is column 0 or 1: n - 2 rows cannot be covered.
    cols = np.arange(n) % 2
    cost = sp.csr_matrix((np.ones(n), (np.arange(n), cols)), shape=(n, n))
    with pytest.raises(ValueError, match=f"{n - 2} rows"):
        hope_rs.auction_assignment(cost)


def test_large_sparse_problem_matches_scipy():
    rng = np.random.default_rng(5)
    n, per_row = 3000, 12
    rows = np.repeat(np.arange(n), per_row)
    cols = rng.integers(0, n, rows.size)
    cols[::per_row] = rng.permutation(n)
    vals = rng.integers(0, 10**6, rows.size)
    cost = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    cost.sum_duplicates()
    g = hope_rs.auction_assignment(cost)
    check_valid(g, n, n)
    shifted = cost.copy()
    shifted.data = (10**7 - shifted.data).astype(float)
    r, c = min_weight_full_bipartite_matching(shifted)
    assert value(cost, g) == float(np.asarray(cost[r, c]).sum())


@pytest.mark.parametrize(
    "cost, err, match",
    [
        (np.array([[1.0, np.nan]]), ValueError, "NaN"),
        (np.array([[1.0, np.inf]]), ValueError, "NaN or infinite"),
        (np.ones(3), ValueError, "2-D"),
        (np.array([["a", "b"]]), TypeError, "integer or float"),
        (sp.csr_matrix(np.array([[np.nan, 1.0]])), ValueError, "NaN"),
    ],
)
def test_bad_costs(cost, err, match):
    with pytest.raises(err, match=match):
        hope_rs.auction_assignment(cost)


def test_empty_and_degenerate_shapes():
    assert hope_rs.auction_assignment(np.zeros((0, 3))).shape == (0,)
    np.testing.assert_array_equal(hope_rs.auction_assignment(np.zeros((2, 0))), [-1, -1])
    np.testing.assert_array_equal(hope_rs.auction_assignment(np.array([[7]])), [0])


def test_results_are_ordinary_numpy_arrays():
    # Arrays wrapping Rust memory refuse `flags.writeable = True`, which scipy's fancy indexing
    # sets on its views: `cost[rows, assignment]` must work on what we return.
    cost = sp.random(40, 40, density=0.3, random_state=0, format="csr") + sp.eye(40)
    m = hope_rs.auction_assignment(cost)
    assert m.flags.owndata and m.flags.writeable
    vals = np.asarray(cost[np.arange(40), m]).ravel()
    assert vals.shape == (40,) and np.all(vals > 0)
    k = hope_rs.khop_neighbourhoods(np.array([[0, 1, 2], [1, 2, 3]]), 1)
    assert k[np.array([0, 3]), np.array([1, 2])].tolist() == [[1, 1]]


def test_duplicate_entries_add_up_and_the_input_is_left_alone():
    # Row 0 stores column 1 twice (2 + 5 = 7 beats column 0's 6); row 1 only allows column 0
    # once row 0 takes column 1.
    indptr = np.array([0, 3, 5])
    indices = np.array([1, 0, 1, 0, 1], dtype=np.int32)
    for data in (np.array([2, 6, 5, 1, 0]), np.array([2.0, 6.0, 5.0, 1.0, 0.0])):
        cost = sp.csr_matrix((data.copy(), indices.copy(), indptr.copy()), shape=(2, 2))
        assert hope_rs.auction_assignment(cost).tolist() == [1, 0]
        assert cost.indices.tolist() == indices.tolist() and cost.data.tolist() == data.tolist()


def test_values_beyond_32_bits_are_solved_exactly():
    # The binding stores values that fit in 32 bits as such; wider ones take the 64-bit path.
    rng = np.random.default_rng(9)
    base = rng.integers(0, 1000, (40, 40))
    dense = base * 10**9 + 7  # spread 1e12: exact only if no value was narrowed
    r, c = linear_sum_assignment(dense, maximize=True)
    g = hope_rs.auction_assignment(sp.csr_matrix(dense))
    assert int(dense[np.arange(40), g].sum()) == int(dense[r, c].sum())

"""The warm-started exact assignment (``_core.warm_assignment_int``) against SciPy's Hungarian
solver on dense equivalents: chains of perturbed integer costs with ties, sparse and
infeasible patterns, square and wide."""

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment

import hope_rs
from hope_rs import _core

FORBIDDEN = -(10**9)


@st.composite
def cost_chains(draw):
    """(n_rows, n_cols, [dense int cost with FORBIDDEN for missing pairs] * steps)."""
    n_rows = draw(st.integers(1, 6))
    n_cols = n_rows + draw(st.integers(0, 3))
    hi = draw(st.sampled_from([1, 3, 20]))
    density = draw(st.sampled_from([1.0, 0.7, 0.4]))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    cost = rng.integers(0, hi + 1, size=(n_rows, n_cols))
    cost[rng.random(cost.shape) >= density] = FORBIDDEN
    chain = [cost]
    for _ in range(draw(st.integers(1, 3))):
        c = chain[-1].copy()
        moved = rng.random(c.shape) < 0.3
        c[moved] = rng.integers(0, hi + 1, size=int(moved.sum()))
        c[moved & (rng.random(c.shape) < 0.2)] = FORBIDDEN
        chain.append(c)
    return n_rows, n_cols, chain


def csr(cost):
    stored = cost != FORBIDDEN
    indptr = np.concatenate([[0], np.cumsum(stored.sum(axis=1))]).astype(np.int64)
    indices = np.nonzero(stored)[1].astype(np.int32)
    return indptr, indices, cost[stored].astype(np.int64)


def optimum(cost):
    """The optimal total, or None when every full assignment needs a forbidden pair."""
    r, c = linear_sum_assignment(cost, maximize=True)
    return None if (cost[r, c] == FORBIDDEN).any() else int(cost[r, c].sum())


@settings(max_examples=300, deadline=None)
@given(cost_chains())
def test_warm_chains_reach_scipys_optimum(chain):
    n_rows, n_cols, costs = chain
    prev = -np.ones(n_rows, dtype=np.int64)
    prices = np.zeros(n_cols, dtype=np.int64)
    for cost in costs:
        want = optimum(cost)
        out = _core.warm_assignment_int(*csr(cost), n_rows, n_cols, prev, prices, n_rows)
        if want is None:
            assert out is None, "an infeasible pattern is left to the full solver"
            continue
        g, p, repaired, unique = out
        assert np.unique(g).size == n_rows and (cost[np.arange(n_rows), g] != FORBIDDEN).all()
        assert int(cost[np.arange(n_rows), g].sum()) == want
        # The prices are optimal duals: with u = the assigned value minus its price, every
        # stored pair has u + price >= value; columns left free cost 0.
        u = cost[np.arange(n_rows), g] - p[g]
        stored = cost != FORBIDDEN
        assert ((u[:, None] + p[None, :] >= cost) | ~stored).all()
        free = np.setdiff1d(np.arange(n_cols), g)
        assert (p >= 0).all() and (p[free] == 0).all()
        assert 0 <= repaired <= n_rows
        if unique:
            sparse = hope_rs.auction_assignment(_as_sparse(cost), maximize=True)
            assert np.array_equal(sparse, g)
        prev, prices = g, p


def _as_sparse(cost):
    indptr, indices, data = csr(cost)
    return sp.csr_matrix((data, indices, indptr), shape=cost.shape)


def test_a_step_whose_cost_did_not_change_repairs_nothing():
    rng = np.random.default_rng(3)
    cost = rng.integers(0, 5, size=(40, 45))
    args = (*csr(cost), 40, 45)
    g, p, _, _ = _core.warm_assignment_int(
        *args, -np.ones(40, dtype=np.int64), np.zeros(45, dtype=np.int64), 40
    )
    again = _core.warm_assignment_int(*args, g, p, 0)
    assert again is not None and again[2] == 0 and np.array_equal(again[0], g)


def test_bad_warm_inputs_are_value_errors():
    cost = np.ones((2, 2), dtype=np.int64)
    args = (*csr(cost), 2, 2)
    with pytest.raises(ValueError, match="one entry per row"):
        _core.warm_assignment_int(*args, np.zeros(1, dtype=np.int64), np.zeros(2, np.int64), 2)
    with pytest.raises(ValueError, match="prices"):
        _core.warm_assignment_int(*args, np.zeros(2, dtype=np.int64), -np.ones(2, np.int64), 2)

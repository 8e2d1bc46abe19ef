"""The edge lists of a face array: every distinct edge, and the edges of one face only."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from hope_rs.geometry.mesh import _face_edges, boundary_edges, unique_edges, unique_rows


def _reference(faces):
    """The row-wise ``np.unique`` the 1-D keys stand in for."""
    u, count = np.unique(_face_edges(faces), axis=0, return_counts=True)
    return u, u[count == 1]


@given(
    arrays(np.int64, st.tuples(st.integers(0, 40), st.just(3)), elements=st.integers(0, 30)),
    st.sampled_from([np.int32, np.int64]),
)
def test_same_rows_order_and_dtype_as_rowwise_unique(faces, dtype):
    faces = faces.astype(dtype)
    want_all, want_boundary = _reference(faces)
    for got, want in ((unique_edges(faces), want_all), (boundary_edges(faces), want_boundary)):
        assert got.dtype == want.dtype
        np.testing.assert_array_equal(got, want)


def test_closed_and_open_surfaces():
    tetra = np.array([[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]])
    assert len(unique_edges(tetra)) == 6
    assert boundary_edges(tetra).shape == (0, 2)
    open_fan = tetra[:3]
    # Three faces around vertex 3: the edges of the missing face [2, 3, 0] are the boundary.
    np.testing.assert_array_equal(boundary_edges(open_fan), [[0, 2], [0, 3], [2, 3]])


@given(
    arrays(
        np.int64,
        st.tuples(st.integers(0, 30), st.integers(1, 4)),
        elements=st.integers(0, 2**20),
    ),
    st.sampled_from([np.int32, np.int64]),
    st.booleans(),
    st.booleans(),
    st.booleans(),
    st.integers(0, 5),
)
def test_unique_rows_is_rowwise_unique(rows, dtype, index, inverse, counts, repeat):
    """The one-key-per-row path gives np.unique(axis=0)'s rows, first indices, inverse and
    counts, in its order (rows repeated so that first indices are tested)."""
    rows = np.vstack([rows, rows[:repeat]]).astype(dtype)
    kw = dict(return_index=index, return_inverse=inverse, return_counts=counts)
    want = np.unique(rows, axis=0, **kw)
    want = want if isinstance(want, tuple) else (want,)
    got = unique_rows(rows, **kw)
    assert len(got) == len(want)
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g.reshape(-1), w.reshape(-1))
    assert got[0].dtype == want[0].dtype


def test_unique_rows_of_indices_too_large_for_one_key():
    rows = np.array([[2**40, 1, 2], [0, 1, 2], [2**40, 1, 2]])
    u, index = unique_rows(rows, return_index=True)
    np.testing.assert_array_equal(u, [[0, 1, 2], [2**40, 1, 2]])
    np.testing.assert_array_equal(index, [1, 0])

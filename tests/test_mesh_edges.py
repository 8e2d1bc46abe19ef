"""The edge lists of a face array: every distinct edge, and the edges of one face only."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from hope_rs.geometry.mesh import _face_edges, boundary_edges, unique_edges


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

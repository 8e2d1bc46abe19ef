"""Vertices that no face uses are left out of the match: never a target on B; on A they take
the image of the nearest vertex faces use, with confidence 0; the rest of the map is the match
of the meshes without them."""

import numpy as np
import pytest
from meshes import bumpy_sphere

import hope_rs

N = 400


def with_loose(v, f, n_loose: int, seed: int):
    """(v, f) with ``n_loose`` vertices in no face spread through the numbering (placed near
    the surface), and the new index of each old vertex."""
    rng = np.random.default_rng(seed)
    n = len(v) + n_loose
    loose = rng.choice(n, n_loose, replace=False)
    old = np.setdiff1d(np.arange(n), loose)
    out = np.empty((n, 3))
    out[old] = v
    out[loose] = v[rng.integers(0, len(v), n_loose)] * 1.01
    return out, old[f], old


@pytest.fixture(scope="module")
def pair():
    return bumpy_sphere(N, 0), bumpy_sphere(N, 1)


def test_loose_vertices_of_b_are_never_targets(pair):
    (va, fa), (vb, fb) = pair
    wb, gb, old_b = with_loose(vb, fb, 150, 2)
    res = hope_rs.match((va, fa), (wb, gb))
    plain = hope_rs.match((va, fa), (vb, fb))
    assert np.isin(res.map, old_b).all()
    np.testing.assert_array_equal(res.map, old_b[plain.map])
    np.testing.assert_array_equal(res.confidence, plain.confidence)
    assert "150 of B's vertices in no face left out" in res.stage("shapes").reason


def test_loose_vertices_of_a_take_their_neighbours_image(pair):
    (va, fa), (vb, fb) = pair
    wa, ga, old_a = with_loose(va, fa, 60, 3)
    res = hope_rs.match((wa, ga), (vb, fb))
    plain = hope_rs.match((va, fa), (vb, fb))
    np.testing.assert_array_equal(res.map[old_a], plain.map)
    np.testing.assert_array_equal(res.confidence[old_a], plain.confidence)
    loose = np.setdiff1d(np.arange(len(wa)), old_a)
    assert (res.confidence[loose] == 0).all()
    nearest = np.argmin(np.linalg.norm(wa[loose, None] - va[None], axis=2), axis=1)
    np.testing.assert_array_equal(res.map[loose], plain.map[nearest])
    assert res.quality == plain.quality  # judged on the vertices faces use
    assert res.map.shape == res.init_map.shape == res.hope_map.shape == (len(wa),)


def test_a_given_map_and_landmarks_are_carried_over(pair):
    (va, fa), (vb, fb) = pair
    wa, ga, old_a = with_loose(va, fa, 30, 4)
    wb, gb, old_b = with_loose(vb, fb, 30, 5)
    init = np.arange(N)[::-1].copy()  # some map of the plain meshes
    full = np.zeros(len(wa), dtype=np.int64)
    full[old_a] = old_b[init]
    lm = np.array([[5, 7], [100, 200]])
    res = hope_rs.match(
        (wa, ga), (wb, gb), init=full, landmarks=np.c_[old_a[lm[:, 0]], old_b[lm[:, 1]]]
    )
    plain = hope_rs.match((va, fa), (vb, fb), init=init, landmarks=lm)
    np.testing.assert_array_equal(res.map[old_a], old_b[plain.map])
    loose_b = np.setdiff1d(np.arange(len(wb)), old_b)
    with pytest.raises(ValueError, match=f"landmark vertex {loose_b[0]} of B is in no face"):
        hope_rs.match((wa, ga), (wb, gb), landmarks=[[old_a[0], loose_b[0]]])

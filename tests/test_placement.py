"""Placement starts: regions of the whole a part's match is started from."""

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from meshes import bumpy_sphere, relabel
from scipy.sparse.csgraph import dijkstra
from strategies import permutations

import hope_rs
from hope_rs import Shape
from hope_rs.evaluation.partial import cut_by_plane, plane_normal
from hope_rs.pipeline.placement import placement_regions, region_start


@pytest.fixture(scope="module")
def whole():
    return Shape(hope_rs.Mesh(*bumpy_sphere(600, 3)))


def _distances(b: Shape, source: int) -> np.ndarray:
    p, e = b.points, b.edges
    w = np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1)
    g = sp.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(b.n_vertices,) * 2).tocsr()
    return dijkstra(g, directed=False, indices=source)


def _ball_centre(b: Shape, r: np.ndarray):
    """The vertex of ``r`` whose ``r.size`` nearest vertices (along edges) are ``r``, and its
    distances; ``None`` when there is none."""
    for c in r:
        d = _distances(b, int(c))
        if np.isin(np.argsort(d, kind="stable")[: r.size], r).all():
            return int(c), d
    return None


@pytest.mark.parametrize("share", [0.3, 0.5, 0.7])
def test_each_region_is_the_ball_around_its_centre_holding_the_share(whole, share):
    area = whole.internal.vertex_areas
    regions = placement_regions(whole, share, 5)
    assert len(regions) == 5
    centres = []
    for r in regions:
        found = _ball_centre(whole, r)
        assert found is not None, "the region is no ball around one of its vertices"
        centres.append(found[0])
        # The smallest ball holding the share: without its farthest vertex it holds less.
        farthest = r[np.argmax(found[1][r])]
        assert area[r].sum() / area.sum() >= share - 1e-9
        assert (area[r].sum() - area[farthest]) / area.sum() < share
    assert len(set(centres)) == 5  # spread: no centre twice


def test_the_centres_spread_each_farthest_from_those_before(whole):
    regions = placement_regions(whole, 0.02, 4)
    # With a tiny share each region is its centre's small ball; the balls are far apart.
    for i, r in enumerate(regions):
        for other in regions[i + 1 :]:
            assert not np.isin(r, other).any()


@settings(max_examples=5, deadline=None)
@given(data=st.data())
def test_regions_follow_the_surface_not_the_numbering(data):
    v, f = bumpy_sphere(300, 5)
    perm = data.draw(permutations(len(v)))
    a = Shape(hope_rs.Mesh(v, f))
    b = Shape(hope_rs.Mesh(v[perm], relabel(f, perm)))
    ra, rb = placement_regions(a, 0.4, 3), placement_regions(b, 0.4, 3)
    for x, y in zip(ra, rb):
        np.testing.assert_array_equal(a.points[x], b.points[y])


def test_a_region_start_sends_every_vertex_to_its_nearest_descriptor_in_the_region(whole):
    part = Shape(cut_by_plane(whole.mesh, plane_normal(2), 0.5).mesh).at_scale(whole.scale)
    (region,) = placement_regions(whole, 0.5, 1)
    g = region_start(part, whole, region, "shot")
    assert np.isin(g, region).all()
    da, db = part.internal_descriptors("shot"), whole.internal_descriptors("shot")
    d = ((da[:, None, :] - db[None, region, :]) ** 2).sum(axis=2)
    best = d.min(axis=1)
    np.testing.assert_allclose(((da - db[g]) ** 2).sum(axis=1), best, rtol=1e-5, atol=1e-9)


def test_a_share_of_everything_is_the_whole_surface(whole):
    (r,) = placement_regions(whole, 1.0, 1)
    assert r.size >= whole.n_vertices - 1

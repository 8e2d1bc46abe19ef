"""SHOT on dense meshes: one descriptor per grid cell, computed at the cell's site."""

import numpy as np
from meshes import renumbered, subdivided

import hope_rs
from hope_rs import _core
from hope_rs.features.descriptors import DescriptorConfig
from hope_rs.geometry import sites as S
from hope_rs.geometry.numbering import canonical_mesh
from hope_rs.geometry.sites import SiteConfig
from hope_rs.pipeline.initial import initial_map, shapes_initial_map
from hope_rs.shape import ShapeConfig

SHOT_RADIUS = DescriptorConfig().shot_radius
#: Cells wide enough that the 6890-vertex FAUST meshes use sites (2.7 vertices each).
COARSE_SITES = ShapeConfig(descriptors=DescriptorConfig(sites=SiteConfig(spacing=0.25)))


def test_grid_cells_group_exactly_the_vertices_of_one_grid_cell():
    rng = np.random.default_rng(3)
    v = rng.random((3000, 3)) * [2.0, 1.0, 0.5]
    side = 0.1
    cells = S.grid_cells(v, side)
    # The Morton grid spans the box's longest side (just under 2) with 2^level cells, level the
    # least that makes a cell at most `side` wide: 2^5 cells of about 0.0625.
    span = (v.max(axis=0) - v.min(axis=0)).max()
    width = span / 2**5
    top = (1 << S.MORTON_BITS) - 1
    q = np.floor((v - v.min(axis=0)) / span * top).astype(np.int64) >> (S.MORTON_BITS - 5)
    want = {tuple(c) for c in q}
    assert np.unique(cells).size == len(want)
    for c in np.unique(cells)[:50]:
        members = q[cells == c]
        assert (members == members[0]).all()
        pts = v[cells == c]
        assert (pts.max(axis=0) - pts.min(axis=0) <= width + 1e-12).all()


def test_each_site_is_the_member_nearest_its_cells_centroid():
    rng = np.random.default_rng(4)
    v = rng.random((500, 3))
    cells = rng.integers(0, 40, 500).astype(np.uint64)
    sites, owner = S.cell_sites(v, cells)
    assert sites.size == np.unique(cells).size
    np.testing.assert_array_equal(cells[sites][owner], cells)
    for k, s in enumerate(sites):
        members = np.flatnonzero(owner == k)
        d = ((v[members] - v[members].mean(axis=0)) ** 2).sum(axis=1)
        assert s == members[np.argmin(d)]


def test_sparse_meshes_keep_one_descriptor_per_vertex(faust_pair):
    a, _ = faust_pair
    assert S.shot_sites(a, SHOT_RADIUS) is None
    assert hope_rs.Shape(a).descriptor_sites("shot") is None
    assert hope_rs.Shape(a).descriptor_sites("wks") is None


def test_vertices_share_the_full_descriptor_of_their_site(faust_pair):
    a, _ = faust_pair
    shape = hope_rs.Shape(a, config=COARSE_SITES)
    sites, owner = shape.descriptor_sites("shot")
    assert 1000 < sites.size < a.n_vertices / 2
    m = shape.internal
    full = _core.shot_descriptors(m.vertices, m.faces, SHOT_RADIUS * m.scale).reshape(-1, 352)
    d = shape.internal_descriptors("shot")
    assert np.array_equal(d, full[sites][owner])
    site_config = COARSE_SITES.descriptors.sites
    canon = shape.internal
    assert np.array_equal(S.shot_sites(canon, SHOT_RADIUS, site_config)[0], sites)
    # The sites depend on the geometry only: a renumbered copy gets the same descriptors.
    b, perm = renumbered(a, np.random.default_rng(5))
    renumbered_shape = hope_rs.Shape(b, config=COARSE_SITES)
    assert np.array_equal(renumbered_shape.descriptors("shot"), shape.descriptors("shot")[perm])


def test_match_from_sites_recovers_the_same_connectivity_pair(faust_pair):
    a, b = faust_pair
    sa, sb = hope_rs.Shape(a, config=COARSE_SITES), hope_rs.Shape(b, config=COARSE_SITES)
    res = hope_rs.match(sa, sb)
    # Every vertex of A starts at a site of B, the same one as the rest of its cell.
    site_a, site_b = sa.descriptor_sites(), sb.descriptor_sites()
    f0 = sa.map_in(sb, res.init_map)
    assert np.isin(f0, site_b[0]).all()
    assert (f0 == f0[site_a[0]][site_a[1]]).all()
    e0 = hope_rs.geodesic_errors(sb, res.init_map)
    assert e0.mean() < 0.15  # about 0.11, against 0.074 with every vertex described
    assert np.mean(hope_rs.geodesic_errors(sb, res.map) == 0) == 1.0


def test_sites_follow_the_density_not_the_scale(faust_pair):
    a, _ = faust_pair
    v, f = subdivided(a.vertices, a.faces)
    once = S.shot_sites(canonical_mesh(hope_rs.Mesh(v, f))[0], SHOT_RADIUS)
    assert once is None  # 27k vertices, 18k cells: not dense enough to pay
    v, f = subdivided(v, f)
    counts = []
    for scale in (1.0, 37.0):
        dense = canonical_mesh(hope_rs.Mesh(v * scale, f))[0]
        sites, owner = S.shot_sites(dense, SHOT_RADIUS)
        assert sites.size < dense.n_vertices / SiteConfig().min_vertices_per_site
        assert np.bincount(owner).min() >= 1
        counts.append(sites.size)
    assert counts[0] == counts[1]


def test_initial_map_between_a_dense_and_a_sparse_shape(faust_pair):
    a, b = faust_pair
    sa = hope_rs.Shape(a, config=COARSE_SITES)
    sites, owner = sa.descriptor_sites()
    da = sa.internal_descriptors("shot")
    sb = hope_rs.Shape(b)
    assert sb.descriptor_sites() is None
    db = sb.internal_descriptors("shot")
    g = shapes_initial_map(sa, sb, da, db, "shot")
    assert g.shape == (a.n_vertices,) and (g == g[sites][owner]).all()
    # The sites are matched against every vertex of B.
    np.testing.assert_array_equal(g[sites], initial_map(da[sites], db))
    # B's descriptors are per vertex: the map reaches beyond any one set of sites.
    assert np.unique(g).size > sites.size / 2

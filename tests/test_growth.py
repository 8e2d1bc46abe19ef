"""Growing the trusted part of a map (hope_rs.pipeline.growth and _core.grow_across_faces)."""

import numpy as np
import pytest
from conftest import data_path, default_match
from meshes import bumpy_sphere, drifted, flat_grid, moved_copy, subdivided

import hope_rs
from hope_rs import _core
from hope_rs.pipeline import growth
from hope_rs.pipeline import shared_faces as SF
from hope_rs.pipeline.anchors import firm_regions
from hope_rs.pipeline.config import GrowthConfig
from hope_rs.pipeline.handles import irregular_vertices, seed_handles


def flip_edges(faces: np.ndarray, inside: np.ndarray, rng) -> np.ndarray:
    """``faces`` with about half the edges between two ``inside`` vertices flipped (each face
    in at most one flip): a retriangulated patch on the same vertices."""
    faces = faces.copy()
    where = {}
    for t, (p, q, r) in enumerate(faces):
        for u, v in ((p, q), (q, r), (r, p)):
            where[(u, v)] = t
    edges = {tuple(sorted(e)) for e in where}
    busy = np.zeros(len(faces), dtype=bool)
    for u, v in rng.permutation(sorted(edges)):
        if not (inside[u] and inside[v]) or rng.random() < 0.5:
            continue
        t1, t2 = where[(u, v)], where[(v, u)]
        if busy[t1] or busy[t2]:
            continue
        x = next(w for w in faces[t1] if w not in (u, v))
        y = next(w for w in faces[t2] if w not in (u, v))
        if (x, y) in where or (y, x) in where:
            continue
        # (u, v, x) and (v, u, y) bound the quad u, y, v, x; its other diagonal is y-x.
        faces[t1], faces[t2] = (u, y, x), (y, v, x)
        busy[[t1, t2]] = True
    return faces


@pytest.fixture(scope="module")
def stretched_patch(faust_pair):
    """A = FAUST 012; B = A relabelled and moved, its right half stretched by up to 30% and a
    ball of A's vertices retriangulated; f = the truth with that ball shifted along faces."""
    a = faust_pair[0]
    b, truth = moved_copy(a, 5)
    rng = np.random.default_rng(6)
    v = a.vertices
    ball = np.linalg.norm(v - v[3000], axis=1) < 0.2 * a.scale
    faces = flip_edges(a.faces, ball, rng)
    x = (v[:, 0] - v[:, 0].min()) / np.ptp(v[:, 0])
    bent = v * (1.0 + 0.3 * x**2)[:, None]
    # The same vertices as A, retriangulated and stretched, in B's numbering and pose.
    order = np.argsort(truth)  # B's vertex i is A's vertex order[i]
    pose = np.linalg.lstsq(np.c_[v, np.ones(len(v))], b.vertices[truth], rcond=None)[0]
    b = hope_rs.Mesh(np.c_[bent, np.ones(len(v))][order] @ pose, truth[faces])
    return a, b, truth, ball, drifted(a, truth, 3000, 0.2)


def test_growth_rebuilds_a_stretched_retriangulated_patch(stretched_patch, monkeypatch):
    a, b, truth, ball, f = stretched_patch
    sa, sb = hope_rs.Shape(a), hope_rs.Shape(b)
    assert (f[ball] == truth[ball]).mean() < 0.1  # measured 8.8%
    assert 0.05 < ball.mean() < 0.3
    g = sa.map_out(sb, growth.grow(sa, sb, sa.map_in(sb, f)))
    np.testing.assert_array_equal(g[~ball], truth[~ball])
    exact = (g[ball] == truth[ball]).mean()
    assert exact > 0.95  # measured 99.9%
    # Across faces alone, the retriangulated ball is not rebuilt as well.
    monkeypatch.setattr(growth._AffineGrowth, "grow", lambda self, g, accept, ratio: g)
    faces_only = sa.map_out(sb, growth.grow(sa, sb, sa.map_in(sb, f)))
    assert (faces_only[ball] == truth[ball]).mean() < exact - 0.1  # measured 21%


def test_only_handle_patches_above_the_seed_share_seed():
    s = hope_rs.Shape(bumpy_sphere(2000, 3))
    z = s.points[:, 2]
    order = np.argsort(-z)
    cap, band = order[:35], order[35:135]  # 1.75% of the vertices, then a ring below them
    f = np.arange(s.n_vertices)
    f[band[0::2]], f[band[1::2]] = band[1::2], band[0::2]  # the ring's images swapped in pairs
    handles = SF.face_handles(s, s, f)
    seeds = seed_handles(s, s, f, GrowthConfig().seed_share)
    in_cap = np.zeros(s.n_vertices, dtype=bool)
    in_cap[cap] = True
    assert handles[cap].sum() >= 5 and not seeds[cap].any()  # 8 handles in the cap
    np.testing.assert_array_equal(seeds, handles & ~in_cap)
    assert seeds.mean() > 0.8


def test_midpoints_of_a_subdivided_mesh_are_regular_and_its_other_vertices_keep_their_degree():
    v, f = bumpy_sphere(300, 1)
    degree = np.bincount(f.ravel(), minlength=len(v))
    s = hope_rs.Shape(hope_rs.Mesh(*subdivided(*subdivided(v, f))))
    irregular = irregular_vertices(s)[s.rank]  # input numbering: the original vertices first
    np.testing.assert_array_equal(irregular[: len(v)], degree != 6)
    assert not irregular[len(v) :].any() and irregular.any()


def test_a_shifted_lattice_patch_does_not_seed_but_the_pinned_map_does():
    n = 30
    s = hope_rs.Shape(hope_rs.Mesh(*flat_grid(n)))
    i, j = np.divmod(np.arange(n * n), n)
    inside = (i > 0) & (i < n - 1) & (j > 0) & (j < n - 1)
    shift = np.where(inside, np.arange(n * n) + n, np.arange(n * n))  # inside: one row on
    shifted = s.rank[shift[s.order]]  # internal numbering, like s.rank[identity[s.order]]
    share = GrowthConfig().seed_share
    lattice = seed_handles(s, s, shifted, share, 0)  # by size alone: the inside, shifted
    assert lattice.mean() > 0.7 and not irregular_vertices(s)[lattice].any()
    assert not seed_handles(s, s, shifted, share, GrowthConfig().seed_irregular).any()
    # The true map's patch holds the grid's corners (fewer than six faces): it seeds.
    same = np.arange(n * n)
    assert seed_handles(s, s, same, share, GrowthConfig().seed_irregular).all()


def test_patches_shifted_against_a_larger_one_do_not_seed_and_the_growth_undoes_them():
    # Alternating diagonals make every vertex irregular (degree 4 or 8), and a shift by an
    # even number of edges keeps faces: a shifted band is a patch of handles that is pinned.
    n = 33
    s = hope_rs.Shape(hope_rs.Mesh(*flat_grid(n, alternate=True)))
    i, j = np.divmod(np.arange(n * n), n)
    band = (i >= 2) & (i <= 9) & (j <= n - 3)
    shift = np.where(band, np.arange(n * n) + 2, np.arange(n * n))  # two columns on
    f = s.rank[shift[s.order]]  # internal numbering
    cfg = GrowthConfig()
    seeds = seed_handles(s, s, f, cfg.seed_share, cfg.seed_irregular)
    label, sizes = firm_regions(s, seeds)
    assert (sizes >= cfg.seed_share * n * n).sum() >= 2  # the band and the rest both seed
    kept = growth.agreeing_patches(s, s, f, seeds, cfg.face_error)
    in_band = band[s.order]
    assert kept[seeds & ~in_band].all() and not kept[in_band].any()
    np.testing.assert_array_equal(growth.grow(s, s, f, cfg), np.arange(n * n))


def test_patches_of_one_map_all_seed():
    n = 33
    s = hope_rs.Shape(hope_rs.Mesh(*flat_grid(n, alternate=True)))
    f = np.arange(n * n)
    f[s.rank[np.arange(16 * n, 17 * n)]] = -1  # a middle row unknown: two identity patches
    cfg = GrowthConfig()
    seeds = seed_handles(s, s, f, cfg.seed_share, cfg.seed_irregular)
    assert len(np.unique(firm_regions(s, seeds)[0][seeds])) == 2
    np.testing.assert_array_equal(growth.agreeing_patches(s, s, f, seeds, cfg.face_error), seeds)


def test_partial_maps_invert_and_their_unknown_vertices_are_not_handles():
    s = hope_rs.Shape(bumpy_sphere(300, 4))
    f = np.random.default_rng(5).permutation(s.n_vertices)
    f[::7] = -1
    back = growth._inverse(f, s.n_vertices)
    np.testing.assert_array_equal(growth._inverse(back, s.n_vertices), f)
    assert (back >= 0).sum() == (f >= 0).sum()
    ident = np.arange(s.n_vertices)
    ident[::7] = -1
    h = SF.face_handles(s, s, ident)
    faces = s.internal.faces
    touching = np.unique(faces[(ident[faces] < 0).any(axis=1)])
    assert not h[touching].any() and h[np.setdiff1d(np.arange(s.n_vertices), touching)].all()


def test_grow_across_faces_rejects_bad_input():
    p = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    f = np.array([[0, 1, 2], [1, 3, 2]])
    ok = _core.grow_across_faces(f, p, f, p, np.array([0, 1, -1, -1]), 0.5)
    np.testing.assert_array_equal(ok, [0, 1, 2, 3])
    with pytest.raises(ValueError, match="one-to-one"):
        _core.grow_across_faces(f, p, f, p, np.array([0, 0, -1, -1]), 0.5)
    with pytest.raises(ValueError, match="vertices of B"):
        _core.grow_across_faces(f, p, f, p, np.array([0, 7, -1, -1]), 0.5)
    with pytest.raises(ValueError, match="one entry per vertex"):
        _core.grow_across_faces(f, p, f, p, np.array([0, 1]), 0.5)
    with pytest.raises(ValueError, match="max_error"):
        _core.grow_across_faces(f, p, f, p, np.array([0, 1, -1, -1]), float("nan"))
    with pytest.raises(ValueError, match=r"\(M, 3\)"):
        _core.grow_across_faces(f[:, :2], p, f, p, np.array([0, 1, -1, -1]), 0.5)
    with pytest.raises(ValueError, match="index"):
        _core.grow_across_faces(f + 5, p, f, p, np.array([0, 1, -1, -1]), 0.5)


@pytest.mark.slow
@pytest.mark.parametrize("a, b", [("cat0", "cat6"), ("cat6", "cat0")])
def test_the_tosca_cat_is_matched_above_95_percent_exact(a, b):
    # The goal on its one TOSCA pair (the ground truth is the identity). Measured
    # 98.0% / 97.6% exact; without the growth 71.5% / 68.6%. (cat0 -> cat6 is a golden map's
    # pair too: the match is made once per test process.)
    ma, _, res = default_match(data_path("tosca", f"{a}.off"), data_path("tosca", f"{b}.off"))
    assert "faces" in res.timings
    assert (res.map == np.arange(ma.n_vertices)).mean() > 0.95

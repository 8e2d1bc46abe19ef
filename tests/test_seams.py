"""A surface split along seams (vertices duplicated for texture coordinates or normals, or a
triangle soup with every corner separate) or stored twice (a double-sided export, each face
reversed on its own copies of the vertices) is matched as one closed surface: the copies are
welded for the match, each copy of A takes its first copy's image and confidence, and a copy
of B is never a target; the map is the one of the plain mesh."""

import numpy as np
import pytest
from conftest import data_path
from meshes import bumpy_sphere

import hope_rs
from hope_rs.geometry.mesh import seam_edges, seam_welds


def split_along_equator(v, f, above: float = 0.0):
    """(v, f) with the faces above the equator (or the height ``above``) given their own
    copies of the vertices they share with the faces below (a closed seam), and per new
    vertex the old vertex it copies."""
    up = v[f].mean(axis=1)[:, 2] > above
    shared = np.intersect1d(f[up].ravel(), f[~up].ravel())
    copy = np.full(len(v), -1)
    copy[shared] = len(v) + np.arange(shared.size)
    g = f.copy()
    g[up] = np.where(copy[f[up]] >= 0, copy[f[up]], f[up])
    return np.vstack([v, v[shared]]), g, np.concatenate([np.arange(len(v)), shared])


def soup(v, f):
    """Every face with its own three corners, and per corner the vertex it copies."""
    of = f.ravel()
    return v[of], np.arange(of.size).reshape(-1, 3), of


@pytest.fixture(scope="module")
def pair():
    return bumpy_sphere(400, 0), bumpy_sphere(400, 1)


@pytest.fixture(scope="module")
def plain(pair):
    (va, fa), (vb, fb) = pair
    return hope_rs.match((va, fa), (vb, fb))


def test_a_seam_is_found_and_welded_to_the_first_copy(pair):
    (v, f), _ = pair
    w, g, of = split_along_equator(v, f)
    mesh = hope_rs.Mesh(w, g)
    copies = np.arange(len(v), len(w))
    assert copies.size > 10
    assert seam_edges(mesh) == 2 * copies.size  # the loop's edges, once on each side
    weld = seam_welds(mesh)
    np.testing.assert_array_equal(weld, of)
    # Coincident vertices that close no seam stay apart: an unused copy, and two spheres
    # touching at one vertex (a pinch, not a seam).
    assert (seam_welds(hope_rs.Mesh(np.vstack([v, v[:1]]), f)) == np.arange(len(v) + 1)).all()
    touching = hope_rs.Mesh(np.vstack([v, 2 * v[0] - v]), np.vstack([f, f + len(v)]))
    assert seam_edges(touching) == 0
    np.testing.assert_array_equal(seam_welds(touching), np.arange(2 * len(v)))
    # tr_reg_003 is folded onto itself at two spots (two faces on the same positions, edges
    # on edges, within its one piece): not a seam, kept as the benchmark has it.
    m003 = hope_rs.load_mesh(data_path("faust_r", "tr_reg_003.off"))
    assert len(np.unique(m003.vertices, axis=0)) < m003.n_vertices
    np.testing.assert_array_equal(seam_welds(m003), np.arange(m003.n_vertices))


def test_a_seam_on_a_is_matched_closed(pair, plain):
    (va, fa), (vb, fb) = pair
    w, g, of = split_along_equator(va, fa)
    res = hope_rs.match((w, g), (vb, fb))
    np.testing.assert_array_equal(res.map, plain.map[of])
    np.testing.assert_array_equal(res.confidence, plain.confidence[of])
    assert res.quality == plain.quality
    n = len(w) - len(va)
    assert f"{n} of A's vertices welded to their copies along seams" in res.stage("shapes").reason


def test_a_seam_on_b_is_matched_closed_and_its_copies_are_never_targets(pair, plain):
    (va, fa), (vb, fb) = pair
    w, g, _ = split_along_equator(vb, fb)
    res = hope_rs.match((va, fa), (w, g))
    np.testing.assert_array_equal(res.map, plain.map)
    assert res.map.max() < len(vb)


def test_landmarks_and_a_given_map_on_copies_are_matched_through_the_first_copy(pair):
    (va, fa), (vb, fb) = pair
    wa, ga, of_a = split_along_equator(va, fa)
    wb, gb, of_b = split_along_equator(vb, fb)
    ca, cb = len(va), len(vb)  # the first copies made: vertex ca copies of_a[ca]
    marks = np.array([[ca, cb], [5, 7]])
    got = hope_rs.match((wa, ga), (wb, gb), landmarks=marks, spectral=False)
    want = hope_rs.match(
        (va, fa), (vb, fb), landmarks=[[of_a[ca], of_b[cb]], [5, 7]], spectral=False
    )
    # The same map, but that a landmark keeps its own copy of B's vertex (the same point).
    expected = want.map[of_a]
    expected[ca] = cb
    np.testing.assert_array_equal(got.map, expected)
    init = np.arange(len(wa)) % len(wb)  # images on copies of B too
    got = hope_rs.match((wa, ga), (wb, gb), init=init, spectral=False)
    want = hope_rs.match((va, fa), (vb, fb), init=of_b[init[: len(va)]], spectral=False)
    np.testing.assert_array_equal(got.map, want.map[of_a])


def test_a_triangle_soup_is_matched_as_the_mesh_it_comes_from():
    # A real pair given as soups (trimesh.load(stl, process=False) gives one): the same map,
    # each corner answering for the vertex it copies.
    a = hope_rs.load_mesh(data_path("faust_r", "tr_reg_000.off"))
    b = hope_rs.load_mesh(data_path("faust_r", "tr_reg_001.off"))
    plain = hope_rs.match(a, b)
    sa, sb = soup(a.vertices, a.faces), soup(b.vertices, b.faces)
    res = hope_rs.match(sa[:2], sb[:2])
    np.testing.assert_array_equal(sb[2][res.map], plain.map[sa[2]])
    np.testing.assert_array_equal(res.confidence, plain.confidence[sa[2]])
    assert not res.quality.likely_failed


def test_a_double_sided_mesh_is_matched_as_one_surface(pair, plain):
    # Each face also listed reversed on its own copies of the vertices (exporters do this to
    # give back faces their own normals): two closed surfaces at one place, no boundary.
    (va, fa), (vb, fb) = pair
    n = len(va)
    twice = (np.vstack([va, va]), np.vstack([fa, fa[:, ::-1] + n]))
    assert seam_edges(hope_rs.Mesh(*twice)) > 0
    res = hope_rs.match(twice, (vb, fb))
    np.testing.assert_array_equal(res.map, np.concatenate([plain.map, plain.map]))
    np.testing.assert_array_equal(res.confidence[n:], plain.confidence)
    m = len(vb)
    res = hope_rs.match((va, fa), (np.vstack([vb, vb]), np.vstack([fb, fb[:, ::-1] + m])))
    np.testing.assert_array_equal(res.map, plain.map)


def test_faces_collapsed_to_a_point_weld_nothing():
    # Every corner at one position: its edges have length 0 and lie on nothing (the mesh
    # stays as given, and match names its zero area).
    point = hope_rs.Mesh(np.zeros((3, 3)), [[0, 1, 2]])
    assert seam_edges(point) == 0
    np.testing.assert_array_equal(seam_welds(point), [0, 1, 2])
    with pytest.raises(ValueError, match="zero surface area"):
        hope_rs.match(point, point)


def test_welds_and_pieces_on_awkward_meshes(pair):
    from hope_rs.geometry.mesh import face_pieces
    from hope_rs.pipeline.unreferenced import _loose, body_vertices

    # A face with a repeated corner lies on an edge without making it an edge of three
    # faces: the two real faces there stay one piece.
    assert face_pieces(np.array([[0, 1, 2], [1, 3, 2], [1, 1, 2]]))[:2].tolist() == [0, 0]
    # Every corner repeated: nothing to weld, and match names the zero area.
    with pytest.raises(ValueError, match="zero surface area"):
        hope_rs.match((np.zeros((2, 3)), [[0, 0, 0]]), (np.zeros((2, 3)), [[0, 0, 0]]))
    # A vertex in no face at a seam's position is not the copy the others weld to.
    (v, f), _ = pair
    w, g, of = split_along_equator(v, f)
    at = len(v)  # the first copy; an unused vertex placed first at its position
    w2 = np.vstack([w[at], w])
    g2 = g + 1
    weld = seam_welds(hope_rs.Mesh(w2, g2))
    assert weld[0] == 0 and weld[at + 1] == of[at] + 1
    # A double-sided card on the same vertices counts its area once.
    card = np.array([[3.0, 0, 0], [3.05, 0, 0], [3.0, 0.05, 0]])
    vv = np.vstack([v, card])
    m = len(v)
    once = hope_rs.Mesh(vv, np.vstack([f, [[m, m + 1, m + 2]]]))
    twice = hope_rs.Mesh(vv, np.vstack([f, [[m, m + 1, m + 2], [m + 2, m + 1, m]]]))
    share = 0.5 * 0.05**2 / once.area
    limit = 1.5 * share
    assert _loose(once, limit)[-1] and _loose(twice, limit)[-2:].all()
    # body_vertices (what show colours) welds as the match does: a small island cut off by
    # a seam (its faces under 0.5% of the area) is kept, not taken for debris.
    top = np.sort(v[f].mean(axis=1)[:, 2])[-4]
    wi, gi, _ = split_along_equator(v, f, above=top - 1e-9)
    island = hope_rs.Mesh(wi, gi)
    assert _loose(island, 0.005).any()  # unwelded, the island is a small piece
    assert body_vertices(island, 0.005).all()


def test_landmarks_on_copies_with_different_partners_are_refused(pair):
    (va, fa), (vb, fb) = pair
    w, g, of = split_along_equator(va, fa)
    copy = len(va)
    with pytest.raises(ValueError, match=r"copies of one vertex of A \(welded along a seam\)"):
        hope_rs.match((w, g), (vb, fb), landmarks=[[of[copy], 5], [copy, 9]])

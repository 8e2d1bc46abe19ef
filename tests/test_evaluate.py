"""The scorer on cases with known answers."""

import warnings

import numpy as np
import pytest
from conftest import data_path

import hope_rs
from hope_rs.evaluation.evaluate import (
    curve_auc,
    error_curve,
    geodesic_errors,
    load_vts,
    score,
    smoothness,
    surface_distances,
)

pytest.importorskip("potpourri3d")


def grid(n: int, h: float = 1.0) -> hope_rs.Mesh:
    """An n x n flat grid of spacing h, every square split along the same diagonal."""
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    v = np.stack([ii.ravel() * h, jj.ravel() * h, np.zeros(n * n)], axis=1)
    q = (ii[:-1, :-1] * n + jj[:-1, :-1]).ravel()
    f = np.concatenate([np.stack([q, q + n, q + n + 1], 1), np.stack([q, q + n + 1, q + 1], 1)])
    return hope_rs.Mesh(v, f)


def shifted(n: int, di: int, dj: int) -> tuple[np.ndarray, np.ndarray]:
    """The map (i, j) -> (i + di, j + dj) on the grid, and the vertices where it stays inside."""
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    ok = ((ii + di < n) & (jj + dj < n)).ravel()
    f = np.arange(n * n)
    f[ok] = ((ii + di) * n + jj + dj).ravel()[ok]
    return f, np.flatnonzero(ok)


@pytest.mark.parametrize("method", ["graph", "surface"])
def test_identity_map_has_zero_error(method):
    m = grid(8)
    e = geodesic_errors(m, np.arange(m.n_vertices), method=method)
    assert e.shape == (64,) and np.all(e == 0)
    s = score(e)
    assert (s.exact, s.mean, s.auc, s.auc_010) == (1.0, 0.0, 1.0, 1.0)


@pytest.mark.parametrize("method", ["graph", "surface"])
def test_one_ring_shift_costs_one_edge(method):
    n, h = 10, 0.5
    m = grid(n, h)
    f, scored = shifted(n, 1, 0)
    e = geodesic_errors(m, f, a_idx=scored, method=method)
    np.testing.assert_allclose(e, h / np.sqrt(m.area))  # area = ((n - 1) h)^2
    assert score(e).exact == 0.0


def test_surface_geodesics_are_exact_on_a_flat_grid_where_graph_paths_are_not():
    n = 12
    m = grid(n)
    f, scored = shifted(n, 1, 2)  # a knight's move: straight-line length sqrt(5)
    exact = np.sqrt(5) / np.sqrt(m.area)
    surf = geodesic_errors(m, f, a_idx=scored, method="surface")
    graph = geodesic_errors(m, f, a_idx=scored, method="graph")
    np.testing.assert_allclose(surf, exact, rtol=1e-9)
    np.testing.assert_allclose(graph, (1 + np.sqrt(2)) / np.sqrt(m.area))  # the zigzag along edges
    # Long straight lines in every direction from one corner.
    src = np.zeros(n * n, dtype=np.int64)
    d = surface_distances(m, src, np.arange(n * n))
    np.testing.assert_allclose(d, np.linalg.norm(m.vertices, axis=1), atol=1e-9)


def test_surface_geodesics_follow_great_circles_on_a_sphere():
    trimesh = pytest.importorskip("trimesh")
    s = trimesh.creation.icosphere(subdivisions=4)  # 2562 vertices on the unit sphere
    m = hope_rs.Mesh(s.vertices, s.faces)
    rng = np.random.default_rng(0)
    src, dst = rng.integers(0, m.n_vertices, (2, 200))
    truth = np.arccos(np.clip(np.einsum("ij,ij->i", m.vertices[src], m.vertices[dst]), -1, 1))
    surf = surface_distances(m, src, dst)
    far = truth > 0.3
    rel = np.abs(surf[far] - truth[far]) / truth[far]
    assert rel.max() < 0.01, rel.max()  # polyhedral vs smooth sphere: well under 1%


def test_surface_never_exceeds_graph_on_a_real_remeshed_shape():
    root = data_path("faust_r")
    b = hope_rs.load_mesh(root / "tr_reg_001.off")
    gt = load_vts(root / "corres" / "tr_reg_001.vts")[:300]
    rng = np.random.default_rng(1)
    f = rng.integers(0, b.n_vertices, b.n_vertices)
    g = geodesic_errors(b, f, a_idx=gt, b_idx=gt, method="graph")
    s = geodesic_errors(b, f, a_idx=gt, b_idx=gt, method="surface")
    assert np.all(s <= g + 1e-12)
    assert 0.85 < s.mean() / g.mean() < 1.0  # graph paths run a few percent long


def test_unknown_method_is_refused():
    with pytest.raises(ValueError, match="method must be one of"):
        geodesic_errors(grid(3), np.arange(9), method="exact-ish")


def test_vts_files_are_one_based(tmp_path):
    p = tmp_path / "a.vts"
    p.write_text("1\n5\n3\n")
    np.testing.assert_array_equal(load_vts(p), [0, 4, 2])
    (tmp_path / "b.vts").write_text("0\n2\n")
    with pytest.raises(ValueError, match="1-based"):
        load_vts(tmp_path / "b.vts")
    (tmp_path / "c.vts").write_text("1\nx\n")
    with pytest.raises(ValueError, match="cannot read"):
        load_vts(tmp_path / "c.vts")
    (tmp_path / "d.vts").write_text("1 5\n2 6\n")  # a landmark file, not a .vts
    with pytest.raises(ValueError, match="has 2 values"):
        load_vts(tmp_path / "d.vts")


@pytest.mark.parametrize(
    "content, message",
    [
        ("1\n2\nx\n", r"bad\.vts:3: cannot read 'x' as a vertex index"),
        ("1 2\n3\n", r"bad\.vts:1: '1 2' has 2 values; a \.vts file has one"),
        ("# c\n1\n\n0\n", r"bad\.vts:4: index 0 is below 1; \.vts files are 1-based"),
        ("1\n1_0\n", r"bad\.vts:2: cannot read '1_0'"),
        ("1\r\n2.0\r\n", r"bad\.vts:2: cannot read '2\.0'"),
        ("1\n99999999999999999999\n", r"bad\.vts:2: vertex index '9+' is too large"),
        ("", r"bad\.vts' has no vertex indices"),
        ("# only a comment\n\n", r"bad\.vts' has no vertex indices"),
    ],
)
def test_bad_vts_files_name_the_file_and_line(tmp_path, content, message):
    path = tmp_path / "bad.vts"
    path.write_text(content)
    with pytest.raises(ValueError, match=message) as err:
        load_vts(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_vts_comments_blank_lines_signs_and_a_bom_are_read(tmp_path):
    path = tmp_path / "a.vts"
    path.write_bytes(b"\xef\xbb\xbf# header\r\n+3\r\n\r\n 1 # first\r\n2\r\n")
    got = load_vts(path)
    assert got.dtype == np.int64
    np.testing.assert_array_equal(got, [2, 0, 1])


def test_vts_files_of_the_shared_data_index_vertices():
    root = data_path("faust_r")
    idx = load_vts(root / "corres" / "tr_reg_000.vts")
    n = hope_rs.load_mesh(root / "tr_reg_000.off").n_vertices
    assert idx.min() >= 0 and idx.max() < n and idx.size == 5000


def test_curve_and_areas_of_known_errors():
    e = np.array([0.0, 0.05, 0.2, 1.0])
    t, c = error_curve(e)
    assert t[0] == 0 and t[-1] == 0.25 and c[0] == 0.25 and c[-1] == 0.75
    assert c[np.searchsorted(t, 0.05)] == 0.5
    # Each error e < max contributes (max - e) / max to the area, up to one grid step.
    assert curve_auc(e) == pytest.approx((1 + 0.8 + 0.2 + 0) / 4, abs=0.01)
    assert curve_auc(e, max_error=0.1) == pytest.approx((1 + 0.5) / 4, abs=0.01)
    s = score(e)
    assert s.exact == 0.25 and s.mean == pytest.approx(1.25 / 4)
    assert s.mean_x100 == pytest.approx(125 / 4) and "x100 31.25" in str(s)
    assert score([np.inf, 0.0]).mean == 0.5  # unreachable counts as error 1
    with pytest.raises(ValueError, match="errors are distances, >= 0"):
        score([-1.0, 0.0])
    with pytest.raises(ValueError, match="must be a 1-D array"):
        score([[0.0, 0.1]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.isnan(score([]).mean) and np.isnan(score([]).exact)
    with pytest.raises(ValueError, match=r"map must be a 1-D array .* got shape \(9, 1\)"):
        geodesic_errors(grid(3), np.arange(9)[:, None])
    with pytest.raises(ValueError, match="errors hold NaN"):
        score([0.0, np.nan])


def test_the_identity_ground_truth_needs_one_vertex_count():
    b = grid(3)
    assert geodesic_errors(b, np.arange(9)).tolist() == [0.0] * 9
    # A map of 8 vertices onto 9: no identity to score against unless the pairs are given.
    with pytest.raises(ValueError, match=r"the map has 8, B 9\); pass the scored pairs"):
        geodesic_errors(b, np.arange(8))
    assert geodesic_errors(b, np.arange(8), a_idx=[0, 7], b_idx=[0, 7]).tolist() == [0.0, 0.0]
    with pytest.raises(ValueError, match="b_idx needs a_idx"):
        geodesic_errors(b, np.arange(9), b_idx=[0, 1])


def test_smoothness_of_identity_and_of_a_scrambled_map():
    m = grid(10)
    s = smoothness(m, m, np.arange(100))
    assert s.edge_stretch == pytest.approx(1.0) and s.coverage == 1.0
    rng = np.random.default_rng(0)
    bad = smoothness(m, m, rng.permutation(100))
    assert bad.edge_stretch > 3 and bad.coverage == 1.0
    collapsed = smoothness(m, m, np.zeros(100, dtype=np.int64))
    assert collapsed.edge_stretch == 0 and collapsed.coverage == 0.01

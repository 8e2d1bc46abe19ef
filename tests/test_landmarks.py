"""``match(landmarks=...)``: user landmarks are mapped exactly and resolve symmetric regions."""

import re

import numpy as np
import pytest
from conftest import data_path
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from meshes import bumpy_sphere, inverse, relabel, write_off
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist
from strategies import permutations

import hope_rs
from hope_rs import matching
from hope_rs.cli import main
from hope_rs.evaluation.datasets import pairs_of
from hope_rs.evaluation.evaluate import geodesic_errors
from hope_rs.evaluation.partial import cut_by_plane, plane_normal
from hope_rs.geometry.map_io import read_landmarks
from hope_rs.pipeline import landmarks as landmarks_module
from hope_rs.pipeline import spectral as spectral_module
from hope_rs.pipeline.anchors import distance_fields, farthest_witnesses
from hope_rs.pipeline.config import LandmarkConfig, MatchConfig, SpectralConfig
from hope_rs.pipeline.landmarks import (
    check_landmarks,
    coarse_landmarks,
    coordinate_landmarks,
    landmark_embedding,
    landmark_initial_map,
)

FAST = {"max_passes": 2, "spectral": False}


@pytest.fixture(scope="module")
def spheres():
    return hope_rs.Mesh(*bumpy_sphere(500, 3)), hope_rs.Mesh(*bumpy_sphere(450, 4))


@pytest.fixture
def no_shapes(monkeypatch):
    """Fails the test if ``match`` starts building shapes (the expensive part)."""

    def forbidden(*args, **kwargs):
        raise AssertionError("match built a Shape before checking its landmarks")

    monkeypatch.setattr(matching.Shape, "__init__", forbidden)


def spread_landmarks(shape: hope_rs.Shape, n: int = 4) -> np.ndarray:
    """``n`` farthest-point samples of the shape (input numbering), the centroid start left out."""
    chosen, _ = farthest_witnesses(shape, np.arange(shape.n_vertices), n + 1)
    return shape.order[chosen[1:]]


def test_landmarks_are_mapped_exactly_by_every_stage(spheres):
    a, b = spheres
    plain = hope_rs.match(a, b, **FAST)
    # Pairs the default map does not make, so pinning them is what puts them in the map.
    rows = np.array([[0, 5], [17, 300], [250, 40], [499, 449]])
    assert not (plain.map[rows[:, 0]] == rows[:, 1]).any()
    res = hope_rs.match(a, b, landmarks=rows, **FAST)
    for m in (res.init_map, res.hope_map, res.map):
        np.testing.assert_array_equal(m[rows[:, 0]], rows[:, 1])
    assert "landmarks" in [s.name for s in res.stages if s.ran]
    # The spectral pass runs after HOPE and keeps them too.
    full = hope_rs.match(a, b, landmarks=rows, max_passes=1)
    np.testing.assert_array_equal(full.map[rows[:, 0]], rows[:, 1])


def test_no_landmarks_is_the_map_without_them(spheres):
    a, b = spheres
    plain = hope_rs.match(a, b, **FAST)
    assert "landmarks" not in [s.name for s in plain.stages]
    for none in (None, np.empty((0, 2), dtype=np.int64), [], np.empty((0, 2))):
        res = hope_rs.match(a, b, landmarks=none, **FAST)
        np.testing.assert_array_equal(res.map, plain.map)
        np.testing.assert_array_equal(res.init_map, plain.init_map)
        assert [s.name for s in res.stages] == [s.name for s in plain.stages]


N = 6890  # vertices of each bundled mesh

BAD = [
    # (landmarks, exception, message)
    (np.array([[1.0, 2.0]]), TypeError, r"landmarks must be integer vertex indices .*float64"),
    (np.array([[True, False]]), TypeError, r"landmarks must be integer .*bool"),
    ([["1", "2"]], TypeError, r"landmarks must be integer .*<U1"),
    (np.array([1, 2]), ValueError, r"landmarks must have shape \(m, 2\).*got shape \(2,\)"),
    (np.zeros((2, 3), int), ValueError, r"shape \(m, 2\).*got shape \(2, 3\)"),
    ([[0, 1], [N, 2]], ValueError, rf"row 1 \({N}, 2\): vertex {N} is not a vertex of A, .*{N}"),
    ([[-1, 2]], ValueError, r"row 0 \(-1, 2\): vertex -1 is not a vertex of A"),
    ([[3, N + 5]], ValueError, rf"vertex {N + 5} is not a vertex of B"),
    (np.array([[2**63, 1]], np.uint64), ValueError, rf"vertex {2**63} is not a vertex of A"),
    (
        [[3, 4], [3, 5]],
        ValueError,
        r"contradict.*vertex 3 of A is paired with vertices 4 and 5 of B",
    ),
    (
        [[3, 9], [7, 9]],
        ValueError,
        r"contradict.*vertex 9 of B is paired with vertices 3 and 7 of A",
    ),
    ([[0, 1], [[2], 3]], TypeError, r"landmarks must be an \(m, 2\) array"),
]


@pytest.mark.parametrize("landmarks, exc, message", BAD)
def test_bad_landmarks_fail_in_one_line_before_any_work(no_shapes, landmarks, exc, message):
    v = np.zeros((N, 3))
    v[1:3] = np.eye(3)[:2]  # one face with area
    f = np.array([[0, 1, 2]])
    with pytest.raises(exc, match=message) as info:
        hope_rs.match((v, f), (v, f), landmarks=landmarks)
    assert "\n" not in str(info.value)


def test_a_landmark_given_twice_counts_once():
    got = check_landmarks([[4, 5], [1, 2], [4, 5]], 10, 10)
    np.testing.assert_array_equal(got, [[1, 2], [4, 5]])


@given(rows=arrays(np.int64, st.tuples(st.integers(1, 8), st.just(2)), elements=st.integers(0, 5)))
def test_checked_landmarks_are_the_given_rows_one_to_one_or_an_error(rows):
    try:
        got = check_landmarks(rows, 6, 6)
    except ValueError as e:
        assert "contradict" in str(e)
        # A contradiction is real: some vertex appears with two different partners.
        pairs = {tuple(r) for r in rows.tolist()}
        assert len({a for a, _ in pairs}) < len(pairs) or len({b for _, b in pairs}) < len(pairs)
        return
    assert {tuple(r) for r in got.tolist()} == {tuple(r) for r in rows.tolist()}
    assert np.unique(got[:, 0]).size == np.unique(got[:, 1]).size == len(got)


@settings(max_examples=4, deadline=None)
@given(
    perm_a=permutations(500),
    perm_b=permutations(450),
    rows=st.permutations(range(4)),
)
def test_relabelled_meshes_and_landmarks_give_the_relabelled_map(spheres, perm_a, perm_b, rows):
    a, b = spheres
    lm = np.array([[0, 5], [17, 300], [250, 40], [499, 449]])
    # New vertex i of a2 is old vertex perm_a[i]; the landmark rows come in another order.
    a2 = hope_rs.Mesh(a.vertices[perm_a], relabel(a.faces, perm_a))
    b2 = hope_rs.Mesh(b.vertices[perm_b], relabel(b.faces, perm_b))
    lm2 = np.stack([inverse(perm_a)[lm[:, 0]], inverse(perm_b)[lm[:, 1]]], axis=1)[list(rows)]
    r1 = hope_rs.match(a, b, landmarks=lm, **FAST)
    r2 = hope_rs.match(a2, b2, landmarks=lm2, **FAST)
    for got, want in [(r2.map, r1.map), (r2.init_map, r1.init_map)]:
        np.testing.assert_array_equal(perm_b[got][inverse(perm_a)], want)


def mirrored_start(mesh: hope_rs.Mesh) -> np.ndarray:
    """FAUST's left/right mirror: each vertex to the vertex nearest its reflection in the
    body's plane of symmetry (x = mean x), on the same triangulation."""
    v = mesh.vertices
    r = v.copy()
    r[:, 0] = 2 * v[:, 0].mean() - r[:, 0]
    return cKDTree(v).query(r)[1]


def test_landmarks_pull_a_mirrored_start_to_the_right_side(faust_pair):
    a, b = faust_pair
    sa, sb = hope_rs.Shape(a), hope_rs.Shape(b)
    mirror = mirrored_start(a)  # vertex i of A is vertex i of B on this pair
    assert geodesic_errors(sb, mirror).mean() > 0.4
    lm = spread_landmarks(sa)
    internal = np.stack([sa.rank[lm], sb.rank[lm]], axis=1)
    f0 = landmark_initial_map(sa, sb, sa.map_in(sb, mirror), internal, None)
    err = geodesic_errors(sb, sa.map_out(sb, f0))
    # The mirrored limbs go back to their side: far fewer vertices stay far from their match
    # (the mirror image leaves more than half of them farther than 0.3).
    assert (err > 0.3).mean() < 0.1 and err.mean() < 0.15


@pytest.mark.slow
def test_four_landmarks_undo_a_mirrored_start(faust_pair):
    a, b = faust_pair
    sa, sb = hope_rs.Shape(a), hope_rs.Shape(b)
    mirror = mirrored_start(a)
    lm = spread_landmarks(sa)
    res = hope_rs.match(sa, sb, init=mirror, landmarks=np.stack([lm, lm], 1), **FAST)
    err = geodesic_errors(sb, res.map)
    # From the mirror image (error 0.55) to the right side: no vertex stays far off.
    assert err.mean() < 0.03 and (err > 0.3).mean() == 0


def test_cli_reads_a_landmark_file(tmp_path, spheres):
    a, b = spheres
    pa, pb = tmp_path / "a.off", tmp_path / "b.off"
    write_off(pa, a.vertices, a.faces)
    write_off(pb, b.vertices, b.faces)
    lm = tmp_path / "lm.txt"
    lm.write_text("# A B\n0 5\n17, 300\n\n250\t40  # a comment\n")
    np.testing.assert_array_equal(read_landmarks(lm), [[0, 5], [17, 300], [250, 40]])
    out = tmp_path / "map.txt"
    args = ["match", str(pa), str(pb), "-q", "--no-spectral", "--landmarks", str(lm)]
    assert main([*args, "-o", str(out)]) == 0
    got = np.loadtxt(out, dtype=np.int64)
    np.testing.assert_array_equal(got[[0, 17, 250]], [5, 300, 40])


@pytest.mark.parametrize(
    "text, message",
    [
        ("0 5\n1 2 3\n", r"lm.txt:2: expected two 0-based vertex indices .*'1 2 3'"),
        ("0 x\n", r"lm.txt:1: expected two .*'0 x'"),
        ("1_0 2\n", r"lm.txt:1: expected two .*'1_0 2'"),  # int() reads it as 10
        ("\u0661 2\n", r"lm.txt:1: expected two"),  # an Arabic-Indic one
        # Beyond int64, and past int()'s digit limit: the same one-line error.
        ("99999999999999999999999 0\n", r"lm.txt:1: vertex index too large"),
        ("9" * 5000 + " 0\n", r"lm.txt:1: vertex index too large"),
        ("0 5\n0 6\n", r"contradict.*vertex 0 of A is paired with vertices 5 and 6 of B"),
        ("0 999\n", r"vertex 999 is not a vertex of B, which has 450"),
    ],
)
def test_cli_landmark_errors_are_one_line(tmp_path, spheres, capsys, text, message):
    a, b = spheres
    pa, pb = tmp_path / "a.off", tmp_path / "b.off"
    write_off(pa, a.vertices, a.faces)
    write_off(pb, b.vertices, b.faces)
    lm = tmp_path / "lm.txt"
    lm.write_text(text)
    assert main(["match", str(pa), str(pb), "-q", "--landmarks", str(lm)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("hope-rs: error: ")
    assert re.search(message, err)


def test_cli_missing_landmark_file(tmp_path, capsys):
    assert main(["match", "a.off", "b.off", "--landmarks", str(tmp_path / "none.txt")]) == 2
    assert "no such landmark file" in capsys.readouterr().err


def test_coarse_landmarks_drop_rows_that_share_a_cell():
    owner_a = np.array([0, 0, 1, 2, 3])
    owner_b = np.array([5, 4, 4, 3, 2])
    # Rows 0 and 1 fall in one cell of A; rows 2 and 3 in one cell of B (4).
    lm = np.array([[0, 0], [1, 3], [2, 1], [3, 2], [4, 4]])
    got = coarse_landmarks(lm, owner_a, owner_b)
    np.testing.assert_array_equal(got, [[3, 2]])
    assert coarse_landmarks(lm[:2], owner_a, owner_b) is None


def ground_truth_landmarks(sa: hope_rs.Shape, ai: np.ndarray, bi: np.ndarray) -> np.ndarray:
    """Four farthest-point samples of A among its ground-truth vertices (the centroid start
    left out), each with its first ground-truth partner (input numbering)."""
    first = dict(zip(ai.tolist()[::-1], bi.tolist()[::-1]))  # each vertex's first partner
    chosen, _ = farthest_witnesses(sa, np.sort(sa.rank[np.array(sorted(first))]), 5)
    return np.array([[int(v), first[int(v)]] for v in sa.order[chosen[1:]]])


def non_isometric_pair(name: str) -> tuple:
    """Shapes, ground truth (ai, bi) and four ground-truth landmarks of a tosca_nonisometric_r
    pair."""
    pair = next(p for p in pairs_of(data_path("tosca_nonisometric_r")) if p.name == name)
    a, b = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
    sa, sb = hope_rs.Shape(a), hope_rs.Shape(b)
    ai, bi = pair.ground_truth(a.n_vertices, b.n_vertices, max_points=None)
    return sa, sb, ai, bi, ground_truth_landmarks(sa, ai, bi)


@pytest.mark.slow
def test_landmarks_do_not_mislead_a_non_isometric_pair():
    # Gorilla -> woman: distances to the landmarks bend with the shape, so as anchors of the
    # global repair they would re-place right matches (docs/decisions.md#landmarks).
    sa, sb, ai, bi, lm = non_isometric_pair("8_gorilla_01->8_woman_01")
    without = geodesic_errors(sb, hope_rs.match(sa, sb).map, a_idx=ai, b_idx=bi).mean()
    res = hope_rs.match(sa, sb, landmarks=lm)
    np.testing.assert_array_equal(res.map[lm[:, 0]], lm[:, 1])
    assert geodesic_errors(sb, res.map, a_idx=ai, b_idx=bi).mean() < 1.05 * without


def test_landmark_embedding_gives_each_landmark_the_same_mean_on_both_shapes(spheres):
    sa = hope_rs.Shape(spheres[0])
    # B scaled by 1.5 along x: distances from each landmark stretch by different factors.
    stretched = hope_rs.Shape(hope_rs.Mesh(spheres[1].vertices * [1.5, 1, 1], spheres[1].faces))
    lm = np.array([[0, 0], [100, 120], [250, 300]])
    xa, xb = landmark_embedding(sa, stretched, lm, 2.0)
    assert xa.shape == (sa.n_vertices, 3) and xb.shape == (stretched.n_vertices, 3)
    np.testing.assert_allclose(xa.mean(axis=0), xb.mean(axis=0), rtol=1e-12)
    np.testing.assert_array_equal(xa[lm[:, 0], range(3)], 0)
    # The weight scales every column; unscaled fields of B would not have A's means.
    xa1, xb1 = landmark_embedding(sa, stretched, lm, 1.0)
    np.testing.assert_allclose(xa, 2.0 * xa1)
    np.testing.assert_allclose(xb, 2.0 * xb1)
    raw = distance_fields(stretched, lm[:, 1]).mean(axis=1)
    assert not np.allclose(raw / raw[0], xb1.mean(axis=0) / xb1.mean(axis=0)[0], rtol=1e-3)


def test_near_landmark_columns_act_only_near_a_landmark(spheres):
    sa = hope_rs.Shape(spheres[0])
    stretched = hope_rs.Shape(hope_rs.Mesh(spheres[1].vertices * [1.5, 1, 1], spheres[1].faces))
    lm = np.array([[0, 0], [100, 120], [250, 300]])
    fa, fb = landmark_embedding(sa, stretched, lm, 2.0)
    xa, xb = landmark_embedding(sa, stretched, lm, 2.0, near_weight=50.0, near_radius=0.3)
    # The scaled fields first, unchanged; then one near-landmark column per landmark.
    assert xa.shape == (sa.n_vertices, 6) and xb.shape == (stretched.n_vertices, 6)
    np.testing.assert_array_equal(xa[:, :3], fa)
    np.testing.assert_array_equal(xb[:, :3], fb)
    for x, f in ((xa, fa), (xb, fb)):
        near, d = x[:, 3:], f / 2.0  # d: the scaled fields
        # Zero wherever the scaled field reaches the radius: vertices far from every landmark
        # are compared by their spectral embedding and scaled fields alone.
        assert (near[d >= 0.3] == 0).all() and (near[d < 0.3] > 0).all()
        assert ((d >= 0.3).all(axis=1)).any()
        # Steep near the landmark: 50 units of embedding per unit of scaled distance.
        np.testing.assert_allclose(near[d < 0.3], 50.0 * (0.3 - d[d < 0.3]))
    # Each landmark's own vertex has the same, largest, near coordinate on both shapes.
    np.testing.assert_allclose(xa[lm[:, 0], range(3, 6)], 15.0)
    np.testing.assert_allclose(xb[lm[:, 1], range(3, 6)], 15.0)


def test_landmark_coordinates_reach_zoomout_on_sampled_shapes(spheres, monkeypatch):
    # Shapes above SpectralConfig.max_samples: ZoomOut fits on samples, then searches every
    # vertex; the landmark columns follow both paths.
    a, b = spheres
    rows = np.array([[0, 5], [17, 300], [250, 40], [499, 449]])
    widths = []
    real = spectral_module._SpectralNeighbours.best

    def spy(self, emb_a, emb_b, guess, k):
        widths.append((emb_a.shape[1], emb_b.shape[1]))
        return real(self, emb_a, emb_b, guess, k)

    monkeypatch.setattr(spectral_module._SpectralNeighbours, "best", spy)
    cfg = MatchConfig(spectral=SpectralConfig(max_samples=200, k_end=40))
    res = hope_rs.match(a, b, landmarks=rows, config=cfg, max_passes=1)
    assert res.stage("spectral").ran
    np.testing.assert_array_equal(res.map[rows[:, 0]], rows[:, 1])
    # Each search compares A's and B's embeddings of equal width, the landmark columns
    # included (4 scaled fields, 4 near-landmark columns): k + 8 for the basis sizes 20..40
    # in steps of 5.
    assert widths and all(wa == wb for wa, wb in widths)
    assert {wa - 8 for wa, _ in widths} <= set(range(20, 41, 5))


@pytest.mark.slow
def test_landmark_coordinates_in_zoomout_help_a_non_isometric_pair():
    # Gorilla -> woman: ZoomOut's spectral embedding alone assumes an isometry; the landmarks'
    # scaled distance fields pull each vertex towards its place along the stretched limbs.
    sa, sb, ai, bi, lm = non_isometric_pair("8_gorilla_02->8_woman_02")
    errors = {}
    for weight in (0.0, LandmarkConfig().zoomout_weight):
        cfg = MatchConfig(landmarks=LandmarkConfig(zoomout_weight=weight))
        res = hope_rs.match(sa, sb, landmarks=lm, config=cfg)
        np.testing.assert_array_equal(res.map[lm[:, 0]], lm[:, 1])
        errors[weight] = geodesic_errors(sb, res.map, a_idx=ai, b_idx=bi).mean()
    assert errors[LandmarkConfig().zoomout_weight] < 0.93 * errors[0.0]


@pytest.mark.slow
def test_near_landmark_columns_help_a_non_isometric_pair():
    # Gorilla -> man: the gorilla's hands are larger (in sqrt(area) units) than the man's, and
    # without the near-landmark columns ZoomOut slid them up the man's forearms.
    sa, sb, ai, bi, lm = non_isometric_pair("8_gorilla_01->8_man_01")
    near = {}
    errors = {}
    for weight in (0.0, LandmarkConfig().near_weight):
        cfg = MatchConfig(landmarks=LandmarkConfig(near_weight=weight))
        res = hope_rs.match(sa, sb, landmarks=lm, config=cfg)
        np.testing.assert_array_equal(res.map[lm[:, 0]], lm[:, 1])
        err = geodesic_errors(sb, res.map, a_idx=ai, b_idx=bi)
        errors[weight] = err.mean()
        # The scored vertices within the radius of a landmark on A (its raw fields: they only
        # pick the region whose error is compared).
        d = distance_fields(sa, sa.rank[lm[:, 0]])[:, sa.rank[ai]].min(axis=0)
        near[weight] = err[d < LandmarkConfig().near_radius].mean()
    default = LandmarkConfig().near_weight
    assert errors[default] < 0.93 * errors[0.0]
    assert near[default] < 0.8 * near[0.0]


@pytest.mark.slow
def test_landmarks_on_a_part_are_kept_and_the_map_stays_accurate():
    # A part and its whole: the partial path's nested matches (several scales and a merge)
    # get the landmarks too. Both maps are right here (about 0.02), and which of two close
    # maps a part settles in can change with the landmarks: the check is the landmark goal
    # of 0.03, not a ratio to the map without them.
    a = hope_rs.load_mesh(data_path("faust_r", "tr_reg_000.off"))
    b = hope_rs.load_mesh(data_path("faust_r", "tr_reg_001.off"))
    gta = hope_rs.load_vts(data_path("faust_r", "corres", "tr_reg_000.vts"))
    gtb = hope_rs.load_vts(data_path("faust_r", "corres", "tr_reg_001.vts"))
    part = cut_by_plane(a, plane_normal(1), 0.3)
    on_part = part.inverse(a.n_vertices)[gta]
    ai, bi = on_part[on_part >= 0], gtb[on_part >= 0]
    sp = hope_rs.Shape(part.mesh)
    lm = ground_truth_landmarks(sp, ai, bi)
    without = geodesic_errors(b, hope_rs.match(sp, b).map, a_idx=ai, b_idx=bi).mean()
    res = hope_rs.match(sp, b, landmarks=lm)
    assert res.stage("partial").ran
    np.testing.assert_array_equal(res.map[lm[:, 0]], lm[:, 1])
    assert without < 0.03
    assert geodesic_errors(b, res.map, a_idx=ai, b_idx=bi).mean() < 0.03


@pytest.mark.slow
@pytest.mark.parametrize("pair", [("002", "007"), ("000", "004")])
def test_landmarks_on_a_part_do_not_distrust_its_right_matches(pair):
    # A part's distances to its landmarks run around the missing region, so a right match
    # there reads "off" by its landmark coordinates. Four ground-truth landmarks on the
    # lower 55% of a body (spread by farthest points in space): the map no more than 30%
    # worse than without them (it was 70% worse, and flagged), and not flagged.
    a = hope_rs.load_mesh(data_path("faust_r", f"tr_reg_{pair[0]}.off"))
    b = hope_rs.load_mesh(data_path("faust_r", f"tr_reg_{pair[1]}.off"))
    gta = hope_rs.load_vts(data_path("faust_r", "corres", f"tr_reg_{pair[0]}.vts"))
    gtb = hope_rs.load_vts(data_path("faust_r", "corres", f"tr_reg_{pair[1]}.vts"))
    # The faces with every corner in the lower 55%, and the vertices they use.
    faces = a.faces[(a.vertices[:, 1] <= np.quantile(a.vertices[:, 1], 0.55))[a.faces].all(1)]
    used = np.unique(faces)
    new = np.full(a.n_vertices, -1)
    new[used] = np.arange(len(used))
    part = hope_rs.Mesh(a.vertices[used], new[faces])
    on_part = new[gta]
    ai, bi = on_part[on_part >= 0], gtb[on_part >= 0]
    p = part.vertices[ai]
    chosen = [int(np.argmax(np.linalg.norm(p - p.mean(axis=0), axis=1)))]
    for _ in range(3):
        chosen.append(int(np.argmax(np.min(cdist(p, p[chosen]), axis=1))))
    lm = np.column_stack([ai[chosen], bi[chosen]])
    without = geodesic_errors(b, hope_rs.match(part, b).map, a_idx=ai, b_idx=bi).mean()
    res = hope_rs.match(part, b, landmarks=lm)
    assert res.stage("partial").ran and without < 0.04
    np.testing.assert_array_equal(res.map[lm[:, 0]], lm[:, 1])
    assert geodesic_errors(b, res.map, a_idx=ai, b_idx=bi).mean() < 1.3 * without
    assert not res.quality.likely_failed


@pytest.mark.slow
def test_multiscale_match_keeps_the_landmarks():
    a = hope_rs.load_mesh(data_path("tosca", "cat0.off"))
    b = hope_rs.load_mesh(data_path("tosca", "cat6.off"))
    sa = hope_rs.Shape(a)
    lm = spread_landmarks(sa)
    rows = np.stack([lm, lm], axis=1)  # the identity is the ground truth of this pair
    res = hope_rs.match(sa, b, landmarks=rows, multiscale=True, spectral=False)
    assert res.coarse is not None and "landmarks" in [s.name for s in res.coarse.stages]
    np.testing.assert_array_equal(res.map[lm], lm)
    err = geodesic_errors(b, res.map, a_idx=np.arange(0, a.n_vertices, 7))
    assert err.mean() < 0.03


def test_many_landmarks_are_all_pinned_and_a_spread_few_give_coordinates(spheres, monkeypatch):
    # Hundreds of landmarks (a sparse correspondence): all pinned, a spread few as coordinates.
    a, b = spheres
    sa, sb = hope_rs.Shape(a), hope_rs.Shape(a)
    lm = np.c_[np.arange(0, 500, 2), np.arange(0, 500, 2)]  # 250 rows, a sphere to itself
    internal = np.c_[sa.rank[lm[:, 0]], sb.rank[lm[:, 1]]]
    some = coordinate_landmarks(sa, internal, 16)
    assert len(some) == 16 and len(np.unique(some[:, 0])) == 16
    assert np.isin(some[:, 0], internal[:, 0]).all()
    np.testing.assert_array_equal(coordinate_landmarks(sa, internal, 250), internal)
    # Farthest points: the 16 are spread, each farther from the others than a random 16's
    # nearest pair.
    p = sa.points[some[:, 0]]
    gap = np.min(np.linalg.norm(p[:, None] - p[None], axis=2) + 9 * np.eye(16))
    q = sa.points[internal[:16, 0]]
    assert gap > np.min(np.linalg.norm(q[:, None] - q[None], axis=2) + 9 * np.eye(16))
    # In a match: every landmark mapped exactly, the coordinates from the capped rows only.
    seen = []
    real = landmarks_module.LandmarkCoordinates.__init__

    def spy(self, a, b, landmarks, *args, **kwargs):
        seen.append(len(landmarks))
        real(self, a, b, landmarks, *args, **kwargs)

    monkeypatch.setattr(landmarks_module.LandmarkCoordinates, "__init__", spy)
    cfg = MatchConfig(landmarks=LandmarkConfig(max_coordinates=16))
    res = hope_rs.match(a, a, landmarks=lm, config=cfg, spectral=False)
    np.testing.assert_array_equal(res.map[lm[:, 0]], lm[:, 1])
    assert seen and set(seen) == {16}
    assert "250 landmarks (16 of them as coordinates)" in res.stage("landmarks").reason


def test_a_multiscale_match_with_landmarks_does_not_depend_on_descriptors_left_before():
    """The landmarks re-place the start by descriptors only where the start was made from them:
    on the multiscale path, SHOT an earlier match left on the fine Shapes changed the map."""
    from hope_rs.geometry.coarsen import CoarsenConfig
    from hope_rs.shape import ShapeConfig

    sc = ShapeConfig(coarsen=CoarsenConfig(spacing=0.06))  # 1500 vertices coarsen
    cfg = hope_rs.MatchConfig(shape=sc)
    meshes = bumpy_sphere(1500, 0), bumpy_sphere(1500, 1)
    lm = np.array([[10, 10], [500, 500], [900, 900]])
    maps = []
    for warm in (False, True):
        a, b = (hope_rs.Shape(m, config=sc) for m in meshes)
        if warm:
            hope_rs.match(a, b, config=cfg)  # computes the fine SHOT descriptors
        res = hope_rs.match(a, b, config=cfg, landmarks=lm, multiscale=True)
        assert res.coarse is not None
        maps.append((res.init_map, res.map))
    for fresh, warm in zip(*maps):
        np.testing.assert_array_equal(warm, fresh)

"""Partial shapes: the benchmark-set generator, the detection of a part, and matching a part."""

import inspect

import numpy as np
import pytest
from conftest import data_path
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from meshes import bumpy_sphere, inverse, relabel, write_off
from scipy.spatial import cKDTree
from strategies import permutations

import hope_rs
from hope_rs import Shape, match
from hope_rs.cli import main
from hope_rs.evaluation.datasets import pairs_of
from hope_rs.evaluation.evaluate import geodesic_errors, load_vts
from hope_rs.evaluation.partial import (
    cut_by_plane,
    plane_normal,
    punch_holes,
    submesh,
    write_partial_sets,
)
from hope_rs.evaluation.perturbed import write_perturbed_sets
from hope_rs.geometry.subdivide import subdivide
from hope_rs.pipeline import refine as refine_module
from hope_rs.pipeline import runner
from hope_rs.pipeline.config import (
    ConfidenceConfig,
    MatchConfig,
    OrientConfig,
    PartialConfig,
    RefineConfig,
    SpectralConfig,
)
from hope_rs.pipeline.partial import (
    boundary_length,
    covered_share,
    covering_rings,
    detect_part,
    invert_given_map,
    invert_part_map,
    mean_edge,
    part_scale,
)
from hope_rs.pipeline.runner import run_match
from hope_rs.pipeline.spectral import basis_slope


@pytest.fixture(scope="module")
def sphere():
    return hope_rs.Mesh(*bumpy_sphere(800, 0))


@pytest.fixture(scope="module")
def self_set(tmp_path_factory, sphere):
    """A .vts data set of one pair, a bumpy sphere and itself, every 3rd vertex a landmark."""
    folder = tmp_path_factory.mktemp("src") / "spheres"
    (folder / "corres").mkdir(parents=True)
    for name in ("s", "t"):
        write_off(folder / f"{name}.off", sphere.vertices, sphere.faces)
        (folder / "corres" / f"{name}.vts").write_text(
            "".join(f"{i + 1}\n" for i in range(0, sphere.n_vertices, 3))
        )
    (folder / "pairs.txt").write_text("s t\n")
    return folder


def boundary_ends(mesh) -> np.ndarray:
    f = mesh.faces
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    u, c = np.unique(e, axis=0, return_counts=True)
    return np.bincount(u[c == 1].reshape(-1), minlength=mesh.n_vertices)


def test_cut_removes_its_share_keeps_positions_and_stays_manifold(sphere):
    part = cut_by_plane(sphere, plane_normal(1), 0.3)
    assert 0.6 * sphere.n_vertices <= part.mesh.n_vertices <= 0.71 * sphere.n_vertices
    np.testing.assert_array_equal(part.mesh.vertices, sphere.vertices[part.origin])
    # Every face of the part is a face of the original, through the vertex map.
    faces = {tuple(sorted(t)) for t in sphere.faces.tolist()}
    assert all(tuple(sorted(t)) in faces for t in part.origin[part.mesh.faces].tolist())
    ends = boundary_ends(part.mesh)
    assert ends.max() == 2 and ends.sum() > 0  # one boundary loop through each boundary vertex
    # The removed side is the one the normal points to.
    h = sphere.vertices @ plane_normal(1)
    assert h[part.origin].max() <= np.sort(h)[int(0.7 * sphere.n_vertices)]


def test_holes_and_submesh_of_everything(sphere):
    part = punch_holes(sphere, 4)
    assert boundary_ends(part.mesh).max() == 2
    assert 0.75 * sphere.n_vertices < part.mesh.n_vertices < 0.95 * sphere.n_vertices
    whole = submesh(sphere, np.ones(sphere.n_vertices, dtype=bool))
    np.testing.assert_array_equal(whole.origin, np.arange(sphere.n_vertices))
    with pytest.raises(ValueError, match="removes every face"):
        submesh(sphere, np.zeros(sphere.n_vertices, dtype=bool))


def test_partial_sets_ground_truth_is_consistent_and_deterministic(tmp_path, self_set):
    """A part of a shape matched to the shape through its vertex map has zero error on every
    landmark, in both directions; writing the sets twice gives the same files."""
    out = write_partial_sets(self_set, tmp_path / "one")
    names = sorted(d.name for d in out)
    want = [f"spheres_{c}{r}" for c in ("cut30", "cut50", "holes") for r in ("", "_rev")]
    assert names == sorted([*want, "spheres_cut_both"])
    for d in out:
        (pair,) = pairs_of(d)
        a, b = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
        ai, bi = pair.ground_truth(a.n_vertices, b.n_vertices)
        assert ai.size > 0.3 * 800 / 3
        origin = {
            p.stem: load_vts(d / "origin" / f"{p.stem}.vts")
            for p in (pair.a, pair.b)
            if (d / "origin" / f"{p.stem}.vts").exists()
        }
        assert origin, "every set has a cut shape"
        # Through the original sphere: both landmarks are the same original vertex.
        oa = origin.get(pair.a.stem, np.arange(a.n_vertices))
        ob = origin.get(pair.b.stem, np.arange(b.n_vertices))
        np.testing.assert_array_equal(oa[ai], ob[bi])
        if pair.b.stem not in origin:  # A is the part of the whole B: its map is the origin
            e = geodesic_errors(b, oa, a_idx=ai, b_idx=bi)
            assert np.all(e == 0)
    again = write_partial_sets(self_set, tmp_path / "two")
    for d1, d2 in zip(out, again):
        for f1 in sorted(d1.rglob("*")):
            if f1.is_file():
                assert f1.read_bytes() == (d2 / f1.relative_to(d1)).read_bytes(), f1


def test_partial_sets_bad_input(tmp_path, sphere):
    write_off(tmp_path / "a.off", sphere.vertices, sphere.faces)
    write_off(tmp_path / "b.off", sphere.vertices, sphere.faces)
    with pytest.raises(ValueError, match="identity ground truth"):
        write_partial_sets(tmp_path, tmp_path / "out")
    with pytest.raises(ValueError, match="unknown condition"):
        write_partial_sets(tmp_path, tmp_path / "out", conditions=["cut99"])
    with pytest.raises(ValueError, match="condition cut30 is given twice"):
        write_partial_sets(tmp_path, tmp_path / "out", conditions=["cut30", "cut50", "cut30"])


def test_derived_set_commands_refuse_sources_that_give_nothing_or_clash(tmp_path, sphere, capsys):
    """Before any work: no source, a source with no pair, and two sources of one folder name
    (whose sets would replace each other's) are refused, each in one line."""
    one, two = tmp_path / "x" / "set", tmp_path / "y" / "set"
    for folder in (one, two):
        (folder / "corres").mkdir(parents=True)
        for name in ("a", "b"):
            write_off(folder / f"{name}.off", sphere.vertices, sphere.faces)
            (folder / "corres" / f"{name}.vts").write_text("1\n2\n3\n")
        (folder / "pairs.txt").write_text("a b\n")
    empty = tmp_path / "empty"
    empty.mkdir()
    write_off(empty / "a.off", sphere.vertices, sphere.faces)
    (empty / "pairs.txt").write_text("")
    for cmd in ("partial-set", "perturb-set", "resolution-set"):
        for sources, why in (
            (",", "no data-set folder given"),
            (f"{one},{one}", "is given twice"),
            (str(empty), "has no pair"),
            (f"{one},{two}", "the same folder name"),
        ):
            out = tmp_path / f"out-{cmd}"
            assert main([cmd, str(out), "--from", sources]) == 2
            err = capsys.readouterr().err
            assert why in err and err.count("\n") == 1, err
            assert not out.exists() or not any(out.iterdir())


def test_detect_part_by_boundary(sphere):
    whole = Shape(sphere)
    part = Shape(cut_by_plane(sphere, plane_normal(0), 0.3).mesh)
    assert boundary_length(whole) == 0.0 and boundary_length(part) > 0.5
    info = detect_part(part, whole)
    assert info is not None and info.part == "a" and info.scale == whole.scale
    assert detect_part(whole, part).part == "b"
    assert detect_part(whole, Shape(sphere)) is None
    strict = PartialConfig(min_boundary_excess=10.0)
    assert detect_part(part, whole, strict) is None
    # Two cut shapes: neither is the other's whole, however their boundaries compare.
    other = Shape(cut_by_plane(sphere, -plane_normal(0), 0.1).mesh)
    assert 0.3 < boundary_length(other) < boundary_length(part) - 0.3
    assert detect_part(part, other) is None and detect_part(other, part) is None


def test_at_scale_is_a_view_with_its_own_descriptors(sphere):
    s = Shape(sphere)
    d = s.descriptors("shot")
    v = s.at_scale(2 * s.scale)
    assert v.graph is s.graph and v.scale == 2 * s.scale and s.scale == s.internal.scale
    assert not np.allclose(v.descriptors("shot"), d)  # twice the SHOT radius
    np.testing.assert_array_equal(s.descriptors("shot"), d)  # the shape itself is untouched
    np.testing.assert_array_equal(s.at_scale(s.scale).descriptors("shot"), d)
    with pytest.raises(ValueError, match="positive"):
        s.at_scale(0.0)


def test_partial_stage_runs_only_on_a_part(sphere, monkeypatch):
    cut = cut_by_plane(sphere, plane_normal(2), 0.3)
    part = cut.mesh
    res = match(part, sphere)
    assert "A is a part" in str(res.stage("partial"))
    # A given initial map (the true one) is taken in the input numbering and kept.
    given = match(part, sphere, init=cut.origin)
    assert (given.map == cut.origin).mean() > 0.95
    np.testing.assert_array_equal(given.init_map, cut.origin)
    # The whole matched to the part from a given start (right on the part, the missing side
    # sent to the cut) goes through the part's match too, which starts from the start inverted:
    # the part's true map.
    _, start = cKDTree(part.vertices).query(sphere.vertices)
    nested = []

    def spy(a, b, init, *args, **kwargs):
        nested.append(np.array(init, copy=True))
        return run_match(a, b, init, *args, **kwargs)  # the runner's own, imported above

    monkeypatch.setattr(runner, "run_match", spy)
    given = match(sphere, part, init=start, max_passes=1)
    monkeypatch.undo()
    assert "B -> A and inverted" in given.stage("partial").reason
    np.testing.assert_array_equal(nested[0], cut.origin)
    np.testing.assert_array_equal(given.init_map, start)
    # Asked to go directly, it does, without the orient stage, and says so.
    start = np.zeros(sphere.n_vertices, dtype=np.int64)
    to_part = MatchConfig(partial=PartialConfig(whole_to_part="direct"))
    direct = match(sphere, part, init=start, max_passes=1, config=to_part)
    assert "matched directly" in direct.stage("orient").reason
    # Two whole shapes, or the stage turned off: not on the match's path.
    whole = match(sphere, sphere)
    assert "partial" not in [s.name for s in whole.stages] and not whole.stage("partial").ran
    off = MatchConfig(partial=PartialConfig(enabled=False))
    res = match(part, sphere, config=off)
    assert "partial" not in [s.name for s in res.stages] and not res.stage("partial").ran
    # Two cut shapes: matched as wholes, and the stage says why it left them.
    other = cut_by_plane(sphere, -plane_normal(2), 0.3).mesh
    both = match(part, other, max_passes=1)
    stage = both.stage("partial")
    assert not stage.ran and "both shapes are open" in stage.reason
    assert stage in both.stages and "check res.quality" in str(stage)


def test_a_dense_part_keeps_the_confidence_of_its_match_at_the_common_resolution():
    # A part of a mesh subdivided twice, matched to the sparse whole: the part's matches run at
    # a common resolution and the kept one's confidence is carried over (measured on the
    # many-to-one map at full resolution, it flags a right map).
    sphere = hope_rs.Mesh(*bumpy_sphere(300, 0))
    dense = subdivide(sphere, 2)
    part = cut_by_plane(dense, plane_normal(2), 0.3).mesh
    res = match(part, sphere, max_passes=1)
    assert "A is a part" in res.stage("partial").reason
    confidence = res.stage("confidence")
    assert not confidence.ran and "carried over" in confidence.reason, confidence.reason
    assert res.confidence is not None and res.confidence.shape == (part.n_vertices,)
    # Each dense vertex takes its coarse vertex's value: constant over each coarse vertex's
    # cell (most edges join two vertices of one cell), varying from cell to cell.
    values = np.unique(res.confidence).size
    assert 20 < values < 0.3 * part.n_vertices, values
    e = part.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    assert np.mean(res.confidence[e[:, 0]] == res.confidence[e[:, 1]]) > 0.5
    off = match(part, sphere, max_passes=1, confidence=False)
    assert off.confidence is None


@pytest.mark.slow
def test_whole_to_part_inverts_the_part_match_and_says_which_vertices_have_a_partner(sphere):
    """match(whole, part): the vertices of the whole that are on the part map to themselves
    (the same surface), and the counterpart estimate on the state tells them from the rest."""
    part = cut_by_plane(sphere, plane_normal(4), 0.3)
    seen = {}
    sa, sb = Shape(sphere), Shape(part.mesh)
    res = run_match(sa, sb, "shot", MatchConfig(), on_stage=lambda st, name: seen.update(st=st))
    assert "B -> A and inverted" in str(res.stage("partial"))
    info = seen["st"].partial
    assert info.part == "b"
    has = np.zeros(sphere.n_vertices, dtype=bool)
    has[part.origin] = True
    counterpart = info.counterpart[sa.rank]  # internal -> input numbering
    assert counterpart[has].mean() > 0.98  # partners found ...
    assert has[counterpart].mean() > 0.9  # ... and few claimed beyond the cut
    exact = part.origin[res.map] == np.arange(sphere.n_vertices)
    assert exact[has].mean() > 0.9
    # No counterpart, no confidence: those vertices come out unmatched.
    assert (res.confidence[~counterpart] == 0).all()
    unmatched = res.map_or_unmatched(0.5) == -1
    assert unmatched[~counterpart].all()
    # The others are judged at the whole's scale, on the vertices that have a partner: a right
    # map is trusted there, and the pair is not reported as failed for the rest.
    assert (res.confidence[has & counterpart] >= 0.5).mean() > 0.9
    assert not res.quality.likely_failed
    # The initial map is the reversed match's, inverted too (it was the final map).
    assert (res.init_map != res.map).any()
    assert (part.origin[res.init_map] == np.arange(sphere.n_vertices))[has].mean() < 0.9
    # The part matched the other way: every vertex has its partner.
    res_a = run_match(sb, sa, "shot", MatchConfig(), on_stage=lambda st, name: seen.update(st=st))
    assert seen["st"].partial.counterpart.all()
    assert (res_a.map == part.origin).mean() > 0.9
    # That match is the one the whole's went through: its maps inverted are the whole's.
    radius = PartialConfig().counterpart_edges * mean_edge(sa)
    for mine, theirs in ((res.map, res_a.map), (res.hope_map, res_a.hope_map)):
        inverted, _ = invert_part_map(sa, sb.map_in(sa, theirs), radius)
        np.testing.assert_array_equal(mine, sa.map_out(sb, inverted))
    # The share of the whole the part's true map covers is the part's share of its area, and
    # at most one ring of faces beyond it (800 vertices: a ring is about a tenth of the area).
    share = covered_share(sa, sa.rank[part.origin][sb.order])
    truth = part.mesh.area / sphere.area
    assert truth <= share < truth + 0.12


def test_a_given_map_of_the_whole_onto_its_part_is_inverted(sphere):
    """The map of the whole onto its part that is right on the part and sends the missing
    side to the cut (each vertex to the part's vertex nearest in space) inverts to the part's
    true map: where several vertices of the whole meet on the cut, the one that fits the
    neighbours' picks is taken. A vertex that nothing maps to takes what its nearest mapped
    neighbour took."""
    cut = cut_by_plane(sphere, plane_normal(2), 0.3)
    sa, sb = Shape(sphere), Shape(cut.mesh)
    _, f = cKDTree(cut.mesh.vertices).query(sphere.vertices)
    several = np.bincount(f, minlength=cut.mesh.n_vertices) > 1
    assert several.sum() >= 20  # the cut's vertices
    g = sb.map_out(sa, invert_given_map(sa, sb, sa.map_in(sb, f)))
    np.testing.assert_array_equal(g, cut.origin)
    # Vertex 0 of the part no longer hit (its vertices of the whole sent to vertex 1).
    f2 = np.where(f == 0, 1, f)
    h = sb.map_out(sa, invert_given_map(sa, sb, sa.map_in(sb, f2)))
    hit = np.flatnonzero(np.bincount(f2, minlength=cut.mesh.n_vertices) > 0)
    near = hit[np.argmin(np.linalg.norm(cut.mesh.vertices[hit] - cut.mesh.vertices[0], axis=1))]
    assert h[0] == h[near]
    # Vertex 1's group changed; every other vertex keeps its pick.
    np.testing.assert_array_equal(h[2:], g[2:])
    with pytest.raises(ValueError, match="at least one vertex"):
        invert_given_map(sa, sb, np.zeros(0, dtype=np.int64))


def test_gaps_among_the_part_s_images_have_a_counterpart_and_its_missing_side_not(sphere):
    """The part's true map into the whole with a few scattered vertices sent to a neighbour
    instead (a locally many-to-one map): the whole's vertices left between the images are
    gaps, filled; the side the part lacks stays without a counterpart."""
    cut = cut_by_plane(sphere, plane_normal(2), 0.3)
    sa = Shape(sphere)
    truth = sa.rank[cut.origin]  # part (input numbering) -> whole (internal)
    on = np.zeros(sa.n_vertices, dtype=bool)
    on[truth] = True
    # Every 7th vertex of the part two rings or more from its cut takes a neighbour's image.
    near_cut = ~on
    for _ in range(2):
        grown = near_cut.copy()
        grown[sa.edges[near_cut[sa.edges[:, 0]], 1]] = True
        grown[sa.edges[near_cut[sa.edges[:, 1]], 0]] = True
        near_cut = grown
    inside = np.flatnonzero(~near_cut)
    g = truth.copy()
    rng = np.random.default_rng(0)
    moved = rng.choice(np.flatnonzero(np.isin(truth, inside)), size=on.sum() // 7, replace=False)
    for i in moved:
        nb = sa.edges[(sa.edges == truth[i]).any(axis=1)].ravel()
        g[i] = nb[nb != truth[i]][0]
    radius = 0.5 * mean_edge(sa)
    _, plain = invert_part_map(sa, g, radius)
    _, filled = invert_part_map(sa, g, radius, gaps=0.01)  # patches under 8 vertices
    gap = on & ~plain
    assert gap.sum() >= 10  # the test makes gaps ...
    assert filled[gap].all()  # ... and they are filled,
    np.testing.assert_array_equal(filled[~on], plain[~on])  # the missing side left as it was


@pytest.mark.slow
def test_a_whole_matched_to_its_part_from_a_given_start_goes_through_the_part_s_match(tmp_path):
    """A FAUST shape matched to another one cut by a plane (30%), from a given start: the
    start is inverted and the part matched to the whole, as without one (directly, the
    refinement's overlaps pull the vertices that have a partner off their place)."""
    folders = write_partial_sets(data_path("faust_r"), tmp_path, conditions=["cut30"], max_pairs=1)
    pair = pairs_of(next(f for f in folders if f.name.endswith("_rev")))[0]
    a, b = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
    ai, bi = pair.ground_truth(a.n_vertices, b.n_vertices)
    start = match(a, b).init_map
    res = match(a, b, init=start)
    assert "B -> A and inverted" in res.stage("partial").reason
    np.testing.assert_array_equal(res.init_map, start)
    assert geodesic_errors(b, res.map, a_idx=ai, b_idx=bi).mean() < 0.04
    # HOPE's map is the part's match's own, inverted: the spectral pass and the finish
    # changed the final map after it.
    assert (res.hope_map != res.map).any()


def test_the_covered_share_of_a_denser_whole_closes_the_gaps_between_images(sphere):
    # A part's vertices mapped onto a whole subdivided twice (16x denser): the images are the
    # original vertices, about 4 edges apart. One ring leaves most faces between them
    # uncovered; sqrt(16) / 2 rings cover the part's share of the area, and not much more.
    part = cut_by_plane(sphere, plane_normal(3), 0.3)
    dense = Shape(subdivide(sphere, 2))
    f = dense.rank[part.origin]  # subdivision keeps the original vertices first
    truth = part.mesh.area / sphere.area
    assert covered_share(dense, f) < 0.5 * truth
    assert truth <= covered_share(dense, f, rings=2) < truth + 0.06
    # The stage's choice for the part at its whole's scale covers the part's share; one ring
    # at equal densities.
    view = Shape(part.mesh).at_scale(Shape(sphere).scale)
    rings = covering_rings(view, dense)
    assert rings >= 2 and truth <= covered_share(dense, f, rings) < truth + 0.1
    assert covering_rings(view, Shape(sphere)) == 1


@pytest.mark.slow
@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_partial_match_is_invariant_to_relabelling(sphere, data):
    """Relabelling the part (or the whole) relabels the map of the partial path, nothing else."""
    part = cut_by_plane(sphere, plane_normal(3), 0.3).mesh
    base = match(part, sphere).map
    pa = data.draw(permutations(part.n_vertices), label="perm_a")
    pb = data.draw(permutations(sphere.n_vertices), label="perm_b")
    a2 = hope_rs.Mesh(part.vertices[pa], relabel(part.faces, pa))
    b2 = hope_rs.Mesh(sphere.vertices[pb], relabel(sphere.faces, pb))
    got = match(a2, b2)
    assert "A is a part" in str(got.stage("partial"))
    np.testing.assert_array_equal(pb[got.map], base[pa])
    np.testing.assert_array_equal(inverse(pb)[base[pa]], got.map)


def test_basis_slope_cuts_the_part_s_basis_by_the_area_ratio(sphere):
    """Shapes in their own units keep square functional maps; a part measured at the whole's
    scale uses its area's share of each basis size, the whole all of it."""
    whole = Shape(sphere)
    assert basis_slope(whole, Shape(sphere)) == (1.0, 1.0)
    cut = cut_by_plane(sphere, plane_normal(2), 0.3).mesh
    own = Shape(cut)
    assert basis_slope(own, whole) == (1.0, 1.0)  # each in its own units: not told apart
    part = own.at_scale(whole.scale)
    share = cut.area / sphere.area
    assert 0.5 < share < 0.8
    np.testing.assert_allclose(basis_slope(part, whole), (share, 1.0), rtol=1e-9)
    np.testing.assert_allclose(basis_slope(whole, part), (1.0, share), rtol=1e-9)


@pytest.mark.slow
def test_a_cut_tosca_shape_gains_from_the_slanted_spectral_pass(tmp_path):
    """TOSCA david0 cut by a plane (30% of its vertices), matched to david1: ZoomOut with the
    part's basis cut to its area's share corrects the refinement's map, a square one less."""
    (out,) = write_partial_sets(
        data_path("tosca_r"), tmp_path, conditions=["cut30"], max_pairs=5, reverse=False
    )
    pair = pairs_of(out)[4]
    assert pair.a.stem == "04_david0_cut30"
    a, b = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
    ai, bi = pair.ground_truth(a.n_vertices, b.n_vertices)
    one = PartialConfig(scale_trials=())  # one scale: the spectral pass's own effect
    held = OrientConfig(on_torn=False)  # no repair after the partial stage
    slanted = MatchConfig(partial=one, orient=held)
    e = geodesic_errors(b, match(a, b, config=slanted).map, a_idx=ai, b_idx=bi).mean()
    square = MatchConfig(partial=one, orient=held, spectral=SpectralConfig(slanted=False))
    e_square = geodesic_errors(b, match(a, b, config=square).map, a_idx=ai, b_idx=bi).mean()
    assert e < 0.03 and e_square > 1.3 * e


@pytest.mark.slow
def test_scale_trials_keep_a_cut_cat_off_the_whole_s_missing_side(tmp_path):
    """TOSCA cat0 cut by a plane along its back, matched to cat2 (sitting): at the guessed
    scale alone a hind quarter settles on the side the part lacks; the trials at nearby
    scales and their merge, chosen by confidence, halve the error. (The trials alone: the
    orientation check of the part's votes is off in both runs.)"""
    a, b, ai, bi = _partial_pair(tmp_path, "tosca_r", "cut30", 1, ("01_cat0_cut30", "01_cat2"))
    held = OrientConfig(on_torn=False)  # no repair after the partial stage
    res = match(a, b, config=MatchConfig(partial=PartialConfig(max_turned=None), orient=held))
    e = geodesic_errors(b, res.map, a_idx=ai, b_idx=bi).mean()
    single = MatchConfig(partial=PartialConfig(scale_trials=(), max_turned=None), orient=held)
    e_single = geodesic_errors(b, match(a, b, config=single).map, a_idx=ai, b_idx=bi).mean()
    assert e < 0.1 and e_single > 1.5 * e
    assert res.confidence is not None and res.stage("partial").ran


def test_scale_trials_setting_is_checked():
    assert PartialConfig(scale_trials=[0.9, 1.1]).scale_trials == (0.9, 1.1)
    assert PartialConfig(scale_trials=()).scale_trials == ()
    with pytest.raises(ValueError, match=r"scale_trials must be positive numbers"):
        PartialConfig(scale_trials=(0.9, -1.0))
    with pytest.raises(TypeError, match=r"scale_trials must be a sequence of positive numbers"):
        PartialConfig(scale_trials=0.9)
    assert PartialConfig(wide_trials=[0.8]).wide_trials == (0.8,)
    with pytest.raises(ValueError, match=r"wide_trials must be positive numbers"):
        PartialConfig(wide_trials=(0.0,))
    with pytest.raises(TypeError, match=r"wide_trials must be a sequence of positive numbers"):
        PartialConfig(wide_trials="19")
    with pytest.raises(ValueError, match=r"wide_below must be a number in \[0, 1\]"):
        PartialConfig(wide_below=1.5)
    with pytest.raises(ValueError, match=r"wide_below must be a number in \[0, 1\]"):
        PartialConfig(wide_below="0.5")
    with pytest.raises(ValueError, match=r"wide_margin must be a number in \[0, 1\]"):
        PartialConfig(wide_margin=-0.1)
    with pytest.raises(ValueError, match=r"merge_rings must be an integer in \[0, 10000\]"):
        match(*_tiny_pair(), config=MatchConfig(partial=PartialConfig(merge_rings=-1)))


def test_wide_trials_run_only_when_no_nearby_map_is_confident(sphere, monkeypatch):
    """The wider scales are matched only below ``wide_below`` and when a map could still win
    by ``wide_margin``; without a win the map is the one of the nearby scales."""
    part = cut_by_plane(sphere, plane_normal(2), 0.3).mesh
    calls = []
    nested = runner.run_match
    monkeypatch.setattr(runner, "run_match", lambda *a, **k: calls.append(1) or nested(*a, **k))

    def run(**kw):
        calls.clear()
        res = match(part, sphere, config=MatchConfig(partial=PartialConfig(**kw)))
        return res, len(calls)

    base, n = run(wide_trials=())
    assert n >= 4  # the guessed scale, two nearby ones, the merge
    for kw in ({"wide_below": 0.0}, {"wide_below": 1.0, "wide_margin": 1.0}):
        res, m = run(**kw)
        assert m == n
        np.testing.assert_array_equal(res.map, base.map)
    res, m = run(wide_below=1.0, wide_margin=0.0)
    assert m == n + len(PartialConfig().wide_trials)


def test_placement_trials_run_only_on_a_flagged_part_without_landmarks(sphere):
    """The part's match is started from regions of the whole only when the kept map is
    flagged or not confident enough, and neither landmarks nor a given start place it; a
    region's map replaces it only when ahead by the margin."""
    part = cut_by_plane(sphere, plane_normal(2), 0.3)

    def run(failed_mean=ConfidenceConfig().failed_mean, landmarks=None, init=None, **kw):
        cfg = MatchConfig(
            partial=PartialConfig(wide_trials=(), **kw),
            confidence=ConfidenceConfig(failed_mean=failed_mean),
        )
        res = match(part.mesh, sphere, config=cfg, landmarks=landmarks, init=init)
        labels = [t.label for t in res.stage("partial").trials]
        return res, [x for x in labels if x.startswith("region")]

    res, regions = run()
    assert not res.quality.likely_failed and regions == []
    assert res.stage("partial").trials[0].score >= PartialConfig().placement_below
    flagged, regions = run(failed_mean=1.0)  # every map flagged
    assert regions == [f"region {i}" for i in range(PartialConfig().placement_trials)]
    # Not flagged, but less confident than placement_below.
    assert len(run(placement_below=1.0)[1]) == PartialConfig().placement_trials
    assert run(failed_mean=1.0, placement_trials=0)[1] == []
    truth = np.stack([[0, int(part.origin[0])], [5, int(part.origin[5])]])
    assert run(failed_mean=1.0, landmarks=truth)[1] == []
    assert run(failed_mean=1.0, init=part.origin)[1] == []  # a given start places the part
    unmoved, regions = run(failed_mean=1.0, placement_trials=3, placement_margin=1.0)
    assert regions == ["region 0", "region 1", "region 2"]
    np.testing.assert_array_equal(unmoved.map, run(failed_mean=1.0, placement_trials=0)[0].map)


@pytest.mark.slow
def test_placement_trials_move_a_cat_part_to_its_own_half_of_the_whole(tmp_path):
    """TOSCA cat2 cut by a plane (30%), matched to cat1: at every scale the part settles on
    the cat's other half, turned end to end (a front and a hind half look alike and keep
    orientation), and the map is flagged. Started from regions of the whole, the region
    holding its counterpart gives the most confident map, and the right one."""
    src = tmp_path / "cats"
    (src / "corres").mkdir(parents=True)
    for name in ("cat0", "cat1", "cat2"):
        (src / f"{name}.off").symlink_to(data_path("tosca_r", f"{name}.off"))
        (src / "corres" / f"{name}.vts").symlink_to(data_path("tosca_r", "corres", f"{name}.vts"))
    # The pair's plane is chosen by its index: cat2 → cat1 is the third pair.
    (src / "pairs.txt").write_text("cat1 cat0\ncat2 cat0\ncat2 cat1\n")
    res, without = _with_and_without_placement(tmp_path, src, 2, ("02_cat2_cut30", "02_cat1"))
    assert without.quality.likely_failed and not res.quality.likely_failed
    kept = [t.label for t in res.stage("partial").trials if t.kept]
    assert len(kept) == 1 and kept[0].startswith("region")


@pytest.mark.slow
def test_placement_trials_turn_a_noisy_faust_part_the_right_way_up(tmp_path):
    """FAUST tr_reg_007 (on one leg, hands up) cut by a plane (30%), matched to tr_reg_008
    with vertex noise of 0.5% sqrt(area): at every scale the part settles upside down (arms
    on legs), which keeps distances well enough for a mean confidence above the flag's bar.
    Below ``placement_below`` the part is started from regions of the whole, and the most
    confident map is the right one."""
    (noisy,) = write_perturbed_sets(
        data_path("faust_r"), tmp_path / "noisy", conditions=["noise05"], max_pairs=8
    )
    stems = ("07_07_tr_reg_007_cut30", "07_07_tr_reg_008_noise05")
    res, without = _with_and_without_placement(tmp_path, noisy, 7, stems)
    assert not without.quality.likely_failed  # the wrong map is not flagged
    assert res.quality.mean_confidence > without.quality.mean_confidence


def _with_and_without_placement(tmp_path, source, index: int, stems: tuple):
    """Pair ``index`` of the cut30 set written from ``source`` (checked to be the pair of
    ``stems``) matched with and without placement trials, after checking that they make its
    error (graph geodesics) fall from over 0.3 to under 0.1."""
    (out,) = write_partial_sets(
        source, tmp_path / "out", conditions=["cut30"], max_pairs=index + 1, reverse=False
    )
    pair = pairs_of(out)[index]
    assert (pair.a.stem, pair.b.stem) == stems
    a, b = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
    ai, bi = pair.ground_truth(a.n_vertices, b.n_vertices)
    res = match(a, b)
    without = match(a, b, config=MatchConfig(partial=PartialConfig(placement_trials=0)))
    e, e_without = (geodesic_errors(b, r.map, a_idx=ai, b_idx=bi).mean() for r in (res, without))
    assert e < 0.1 and e_without > 0.3
    return res, without


@pytest.mark.slow
def test_wide_trials_rescue_a_posed_faust_part(tmp_path):
    """FAUST tr_reg_007 (standing on one leg, hands up) cut at 30%, matched to tr_reg_008: at
    the guessed scale and its nearby trials the shoulder stumps settle on the chest and the
    raised knee elsewhere, the mean confidence stays low, and the wider trials find the map.
    (The trials alone: the orientation check of the part's votes is off in both runs.)"""
    stems = ("07_tr_reg_007_cut30", "07_tr_reg_008")
    a, b, ai, bi = _partial_pair(tmp_path, "faust_r", "cut30", 7, stems)
    held = OrientConfig(on_torn=False)  # no repair after the partial stage
    res = match(a, b, config=MatchConfig(partial=PartialConfig(max_turned=None), orient=held))
    narrow_cfg = PartialConfig(wide_trials=(), max_turned=None)
    narrow = match(a, b, config=MatchConfig(partial=narrow_cfg, orient=held))
    e, e_narrow = (geodesic_errors(b, r.map, a_idx=ai, b_idx=bi).mean() for r in (res, narrow))
    assert e < 0.1 and e_narrow > 0.12
    assert res.confidence.mean() > narrow.confidence.mean() + 0.15


@pytest.mark.slow
def test_a_half_faust_part_keeps_its_orientation(tmp_path):
    """FAUST 007 (on one leg, the other raised) cut in half and matched to 008. Without the
    orientation check of the part's refinement, at no scale does the part settle in the right
    basin: the map carries the torso onto B's other leg and the raised leg onto the torso,
    which keeps distances well enough for a middling confidence but turns that area over, and
    the pair is flagged. With it (the default) the turned vertices do not vote and the map
    is right."""
    stems = ("07_tr_reg_007_cut50", "07_tr_reg_008")
    a, b, ai, bi = _partial_pair(tmp_path, "faust_r", "cut50", 7, stems)
    held = OrientConfig(on_torn=False)  # no repair after the partial stage
    res = match(a, b, config=MatchConfig(orient=held))
    unchecked_cfg = MatchConfig(partial=PartialConfig(max_turned=None), orient=held)
    unchecked = match(a, b, config=unchecked_cfg)
    e, e_unchecked = (
        geodesic_errors(b, r.map, a_idx=ai, b_idx=bi).mean() for r in (res, unchecked)
    )
    assert e < 0.15 and e_unchecked > 0.3
    assert not res.quality.likely_failed and res.quality.flipped_share < 0.15
    # The confidence alone passes the wrong map; the turned-over area does not.
    assert unchecked.quality.likely_failed
    assert unchecked.quality.mean_confidence > ConfidenceConfig().failed_mean
    assert unchecked.quality.flipped_share > ConfidenceConfig().failed_flipped


def test_the_part_s_matches_check_orientation(sphere, monkeypatch):
    """``PartialConfig.max_turned`` reaches the refinement of the part's matches only; a whole
    pair's refinement keeps ``RefineConfig.max_turned`` (unset by default)."""
    seen = []
    real = refine_module.refine

    def spy(*args, **kwargs):
        config = inspect.signature(real).bind(*args, **kwargs).arguments["config"]
        seen.append(config.max_turned)
        return real(*args, **kwargs)

    monkeypatch.setattr(refine_module, "refine", spy)
    part = cut_by_plane(sphere, plane_normal(2), 0.3).mesh
    match(part, sphere)
    assert seen and set(seen) == {PartialConfig().max_turned}
    seen.clear()
    match(part, sphere, config=MatchConfig(partial=PartialConfig(max_turned=0.25)))
    assert seen and set(seen) == {0.25}
    seen.clear()
    match(sphere, part)  # whole -> part: the part's match to the whole, inverted
    assert seen and set(seen) == {PartialConfig().max_turned}
    seen.clear()
    # Without the partial setting a part's matches keep the refinement's own.
    own = MatchConfig(partial=PartialConfig(max_turned=None), refine=RefineConfig(max_turned=0.75))
    match(part, sphere, config=own)
    assert seen and set(seen) == {0.75}
    seen.clear()
    match(sphere, sphere)
    assert seen == [None]
    for bad in (0.0, 1.5, "0.5", True):
        with pytest.raises(ValueError, match=r"PartialConfig.max_turned must be None or a number"):
            PartialConfig(max_turned=bad)
    with pytest.raises(ValueError, match=r"RefineConfig.max_turned must be None or a number"):
        RefineConfig(max_turned=-1)


def _partial_pair(tmp_path, source: str, condition: str, index: int, stems: tuple):
    """Pair ``index`` of the ``condition`` set written from ``source``: its meshes and scored
    ground truth, after checking that it is the pair of ``stems``."""
    (out,) = write_partial_sets(
        data_path(source), tmp_path, conditions=[condition], max_pairs=index + 1, reverse=False
    )
    pair = pairs_of(out)[index]
    assert (pair.a.stem, pair.b.stem) == stems
    a, b = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
    return (a, b, *pair.ground_truth(a.n_vertices, b.n_vertices))


def _tiny_pair():
    mesh = hope_rs.Mesh(*bumpy_sphere(200, 0))
    return mesh, mesh


@pytest.mark.slow
def test_half_a_faust_shape_matches_the_whole(tmp_path):
    """A FAUST shape cut in half by a plane, matched to another person in another pose."""
    (out,) = write_partial_sets(
        data_path("faust_r"), tmp_path, conditions=["cut50"], max_pairs=2, reverse=False
    )
    pair = pairs_of(out)[1]
    a, b = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
    ai, bi = pair.ground_truth(a.n_vertices, b.n_vertices)
    e = geodesic_errors(b, match(a, b).map, a_idx=ai, b_idx=bi)
    off = MatchConfig(partial=PartialConfig(enabled=False))
    e_off = geodesic_errors(b, match(a, b, config=off).map, a_idx=ai, b_idx=bi)
    assert e.mean() < 0.06 and e_off.mean() > 2 * e.mean()


def test_partial_set_cli(tmp_path, self_set, capsys):
    assert main(["partial-set", str(tmp_path / "out"), "--from", str(self_set), "--max-pairs", "1",
                 "--conditions", "cut30", "--no-reverse"]) == 0  # fmt: skip
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["spheres_cut30"]
    assert main(["partial-set", str(tmp_path / "bad"), "--from", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err
    assert "is not a folder" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "bad").exists()


@pytest.mark.slow
def test_a_legless_faust_registration_is_matched_exactly(faust_pair):
    """FAUST 012 without its legs onto 018 (same triangulation): the partial path keeps the
    exact map the whole-shape path's shared-face finish reaches."""
    a, b = faust_pair
    keep = a.vertices[:, 1] > np.quantile(a.vertices[:, 1], 0.3)
    part = submesh(a, keep)
    res = match(part.mesh, b)
    assert "A is a part" in str(res.stage("partial")) and "faces" in res.timings
    assert (res.map == part.origin).mean() > 0.999


def test_the_part_s_scale_trials_are_recorded_with_the_kept_one(sphere):
    part = cut_by_plane(sphere, plane_normal(2), 0.3).mesh
    wide_every_time = PartialConfig(wide_below=1.0, wide_margin=0.0)
    res = match(part, sphere, config=MatchConfig(partial=wide_every_time))
    trials = res.stage("partial").trials
    labels = [t.label for t in trials]
    assert labels[:3] == ["x1", "x0.95", "x1.05"] and "merge" in labels
    assert labels[-3:] == ["x0.85", "x0.9", "x1.1"]  # the wider scales every time
    assert all(t.score is not None and 0.0 <= t.score <= 1.0 for t in trials)
    (kept,) = [t for t in trials if t.kept]
    # The kept trial is the map of highest mean confidence among the nearby ones and the
    # merge, unless a wider one reaches it (wide_margin=0).
    best = max(trials[:-3], key=lambda t: t.score)
    wide = max(trials[-3:], key=lambda t: t.score)
    assert kept is (wide if wide.score >= best.score else best)
    assert str(res.stage("partial")).startswith("partial: ")


def test_the_callback_and_progress_see_the_steps_of_a_partial_match(sphere):
    """Both ways: the nested matches' steps reach the caller's callback (so raising there
    stops a partial match too) and progress; whole -> part reports the reversed match's steps
    as its history. (Neither saw a step: the nested matches ran without them.)"""
    part = cut_by_plane(sphere, plane_normal(4), 0.3).mesh
    for a, b in ((part, sphere), (sphere, part)):
        calls, events = [], []
        res = hope_rs.match(a, b, callback=calls.append, progress=events.append)
        assert res.stage("partial").ran
        assert len(res.history) > 0 and len(calls) >= len(res.history)
        assert any(e.iteration is not None for e in events)

        def stop(it):
            raise KeyboardInterrupt

        with pytest.raises(KeyboardInterrupt):
            hope_rs.match(a, b, callback=stop)


def test_a_noisy_dense_part_is_measured_on_its_smoothed_copy(sphere):
    # Vertex noise of about a dense scan's edge length inflates its area: a noisy part
    # subdivided twice measured larger than its whole, kept its own scale, and a faust_r
    # scan (80k, 0.2% noise, holes and a cut) went wrong everywhere (0.49). Its smoothed
    # copy's sqrt(area) is about the clean part's; a clean part keeps its own.
    part = cut_by_plane(sphere, plane_normal(4), 0.3).mesh
    dense = subdivide(part, 2)
    e = dense.faces[:, :2]
    edge = np.linalg.norm(dense.vertices[e[:, 0]] - dense.vertices[e[:, 1]], axis=1).mean()
    rng = np.random.default_rng(3)
    noisy = hope_rs.Mesh(
        dense.vertices + rng.normal(0, 0.6 * edge, dense.vertices.shape), dense.faces
    )
    shapes = {name: Shape(m) for name, m in (("clean", dense), ("noisy", noisy))}
    assert shapes["noisy"].scale > 1.15 * shapes["clean"].scale
    # Against a whole smaller than the noisy part's raw area: the whole's scale is the guess.
    whole = Shape(
        hope_rs.Mesh(sphere.vertices * 1.1 * shapes["clean"].scale / part.scale, sphere.faces)
    )
    assert shapes["clean"].scale < whole.scale < shapes["noisy"].scale
    cfg = PartialConfig()
    assert part_scale(shapes["clean"], cfg) == shapes["clean"].scale
    guess = part_scale(shapes["noisy"], cfg)
    assert guess == pytest.approx(shapes["clean"].scale, rel=0.05)
    off = PartialConfig(rough_smoothing=0)
    assert part_scale(shapes["noisy"], off) == shapes["noisy"].scale
    info = detect_part(shapes["noisy"], whole)
    assert info is not None and info.part == "a" and info.scale == whole.scale


def test_a_part_of_a_noisy_dense_whole_is_measured_at_the_whole_without_its_noise(sphere):
    # The whole's noise inflates its area as a part's does: measured at the noisy whole's raw
    # sqrt(area), a clean FAUST part matched to its whole subdivided once with 0.5% noise was
    # measured half again the size it has against the clean whole, and its match failed.
    whole = subdivide(sphere, 2)
    e = whole.faces[:, :2]
    edge = np.linalg.norm(whole.vertices[e[:, 0]] - whole.vertices[e[:, 1]], axis=1).mean()
    rng = np.random.default_rng(5)
    noisy = Shape(
        hope_rs.Mesh(whole.vertices + rng.normal(0, 0.6 * edge, whole.vertices.shape), whole.faces)
    )
    clean = Shape(whole)
    assert noisy.scale > 1.15 * clean.scale
    part = Shape(cut_by_plane(sphere, plane_normal(4), 0.3).mesh)
    for a, b, side in ((part, noisy, "a"), (noisy, part, "b")):
        info = detect_part(a, b)
        assert info is not None and info.part == side
        assert info.scale == pytest.approx(detect_part(part, clean).scale, rel=0.05)

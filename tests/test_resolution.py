"""Matching at a common resolution: the coarsening to a vertex count, the stage's trigger,
the lifted map on subdivided copies, and the mixed-resolution benchmark sets."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
import trimesh
from conftest import data_path, shared_pair
from meshes import bumpy_sphere, euler_characteristic, flat_grid, mesh_defects
from scipy.spatial import cKDTree

import hope_rs
from hope_rs import MatchConfig
from hope_rs.evaluation.datasets import pairs_of
from hope_rs.evaluation.evaluate import geodesic_errors
from hope_rs.evaluation.partial import cut_by_plane, plane_normal, write_partial_sets
from hope_rs.evaluation.resolution import write_resolution_sets
from hope_rs.features.descriptors import shot_at
from hope_rs.geometry.coarsen import coarse_to_count
from hope_rs.geometry.subdivide import subdivide
from hope_rs.pipeline import multiscale, orientation_repair, resolution
from hope_rs.pipeline.confidence import flipped_share
from hope_rs.pipeline.config import ResolutionConfig
from hope_rs.pipeline.options import check_config
from hope_rs.pipeline.resolution import (
    coarse_copy,
    common_count,
    rough_scan,
    sites_like,
    subdivisions,
)
from hope_rs.pipeline.runner import run_match
from hope_rs.pipeline.turned import TurnedFaces


def test_subdivision_keeps_the_original_vertices_first():
    m = hope_rs.Mesh(*bumpy_sphere(300, 1))
    s = subdivide(m, 2)
    np.testing.assert_array_equal(s.vertices[: m.n_vertices], m.vertices)
    assert s.n_faces == 16 * m.n_faces
    # A closed mesh: V - E + F stays 2 (each edge adds a vertex).
    assert s.n_vertices - 3 * s.n_faces // 2 + s.n_faces == 2


@pytest.mark.parametrize("target", [200, 700])
def test_coarsening_hits_the_vertex_count(target):
    m = subdivide(hope_rs.Mesh(*bumpy_sphere(600, 2)), 1)
    c = coarse_to_count(m, target)
    assert c is not None
    assert abs(c.sites.size / target - 1) <= 0.05
    # Each coarse vertex is a vertex of the mesh and owns itself; every vertex has an owner.
    np.testing.assert_array_equal(c.owner[c.sites], np.arange(c.sites.size))
    np.testing.assert_array_equal(c.mesh.vertices, m.vertices[c.sites])
    assert coarse_to_count(m, m.n_vertices) is None


@pytest.mark.parametrize(
    "bad, why",
    [
        ({"max_ratio": 0.5}, r"max_ratio must be a number >= 1.0"),
        ({"max_ratio": float("inf")}, "max_ratio must be a finite number"),
        ({"count_tolerance": 0.0}, r"count_tolerance must be a number in \(0.0, 1.0\)"),
        ({"count_tolerance": 1.0}, r"count_tolerance must be a number in \(0.0, 1.0\)"),
        ({"refine_min_handles": 1.5}, r"refine_min_handles must be a number in \[0.0, 1.0\]"),
        ({"refine_seed_share": -0.1}, r"refine_seed_share must be a number in \[0.0, 1.0\]"),
        ({"refine_patch_share": 2.0}, r"refine_patch_share must be a number in \[0.0, 1.0\]"),
        ({"refine_min_patched": -1.0}, r"refine_min_patched must be a number in \[0.0, 1.0\]"),
    ],
)
def test_the_setting_is_checked_before_any_work(bad, why):
    # Declared on the fields and checked by check_config, as every other setting.
    config = MatchConfig(resolution=ResolutionConfig(**bad))
    with pytest.raises(ValueError, match=why):
        check_config(config)
    with pytest.raises(ValueError, match=why):
        hope_rs.match(bumpy_sphere(60, 1), bumpy_sphere(60, 2), config=config)


@pytest.mark.parametrize("schedule", [(), (3, 0), (2.5,), (True,), 3])
def test_a_refine_schedule_that_is_not_hop_radii_is_refused(schedule):
    with pytest.raises(ValueError, match="refine_schedule must be a non-empty sequence"):
        ResolutionConfig(refine_schedule=schedule)


def test_a_refine_schedule_list_is_stored_as_a_tuple():
    assert ResolutionConfig(refine_schedule=[2, 1]).refine_schedule == (2, 1)


def _errors(b, res, n):
    idx = np.arange(n)
    return geodesic_errors(b, res.map, a_idx=idx, b_idx=idx)


def test_the_stage_runs_only_when_one_shape_is_much_denser():
    m = hope_rs.Mesh(*bumpy_sphere(400, 3))
    dense = subdivide(m, 1)
    same = hope_rs.match(m, hope_rs.Mesh(*bumpy_sphere(420, 4)), max_passes=1)
    assert "resolution" not in [s.name for s in same.stages]
    res = hope_rs.match(m, dense, max_passes=1)
    stage = res.stage("resolution")
    assert stage.ran and "B clustered to" in stage.reason
    assert res.map.shape == (m.n_vertices,) and res.map.max() < dense.n_vertices
    assert res.confidence is not None and res.confidence.shape == (m.n_vertices,)
    # From the dense side the map is many-to-one: it is judged where it was made, at the
    # common resolution, not by the stages that judge a map at full resolution.
    back = hope_rs.match(dense, m, max_passes=1)
    assert "A clustered to" in back.stage("resolution").reason
    assert "placed as densely as B's" in back.stage("resolution").reason
    # The verdict is the match's at the common resolution, where its 2-rings' distances are
    # kept: measured on the lifted many-to-one map it would flag every such pair.
    orient = back.stage("orient")
    assert not orient.ran and "not flagged" in orient.reason, orient.reason
    assert not back.quality.likely_failed and back.quality.mean_confidence > 0.5
    off = dataclasses.replace(MatchConfig().resolution, enabled=False)
    full = hope_rs.match(m, dense, max_passes=1, config=MatchConfig(resolution=off))
    assert "resolution" not in [s.name for s in full.stages]


@pytest.mark.slow
def test_the_lifted_map_of_a_subdivided_copy(faust_pair):
    """The same body against its subdivided copy (4x the vertices, renumbered), both ways:
    after the lift, the refinement at full resolution (the sparser shape subdivided, the
    shared-face finish) puts the original vertices on themselves."""
    a, _ = faust_pair
    dense = subdivide(a, 1)
    n = a.n_vertices
    perm = np.random.default_rng(3).permutation(dense.n_vertices)
    new = np.argsort(perm)  # vertex i of the subdivided copy is vertex new[i] of the renumbered
    dense = hope_rs.Mesh(dense.vertices[perm], new[dense.faces])
    sa, sd = hope_rs.Shape(a), hope_rs.Shape(dense)
    idx = np.arange(n)
    to_dense = hope_rs.match(sa, sd)
    assert "refined at full resolution" in to_dense.stage("resolution").reason
    e = geodesic_errors(sd, to_dense.map, a_idx=idx, b_idx=new[:n])
    assert np.mean(e == 0) > 0.6 and e.mean() < 0.006
    assert not to_dense.quality.likely_failed
    from_dense = hope_rs.match(sd, sa)
    assert "refined at full resolution" in from_dense.stage("resolution").reason
    e = geodesic_errors(sa, from_dense.map, a_idx=new[:n], b_idx=idx)
    assert np.mean(e == 0) > 0.95 and e.mean() < 0.002


@pytest.mark.slow
def test_with_landmarks_the_lifted_map_is_refined_at_full_resolution_too(faust_pair):
    """Landmarks do not turn the refinement at full resolution off: it runs with them
    pinned, in the subdivided copy's numbering."""
    a, _ = faust_pair
    dense = subdivide(a, 1)
    n = a.n_vertices
    marks = np.array([0, n // 3, n // 2, n - 1])
    pairs = np.column_stack([marks, marks])
    idx = np.arange(n)
    for x, y in ((a, dense), (dense, a)):  # B subdivided, then A
        res = hope_rs.match(x, y, landmarks=pairs)
        assert "refined at full resolution" in res.stage("resolution").reason
        np.testing.assert_array_equal(res.map[marks], marks)
        assert geodesic_errors(y, res.map, a_idx=idx, b_idx=idx).mean() < 0.03


@pytest.mark.slow
def test_landmarks_keep_a_same_triangulation_pair_exact_at_another_resolution(faust_pair):
    """Two poses of one triangulation, B subdivided once, with four right landmarks: the
    refinement at full resolution ends as exact on the original vertices as without them (its
    short pass leaves the right handle patches small, and the finish seeds from them)."""
    a, b = faust_pair
    dense = subdivide(b, 1)
    n = a.n_vertices
    marks = np.array([412, 3350, 5500, 6600])
    res = hope_rs.match(a, dense, landmarks=np.column_stack([marks, marks]))
    assert "refined at full resolution" in res.stage("resolution").reason
    np.testing.assert_array_equal(res.map[marks], marks)
    assert np.mean(res.map == np.arange(n)) > 0.95


@pytest.mark.slow
def test_a_much_denser_a_is_judged_at_the_common_resolution(faust_pair):
    """A body subdivided twice (16x the vertices) against itself: the lifted map is many-to-one,
    so at full resolution it keeps few 2-rings' distances however right it is. The pair is
    judged on the confidence of the match at the common resolution, and the orient stage, which
    would rerun the pipeline at full resolution on a flagged map, is not started."""
    a, _ = faust_pair
    dense = subdivide(a, 2)
    n = a.n_vertices
    res = hope_rs.match(hope_rs.Shape(dense), hope_rs.Shape(a))
    assert "A clustered to" in res.stage("resolution").reason
    orient = res.stage("orient")
    assert not orient.ran and "not flagged" in orient.reason, orient.reason
    assert not res.quality.likely_failed
    e = geodesic_errors(hope_rs.Shape(a), res.map, a_idx=np.arange(n), b_idx=np.arange(n))
    assert e.mean() < 0.02


def test_a_map_the_orient_stage_adopts_after_a_lift_carries_its_own_confidence(monkeypatch):
    # The orient stage forced to replace a lifted map (every turned-over share triggers it, and
    # the best hypothesis replaces the map whatever it costs). Its hypothesis is matched through
    # the resolution stage too, from its map carried to the common resolution, and the map it
    # adopts carries that match's confidence: measured on the many-to-one map at full
    # resolution the confidence would flag it however right.
    real = orientation_repair.choose
    kept = []

    def forced_choice(state, stage, tried, **_):
        kept.append(real(state, stage, tried))
        return kept[-1]

    monkeypatch.setattr(orientation_repair, "choose", forced_choice)
    sphere = hope_rs.Mesh(*bumpy_sphere(400, 3))
    dense = subdivide(sphere, 2)
    forced = dataclasses.replace(MatchConfig().orient, min_turned=0.0, hypotheses=("reverse",))
    cfg = dataclasses.replace(MatchConfig(), orient=forced)
    res = hope_rs.match(dense, sphere, config=cfg)
    assert "A clustered to" in res.stage("resolution").reason
    orient, confidence = res.stage("orient"), res.stage("confidence")
    assert orient.ran and [t.label for t in orient.trials if t.kept] == ["reverse"]
    assert not confidence.ran and "carried over" in confidence.reason
    # The kept trial's own confidence, vertex by vertex (both in A's input numbering).
    trial = kept[-1]  # the stage's final choice
    assert trial.result.confidence is not None
    np.testing.assert_array_equal(res.confidence, trial.result.confidence)
    # Every dense vertex takes its coarse vertex's confidence: the copy's values, repeated.
    assert np.unique(res.confidence).size <= 0.3 * dense.n_vertices
    assert not res.quality.likely_failed and res.quality.mean_confidence > 0.5


@pytest.mark.parametrize("dense_side", ["a", "b"])
def test_a_given_initial_map_is_matched_at_the_common_resolution(dense_side):
    # A start map given for a pair of unlike densities is carried to the coarse copy (each
    # coarse vertex of a dense A takes its site's image; each vertex of A onto a dense B the
    # coarse vertex owning its image) and the pair is matched there, then lifted; the
    # result's init_map stays the map given.
    sphere = hope_rs.Mesh(*bumpy_sphere(300, 5))
    dense = subdivide(sphere, 1)
    n = sphere.n_vertices
    rng = np.random.default_rng(0)
    if dense_side == "a":
        a, b = dense, sphere
        # Each dense vertex onto the nearest original vertex: right, up to an edge.
        init = cKDTree(sphere.vertices).query(dense.vertices)[1]
    else:
        a, b = sphere, dense
        init = np.arange(n)
    # A tenth of the start scrambled: the match must repair it, not only carry it.
    bad = rng.choice(a.n_vertices, a.n_vertices // 10, replace=False)
    init = init.copy()
    init[bad] = rng.integers(0, b.n_vertices, bad.size)
    res = hope_rs.match(a, b, init=init)
    stage = res.stage("resolution")
    assert stage.ran and "clustered to" in stage.reason, stage.reason
    np.testing.assert_array_equal(res.init_map, init)
    idx = np.arange(n)
    e = geodesic_errors(b, res.map[:n] if dense_side == "a" else res.map, a_idx=idx, b_idx=idx)
    assert e.mean() < 0.03 and np.mean(e > 0.15) < 0.01


def test_the_copy_a_dense_a_is_judged_at_is_the_one_it_was_matched_at():
    # state.common_a: per internal vertex of the copy, the vertex of A it is (the copy's own
    # numbering differs from the coarse mesh's), and per vertex of A the copy vertex owning it.
    sphere = hope_rs.Mesh(*bumpy_sphere(400, 3))
    a, b = hope_rs.Shape(subdivide(sphere, 2)), hope_rs.Shape(sphere)
    seen = {}

    def grab(state, name):
        if name == "resolution":
            seen["view"] = state.common_a

    run_match(a, b, "shot", MatchConfig(), on_stage=grab)
    view = seen["view"]
    assert view is not None and view.shape.n_vertices < a.n_vertices / 4
    np.testing.assert_array_equal(view.shape.points, a.points[view.sites])
    np.testing.assert_array_equal(view.owner[view.sites], np.arange(view.shape.n_vertices))
    # Every vertex of A lies nearer its owner than most other copy vertices: a merged cell.
    d_own = np.linalg.norm(a.points - view.shape.points[view.owner], axis=1)
    assert np.median(d_own) < 2.0 * np.median(
        np.linalg.norm(np.diff(a.points[a.edges], axis=1), axis=2)
    )
    # A pair of like densities has none.
    run_match(
        b, hope_rs.Shape(hope_rs.Mesh(*bumpy_sphere(420, 4))), "shot", MatchConfig(), on_stage=grab
    )
    assert seen["view"] is None


def test_a_noisy_dense_a_is_judged_on_its_copy_a_clean_one_at_full_resolution():
    sphere = hope_rs.Mesh(*bumpy_sphere(400, 3))
    dense = subdivide(sphere, 2)
    noise = np.random.default_rng(0).normal(0.0, 0.005 * dense.scale, dense.vertices.shape)
    noisy = hope_rs.Shape(hope_rs.Mesh(dense.vertices + noise, dense.faces))
    clean, b = hope_rs.Shape(dense), hope_rs.Shape(sphere)
    assert rough_scan(noisy, b, 1.5) and not rough_scan(noisy, b, float("inf"))
    assert not rough_scan(clean, b, 1.5)  # subdivision makes a surface smoother
    flat = hope_rs.Shape(hope_rs.Mesh(*flat_grid(20)))  # measures 0: compared with a floor
    assert not rough_scan(clean, flat, 1.5) and rough_scan(noisy, flat, 1.5)
    seen = {}

    def grab(state, name):
        if name == "resolution":
            seen["view"], seen["f"] = state.common_a, state.f

    for a, rough in ((noisy, True), (clean, False)):
        res = run_match(a, b, "shot", MatchConfig(), on_stage=grab)
        view, f = seen["view"], seen["f"]
        assert view.rough is rough
        assert ("a rough scan" in res.stage("resolution").reason) is rough
        on_copy = TurnedFaces(view.shape, b).share(view.of(f))
        full = TurnedFaces(a, b).share(f)
        assert flipped_share(a, b, f, view=view) == (on_copy if rough else full)
        assert res.quality.flipped_share == (on_copy if rough else full)
        if rough:  # a noisy scan's own triangles turn over at random
            assert full > 2 * on_copy, (full, on_copy)


def test_subdivisions_come_nearest_the_denser_count():
    assert [subdivisions(5000, n) for n in (6000, 20000, 40000, 80000, 110000)] == [1, 1, 2, 2, 2]
    assert subdivisions(1000, 5000) == 1


def test_the_benchmark_sets_carry_the_ground_truth(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    for i in range(2):
        v, f = bumpy_sphere(1500, 5 + i)
        with open(src / f"s{i}.off", "w") as fh:
            fh.write(f"OFF\n{len(v)} {len(f)} 0\n")
            np.savetxt(fh, v)
            np.savetxt(fh, np.column_stack([np.full(len(f), 3), f]), fmt="%d")
    written = write_resolution_sets(src, tmp_path / "out", conditions=("sub1", "dec1k"))
    assert sorted(p.name for p in written) == sorted(
        ["src_sub1", "src_sub1_rev", "src_dec1k", "src_dec1k_rev"]
    )
    orig = hope_rs.load_mesh(src / "s0.off")
    for folder in written:
        (pair,) = pairs_of(folder)
        ma, mb = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
        ai, bi = pair.ground_truth(ma.n_vertices, mb.n_vertices)
        assert ai.size == bi.size
        if folder.name.startswith("src_sub1"):
            assert ai.size == 1500
        if folder.name == "src_sub1":
            assert mb.n_vertices > 3 * ma.n_vertices
            np.testing.assert_allclose(
                mb.vertices[bi], hope_rs.load_mesh(src / "s1.off").vertices[bi]
            )
        if folder.name == "src_dec1k":
            assert 800 <= ma.n_vertices <= 1050
            # A valid closed surface, one piece, no isolated vertex.
            defects = mesh_defects(ma.faces)
            assert defects == dict.fromkeys(defects, 0)
            assert euler_characteristic(ma.n_vertices, ma.faces) == 2
            assert np.unique(ma.faces).size == ma.n_vertices
            # The ground truth is the lines whose vertex of A is kept: exact (identity
            # ground truth: vertex bi of s1 is vertex bi of s0).
            assert ai.size == ma.n_vertices
            np.testing.assert_allclose(ma.vertices[ai], orig.vertices[bi], atol=1e-7)
        if folder.name == "src_dec1k_rev":
            assert mb.n_vertices == ai.size


def test_sites_follow_the_sparse_shape_one_per_vertex_reached():
    rng = np.random.default_rng(5)
    points = rng.normal(size=(300, 3))
    f = rng.integers(0, 40, size=300)
    f[f == 7] = 8  # vertex 7 of B is reached by none
    sites = sites_like(f, points)
    reached = np.unique(f)
    # One site per vertex of B reached, sent there, and the one nearest its cluster's centroid.
    assert sites.size == reached.size and np.array_equal(np.sort(f[sites]), reached)
    for v in reached:
        members = np.flatnonzero(f == v)
        d = np.linalg.norm(points[members] - points[members].mean(axis=0), axis=1)
        assert sites[f[sites] == v][0] == members[np.argmin(d)]


def test_a_part_is_coarsened_to_the_density_not_the_count_of_the_other():
    # A whole is coarsened to the sparser shape's vertex count; a part viewed at its whole's
    # scale covers less than unit area, so a whole coarsened to the part's density keeps more
    # vertices than the part has, and the copy of a part view is measured at the view's scale.
    sphere = hope_rs.Mesh(*bumpy_sphere(300, 0))
    dense = hope_rs.Shape(subdivide(sphere, 2))
    whole = hope_rs.Shape(sphere)
    assert common_count(dense, whole) == whole.n_vertices
    part = hope_rs.Shape(cut_by_plane(sphere, plane_normal(2), 0.3).mesh)
    view = part.at_scale(part.internal.scale * 1.2)
    n = common_count(dense, view)
    assert n == round(part.n_vertices * 1.2**2) and n > part.n_vertices
    dense_part = hope_rs.Shape(cut_by_plane(subdivide(sphere, 2), plane_normal(2), 0.3).mesh)
    dense_view = dense_part.at_scale(dense_part.internal.scale * 1.2)
    n_part = common_count(dense_view, whole)
    assert n_part == round(whole.n_vertices / 1.2**2)
    c, copy = coarse_copy(dense_view, n_part, 0.05)
    assert copy.scale == dense_view.scale and copy.scale != copy.internal.scale
    assert copy.n_vertices == pytest.approx(n_part, rel=0.2)
    whole_copy = coarse_copy(dense, whole.n_vertices, 0.05)[1]
    assert whole_copy.scale == whole_copy.internal.scale  # a whole's copy at its own scale
    # So is the multiscale path's copy of a part view, also when the shape built it first.
    big = hope_rs.Shape(cut_by_plane(subdivide(sphere, 3), plane_normal(2), 0.3).mesh)
    own = big.coarse_level()
    big_view = big.at_scale(big.internal.scale * 1.2)
    level = big_view.coarse_level()
    assert own is not None and level is not None
    assert own[1].scale == own[1].internal.scale and level[1].scale == big_view.scale
    # Its SHOT (on the fine mesh at the coarse vertices) has the view's stretched radius.
    c, cs = multiscale.coarse_level(big_view, "shot")
    radius = big.config.descriptors.shot_radius * 1.2
    assert big_view.shot_radius() == pytest.approx(radius)
    # The copy's input numbering is its coarse vertices', in the order of ``c.sites``.
    expected = shot_at(big.internal, c.sites, radius)
    np.testing.assert_allclose(cs.descriptors("shot"), expected, atol=1e-6)


def _matched(pair):
    """The default match of a benchmark pair and its errors at the ground truth."""
    a, b = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
    ai, bi = pair.ground_truth(a.n_vertices, b.n_vertices)
    res = hope_rs.match(a, b)
    return res, geodesic_errors(b, res.map, a_idx=ai, b_idx=bi)


@pytest.mark.slow
def test_a_dense_cut_scan_is_matched_at_its_own_density_and_scale(tmp_path):
    """FAUST tr_reg_004 subdivided twice and cut by a plane (a 49k part), matched to tr_reg_000
    (5k): the part's copy at the common resolution has the whole's density over the part's
    area and is matched at the whole's scale, as the part is (at the whole's vertex count
    and its own scale every trial of the partial stage failed: mean error 0.26)."""
    (rev,) = write_resolution_sets(
        data_path("faust_r"), tmp_path / "res", conditions=("sub2",), max_pairs=2
    )[1:]
    (out,) = write_partial_sets(
        rev, tmp_path / "part", conditions=["cut30"], max_pairs=2, reverse=False
    )
    pair = pairs_of(out)[1]
    assert (pair.a.stem, pair.b.stem) == ("01_01_tr_reg_004_sub2_cut30", "01_01_tr_reg_000")
    res, e = _matched(pair)
    assert "A is a part" in res.stage("partial").reason
    assert e.mean() < 0.06 and np.mean(e > 0.15) < 0.02
    assert not res.quality.likely_failed


@pytest.mark.slow
def test_a_dense_scan_meets_a_template_denser_at_its_hands(tmp_path):
    """A FAUST registration subdivided twice (a uniform 110k "scan", as the benchmark set
    writes it) against another registration (6.9k, denser at the hands and face): matched
    again at a copy of A placed as densely as B's vertices, no region lands far from its
    place (at the uniform copy a hand lands on a thigh: mean error 0.065)."""
    (folder,) = write_resolution_sets(
        data_path("faust_reg"), tmp_path, conditions=("sub2",), max_pairs=3
    )[1:]
    pair = [p for p in pairs_of(folder) if p.name == "02_tr_reg_020_sub2->02_tr_reg_012"][0]
    res, e = _matched(pair)
    assert "placed as densely as B's" in res.stage("resolution").reason
    assert e.mean() < 0.03 and np.mean(e > 0.15) < 0.005
    assert not res.quality.likely_failed


@pytest.mark.slow
def test_a_lifted_map_that_turns_a_side_over_is_repaired_at_the_common_resolution():
    """The same registration subdivided twice in memory (its uniform copy differs from the
    benchmark set's, whose coordinates went through a file): the first lifted map is about a
    half turn of the body (front onto back, left onto right), which turns 23% of A over. The
    orient stage's hypotheses are matched at the common resolution from their maps, so the
    repair takes seconds instead of full-resolution refinements, and the map it keeps carries
    its own match's confidence (measured at full resolution, a right many-to-one map would be
    flagged)."""
    a, b = (
        hope_rs.load_mesh(data_path("faust_reg", "tr_reg_020.off")),
        hope_rs.load_mesh(data_path("faust_reg", "tr_reg_012.off")),
    )
    n = a.n_vertices
    res = hope_rs.match(subdivide(a, 2), b)
    assert "A clustered to" in res.stage("resolution").reason
    assert "carried over" in res.stage("confidence").reason
    idx = np.arange(n)
    e = geodesic_errors(b, res.map[:n], a_idx=idx, b_idx=idx)
    assert e.mean() < 0.04 and np.mean(e > 0.15) < 0.01
    assert not res.quality.likely_failed


def test_with_the_confidence_off_a_lifted_map_is_not_judged_at_full_resolution():
    # Without a confidence of the match at the common resolution there is nothing to judge a
    # dense A's many-to-one map on: measured at full resolution the confidence's rule would
    # flag it however right and send the orient stage through every hypothesis.
    sphere = hope_rs.Mesh(*bumpy_sphere(400, 3))
    dense = subdivide(sphere, 2)
    res = hope_rs.match(dense, sphere, confidence=False)
    assert "A clustered to" in res.stage("resolution").reason
    orient = res.stage("orient")
    assert not orient.ran and "turned over (at most" in orient.reason, orient.reason
    assert "flagged" not in orient.reason
    assert res.confidence is None


def test_a_noisy_dense_copy_is_smoothed_a_clean_one_is_not():
    m = hope_rs.Mesh(*bumpy_sphere(400, 3))
    dense = subdivide(m, 2)
    noise = np.random.default_rng(0).normal(0.0, 0.005 * dense.scale, dense.vertices.shape)
    noisy = hope_rs.Mesh(dense.vertices + noise, dense.faces)
    # The copy made by the collapses alone (the second attempt on the smoothed mesh is tested
    # below): the smoothing of its vertices is what this test is about.
    once = dataclasses.replace(MatchConfig().resolution, collapse_excess=float("inf"))
    config = MatchConfig(resolution=once)
    res = hope_rs.match(m, noisy, max_passes=1, config=config)
    assert "(smoothed: " in res.stage("resolution").reason
    idx = np.arange(m.n_vertices)  # a subdivided mesh keeps its vertices first
    assert geodesic_errors(hope_rs.Shape(noisy), res.map, a_idx=idx, b_idx=idx).mean() < 0.06
    back = hope_rs.match(noisy, m, max_passes=1, config=config)  # a noisy dense A is not smoothed
    assert "A clustered to" in back.stage("resolution").reason
    assert "smoothed" not in back.stage("resolution").reason
    never = dataclasses.replace(once, smooth_rougher=float("inf"))
    off = hope_rs.match(m, noisy, max_passes=1, config=MatchConfig(resolution=never))
    assert "smoothed" not in off.stage("resolution").reason
    clean = hope_rs.match(m, dense, max_passes=1)
    assert "smoothed" not in clean.stage("resolution").reason


def test_collapses_a_noisy_scan_refuses_are_made_again_on_it_smoothed():
    dense = subdivide(hope_rs.Mesh(*bumpy_sphere(400, 0)), 2)
    noise = np.random.default_rng(1).normal(0.0, 0.005 * dense.scale, dense.vertices.shape)
    noisy = hope_rs.Shape(hope_rs.Mesh(dense.vertices + noise, dense.faces))
    target = noisy.n_vertices // 16
    first, _ = coarse_copy(noisy, target, 0.05)  # collapses turning a noisy face over refused
    assert first.mesh.n_vertices > 1.25 * target
    again, _ = coarse_copy(noisy, target, 0.05, 1.25, 5)
    assert again.mesh.n_vertices <= 1.1 * target
    # The copy keeps its vertices' own positions, a valid closed manifold of the same genus.
    np.testing.assert_array_equal(again.mesh.vertices, noisy.internal.vertices[again.sites])
    assert euler_characteristic(again.mesh.n_vertices, again.mesh.faces) == 2
    assert not any(mesh_defects(again.mesh.faces).values())
    np.testing.assert_array_equal(again.owner[again.sites], np.arange(again.sites.size))
    clean = hope_rs.Shape(dense)  # a clean copy reaches its count: made once, the same
    made, _ = coarse_copy(clean, target, 0.05, 1.25, 5)
    np.testing.assert_array_equal(made.sites, coarse_copy(clean, target, 0.05)[0].sites)


@pytest.mark.parametrize("dense_side", ["a", "b"])
def test_remeshed_shapes_skip_the_pass_at_full_resolution(monkeypatch, dense_side):
    """A 5k remeshed FAUST body against another subdivided once (20k), either way round: the
    lifted map's few handles are coincidences scattered in small patches, so the pass at full
    resolution does not run, whatever share of handles it needs; forced to run, it is not
    kept (the finish never qualifies), so the map is the same."""
    a, b, _, _ = shared_pair("faust_r", "tr_reg_000->tr_reg_001")
    dense = hope_rs.Shape(subdivide(b, 1))
    pair = (dense, a) if dense_side == "a" else (a, dense)
    passes = []
    qualifies = resolution.qualifies

    def spy(*args):
        passes.append(qualifies(*args))
        return passes[-1]

    monkeypatch.setattr(resolution, "qualifies", spy)
    rc = dataclasses.replace(ResolutionConfig(), refine_min_handles=0.0)
    res = hope_rs.match(*pair, config=MatchConfig(resolution=rc))
    why = res.stage("resolution").reason
    handles, patched = (float(x) for x in re.findall(r"([0-9.]+)% ", why.split("(")[-1])[:2])
    assert handles > 0 and patched < 100 * rc.refine_min_patched, why
    assert "no shared faces to refine" in why and passes == []
    forced = dataclasses.replace(rc, refine_min_patched=0.0)
    again = hope_rs.match(*pair, config=MatchConfig(resolution=forced))
    assert passes == [False]
    np.testing.assert_array_equal(again.map, res.map)


@pytest.mark.slow
def test_a_remeshed_body_against_a_noisy_dense_scan_of_another(tmp_path):
    """A 5k remeshed FAUST body against another, subdivided twice (80k) with Gaussian noise of
    0.5% of sqrt(area): the copy is smoothed and the map is right."""
    a, b, ai, bi = shared_pair("faust_r", "tr_reg_000->tr_reg_001")
    dense = subdivide(b, 2)
    noise = np.random.default_rng(5).normal(0.0, 0.005 * dense.scale, dense.vertices.shape)
    scan = hope_rs.Shape(hope_rs.Mesh(dense.vertices + noise, dense.faces))
    res = hope_rs.match(a, scan)
    assert "(smoothed: " in res.stage("resolution").reason
    clean_b = hope_rs.Shape(dense)  # scored on the clean surface
    assert geodesic_errors(clean_b, res.map, a_idx=ai, b_idx=bi).mean() < 0.03
    assert not res.quality.likely_failed
    # The other way, the noisy scan as A: the collapses its noise refuses are made again on
    # it smoothed, and the lifted map is judged on the copy it was made at (at full
    # resolution its triangles land degenerate or turned over at random).
    back = hope_rs.match(scan, a)
    why = back.stage("resolution").reason
    count = int(why.split("clustered to ")[1].split(" ")[0])
    assert count <= 1.1 * a.n_vertices and "collapses redone" in why, why
    assert "a rough scan" in why
    template = hope_rs.Shape(a)
    full = flipped_share(scan, template, template.rank[back.map[scan.order]])  # internal maps
    assert geodesic_errors(template, back.map, a_idx=bi, b_idx=ai).mean() < 0.04
    assert back.quality.flipped_share < 0.2 < full
    assert not back.quality.likely_failed and not back.stage("orient").ran


def test_a_copy_that_keeps_no_face_leaves_the_pair_at_full_resolution():
    """Five separate spheres against an icosahedron: the copy at the icosahedron's density
    keeps no face, so the pair is matched as it is, either way round."""
    ball = trimesh.creation.icosphere(1)
    v, f, n = ball.vertices, ball.faces, len(ball.vertices)
    spheres = (
        np.concatenate([v + [3.0 * i, 0, 0] for i in range(5)]),
        np.concatenate([f + n * i for i in range(5)]),
    )
    small = (trimesh.creation.icosphere(0).vertices, trimesh.creation.icosphere(0).faces)
    for a, b in ((spheres, small), (small, spheres)):
        res = hope_rs.match(a, b)
        stage = res.stage("resolution")
        assert stage.ran and "leaves no face: matched at full resolution" in stage.reason
        assert res.map.shape == (len(a[0]),) and res.map.max() < len(b[0])


@pytest.mark.parametrize("dense_side", ["a", "b"])
def test_a_clean_copy_takes_the_dense_meshs_shot_a_smoothed_one_its_own(monkeypatch, dense_side):
    """With ``dense_shot`` a clean copy's SHOT is the dense mesh's at the copy's vertices
    (every dense vertex voting); a noisy dense B's smoothed copy keeps its own."""
    m = hope_rs.Mesh(*bumpy_sphere(400, 3))
    dense = subdivide(m, 2)
    noise = np.random.default_rng(0).normal(0.0, 0.005 * dense.scale, dense.vertices.shape)
    noisy = hope_rs.Mesh(dense.vertices + noise, dense.faces)
    seen = []
    lifted = resolution.ResolutionStage.lifted

    def spy(self, state, coarse, cs, nested):
        big = state.a if self.side == "a" else state.b
        seen.append((big, coarse, cs))
        return lifted(self, state, coarse, cs, nested)

    monkeypatch.setattr(resolution.ResolutionStage, "lifted", spy)
    on = MatchConfig(resolution=dataclasses.replace(MatchConfig().resolution, dense_shot=True))
    pair = (dense, m) if dense_side == "a" else (m, dense)
    hope_rs.match(*pair, max_passes=1, config=on)
    (big, coarse, cs), *_ = seen
    want = shot_at(big.internal, coarse.sites, big.shot_radius())
    np.testing.assert_array_equal(cs.descriptors("shot"), want)
    own = hope_rs.Shape(coarse.mesh).descriptors("shot")  # what the copy alone would give
    assert not np.allclose(own, want)
    seen.clear()
    hope_rs.match(m, noisy, max_passes=1, config=on)  # its copy smoothed: its own SHOT
    (big, coarse, cs), *_ = seen
    dense_shot = shot_at(big.internal, coarse.sites, big.shot_radius())
    assert not np.allclose(cs.descriptors("shot"), dense_shot)

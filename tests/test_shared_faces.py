"""The finishing rounds for shapes that share their triangulation (hope_rs.pipeline.shared_faces)."""

import numpy as np
import pytest
from conftest import data_path
from meshes import bumpy_sphere, cli_maps, drifted, legless, moved_copy, random_rigid, write_off

import hope_rs
from hope_rs import _core
from hope_rs.cli import main
from hope_rs.geometry.mesh import unique_edges
from hope_rs.geometry.numbering import canonical_mesh
from hope_rs.geometry.subdivide import subdivide
from hope_rs.pipeline import handles
from hope_rs.pipeline import shared_faces as SF
from hope_rs.pipeline.config import FinishConfig, PartialConfig
from hope_rs.pipeline.refine import RefineEvents, refine


def test_face_keys_ignore_rotation_but_not_orientation():
    f = np.array([[0, 1, 2], [1, 2, 0], [2, 0, 1], [0, 2, 1], [5, 3, 4]])
    k = handles.face_keys(f, 6)
    assert k[0] == k[1] == k[2] and k[3] != k[0]
    assert k[4] == handles.face_keys(np.array([[3, 4, 5]]), 6)[0]
    # Above 2M vertices the keys are records (n**3 would overflow int64): the same rules.
    big = handles.face_keys(f, 3_000_000)
    assert big[0] == big[1] == big[2] and big[3] != big[0]
    np.testing.assert_array_equal(np.isin(big, big[[1, 4]]), [True, True, True, False, True])


def test_handles_are_the_vertices_whose_faces_all_map_onto_faces_one_to_one():
    s = hope_rs.Shape(bumpy_sphere(200, 0))
    f = np.arange(s.n_vertices)
    assert SF.face_handles(s, s, f).all()
    faces = s.internal.faces
    u, v = faces[0, 0], faces[0, 1]  # swap the images of two neighbours
    g = f.copy()
    g[[u, v]] = g[[v, u]]
    h = SF.face_handles(s, s, g)
    touching = np.unique(faces[(faces == u).any(axis=1) | (faces == v).any(axis=1)])
    assert not h[touching].any() and h[np.setdiff1d(f, touching)].all()
    g = f.copy()
    g[u] = v  # two vertices on one image: neither is a handle
    assert not SF.face_handles(s, s, g)[[u, v]].any()
    # The identity onto the mirror image (a reflection turns every face of a map around) has
    # no handle; reversing the faces alone is not a mirror, since shapes orient them outward.
    mirror = hope_rs.Shape(hope_rs.Mesh(s.mesh.vertices * [-1.0, 1.0, 1.0], s.mesh.faces))
    to_mirror = mirror.rank[s.order]
    assert not SF.face_handles(s, mirror, to_mirror).any()
    rewound = hope_rs.Shape(hope_rs.Mesh(s.mesh.vertices, s.mesh.faces[:, ::-1]))
    assert SF.face_handles(s, rewound, f).all()


def test_the_resolution_stage_checks_a_subdivided_copy_as_its_shape_would():
    # The resolution stage tests a subdivided copy's handles on its canonical mesh before
    # making it a Shape: that mesh and numbering must be the Shape's, even where subdividing
    # a face with a repeated vertex made a face twice, once each way round.
    s = hope_rs.Shape(bumpy_sphere(300, 1))
    faces = s.internal.faces
    a, b = faces[0, 0], faces[0, 1]
    degenerate = hope_rs.Mesh(s.internal.vertices, np.vstack([faces, [[a, a, b]]]))
    for base in (s.internal, degenerate):
        mesh = subdivide(base, 1)
        up = s.derived(mesh)
        internal, order, rank = canonical_mesh(mesh, orient=False)
        assert not np.array_equal(order, np.arange(len(order)))  # a real renumbering
        assert np.array_equal(internal.faces, up.internal.faces)
        assert np.array_equal(order, up.order) and np.array_equal(rank, up.rank)
        assert np.array_equal(internal.vertices, up.points)
        assert np.array_equal(mesh.vertices, up.points[up.rank])  # the stage's points
    assert len(mesh.faces) > len(up.internal.faces)  # the repeated face was dropped


def test_handle_patches_of_a_mesh_are_those_of_its_shape():
    s = hope_rs.Shape(subdivide(hope_rs.Mesh(*bumpy_sphere(300, 1)), 1))
    own = np.arange(s.n_vertices)
    # The identity unknown on a band around a cap: two patches of handles, the cap small.
    d = np.linalg.norm(s.points - s.points[0], axis=1) / s.scale
    banded = np.where((d > 0.2) & (d < 0.3), -1, own)
    rng = np.random.default_rng(0)
    for case, g in enumerate((banded, drifted(s.internal, own, 0, 0.4), rng.permutation(own))):
        h = handles.mesh_face_handles(s.internal, s.internal, g)
        assert np.array_equal(h, SF.face_handles(s, s, g))
        edges = unique_edges(s.internal.faces)
        kept = [handles.edge_large_patches(edges, h, share) for share in (0.0, 0.2, 0.9)]
        for share, mask in zip((0.0, 0.2, 0.9), kept):
            assert np.array_equal(mask, handles.large_patches(s, h, share))
        if case == 0:
            assert np.array_equal(kept[0], h) and 0 < kept[1].sum() < h.sum()
            assert not kept[2].any()


def test_arap_puts_a_rigidly_moved_mesh_back_from_a_third_of_its_vertices():
    v, faces = bumpy_sphere(300, 1)
    s = hope_rs.Shape((v, faces))
    rng = np.random.default_rng(2)
    q, t = random_rigid(rng)
    target = s.points @ q.T + t
    handles = rng.random(s.n_vertices) < 0.3
    start = target + rng.normal(scale=0.02, size=target.shape)
    y = SF.arap_to_handles(s.points, s.edges, start, handles)
    np.testing.assert_array_equal(y[handles], start[handles])
    assert np.abs(y[~handles] - target[~handles]).max() < 0.05  # the noise was 0.02 per axis
    err_free = np.linalg.norm(y[~handles] - target[~handles], axis=1).mean()
    assert err_free < 0.5 * np.linalg.norm(start[~handles] - target[~handles], axis=1).mean()


def test_closest_rotations_match_the_svd_and_reject_bad_input():
    rng = np.random.default_rng(3)
    m = rng.normal(size=(500, 3, 3))
    u, _, vt = np.linalg.svd(m)
    flip = np.ones((500, 3))
    flip[:, 2] = np.sign(np.linalg.det(u @ vt))
    want = np.einsum("nji,nj,nkj->nik", vt, flip, u)
    np.testing.assert_allclose(_core.closest_rotations(m), want, atol=1e-9)
    with pytest.raises(ValueError, match=r"\(n, 3, 3\)"):
        _core.closest_rotations(np.zeros((4, 3, 2)))
    bad = m.copy()
    bad[7, 1, 1] = np.nan
    with pytest.raises(ValueError, match="finite"):
        _core.closest_rotations(bad)


def test_edge_rotations_are_the_rotations_of_the_summed_outer_products_bit_for_bit():
    # The sums the ARAP step formed as a sparse product: the same bits, so the same finish.
    v, faces = bumpy_sphere(300, 1)
    s = hope_rs.Shape((v, faces))
    arap = SF._Arap(s.points, s.edges, FinishConfig())
    rng = np.random.default_rng(4)
    y = s.points + rng.normal(scale=0.05, size=s.points.shape)
    ey = y[arap.i] - y[arap.j]
    cov = arap.per_vertex @ (arap.ex[:, :, None] * ey[:, None, :]).reshape(-1, 9)
    want = _core.closest_rotations(cov.reshape(-1, 3, 3))
    got = _core.edge_rotations(arap.edge_ptr, arap.edge_ids, arap.ex, ey)
    assert np.array_equal(got, want)
    with pytest.raises(ValueError, match="one shape"):
        _core.edge_rotations(arap.edge_ptr, arap.edge_ids, arap.ex, ey[:-1])
    with pytest.raises(ValueError, match="out of range"):
        _core.edge_rotations(arap.edge_ptr, arap.edge_ids + len(ey), arap.ex, ey)
    bad = ey.copy()
    bad[3, 0] = np.inf
    with pytest.raises(ValueError, match="finite"):
        _core.edge_rotations(arap.edge_ptr, arap.edge_ids, arap.ex, bad)


def test_finish_puts_a_drifted_patch_back_on_a_scaled_relabelled_copy(faust_pair):
    a = faust_pair[0]
    b, truth = moved_copy(a, 4)  # relabelled, rotated, scaled by 1.7
    sa, sb = hope_rs.Shape(a), hope_rs.Shape(b)
    f = drifted(a, truth, 3000, 0.15)
    assert 0.08 < (f != truth).mean() < 0.3
    g, rounds = SF.finish(sa, sb, sa.map_in(sb, f))
    assert rounds >= 1
    np.testing.assert_array_equal(sa.map_out(sb, g), truth)


def test_finish_leaves_differently_triangulated_shapes_alone():
    a = hope_rs.Shape(hope_rs.load_mesh(data_path("faust_r", "tr_reg_000.off")))
    b = hope_rs.Shape(hope_rs.load_mesh(data_path("faust_r", "tr_reg_001.off")))
    f = hope_rs.match(a, b, shared_faces=False).map
    fi = a.map_in(b, f)
    assert SF.face_handles(a, b, fi).mean() < FinishConfig().min_handles / 2
    g, rounds = SF.finish(a, b, fi)
    assert rounds == 0 and g is not None
    np.testing.assert_array_equal(g, fi)
    res = hope_rs.match(a, b)
    assert "faces" not in res.timings
    np.testing.assert_array_equal(res.map, f)


@pytest.fixture(scope="module")
def legless_whole_path(faust_pair):
    """FAUST 012 without its legs (A) and the whole 018 (B), matched on the whole-shape path
    (the partial stage off; its own test is in test_partial.py) with and without the
    shared-face finish: ``(part, b, idx, config, res, without)``, ``idx`` A's vertices in 012."""
    part, idx = legless(faust_pair[0])
    sa, sb = hope_rs.Shape(part), hope_rs.Shape(faust_pair[1])
    cfg = hope_rs.MatchConfig(partial=PartialConfig(enabled=False))
    without = hope_rs.match(sa, sb, shared_faces=False, config=cfg)
    res = hope_rs.match(sa, sb, config=cfg)
    return part, faust_pair[1], idx, cfg, res, without


def test_a_partial_shape_of_the_same_triangulation_becomes_exact(legless_whole_path):
    _, _, idx, _, res, without = legless_whole_path
    assert "faces" in res.timings and "faces" not in without.timings
    # The finish's HOPE steps are profiled like the refinement's.
    assert 0 < res.timings["faces.cost"] + res.timings["faces.assign"] < res.timings["faces"]
    assert "faces.cost" not in without.timings
    assert (without.map == idx).mean() < 0.95  # measured 93.1%
    assert (res.map == idx).mean() > 0.999  # measured 100% (99.98% before the growth)


@pytest.mark.slow
def test_cli_and_batch_no_shared_faces_flags(legless_whole_path, tmp_path, capsys):
    # The pair above, whose map the finish changes, with the partial stage off by a --config
    # file: --no-shared-faces gives match(..., shared_faces=False)'s map in both commands,
    # and without the flag `hope-rs match` gives match's map, the finish run.
    part, b, _, _, res, without = legless_whole_path
    assert not np.array_equal(res.map, without.map)  # the flag must make a difference here
    pa, pb, cfg = tmp_path / "a.off", tmp_path / "b.off", tmp_path / "whole.toml"
    write_off(pa, part.vertices, part.faces)
    write_off(pb, b.vertices, b.faces)
    cfg.write_text("[partial]\nenabled = false\n")
    for got in cli_maps(tmp_path, pa, pb, "--config", str(cfg), "--no-shared-faces"):
        np.testing.assert_array_equal(got, without.map)
    out = tmp_path / "default.txt"
    assert main(["match", str(pa), str(pb), "-o", str(out), "-q", "--config", str(cfg)]) == 0
    np.testing.assert_array_equal(np.loadtxt(out, dtype=np.int64), res.map)
    capsys.readouterr()


def test_last_pass_now_makes_that_pass_the_last(faust_pair):
    a, b = faust_pair
    sa, sb = hope_rs.Shape(a), hope_rs.Shape(b)
    f0 = sa.map_in(sb, hope_rs.match(sa, sb, spectral=False, max_passes=1).init_map)
    seen, calls = [], []

    class AfterFirst(RefineEvents):
        def last_pass(self, f, n_pass):
            calls.append(n_pass)

        def last_pass_now(self, f):
            seen.append(f.copy())
            return True

    res = refine(sa, sb, f0, events=AfterFirst())
    passes = sum(it.k == 0 for it in res.history)
    assert passes == 2 and len(seen) == 1 and calls == [1]
    # Never True: the same as without it.
    plain = refine(sa, sb, f0)
    never = refine(sa, sb, f0, events=RefineEvents())
    np.testing.assert_array_equal(never.map, plain.map)
    assert len(never.history) == len(plain.history)

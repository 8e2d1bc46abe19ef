"""The "deform" stage: a deformation-aware pass that runs only between non-isometric shapes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import shared_pair
from meshes import bumped, bumpy_sphere, moved_copy

import hope_rs
from hope_rs import MatchConfig
from hope_rs.evaluation.evaluate import geodesic_errors
from hope_rs.pipeline.config import DeformConfig
from hope_rs.pipeline.deform import deform_refine, spectral_mismatch
from hope_rs.shape import Shape


@pytest.fixture(scope="module")
def blob():
    return hope_rs.Mesh(*bumpy_sphere(600, 3))


def stretched(mesh: hope_rs.Mesh, factor: float) -> hope_rs.Mesh:
    """The mesh with its x axis scaled by ``factor``: not isometric to the original."""
    return hope_rs.Mesh(mesh.vertices * np.array([factor, 1.0, 1.0]), mesh.faces)


def test_spectra_agree_for_an_isometric_copy_and_differ_more_the_more_it_is_stretched(blob):
    moved, _ = moved_copy(blob, 5)  # relabelled, rotated, scaled, shifted
    same = spectral_mismatch(Shape(blob), Shape(moved))
    more = [spectral_mismatch(Shape(blob), Shape(stretched(blob, s))) for s in (2.0, 8.0)]
    assert same < 0.01 < more[0] < more[1]


def test_the_pass_keeps_a_right_map_between_isometric_copies(blob):
    # Deforming A onto B along a right map leaves A's vertices on or next to their images
    # (the low-pass displacement bends a rigid motion's a little: a nearest-point map).
    moved, truth = moved_copy(blob, 7)
    a, b = Shape(blob), Shape(moved)
    f = a.map_in(b, truth)
    g = deform_refine(a, b, f)
    assert np.mean(g == f) > 0.8
    off = np.linalg.norm(b.points[g] - b.points[f], axis=1) / b.scale
    assert off.max() < 0.1


def test_isometric_shapes_skip_the_stage_and_keep_their_map(blob):
    moved, _ = moved_copy(blob, 9)
    on = hope_rs.match(blob, moved, max_passes=2)
    off = hope_rs.match(
        blob, moved, max_passes=2, config=MatchConfig(deform=DeformConfig(enabled=False))
    )
    assert "deform" not in [s.name for s in on.stages]
    assert np.array_equal(on.map, off.map)


def test_a_stretched_pair_runs_the_stage_and_says_why(blob):
    # Another triangulation of the blob's surface, stretched (one triangulation in two poses
    # is the shared-face finish's, whose map is final).
    rng = np.random.default_rng(3)
    rng.normal(size=(600, 3))
    w = rng.normal(size=(6, 3))  # the bumps of bumpy_sphere(600, 3), as drawn there
    p = np.random.default_rng(4).normal(size=(600, 3))
    other = hope_rs.Mesh(*bumped(p / np.linalg.norm(p, axis=1, keepdims=True), w))
    cfg = MatchConfig(deform=DeformConfig(min_mismatch=0.02))
    res = hope_rs.match(blob, stretched(other, 2.0), max_passes=2, config=cfg)
    info = res.stage("deform")
    assert info.ran and info.reason.startswith("spectra differ by")
    assert res.map.shape == (blob.n_vertices,)
    assert res.map.min() >= 0 and res.map.max() < blob.n_vertices


def test_without_the_spectral_pass_no_basis_left_by_an_earlier_match_runs_the_stage(blob):
    """The stage reads the bases of this match's spectral pass only: with spectral=False, a
    basis an earlier match left on the same Shapes re-matched the pair (4692 of 5000 vertices
    of gorilla_01 -> man_01 moved), so the map depended on what ran before."""
    p = np.random.default_rng(4).normal(size=(600, 3))
    w = np.random.default_rng(3).normal(size=(6, 3))
    other = stretched(hope_rs.Mesh(*bumped(p / np.linalg.norm(p, axis=1, keepdims=True), w)), 2.0)
    cfg = MatchConfig(deform=DeformConfig(min_mismatch=0.02))
    fresh = hope_rs.match(Shape(blob), Shape(other), max_passes=2, spectral=False, config=cfg)
    a, b = Shape(blob), Shape(other)
    assert hope_rs.match(a, b, max_passes=2, config=cfg).stage("deform").ran  # bases left
    warm = hope_rs.match(a, b, max_passes=2, spectral=False, config=cfg)
    np.testing.assert_array_equal(warm.map, fresh.map)
    np.testing.assert_array_equal(warm.map, warm.hope_map)
    assert "deform" not in [s.name for s in warm.stages]


def test_the_config_rejects_a_negative_weight():
    with pytest.raises(ValueError, match="spectral_weight"):
        hope_rs.match(
            hope_rs.Mesh(*bumpy_sphere(100, 1)),
            hope_rs.Mesh(*bumpy_sphere(100, 2)),
            config=MatchConfig(deform=DeformConfig(spectral_weight=-1.0)),
        )


@pytest.mark.slow
def test_the_pass_lowers_the_error_of_a_gorilla_to_woman_pair():
    a, b, ai, bi = shared_pair("tosca_nonisometric_r", "8_gorilla_02->8_woman_01")
    cfg = MatchConfig()
    off = dataclasses.replace(cfg, deform=DeformConfig(enabled=False))
    res_on, res_off = hope_rs.match(a, b, config=cfg), hope_rs.match(a, b, config=off)
    assert res_on.stage("deform").ran  # the default gate: these spectra differ by about 0.2
    e_on = geodesic_errors(b, res_on.map, a_idx=ai, b_idx=bi).mean()
    e_off = geodesic_errors(b, res_off.map, a_idx=ai, b_idx=bi).mean()
    # Edge-graph errors: about 0.13 without the pass, 0.09 with it.
    assert e_on < 0.9 * e_off


def test_a_second_closed_piece_does_not_count_as_a_spectral_mismatch():
    """Its constant is a second null eigenvalue: read as A's first frequency, it set a zero
    against B's and made the stage re-match an isometric pair."""
    (va, fa), (vb, fb) = bumpy_sphere(400, 0), bumpy_sphere(400, 1)
    side = np.sqrt(0.01 * hope_rs.Mesh(va, fa).area / 2.366)  # a tetrahedron of 1% the area
    tv = va.max(axis=0) + 1 + side * np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    tf = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]) + len(va)
    with_piece = Shape((np.vstack([va, tv]), np.vstack([fa, tf])))
    b = Shape((vb, fb))
    alone = spectral_mismatch(Shape((va, fa)), b)
    assert abs(spectral_mismatch(with_piece, b) - alone) < 0.01
    assert spectral_mismatch(with_piece, b) < DeformConfig().min_mismatch

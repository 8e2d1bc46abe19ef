"""A noisy shape is judged on its smoothed copy: the confidence of a right map onto a noisy
scan stays high, a wrong region still ranks low, and clean shapes are judged as they are."""

import copy
import dataclasses
import pickle

import numpy as np
import pytest
from meshes import bumpy_sphere
from scipy.spatial import cKDTree

import hope_rs
from hope_rs import Shape
from hope_rs.evaluation.evaluate import confidence_auroc
from hope_rs.geometry.roughness import umbrella_smoothed
from hope_rs.geometry.subdivide import subdivide
from hope_rs.pipeline.confidence import (
    ConfidenceStage,
    confidence_features,
    judged_shapes,
    map_quality,
    state_quality,
    vertex_confidence,
)
from hope_rs.pipeline.config import ConfidenceConfig, MatchConfig
from hope_rs.pipeline.part_info import PartialInfo
from hope_rs.pipeline.progress import StageLog
from hope_rs.pipeline.state import MatchState


def noisy(mesh: hope_rs.Mesh, share: float, seed: int = 0) -> hope_rs.Mesh:
    """``mesh`` with Gaussian vertex noise of ``share`` of its sqrt(area)."""
    rng = np.random.default_rng(seed)
    return hope_rs.Mesh(
        mesh.vertices + rng.normal(0.0, share * mesh.scale, mesh.vertices.shape), mesh.faces
    )


@pytest.fixture(scope="module")
def template_and_scan(faust_pair):
    """FAUST 012 and 018 (same triangulation), 018 subdivided once (its first vertices are
    the original ones, so the identity is the true map) with vertex noise of 0.3% of
    sqrt(area): about half its mean edge length, as a dense scan's."""
    a, b = faust_pair
    return a, noisy(subdivide(b, 1), 0.003)


def test_smoothed_keeps_the_numbering_and_is_measured_in_its_own_units(faust_pair):
    a = Shape(noisy(faust_pair[0], 0.003))
    s = a.smoothed(5)
    np.testing.assert_array_equal(s.internal.faces, a.internal.faces)
    np.testing.assert_array_equal(s.order, a.order)
    np.testing.assert_array_equal(s.points, umbrella_smoothed(a.internal, 5).vertices)
    # The input-numbered mesh is the same surface (internal vertex i is input vertex order[i]).
    np.testing.assert_allclose(s.mesh.vertices[s.order], s.points)
    assert s.scale == s.internal.scale < a.scale  # noise inflates the area; smoothing takes it out
    assert a.smoothed(5) is s  # kept
    # Geodesics run on the smoothed surface: the zigzag of the noisy edges is gone.
    src = np.array([0], dtype=np.int64)
    clean = Shape(faust_pair[0]).graph.distance_fields(src)
    ratio_noisy = np.median(a.graph.distance_fields(src) / np.maximum(clean, 1e-12))
    ratio_smooth = np.median(s.graph.distance_fields(src) / np.maximum(clean, 1e-12))
    assert abs(ratio_smooth - 1.0) < 0.5 * abs(ratio_noisy - 1.0)
    # A view at another scale (a part at its whole's) keeps that scale.
    view = a.at_scale(2.0 * a.scale)
    assert view.smoothed(5).scale == view.scale
    assert view.smoothed(5) is not s


def test_only_a_noisy_denser_shape_is_smoothed(faust_pair, template_and_scan):
    clean = Shape(faust_pair[0])
    dense_clean = Shape(subdivide(faust_pair[1], 1))  # far smoother than FAUST's own mesh
    rough = Shape(noisy(faust_pair[1], 0.003))  # as dense as the template
    scan = Shape(template_and_scan[1])  # 4x as dense, noisy
    bumpy = Shape(hope_rs.Mesh(*bumpy_sphere(600, 3)))
    for s in (clean, dense_clean, bumpy):
        assert s.smoothing_drop < ConfidenceConfig.noisy
    assert rough.smoothing_drop > ConfidenceConfig.noisy
    assert scan.smoothing_drop > ConfidenceConfig.noisy
    cfg = ConfidenceConfig()
    assert judged_shapes(clean, dense_clean, cfg) == (clean, dense_clean)
    # At like densities noise is read as it is (the model ranks it better so).
    assert judged_shapes(clean, rough, cfg) == (clean, rough)
    assert judged_shapes(rough, clean, cfg) == (rough, clean)
    a, b = judged_shapes(clean, scan, cfg)
    assert a is clean and b is scan.smoothed(cfg.rough_smoothing)
    a, b = judged_shapes(scan, clean, cfg)
    assert a is scan.smoothed(cfg.rough_smoothing) and b is clean
    off = dataclasses.replace(cfg, rough_smoothing=0)
    assert judged_shapes(clean, scan, off) == (clean, scan)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("noisy", 1.5),
        ("noisy", -0.1),
        ("denser", 0.5),
        ("denser", float("inf")),
        ("rough_smoothing", -1),
        ("rough_smoothing", 2.5),
    ],
)
def test_noisy_settings_are_checked(field, value):
    with pytest.raises(ValueError, match=f"ConfidenceConfig.{field}"):
        ConfidenceConfig(**{field: value})


def test_a_right_map_onto_a_noisy_scan_is_confident(template_and_scan):
    a_mesh, b_mesh = template_and_scan
    a, b = Shape(a_mesh), Shape(b_mesh)
    f = a.map_in(b, np.arange(a.n_vertices))  # the true map
    on = map_quality(a, b, f, None, None, MatchConfig())
    as_is = MatchConfig(confidence=ConfidenceConfig(rough_smoothing=0))
    off = map_quality(a, b, f, None, None, as_is)
    assert on.mean_confidence > 0.95 and not on.likely_failed
    # Measured on the noisy surface, the same map reads as distorted.
    assert off.mean_confidence < on.mean_confidence - 0.1


def test_a_wrong_region_onto_a_noisy_scan_still_ranks_low(template_and_scan):
    a_mesh, b_mesh = template_and_scan
    a, b = Shape(a_mesh), Shape(b_mesh)
    truth = np.arange(a_mesh.n_vertices)
    # A ball of A (0.25 sqrt(area) around the top of the head) carried 0.1 sqrt(area) along
    # x: consistent locally, wrong.
    centre = a_mesh.vertices[int(np.argmax(a_mesh.vertices[:, 1]))]
    region = np.linalg.norm(a_mesh.vertices - centre, axis=1) < 0.25 * a_mesh.scale
    moved = a_mesh.vertices[region] + np.array([0.1 * a_mesh.scale, 0.0, 0.0])
    g = truth.copy()
    g[region] = truth[cKDTree(a_mesh.vertices).query(moved)[1]]
    f = a.map_in(b, g)
    wrong = np.linalg.norm(a_mesh.vertices[g] - a_mesh.vertices, axis=1) > 0.05 * a_mesh.scale
    assert 0.02 < wrong.mean() < 0.5
    cfg = MatchConfig().confidence
    ja, jb = judged_shapes(a, b, cfg)
    assert jb is not b  # the scan is judged smoothed
    conf = vertex_confidence(ja, jb, f, confidence_features(ja, jb, f, config=cfg), cfg)[a.rank]
    assert confidence_auroc(conf, np.where(wrong, 1.0, 0.0), wrong_above=0.5) > 0.9
    assert conf[~wrong].mean() > 0.9


def test_a_smoothed_copy_pickles_and_views_share_its_geometry(faust_pair):
    a = Shape(noisy(faust_pair[0], 0.003))
    s = a.smoothed(5)
    for back in (pickle.loads(pickle.dumps(s)), copy.deepcopy(s)):
        np.testing.assert_array_equal(back.order, s.order)
        np.testing.assert_array_equal(back.internal.faces, s.internal.faces)
        np.testing.assert_array_equal(back.points, s.points)
        assert back.scale == s.scale
    view = a.at_scale(1.5 * a.scale)
    vs = view.smoothed(5)
    assert vs.graph is s.graph and vs.scale == view.scale  # made once, measured at the view's
    back = pickle.loads(pickle.dumps(vs))
    np.testing.assert_array_equal(back.points, s.points)
    assert back.scale == vs.scale
    assert view.smoothing_drop == a.smoothing_drop


def test_the_confidence_stage_judges_a_dense_noisy_part_smoothed(template_and_scan):
    """The whole -> part path's confidence stage on the true map onto a noisy dense part (the
    scan without its top quarter), as the partial stage leaves it: confident and not flagged;
    measured on the noisy scan itself, flagged."""
    a_mesh, b_mesh = template_and_scan
    top = b_mesh.vertices[:, 1] > np.quantile(b_mesh.vertices[:, 1], 0.75)
    faces = b_mesh.faces[~top[b_mesh.faces].any(axis=1)]
    used = np.unique(faces)
    part = hope_rs.Mesh(b_mesh.vertices[used], np.searchsorted(used, faces))
    a = Shape(a_mesh)
    b = Shape(part).at_scale(a.scale)  # the part measured at the whole's scale
    on_part = np.flatnonzero(~top[: a_mesh.n_vertices])  # A's vertices kept on the part
    g = np.zeros(a_mesh.n_vertices, dtype=np.int64)
    g[on_part] = np.searchsorted(used, on_part)
    counterpart = np.zeros(a.n_vertices, dtype=bool)
    counterpart[a.rank[on_part]] = True
    quality = {}
    for n in (5, 0):
        config = MatchConfig(confidence=ConfidenceConfig(rough_smoothing=n))
        state = MatchState(a, b, config, "shot", StageLog())
        state.f = state.hope_map = a.map_in(b, g)
        state.partial = PartialInfo("b", (0.0, 1.0), a.scale, counterpart=counterpart)
        ConfidenceStage().run(state)
        quality[n] = state_quality(state)
    assert not quality[5].likely_failed and quality[5].mean_confidence > 0.9
    assert quality[0].likely_failed

"""The "denoise" stage: a noisy shape is matched on its smoothed copy, only when its noise is
large against its edges, only between shapes of like density, and never twice."""

import dataclasses

import numpy as np
import pytest
from conftest import data_path
from meshes import bumpy_sphere

import hope_rs
from hope_rs import MatchConfig, Mesh, Shape
from hope_rs.evaluation.evaluate import load_vts
from hope_rs.evaluation.partial import cut_by_plane
from hope_rs.evaluation.perturbed import add_noise
from hope_rs.pipeline import runner
from hope_rs.pipeline.denoise import noisy
from hope_rs.pipeline.runner import run_match

#: Quick settings: the stage's choice, not the maps, is what most tests look at.
FAST = {"max_passes": 1, "spectral": False, "shared_faces": False}


def _edge_noise(mesh: Mesh, edges: float, seed: int) -> Mesh:
    """``mesh`` with Gaussian noise of ``edges`` mean edge lengths on each coordinate."""
    e = np.concatenate([mesh.faces[:, [0, 1]], mesh.faces[:, [1, 2]], mesh.faces[:, [2, 0]]])
    mean_edge = np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1).mean()
    rng = np.random.default_rng(seed)
    return Mesh(mesh.vertices + rng.normal(0.0, edges * mean_edge, mesh.vertices.shape), mesh.faces)


@pytest.fixture(scope="module")
def spheres():
    return [Mesh(*bumpy_sphere(400, s)) for s in (11, 12)]


def test_a_noisy_b_is_matched_smoothed_and_a_clean_pair_is_not(spheres):
    a, b = spheres
    clean = hope_rs.match(a, b, **FAST)
    assert not clean.stage("denoise").ran  # not applicable: not even recorded
    rough = hope_rs.match(a, _edge_noise(b, 0.4, 1), **FAST)
    info = rough.stage("denoise")
    assert info is not None and info.ran
    assert info.reason.startswith("B smoothed 2 times (roughness ")
    assert "A smoothed" not in info.reason
    assert rough.map.shape == (a.n_vertices,) and rough.map.max() < b.n_vertices
    # Light noise (a tenth of an edge) reads as a clean surface.
    assert not hope_rs.match(a, _edge_noise(b, 0.1, 1), **FAST).stage("denoise").ran


def test_both_shapes_noisy_are_both_smoothed_and_the_stage_can_be_turned_off(spheres):
    a, b = (_edge_noise(m, 0.4, s) for s, m in enumerate(spheres))
    res = hope_rs.match(a, b, **FAST)
    assert "A smoothed 2 times" in res.stage("denoise").reason
    assert "B smoothed 2 times" in res.stage("denoise").reason
    cfg = MatchConfig().with_options(**FAST)
    off = dataclasses.replace(cfg, denoise=dataclasses.replace(cfg.denoise, enabled=False))
    assert not hope_rs.match(a, b, config=off).stage("denoise").ran


def test_the_map_is_the_match_of_the_smoothed_copy_in_the_input_numbering(spheres):
    """The stage swaps in Shape.smoothed copies (same numbering): the map equals a match of
    those copies run with the stage off."""
    a = Shape(spheres[0])
    b = Shape(_edge_noise(spheres[1], 0.4, 3))
    cfg = MatchConfig().with_options(**FAST)
    res = run_match(a, b, "shot", cfg)
    off = dataclasses.replace(cfg, denoise=dataclasses.replace(cfg.denoise, enabled=False))
    direct = run_match(a, b.smoothed(cfg.denoise.iterations), "shot", off)
    np.testing.assert_array_equal(res.map, direct.map)


def test_a_smoothed_copy_is_never_smoothed_again(spheres):
    s = Shape(_edge_noise(spheres[0], 0.8, 4))
    assert noisy(s, 0.16, 0.2)
    once = s.smoothed(2)
    assert once.smoothing == 2 and s.smoothing == 0
    assert not noisy(once, 0.0, 0.0)  # whatever the thresholds
    assert not noisy(once.at_scale(0.5 * once.scale), 0.0, 0.0)  # nor its views


def test_smoothings_add_up():
    s = Shape(Mesh(*bumpy_sphere(200, 3)))
    assert s.smoothed(2).smoothed(1).smoothing == 3


def test_a_noisy_part_and_its_whole_are_smoothed_and_no_nested_match_smooths_again(
    spheres, monkeypatch
):
    """A part (40% of a noisy sphere: fewer than half its vertices, for its smaller area)
    against its noisy whole: like density at the whole's scale, so both are smoothed by the
    outer match; the nested matches (the partial stage's trials) run with the stage off."""
    whole = _edge_noise(spheres[1], 0.4, 6)
    part = cut_by_plane(whole, np.array([0.3, 1.0, 0.2]), 0.6).mesh
    assert part.n_vertices < whole.n_vertices / 2
    nested = []
    real = runner.run_match

    def spy(a, b, init, config, **kwargs):
        nested.append(config.denoise.enabled)
        return real(a, b, init, config, **kwargs)

    monkeypatch.setattr(runner, "run_match", spy)
    res = hope_rs.match(part, whole, **FAST)
    assert res.stage("partial").ran
    reason = res.stage("denoise").reason
    assert "A smoothed 2 times" in reason and "B smoothed 2 times" in reason
    assert nested and not any(nested)


def test_a_much_denser_noisy_shape_is_left_to_the_resolution_stage(spheres):
    a = spheres[0]
    dense = Mesh(*bumpy_sphere(2400, 13))
    res = hope_rs.match(a, _edge_noise(dense, 0.4, 5), **FAST)
    assert not res.stage("denoise").ran and res.stage("resolution").ran


@pytest.mark.slow
def test_a_non_isometric_pair_against_a_noisy_copy_is_repaired():
    """TOSCA woman 02 -> man 02 (remeshed, not a benchmark pair) with Gaussian noise of 0.5%
    of sqrt(area) on B, as perturb-set's noise05 builds it: on the noisy B the map put most
    of the body on the wrong place (0.50), on its smoothed copy it is right."""
    d = data_path("tosca_nonisometric_r")
    a, b = hope_rs.load_mesh(d / "8_woman_02.off"), hope_rs.load_mesh(d / "8_man_02.off")
    a_idx, b_idx = (
        load_vts(d / "corres" / "8_woman_02.vts"),
        load_vts(d / "corres" / "8_man_02.vts"),
    )
    b = add_noise(b, 0.005, 7)
    res = hope_rs.match(a, b)
    assert res.stage("denoise").reason.startswith("B smoothed 2 times")
    errors = hope_rs.geodesic_errors(b, res.map, a_idx=a_idx, b_idx=b_idx)
    assert errors.mean() < 0.06 and (errors > 0.15).mean() < 0.05, errors.mean()
    assert not res.quality.likely_failed

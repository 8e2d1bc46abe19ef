import json

import numpy as np
import pytest
from conftest import shared_pair
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from meshes import bumpy_sphere, bumpy_sphere_files, flat_grid, inverse, relabel
from strategies import bumpy_surfaces, half_corrupted, isometric_copies, permutations

import hope_rs
from hope_rs.cli.commands import main
from hope_rs.evaluation.evaluate import confidence_auroc
from hope_rs.pipeline.confidence import (
    MatchQuality,
    flipped_share,
    match_quality,
    predict_confidence,
)
from hope_rs.pipeline.config import (
    CONFIDENCE_FEATURES,
    ConfidenceConfig,
    MatchConfig,
    OrientConfig,
)
from hope_rs.pipeline.progress import STAGES
from hope_rs.pipeline.turned import TurnedFaces


@pytest.fixture(scope="module")
def broken_and_good(faust_pair):
    """FAUST 012 -> 018 matched from a scrambled initial map with one pass and no spectral
    pass (a broken map), and from the right map (a good one)."""
    a, b = faust_pair
    order = np.argsort(np.sin(np.arange(a.n_vertices) * 12.9898) * 43758.5453 % 1.0)
    # Without the orient stage, which repairs this map (it turns much of A over).
    no_repair = MatchConfig(orient=OrientConfig(enabled=False))
    broken = hope_rs.match(a, b, init=order, max_passes=1, spectral=False, config=no_repair)
    good = hope_rs.match(a, b, init=np.arange(a.n_vertices), max_passes=1, spectral=False)
    return a, b, broken, good


def test_confidence_is_a_probability_per_vertex_of_a(broken_and_good):
    a, _, broken, good = broken_and_good
    for res in (broken, good):
        assert res.confidence.shape == (a.n_vertices,)
        assert res.confidence.dtype == np.float64
        assert np.all((res.confidence >= 0) & (res.confidence <= 1))
    assert "confidence" in STAGES and res.stage("confidence").ran


def test_quality_flags_a_broken_match_and_not_a_good_one(broken_and_good):
    a, b, broken, good = broken_and_good
    truth = np.arange(a.n_vertices)
    assert np.mean(broken.map == truth) < 0.5  # the broken match is broken
    assert np.mean(good.map == truth) > 0.95
    assert isinstance(good.quality, MatchQuality)
    assert broken.quality.likely_failed
    assert not good.quality.likely_failed
    assert good.quality.mean_confidence > broken.quality.mean_confidence + 0.3
    assert good.quality == match_quality(
        good.confidence, good.config.confidence, flipped=good.quality.flipped_share
    )
    sa, sb = hope_rs.Shape(a), hope_rs.Shape(b)
    turned = flipped_share(sa, sb, sa.map_in(sb, good.map))
    assert good.quality.flipped_share == pytest.approx(turned, abs=1e-12)
    assert good.quality.flipped_share < 0.01  # one triangulation: the right map keeps windings
    assert broken.quality.flipped_share > 0.1


def test_map_or_unmatched(broken_and_good):
    _, _, broken, _ = broken_and_good
    for t in (0.0, 0.3, 0.5, 0.9, 1.0):
        m = broken.map_or_unmatched(t)
        low = broken.confidence < t
        assert np.all(m[low] == -1)
        np.testing.assert_array_equal(m[~low], broken.map[~low])
    assert np.any(broken.map_or_unmatched() == -1)
    for bad in ("0.5", 1.5, True):
        with pytest.raises(ValueError, match="threshold must be a number in"):
            broken.map_or_unmatched(bad)
    np.testing.assert_array_equal(broken.map_or_unmatched(0.0), broken.map)
    m = broken.map_or_unmatched()
    m[:] = 0  # a new array: the result's map is untouched
    assert not np.all(broken.map == 0)
    with pytest.raises(ValueError, match="threshold"):
        broken.map_or_unmatched(1.5)


def test_turned_off_the_stage_is_skipped_and_the_map_unchanged():
    a, b = (hope_rs.Mesh(*bumpy_sphere(600, s)) for s in (0, 1))
    init = np.arange(a.n_vertices)
    on = hope_rs.match(a, b, init=init, max_passes=1, spectral=False)
    off = hope_rs.match(a, b, init=init, max_passes=1, spectral=False, confidence=False)
    assert off.confidence is None and off.quality is None
    assert not off.stage("confidence").ran
    np.testing.assert_array_equal(on.map, off.map)
    with pytest.raises(ValueError, match="confidence=False"):
        off.map_or_unmatched()
    cfg = MatchConfig(confidence=ConfidenceConfig(enabled=False))
    assert hope_rs.match(a, b, init=init, max_passes=1, config=cfg).confidence is None
    with pytest.raises(TypeError, match="confidence"):
        hope_rs.match(a, b, confidence="yes")


def test_the_model_reads_one_weight_per_feature():
    x = np.zeros((3, len(CONFIDENCE_FEATURES)))
    np.testing.assert_allclose(
        predict_confidence(x, ConfidenceConfig(intercept=0.0)), np.full(3, 0.5)
    )
    with pytest.raises(ValueError, match="features must have one column per feature"):
        predict_confidence(x[:, :2])


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("weights", (1.0, 2.0), "one finite number per feature"),
        ("weights", (float("inf"),) * len(CONFIDENCE_FEATURES), "got inf"),
        ("weights", "abc", "sequence of numbers"),
        ("n_anchors", 0, r"integer in \[1, 10000\]"),
        ("rings", 2.5, r"integer in \[0, 10000\]"),
        ("floor", 0.0, "finite positive number"),
        ("intercept", float("nan"), "finite number"),
        ("threshold", 1.5, r"in \[0, 1\]"),
        ("failed_flipped", True, r"in \[0, 1\]"),
    ],
)
def test_confidence_config_refuses_bad_settings_before_matching(field, value, message):
    with pytest.raises((TypeError, ValueError), match=f"ConfidenceConfig.{field} must .*{message}"):
        ConfidenceConfig(**{field: value})


def test_confidence_config_weights_become_floats():
    cfg = ConfidenceConfig(weights=list(range(len(CONFIDENCE_FEATURES))))
    assert cfg.weights == tuple(float(i) for i in range(len(CONFIDENCE_FEATURES)))
    assert ConfidenceConfig() == ConfidenceConfig(weights=list(ConfidenceConfig().weights))


def test_quality_rule():
    cfg = ConfidenceConfig(threshold=0.5, failed_mean=0.5, failed_share=0.5)
    assert not match_quality(np.array([0.9, 0.8, 0.2]), cfg).likely_failed
    assert match_quality(np.array([0.9, 0.1, 0.2]), cfg).likely_failed
    q = match_quality(np.array([0.6, 0.4]), cfg)
    assert q.share_confident == 0.5 and q.mean_confidence == pytest.approx(0.5)
    assert q.flipped_share == 0.0 and not q.likely_failed
    assert match_quality(np.array([0.9, 0.8]), cfg, flipped=0.2).flipped_share == 0.2
    cfg = ConfidenceConfig(failed_flipped=0.25)
    assert not match_quality(np.array([0.9, 0.8]), cfg, flipped=0.25).likely_failed
    assert match_quality(np.array([0.9, 0.8]), cfg, flipped=0.26).likely_failed


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_relabelling_both_meshes_relabels_the_confidence(data):
    v, f = data.draw(bumpy_surfaces(300, 500), label="surface")
    a = hope_rs.Mesh(v, f)
    b, truth = data.draw(isometric_copies(v, f), label="copy")
    init = data.draw(half_corrupted(truth), label="init")
    pa = data.draw(permutations(a.n_vertices), label="pa")  # new vertex i of A = old pa[i]
    pb = data.draw(permutations(b.n_vertices), label="pb")
    a2 = hope_rs.Mesh(a.vertices[pa], relabel(a.faces, pa))
    b2 = hope_rs.Mesh(b.vertices[pb], relabel(b.faces, pb))
    opts = {"max_passes": 1, "spectral": False}
    res = hope_rs.match(a, b, init=init, **opts)
    res2 = hope_rs.match(a2, b2, init=inverse(pb)[init[pa]], **opts)
    np.testing.assert_array_equal(res2.map, inverse(pb)[res.map[pa]])
    np.testing.assert_allclose(res2.confidence, res.confidence[pa], rtol=1e-9, atol=1e-12)
    assert res2.quality.flipped_share == pytest.approx(res.quality.flipped_share, abs=1e-12)


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_flipped_share_is_the_area_a_map_turns_over(data):
    v, f = data.draw(bumpy_surfaces(200, 400), label="surface")
    n = len(v)
    # Two closed components, the second twice as large (four times the area); on B the
    # second is mirrored. Each vertex onto itself keeps the first one's windings and turns
    # every triangle of the second over (both shapes are oriented outward).
    big = v * 2.0 + np.array([10.0, 0.0, 0.0])
    flip = np.array([-1.0, 1.0, 1.0])
    faces = np.concatenate([f, f + n])
    a = hope_rs.Shape(hope_rs.Mesh(np.concatenate([v, big]), faces))
    b = hope_rs.Shape(hope_rs.Mesh(np.concatenate([v, big * flip]), faces))
    same = a.map_in(b, np.arange(2 * n))
    second = (np.arange(2 * n) >= n)[a.order]  # internal numbering
    assert flipped_share(a, b, same) == pytest.approx(0.8, abs=0.02)  # by area, not count
    assert flipped_share(a, b, same, among=~second) < 0.01
    assert flipped_share(a, b, same, among=second) > 0.99
    assert flipped_share(a, a, a.map_in(a, np.arange(2 * n))) < 0.01
    # Per vertex (the refinement's orientation check): the second component's vertices.
    np.testing.assert_array_equal(TurnedFaces(a, b).vertices(same, 0.5), second)
    # Images on one vertex count on neither side; no counted triangle gives 0.
    assert flipped_share(a, b, np.zeros(2 * n, dtype=np.int64)) == 0.0
    assert flipped_share(a, b, same, among=np.zeros(2 * n, dtype=bool)) == 0.0


def test_flipped_share_of_open_surfaces_counts_the_smaller_side():
    # A cap of a sphere: which side of an open surface is outward is a guess, so a map onto
    # its mirror image turns nothing over as far as the share can tell; the whole sphere
    # onto its mirror image turns everything over.
    v, f = bumpy_sphere(600, 3)
    cap = f[(v[f][:, :, 2] > -0.2).all(axis=1)]
    used = np.unique(cap)
    renum = np.full(len(v), -1)
    renum[used] = np.arange(used.size)
    pv, pf = v[used], renum[cap]
    a = hope_rs.Shape(hope_rs.Mesh(pv, pf))
    mirror = hope_rs.Shape(hope_rs.Mesh(pv * np.array([-1.0, 1.0, 1.0]), pf))
    same = a.map_in(mirror, np.arange(used.size))
    assert flipped_share(a, mirror, same) < 0.01
    whole = hope_rs.Shape(hope_rs.Mesh(v, f))
    closed = hope_rs.Shape(hope_rs.Mesh(v * np.array([-1.0, 1.0, 1.0]), f))
    assert flipped_share(whole, closed, whole.map_in(closed, np.arange(len(v)))) > 0.99


@pytest.mark.slow
def test_auroc_on_a_held_out_remeshed_pair():
    a, b, a_idx, b_idx = shared_pair("faust_r", "tr_reg_000->tr_reg_001")
    # One pass without the spectral pass leaves wrong regions to find.
    res = hope_rs.match(a, b, max_passes=1, spectral=False)
    errors = hope_rs.geodesic_errors(b, res.map, a_idx=a_idx, b_idx=b_idx)
    assert 0.02 < np.mean(errors > 0.05) < 0.9
    assert confidence_auroc(res.confidence[a_idx], errors) > 0.85


def test_confidence_auroc():
    errors = np.array([0.0, 0.01, 0.2, 0.3])
    assert confidence_auroc([0.9, 0.8, 0.1, 0.2], errors) == 1.0
    assert confidence_auroc([0.1, 0.2, 0.9, 0.8], errors) == 0.0
    assert confidence_auroc([0.5, 0.5, 0.5, 0.5], errors) == 0.5
    assert confidence_auroc([0.9, 0.3, 0.5, 0.2], errors) == 0.75
    assert np.isnan(confidence_auroc([0.1, 0.2], [0.0, 0.0]))
    # A NaN would rank as it happens to sort: refused.
    for conf, err in (([np.nan, 0.1, 0.5], [0.0, 1.0, 0.0]), ([0.9, 0.1], [np.nan, 0.0])):
        with pytest.raises(ValueError, match=r"holds NaN \(at index 0\)"):
            confidence_auroc(conf, err)


def test_cli_writes_the_confidence_for_show(tmp_path, capsys):
    pa, pb = bumpy_sphere_files(tmp_path, 2, 400)
    out, conf = tmp_path / "map.npy", tmp_path / "conf.npy"
    args = ["match", str(pa), str(pb), "-o", str(out), "-q", "--json"]
    assert main([*args, "--confidence-out", str(conf)]) == 0
    summary = json.loads(capsys.readouterr().out)
    c = np.load(conf)
    assert c.shape == (np.load(out).size,) and c.dtype == np.float64
    assert np.all((c >= 0) & (c <= 1))
    assert summary["quality"]["mean_confidence"] == pytest.approx(c.mean())
    # A bad name fails before any work, in one line.
    assert main(["match", str(pa), str(pb), "-q", "--confidence-out", str(tmp_path / "c.txt")]) == 2
    assert "must end in .npy" in capsys.readouterr().err
    assert not (tmp_path / "c.txt").exists()
    # So does asking for the confidence with a config that turns its stage off.
    cfg = tmp_path / "noconf.toml"
    cfg.write_text("[confidence]\nenabled = false\n")
    off = ["--config", str(cfg), "--confidence-out", str(tmp_path / "c2.npy")]
    assert main(["match", str(pa), str(pb), "-q", "-o", str(tmp_path / "m2.npy"), *off]) == 2
    assert "needs the confidence stage" in capsys.readouterr().err
    assert not (tmp_path / "m2.npy").exists() and not (tmp_path / "c2.npy").exists()


@pytest.mark.slow
def test_quality_flags_a_failed_benchmark_pair():
    # Gorilla -> man (TOSCA non-isometric, remeshed): without the orient stage, which repairs
    # it, the map is wrong almost everywhere (mean geodesic error about 0.7).
    a, b, a_idx, b_idx = shared_pair("tosca_nonisometric_r", "8_gorilla_02->8_man_02")
    res = hope_rs.match(a, b, config=MatchConfig(orient=OrientConfig(enabled=False)))
    errors = hope_rs.geodesic_errors(b, res.map, a_idx=a_idx, b_idx=b_idx)
    assert np.mean(errors > 0.05) > 0.9
    assert res.quality.likely_failed and res.quality.mean_confidence < 0.5


def test_a_lone_triangle_matched_to_itself_is_not_confident():
    # Three vertices: every 2-ring is the whole shape and no anchor is far, so no feature
    # can tell the rotated map it comes back with from the identity.
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.3, 0.8, 0.0]])
    tri = (v, np.array([[0, 1, 2]]))
    res = hope_rs.match(tri, tri)
    assert np.all(res.confidence == 0.0)
    assert res.quality.likely_failed


def test_shapes_below_min_vertices_get_no_confidence_and_above_keep_it():
    v, f = flat_grid(6)  # 36 vertices
    res = hope_rs.match((v, f), (v, f), init=np.arange(36))
    assert res.confidence.mean() > 0.5
    small = MatchConfig(confidence=ConfidenceConfig(min_vertices=37))
    res = hope_rs.match((v, f), (v, f), config=small, init=np.arange(36))
    assert np.all(res.confidence == 0.0) and res.quality.likely_failed


@pytest.mark.parametrize("bad", [-1, 2.5, True])
def test_min_vertices_must_be_a_non_negative_integer(bad):
    with pytest.raises(ValueError, match="min_vertices"):
        ConfidenceConfig(min_vertices=bad)


def test_a_self_match_onto_a_true_symmetry_stays_confident():
    # The grid turned by 180 degrees onto itself keeps every edge (the diagonals included).
    n = 17
    v, f = flat_grid(n)
    turn = (n * n - 1) - np.arange(n * n)
    res = hope_rs.match((v, f), (v, f), init=turn)
    assert np.array_equal(res.map, turn) or np.array_equal(res.map, np.arange(n * n))
    assert res.confidence.mean() > 0.9 and not res.quality.likely_failed


@pytest.mark.parametrize("n", [17, 33, 41])
@pytest.mark.parametrize("alternate", [False, True])
def test_a_grid_self_match_fits_a_symmetry_and_is_confident(n, alternate):
    # With alternating diagonals every vertex is irregular and even shifts keep faces, so
    # HOPE's map can be several shifted patches; the finish keeps the patches that agree.
    v, f = flat_grid(n, alternate=alternate)
    res = hope_rs.match((v, f), (v, f))
    i, j = np.divmod(np.arange(n * n), n)
    m = n - 1
    pairs = [(i, j), (m - i, j), (i, m - j), (m - i, m - j)]
    if alternate:  # the diagonals alternate, so the grid has all 8 symmetries of the square
        pairs += [(j, i), (m - j, i), (j, m - i), (m - j, m - i)]
    fits = max((res.map == a * n + b).mean() for a, b in pairs)
    assert fits == 1.0
    assert res.confidence.mean() > 0.9 and not res.quality.likely_failed

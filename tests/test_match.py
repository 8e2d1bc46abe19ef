import copy
import pickle

import numpy as np
import pytest
from conftest import data_path
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from meshes import bumpy_sphere
from strategies import bumpy_surfaces, half_corrupted, isometric_copies

import hope_rs


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_exact_recovery_on_generated_isometric_copies(data):
    v, f = data.draw(bumpy_surfaces(600, 1000), label="surface")
    a = hope_rs.Mesh(v, f)
    b, truth = data.draw(isometric_copies(v, f), label="copy")
    res = hope_rs.match(a, b, init=data.draw(half_corrupted(truth), label="init"))
    assert np.mean(res.init_map == truth) < 0.6
    np.testing.assert_array_equal(res.map, truth)


# A relabelling of 6890 vertices is a large example by nature (two are drawn).
@pytest.mark.slow
@settings(
    max_examples=2,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.large_base_example],
)
@given(data=st.data())
def test_exact_recovery_on_a_relabelled_faust_shape(faust_pair, data):
    a = faust_pair[0]
    b, truth = data.draw(isometric_copies(a.vertices, a.faces), label="copy")
    res = hope_rs.match(a, b, init=data.draw(half_corrupted(truth), label="init"))
    assert np.mean(res.init_map == truth) < 0.6
    np.testing.assert_array_equal(res.map, truth)


def test_faust_pair_with_default_parameters(faust_pair):
    a, b = faust_pair
    res = hope_rs.match(a, b)
    init = hope_rs.score(hope_rs.geodesic_errors(b, res.init_map))
    final = hope_rs.score(hope_rs.geodesic_errors(b, res.map))
    assert final.exact >= 0.95, f"{final} (initial map: {init})"
    assert final.mean < init.mean
    # Each pass: one global repair (k = 0), then the k-hop steps.
    assert res.history[0].k == 0 and all(0 <= h.k <= 8 for h in res.history)
    assert sum(h.k == 0 for h in res.history) == sum(h.k == 8 for h in res.history)
    assert set(res.timings) >= {"descriptors", "init", "refine", "total"}


def test_every_step_reports_its_cost_and_assignment_seconds(faust_pair):
    a, b = faust_pair
    res = hope_rs.match(a, b, spectral=False)
    steps = [h for h in res.history if h.k > 0 and not h.polish]
    assert steps and all(h.cost_seconds > 0 and h.assign_seconds > 0 for h in steps)
    assert all(h.cost_seconds + h.assign_seconds <= h.seconds for h in steps)
    # The repair steps build no overlap cost.
    assert all(h.cost_seconds == h.assign_seconds == 0 for h in res.history if h.k == 0)
    t = res.timings
    assert t["refine.cost"] == pytest.approx(sum(h.cost_seconds for h in steps))
    assert t["refine.assign"] == pytest.approx(sum(h.assign_seconds for h in steps))
    assert t["refine.cost"] + t["refine.assign"] < t["refine"]


def test_a_right_map_whose_distances_a_pose_bends_is_kept():
    # FAUST 018 -> 019: the long-range check of the global repair flagged right vertices whose
    # geodesics the pose bends, and re-placed them a few edges off (85.1% exact); flagged
    # vertices now move only as far as a mirror image lies (anchors.FLAGGED_MIN_SHIFT).
    a, b = (hope_rs.load_mesh(data_path("faust_reg", f"tr_reg_0{i}.off")) for i in (18, 19))
    res = hope_rs.match(a, b)
    assert np.mean(res.map == np.arange(a.n_vertices)) == 1.0


def test_shapes_are_reusable_and_k_max_is_checked(faust_pair):
    a, b = faust_pair
    sa, sb = hope_rs.Shape(a), hope_rs.Shape(b, k_max=4)
    with pytest.raises(ValueError, match="k_max"):
        hope_rs.match(sa, sb)
    res = hope_rs.match(sa, hope_rs.Shape(b), init=np.arange(a.n_vertices), max_passes=1)
    assert res.map.shape == (a.n_vertices,)
    assert "shot" not in sa._descriptors  # an explicit init map needs no descriptors


def test_different_vertex_counts_every_vertex_gets_a_partner():
    v, f = bumpy_sphere(900, 1)
    vb, fb = bumpy_sphere(700, 2)
    for a, b in [
        (hope_rs.Mesh(v, f), hope_rs.Mesh(vb, fb)),
        (hope_rs.Mesh(vb, fb), hope_rs.Mesh(v, f)),
    ]:
        res = hope_rs.match(a, b, max_passes=1)
        assert res.map.shape == (a.n_vertices,)
        assert res.map.min() >= 0 and res.map.max() < b.n_vertices
        one_to_one = hope_rs.match(a, b, max_passes=1, polish_k=None, spectral=False).map
        assert np.unique(one_to_one).size == min(a.n_vertices, b.n_vertices)


def test_several_components_and_unreferenced_vertices():
    v, f = bumpy_sphere(500, 3)
    v2 = np.vstack([v, v + [5.0, 0, 0], [[9.0, 9.0, 9.0]]])
    f2 = np.vstack([f, f + v.shape[0]])
    mesh = hope_rs.Mesh(v2, f2)
    truth = np.arange(mesh.n_vertices)
    init = truth.copy()
    init[::7] = init[::7][::-1]
    res = hope_rs.match(mesh, mesh, init=init)
    assert np.mean(res.map == truth) > 0.95


@pytest.mark.parametrize(
    "init, err",
    [
        (np.arange(5), ValueError),
        (np.full(6890, 10**6), ValueError),
        (np.zeros(6890) + 0.5, TypeError),
    ],
)
def test_bad_init_map(faust_pair, init, err):
    with pytest.raises(err):
        hope_rs.match(*faust_pair, init=init)


def test_an_unsigned_init_out_of_range_is_reported_as_given(faust_pair):
    init = np.zeros(6890, dtype=np.uint64)
    init[5] = 2**64 - 1
    with pytest.raises(
        ValueError, match=r"init must hold values in \[0, 6890\), got \[0, 18446744073709551615\]"
    ):
        hope_rs.match(*faust_pair, init=init)


def test_bad_init_name(faust_pair):
    with pytest.raises(ValueError, match="unknown descriptor"):
        hope_rs.match(*faust_pair, init="sift")


def test_stay_keeps_witnesses_unless_the_overlap_clearly_gains():
    from hope_rs.pipeline.refine import assign_by_overlap

    # Two triangulations of one surface: no vertex bijection, so one-to-one steps trade
    # witnesses between near-equal overlaps; a large enough stay forbids every such trade.
    a = hope_rs.Shape(hope_rs.Mesh(*bumpy_sphere(800, 3)))
    b = hope_rs.Shape(hope_rs.Mesh(*bumpy_sphere(800, 4)))
    rng = np.random.default_rng(0)
    f = rng.permutation(b.n_vertices)[: a.n_vertices]
    w = rng.random(a.n_vertices) < 0.7
    free = assign_by_overlap(a, b, 2, f, w)
    assert np.any(free[w] != f[w]), "without stay some witnesses move"
    held = assign_by_overlap(a, b, 2, f, w, stay=1000)
    assert np.array_equal(held[w], f[w])
    assert np.any(held[~w] != f[~w]), "the others still move"
    assert np.unique(held).size == a.n_vertices
    with pytest.raises(ValueError, match="stay"):
        assign_by_overlap(a, b, 2, f, w, stay=-1)


def test_refine_reports_a_settled_map_only_when_nothing_moves():
    from hope_rs.pipeline.config import RefineConfig
    from hope_rs.pipeline.refine import refine

    s = hope_rs.Shape(hope_rs.Mesh(*bumpy_sphere(800, 3)))
    exact = np.arange(s.n_vertices)
    assert refine(s, s, exact).settled
    wrong = exact.copy()
    rng = np.random.default_rng(0)
    moved = rng.choice(s.n_vertices, s.n_vertices // 10, replace=False)
    wrong[moved] = rng.permutation(moved)
    once = refine(s, s, wrong, RefineConfig(max_passes=1))
    assert not once.settled  # its only pass moved vertices
    full = refine(s, s, wrong)
    np.testing.assert_array_equal(full.map, exact)
    assert full.settled


def test_a_shape_pickles_and_copies_with_its_computed_descriptors():
    a = hope_rs.Shape(hope_rs.Mesh(*bumpy_sphere(300, 1)), k_max=5)
    b = hope_rs.Mesh(*bumpy_sphere(300, 2))
    before = hope_rs.match(a, b, k_max=5, max_passes=1, spectral=False)
    for again in (pickle.loads(pickle.dumps(a)), copy.deepcopy(a)):
        assert again.k_max == 5 and np.array_equal(again.order, a.order)
        assert again._descriptors.keys() == a._descriptors.keys() != set()
        after = hope_rs.match(again, b, k_max=5, max_passes=1, spectral=False)
        np.testing.assert_array_equal(after.map, before.map)
    # A view at another scale shares the graph; pickled, it keeps its scale.
    view = a.at_scale(2 * a.scale)
    assert view.graph is a.graph
    assert pickle.loads(pickle.dumps(view)).scale == view.scale

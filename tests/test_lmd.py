import numpy as np
import pytest

from hope_rs.pipeline.lmd import LmdTracker, local_map_distortion, witnesses
from hope_rs.shape import Shape


@pytest.fixture(scope="module")
def shapes(faust_pair):
    return Shape(faust_pair[0]), Shape(faust_pair[1])


def test_identity_on_one_shape_is_consistent_everywhere(shapes):
    a, _ = shapes
    mean, consistent = local_map_distortion(a, a, np.arange(a.n_vertices))
    assert np.all(mean == 0) and np.all(consistent == 1)
    # A random map keeps almost no 2-ring's distances.
    scrambled = np.random.default_rng(0).permutation(a.n_vertices)
    assert witnesses(a, a, scrambled).mean() < 0.01


def test_tracker_matches_the_full_computation_over_a_sequence_of_maps(shapes):
    a, b = shapes
    rng = np.random.default_rng(3)
    tracker = LmdTracker(a, b)
    f = np.arange(a.n_vertices)  # FAUST registrations: the identity is the true map
    f[rng.choice(a.n_vertices, 2000, replace=False)] = rng.integers(0, b.n_vertices, 2000)
    # Small and large changes, a repeat of the same map and a return to an earlier one.
    for moved in [0, 5, 300, 4000, 0, 50]:
        g = f.copy()
        idx = rng.choice(a.n_vertices, moved, replace=False)
        g[idx] = rng.integers(0, b.n_vertices, moved)
        want = local_map_distortion(a, b, g)
        got = tracker.local_map_distortion(g)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
        assert np.array_equal(tracker.witnesses(g), want[1] >= 0.5)
        f = g if moved != 50 else f

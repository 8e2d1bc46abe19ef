"""Normal roughness: zero on a plane, scale-free, larger with vertex noise; a coarse copy
moved to its owners' means loses most of that noise."""

import numpy as np
from meshes import bumpy_sphere, flat_grid

import hope_rs
from hope_rs.geometry.collapse import collapse_to_count
from hope_rs.geometry.roughness import (
    _ring_sums,
    at_owner_means,
    normal_roughness,
    umbrella_smoothed,
)
from hope_rs.geometry.subdivide import subdivide


def test_a_plane_is_not_rough_and_the_measure_is_scale_free():
    v, f = flat_grid(9)
    assert normal_roughness(hope_rs.Mesh(v, f)) == 0.0
    m = hope_rs.Mesh(*bumpy_sphere(400, 0))
    big = hope_rs.Mesh(m.vertices * 1000.0, m.faces)
    assert np.isclose(normal_roughness(m), normal_roughness(big))


def test_noise_is_rough_and_owner_means_take_it_out():
    dense = subdivide(hope_rs.Mesh(*bumpy_sphere(400, 0)), 2)
    rng = np.random.default_rng(1)
    noise = rng.normal(0.0, 0.005 * dense.scale, dense.vertices.shape)
    noisy = hope_rs.Mesh(dense.vertices + noise, dense.faces)
    assert normal_roughness(noisy) > 3 * normal_roughness(dense)
    c = collapse_to_count(noisy, noisy.n_vertices // 16)
    means = at_owner_means(c.mesh, noisy.vertices, c.owner)
    expect = np.stack([noisy.vertices[c.owner == j].mean(axis=0) for j in range(c.mesh.n_vertices)])
    np.testing.assert_allclose(means.vertices, expect)
    np.testing.assert_array_equal(means.faces, c.mesh.faces)
    assert normal_roughness(means) < normal_roughness(c.mesh)


def test_umbrella_smoothing_takes_noise_out_and_keeps_the_faces():
    dense = subdivide(hope_rs.Mesh(*bumpy_sphere(400, 0)), 1)
    rng = np.random.default_rng(2)
    noise = rng.normal(0.0, 0.005 * dense.scale, dense.vertices.shape)
    lone = np.array([[5.0, 5.0, 5.0]])  # a vertex in no face stays where it is
    noisy = hope_rs.Mesh(np.vstack([dense.vertices + noise, lone]), dense.faces)
    smooth = umbrella_smoothed(noisy, 5)
    np.testing.assert_array_equal(smooth.faces, noisy.faces)
    np.testing.assert_array_equal(smooth.vertices[-1], lone[0])
    assert normal_roughness(smooth) < 0.5 * normal_roughness(noisy)
    np.testing.assert_array_equal(umbrella_smoothed(noisy, 0).vertices, noisy.vertices)
    # One step moves a vertex halfway to its 1-ring's centroid.
    one = umbrella_smoothed(noisy, 1).vertices
    ring = [j for f in noisy.faces if 0 in f for j in f if j != 0]
    centroid = noisy.vertices[sorted(set(ring))].mean(axis=0)
    np.testing.assert_allclose(one[0], 0.5 * noisy.vertices[0] + 0.5 * centroid)


def test_ring_sums_add_in_np_add_at_order():
    """The bincount sums are np.add.at's over e[:, 0], then e[:, 1], bit for bit."""
    rng = np.random.default_rng(5)
    for dtype in (np.float64, np.float32):
        v = (rng.normal(size=(300, 3)) * 10.0 ** rng.integers(-8, 8, size=(300, 1))).astype(dtype)
        e = np.sort(rng.integers(0, 300, size=(2000, 2)), axis=1)
        want = np.zeros(v.shape, dtype=np.float64)
        np.add.at(want, e[:, 0], v[e[:, 1]])
        np.add.at(want, e[:, 1], v[e[:, 0]])
        got = _ring_sums(v, e)
        assert got.dtype == np.float64
        np.testing.assert_array_equal(got, want)

"""Normal roughness: zero on a plane, scale-free, larger with vertex noise; a coarse copy
moved to its owners' means loses most of that noise."""

import numpy as np
from meshes import bumpy_sphere, flat_grid

import hope_rs
from hope_rs.geometry.collapse import collapse_to_count
from hope_rs.geometry.roughness import at_owner_means, normal_roughness
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

"""Vertex clustering by manifold-keeping edge collapses (hope_rs.geometry.collapse)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import data_path
from hypothesis import given, settings
from hypothesis import strategies as st
from meshes import bumpy_sphere, euler_characteristic, mesh_defects, py_collapse_to_sites

import hope_rs
from hope_rs import _core
from hope_rs.geometry.coarsen import uniform_cells_for_count
from hope_rs.geometry.collapse import collapse_to_count, collapse_to_sites, shortest_path_tree
from hope_rs.geometry.sites import cell_sites
from hope_rs.pipeline.resolution import coarse_copy

VALID = {"degenerate": 0, "duplicate": 0, "non_manifold_edges": 0, "flipped_edges": 0}


def _check_coarse(mesh, c, *, boundary: int = 0) -> None:
    """``c`` is a valid coarse copy of ``mesh``: a manifold of the same topology and
    orientation, each vertex a vertex of ``mesh``, each vertex of ``mesh`` owned by one."""
    defects = mesh_defects(c.mesh.faces)
    assert {k: defects[k] for k in VALID} == VALID
    assert (defects["boundary"] == 0) == (boundary == 0)
    assert euler_characteristic(c.mesh.n_vertices, c.mesh.faces) == euler_characteristic(
        mesh.n_vertices, mesh.faces
    )
    np.testing.assert_array_equal(c.mesh.vertices, mesh.vertices[c.sites])
    np.testing.assert_array_equal(c.owner[c.sites], np.arange(c.sites.size))
    assert c.owner.min() >= 0 and c.owner.max() < c.sites.size
    # No vertex left without a face: every kept vertex is on the surface.
    assert np.unique(c.mesh.faces).size == c.mesh.n_vertices


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 1000), target=st.integers(40, 400))
def test_collapse_keeps_a_closed_manifold_near_the_count(seed, target):
    v, f = bumpy_sphere(900, seed)
    mesh = hope_rs.Mesh(v, f)
    c = collapse_to_count(mesh, target)
    _check_coarse(mesh, c)
    # The grid's sites plus the few vertices whose every collapse was refused.
    assert 0.8 * target <= c.mesh.n_vertices <= 1.25 * target
    # Orientation kept: the enclosed volume keeps its sign.
    assert np.sign(_volume(c.mesh)) == np.sign(_volume(mesh))


def _volume(m) -> float:
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    return float(np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum())


def test_an_open_surface_keeps_its_boundary():
    v, f = bumpy_sphere(900, 3)
    cap = (v[f][:, :, 2] > 0.5).any(axis=1)  # cut a cap off: a disc
    mesh = hope_rs.Mesh(v, f[~cap])
    used = np.unique(mesh.faces)
    mesh = hope_rs.Mesh(v[used], np.searchsorted(used, mesh.faces))
    c = collapse_to_count(mesh, 150)
    _check_coarse(mesh, c, boundary=1)

    # The boundary moves only along itself: each boundary vertex of the copy was one before.
    def boundary_vertices(faces):
        e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
        u, n = np.unique(e, axis=0, return_counts=True)
        return np.unique(u[n == 1])

    assert set(c.sites[boundary_vertices(c.mesh.faces)]) <= set(boundary_vertices(mesh.faces))


def test_two_close_sheets_are_not_glued():
    """Two nested spheres 2% apart, in one mesh: grid cells hold both sheets, yet each vertex
    is merged only along its own surface, so the copy has two pieces as the input."""
    v, f = bumpy_sphere(600, 4)
    mesh = hope_rs.Mesh(np.vstack([v, 0.98 * v]), np.vstack([f, f[:, ::-1] + len(v)]))
    c = collapse_to_count(mesh, 200)
    _check_coarse(mesh, c)
    inner = c.sites >= len(v)
    assert 0 < inner.sum() < c.sites.size
    # No face joins the sheets.
    assert (inner[c.mesh.faces].all(axis=1) | (~inner[c.mesh.faces]).all(axis=1)).all()


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 1000), target=st.integers(40, 300), open_cut=st.booleans())
def test_the_core_makes_the_collapses_of_the_python_reference(seed, target, open_cut):
    """The Rust collapses (src/collapse.rs) and the Python reference (tests/meshes.py) keep
    the same vertices and faces and merge each vertex into the same one."""
    v, f = bumpy_sphere(700, seed)
    if open_cut:  # a disc: the boundary rules too
        f = f[~(v[f][:, :, 2] > 0.5).any(axis=1)]
        used = np.unique(f)
        v, f = v[used], np.searchsorted(used, f)
    mesh = hope_rs.Mesh(v, f)
    sites, _ = cell_sites(mesh.vertices, uniform_cells_for_count(mesh, target))
    got, want = collapse_to_sites(mesh, sites), py_collapse_to_sites(mesh, sites)
    np.testing.assert_array_equal(got.sites, want.sites)
    np.testing.assert_array_equal(got.owner, want.owner)
    np.testing.assert_array_equal(got.mesh.faces, want.mesh.faces)
    defects = mesh_defects(got.mesh.faces)
    assert {k: defects[k] for k in VALID} == VALID
    assert euler_characteristic(got.mesh.n_vertices, got.mesh.faces) == euler_characteristic(
        len(v), f
    )


def test_the_core_refuses_a_site_beyond_the_mesh():
    v, f = bumpy_sphere(100, 0)
    mesh = hope_rs.Mesh(v, f)
    dist, pred, source = shortest_path_tree(mesh, np.array([0]))
    with pytest.raises(ValueError, match="site 100 is beyond the 100 vertices"):
        _core.collapse_to_sites(
            v,
            f.astype(np.int64),
            np.array([100]),
            dist,
            pred.astype(np.int64),
            source.astype(np.int64),
        )


def test_every_vertex_a_site_changes_nothing():
    v, f = bumpy_sphere(200, 1)
    mesh = hope_rs.Mesh(v, f)
    c = collapse_to_sites(mesh, np.arange(200))
    np.testing.assert_array_equal(c.mesh.faces, mesh.faces)
    assert collapse_to_count(mesh, 200) is None


@pytest.mark.slow
def test_a_faust_body_at_1000_vertices_has_surface_geodesics():
    """The plain clustering of this body has non-manifold edges, on which potpourri3d's
    surface geodesics abort; the collapsed copy is a valid closed surface."""
    pp3d = pytest.importorskip("potpourri3d")
    mesh = hope_rs.load_mesh(data_path("faust_r", "tr_reg_002.off"))
    c = collapse_to_count(mesh, 1000)
    _check_coarse(mesh, c)
    pp3d.EdgeFlipGeodesicSolver(np.asarray(c.mesh.vertices), np.asarray(c.mesh.faces))


def test_the_resolution_stage_coarsens_a_dense_shape_to_a_manifold():
    v, f = bumpy_sphere(2000, 7)
    shape = hope_rs.Shape(hope_rs.Mesh(v, f))
    collapsed, cs = coarse_copy(shape, 400, 0.05)
    _check_coarse(shape.internal, collapsed)
    np.testing.assert_array_equal(
        collapsed.mesh.faces, collapse_to_count(shape.internal, 400).mesh.faces
    )
    assert cs.n_vertices == collapsed.mesh.n_vertices
    assert coarse_copy(shape, 2000, 0.05) is None


def test_a_copy_with_no_face_left_is_none():
    """Five separate spheres merged into 12 sites: no sphere keeps three, so no face is left,
    and the copy is None rather than a mesh that is not one."""
    ball = trimesh.creation.icosphere(1)
    v, f, n = ball.vertices, ball.faces, len(ball.vertices)
    mesh = hope_rs.Mesh(
        np.concatenate([v + [3.0 * i, 0, 0] for i in range(5)]),
        np.concatenate([f + n * i for i in range(5)]),
    )
    assert collapse_to_count(mesh, 12) is None
    assert collapse_to_sites(mesh, np.arange(5) * n) is None

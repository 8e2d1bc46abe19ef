"""What match and Shape take as a mesh (:func:`hope_rs.geometry.mesh.as_mesh`): a file's path,
trimesh and open3d objects, a one-mesh trimesh Scene, and polygons, fan-triangulated as the
file readers do; anything else is refused saying what to pass."""

import numpy as np
import pytest
from conftest import data_path
from meshes import bumpy_sphere

import hope_rs
from hope_rs.geometry.mesh import as_mesh

trimesh = pytest.importorskip("trimesh")


def same(m, v, f):
    np.testing.assert_array_equal(m.vertices, v)
    np.testing.assert_array_equal(m.faces, f)


def test_a_path_is_read_as_load_mesh_reads_it():
    path = data_path("faust_r", "tr_reg_000.off")
    want = hope_rs.load_mesh(path)
    for given in (path, str(path)):
        same(as_mesh(given), want.vertices, want.faces)
    with pytest.raises(FileNotFoundError, match="no such mesh file"):
        as_mesh(str(path) + ".missing")


def test_polygons_are_fan_triangulated_in_place():
    v = np.random.default_rng(0).random((9, 3))
    quads = np.array([[0, 1, 2, 3], [4, 5, 6, 7]])
    same(as_mesh((v, quads)), v, [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    mixed = [[0, 1, 2, 3, 4], [5, 6, 7], (8, 0, 1)]
    same(as_mesh((v, mixed)), v, [[0, 1, 2], [0, 2, 3], [0, 3, 4], [5, 6, 7], [8, 0, 1]])
    with pytest.raises(ValueError, match="a face has 2 corners"):
        as_mesh((v, [[0, 1], [2, 3, 4]]), "a")
    with pytest.raises(TypeError, match="integer vertex indices"):
        as_mesh((v, np.array([[0, 1, 2, 3.5]])))  # checked as any faces are


def test_trimesh_open3d_and_a_one_mesh_scene():
    v, f = bumpy_sphere(200, 0)
    tm = trimesh.Trimesh(v, f, process=False)
    same(as_mesh(tm), v, f)
    same(as_mesh(trimesh.Scene(tm)), v, f)  # a .glb of one mesh loads as a scene

    class TriangleMesh:  # open3d's: .vertices and .triangles, list-like vectors
        vertices = list(v)
        triangles = list(f)

    same(as_mesh(TriangleMesh()), v, f)
    two = trimesh.Scene([tm, trimesh.creation.box()])
    with pytest.raises(TypeError, match=r"a scene of 2 meshes.*force='mesh'"):
        as_mesh(two, "a")
    # One mesh placed at two nodes is two bodies, not the mesh.
    twice = trimesh.Scene(tm)
    shift = trimesh.transformations.translation_matrix([3.0, 0.0, 0.0])
    twice.graph.update(frame_to="again", geometry=next(iter(twice.geometry)), matrix=shift)
    with pytest.raises(TypeError, match=r"placing its one mesh at 2 nodes.*to_geometry"):
        as_mesh(twice, "a")
    with pytest.raises(TypeError, match="a mesh file's path"):
        hope_rs.match(3, tm)


def test_match_takes_paths():
    a = data_path("faust_r", "tr_reg_000.off")
    b = data_path("faust_r", "tr_reg_001.off")
    ma, mb = hope_rs.load_mesh(a), hope_rs.load_mesh(b)
    res = hope_rs.match(str(a), b, spectral=False)
    np.testing.assert_array_equal(res.map, hope_rs.match(ma, mb, spectral=False).map)
    assert res.map.shape == (ma.n_vertices,)


def test_a_glb_file_is_read_through_trimesh(tmp_path):
    a = hope_rs.load_mesh(data_path("faust_r", "tr_reg_000.off"))
    tm = trimesh.Trimesh(a.vertices, a.faces, process=False)
    tm.export(tmp_path / "a.glb")
    g = hope_rs.load_mesh(tmp_path / "a.glb")
    np.testing.assert_array_equal(g.faces, a.faces)
    np.testing.assert_allclose(g.vertices, a.vertices, atol=1e-6)  # glTF stores float32
    # Two meshes in the scene: one after the other, each placed as the scene places it.
    box = trimesh.creation.box()
    scene = trimesh.Scene()
    scene.add_geometry(tm, node_name="body")
    scene.add_geometry(
        box, node_name="box", transform=trimesh.transformations.translation_matrix([5, 0, 0])
    )
    scene.export(tmp_path / "two.glb")
    two = hope_rs.load_mesh(tmp_path / "two.glb")
    assert (two.n_vertices, two.n_faces) == (a.n_vertices + 8, a.n_faces + 12)
    assert two.vertices[:, 0].max() == pytest.approx(5.5)
    (tmp_path / "bad.glb").write_bytes(b"glTF" + bytes(40))
    with pytest.raises(ValueError, match=r"cannot read .*bad\.glb.*trimesh cannot read it"):
        hope_rs.load_mesh(tmp_path / "bad.glb")
    (tmp_path / "text.glb").write_text("OFF\n")
    with pytest.raises(ValueError, match="not a binary glTF file"):
        hope_rs.load_mesh(tmp_path / "text.glb")

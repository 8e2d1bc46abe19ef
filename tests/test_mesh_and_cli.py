import json

import numpy as np
import pytest
from conftest import data_path
from meshes import bumpy_sphere, write_off

import hope_rs
from hope_rs.cli import main


def test_off_keeps_vertex_order_and_other_formats_match(tmp_path):
    pytest.importorskip("trimesh")
    v, f = bumpy_sphere(300, 0)
    write_off(tmp_path / "m.off", v, f)
    m = hope_rs.load_mesh(tmp_path / "m.off")
    np.testing.assert_allclose(m.vertices, v)
    np.testing.assert_array_equal(m.faces, f)
    import trimesh

    # Duplicate a vertex: trimesh's default processing would merge it and renumber.
    v2 = np.vstack([v, v[:1]])
    f2 = f.copy()
    f2[0, 0] = len(v)
    for ext in ("obj", "ply", "stl"):
        trimesh.Trimesh(v2, f2, process=False).export(tmp_path / f"m.{ext}")
        m2 = hope_rs.load_mesh(tmp_path / f"m.{ext}")
        if ext != "stl":  # STL stores triangles only, so vertex identity is lost by the format
            np.testing.assert_allclose(m2.vertices, v2, atol=1e-6)
            np.testing.assert_array_equal(m2.faces, f2)
        assert m2.n_faces == len(f2)


def test_quads_are_triangulated(tmp_path):
    p = tmp_path / "q.off"
    p.write_text("OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")
    np.testing.assert_array_equal(hope_rs.load_mesh(p).faces, [[0, 1, 2], [0, 2, 3]])


@pytest.mark.parametrize(
    "content, match",
    [
        ("hello world", "not an OFF"),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n", "shorter"),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", "only 3 vertices"),
        ("OFF\n3 1 0\n0 0 nan\n1 0 0\n0 1 0\n3 0 1 2\n", "NaN"),
        ("OFF\n0 0 0\n", "no vertices"),
        ("OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", "no faces"),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 -1\n", "negative"),
    ],
)
def test_bad_off_files(tmp_path, content, match):
    p = tmp_path / "bad.off"
    p.write_text(content)
    with pytest.raises(ValueError, match=match):
        hope_rs.load_mesh(p)


def test_missing_and_garbage_files(tmp_path):
    with pytest.raises(FileNotFoundError):
        hope_rs.load_mesh(tmp_path / "nope.off")
    g = tmp_path / "garbage.ply"
    g.write_bytes(b"\x00\xff" * 100)
    with pytest.raises(ValueError, match="cannot read"):
        hope_rs.load_mesh(g)


@pytest.mark.parametrize(
    "v, f, err, match",
    [
        (np.zeros((3, 2)), [[0, 1, 2]], ValueError, r"\(N, 3\)"),
        (np.zeros((3, 3)), [[0, 1, 2, 0]], ValueError, r"\(M, 3\)"),
        (np.full((3, 3), np.nan), [[0, 1, 2]], ValueError, "NaN"),
        (np.zeros((3, 3)), [[0, 1, 3]], ValueError, "only 3 vertices"),
        (np.zeros((3, 3)), np.zeros((0, 3), int), ValueError, "no faces"),
    ],
)
def test_bad_arrays(v, f, err, match):
    with pytest.raises(err, match=match):
        hope_rs.Mesh(v, f)


def test_zero_area_mesh_is_rejected_by_match():
    m = hope_rs.Mesh(np.zeros((3, 3)), [[0, 1, 2]])
    with pytest.raises(ValueError, match="zero surface area"):
        hope_rs.match(m, m)


def test_cli_match_writes_the_map_atomically(tmp_path, capsys):
    a, b = data_path("faust_reg", "tr_reg_012.off"), data_path("faust_reg", "tr_reg_018.off")
    out = tmp_path / "map.txt"
    assert main(["match", str(a), str(b), "-o", str(out), "--json", "-q"]) == 0
    mapping = np.loadtxt(out, dtype=np.int64)
    assert mapping.shape == (6890,)
    assert np.mean(mapping == np.arange(6890)) > 0.95
    summary = json.loads(capsys.readouterr().out)
    assert summary["n_vertices"] == 6890 and "refine" in summary["timings"]
    assert "map" not in summary  # written to -o


def test_cli_errors_exit_2_and_write_nothing(tmp_path, capsys):
    good = data_path("faust_reg", "tr_reg_012.off")
    bad = tmp_path / "bad.off"
    bad.write_text("OFF\n3 1 0\n0 0 0\n")
    out = tmp_path / "map.txt"
    for args in (
        ["match", str(tmp_path / "missing.off"), str(good), "-o", str(out)],
        ["match", str(bad), str(good), "-o", str(out)],
        ["match", str(good), str(good), "-o", str(tmp_path)],
    ):
        assert main(args) == 2
        err = capsys.readouterr().err
        assert err.startswith("hope-rs: error:") and "Traceback" not in err
    assert list(tmp_path.iterdir()) == [bad]

"""Bad input fails early in one line; odd but valid input loads; extreme scales, array
ownership, face dtypes and other mesh types are handled (corpus in input_corpus.py)."""

import copy
import os
import pickle
import subprocess
import sys
import warnings

import numpy as np
import pytest
from conftest import data_path
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from input_corpus import (
    BAD,
    MATCH_ERRORS,
    ODD,
    TET_F,
    TET_V,
    obj_text,
    off_text,
    ply_ascii,
    ply_binary,
    stl_ascii,
    stl_binary,
)
from meshes import bumpy_sphere

import hope_rs
from hope_rs.cli import main
from hope_rs.geometry.mesh import as_mesh, scale_exponent

TET_MESH = hope_rs.Mesh(TET_V, TET_F)
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def write(tmp_path, name, ext, data):
    p = tmp_path / (f"{name}.{ext}" if ext else name)
    p.write_bytes(data)
    return p


@pytest.fixture
def good_off(tmp_path):
    p = tmp_path / "good.off"
    p.write_bytes(off_text(*bumpy_sphere(120, 2)))
    return p


# --- the corpus through load_mesh, match and the CLI ---------------------------------------------


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_files_are_refused_in_one_line(tmp_path, name):
    ext, data, fragment = BAD[name]
    p = write(tmp_path, name, ext, data)
    with pytest.raises(ValueError) as e:
        hope_rs.load_mesh(p)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"cannot read {str(p)!r}")
    assert fragment in msg, msg
    with pytest.raises(ValueError):
        hope_rs.match(hope_rs.load_mesh(p), TET_MESH)


@pytest.mark.parametrize("name", sorted(MATCH_ERRORS))
def test_files_that_load_but_cannot_be_matched(tmp_path, name):
    ext, data, fragment = MATCH_ERRORS[name]
    m = hope_rs.load_mesh(write(tmp_path, name, ext, data))
    with pytest.raises(ValueError, match=fragment) as e:
        hope_rs.match(m, TET_MESH)
    assert "\n" not in str(e.value) and str(e.value).startswith("a: ")
    with pytest.raises(ValueError, match=f"^b: .*{fragment}"):
        hope_rs.match(TET_MESH, m)


@pytest.mark.parametrize(
    "vertices, faces, err, fragment",
    [
        (np.where(np.arange(12).reshape(4, 3) == 5, np.nan, TET_V), TET_F, ValueError,
         r"vertices contain NaN or infinite coordinates \(first at row 1\)"),
        (TET_V, TET_F[:, :2], ValueError, r"faces must be an \(M, 3\) integer array"),
        (TET_V, np.zeros((0, 3), int), ValueError, "the mesh has no faces"),
        (TET_V, TET_F + 0.5, TypeError, "faces must hold integer vertex indices"),
        (TET_V, [[0, 1], [1, 2, 3]], ValueError, "a face has 2 corners"),
    ],
)  # fmt: skip
def test_bad_mesh_arrays_are_named_by_argument(vertices, faces, err, fragment):
    for which, args in (("a", ((vertices, faces), TET_MESH)), ("b", (TET_MESH, (vertices, faces)))):
        with pytest.raises(err, match=f"^{which}: {fragment}") as e:
            hope_rs.match(*args)
        assert not str(e.value).startswith(f"{which}: {which}: ") and "\n" not in str(e.value)


@pytest.mark.parametrize("name", sorted(ODD))
def test_odd_but_valid_files_load_and_match(tmp_path, name):
    ext, data, nv, nf = ODD[name]
    p = write(tmp_path, name, ext, data)
    m = hope_rs.load_mesh(p)
    assert (m.n_vertices, m.n_faces) == (nv, nf)
    assert np.all(np.isfinite(m.vertices)) and m.faces.min() >= 0 and m.faces.max() < nv
    r = hope_rs.match(m, m, max_passes=1)
    assert r.map.shape == (nv,) and r.map.min() >= 0 and r.map.max() < nv


def run_cli(args, cwd):
    env = dict(os.environ, PYTHONPATH=os.path.join(ROOT, "python"))
    return subprocess.run(
        [sys.executable, "-m", "hope_rs.cli", *args], check=False, capture_output=True,
        text=True, env=env, cwd=cwd, timeout=120,
    )  # fmt: skip


def check_cli_error(proc, out):
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("hope-rs: error:"), proc.stderr
    assert "Traceback" not in proc.stderr
    assert not out.exists()


CLI_SAMPLE = [
    "off_face_read_as_vertex",
    "obj_binary_junk",
    "ply_binary_huge_count",
    "stl_garbage_text",
]


@pytest.mark.parametrize(
    "name",
    [n if n in CLI_SAMPLE else pytest.param(n, marks=pytest.mark.slow) for n in sorted(BAD)]
    + list(MATCH_ERRORS),
)
def test_the_cli_refuses_bad_files_with_exit_2_and_one_line(tmp_path, good_off, name):
    ext, data, fragment = {**BAD, **MATCH_ERRORS}[name]
    bad = write(tmp_path, name, ext, data)
    out = tmp_path / "out.txt"
    for a, b in ((bad, good_off), (good_off, bad)):
        proc = run_cli(["match", str(a), str(b), "-o", str(out)], tmp_path)
        check_cli_error(proc, out)
        assert fragment in proc.stderr


@pytest.mark.parametrize("name", sorted({**BAD, **MATCH_ERRORS}))
def test_the_cli_in_process_exits_2_with_one_line(tmp_path, good_off, capsys, name):
    ext, data, fragment = {**BAD, **MATCH_ERRORS}[name]
    bad = write(tmp_path, name, ext, data)
    out = tmp_path / "out.txt"
    assert main(["match", str(bad), str(good_off), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("hope-rs: error:") and fragment in err
    assert str(bad) in err  # which file
    assert not out.exists()


def test_a_missing_file_and_a_folder(tmp_path, good_off, capsys):
    with pytest.raises(FileNotFoundError):
        hope_rs.load_mesh(tmp_path / "nope.off")
    with pytest.raises(ValueError, match="folder"):
        hope_rs.load_mesh(tmp_path)
    out = tmp_path / "out.txt"
    proc = run_cli(["match", str(tmp_path / "nope.off"), str(good_off), "-o", str(out)], tmp_path)
    check_cli_error(proc, out)


# --- formats -------------------------------------------------------------------------------------


def test_stl_corners_are_merged_in_first_appearance_order(tmp_path):
    v, f = bumpy_sphere(150, 5)
    v = v.astype(np.float32).astype(np.float64)  # STL stores float32
    p = write(tmp_path, "s", "stl", stl_binary(v, f))
    m = hope_rs.load_mesh(p)
    assert m.n_vertices == len(v) and m.n_faces == len(f)
    # First appearance: the merged vertices come in the order the triangles first use them.
    first_use = list(dict.fromkeys(f.reshape(-1).tolist()))
    np.testing.assert_array_equal(m.vertices, v[first_use])
    np.testing.assert_array_equal(m.vertices[m.faces], v[f])
    soup = hope_rs.load_mesh(p, merge_duplicates=False)
    assert soup.n_vertices == 3 * len(f)


def test_a_real_stl_export_matches_like_the_off_file(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    a = hope_rs.load_mesh(data_path("faust_reg", "tr_reg_012.off"))
    trimesh.Trimesh(a.vertices, a.faces, process=False).export(tmp_path / "a.stl")
    s = hope_rs.load_mesh(tmp_path / "a.stl")
    assert (s.n_vertices, s.n_faces) == (6890, 13776)


def test_split_seams_keep_the_file_order(tmp_path):
    # match welds the seams itself (tests/test_seams.py), so the file loads as it is.
    v = np.vstack([TET_V, TET_V[:1]])  # vertex 4 sits on vertex 0 (a seam)
    f = TET_F.copy()
    f[0, 0] = 4
    for ext, data in (("obj", obj_text(v, f)), ("ply", ply_ascii(v, f)), ("off", off_text(v, f))):
        p = write(tmp_path, "seam", ext, data)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            m = hope_rs.load_mesh(p)
        np.testing.assert_array_equal(m.faces, f)
        merged = hope_rs.load_mesh(p, merge_duplicates=True)
        assert merged.n_vertices == 4
    m = hope_rs.load_mesh(write(tmp_path, "copy", "off", off_text(v, TET_F)))
    assert m.n_vertices == 5


def test_binary_and_ascii_ply_agree_with_the_off_file(tmp_path):
    v, f = bumpy_sphere(100, 6)
    want = hope_rs.load_mesh(write(tmp_path, "m", "off", off_text(v, f)))
    for data in (ply_binary(v, f), ply_binary(v, f, endian=">")):
        m = hope_rs.load_mesh(write(tmp_path, "m", "ply", data))
        np.testing.assert_array_equal(m.vertices, v)
        np.testing.assert_array_equal(m.faces, want.faces)


# --- scale ---------------------------------------------------------------------------------------


def test_the_scale_exponent_brings_extreme_meshes_into_one_window():
    v = bumpy_sphere(50, 0)[0]
    assert 1 <= np.abs(v).max() < 4
    assert scale_exponent(v) == 0 and scale_exponent(v * 1e3) == 0
    for k in (-300, -133, -20, 25, 133, 300):
        s = np.ldexp(v, 2 * k)
        assert scale_exponent(s) == -k
        np.testing.assert_array_equal(np.ldexp(s, 2 * scale_exponent(s)), v)


@pytest.mark.parametrize("factor", [4.0**133, 4.0**-332, 1e80, 1e-200])
def test_extreme_scales_give_the_unit_scale_map(factor):
    a, b = hope_rs.Mesh(*bumpy_sphere(500, 3)), hope_rs.Mesh(*bumpy_sphere(400, 4))
    want = hope_rs.match(a, b, max_passes=2).map
    sa = hope_rs.Mesh(a.vertices * factor, a.faces)
    sb = hope_rs.Mesh(b.vertices * factor, b.faces)
    got = hope_rs.match(sa, sb, max_passes=2).map
    np.testing.assert_array_equal(got, want)


def test_geodesic_errors_are_in_the_meshes_units_at_any_scale():
    b = hope_rs.Mesh(*bumpy_sphere(300, 3))
    f = np.roll(np.arange(b.n_vertices), 1)
    want = hope_rs.geodesic_errors(hope_rs.Shape(b), f)
    big = hope_rs.Mesh(b.vertices * 4.0**100, b.faces)
    np.testing.assert_array_equal(hope_rs.geodesic_errors(hope_rs.Shape(big), f), want)


# --- arrays --------------------------------------------------------------------------------------


def test_a_mesh_copies_the_callers_arrays():
    v, f = TET_V.copy(), TET_F.copy()
    m = hope_rs.Mesh(v, f)
    assert v.flags.writeable and f.flags.writeable
    v[0] = 9.0
    f[0] = [1, 2, 3]
    np.testing.assert_array_equal(m.vertices, TET_V)
    np.testing.assert_array_equal(m.faces, TET_F)
    assert not m.vertices.flags.writeable and not m.faces.flags.writeable
    # So does an unpickled mesh, and a Shape's.
    for back in (pickle.loads(pickle.dumps(m)), pickle.loads(pickle.dumps(hope_rs.Shape(m))).mesh):
        np.testing.assert_array_equal(back.vertices, TET_V)
        assert not back.vertices.flags.writeable and not back.faces.flags.writeable


def test_match_results_compare_by_identity():
    res = hope_rs.match(TET_MESH, TET_MESH)
    other = copy.copy(res)
    assert res == res and res != other and res in [res] and other not in [res]


@pytest.mark.parametrize(
    "faces, err, fragment",
    [
        (np.array([[0, 1, 2**64 - 1]], dtype=np.uint64), ValueError, "vertex 18446744073709551615"),
        (np.array([[0, 1, 2**63 - 1]], dtype=np.int64), ValueError, "vertex 9223372036854775807"),
        (np.array([[0, 1, 1e30]]), ValueError, "vertex 1000000000000000019884624838656"),
        (np.array([[0, 1, 1.5]]), TypeError, "got 1.5"),
        (np.array([[0, 1, np.nan]]), TypeError, "got nan"),
        (np.array([[True, False, True]]), TypeError, "dtype bool"),
        (np.array([[0, 1, -2.0]]), ValueError, r"negative vertex index \(-2\)"),
        # Indices cast to int8 wrapped past 127: the cause is named.
        (
            np.array([[0, 1, 200]]).astype(np.int8),
            ValueError,
            "int8, which wraps indices above 127",
        ),
        ([[0, 1, 2], [0, 1]], ValueError, "different lengths"),
    ],
)
def test_face_arrays_are_checked_before_conversion(faces, err, fragment):
    with pytest.raises(err, match=fragment):
        hope_rs.Mesh(TET_V, faces)


def test_integral_float_and_unsigned_faces_are_accepted():
    for faces in (TET_F.astype(np.float32), TET_F.astype(np.uint16)):
        np.testing.assert_array_equal(hope_rs.Mesh(TET_V, faces).faces, TET_F)
    with pytest.raises(TypeError, match="dtype bool"):
        hope_rs.Mesh(TET_V.astype(bool), TET_F)


# --- other mesh types ----------------------------------------------------------------------------


def test_trimesh_and_duck_typed_meshes_are_accepted_everywhere():
    trimesh = pytest.importorskip("trimesh")
    v, f = bumpy_sphere(300, 3)
    tm = trimesh.Trimesh(v, f, process=False)
    m = as_mesh(tm)
    np.testing.assert_array_equal(m.vertices, v)
    np.testing.assert_array_equal(m.faces, f)

    class Duck:
        vertices, faces = v, f

    want = hope_rs.match(hope_rs.Mesh(v, f), (v, f), max_passes=1).map
    np.testing.assert_array_equal(hope_rs.match(tm, Duck(), max_passes=1).map, want)
    assert hope_rs.Shape(tm).n_vertices == len(v)
    err = hope_rs.geodesic_errors(tm, want)
    assert err.shape == (len(v),)
    from hope_rs.batch.driver import _spec

    assert _spec(tm, hope_rs.shape.ShapeConfig())["kind"] == "mesh"


@pytest.mark.parametrize("x", [42, b"not a mesh", (TET_V,), object()])
def test_other_objects_get_a_one_line_type_error(x):
    # (A str is a mesh file's path: tests/test_input_forms.py.)
    with pytest.raises(TypeError, match="must be a hope_rs.Mesh") as e:
        as_mesh(x, "a")
    assert "\n" not in str(e.value)
    with pytest.raises(TypeError):
        hope_rs.match(x, TET_MESH)


# --- fuzzing the readers -------------------------------------------------------------------------


SEEDS = {
    "off": off_text(TET_V, TET_F),
    "obj": obj_text(TET_V, TET_F),
    "ply_ascii": ply_ascii(TET_V, TET_F),
    "ply_binary": ply_binary(TET_V, TET_F),
    "stl_ascii": stl_ascii(TET_V, TET_F),
    "stl_binary": stl_binary(TET_V, TET_F),
}


@st.composite
def mutated(draw, seed: bytes):
    data = bytearray(seed)
    for _ in range(draw(st.integers(1, 6))):
        op = draw(st.sampled_from(["replace", "insert", "delete"]))
        if not data:
            op = "insert"
        i = draw(st.integers(0, max(len(data) - 1, 0)))
        if op == "replace":
            data[i] = draw(st.integers(0, 255))
        elif op == "insert":
            data[i:i] = draw(st.binary(min_size=1, max_size=4))
        else:
            del data[i : i + draw(st.integers(1, 4))]
    return bytes(data)


def off_header_counts(data: bytes):
    text = data.decode("utf-8-sig", errors="replace")
    lines = [ln.split("#", 1)[0].split() for ln in text.split("\n")]
    lines = [t for t in lines if t]
    head = lines[0][1:] if len(lines[0]) > 1 else lines[1]
    return int(head[0]), int(head[1]), len(lines) - (1 if len(lines[0]) > 1 else 2)


@pytest.mark.parametrize("kind", sorted(SEEDS))
@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data())
def test_mutated_files_load_or_fail_in_one_line(tmp_path, kind, data):
    blob = data.draw(mutated(SEEDS[kind]), label="file")
    ext = kind.split("_")[0]
    p = tmp_path / f"m.{ext}"
    p.write_bytes(blob)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        try:
            m = hope_rs.load_mesh(p)
        except ValueError as e:
            assert "\n" not in str(e) and str(e).startswith("cannot read"), str(e)
            return
    assert m.vertices.dtype == np.float64 and np.all(np.isfinite(m.vertices))
    assert m.faces.shape[1] == 3 and m.faces.min() >= 0 and m.faces.max() < m.n_vertices
    if ext == "off":
        nv, nf, body = off_header_counts(blob)
        assert m.n_vertices == nv and body == nv + nf


@pytest.mark.parametrize("init", ["shot", "wks", "hks"])
def test_meshes_too_small_for_a_spectrum_match_without_warnings(init):
    # A lone triangle has no non-constant eigenfunction; a regular tetrahedron one distinct
    # eigenvalue: WKS and HKS describe every vertex alike there instead of failing.
    tri = hope_rs.Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]), np.array([[0, 1, 2]]))
    reg_v = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1.0]])
    reg = hope_rs.Mesh(reg_v, np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for a, b in ((tri, TET_MESH), (reg, reg), (reg, TET_MESH)):
            res = hope_rs.match(a, b, init=init)
            assert res.map.shape == (a.n_vertices,)
            assert ((res.map >= 0) & (res.map < b.n_vertices)).all()


def test_a_scale_far_from_the_shapes_own_and_maps_out_of_range_are_refused():
    s = hope_rs.Shape(bumpy_sphere(200, 1))
    own = s.scale
    for scale in (own * 1e-300, own * 1e9, 1e-300):
        with pytest.raises(ValueError, match="is not within a factor"):
            s.at_scale(scale)
    assert s.at_scale(own * 1e3).scale == own * 1e3
    identity = np.arange(s.n_vertices)
    np.testing.assert_array_equal(s.map_out(s, s.map_in(s, identity)), identity)
    for bad, what in [
        (np.r_[-1, identity[1:]], r"must lie in \[0, 200\), got -1"),
        (np.r_[identity[:-1], 200], r"must lie in \[0, 200\), got 0 to 200"),
        (identity[:-1], "needs 200 integer indices"),
        (identity.astype(float), "needs 200 integer indices"),
    ]:
        for method in (s.map_in, s.map_out):
            with pytest.raises(ValueError, match=what):
                method(s, bad)

"""``hope-rs show``: PNG renders of the requested size, error and confidence panels, PLY
colour-transfer exports."""

import numpy as np
import pytest
from meshes import bumpy_sphere, write_off

import hope_rs
from hope_rs.cli import main
from hope_rs.evaluation.show import (
    detect_up,
    ply_pair_paths,
    position_colours,
    view_frame,
    write_ply_pair,
)

pytest.importorskip("matplotlib")


@pytest.fixture
def pair(tmp_path):
    """A sphere-like A, B its copy with vertices renumbered, and a map with 20 wrong entries."""
    v, f = bumpy_sphere(300, 0)
    perm = np.random.default_rng(1).permutation(300)  # B's vertex j is A's vertex perm[j]
    inv = np.argsort(perm)
    write_off(tmp_path / "a.off", v, f)
    write_off(tmp_path / "b.off", v[perm] * 1.1, inv[f])
    truth = inv.copy()
    mapping = truth.copy()
    mapping[:20] = truth[100:120]
    (tmp_path / "map.txt").write_text("\n".join(map(str, mapping)))
    np.save(tmp_path / "perm.npy", perm)
    return tmp_path, mapping, truth


def png_size(path) -> tuple[int, int]:
    from PIL import Image

    with Image.open(path) as im:
        return im.size


def argv(d):
    return ["show", str(d / "a.off"), str(d / "b.off"), str(d / "map.txt")]


def test_png_has_the_requested_size(pair):
    d, _, _ = pair
    assert main([*argv(d), "--png", str(d / "big.png")]) == 0
    assert png_size(d / "big.png") == (1600, 900)
    assert main([*argv(d), "--png", str(d / "small.png"), "--size", "640x400"]) == 0
    assert png_size(d / "small.png") == (640, 400)
    assert not [p for p in d.iterdir() if p.name.startswith(".hope-rs-")]  # no leftovers
    assert (d / "big.png").stat().st_mode & 0o044 == (d / "a.off").stat().st_mode & 0o044


@pytest.mark.parametrize(
    "extra, message",
    [
        ([], "give --png FILE and/or --ply FILE"),
        (["--png", "x.png", "--size", "big"], "--size must be WIDTHxHEIGHT"),
        (["--png", "x.png", "--size", "50x50"], "between 100x100"),
        (["--png", "x.png", "--color-by", "error"], "--color-by error needs --truth"),
        (["--png", "x.png", "--color-by", "confidence"], "needs --confidence FILE.npy"),
        (["--png", "x.png", "--truth", "a.vts"], "'identity' or two .vts files"),
        (["--png", "x.jpg"], "must end in .png"),
        (["--ply", "x.ply", "--truth", "a", "b", "c"], "--truth colour the --png picture only"),
        (["--ply", "x.ply", "--confidence", "c.npy"], "--confidence colour the --png picture"),
        (
            ["--png", "x.png", "--truth", "identity", "--color-by", "position"],
            "--truth is read only with --color-by error, not position",
        ),
        (
            ["--png", "x.png", "--confidence", "c.npy", "--truth", "identity"],
            "--confidence is read only with --color-by confidence, not error",
        ),
    ],
)
def test_bad_options_fail_in_one_line(pair, capsys, extra, message):
    d, _, _ = pair
    assert main([*argv(d), *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith("hope-rs: error:") and message in err and err.count("\n") == 1
    assert not (d / "x.png").exists()


def test_error_and_confidence_panels(pair):
    d, _, truth = pair
    # Landmark files for the true correspondence: line i of each, 1-based.
    np.savetxt(d / "a.vts", np.arange(300) + 1, fmt="%d")
    np.savetxt(d / "b.vts", truth + 1, fmt="%d")
    out = d / "err.png"
    assert main([*argv(d), "--png", str(out), "--truth", str(d / "a.vts"), str(d / "b.vts")]) == 0
    assert png_size(out) == (1600, 900)
    np.save(d / "conf.npy", np.linspace(0, 1, 300))
    out2 = d / "conf.npy.png"
    cmd = [*argv(d), "--png", str(out2), "--color-by", "confidence", "--confidence"]
    assert main([*cmd, str(d / "conf.npy")]) == 0
    assert png_size(out2) == (1600, 900)
    np.save(d / "short.npy", np.zeros(10))
    assert main([*cmd, str(d / "short.npy")]) == 2


@pytest.mark.parametrize(
    "values, message",
    [
        (np.full(300, np.nan), "must hold numbers in [0, 1]"),
        (np.full(300, 5.0), "must hold numbers in [0, 1]"),
        (np.full(300, 1j), "must hold numbers in [0, 1]"),
        (None, "is not a NumPy .npy array"),
    ],
)
def test_a_confidence_file_that_is_not_a_confidence_fails_in_one_line(
    pair, capsys, values, message
):
    d, _, _ = pair
    path = d / "bad.npy"
    if values is None:
        path.write_text("0.5\n" * 300)
    else:
        np.save(path, values)
    out = d / "bad.png"
    cmd = [*argv(d), "--png", str(out), "--color-by", "confidence", "--confidence", str(path)]
    assert main(cmd) == 2
    err = capsys.readouterr().err
    assert err.startswith("hope-rs: error:") and message in err and err.count("\n") == 1
    assert not out.exists()


@pytest.mark.parametrize(
    "content, message",
    [("", "a.vts' has no vertex indices"), ("1\n2\nx\n", "a.vts:3: cannot read 'x'")],
)
def test_a_bad_truth_file_is_an_input_error(pair, capsys, content, message):
    d, _, _ = pair
    (d / "a.vts").write_text(content)
    out = d / "err.png"
    assert main([*argv(d), "--png", str(out), "--truth", str(d / "a.vts"), str(d / "a.vts")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("hope-rs: error:") and message in err and err.count("\n") == 1
    assert not out.exists()


def test_vertex_errors_are_zero_exactly_where_the_map_is_right(pair):
    from hope_rs.evaluation.show import vertex_errors

    d, mapping, truth = pair
    a, b = hope_rs.load_mesh(d / "a.off"), hope_rs.load_mesh(d / "b.off")
    e = vertex_errors(a, b, mapping, np.arange(300), truth)
    assert np.array_equal(e > 0, mapping != truth)
    # Landmarks on some vertices only: the others take their nearest landmark's error.
    e2 = vertex_errors(a, b, mapping, np.arange(0, 300, 2), truth[::2])
    assert e2.shape == (300,) and (e2 >= 0).all()
    np.testing.assert_array_equal(e2[::2], e[::2])


def test_ply_pair_reads_back_with_colours_through_the_map(pair):
    trimesh = pytest.importorskip("trimesh")
    d, mapping, _ = pair
    assert main([*argv(d), "--ply", str(d / "out.ply")]) == 0
    ta = trimesh.load(d / "out_A.ply", process=False)
    tb = trimesh.load(d / "out_B.ply", process=False)
    a, b = hope_rs.load_mesh(d / "a.off"), hope_rs.load_mesh(d / "b.off")
    np.testing.assert_allclose(ta.vertices, a.vertices, rtol=1e-6)
    np.testing.assert_array_equal(tb.faces, b.faces)
    ca = ta.visual.vertex_colors[:, :3].astype(float)
    cb = tb.visual.vertex_colors[:, :3].astype(float)
    assert len(np.unique(ca, axis=0)) > 100  # a smooth colouring, not one flat colour
    # Every vertex of B the map hits has the mean colour of the A vertices mapped onto it.
    for j in np.unique(mapping):
        want = ca[mapping == j].mean(axis=0)
        np.testing.assert_allclose(cb[j], want, atol=1.01)
    # Vertices nothing maps to copy their nearest hit vertex.
    miss = np.setdiff1d(np.arange(300), mapping)
    assert miss.size == 20
    hit = np.unique(mapping)
    for j in miss:
        nearest = hit[np.argmin(np.linalg.norm(b.vertices[hit] - b.vertices[j], axis=1))]
        np.testing.assert_array_equal(cb[j], cb[nearest])
    # Either output may be named with or without the extension.
    assert write_ply_pair(a, b, mapping, d / "again") == (
        str(d / "again_A.ply"),
        str(d / "again_B.ply"),
    )


def test_ply_pair_names_follow_the_help(capsys):
    assert ply_pair_paths("out.PLY") == ply_pair_paths("out") == ("out_A.ply", "out_B.ply")
    assert ply_pair_paths("out.txt") == ("out.txt_A.ply", "out.txt_B.ply")
    with pytest.raises(SystemExit):
        main(["show", "--help"])
    assert "out.txt writes out.txt_A.ply" in " ".join(capsys.readouterr().out.split())


def test_up_axis_and_view_frame():
    v, f = bumpy_sphere(200, 3)
    tall = hope_rs.Mesh(v * np.array([0.5, 3.0, 0.3]), f)  # standing along +y, thin along z
    assert detect_up(tall) == (1, 1)
    frame = view_frame(tall)
    np.testing.assert_array_equal(frame[:, 0], [0, 1, 0])  # screen up = +y
    np.testing.assert_array_equal(np.abs(frame[:, 2]), [0, 0, 1])  # looking along z
    np.testing.assert_allclose(frame.T @ frame, np.eye(3))
    # (right, up, towards the viewer) is right-handed: the render is not mirrored.
    assert np.linalg.det(frame[:, [1, 0, 2]]) > 0
    np.testing.assert_array_equal(view_frame(tall, "z")[:, 0], [0, 0, 1])
    with pytest.raises(ValueError, match="up must be"):
        view_frame(tall, "w")
    c = position_colours(tall)
    assert c.shape == (200, 3) and c.min() >= 0 and c.max() <= 1
    # Vivid: most colours well away from grey.
    assert np.median(c.max(axis=1) - c.min(axis=1)) > 0.4


def test_scan_debris_neither_frames_the_view_nor_spans_the_colours():
    """Loose pieces a match leaves out (MatchConfig.min_piece) are drawn, but the view is
    framed and the colours spread on the body alone."""
    from hope_rs.evaluation.show import _half_size

    v, f = bumpy_sphere(300, 0)
    v = v * [1.0, 2.0, 0.5]  # up +y, seen along z
    tri = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]])
    debris = [tri + [40.0, 0.0, 30.0], tri + [0.0, -50.0, 0.0]]
    w = np.vstack([v, *debris])
    g = np.vstack([f, [[300, 301, 302], [303, 304, 305]]])
    body, scan = hope_rs.Mesh(v, f), hope_rs.Mesh(w, g)
    frame = view_frame(body)
    np.testing.assert_array_equal(view_frame(scan), frame)
    np.testing.assert_allclose(_half_size([scan], frame), _half_size([body], frame))
    np.testing.assert_allclose(position_colours(scan)[:300], position_colours(body))

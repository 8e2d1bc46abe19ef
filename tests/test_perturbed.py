"""``hope-rs perturb-set``: noisy and welded targets with their ground truth carried over."""

from pathlib import Path

import numpy as np
import pytest
from meshes import bumpy_sphere, write_off
from scipy.sparse.csgraph import dijkstra

import hope_rs
from hope_rs.cli import main
from hope_rs.evaluation import derived_sets
from hope_rs.evaluation.datasets import pairs_of
from hope_rs.evaluation.partial import edge_graph
from hope_rs.evaluation.perturbed import (
    WELD_SPACE,
    WELD_SURFACE,
    add_noise,
    clean_errors,
    read_clean,
    shortcut_errors,
    weld_shortcuts,
    write_perturbed_sets,
)


def bent_tube() -> hope_rs.Mesh:
    """A thin ellipsoid bent almost into a ring: its two tips nearly touch in space and lie
    far apart along the surface."""
    v, f = bumpy_sphere(1500, 0)
    x, y, z = v[:, 0] * 5.0, v[:, 1] * 0.3, v[:, 2] * 0.3
    r = 10.0 / (1.95 * np.pi)
    t = x / r
    return hope_rs.Mesh(np.column_stack([(r + y) * np.cos(t), (r + y) * np.sin(t), z]), f)


def test_welds_follow_the_rule_and_scoring_reads_the_clean_mesh():
    mesh = bent_tube()
    w = weld_shortcuts(mesh)
    assert 1 <= len(w.welds) <= 10
    s = mesh.scale
    g = dijkstra(edge_graph(mesh), indices=w.welds[:, 0])
    for row, (i, j) in enumerate(w.welds):
        assert np.linalg.norm(mesh.vertices[i] - mesh.vertices[j]) < WELD_SPACE * s
        assert g[row, j] > WELD_SURFACE * s
    assert w.mesh.n_vertices == mesh.n_vertices - len(w.welds)
    np.testing.assert_array_equal(w.inverse[w.welds[:, 1]], w.inverse[w.welds[:, 0]])
    np.testing.assert_array_equal(w.origin[w.inverse[w.origin]], w.origin)
    # The map through the welds is right everywhere, the second vertex of a weld included.
    truth = np.arange(mesh.n_vertices)
    e = clean_errors(mesh, w.inverse, w.origin, w.welds, truth, truth, method="graph")
    assert np.all(e == 0)
    wrong = np.roll(w.inverse, 7)
    assert clean_errors(mesh, wrong, w.origin, w.welds, truth, truth, method="graph").mean() > 0
    # A true match on a weld's second vertex, as a welded ground truth reads it (the weld's
    # first), counts as either: a neighbour of the second vertex is one edge off, not the
    # surface distance between the two.
    i, j = w.welds[0]
    faces = mesh.faces[(mesh.faces == j).any(axis=1)]
    k = int(next(x for x in faces.ravel() if x != j and x not in w.welds))
    near = w.inverse.copy()
    near[j] = w.inverse[k]
    read = w.origin[w.inverse[truth]]
    assert read[j] == i
    got = clean_errors(mesh, near, w.origin, w.welds, truth, read, method="graph")
    edge = np.linalg.norm(mesh.vertices[j] - mesh.vertices[k]) / s
    assert got[j] == pytest.approx(edge, rel=1e-6) and got[j] < WELD_SURFACE


def test_noise_is_seeded_and_scaled():
    mesh = hope_rs.Mesh(*bumpy_sphere(800, 1))
    a, b = add_noise(mesh, 0.005, 3), add_noise(mesh, 0.005, 3)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    d = a.vertices - mesh.vertices
    assert d.std() == pytest.approx(0.005 * mesh.scale, rel=0.1)
    np.testing.assert_array_equal(a.faces, mesh.faces)


def test_perturbed_sets_carry_the_ground_truth(tmp_path):
    src = tmp_path / "src" / "tubes"
    (src / "corres").mkdir(parents=True)
    mesh = bent_tube()
    for name in ("s", "t"):
        write_off(src / f"{name}.off", mesh.vertices, mesh.faces)
        (src / "corres" / f"{name}.vts").write_text(
            "".join(f"{i + 1}\n" for i in range(0, mesh.n_vertices, 3))
        )
    (src / "pairs.txt").write_text("s t\n")
    out = write_perturbed_sets(
        src, tmp_path / "out", conditions=["noise02", "noise05", "shortcuts"]
    )
    assert sorted(d.name for d in out) == ["tubes_noise02", "tubes_noise05", "tubes_shortcuts"]
    for d in out:
        (pair,) = pairs_of(d)
        a, b = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
        ai, bi = pair.ground_truth(a.n_vertices, b.n_vertices)
        clean = read_clean(d, pair.b.stem)
        if d.name.endswith("shortcuts"):
            cb, origin, welds = clean
            assert b.n_vertices == mesh.n_vertices - len(welds) and len(welds) >= 1
            # The identity of the clean shapes, read on the welded B, scores 0 on the clean B.
            m = np.full(a.n_vertices, -1)
            m[ai] = bi
            m[m < 0] = 0
            e = clean_errors(cb, m, origin, welds, ai, origin[bi], method="graph")
            assert np.all(e == 0)
            # What hope-rs bench scores a welded B with: the same, from the set's files.
            e = shortcut_errors(d, pair.b.stem, m, ai, bi, method="graph")
            assert e is not None and np.all(e == 0)
            off = shortcut_errors(d, pair.b.stem, np.roll(m, 5), ai, bi, method="graph")
            assert off is not None and off.mean() > 0
        else:
            assert clean is None and b.n_vertices == mesh.n_vertices
            assert shortcut_errors(d, pair.b.stem, np.arange(a.n_vertices), ai, bi) is None
            np.testing.assert_array_equal(ai, bi)
    # A shape with no shortcut (a convex sphere) leaves no shortcut set.
    sphere = tmp_path / "src2" / "spheres"
    (sphere / "corres").mkdir(parents=True)
    v, f = bumpy_sphere(600, 2)
    for name in ("s", "t"):
        write_off(sphere / f"{name}.off", v, f)
        (sphere / "corres" / f"{name}.vts").write_text("1\n2\n")
    (sphere / "pairs.txt").write_text("s t\n")
    assert write_perturbed_sets(sphere, tmp_path / "out2", conditions=["shortcuts"]) == []
    assert not (tmp_path / "out2" / "spheres_shortcuts").exists()


def test_perturb_set_cli(tmp_path, capsys):
    assert main(["perturb-set", str(tmp_path / "bad"), "--from", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err
    assert "is not a folder" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "bad").exists()
    with pytest.raises(ValueError, match="unknown perturbation"):
        write_perturbed_sets(tmp_path, tmp_path / "out", conditions=["blur"])


def test_a_reversed_set_swaps_the_shapes_and_their_ground_truth(tmp_path, capsys):
    src = tmp_path / "src" / "pair"
    (src / "corres").mkdir(parents=True)
    s, t = hope_rs.Mesh(*bumpy_sphere(300, 1)), hope_rs.Mesh(*bumpy_sphere(400, 2))
    write_off(src / "s.off", s.vertices, s.faces)
    write_off(src / "t.off", t.vertices, t.faces)
    (src / "corres" / "s.vts").write_text("1\n2\n3\n")
    (src / "corres" / "t.vts").write_text("7\n8\n9\n")
    (src / "pairs.txt").write_text("s t\n")
    (d,) = write_perturbed_sets(src, tmp_path / "out", conditions=["reversed"])
    assert d.name == "pair_reversed"
    # The command says how many pairs each set holds (a condition may leave some out).
    out = tmp_path / "cli"
    assert main(["perturb-set", str(out), "--from", str(src), "--conditions", "reversed"]) == 0
    said = capsys.readouterr().out
    assert f"1 data sets written to {out} (pair_reversed: 1 pair)" in said
    (pair,) = pairs_of(d)
    a, b = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
    assert (a.n_vertices, b.n_vertices) == (400, 300)
    np.testing.assert_allclose(a.vertices, t.vertices, atol=1e-5)
    ai, bi = pair.ground_truth(a.n_vertices, b.n_vertices)
    np.testing.assert_array_equal(ai, [6, 7, 8])
    np.testing.assert_array_equal(bi, [0, 1, 2])


def test_the_set_writers_name_the_file_they_cannot_write(tmp_path):
    # A full disk or a file-size limit raises an OSError without a file name ("File too
    # large"); the derived-set commands print it as their one-line error.
    mesh = hope_rs.Mesh(*bumpy_sphere(2000, 0))
    for write in (lambda p: derived_sets.write_off(p, mesh),
                  lambda p: derived_sets.write_vts(p, np.arange(5000))):  # fmt: skip
        with pytest.raises(OSError, match="No space left on device: '/dev/full'"):
            write(Path("/dev/full"))
        write(tmp_path / "ok")  # a writable file is written
        assert (tmp_path / "ok").stat().st_size > 0

"""Data-set adapters, named methods, the bench runner and the colour-transfer renderer."""

import csv
import importlib.util

import numpy as np
import pytest
from conftest import data_path
from meshes import bumpy_sphere, relabel, write_off

import hope_rs
from hope_rs.cli import main
from hope_rs.evaluation import bench
from hope_rs.evaluation.datasets import Pair, datasets_in, pairs_of
from hope_rs.evaluation.methods import PairContext, check_methods, run_method

pytest.importorskip("potpourri3d")
pytest.importorskip("matplotlib")


@pytest.fixture(scope="module")
def identity_set(tmp_path_factory):
    """Three bent copies of one triangulation: identity ground truth, no pairs.txt."""
    root = tmp_path_factory.mktemp("data")
    folder = root / "spheres"
    folder.mkdir()
    v, f = bumpy_sphere(400, 0)
    for i, s in enumerate((1.0, 1.1, 0.9)):
        w = v * np.array([1.0, s, 1.0]) + 0.02 * np.sin(3 * v[:, [1, 2, 0]]) * i
        write_off(folder / f"s{i}.off", w, f)
    return root


@pytest.fixture(scope="module")
def vts_set(tmp_path_factory):
    """Two relabelled copies with 1-based .vts landmarks and pairs.txt."""
    folder = tmp_path_factory.mktemp("vts") / "perm"
    (folder / "corres").mkdir(parents=True)
    v, f = bumpy_sphere(300, 1)
    rng = np.random.default_rng(0)
    landmarks = rng.choice(300, 50, replace=False)
    for name in ("p", "q"):
        perm = rng.permutation(300)  # new vertex i is old vertex perm[i]
        write_off(folder / f"{name}.off", v[perm], relabel(f, perm))
        inv = np.argsort(perm)
        (folder / "corres" / f"{name}.vts").write_text("\n".join(map(str, inv[landmarks] + 1)))
    (folder / "pairs.txt").write_text("p q\n")
    return folder


def test_identity_folder_pairs_every_two_meshes(identity_set):
    (folder,) = datasets_in(identity_set)
    pairs = pairs_of(folder)
    assert [p.name for p in pairs] == ["s0->s1", "s0->s2", "s1->s2"]
    ai, bi = pairs[0].ground_truth(400, 400)
    assert np.array_equal(ai, np.arange(400)) and np.array_equal(ai, bi)
    ai, _ = pairs[0].ground_truth(400, 400, max_points=100)
    assert ai.size == 100 and ai[0] == 0 and ai[-1] == 399


def test_vts_pairs_are_one_based_and_correspond(vts_set):
    (pair,) = pairs_of(vts_set)
    a, b = hope_rs.load_mesh(pair.a), hope_rs.load_mesh(pair.b)
    ai, bi = pair.ground_truth(a.n_vertices, b.n_vertices)
    np.testing.assert_allclose(a.vertices[ai], b.vertices[bi])  # the same points of the shape


def test_shared_remeshed_sets_are_read(tmp_path):
    pairs = pairs_of(data_path("faust_r"))
    assert len(pairs) == 10 and pairs[0].name == "tr_reg_002->tr_reg_007"
    ai, bi = pairs[0].ground_truth(4999, 5000)
    assert ai.size == bi.size == 5000


def test_bad_data_sets_say_how_to_fix_them(tmp_path, vts_set):
    with pytest.raises(ValueError, match="no meshes"):
        pairs_of(tmp_path)
    v, f = bumpy_sphere(100, 0)
    write_off(tmp_path / "a.off", v, f)
    write_off(tmp_path / "b.off", *bumpy_sphere(120, 0))
    with pytest.raises(ValueError, match="add pairs.txt"):
        pairs_of(tmp_path)
    (tmp_path / "pairs.txt").write_text("a c\n")
    with pytest.raises(ValueError, match="no mesh named 'c'"):
        pairs_of(tmp_path)
    (tmp_path / "pairs.txt").write_text("a b\n")
    with pytest.raises(ValueError, match="ground truth .* is missing"):
        pairs_of(tmp_path)
    (tmp_path / "pairs.txt").write_text("a b extra\n")
    with pytest.raises(ValueError, match="SOURCE TARGET"):
        pairs_of(tmp_path)
    with pytest.raises(ValueError, match="refers to vertex"):
        Pair("x", vts_set / "p.off", vts_set / "q.off", vts_set / "corres" / "p.vts",
             vts_set / "corres" / "q.vts").ground_truth(10, 300)  # fmt: skip


def test_methods_are_checked_and_timed(identity_set):
    with pytest.raises(ValueError, match="unknown method"):
        check_methods("hope,zoomin")
    assert check_methods("init, hope,init") == ["init", "hope"]
    folder = identity_set / "spheres"
    ctx = PairContext(hope_rs.load_mesh(folder / "s0.off"), hope_rs.load_mesh(folder / "s1.off"))
    init = run_method("init", ctx)
    hope = run_method("hope", ctx)
    rand = run_method("hope-rand50", ctx)
    assert init.seconds > 0 and hope.seconds > init.seconds and hope.start == "shot"
    assert rand.start == "shot-rand50"
    start = ctx.start_map("shot-rand50")
    assert 0.3 < np.mean(start != init.map) < 0.7  # about half the entries randomised
    e = hope_rs.geodesic_errors(ctx.b, hope.map)
    assert e.mean() <= hope_rs.geodesic_errors(ctx.b, init.map).mean()


def test_hope_on_a_noisy_pair_is_the_default_match_not_the_shared_start():
    """A noisy B is matched on its smoothed copy, whose descriptors are HOPE's start: the
    bench's "hope" is then the default match, not a match from the raw meshes' shared
    start (as for a part or a much denser shape)."""
    v, f = bumpy_sphere(400, 0)
    a = hope_rs.Mesh(v, f)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]]])
    edge = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1).mean()
    rng = np.random.default_rng(0)
    b = hope_rs.Mesh(v + rng.normal(0.0, 0.4 * edge, v.shape), f)
    res = run_method("hope", PairContext(a, b))
    assert res.start is None  # not the shared start
    np.testing.assert_array_equal(res.map, hope_rs.match(a, b).map)


def test_zoomout_maps_a_to_b():
    pytest.importorskip("pyFM")
    v, f = bumpy_sphere(400, 0)
    a = hope_rs.Mesh(v, f)
    b = hope_rs.Mesh(v * np.array([1.0, 1.1, 1.0]), f)
    res = run_method("zoomout", PairContext(a, b))
    assert res.map.shape == (400,) and res.map.max() < 400
    assert hope_rs.geodesic_errors(b, res.map).mean() < 0.2


def test_bench_command_writes_tables_plots_and_renders(identity_set, tmp_path, capsys):
    out = tmp_path / "res"
    argv = [str(identity_set), "--out", str(out), "--methods", "init,hope,hope-k4"]
    assert main(["bench", *argv, "--max-pairs", "2", "--ablation-pairs", "1", "-q"]) == 0
    names = {p.name for p in out.iterdir()}
    assert {"spheres.csv", "spheres.md", "summary.md", "spheres_curves.png"} <= names
    assert {"spheres_best.png", "spheres_worst.png"} <= names
    rows = list(csv.DictReader((out / "spheres.csv").read_text().splitlines()))
    assert [(r["pair"], r["method"]) for r in rows] == [
        ("s0->s1", "init"), ("s0->s1", "hope"), ("s0->s1", "hope-k4"),
        ("s0->s2", "init"), ("s0->s2", "hope"),
    ]  # fmt: skip
    scale = {
        f"s{i}": hope_rs.load_mesh(identity_set / "spheres" / f"s{i}.off").scale for i in range(3)
    }
    assert scale["s2"] < scale["s0"] < scale["s1"]
    for r in rows:
        assert 0 <= float(r["exact"]) <= 1 and float(r["seconds"]) > 0
        assert float(r["mean_x100"]) == pytest.approx(100 * float(r["mean"]), rel=1e-4)
        # mean_a is the same distances ÷ sqrt(area) of A: they read smaller against the
        # larger s0 when B is s2, the smallest sphere, and larger against s0 when B is s1.
        a, b = r["pair"].split("->")
        mean, mean_a = float(r["mean"]), float(r["mean_a"])
        assert mean_a == pytest.approx(mean * scale[b] / scale[a], rel=1e-4, abs=1e-9)
        if mean > 0:
            assert (mean_a < mean) if b == "s2" else (mean_a > mean)
        # HOPE's methods report how well their confidence ranks right above wrong matches
        # (NaN when a pair has no wrong match); the initial map has no confidence.
        auroc = r["confidence_auroc"]
        if r["method"] == "init":
            assert auroc == ""
        else:
            assert auroc == "nan" or 0 <= float(auroc) <= 1
    md = (out / "spheres.md").read_text()
    assert "| confidence AUROC |" in md
    assert "| hope | 2 |" in md and "Ablations" in md and "| hope-k4 | 1 |" in md
    assert (out / "spheres_curves.png").read_bytes()[:4] == b"\x89PNG"
    assert "5 of 5 results scored" in capsys.readouterr().out


def test_bench_refuses_bad_arguments(identity_set, tmp_path, capsys):
    assert main(["bench", str(identity_set), "--out", str(tmp_path), "--methods", "magic"]) == 2
    assert "unknown method" in capsys.readouterr().err
    init = ["--methods", "init"]  # these checks do not depend on pyFM being installed
    assert main(["bench", str(identity_set), "--out", str(tmp_path), "--sets", "nope", *init]) == 2
    assert "no data set nope" in capsys.readouterr().err
    assert main(["bench", str(tmp_path / "missing"), "--out", str(tmp_path), *init]) == 2
    assert main(["bench", str(identity_set), "--out", str(tmp_path), "--max-pairs", "0"]) == 2
    capsys.readouterr()
    # Checked before any work: nothing is written.
    for i, up in enumerate(("Z", "spheres=q", "=x", "sphres=z", "z,spheres=")):
        out = tmp_path / f"up{i}"
        assert main(["bench", str(identity_set), "--out", str(out), "--up", up, "-q", *init]) == 2
        assert "--up" in capsys.readouterr().err and not out.exists()
    afile = tmp_path / "afile"
    afile.write_text("x")
    assert main(["bench", str(identity_set), "--out", str(afile), "--methods", "init", "-q"]) == 2
    assert "exists and is not a folder" in capsys.readouterr().err
    lonely = tmp_path / "lonely" / "one"
    lonely.mkdir(parents=True)
    write_off(lonely / "a.off", *bumpy_sphere(100, 0))
    assert main(["bench", str(lonely.parent), "--out", str(tmp_path / "o"), "-q", *init]) == 2
    assert "no pair to run" in capsys.readouterr().err


def test_bench_refuses_up_front_without_the_packages_it_needs(
    identity_set, tmp_path, capsys, monkeypatch
):
    gone = {"potpourri3d", "pyFM"}
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name in gone else object()
    )
    out = tmp_path / "o"
    # The default methods hold ZoomOut: its fix comes first, with the way round it.
    assert main(["bench", str(identity_set), "--out", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert "need pyFM: pip install pyfmaps" in err and "leave zoomout out of --methods" in err
    assert not out.exists()  # checked before any work
    # Without a ZoomOut method pyFM is not needed; what is missing is named.
    assert main(["bench", str(identity_set), "--out", str(out), "--methods", "init", "-q"]) == 2
    assert "needs potpourri3d for scoring" in capsys.readouterr().err and not out.exists()
    assert bench.missing_packages(["init", "hope"]) == ["potpourri3d"]
    assert bench.missing_packages(["zoomout-wks"]) == ["potpourri3d", "pyfmaps"]
    gone.clear()
    assert bench.missing_packages(list(bench.METHODS)) == []


def test_bench_leaves_other_csv_files_alone(identity_set, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    others = {
        "mine.csv": b"a,b\n1,2\n",
        "latin1.csv": "caf\xe9,b\n1,2\n".encode("latin-1"),
        "alike.csv": b"dataset,pair,method\nx,y,z\n",
    }
    for name, data in others.items():
        (out / name).write_bytes(data)
    argv = ["bench", str(identity_set), "--out", str(out), "--methods", "init", "--max-pairs", "1"]
    assert main([*argv, "--no-render", "-q", "--up", "z,spheres=y,"]) == 0
    for name, data in others.items():
        assert (out / name).read_bytes() == data
        assert not (out / name).with_suffix(".md").exists()
    assert "spheres" in (out / "summary.md").read_text()


def test_colour_transfer_pulls_back_and_fills_gaps():
    from hope_rs.evaluation.show import pull_back_colours

    v, f = bumpy_sphere(100, 0)
    m = hope_rs.Mesh(v, f)
    c = np.random.default_rng(0).random((100, 3))
    np.testing.assert_allclose(pull_back_colours(c, np.arange(100), m), c)
    g = np.arange(100)
    g[1] = 0  # vertex 0 of B is hit twice, vertex 1 never
    out = pull_back_colours(c, g, m)
    np.testing.assert_allclose(out[0], (c[0] + c[1]) / 2)
    nearest = np.argsort(np.linalg.norm(v - v[1], axis=1))[1]
    np.testing.assert_allclose(out[1], out[nearest])


def test_show_command_renders_a_png(tmp_path, capsys):
    v, f = bumpy_sphere(300, 0)
    write_off(tmp_path / "a.off", v, f)
    write_off(tmp_path / "b.off", v * 1.1, f)
    (tmp_path / "map.txt").write_text("\n".join(map(str, range(300))))
    png = tmp_path / "out.png"
    argv = ["show", str(tmp_path / "a.off"), str(tmp_path / "b.off"), str(tmp_path / "map.txt")]
    assert main([*argv, "--png", str(png), "--up", "z"]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG" and png.stat().st_size > 5000
    (tmp_path / "map.txt").write_text("0\n1\n")
    assert main([*argv, "--png", str(png)]) == 2
    assert "has 2 entries but A has 300" in capsys.readouterr().err


def test_a_failing_pair_is_reported_and_the_others_still_run(
    vts_set, tmp_path, monkeypatch, capsys
):
    """One pair whose mesh cannot be read and one method that raises on one pair: both are
    rows with their reason, left out of the figures; every other (pair, method) is scored."""
    from hope_rs.evaluation import bench

    folder = tmp_path / "perm"
    (folder / "corres").mkdir(parents=True)
    for name in ("p", "q"):
        (folder / f"{name}.off").write_text((vts_set / f"{name}.off").read_text())
        (folder / "corres" / f"{name}.vts").write_text(
            (vts_set / "corres" / f"{name}.vts").read_text()
        )
    (folder / "bad.off").write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n")
    (folder / "corres" / "bad.vts").write_text("1\n")
    (folder / "pairs.txt").write_text("p q\np bad\nq p\n")
    real = bench.run_method

    def flaky(name, ctx):
        if (
            name == "hope"
            and ctx.a.vertices[0, 0] == hope_rs.load_mesh(folder / "q.off").vertices[0, 0]
        ):
            raise RuntimeError("GC_SAFETY_ASSERT FAILURE: duplicate edge\n(more lines)")
        return real(name, ctx)

    monkeypatch.setattr(bench, "run_method", flaky)
    out = tmp_path / "res"
    # The tables are written and the status says a pair failed (1, as a batch's).
    assert main(["bench", str(tmp_path), "--out", str(out), "--methods", "init,hope", "-q",
                 "--no-render"]) == 1  # fmt: skip
    rows = list(csv.DictReader((out / "perm.csv").read_text().splitlines()))
    got = {(r["pair"], r["method"]): r for r in rows}
    assert list(got) == [
        ("p->q", "init"), ("p->q", "hope"), ("p->bad", "init"), ("p->bad", "hope"),
        ("q->p", "init"), ("q->p", "hope"),
    ]  # fmt: skip
    ok = [k for k, r in got.items() if not r["failed"]]
    assert ok == [("p->q", "init"), ("p->q", "hope"), ("q->p", "init")]
    for k in ok:
        assert 0 <= float(got[k]["mean"]) < 0.3
    assert "index" in got[("p->bad", "hope")]["failed"]
    assert got[("q->p", "hope")]["failed"] == (
        "RuntimeError: GC_SAFETY_ASSERT FAILURE: duplicate edge (more lines)"
    )
    md = (out / "perm.md").read_text()
    # The figures are over the scored pairs only; the failures are listed with their reason.
    assert "| init | 2 |" in md and "| hope | 1 |" in md
    assert "Failed (3, left out of the figures above)" in md
    assert "- q->p hope: RuntimeError: GC_SAFETY_ASSERT FAILURE" in md
    err = capsys.readouterr().err
    assert "3 failed" in err and "perm p->bad init" in err


def test_an_interrupted_set_never_passes_for_a_finished_one(identity_set, vts_set, tmp_path,
                                                            monkeypatch):  # fmt: skip
    import hope_rs.evaluation.bench as bench

    out = tmp_path / "out"
    real, calls = bench.run_method, []

    def stop_at_the_second_pair(m, ctx):
        calls.append(m)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(m, ctx)

    monkeypatch.setattr(bench, "run_method", stop_at_the_second_pair)
    with pytest.raises(KeyboardInterrupt):
        bench.run_bench(identity_set, out, methods=["init"], render=False, progress=False)
    monkeypatch.undo()
    assert not (out / "spheres.csv").exists()
    with open(out / "spheres.csv.partial", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == 1  # the pair that ran, kept for a look
    # Another set into the same folder: its summary holds that set only.
    bench.run_bench(vts_set.parent, out, methods=["init"], render=False, progress=False)
    summary = (out / "summary.md").read_text()
    assert "perm" in summary and "spheres" not in summary
    # The whole set run again: its table, and no partial one left.
    bench.run_bench(identity_set, out, methods=["init"], render=False, progress=False)
    assert (out / "spheres.csv").exists() and not (out / "spheres.csv.partial").exists()
    assert "spheres" in (out / "summary.md").read_text()

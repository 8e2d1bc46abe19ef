import os

import numpy as np
import pytest
from meshes import bumpy_sphere, bumpy_sphere_files, write_off

import hope_rs
from hope_rs.batch.cache import ShapeCache, cached_shape, file_digest
from hope_rs.batch.driver import imatch_many, map_name, read_pairs
from hope_rs.batch.manifest import MANIFEST, Manifest
from hope_rs.batch.pairs_file import landmark_files
from hope_rs.cli import main
from hope_rs.features.descriptors import DescriptorConfig
from hope_rs.pipeline.config import OrientConfig
from hope_rs.shape import ShapeConfig


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """Three small generated meshes, a broken one and a pairs file naming them without suffix."""
    d = tmp_path_factory.mktemp("batch")
    (d / "m").mkdir()
    bumpy_sphere_files(d / "m", 3, 300)
    (d / "m" / "bad.off").write_text("OFF\n3 1 0\n0 0 0\n")
    (d / "m" / "pairs.txt").write_text("s0 s1\n# a comment\n\ns1 s2\ns2 s0  # trailing\n")
    (d / "m" / "with_bad.txt").write_text("s0 s1\ns0 bad\nbad s2\ns1 s2\n")
    return d


def test_read_pairs_resolves_relative_paths_against_the_file_and_appends_ext(folder, tmp_path):
    pairs = read_pairs(folder / "m" / "pairs.txt", ext=".off")
    m = (folder / "m").resolve()
    assert pairs == [(m / "s0.off", m / "s1.off"), (m / "s1.off", m / "s2.off"),
                     (m / "s2.off", m / "s0.off")]  # fmt: skip
    # Names already carrying the suffix, absolute paths and "off" without the dot.
    f = tmp_path / "p.txt"
    f.write_text(f"sub/a.off {m / 's1.off'}\n")
    assert read_pairs(f, ext="off") == [(tmp_path / "sub" / "a.off", m / "s1.off")]
    f.write_text("a.off b.off\nonly_one\n")
    with pytest.raises(ValueError, match=r"p.txt:2: expected two mesh paths"):
        read_pairs(f)
    f.write_text("# nothing\n")
    with pytest.raises(ValueError, match="lists no pairs"):
        read_pairs(f)
    # A pair listed twice (spelled two ways) would write one map file twice: named by line.
    f.write_text("a.off b.off\nb.off a.off\n\nsub/../a.off b\n")
    with pytest.raises(ValueError, match=r"p.txt:4: the pair sub/../a.off -> b .* line 1 already"):
        read_pairs(f, ext=".off")


def test_maps_are_written_atomically_and_a_rerun_skips_them(folder, tmp_path):
    pairs = read_pairs(folder / "m" / "pairs.txt", ext=".off")
    shapes = sorted({p for pr in pairs for p in pr})
    idx = [(shapes.index(a), shapes.index(b)) for a, b in pairs]
    out, cache = tmp_path / "out", tmp_path / "cache"
    first = hope_rs.match_many(shapes, idx, out_dir=out, jobs=1, cache=cache)
    assert [r.ok and not r.skipped for r in first] == [True] * 3
    files = sorted(f for f in out.iterdir() if f.name != MANIFEST)
    assert [f.name for f in files] == sorted(map_name(r.a, r.b) for r in first)  # no temp files
    assert sorted(Manifest(out).entries) == [f.name for f in files]
    for r in first:
        np.testing.assert_array_equal(np.loadtxt(r.path, dtype=np.int64), r.map)
        ref = hope_rs.match(hope_rs.load_mesh(shapes[idx[r.index][0]]),
                            hope_rs.load_mesh(shapes[idx[r.index][1]]))  # fmt: skip
        np.testing.assert_array_equal(r.map, ref.map)
    stamps = {f: f.stat().st_mtime_ns for f in files}
    os.remove(files[0])
    second = hope_rs.match_many(shapes, idx, out_dir=out, jobs=1, cache=cache)
    assert sum(r.skipped for r in second) == 2
    for f in files[1:]:
        assert f.stat().st_mtime_ns == stamps[f]  # not rewritten
    for a, b in zip(first, second):
        np.testing.assert_array_equal(a.map, b.map)


def test_a_bad_mesh_fails_its_pairs_only(folder, tmp_path):
    pairs = read_pairs(folder / "m" / "with_bad.txt", ext=".off")
    shapes = list(dict.fromkeys(p for pr in pairs for p in pr))
    idx = [(shapes.index(a), shapes.index(b)) for a, b in pairs]
    seen = []
    res = hope_rs.match_many(
        shapes, idx, out_dir=tmp_path, jobs=1, cache=False, progress=seen.append
    )
    assert [r.ok for r in res] == [True, False, False, True]
    assert len(seen) == 4
    assert "bad.off" in res[1].error and "OFF header" in res[1].error
    assert sorted(p.name for p in tmp_path.iterdir()) == [MANIFEST, "s0__s1.txt", "s1__s2.txt"]


def test_a_bad_mesh_in_memory_fails_its_pairs_only(tmp_path):
    v, f = bumpy_sphere(200, 1)
    broken = v.copy()
    broken[3, 1] = np.nan
    shapes = {"a": (v, f), "b": (v * 2, f), "bad": (broken, f), "holey": (v, f + 1000)}
    pairs = [("a", "b"), ("bad", "a"), ("b", "holey")]
    res = hope_rs.match_many(shapes, pairs, out_dir=tmp_path, jobs=1, cache=False)
    assert [r.ok for r in res] == [True, False, False]
    assert res[1].error.startswith("bad: ValueError: vertices contain NaN")
    assert res[2].error.startswith("holey: ValueError:") and "face" in res[2].error
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([MANIFEST, "a__b.txt"])


def test_shapes_described_with_different_settings_are_refused_before_any_work(tmp_path):
    v, f = bumpy_sphere(200, 1)
    wide = ShapeConfig(descriptors=DescriptorConfig(shot_radius=0.3))
    shapes = {"s": hope_rs.Shape((v, f), config=wide), "m": (v * [1.0, 1.1, 0.9], f)}
    with pytest.raises(ValueError, match=r"pair \('s', 'm'\): the two shapes are described"):
        hope_rs.match_many(shapes, [("s", "m")], out_dir=tmp_path / "out", jobs=1, cache=False)
    assert not (tmp_path / "out").exists()
    # With the Shape's settings as the batch's, the pair runs.
    same = hope_rs.match_many(
        shapes, [("s", "m")], jobs=1, cache=False, config=hope_rs.MatchConfig(shape=wide)
    )
    assert same[0].ok


@pytest.mark.slow
def test_objects_names_and_a_process_pool_give_the_same_maps(tmp_path):
    meshes = {f"m{s}": hope_rs.Mesh(*bumpy_sphere(250, 10 + s)) for s in range(3)}
    shape0 = hope_rs.Shape(meshes["m0"])
    shape0.descriptors("shot")
    shapes = {"m0": shape0, "m1": meshes["m1"], "m2": meshes["m2"]}
    pairs = [("m0", "m1"), ("m2", "m0")]
    serial = hope_rs.match_many(shapes, pairs, jobs=1, cache=tmp_path)
    pooled = hope_rs.match_many(shapes, pairs, jobs=2, cache=tmp_path)
    for s, p, (a, b) in zip(serial, pooled, pairs):
        assert (s.a, s.b) == (a, b) and s.ok and p.ok
        np.testing.assert_array_equal(s.map, hope_rs.match(meshes[a], meshes[b]).map)
        np.testing.assert_array_equal(s.map, p.map)
    assert len(hope_rs.match_many(list(meshes.values()), jobs=1, cache=False)) == 3  # all pairs
    with pytest.raises(ValueError, match="neither a shape index nor one of the names"):
        hope_rs.match_many(shapes, [("m0", "nope")])
    with pytest.raises(ValueError, match="jobs must be a positive integer"):
        hope_rs.match_many(shapes, [(0, 1)], jobs=0)


def test_cache_hits_are_identical_and_keyed_by_content(folder, tmp_path):
    src = tmp_path / "s.off"
    src.write_bytes((folder / "m" / "s0.off").read_bytes())
    cache = ShapeCache(tmp_path / "c")
    fresh = cached_shape(src, cache=cache).descriptors("shot")
    assert (cache.hits, cache.misses) == (0, 2)  # mesh + descriptors computed and stored
    again = cached_shape(src, cache=cache).descriptors("shot")
    assert (cache.hits, cache.misses) == (2, 2)
    np.testing.assert_array_equal(fresh, again)
    np.testing.assert_array_equal(fresh, hope_rs.Shape(hope_rs.load_mesh(src)).descriptors())
    # Editing the file changes its digest: nothing stale comes back.
    v, f = bumpy_sphere(300, 0)
    old = file_digest(src)
    write_off(src, v + np.random.default_rng(0).normal(scale=0.02, size=v.shape), f)
    assert file_digest(src) != old
    edited = cached_shape(src, cache=cache).descriptors("shot")
    assert (cache.hits, cache.misses) == (2, 4)
    assert not np.array_equal(edited, fresh)
    # A damaged entry is recomputed, not returned.
    for p in (tmp_path / "c").rglob("shot-*.npz"):
        p.write_bytes(b"garbage")
    with pytest.warns(RuntimeWarning, match="damaged"):
        got = cached_shape(src, cache=cache).descriptors("shot")
    np.testing.assert_array_equal(got, edited)


def test_cli_batch_exit_codes(folder, tmp_path, capsys):
    cache = ["--cache", str(tmp_path / "c"), "-q", "-j", "1"]
    args = ["batch", str(folder / "m" / "pairs.txt"), "--ext", ".off", "--out", str(tmp_path / "o")]
    assert main(args + cache) == 0
    assert "3 pairs: 3 matched, 0 skipped, 0 failed" in capsys.readouterr().out
    assert main(args + cache) == 0
    assert "0 matched, 3 skipped" in capsys.readouterr().out
    bad = ["batch", str(folder / "m" / "with_bad.txt"), "--ext", ".off", "--out"]
    assert main(bad + [str(tmp_path / "o2")] + cache) == 1
    err = capsys.readouterr().err
    assert "pair failed: s0 -> bad" in err and "pair failed: bad -> s2" in err
    assert main(["batch", str(tmp_path / "missing.txt"), "--out", str(tmp_path)]) == 2
    assert "hope-rs: error: no such pairs file" in capsys.readouterr().err
    # Names without a suffix and no --ext: their pairs fail, with a hint up front.
    noext = ["batch", str(folder / "m" / "pairs.txt"), "--out", str(tmp_path / "o4")]
    assert main(noext + cache[:2] + ["-j", "1"]) == 1
    err = capsys.readouterr().err
    assert "mesh file(s) of the pairs file do not exist" in err and "need --ext" in err
    assert f"no such mesh file: {str(folder / 'm' / 's0')!r}" in err
    assert main(noext[:-1] + [str(tmp_path / "o5")] + cache) == 1
    assert "mesh file(s) of the pairs file do not exist" in capsys.readouterr().err  # -q too
    assert main(args + ["--no-cache", "--cache", str(tmp_path)]) == 2
    (tmp_path / "file").write_text("")
    assert main(["batch", str(folder / "m" / "pairs.txt"), "--out", str(tmp_path / "file")]) == 2
    assert "is not a folder" in capsys.readouterr().err


@pytest.mark.slow
def test_ray_backend_matches_the_local_run_pair_for_pair(folder, tmp_path):
    ray = pytest.importorskip("ray")
    pairs = read_pairs(folder / "m" / "with_bad.txt", ext=".off")
    shapes = list(dict.fromkeys(p for pr in pairs for p in pr))
    idx = [(shapes.index(a), shapes.index(b)) for a, b in pairs]
    local = hope_rs.match_many(shapes, idx, jobs=1, cache=tmp_path / "c")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        remote = list(imatch_many(shapes, idx, backend="ray", cache=tmp_path / "c2"))
    finally:
        ray.shutdown()
    remote.sort(key=lambda r: r.index)
    assert [r.ok for r in remote] == [r.ok for r in local] == [True, False, False, True]
    for a, b in zip(local, remote):
        assert (a.a, a.b, a.error) == (b.a, b.b, b.error)
        if a.ok:
            np.testing.assert_array_equal(a.map, b.map)


@pytest.mark.slow
def test_the_spectral_basis_is_cached_once_per_shape_and_reused(folder, tmp_path, monkeypatch):
    import hope_rs.batch.tasks as batch_module
    import hope_rs.features.descriptors
    import hope_rs.shape

    shapes = [folder / "m" / f"s{s}.off" for s in range(3)]
    pairs = [(0, 1), (1, 2)]
    # Without the orient stage, whose nested matches of B's mirror image solve their own bases.
    cfg = hope_rs.MatchConfig(orient=OrientConfig(enabled=False))
    first = hope_rs.match_many(shapes, pairs, jobs=1, cache=tmp_path / "c", config=cfg)
    assert len(list((tmp_path / "c").rglob("basis-*.npz"))) == 3  # one per shape

    # A new process (no shapes kept in memory) reads the bases instead of solving for them.
    def no_eigensolve(*args, **kwargs):
        raise AssertionError("the basis should have come from the cache")

    monkeypatch.setattr(batch_module, "_SHAPES", type(batch_module._SHAPES)())
    monkeypatch.setattr(hope_rs.shape, "spectral_basis_of", no_eigensolve)
    monkeypatch.setattr(hope_rs.features.descriptors, "laplacian_basis_as_numbered", no_eigensolve)
    again = hope_rs.match_many(shapes, pairs, jobs=1, cache=tmp_path / "c", config=cfg)
    for x, y in zip(first, again):
        assert x.ok and y.ok, (x.error, y.error)
        np.testing.assert_array_equal(x.map, y.map)
    monkeypatch.undo()
    direct = hope_rs.match(hope_rs.load_mesh(shapes[0]), hope_rs.load_mesh(shapes[1]), config=cfg)
    assert direct.timings["spectral"] > 0
    np.testing.assert_array_equal(first[0].map, direct.map)
    # Without the spectral pass nothing is solved or stored.
    none = hope_rs.match_many(shapes, pairs, jobs=1, cache=tmp_path / "d", spectral=False)
    assert all(r.ok for r in none)
    assert not list((tmp_path / "d").rglob("basis-*.npz"))


def test_per_pair_landmarks_from_the_pairs_file_and_match_many(folder, tmp_path, capsys):
    """A third field of a pairs line names the pair's landmark file: the batch's map keeps its
    landmarks (as ``match(..., landmarks=)`` does); other pairs run without."""
    m = (folder / "m").resolve()
    s0, s1 = (hope_rs.load_mesh(m / f"s{i}.off") for i in (0, 1))
    free = hope_rs.match(s0, s1).map
    # Two landmarks the free map does not keep: vertex 0 and 7 sent to other vertices.
    lm = np.array([[0, free[5]], [7, free[40]]], dtype=np.int64)
    want = hope_rs.match(s0, s1, landmarks=lm).map
    assert (want[lm[:, 0]] == lm[:, 1]).all() and not np.array_equal(want, free)
    (tmp_path / "lm.txt").write_text("".join(f"{a} {b}\n" for a, b in lm))
    pairs_file = tmp_path / "pairs.txt"
    pairs_file.write_text(f"{m / 's0.off'} {m / 's1.off'} lm.txt\n{m / 's1.off'} {m / 's2.off'}\n")
    pairs, marks = read_pairs(pairs_file, with_landmarks=True)
    assert pairs == [(m / "s0.off", m / "s1.off"), (m / "s1.off", m / "s2.off")]
    assert marks[0].tolist() == lm.tolist() and marks[1] is None
    with pytest.raises(ValueError, match=r"pairs.txt:1: expected two mesh paths"):
        read_pairs(pairs_file)  # a third field only with with_landmarks
    cache = ["--cache", str(tmp_path / "c"), "-q", "-j", "1"]
    assert main(["batch", str(pairs_file), "--out", str(tmp_path / "o")] + cache) == 0
    np.testing.assert_array_equal(np.loadtxt(tmp_path / "o" / "s0__s1.txt", dtype=np.int64), want)
    np.testing.assert_array_equal(
        np.loadtxt(tmp_path / "o" / "s1__s2.txt", dtype=np.int64),
        hope_rs.match(s1, hope_rs.load_mesh(m / "s2.off")).map,
    )
    capsys.readouterr()  # the first batch's output (it may warn that a pair likely failed)
    # A missing landmark file: one line naming the pairs file's line, before any work.
    pairs_file.write_text(f"{m / 's0.off'} {m / 's1.off'} nowhere.txt\n")
    assert main(["batch", str(pairs_file), "--out", str(tmp_path / "o3")] + cache) == 2
    err = capsys.readouterr().err.strip()
    assert "pairs.txt:1: a third field names the pair's landmark file: no such landmark file" in err
    assert len(err.splitlines()) == 1
    assert not (tmp_path / "o3").exists()


def test_match_many_landmarks_are_checked_per_pair(folder, tmp_path):
    m = (folder / "m").resolve()
    shapes = [m / "s0.off", m / "s1.off"]
    n = hope_rs.load_mesh(shapes[1]).n_vertices
    with pytest.raises(ValueError, match="give the pairs they are for"):
        hope_rs.match_many(shapes, landmarks=[None], jobs=1, cache=False)
    with pytest.raises(ValueError, match="2 entries for 1 pairs"):
        hope_rs.match_many(shapes, [(0, 1)], landmarks=[None, None], jobs=1, cache=False)
    with pytest.raises(ValueError, match=r"landmarks\[0\] \(for pairs\[0\]\): .*shape \(m, 2\)"):
        hope_rs.match_many(shapes, [(0, 1)], landmarks=[[1, 2, 3]], jobs=1, cache=False)
    # Out of range for this pair's shapes: that pair fails, the others are matched.
    res = hope_rs.match_many(
        shapes, [(0, 1), (1, 0)], landmarks=[[[0, n]], None], jobs=1, cache=False
    )
    assert not res[0].ok and f"vertex {n} is not a vertex of B" in res[0].error and res[1].ok


def test_landmark_files_are_each_pairs_third_field_resolved(tmp_path):
    elsewhere = tmp_path / "lm" / "b.lm"
    (tmp_path / "pairs.txt").write_text(
        f"a b a.lm\nb c\nc d {elsewhere}\n# a comment\nd e sub/e.lm  # trailing\n"
    )
    assert landmark_files(tmp_path / "pairs.txt", ext=".off") == [
        tmp_path / "a.lm", None, elsewhere, tmp_path / "sub" / "e.lm"
    ]  # fmt: skip
    (tmp_path / "bad.txt").write_text("a b c d\n")
    with pytest.raises(ValueError, match=r"bad.txt:1: expected two mesh paths \(and a landmark"):
        landmark_files(tmp_path / "bad.txt")


def test_a_landmark_file_out_of_range_for_its_pair_is_named(folder, tmp_path, capsys):
    """Landmarks read from a file and out of range for their pair's shapes fail that pair with
    an error naming the file, from the pairs file and from ``match_many``'s paths alike."""
    m = (folder / "m").resolve()
    n = hope_rs.load_mesh(m / "s1.off").n_vertices
    (tmp_path / "far.lm").write_text(f"0 {n}\n")
    (tmp_path / "near.lm").write_text("0 0\n")
    pairs_file = tmp_path / "pairs.txt"
    pairs_file.write_text(
        f"{m / 's0.off'} {m / 's1.off'} far.lm\n{m / 's1.off'} {m / 's2.off'} near.lm\n"
    )
    assert landmark_files(pairs_file) == [tmp_path / "far.lm", tmp_path / "near.lm"]
    cache = ["--cache", str(tmp_path / "c"), "-q", "-j", "1"]
    assert main(["batch", str(pairs_file), "--out", str(tmp_path / "o")] + cache) == 1
    err = capsys.readouterr().err
    assert f"landmark file {str(tmp_path / 'far.lm')!r}: " in err
    assert f"vertex {n} is not a vertex of B" in err
    assert (tmp_path / "o" / "s1__s2.txt").is_file() and not (
        tmp_path / "o" / "s0__s1.txt"
    ).exists()
    shapes = [m / "s0.off", m / "s1.off"]
    res = hope_rs.match_many(
        shapes, [(0, 1), (1, 0)], landmarks=[tmp_path / "far.lm", None], jobs=1, cache=False
    )
    assert not res[0].ok and "far.lm" in res[0].error and res[1].ok
    with pytest.raises(FileNotFoundError, match=r"landmarks\[0\] .*no such landmark file"):
        hope_rs.match_many(shapes, [(0, 1)], landmarks=[tmp_path / "gone.lm"], cache=False)
    with pytest.raises(TypeError, match="one entry per pair"):
        hope_rs.match_many(shapes, [(0, 1)], landmarks=str(tmp_path / "far.lm"), cache=False)


def test_a_rerun_redoes_a_map_that_does_not_keep_its_new_landmarks(folder, tmp_path):
    m = (folder / "m").resolve()
    shapes = [m / "s0.off", m / "s1.off"]
    out, cache = tmp_path / "out", tmp_path / "cache"
    (free,) = hope_rs.match_many(shapes, [(0, 1)], out_dir=out, jobs=1, cache=cache)
    lm = np.array([[0, free.map[5]]])  # not kept by the map already written
    with pytest.warns(RuntimeWarning, match="its landmarks changed; computing it again"):
        (again,) = hope_rs.match_many(
            shapes, [(0, 1)], out_dir=out, jobs=1, cache=cache, landmarks=[lm]
        )
    assert not again.skipped and again.map[0] == lm[0, 1]
    np.testing.assert_array_equal(np.loadtxt(again.path, dtype=np.int64), again.map)
    # Kept now: the next rerun skips it, and a landmark out of range fails the pair.
    (third,) = hope_rs.match_many(
        shapes, [(0, 1)], out_dir=out, jobs=1, cache=cache, landmarks=[lm]
    )
    assert third.skipped
    (bad,) = hope_rs.match_many(
        shapes, [(0, 1)], out_dir=out, jobs=1, cache=cache, landmarks=[[[10**6, 0]]]
    )
    assert not bad.ok and "is not a vertex of A" in bad.error

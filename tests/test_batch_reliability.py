"""A batch loses nothing and reuses nothing stale: maps written as each pair finishes, a summary
on Ctrl-C, existing map files and cache entries checked before they are reused."""

import os
import shutil
import stat
import subprocess
import sys
import warnings

import numpy as np
import pytest
from conftest import unwritable_folder
from meshes import bumpy_sphere_files

import hope_rs
import hope_rs.batch.driver
import hope_rs.batch.tasks
import hope_rs.matching
from hope_rs.batch.cache import ShapeCache, cached_shape
from hope_rs.batch.driver import imatch_many, map_name, read_pairs
from hope_rs.batch.manifest import MANIFEST
from hope_rs.cli import main
from hope_rs.geometry.map_io import read_map

N = 300


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """Three small generated meshes and a pairs file of three pairs."""
    d = tmp_path_factory.mktemp("reliable")
    bumpy_sphere_files(d, 3, N)
    (d / "pairs.txt").write_text("s0 s1\ns1 s2\ns2 s0\n")
    return d


@pytest.fixture(scope="module")
def reference_run(folder, tmp_path_factory):
    """The output folder of the three pairs and their maps, keyed by file name."""
    out = tmp_path_factory.mktemp("ref")
    res = hope_rs.match_many(
        [folder / f"s{s}.off" for s in range(3)], [(0, 1), (1, 2), (2, 0)], out_dir=out,
        jobs=1, cache=out / "cache",
    )  # fmt: skip
    return out, {r.path.name: r.map for r in res}


@pytest.fixture(scope="module")
def reference(reference_run):
    """The maps of the three pairs, keyed by file name."""
    return reference_run[1]


def shapes_and_pairs(folder):
    return [folder / f"s{s}.off" for s in range(3)], [(0, 1), (1, 2), (2, 0)]


@pytest.fixture
def count_matches(monkeypatch):
    """Count the pairs matched in this process (the serial backend runs them here)."""
    calls = []
    real = hope_rs.matching.match

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(hope_rs.batch.tasks, "match", counting)
    return calls


def test_one_job_writes_each_map_as_soon_as_its_pair_is_done(folder, tmp_path, count_matches):
    shapes, pairs = shapes_and_pairs(folder)
    seen = []

    def check(r):  # called before the next pair starts
        seen.append((len(count_matches), sorted(p.name for p in tmp_path.glob("*.txt"))))

    hope_rs.match_many(shapes, pairs, out_dir=tmp_path, jobs=1, cache=False, progress=check)
    names = [map_name(f"s{i}", f"s{j}") for i, j in pairs]
    assert [n for n, _ in seen] == [1, 2, 3]
    for k, (_, files) in enumerate(seen):
        assert len(files) == k + 1 and set(files) <= set(names)


def test_ctrl_c_prints_the_summary_keeps_the_maps_and_a_rerun_finishes(
    folder, reference, tmp_path, monkeypatch, capsys
):
    real = hope_rs.matching.match
    calls = []

    def interrupted_second(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(hope_rs.batch.tasks, "match", interrupted_second)
    out = tmp_path / "out"
    args = ["batch", str(folder / "pairs.txt"), "--ext", ".off", "--out", str(out), "-j", "1",
            "-q", "--cache", str(tmp_path / "c")]  # fmt: skip
    assert main(args) == 130
    cap = capsys.readouterr()
    assert "3 pairs: 1 matched, 0 skipped, 0 failed, 2 not run (interrupted)" in cap.out
    assert "rerun the same command" in cap.err and "Traceback" not in cap.err
    files = [f for f in out.iterdir() if f.name != MANIFEST]
    assert len(files) == 1  # the finished map, whole; no temporary file
    np.testing.assert_array_equal(read_map(files[0], N, N), reference[files[0].name])
    monkeypatch.setattr(hope_rs.batch.tasks, "match", real)
    assert main(args) == 0
    assert "3 pairs: 2 matched, 1 skipped, 0 failed" in capsys.readouterr().out
    for name, m in reference.items():
        np.testing.assert_array_equal(read_map(out / name, N, N), m)


@pytest.mark.parametrize(
    "damage",
    ["empty", "truncated", "cut_in_last_line", "garbage", "out_of_range", "negative", "npy"],
)
def test_a_damaged_map_file_is_redone_not_skipped(folder, reference_run, tmp_path, damage):
    reference = reference_run[1]
    shapes, pairs = shapes_and_pairs(folder)
    name = map_name("s1", "s2")
    good = "".join(f"{x}\n" for x in reference[name])
    rest = good.split("\n", 1)[1]  # every line but the first
    bad = {
        "empty": "",
        "truncated": good[: len(good) // 2],
        "cut_in_last_line": good.rstrip("\n")[:-1],  # same count, last index cut short
        "garbage": "\x00\x01 not a map \xff",
        "out_of_range": f"{N}\n{rest}",
        "negative": f"-1\n{rest}",
        "npy": "\x93NUMPY garbage",
    }[damage]
    if damage == "cut_in_last_line":  # passes the length and range checks: only the end tells
        assert bad.count("\n") == N - 1 and 0 <= int(bad.rsplit("\n", 1)[1]) < N
    for n, m in reference.items():
        (tmp_path / n).write_text("".join(f"{x}\n" for x in m))
    shutil.copy(reference_run[0] / MANIFEST, tmp_path)  # the maps' record: only damage differs
    (tmp_path / name).write_bytes(bad.encode("latin-1"))
    # A map cut inside its last line is named as cut short, before its digest is compared.
    why = "ends inside its last line.*" if damage == "cut_in_last_line" else ""
    with pytest.warns(RuntimeWarning, match=f"{name}.*{why}computing it again"):
        res = hope_rs.match_many(shapes, pairs, out_dir=tmp_path, jobs=1, cache=tmp_path / "c")
    assert [r.skipped for r in res] == [True, False, True]
    for r in res:
        assert r.ok
        np.testing.assert_array_equal(r.map, reference[r.path.name])
        np.testing.assert_array_equal(read_map(r.path, N, N), reference[r.path.name])


def test_npy_maps_and_their_permissions(folder, reference, tmp_path):
    shapes, pairs = shapes_and_pairs(folder)
    old = os.umask(0o022)
    try:
        res = hope_rs.match_many(
            shapes, pairs, out_dir=tmp_path, jobs=1, cache=tmp_path / "c", map_format="npy"
        )
    finally:
        os.umask(old)
    for r in res:
        assert r.path.suffix == ".npy"
        np.testing.assert_array_equal(np.load(r.path), reference[r.path.stem + ".txt"])
        assert stat.S_IMODE(r.path.stat().st_mode) == 0o644
    again = hope_rs.match_many(
        shapes, pairs, out_dir=tmp_path, jobs=1, cache=tmp_path / "c", map_format="npy"
    )
    assert all(r.skipped for r in again)


def test_an_unwritable_out_fails_before_any_work(folder, tmp_path, count_matches, capsys):
    ro = unwritable_folder(tmp_path)
    for out in (str(ro), os.path.join(str(ro), "sub")):
        args = ["batch", str(folder / "pairs.txt"), "--ext", ".off", "--out", out, "-j", "1"]
        assert main(args + ["-q", "--no-cache"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err
        assert f"'{out}'" in err and ("cannot write" in err or "cannot create" in err)
        assert ".hope-rs-" not in err  # not a temporary file's name
    assert count_matches == []


# -- pairs files --------------------------------------------------------------------------------


def test_pairs_files_take_quoted_and_tab_separated_paths_with_spaces(tmp_path):
    (tmp_path / "my meshes").mkdir()
    f = tmp_path / "pairs.txt"
    f.write_text(
        '"my meshes/a b" c  # quoted\n'
        "'my meshes/x.off' \"my meshes/a b\"\n"
        "my meshes/a b\tc d.off\t# tab-separated, comment\n"
        "\tc\t my meshes/x \n"
        "\"my meshes/a b\"\t'c d.ply'\n"  # quoted and tab-separated
        "scan.v2 b.PLY\n"  # a bare name with a dot, a mesh suffix in capitals
    )
    d = tmp_path / "my meshes"
    assert read_pairs(f, ext=".off") == [
        (d / "a b.off", tmp_path / "c.off"),
        (d / "x.off", d / "a b.off"),
        (d / "a b.off", tmp_path / "c d.off"),
        (tmp_path / "c.off", d / "x.off"),
        (d / "a b.off", tmp_path / "c d.ply"),
        (tmp_path / "scan.v2.off", tmp_path / "b.PLY"),
    ]


@pytest.mark.parametrize(
    "line, fields",
    [("only_one", 1), ("a b c", 3), ("a\tb\tc", 3), ("my meshes/a b c.off", 4), ("a 'b", None)],
)
def test_a_malformed_pairs_line_is_named(tmp_path, line, fields):
    f = tmp_path / "p.txt"
    f.write_text(f"a b\n{line}\n")
    want = f"got {fields} field" if fields else "No closing quotation"
    with pytest.raises(ValueError, match=rf"p\.txt:2: .*{want}") as err:
        read_pairs(f)
    assert "\n" not in str(err.value)


# -- the cache ------------------------------------------------------------------------------------


def _entries(root, what):
    return sorted(root.rglob(f"{what}-*.npz"))


@pytest.mark.parametrize(
    "damage", ["truncate", "garbage", "swap", "pickle", "no_key", "altered_arrays"]
)
def test_a_damaged_cache_entry_is_recomputed_and_rewritten(folder, tmp_path, damage):
    cache = ShapeCache(tmp_path / "c")
    srcs = [folder / "s0.off", folder / "s1.off"]
    want = [cached_shape(s, cache=cache).descriptors("shot") for s in srcs]
    entries = _entries(tmp_path / "c", "shot")
    assert len(entries) == 2
    victim = next(e for e in entries if e.parent.name == cache._key(
        hope_rs.batch.cache.file_digest(srcs[0]), "shot", hope_rs.batch.cache.descriptor_params("shot"))[0]
        .parent.name)  # fmt: skip
    other = next(e for e in entries if e != victim)
    data = victim.read_bytes()
    if damage == "truncate":
        victim.write_bytes(data[: len(data) // 2])
    elif damage == "garbage":
        victim.write_bytes(os.urandom(len(data)))
    elif damage == "swap":  # another shape's entry under this shape's name
        shutil.copyfile(other, victim)
    elif damage == "pickle":
        with open(victim, "wb") as fh:
            np.save(fh, np.array([object()]), allow_pickle=True)
    elif damage == "altered_arrays":  # its key and checksum kept, its values changed
        with np.load(victim) as z:
            arrays = {k: z[k] for k in z.files}
        for k, v in arrays.items():
            if v.dtype.kind == "f":
                arrays[k] = np.zeros_like(v)
        with open(victim, "wb") as fh:
            np.savez(fh, **arrays)
    else:  # a well-formed npz without the integrity fields (e.g. written by hand)
        with open(victim, "wb") as fh:
            np.savez(fh, d=want[0])
    fresh = ShapeCache(tmp_path / "c")
    reason = "checksum mismatch" if damage == "altered_arrays" else ""
    with pytest.warns(RuntimeWarning, match=f"{victim.name}.*damaged.*{reason}.*recomputing"):
        got = cached_shape(srcs[0], cache=fresh).descriptors("shot")
    np.testing.assert_array_equal(got, want[0])
    assert fresh.misses == 1  # recomputed, rewritten
    again = ShapeCache(tmp_path / "c")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the rewritten entry is whole
        np.testing.assert_array_equal(cached_shape(srcs[0], cache=again).descriptors("shot"),
                                      want[0])  # fmt: skip
        np.testing.assert_array_equal(cached_shape(srcs[1], cache=again).descriptors("shot"),
                                      want[1])  # fmt: skip
    assert (again.hits, again.misses) == (4, 0)


def test_a_batch_over_damaged_cache_entries_gives_the_right_maps(folder, reference, tmp_path):
    shapes, pairs = shapes_and_pairs(folder)
    cache = tmp_path / "c"
    hope_rs.match_many(shapes, pairs, jobs=1, cache=cache, spectral=True)
    shots, meshes = _entries(cache, "shot"), _entries(cache, "mesh")
    shutil.copyfile(shots[1], shots[0])  # swapped
    meshes[2].write_bytes(meshes[2].read_bytes()[:100])  # truncated
    bases = _entries(cache, "basis")
    bases[1].write_bytes(b"garbage")
    with pytest.warns(RuntimeWarning, match="damaged"):
        res = list(imatch_many(shapes, pairs, jobs=1, cache=cache, out_dir=tmp_path / "o"))
    for r in res:
        assert r.ok, r.error
        np.testing.assert_array_equal(r.map, reference[r.path.name])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # every entry was rewritten whole
        for s in shapes:
            cached_shape(s, cache=ShapeCache(cache))


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_damaged_map_among_missing_ones_is_redone(folder, reference, tmp_path, jobs):
    # Its shapes are prepared in full for the missing pairs, before its file is checked.
    shapes, pairs = shapes_and_pairs(folder)
    name = map_name("s1", "s2")
    (tmp_path / name).write_text("1\n2\n")
    with pytest.warns(RuntimeWarning, match=f"{name}' has 2 entries"):
        res = hope_rs.match_many(shapes, pairs, out_dir=tmp_path, jobs=jobs, cache=tmp_path / "c")
    assert [r.ok and not r.skipped for r in res] == [True] * 3
    for r in res:
        np.testing.assert_array_equal(read_map(r.path, N, N), reference[r.path.name])


def test_a_script_without_the_main_guard_fails_with_the_fix_instead_of_hanging(tmp_path):
    # Workers are spawned: each imports the main script, which here starts the batch again.
    script = tmp_path / "noguard.py"
    script.write_text(
        "import numpy as np, hope_rs\n"
        "v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])\n"
        "f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])\n"
        "hope_rs.match_many({'a': (v, f), 'b': (v, f)}, [('a', 'b'), ('b', 'a')], jobs=2, "
        "cache=False)\n"
    )
    res = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=300, check=False
    )
    assert res.returncode != 0
    last = res.stderr.strip().splitlines()[-1]
    assert last.startswith("RuntimeError: the batch's worker processes died while starting")
    assert 'if __name__ == "__main__":' in last and "jobs=1" in last


def test_a_cache_that_cannot_be_written_leaves_the_pairs_right(folder, reference, tmp_path, capfd):
    # The cache root is checked up front; an entry that cannot be written later (a full disk,
    # a read-only subfolder) is left out with a warning and the pair goes on.
    cache = tmp_path / "cache"
    (cache / "v2").parent.mkdir(parents=True)
    (cache / "v2").write_text("not a folder")  # every entry's folder lies below it
    shapes, pairs = shapes_and_pairs(folder)
    # Two workers: a pair task cannot read the shapes from the cache, so they come with it.
    res = hope_rs.match_many(shapes, pairs, out_dir=tmp_path / "o", jobs=2, cache=cache)
    assert "cannot be written (Not a directory); going on without it" in capfd.readouterr().err
    assert all(r.ok for r in res)
    for r in res:
        np.testing.assert_array_equal(r.map, reference[r.path.name])


def test_a_mesh_file_replaced_while_it_is_read_cannot_poison_the_cache(
    folder, tmp_path, monkeypatch
):
    # The digest and the parse come from one read of the file.
    path = tmp_path / "m.off"
    shutil.copy(folder / "s0.off", path)
    first = hope_rs.load_mesh(path)
    real = hope_rs.batch.cache.parse_mesh

    def swap_then_parse(p, data, **kw):
        shutil.copy(folder / "s1.off", path)  # another writer replaces the file
        return real(p, data, **kw)

    monkeypatch.setattr(hope_rs.batch.cache, "parse_mesh", swap_then_parse)
    cache = ShapeCache(tmp_path / "cache")
    mesh, digest = cache.mesh(shutil.copy(folder / "s0.off", path))
    np.testing.assert_array_equal(mesh.vertices, first.vertices)
    stored = cache.get(digest, "mesh", {})
    np.testing.assert_array_equal(stored["vertices"], first.vertices)


def test_a_batch_describes_a_shape_itself_and_refuses_a_view(folder, tmp_path):
    # Descriptors set on a Shape by hand are not written into the shared cache under its
    # mesh; a Shape measured at another scale has no place in a batch.
    shapes, pairs = shapes_and_pairs(folder)
    s0 = hope_rs.Shape(hope_rs.load_mesh(shapes[0]))
    s0.set_descriptors("shot", np.zeros_like(s0.descriptors("shot")))
    cache = tmp_path / "cache"
    got = hope_rs.match_many([s0, shapes[1]], [(0, 1)], jobs=1, cache=cache)[0]
    plain = hope_rs.match_many(shapes[:2], [(0, 1)], jobs=1, cache=False)[0]
    np.testing.assert_array_equal(got.map, plain.map)
    mesh = hope_rs.load_mesh(shapes[0])
    stored = ShapeCache(cache).descriptors(mesh, "shot")
    assert np.abs(stored).sum() > 0
    view = hope_rs.Shape(mesh).at_scale(2.0)
    with pytest.raises(ValueError, match="at another scale .* cannot be batched"):
        hope_rs.match_many([view, shapes[1]], [(0, 1)], jobs=1, cache=False)


def test_empty_and_tilde_folders(folder, tmp_path, monkeypatch):
    # An empty path is the current folder to pathlib; "~" in a variable is the home folder.
    shapes, pairs = shapes_and_pairs(folder)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match="names no folder"):
        hope_rs.match_many(shapes, pairs, jobs=1, cache="")
    with pytest.raises(ValueError, match="output folder names no folder"):
        hope_rs.match_many(shapes, pairs, jobs=1, cache=False, out_dir="")
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv("HOPE_RS_CACHE", "~/c")
    assert hope_rs.batch.cache.default_cache_dir() == tmp_path / "home" / "c"
    with pytest.raises(ValueError, match="k must be a positive integer"):
        hope_rs.Shape(hope_rs.load_mesh(shapes[0])).spectral_basis(0)

"""Batches you can trust: one file per pair inside the output folder, the settings asked for,
resumes that know what changed, and one bad pair or worker never stopping the others."""

import json
import os
import shutil
import subprocess
import sys
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from meshes import bumpy_sphere, echo_or_die, relabel, write_off

import hope_rs
import hope_rs.batch.driver
import hope_rs.batch.tasks
import hope_rs.cli.commands
import hope_rs.evaluation.show
import hope_rs.geometry.map_io
import hope_rs.matching
from hope_rs import MatchConfig
from hope_rs.batch.backends import DIED, PoolBackend
from hope_rs.batch.cache import ShapeCache
from hope_rs.batch.driver import imatch_many, read_pairs
from hope_rs.batch.manifest import MANIFEST, Manifest
from hope_rs.batch.naming import map_names
from hope_rs.batch.scheduler import _quality
from hope_rs.cli import main
from hope_rs.features.descriptors import DescriptorConfig
from hope_rs.pipeline.config import InitialConfig
from hope_rs.shape import ShapeConfig

N = 150
#: Quick settings for pairs whose maps are not what a test looks at.
FAST = {"max_passes": 1, "spectral": False, "shared_faces": False}


@pytest.fixture(scope="module")
def meshes():
    """Four small bumpy spheres with different triangulations."""
    return [hope_rs.Mesh(*bumpy_sphere(N, 40 + s)) for s in range(4)]


@pytest.fixture(scope="module")
def files(meshes, tmp_path_factory):
    d = tmp_path_factory.mktemp("trust")
    for s, m in enumerate(meshes):
        write_off(d / f"s{s}.off", m.vertices, m.faces)
    return d


@pytest.fixture
def configs(monkeypatch):
    """The MatchConfig and shapes each pair matched in this process was run with."""
    seen = []
    real = hope_rs.matching.run_match

    def spy(a, b, init, config, **kwargs):
        seen.append((config, a, b))
        return real(a, b, init, config, **kwargs)

    monkeypatch.setattr(hope_rs.matching, "run_match", spy)
    return seen


def maps_in(out) -> list[str]:
    return sorted(p.name for p in out.iterdir() if p.name != MANIFEST)


# -- 1-4: data lost or written where nobody asked ------------------------------------------------


def test_1_names_joined_alike_and_keys_alike_get_their_own_map_files(meshes, tmp_path):
    shapes = {"x__y": meshes[0], "z": meshes[1], "x": meshes[2], "y__z": meshes[3]}
    pairs = [("x__y", "z"), ("x", "y__z")]
    out = tmp_path / "out"
    res = hope_rs.match_many(shapes, pairs, out_dir=out, jobs=1, cache=False, **FAST)
    assert all(r.ok for r in res) and res[0].path != res[1].path
    assert len(maps_in(out)) == 2
    for r in res:
        np.testing.assert_array_equal(hope_rs.read_map(r.path, N, N), r.map)
    again = hope_rs.match_many(shapes, pairs, out_dir=out, jobs=1, cache=False, **FAST)
    for r, s in zip(res, again):
        assert s.skipped and s.path == r.path
        np.testing.assert_array_equal(s.map, r.map)
    # Dict keys 1 and "1" name two shapes: two files.
    keyed = {1: meshes[0], "1": meshes[1], "c": meshes[2]}
    res = hope_rs.match_many(keyed, [(1, "c"), ("1", "c")], out_dir=tmp_path / "k", jobs=1,
                             cache=False, **FAST)  # fmt: skip
    assert res[0].path != res[1].path and len(maps_in(tmp_path / "k")) == 2
    assert (res[0].map == hope_rs.match(meshes[0], meshes[2], **FAST).map).all()
    assert (res[1].map == hope_rs.match(meshes[1], meshes[2], **FAST).map).all()


def test_1c_one_file_spelled_two_ways_keeps_its_name_and_only_shared_stems_are_qualified(
    files, tmp_path
):
    other = tmp_path / "other"
    other.mkdir()
    shutil.copy(files / "s1.off", other / "s1.off")
    twice = files / ".." / files.name / "s1.off"  # the same file as files / "s1.off"
    shapes = [files / "s0.off", files / "s1.off", twice, files / "s2.off"]
    res = hope_rs.match_many(shapes, [(0, 1), (1, 3)], out_dir=tmp_path / "o", jobs=1,
                             cache=False, **FAST)  # fmt: skip
    assert [r.path.name for r in res] == ["s0__s1.txt", "s1__s2.txt"]
    # Two files with one stem: those two are named by their folder too, the others are not.
    res = hope_rs.match_many([*shapes, other / "s1.off"], [(0, 1), (0, 4), (0, 3)],
                             out_dir=tmp_path / "p", jobs=1, cache=False, **FAST)  # fmt: skip
    assert [r.path.name for r in res] == [
        f"s0__{files.name}_s1.txt",
        "s0__other_s1.txt",
        "s0__s2.txt",
    ]


def test_1b_pairs_of_a_dict_with_int_keys_name_its_keys_not_positions(meshes, tmp_path):
    keyed = {1: meshes[0], 0: meshes[1], 7: meshes[2]}
    (r,) = hope_rs.match_many(keyed, [(0, 1)], jobs=1, cache=False, **FAST)
    assert (r.a, r.b) == ("0", "1")
    np.testing.assert_array_equal(r.map, hope_rs.match(meshes[1], meshes[0], **FAST).map)
    for bad in [(0, 2), (True, 0), ([1], 0)]:
        with pytest.raises(ValueError, match="is not a key of the shapes dict"):
            hope_rs.match_many(keyed, [bad], jobs=1, cache=False)


@pytest.mark.parametrize("pairs", [[0, 1], ["s0"], [(0,)], [(0, 1, 2)]])
def test_1d_a_pair_that_is_not_two_entries_is_refused_in_one_line(files, pairs, configs):
    shapes = [files / "s0.off", files / "s1.off"]
    with pytest.raises(ValueError, match="each pair must be a tuple or list of two entries"):
        hope_rs.match_many(shapes, pairs, jobs=1, **FAST)
    assert configs == []


def test_2_map_files_stay_inside_out_dir(meshes, tmp_path):
    work = tmp_path / "work"
    work.mkdir()
    shapes = {"../escaped": meshes[0], "C": meshes[1], str(tmp_path / "abs" / "x"): meshes[2],
              "a/b": meshes[3]}  # fmt: skip
    out = work / "out"
    res = hope_rs.match_many(
        shapes, [(0, 1), (2, 1), (3, 1)], out_dir=out, jobs=1, cache=False, **FAST
    )
    assert all(r.ok for r in res), [r.error for r in res]
    assert sorted(p.name for p in work.iterdir()) == ["out"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["work"]
    for r in res:
        assert r.path.parent == out and r.path.is_file() and not r.path.name.startswith(".")
    assert len(maps_in(out)) == 3


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.text(min_size=0, max_size=300), st.text(max_size=300)), max_size=8))
def test_1_2_map_names_are_unique_plain_and_short_for_any_shape_names(pairs):
    """Any names: one file per distinct pair, no separator, no hidden or parent name, at most
    255 bytes; names listed twice are refused."""
    idents = [(f"key {a!r}", f"key {b!r}") for a, b in pairs]
    if len(set(idents)) < len(idents):
        with pytest.raises(ValueError, match="would both write the map file"):
            map_names(pairs, idents, "txt")
        return
    names = map_names(pairs, idents, "txt")
    assert len({n.casefold() for n in names}) == len(names)
    for n in names:
        assert "/" not in n and "\\" not in n and "\0" not in n and not n.startswith(".")
        assert len(n.encode("utf-8")) <= 255 and n.endswith(".txt")


def test_1_3_a_path_of_undecodable_bytes_is_named_like_any_other():
    # os.fsdecode keeps such bytes as lone surrogates, which UTF-8 cannot encode.
    path = os.fsdecode(b"/data/d\xff/x y.off")
    names = map_names([("x y", "b")], [(path, "/data/b.off")], "txt")
    assert names[0].startswith("x_y__b-") and names[0].endswith(".txt")


def test_3_a_hash_inside_a_pairs_file_path_is_part_of_the_path(tmp_path):
    (tmp_path / "p.txt").write_text("tmpl scan#2\n# a comment\ntmpl 'b #c'  # trailing\n")
    pairs = read_pairs(tmp_path / "p.txt", ext=".off")
    assert [(a.name, b.name) for a, b in pairs] == [
        ("tmpl.off", "scan#2.off"),
        ("tmpl.off", "b #c.off"),
    ]


def test_4_map_and_confidence_to_one_file_is_refused_before_any_work(files, tmp_path, capsys):
    same = tmp_path / "same.npy"
    args = ["match", str(files / "s0.off"), str(files / "s1.off"), "-q"]
    assert main(args + ["-o", str(same), "--confidence-out", str(same)]) == 2
    assert "name the same file" in capsys.readouterr().err
    assert not same.exists()


# -- 5-7: settings ----------------------------------------------------------------------------


def test_5_a_batch_runs_with_the_config_given(files, tmp_path, configs, capsys):
    shapes = [files / "s0.off", files / "s1.off"]
    cfg = MatchConfig(initial=InitialConfig(descriptor="wks")).with_options(k_max=6, **FAST)
    (r,) = hope_rs.match_many(shapes, [(0, 1)], jobs=1, cache=False, config=cfg)
    assert r.ok and configs[-1][0] == cfg
    # Keyword shortcuts go over the config, as in match.
    hope_rs.match_many(shapes, [(0, 1)], jobs=1, cache=False, config=cfg, k_max=5)
    assert configs[-1][0] == cfg.with_options(k_max=5)
    # The command line: --config FILE, its flags over it.
    (tmp_path / "s.toml").write_text(
        'k_max = 6\n[initial]\ndescriptor = "wks"\n[refine]\nmax_passes = 1\n'
        "[spectral]\nenabled = false\n[finish]\nenabled = false\n"
    )
    (tmp_path / "pairs.txt").write_text(f"{shapes[0]} {shapes[1]}\n")
    args = ["batch", str(tmp_path / "pairs.txt"), "--out", str(tmp_path / "o"), "-q", "-j", "1",
            "--no-cache", "--config", str(tmp_path / "s.toml")]  # fmt: skip
    assert main(args) == 0
    assert configs[-1][0] == cfg
    assert main(args + ["--k-max", "4"]) == 0
    assert configs[-1][0] == cfg.with_options(k_max=4)
    (tmp_path / "bad.toml").write_text("[refine]\nmax_pases = 2\n")
    assert main(args[:-1] + [str(tmp_path / "bad.toml")]) == 2
    assert "MatchConfig.refine has no setting 'max_pases'" in capsys.readouterr().err


def test_5_config_to_dict_and_from_dict_round_trip():
    cfg = MatchConfig().with_options(k_max=6, schedule=[4, 2, 1], spectral=False)
    back = MatchConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert back == cfg and back.key() == cfg.key()
    assert MatchConfig.from_dict({}) == MatchConfig()
    with pytest.raises(ValueError, match="has no setting 'nope'"):
        MatchConfig.from_dict({"nope": 1})


@pytest.mark.parametrize(
    ("data", "error"),
    [
        ({"k_max": 100}, r"MatchConfig.k_max must be an integer in \[2, 64\], got 100"),
        ({"initial": {"descriptor": "sift"}}, "MatchConfig.initial.descriptor must be one of"),
        ({"refine": {"max_passes": 0}}, "MatchConfig.refine.max_passes must be an integer >= 1"),
    ],
)
def test_5_a_config_is_checked_by_one_function_for_match_batch_and_cli(
    data, error, files, tmp_path, capsys
):
    """The constraints declared on the config's fields, checked before any work."""
    cfg = MatchConfig.from_dict(data)
    a, b = files / "s0.off", files / "s1.off"
    with pytest.raises(ValueError, match=error):
        hope_rs.match(hope_rs.load_mesh(a), hope_rs.load_mesh(b), config=cfg)
    with pytest.raises(ValueError, match=error):
        list(imatch_many([a, b], [(0, 1)], jobs=1, cache=False, config=cfg))
    lines = [f"{k} = {v}" for k, v in data.items() if not isinstance(v, dict)]
    for stage, table in ((k, v) for k, v in data.items() if isinstance(v, dict)):
        lines += [f"[{stage}]"] + [f"{k} = {json.dumps(v)}" for k, v in table.items()]
    (tmp_path / "s.toml").write_text("\n".join(lines) + "\n")
    assert main(["match", str(a), str(b), "-q", "--config", str(tmp_path / "s.toml")]) == 2
    assert error.replace("\\", "") in capsys.readouterr().err


def test_6_shapes_are_cached_and_kept_under_their_own_config(meshes, tmp_path, configs):
    wide = ShapeConfig(descriptors=DescriptorConfig(shot_radius=0.2))
    custom = {f"m{s}": hope_rs.Shape(meshes[s], config=wide) for s in range(2)}
    plain = {f"m{s}": meshes[s] for s in range(2)}
    default = hope_rs.Shape(meshes[0]).descriptors("shot")
    assert not np.allclose(custom["m0"].descriptors("shot"), default)
    cache = tmp_path / "c"
    for shapes in (custom, plain):
        (r,) = hope_rs.match_many(shapes, [(0, 1)], jobs=1, cache=cache, **FAST)
        assert r.ok
    # On disk: the default entry holds the default descriptors.
    np.testing.assert_array_equal(ShapeCache(cache).descriptors(meshes[0], "shot"), default)
    # In memory (no cache): the plain batch's shapes are not the custom ones.
    for shapes in (custom, plain):
        hope_rs.match_many(shapes, [(0, 1)], jobs=1, cache=False, **FAST)
        a = configs[-1][1]
        assert a.config == (wide if shapes is custom else ShapeConfig())
        want = custom["m0"] if shapes is custom else hope_rs.Shape(meshes[0])
        np.testing.assert_array_equal(a.descriptors("shot"), want.descriptors("shot"))


def editable_pair(files, tmp_path) -> tuple[list, object, dict]:
    """Copies of s0 and s1 that a test may edit, the output folder, and the batch options."""
    src = tmp_path / "m"
    shutil.copytree(files, src)
    out = tmp_path / "out"
    return (
        [src / "s0.off", src / "s1.off"],
        out,
        {"out_dir": out, "jobs": 1, "cache": tmp_path / "c"},
    )


def test_7_a_rerun_redoes_pairs_whose_settings_or_meshes_changed(files, tmp_path, monkeypatch):
    shapes, out, run = editable_pair(files, tmp_path)
    hope_rs.match_many(shapes, [(0, 1)], **run, **FAST)
    (same,) = hope_rs.match_many(shapes, [(0, 1)], **run, **FAST)
    assert same.skipped
    for change, why in [
        ({"spectral": True}, "the settings changed"),
        ({"k_max": 6}, "the settings changed"),
        ({"init": "wks"}, "the settings changed"),
    ]:
        with pytest.warns(RuntimeWarning, match=f"s0__s1.txt: {why}; computing it again"):
            (r,) = hope_rs.match_many(shapes, [(0, 1)], **run, **{**FAST, **change})
        assert r.ok and not r.skipped
    # Another build of hope_rs (the manifest's code version differs).
    with pytest.warns(RuntimeWarning, match="the settings changed"):  # back to FAST's
        hope_rs.match_many(shapes, [(0, 1)], **run, **FAST)
    monkeypatch.setattr(hope_rs.batch.driver, "code_fingerprint", lambda: "another-build")
    why = "it was computed by another version of hope_rs"
    with pytest.warns(RuntimeWarning, match=f"s0__s1.txt: {why}; computing it again"):
        (r,) = hope_rs.match_many(shapes, [(0, 1)], **run, **FAST)
    assert r.ok and not r.skipped
    monkeypatch.undo()
    with pytest.warns(RuntimeWarning, match=why):  # and back to this build
        hope_rs.match_many(shapes, [(0, 1)], **run, **FAST)
    # An edited mesh with the same vertex count.
    v, f = hope_rs.load_mesh(shapes[1]).vertices, hope_rs.load_mesh(shapes[1]).faces
    write_off(shapes[1], v * 1.01 + 0.002 * np.sin(7 * v), f)
    with pytest.warns(RuntimeWarning, match="mesh s1 changed; computing it again"):
        (r,) = hope_rs.match_many(shapes, [(0, 1)], **run, **FAST)
    assert r.ok and not r.skipped
    entry = Manifest(out).entries["s0__s1.txt"]
    assert set(entry) >= {"a_digest", "b_digest", "landmarks", "settings", "code", "map_digest"}


def test_7b_a_rerun_redoes_a_map_file_changed_after_the_batch_wrote_it(files, tmp_path):
    shapes, out = [files / "s0.off", files / "s1.off"], tmp_path / "out"
    run = {"out_dir": out, "jobs": 1, "cache": tmp_path / "c"}
    (first,) = hope_rs.match_many(shapes, [(0, 1)], **run, **FAST)
    path = out / "s0__s1.txt"
    # Well formed (right length, indices in range, whole last line), but not the batch's map.
    hope_rs.write_map(path, np.roll(first.map, 1))
    with pytest.warns(RuntimeWarning, match="s0__s1.txt: the map file is not the one the batch"):
        (r,) = hope_rs.match_many(shapes, [(0, 1)], **run, **FAST)
    assert r.ok and not r.skipped
    np.testing.assert_array_equal(hope_rs.read_map(path), first.map)
    (again,) = hope_rs.match_many(shapes, [(0, 1)], **run, **FAST)
    assert again.skipped


def test_7e_a_mesh_that_changed_its_vertex_count_is_named_as_changed(files, tmp_path):
    shapes, out, run = editable_pair(files, tmp_path)
    hope_rs.match_many(shapes, [(0, 1)], **run, **FAST)
    m = hope_rs.load_mesh(shapes[0])
    write_off(shapes[0], np.vstack([m.vertices, [[9.0, 9.0, 9.0]]]), m.faces)  # one vertex more
    with pytest.warns(RuntimeWarning, match="s0__s1.txt: mesh s0 changed; computing it again"):
        (r,) = hope_rs.match_many(shapes, [(0, 1)], **run, **FAST)
    assert r.ok and r.map.shape == (N + 1,)


def test_7c_a_redo_that_fails_leaves_no_outdated_map(files, tmp_path):
    shapes, out, run = editable_pair(files, tmp_path)
    (first,) = hope_rs.match_many(shapes, [(0, 1)], **run, **FAST)
    assert first.ok and (out / "s0__s1.txt").is_file()
    # B edited in place into a mesh that cannot be matched (no surface area).
    f = hope_rs.load_mesh(shapes[1]).faces
    write_off(shapes[1], np.zeros((N, 3)), f)
    with pytest.warns(RuntimeWarning, match="mesh s1 changed; computing it again"):
        (r,) = hope_rs.match_many(shapes, [(0, 1)], **run, **FAST)
    assert not r.ok and "area" in r.error
    assert not (out / "s0__s1.txt").exists()  # the map of the old B is gone
    assert "s0__s1.txt" not in Manifest(out).entries


def test_7d_a_map_file_that_is_an_input_is_refused_before_any_work(files, tmp_path, configs):
    shapes = [files / "s0.off", files / "s1.off"]
    # The pair's landmark file sits in the output folder under the map's own name.
    marks = tmp_path / "s0__s1.txt"
    marks.write_text("0 5\n10 20\n")
    with pytest.raises(ValueError, match=r"s0 -> s1 would be written over .*s0__s1\.txt'"):
        hope_rs.match_many(shapes, [(0, 1)], out_dir=tmp_path, landmarks=[marks], jobs=1, **FAST)
    assert marks.read_text() == "0 5\n10 20\n" and configs == []
    # A mesh in the output folder named as a map file is refused alike.
    mesh = tmp_path / "s0__b.txt"
    shutil.copy(files / "s1.off", mesh)
    mesh_off = tmp_path / "b.off"
    os.symlink(mesh, mesh_off)  # the batch names the mesh after the link: "b"
    with pytest.raises(ValueError, match="one of the inputs; choose another output folder"):
        hope_rs.match_many([files / "s0.off", mesh_off], [(0, 1)], out_dir=tmp_path, jobs=1, **FAST)
    assert configs == []


# -- 8-11: one failure stays local -------------------------------------------------------------


def test_8_a_map_that_cannot_be_written_fails_its_pair_only(files, tmp_path, capsys):
    (tmp_path / "pairs.txt").write_text("s0 s1\ns1 s2\ns2 s3\n")
    shutil.copy(files / "s0.off", tmp_path)
    for s in (1, 2, 3):
        shutil.copy(files / f"s{s}.off", tmp_path)
    out = tmp_path / "out"
    (out / "s1__s2.txt").mkdir(parents=True)  # a folder where the map goes
    args = ["batch", str(tmp_path / "pairs.txt"), "--ext", ".off", "--out", str(out), "-q",
            "-j", "1", "--no-cache", "--no-spectral", "--no-shared-faces"]  # fmt: skip
    for _ in range(2):  # the rerun too: the other pairs are skipped, this one fails again
        assert main(args) == 1
        cap = capsys.readouterr()
        assert f"cannot write the map '{out / 's1__s2.txt'}'" in cap.err
        assert "3 pairs: " in cap.out and ", 1 failed, 0 not run" in cap.out
        assert (out / "s0__s1.txt").is_file() and (out / "s2__s3.txt").is_file()


@pytest.mark.slow
def test_9_a_killed_worker_fails_its_task_only_and_the_pool_goes_on():
    pool = PoolBackend(2, 1)
    try:
        names = ["a", "die", "b", "c", "d", "e"]
        handles = {pool.submit(echo_or_die, x, 0.3): x for x in names}
        got = {}
        while len(got) < len(names):
            for h, value in pool.wait([h for h in handles if handles[h] not in got]):
                got[handles[h]] = value
    finally:
        pool.close()
    assert got["die"]["error"] == DIED
    assert {x: got[x] for x in names if x != "die"} == {x: {"x": x} for x in names if x != "die"}


class KillsOnePair:
    """A pool whose ``nth`` pair task kills its worker, each time it runs (first among the
    others, then alone): the others run in the pool restarted after it."""

    ships_data = False

    def __init__(self, nth: int):
        self.pool, self.nth, self.pairs = PoolBackend(2, 1), nth, 0

    @property
    def threads(self):
        return self.pool.threads

    def submit(self, fn, *args):
        if fn is hope_rs.batch.tasks.pair_task:
            self.pairs += 1
            if self.pairs == self.nth:
                return self.pool.submit(echo_or_die, "die", 0.0)
        return self.pool.submit(fn, *args)

    def wait(self, handles):
        return self.pool.wait(handles)

    def close(self, abort=False):
        self.pool.close(abort)


@pytest.mark.slow
def test_9_a_pair_whose_worker_dies_fails_alone_with_its_map_named(
    files, tmp_path, monkeypatch, capsys
):
    (tmp_path / "pairs.txt").write_text("s0 s1\ns1 s2\ns2 s3\ns0 s3\n")
    for s in range(4):
        shutil.copy(files / f"s{s}.off", tmp_path)
    monkeypatch.setattr(hope_rs.batch.driver, "make_backend", lambda *a: KillsOnePair(2))
    out = tmp_path / "out"
    args = ["batch", str(tmp_path / "pairs.txt"), "--ext", ".off", "--out", str(out), "-q",
            "--no-cache", "--no-spectral", "--no-shared-faces", "-j", "2"]  # fmt: skip
    assert main(args) == 1
    cap = capsys.readouterr()
    assert "4 pairs: 3 matched, 0 skipped, 1 failed, 0 not run" in cap.out
    (line,) = [x for x in cap.err.splitlines() if "pair failed" in x]
    assert DIED in line
    (dead,) = [n for n in map_names_of(tmp_path / "pairs.txt") if f"'{out / n}'" in line]
    assert sorted(p.name for p in out.glob("*.txt")) == sorted(
        n for n in map_names_of(tmp_path / "pairs.txt") if n != dead
    )


def map_names_of(pairs_file):
    return [f"{a}__{b}.txt" for a, b in (x.split() for x in pairs_file.read_text().splitlines())]


def test_10_an_unusable_cache_gives_way_to_a_temporary_one(files, tmp_path, monkeypatch):
    shapes = [files / "s0.off", files / "s1.off"]
    (tmp_path / "plain").write_text("not a folder")
    with pytest.warns(RuntimeWarning, match="using a temporary cache"):
        (r,) = hope_rs.match_many(shapes, [(0, 1)], jobs=1, cache=tmp_path / "plain", **FAST)
    assert r.ok
    # A full disk: the cache gives way; an output folder without room is refused up front.
    full = shutil.disk_usage(tmp_path)._replace(free=1000)
    real = shutil.disk_usage
    monkeypatch.setattr(
        hope_rs.geometry.map_io.shutil, "disk_usage",
        lambda p: full if str(p).startswith(str(tmp_path)) else real(p),
    )  # fmt: skip
    with pytest.warns(RuntimeWarning, match="MiB free.*using a temporary cache"):
        (r,) = hope_rs.match_many(shapes, [(0, 1)], jobs=1, cache=tmp_path / "c", **FAST)
    assert r.ok
    with pytest.raises(ValueError, match="MiB free"):
        list(imatch_many(shapes, [(0, 1)], jobs=1, cache=False, out_dir=tmp_path / "o"))


def test_11_outputs_onto_folders_are_refused_before_the_match(files, tmp_path, monkeypatch, capsys):
    def no_match(*args, **kwargs):
        raise AssertionError("the outputs should have been checked first")

    monkeypatch.setattr(hope_rs.cli.commands, "match", no_match)
    monkeypatch.setattr(hope_rs.evaluation.show, "load_mesh", no_match)
    (tmp_path / "conf.npy").mkdir()
    a, b = str(files / "s0.off"), str(files / "s1.off")
    args = ["match", a, b, "-q", "-o", str(tmp_path / "m.txt")]
    assert main(args + ["--confidence-out", str(tmp_path / "conf.npy")]) == 2
    assert "is a folder" in capsys.readouterr().err
    assert not (tmp_path / "m.txt").exists()
    (tmp_path / "m.txt").write_text("".join(f"{i}\n" for i in range(N)))
    (tmp_path / "view_A.ply").mkdir()
    assert main(["show", a, b, str(tmp_path / "m.txt"), "--ply", str(tmp_path / "view.ply")]) == 2
    assert "is a folder" in capsys.readouterr().err


# -- 12: confidence where there is nothing to match by -----------------------------------------


def test_12_a_vertex_in_no_face_has_confidence_zero(meshes):
    a = meshes[0]
    rng = np.random.default_rng(3)
    perm = rng.permutation(N)
    b = hope_rs.Mesh(a.vertices[perm], relabel(a.faces, perm))
    loose = hope_rs.Mesh(np.vstack([a.vertices, [[0.0, 0.0, 0.05]]]), a.faces)
    res = hope_rs.match(loose, b, **FAST)
    assert res.confidence[N] == 0.0 and res.map_or_unmatched(0.0)[N] == res.map[N]
    assert res.map_or_unmatched(0.5)[N] == -1
    assert np.median(res.confidence[:N]) > 0.5


# -- also found --------------------------------------------------------------------------------


def test_rayon_threads_above_the_cores_are_capped_with_a_warning():
    code = "import os, hope_rs; print(os.environ['RAYON_NUM_THREADS'])"
    env = {**os.environ, "RAYON_NUM_THREADS": "1000"}
    run = subprocess.run(
        [sys.executable, "-c", code], check=False, env=env, capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr
    assert int(run.stdout) == len(os.sched_getaffinity(0)) < 1000
    assert "RAYON_NUM_THREADS=1000 is more than the" in run.stderr


def test_7_the_manifest_journal_survives_a_cut_last_line_and_keeps_the_last_word(tmp_path):
    entry = {"a": "x", "b": "y", "a_digest": "1", "b_digest": "2", "landmarks": None,
             "settings": "s", "code": "c", "map_digest": "m"}  # fmt: skip
    m = Manifest(tmp_path)
    m.record("x__y.txt", entry)
    m.record("x__z.txt", entry)
    m.forget("x__z.txt")
    m.record("x__y.txt", {**entry, "settings": "t"})
    with open(tmp_path / MANIFEST, "ab") as fh:  # a batch killed in the middle of a line
        fh.write(b'{"map": "x__w.txt", "ent')
    again = Manifest(tmp_path)
    assert again.entries == {"x__y.txt": {**entry, "settings": "t"}}
    assert again.why_redo("x__y.txt", entry) == "the settings changed"
    assert again.why_redo("x__z.txt", entry) == "the manifest has no entry for it"
    again.record("x__v.txt", entry)  # starts on a line of its own
    assert set(Manifest(tmp_path).entries) == {"x__y.txt", "x__v.txt"}
    # An entry from before map digests: redone, saying why.
    again.record("x__u.txt", {k: v for k, v in entry.items() if k != "map_digest"})
    assert "written by an older hope_rs" in again.why_redo("x__u.txt", entry)
    (tmp_path / MANIFEST).write_text("not a manifest\n")
    with pytest.warns(RuntimeWarning, match="unreadable"):
        assert Manifest(tmp_path).entries == {}
    newer = '{"hope_rs_manifest": 2}\n{"map": "x__y.txt", "entry": {}}\n'
    (tmp_path / MANIFEST).write_text(newer)  # a newer version's: refused, not replaced
    with pytest.raises(ValueError, match=r"written by a newer hope_rs \(layout 2\)"):
        Manifest(tmp_path)
    assert (tmp_path / MANIFEST).read_text() == newer
    (tmp_path / MANIFEST).unlink()
    (tmp_path / MANIFEST).mkdir()  # refused in one line, with no warning first
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=r"the batch manifest .* is a folder; move it away"):
            Manifest(tmp_path)


def test_8b_a_folder_where_a_map_goes_fails_its_pair_before_matching_it(files, tmp_path, configs):
    out = tmp_path / "out"
    (out / "s0__s1.txt").mkdir(parents=True)
    res = hope_rs.match_many([files / "s0.off", files / "s1.off", files / "s2.off"],
                             [(0, 1), (1, 2)], out_dir=out, jobs=1, cache=False, **FAST)  # fmt: skip
    assert not res[0].ok and "a folder is there" in res[0].error and res[1].ok
    assert len(configs) == 1  # the other pair only


def test_13_a_pair_whose_map_likely_failed_is_marked_and_a_rerun_keeps_the_mark(
    files, tmp_path, capsys
):
    """Each PairResult carries the match's MatchQuality (a skipped pair's from the manifest),
    and the command line marks a pair that likely failed: a single triangle against a sphere
    is matched (its map written) but flagged, as `match` flags it."""
    tri = tmp_path / "tri.off"
    tri.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    shapes, out = [files / "s0.off", files / "s1.off", tri], tmp_path / "out"
    run = {"out_dir": out, "jobs": 1, "cache": False, **FAST}
    results = hope_rs.match_many(shapes, [(0, 1), (2, 0)], **run)
    for r, (i, j) in zip(results, [(0, 1), (2, 0)]):
        alone = hope_rs.match(hope_rs.load_mesh(shapes[i]), hope_rs.load_mesh(shapes[j]), **FAST)
        assert r.ok and r.quality == alone.quality
    assert results[1].quality.likely_failed
    again = hope_rs.match_many(shapes, [(0, 1), (2, 0)], **run)
    assert all(r.skipped for r in again)
    assert [r.quality for r in again] == [r.quality for r in results]
    # The command line: the pair's line, a warning with the figures, the count; status 0.
    (tmp_path / "pairs.txt").write_text(f"{tri} {shapes[0]}\n{shapes[0]} {shapes[1]}\n")
    args = ["batch", str(tmp_path / "pairs.txt"), "--out", str(tmp_path / "o"), "-j", "1",
            "--no-cache", "--no-spectral"]  # fmt: skip
    assert main(args) == 0
    captured = capsys.readouterr()
    assert "tri -> s0: ok, likely failed" in captured.err
    assert "(0 failed, 0 skipped, 1 likely failed)" in captured.err
    assert "hope-rs: warning: tri -> s0: likely failed (mean confidence 0.00" in captured.err
    assert ", 1 likely failed in " in captured.out


def test_13b_a_manifest_quality_of_another_form_is_read_as_unknown():
    good = {"mean_confidence": 0.4, "share_confident": 0.3, "likely_failed": True,
            "flipped_share": 0.1}  # fmt: skip
    assert _quality(good) == hope_rs.MatchQuality(0.4, 0.3, True, 0.1)
    for bad in (
        None,
        "x",
        {k: v for k, v in good.items() if k != "flipped_share"},  # an older form
        {**good, "extra": 1},
        {**good, "likely_failed": "no"},  # hand-edited
        {**good, "mean_confidence": None},
        {**good, "share_confident": True},
    ):
        assert _quality(bad) is None, bad

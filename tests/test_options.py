"""``match`` rejects bad options up front, with one line saying what is allowed."""

import inspect
import math

import numpy as np
import pytest
from meshes import bumpy_sphere, write_off

import hope_rs
import hope_rs.batch.driver
import hope_rs.batch.scheduler
import hope_rs.batch.tasks
from hope_rs import cli, matching
from hope_rs.batch.manifest import settings_key
from hope_rs.evaluation.demo import demo_pair
from hope_rs.features.descriptors import DescriptorConfig


@pytest.fixture(scope="module")
def pair():
    return demo_pair()


@pytest.fixture
def no_shapes(monkeypatch):
    """Fails the test if ``match`` starts building shapes (the expensive part)."""

    def forbidden(*args, **kwargs):
        raise AssertionError("match built a Shape before checking its options")

    monkeypatch.setattr(matching.Shape, "__init__", forbidden)


N = 6890  # vertices of each bundled mesh

BAD = [
    # (options, exception, message)
    ({"top_k": -1}, ValueError, r"top_k must be an integer in \[1, 2147483647\].*got -1"),
    ({"top_k": 0}, ValueError, r"top_k must be an integer in \[1, .*got 0"),
    ({"top_k": 2**40}, ValueError, r"top_k must be an integer in \[1, 2147483647\]"),
    ({"top_k": 4.0}, TypeError, r"top_k must be an integer .*got float"),
    ({"top_k": True}, TypeError, r"top_k must be an integer .*not a bool"),
    ({"polish_k": -1}, ValueError, r"polish_k must be None or an integer in \[1, 64\]"),
    ({"polish_k": 0}, ValueError, r"polish_k must be None or an integer in \[1, 64\]"),
    ({"polish_k": 65}, ValueError, r"polish_k must be None or an integer in \[1, 64\]"),
    ({"polish_k": False}, TypeError, r"polish_k .*not a bool"),
    ({"schedule": "8"}, TypeError, r"schedule must be a non-empty list .*got the string '8'"),
    ({"schedule": [8, 0]}, ValueError, r"hop radii in \[1, k_max=8\], got the entry 0"),
    ({"schedule": [9]}, ValueError, r"hop radii in \[1, k_max=8\], got the entry 9"),
    ({"schedule": [3, 2.5]}, TypeError, r"got the entry 2.5"),
    ({"schedule": [True]}, TypeError, r"got the entry True"),
    ({"schedule": []}, ValueError, r"schedule must be a non-empty list .*got an empty one"),
    ({"schedule": 8}, TypeError, r"schedule must be a non-empty list .*got int"),
    ({"schedule": [4], "k_max": 3}, ValueError, r"in \[1, k_max=3\], got the entry 4"),
    ({"max_passes": 0}, ValueError, r"max_passes must be an integer >= 1, got 0"),
    ({"max_passes": -2}, ValueError, r"max_passes must be an integer >= 1, got -2"),
    ({"max_passes": 2.0}, TypeError, r"max_passes must be an integer >= 1, got float"),
    ({"max_passes": True}, TypeError, r"max_passes .*not a bool"),
    ({"min_consistent": math.nan}, ValueError, r"min_consistent must be a number in \[0, 1\]"),
    ({"min_consistent": -0.1}, ValueError, r"min_consistent must be a number in \[0, 1\]"),
    ({"min_consistent": 1.5}, ValueError, r"min_consistent must be a number in \[0, 1\]"),
    ({"min_consistent": "0.5"}, TypeError, r"min_consistent must be a number in \[0, 1\]"),
    ({"min_consistent": True}, TypeError, r"min_consistent must be a number in \[0, 1\]"),
    ({"k_max": 0}, ValueError, r"k_max must be an integer in \[2, 64\].*got 0"),
    ({"k_max": 1}, ValueError, r"k_max must be an integer in \[2, 64\].*got 1"),
    ({"k_max": 99}, ValueError, r"k_max must be an integer in \[2, 64\].*got 99"),
    ({"k_max": True}, TypeError, r"k_max .*not a bool"),
    ({"k_max": 8.0}, TypeError, r"k_max must be an integer .*got float"),
    ({"init": "sift"}, ValueError, r"unknown descriptor 'sift'; choose 'shot', 'wks' or 'hks'"),
    ({"init": 3}, TypeError, r"init must be one of 'shot', 'wks', 'hks' or an \(n_a,\)"),
    ({"init": 3}, TypeError, r"init must be one of .*got int"),
    ({"init": np.arange(5)}, ValueError, rf"init must be a 1-D array of length {N}"),
    ({"init": np.zeros((N, 2), int)}, ValueError, rf"init must be a 1-D array of length {N}"),
    ({"init": np.full(N, N)}, ValueError, rf"init must hold values in \[0, {N}\)"),
    ({"init": np.full(N, -1)}, ValueError, rf"init must hold values in \[0, {N}\)"),
    ({"init": np.zeros(N)}, TypeError, r"init must be an integer array"),
    ({"callback": 3}, TypeError, r"callback must be None or callable .*got int"),
    ({"callback": "print"}, TypeError, r"callback must be None or callable .*got str"),
    ({"spectral": "no"}, TypeError, r"spectral must be True or False, got 'no'"),
    (
        {"multiscale": 1},
        TypeError,
        r"multiscale must be None \(chosen by size; .*\), True or False",
    ),
    ({"global_step": None}, TypeError, r"global_step must be True or False"),
    ({"shared_faces": [True]}, TypeError, r"shared_faces must be True or False"),
    ({"progress": "yes"}, TypeError, r"progress must be None, True, False or callable.*got str"),
    ({"progress": 1}, TypeError, r"progress must be None, True, False or callable.*got int"),
]


@pytest.mark.parametrize(("options", "exc", "message"), BAD)
def test_bad_option_is_rejected_before_any_work(pair, no_shapes, options, exc, message):
    with pytest.raises(exc, match=message) as info:
        hope_rs.match(*pair, **options)
    assert "\n" not in str(info.value)


def test_good_options_pass_the_checks(pair, no_shapes):
    """Values of every accepted kind get past the checks (to the first Shape)."""
    for options in [
        {},
        {"top_k": np.int64(5), "polish_k": None, "schedule": np.array([2, 1])},
        {"schedule": (8, 4, 1), "max_passes": 1, "min_consistent": 0, "k_max": 8},
        {"min_consistent": np.float32(1.0), "spectral": np.bool_(False), "callback": print},
        {"init": np.arange(N, dtype=np.int32), "k_max": 2, "polish_k": 2},
        # The default polish_k (3) runs at k_max = 2: a k_max the range allows is never refused.
        {"k_max": 2},
        {"polish_k": 9},
        {"progress": True},
        {"progress": False, "callback": None},
        {"progress": lambda event: None},
    ]:
        with pytest.raises(AssertionError, match="built a Shape"):
            hope_rs.match(*pair, **options)


def test_a_prebuilt_shape_with_a_smaller_k_max_is_rejected(pair):
    a = hope_rs.Shape(pair[0], k_max=3)
    with pytest.raises(ValueError, match="built with k_max=3 < requested k_max=8") as e:
        hope_rs.match(a, pair[1])
    # The message says both ways out.
    assert "Shape(..., k_max=8)" in str(e.value) and "match with k_max=3" in str(e.value)
    hope_rs.match(a, pair[1], k_max=3, max_passes=1)


def test_prebuilt_shapes_run_the_requested_smaller_k_max():
    # Shapes hold balls up to their own k_max; the match's k_max decides the radii it runs.
    a, b = hope_rs.Mesh(*bumpy_sphere(500, 1)), hope_rs.Mesh(*bumpy_sphere(450, 2))
    opts = {"k_max": 4, "max_passes": 1, "spectral": False}
    on_meshes = hope_rs.match(a, b, **opts)
    on_shapes = hope_rs.match(hope_rs.Shape(a), hope_rs.Shape(b), **opts)
    assert max(h.k for h in on_shapes.history) == 4
    np.testing.assert_array_equal(on_shapes.map, on_meshes.map)


def test_the_result_config_records_the_init_kind_given():
    a, b = hope_rs.Mesh(*bumpy_sphere(300, 1)), hope_rs.Mesh(*bumpy_sphere(300, 2))
    opts = {"max_passes": 1, "spectral": False}
    assert hope_rs.match(a, b, init="hks", **opts).config.initial.descriptor == "hks"
    assert hope_rs.match(a, b, **opts).config.initial.descriptor == "shot"


@pytest.mark.parametrize("k_max", ["0", "99", "-3"])
def test_cli_rejects_k_max_with_one_line(pair, tmp_path, capsys, k_max):
    write_off(tmp_path / "a.off", pair[0].vertices, pair[0].faces)
    write_off(tmp_path / "b.off", pair[1].vertices, pair[1].faces)
    out = tmp_path / "map.txt"
    argv = ["match", str(tmp_path / "a.off"), str(tmp_path / "b.off"), "-o", str(out)]
    assert cli.main([*argv, "--k-max", k_max, "-q"]) == 2
    err = capsys.readouterr().err
    assert (
        err
        == f"hope-rs: error: k_max must be an integer in [2, 64] (LMD reads 2-rings), got {k_max}\n"
    )
    assert not out.exists()


@pytest.mark.parametrize(
    ("options", "exc", "message"),
    [
        ({"max_passes": 0}, ValueError, "max_passes must be an integer >= 1"),
        ({"k_max": 1}, ValueError, "k_max must be an integer in"),
        ({"bogus": 1}, TypeError, "not an option of hope_rs.match_many: 'bogus'"),
        # A mistyped batch option: the message lists the batch's own options too.
        ({"jbos": 1}, TypeError, "'jbos'; its own options are out_dir, jobs, backend, cache"),
        ({"progress": 5}, TypeError, "progress must be None, True, False or callable"),
        # One line, not the array's repr.
        ({"init": np.arange(N)}, ValueError, "in a batch, got ndarray \\(a pair's own initial map"),
    ],
)
def test_a_batch_checks_match_options_before_any_work(
    pair, tmp_path, monkeypatch, options, exc, message
):
    def forbidden(*args, **kwargs):
        raise AssertionError("the batch prepared a shape before checking the match options")

    monkeypatch.setattr(hope_rs.batch.scheduler, "prepare_task", forbidden)
    with pytest.raises(exc, match=message) as info:
        hope_rs.match_many(list(pair), out_dir=tmp_path / "maps", jobs=1, cache=False, **options)
    assert "\n" not in str(info.value)
    assert not (tmp_path / "maps").exists()


def test_numpy_scalars_set_options_as_python_numbers_do(pair, no_shapes):
    # A batch names a pair's settings by MatchConfig.key() and each ShapeConfig's.
    plain = hope_rs.MatchConfig().with_options(top_k=32, spectral=True)
    numpy = hope_rs.MatchConfig().with_options(top_k=np.int64(32), spectral=np.True_)
    assert numpy == plain and numpy.key() == plain.key()
    shapes = [
        hope_rs.ShapeConfig(descriptors=DescriptorConfig(n_eigen=n)) for n in (100, np.int64(100))
    ]
    keys = [settings_key(plain.key(), s, s) for s in shapes]
    assert keys[0] == keys[1]
    # with_options stores what it is given; match refuses it as the option itself.
    for schedule, message in (([3.7, 2.2], "got the entry 3.7"), ("321", "got the string")):
        cfg = hope_rs.MatchConfig().with_options(schedule=schedule)
        with pytest.raises(TypeError, match=message):
            hope_rs.match(*pair, config=cfg)


def test_the_batch_options_listed_are_its_keyword_arguments():
    params = inspect.signature(hope_rs.batch.driver.imatch_many).parameters.values()
    own = {p.name for p in params if p.kind is inspect.Parameter.KEYWORD_ONLY}
    assert set(hope_rs.batch.driver.BATCH_OPTIONS) == own


def test_batch_cli_rejects_k_max_with_one_line(pair, tmp_path, capsys):
    write_off(tmp_path / "a.off", pair[0].vertices, pair[0].faces)
    write_off(tmp_path / "b.off", pair[1].vertices, pair[1].faces)
    (tmp_path / "pairs.txt").write_text("a.off b.off\n")
    out = tmp_path / "maps"
    assert cli.main(["batch", str(tmp_path / "pairs.txt"), "--out", str(out), "--k-max", "1"]) == 2
    err = capsys.readouterr().err
    assert err == "hope-rs: error: k_max must be an integer in [2, 64] (LMD reads 2-rings), got 1\n"
    assert not out.exists()


def test_imatch_many_checks_its_inputs_when_called(pair, tmp_path):
    # A generator function would check nothing until the first result is asked for.
    with pytest.raises(TypeError, match="not an option of hope_rs.match_many: 'bogus'"):
        hope_rs.batch.driver.imatch_many(list(pair), bogus=1)
    with pytest.raises(ValueError, match="k_max must be an integer"):
        hope_rs.batch.driver.imatch_many(list(pair), k_max=1)
    with pytest.raises(ValueError, match="output folder names no folder"):
        hope_rs.batch.driver.imatch_many(list(pair), out_dir="")

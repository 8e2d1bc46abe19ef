"""Settings as data: MatchConfig and the stage configs, the keyword options, the stage runner."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from meshes import bumpy_sphere, legless

import hope_rs
from hope_rs import MatchConfig
from hope_rs.batch.cache import basis_params, descriptor_params
from hope_rs.evaluation.demo import demo_pair
from hope_rs.features.descriptors import DescriptorConfig
from hope_rs.pipeline import overlap as overlap_module
from hope_rs.pipeline import shared_faces as finish_module
from hope_rs.pipeline.config import (
    KEYWORDS,
    ConfidenceConfig,
    FinishConfig,
    GrowthConfig,
    InitialConfig,
    LandmarkConfig,
    OrientConfig,
    PartialConfig,
    RefineConfig,
    RepairConfig,
    ResolutionConfig,
    SpectralConfig,
    check_config,
    read_config,
)
from hope_rs.pipeline.runner import run_match
from hope_rs.pipeline.stages import default_stages
from hope_rs.pipeline.state import Stage
from hope_rs.shape import ShapeConfig


@pytest.fixture(scope="module")
def bundled():
    return demo_pair()


def test_the_default_config_is_the_default_match(bundled):
    a, b = bundled
    plain = hope_rs.match(a, b)
    given = hope_rs.match(a, b, config=MatchConfig())
    np.testing.assert_array_equal(plain.map, given.map)
    assert plain.config == given.config == MatchConfig()


def test_configs_are_printable_comparable_and_hashable():
    cfg = MatchConfig()
    assert "top_k=48" in repr(cfg) and "RefineConfig(" in repr(cfg)
    other = cfg.with_options(top_k=32)
    assert other != cfg and other.refine.top_k == 32 and cfg.refine.top_k == 48
    assert len({MatchConfig(), MatchConfig(), other}) == 2
    assert MatchConfig().key() == cfg.key() != other.key()
    # Equal configs, equal keys: a whole number given as an int or a float.
    for a, b in [
        (MatchConfig(min_piece=0), MatchConfig(min_piece=0.0)),
        (cfg.with_options(min_consistent=1), cfg.with_options(min_consistent=1.0)),
    ]:
        assert a == b and a.key() == b.key()
    assert MatchConfig(min_piece=0.01).key() != MatchConfig().key()
    listed = MatchConfig(refine=RefineConfig(schedule=[3, 2, 1]))
    assert listed.refine.schedule == (3, 2, 1) and hash(listed) == hash(listed.with_options())
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.refine.top_k = 1  # type: ignore[misc]


def test_every_keyword_option_round_trips():
    values = {
        "k_max": 6, "schedule": [3, 2, 1], "max_passes": 2, "min_consistent": 0.4, "top_k": 7,
        "polish_k": None, "global_step": False, "multiscale": True, "spectral": False,
        "shared_faces": False, "confidence": False,
    }  # fmt: skip
    assert set(values) == set(KEYWORDS)
    cfg = MatchConfig().with_options(**values)
    got = cfg.options()
    assert got == {**values, "schedule": (3, 2, 1)}
    # A different key for every option changed alone.
    keys = {MatchConfig().with_options(**{k: v}).key() for k, v in values.items()}
    assert len(keys) == len(values) and MatchConfig().key() not in keys


def test_bad_config_and_unknown_options_are_rejected_before_any_work(bundled):
    a, b = bundled
    with pytest.raises(TypeError, match="config must be a hope_rs.MatchConfig"):
        hope_rs.match(a, b, config={"top_k": 3})
    with pytest.raises(TypeError, match="unexpected keyword argument 'topk'.*top_k"):
        hope_rs.match(a, b, topk=3)
    bad = MatchConfig(refine=RefineConfig(top_k=0))
    with pytest.raises(ValueError, match="top_k must be an integer in"):
        hope_rs.match(a, b, config=bad)


def test_with_options_refuses_a_bad_value_at_once():
    cfg = MatchConfig()
    with pytest.raises(ValueError, match=r"^MatchConfig\.refine\.top_k must be an integer in \[1,"):
        cfg.with_options(top_k=0)
    with pytest.raises(TypeError, match=r"^MatchConfig\.k_max must be an integer in \[2, 64\]"):
        cfg.with_options(k_max="8")
    with pytest.raises(TypeError, match=r"^MatchConfig\.spectral\.enabled must be True or False"):
        cfg.with_options(spectral="no")
    with pytest.raises(ValueError, match=r"^MatchConfig\.refine\.min_consistent must be a number"):
        cfg.with_options(top_k=32, min_consistent=1.5)
    assert cfg == MatchConfig() and cfg.with_options(top_k=1).refine.top_k == 1


@pytest.mark.slow
def test_the_polish_and_the_finish_use_the_configured_top_k(monkeypatch):
    """``top_k`` reaches every overlap cost: the polish's and the finish's HOPE steps too."""
    seen = {"polish": [], "finish": []}
    polish, step = overlap_module.best_overlap, finish_module.assign_by_overlap

    def spy_polish(*args, top_k, **kw):
        seen["polish"].append(top_k)
        return polish(*args, top_k=top_k, **kw)

    def spy_step(*args, config, **kw):
        seen["finish"].append(config.top_k)
        return step(*args, config=config, **kw)

    monkeypatch.setattr(overlap_module, "best_overlap", spy_polish)
    monkeypatch.setattr(finish_module, "assign_by_overlap", spy_step)
    # A = FAUST 012 without its legs, B = the whole 018: the finish runs on this pair.
    a, b = demo_pair()
    part, _ = legless(a)
    whole_path = MatchConfig(partial=PartialConfig(enabled=False))  # the stages run here
    res = hope_rs.match(part, b, top_k=20, config=whole_path)
    assert res.stage("faces").ran, "the finish must run for this test to see its steps"
    assert seen["polish"] == [20] and seen["finish"] and set(seen["finish"]) == {20}


def test_descriptor_and_basis_settings_key_the_cache():
    assert descriptor_params("shot") == descriptor_params("shot", DescriptorConfig())
    assert descriptor_params("shot") != descriptor_params("shot", DescriptorConfig(shot_radius=0.2))
    assert basis_params(120) != basis_params(100)
    cfg = ShapeConfig()
    changed = dataclasses.replace(cfg, basis=dataclasses.replace(cfg.basis, coarse_iterations=3))
    assert basis_params(120, cfg) != basis_params(120, changed)


def test_a_stage_is_added_by_a_list_entry(bundled):
    """The runner runs any Stage: a stage appended to the list sees the final map and can
    change it; its record joins the others."""
    a, b = bundled
    sa, sb = hope_rs.Shape(a), hope_rs.Shape(b)

    class Shift(Stage):
        name = "faces"  # reuses a known stage name for the record

        def run(self, state):
            state.f = np.roll(state.f, 1)
            state.log.ran(self.name, 0.0, "rolled")

    base = run_match(sa, sb, "shot", MatchConfig())
    rolled = run_match(sa, sb, "shot", MatchConfig(), stages=[*default_stages(), Shift()])
    internal = sa.map_in(sb, base.map)
    np.testing.assert_array_equal(rolled.map, sa.map_out(sb, np.roll(internal, 1)))
    assert rolled.stages[-1].reason == "rolled"


def test_spectral_settings_reach_the_pass(bundled):
    a, b = bundled
    cfg = MatchConfig(spectral=SpectralConfig(max_vertices=100))
    res = hope_rs.match(a, b, config=cfg, init=np.roll(np.arange(a.n_vertices), 5))
    assert not res.stage("spectral").ran


@pytest.mark.parametrize(
    "config, exc, message",
    [
        (
            MatchConfig(spectral=SpectralConfig(k_end=-1)),
            ValueError,
            r"spectral\.k_end must be an integer >= 1",
        ),
        (
            MatchConfig(spectral=SpectralConfig(margin=float("nan"))),
            ValueError,
            r"spectral\.margin must be a number >= 0",
        ),
        (
            # NaN on a field with a declared range: the message quotes the range.
            MatchConfig(resolution=ResolutionConfig(judge_rougher=float("nan"))),
            ValueError,
            r"resolution\.judge_rougher must be a number >= 1\.0, got nan",
        ),
        (MatchConfig(refine=RefineConfig(top_k=2.5)), TypeError, r"top_k must be an integer"),
        (
            MatchConfig(refine=RefineConfig(schedule="87")),
            TypeError,
            r"schedule must be a non-empty list .*got the string '87'",
        ),
        (
            MatchConfig(finish=FinishConfig(max_vertices="x")),
            TypeError,
            r"finish\.max_vertices must be None or an integer >= 0, got str 'x'",
        ),
        (
            MatchConfig(spectral=SpectralConfig(enabled=1)),
            TypeError,
            r"MatchConfig\.spectral\.enabled must be True or False",
        ),
        (
            MatchConfig(refine=RefineConfig(repair=RepairConfig(agree_rel=-0.1))),
            ValueError,
            r"refine\.repair\.agree_rel",
        ),
        (MatchConfig(spectral=RefineConfig()), TypeError, r"spectral must be a SpectralConfig"),
        (
            MatchConfig(landmarks=LandmarkConfig(zoomout_weight=float("inf"))),
            ValueError,
            r"landmarks\.zoomout_weight must be a finite number",
        ),
    ],
)
def test_a_bad_setting_in_a_config_is_refused_before_any_work(bundled, config, exc, message):
    a, b = bundled
    with pytest.raises(exc, match=message):
        hope_rs.match(a, b, config=config)


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"k_start": 50, "k_end": 40}, r"k_start \(50\) must be at most k_end \(40\)"),
        ({"max_samples": 119}, r"max_samples \(119\) must be at least k_end \(120\)"),
    ],
)
def test_spectral_settings_that_contradict_each_other(fields, message):
    with pytest.raises(ValueError, match=message):
        SpectralConfig(**fields)
    assert SpectralConfig(max_samples=120).max_samples == 120


def test_repetitions_and_lengths_out_of_reach_are_refused_when_made():
    with pytest.raises(
        ValueError, match=r"ConfidenceConfig\.rings must be an integer in \[0, 10000\]"
    ):
        ConfidenceConfig(rings=2**40)
    with pytest.raises(
        ValueError, match=r"OrientConfig\.seam_rings must be an integer in \[0, 10000\]"
    ):
        OrientConfig(seam_rings=2**40)
    a = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    for radius, message in ((0.0, "a number > 0.0"), (float("inf"), "a finite number")):
        shape = ShapeConfig(descriptors=DescriptorConfig(shot_radius=radius))
        with pytest.raises(ValueError, match=rf"shot_radius must be {message}"):
            hope_rs.match((a, f), (a, f), config=MatchConfig(shape=shape))
    repair = RepairConfig(search_dims=0)
    with pytest.raises(ValueError, match=r"repair\.search_dims must be an integer in \[1, 1024\]"):
        hope_rs.match((a, f), (a, f), config=MatchConfig(refine=RefineConfig(repair=repair)))


def test_a_shape_keeps_its_own_settings_and_the_result_says_so():
    v, f = bumpy_sphere(400, 3)
    wide = ShapeConfig(descriptors=DescriptorConfig(shot_radius=0.3))
    b = (v * [1.0, 1.1, 0.9], f)
    own = hope_rs.match(hope_rs.Shape((v, f), config=wide), b)
    # The mesh beside it is described alike, and res.config says which settings ran.
    assert own.config.shape == wide
    np.testing.assert_array_equal(
        own.map, hope_rs.match((v, f), b, config=MatchConfig(shape=wide)).map
    )
    with pytest.raises(ValueError, match="Shapes built with different ShapeConfigs"):
        hope_rs.match(hope_rs.Shape((v, f), config=wide), hope_rs.Shape(b))
    # A Shape's own settings are checked like the config's.
    endless = ShapeConfig(descriptors=DescriptorConfig(n_eigen=2**40))
    with pytest.raises(
        ValueError, match=r"Shape\.config\.descriptors\.n_eigen must be an integer in"
    ):
        hope_rs.match(hope_rs.Shape((v, f), config=endless), b)
    # WKS and HKS need a non-constant eigenpair: n_eigen=0 is refused before any work.
    none = MatchConfig(shape=ShapeConfig(descriptors=DescriptorConfig(n_eigen=0)))
    with pytest.raises(ValueError, match=r"n_eigen must be an integer in \[2, 5000\]"):
        hope_rs.match((v, f), b, config=none, init="wks")


def test_a_shape_refuses_settings_that_are_not_its_own():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    with pytest.raises(TypeError, match="config must be a hope_rs.shape.ShapeConfig, got dict"):
        hope_rs.Shape((v, f), config={"a": 1})


@pytest.mark.parametrize(
    "stage, name, value, allowed",
    [
        ("spectral", "k_step", 0, ">= 1"),
        ("spectral", "local_candidates", 0, ">= 1"),
        ("refine", "auction_floor_div", 0, ">= 1"),
        ("refine", "nearest_unused_k", 0, ">= 1"),
        ("refine", "polish_k", 0, r"in \[1, 64\]"),
        # Repetitions without a ceiling would run for hours before anything failed.
        ("spectral", "smoothing_steps", 2**40, r"in \[0, 10000\]"),
        ("refine", "stay_counts", 2**40, r"in \[0, 1000\]"),
        ("finish", "rounds", 2**40, r"in \[0, 1000\]"),
        ("finish", "step_k", 0, r"in \[1, 64\]"),
        ("partial", "merge_rings", 2**40, r"in \[0, 10000\]"),
        ("multiscale", "fine_passes", 2**40, r"in \[0, 100\]"),
    ],
)
def test_counts_that_cannot_run_are_refused_before_any_work(bundled, stage, name, value, allowed):
    a, b = bundled
    base = MatchConfig()
    config = dataclasses.replace(
        base, **{stage: dataclasses.replace(getattr(base, stage), **{name: value})}
    )
    with pytest.raises(ValueError, match=rf"{stage}\.{name} must be an integer {allowed}"):
        hope_rs.match(a, b, config=config)
    search = dataclasses.replace(base.initial.search, pca_dims=0)
    with pytest.raises(ValueError, match=r"initial\.search\.pca_dims must be an integer >= 1"):
        hope_rs.match(a, b, config=MatchConfig(initial=InitialConfig(search=search)))


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"faces_first": ("bogus",)}, r"faces_first must be a sequence of steps"),
        ({"affine_first": (0, 7)}, r"affine_first must be .*\('faces', 0, 1, 2\), got \(0, 7\)"),
        ({"agreement_order": "faces"}, r"agreement_order must be a sequence"),
        ({"faces_first": (True,)}, r"faces_first must be"),
        ({"affine_stages": ((0.3,),)}, r"affine_stages must be \(accept, ratio\) pairs"),
        ({"affine_stages": ((0.3, 2.0),), "faces_first": ("faces", 1)}, r"\('faces', 0\)"),
    ],
)
def test_growth_step_orders_are_checked_when_made(fields, message):
    # Checked when made, before any match's work (the finish reads them last).
    with pytest.raises(ValueError, match=message):
        GrowthConfig(**fields)
    assert GrowthConfig(faces_first=["faces", 2]).faces_first == ("faces", 2)


def test_a_settings_file_sets_a_setting_to_none_by_the_string_none(tmp_path):
    # TOML has no null: "none", in any case, stands for None where a setting may be None.
    f = tmp_path / "s.toml"
    f.write_text(
        '[refine]\npolish_k = "none"\npass_k_max = [8, "None"]\n[finish]\nmax_vertices = "NONE"\n'
    )
    cfg = read_config(f)
    assert cfg.refine.polish_k is None and cfg.refine.pass_k_max == (8, None)
    assert cfg.finish.max_vertices is None
    check_config(cfg)
    f.write_text('[refine]\nmax_passes = "none"\n')  # a setting that cannot be None
    with pytest.raises(TypeError, match="refine.max_passes must be an integer"):
        check_config(read_config(f))

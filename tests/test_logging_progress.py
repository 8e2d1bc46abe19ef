"""Logging, progress events, stage records and the CLI's -v flag."""

import io
import json
import logging
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from meshes import bumpy_sphere, write_off

import hope_rs
from hope_rs import MatchConfig
from hope_rs.cli import main
from hope_rs.evaluation.partial import cut_by_plane, plane_normal
from hope_rs.geometry.coarsen import CoarsenConfig
from hope_rs.pipeline.progress import STAGES, ProgressBar, ProgressEvent
from hope_rs.pipeline.refine import Iteration
from hope_rs.shape import ShapeConfig

DEFAULT_STAGES = [
    "shapes", "descriptors", "init", "refine", "polish", "spectral", "faces", "orient",
    "confidence",
]  # fmt: skip


@pytest.fixture(scope="module")
def spheres():
    return hope_rs.Mesh(*bumpy_sphere(400, 1)), hope_rs.Mesh(*bumpy_sphere(380, 2))


def test_a_default_match_logs_each_stage_once_in_order(spheres, caplog):
    caplog.set_level(logging.DEBUG, logger="hope_rs")
    res = hope_rs.match(*spheres, max_passes=2)
    # The orient stage's nested matches (this pair's map turns most of A over) log under its
    # prefix, as the coarse match of a multiscale one does.
    nested = [r for r in caplog.records if r.getMessage().startswith("orient ")]
    assert nested and all(r.name == "hope_rs" for r in nested)
    records = [r for r in caplog.records if r not in nested]
    info = [r.getMessage() for r in records if r.levelno == logging.INFO]
    assert [m.split(":")[0] for m in info] == DEFAULT_STAGES == [s.name for s in res.stages]
    assert all(r.name == "hope_rs" for r in records)
    # One DEBUG line per refinement step, the polish labelled as such.
    debug = [r.getMessage() for r in records if r.levelno == logging.DEBUG]
    assert len(debug) == len(res.history)
    assert debug[-1].startswith("polish: polish k=3") and "pass" not in debug[-1]
    assert debug[0].startswith("refine: pass 1/2 repair")
    # Each INFO line is the stage's record: seconds when it ran, the reason when skipped.
    for m, s in zip(info, res.stages):
        assert m == str(s)
        assert ("skipped" in m) != s.ran


def test_nothing_is_printed_without_logging_configured(tmp_path):
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]); from meshes import bumpy_sphere; "
        "import hope_rs; a = hope_rs.Mesh(*bumpy_sphere(300, 1)); "
        "b = hope_rs.Mesh(*bumpy_sphere(300, 2)); hope_rs.match(a, b, max_passes=1)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, str(Path(__file__).parent)],
        capture_output=True,
        text=True,
        check=True,
    )
    assert out.stdout == "" and out.stderr == ""
    assert any(isinstance(h, logging.NullHandler) for h in logging.getLogger("hope_rs").handlers)


def test_progress_events_cover_every_stage_in_order(spheres):
    events: list[ProgressEvent] = []
    its: list[Iteration] = []
    res = hope_rs.match(*spheres, max_passes=2, progress=events.append, callback=its.append)
    done = [e for e in events if e.done]
    assert [e.stage for e in done] == [s.name for s in res.stages] == DEFAULT_STAGES
    assert [e.ran for e in done] == [s.ran for s in res.stages]
    assert all(e.stage in STAGES for e in events)
    # Stages appear in one block each, in the order they ran.
    order = list(dict.fromkeys(e.stage for e in events))
    assert order == DEFAULT_STAGES
    elapsed = [e.elapsed for e in events]
    assert elapsed == sorted(elapsed)
    # Refinement steps carry the Iteration the callback received, in the same order.
    stepped = [e.iteration for e in events if e.iteration is not None]
    assert stepped == its == res.history
    assert all(isinstance(it, Iteration) for it in its)
    refine = [e for e in events if e.stage == "refine" and not e.done and e.iteration]
    assert [e.step for e in refine] == list(range(1, len(res.history)))
    assert all(e.total == 2 * 9 for e in refine)  # 2 passes of a repair and k = 8..1
    polish = [e for e in events if e.stage == "polish"]
    assert polish[0].iteration is res.history[-1] and res.history[-1].polish
    assert "polish" in polish[0].detail and "pass" not in polish[0].detail
    assert [it.polish for it in res.history] == [False] * (len(res.history) - 1) + [True]


def test_the_old_callback_alone_still_gets_iterations(spheres):
    seen = []
    res = hope_rs.match(*spheres, max_passes=1, callback=seen.append)
    assert seen == res.history and all(isinstance(it, Iteration) for it in seen)
    assert [it.n_pass for it in seen[:-1]] == [0] * (len(seen) - 1)


def test_a_non_terminal_gets_one_line_per_stage(spheres):
    out = io.StringIO()
    bar = ProgressBar(out)
    assert not bar.live  # a StringIO is no terminal
    res = hope_rs.match(*spheres, max_passes=1, progress=bar)
    lines = out.getvalue().splitlines()
    assert len(lines) == len(res.stages) and "\r" not in out.getvalue()
    for line, s in zip(lines, res.stages):
        assert line == f"hope_rs: {s}"


def test_a_terminal_gets_one_rewritten_line(spheres):
    out = io.StringIO()
    bar = ProgressBar(out, live=True)
    hope_rs.match(*spheres, max_passes=1, progress=bar)
    bar.close()
    text = out.getvalue()
    frames = text.split("\r")[1:]
    assert text.endswith("\n") and text.count("\n") == 1
    assert all(len(f.rstrip("\n")) == bar.width for f in frames)
    polish = [f for f in frames if f.startswith("hope_rs polish")]
    assert polish and all("pass" not in f for f in polish)
    assert any("refine      [" in f and "pass 1/1" in f for f in frames)
    assert any(f.startswith("hope_rs spectral") for f in frames)


@pytest.mark.parametrize("flag", [True, np.True_])
def test_progress_true_draws_on_stderr(spheres, capsys, flag):
    hope_rs.match(*spheres, max_passes=1, progress=flag)
    err = capsys.readouterr().err
    assert err.count("\n") == len(DEFAULT_STAGES) and "hope_rs: refine:" in err


@pytest.mark.parametrize("flag", [False, np.False_])
def test_progress_false_draws_nothing(spheres, capsys, flag):
    hope_rs.match(*spheres, max_passes=1, progress=flag)
    assert capsys.readouterr().err == ""


def test_hope_map_is_always_hopes_own_map(faust_pair):
    """The README example: the later stages are skipped, and hope_map is still HOPE's map."""
    res = hope_rs.match(*faust_pair)
    assert res.hope_map is not None
    np.testing.assert_array_equal(res.hope_map, res.map)
    for name in ("spectral", "faces"):
        s = res.stage(name)
        assert not s.ran and s.seconds == 0 and "HOPE's map" in s.reason
    assert res.stage("refine").ran and res.stage("refine").seconds > 0
    # A stage this path does not include reads as not run; a name that is no stage raises.
    coarse = res.stage("coarse")
    assert not coarse.ran and coarse.seconds == 0 and "not on this match's path" in coarse.reason
    assert "coarse" not in [s.name for s in res.stages]
    with pytest.raises(KeyError, match="no stage 'corse'; the stages are shapes, denoise, partial"):
        res.stage("corse")


def test_stage_reasons_for_turned_off_stages_and_a_given_map(spheres):
    a, b = spheres
    res = hope_rs.match(
        a, b, init=np.arange(380).tolist() + [0] * 20, max_passes=1, spectral=False,
        shared_faces=False, polish_k=None,
    )  # fmt: skip
    reasons = {s.name: s.reason for s in res.stages if not s.ran}
    # This guessed map turns little over, so only the confidence's rule sends it to the orient
    # stage, which says both.
    orient = res.stage("orient").reason.split(";")[0]
    assert "of A turned over, flagged likely failed (mean confidence" in orient
    assert reasons == {
        "descriptors": "an initial map was given (init=...)",
        "init": "an initial map was given (init=...)",
        "polish": "turned off (polish_k=None)",
        "spectral": "turned off (spectral=False)",
        "faces": "turned off (shared_faces=False)",
    }


def test_multiscale_that_does_not_apply_says_so(spheres, caplog):
    caplog.set_level(logging.INFO, logger="hope_rs")
    res = hope_rs.match(*spheres, max_passes=1, multiscale=True)
    s = res.stage("coarse")
    assert not s.ran and "A (400 vertices) is too sparse to halve" in s.reason
    assert [m for m in caplog.messages if m.startswith("coarse")] == [str(s)]
    assert res.coarse is None


@pytest.mark.slow
def test_multiscale_stages_and_the_coarse_progress(faust_pair, caplog):
    # FAUST coarsens to about 2.5k vertices with these cells.
    coarser = MatchConfig(shape=ShapeConfig(coarsen=CoarsenConfig(spacing=0.025)))
    caplog.set_level(logging.INFO, logger="hope_rs")
    events = []
    res = hope_rs.match(*faust_pair, multiscale=True, progress=events.append, config=coarser)
    names = [s.name for s in res.stages]
    assert names[:3] == ["shapes", "coarse", "lift"] and names[-4:] == DEFAULT_STAGES[-4:]
    assert res.stage("coarse").ran and res.stage("lift").ran
    assert not res.stage("init").ran and "multiscale" in res.stage("init").reason
    # The coarse match's stages show as steps of "coarse", and log with that prefix.
    inner = [e.detail.split()[0] for e in events if e.stage == "coarse" and not e.done]
    assert {"refine", "polish", "spectral"} <= set(inner)
    assert any(m.startswith("coarse refine:") for m in caplog.messages)
    assert [e.stage for e in events if e.done] == names


def test_cli_verbose_logs_stages_and_restores_the_logger(tmp_path, capsys):
    v, f = bumpy_sphere(300, 1)
    write_off(tmp_path / "a.off", v, f)
    v, f = bumpy_sphere(300, 2)
    write_off(tmp_path / "b.off", v, f)
    argv = ["match", str(tmp_path / "a.off"), str(tmp_path / "b.off"), "-o", str(tmp_path / "m")]
    logger = logging.getLogger("hope_rs")
    handlers, level = list(logger.handlers), logger.level
    assert main(["-v", *argv]) == 0
    # Two unrelated spheres: the match may also warn that it likely failed.
    err = [x for x in capsys.readouterr().err.splitlines() if "likely failed" not in x]
    # The orient stage's nested matches log under its prefix ("orient refine: ...").
    err = [x for x in err if not x.split(":")[1].strip().startswith("orient ")]
    assert [line.split(":")[1].strip() for line in err] == DEFAULT_STAGES
    assert all(line.startswith("hope-rs: ") for line in err)
    assert main([*argv, "-vv"]) == 0
    err = capsys.readouterr().err
    assert "hope-rs: refine: pass 1/4 repair" in err and "hope-rs: polish: polish k=3" in err
    assert logger.handlers == handlers and logger.level == level
    # The JSON summary lists the stages and marks the polish step.
    assert main([*argv, "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert [s["name"] for s in summary["stages"]] == DEFAULT_STAGES
    assert "map" not in summary  # written to -o
    # Without -o it holds the map, which standard output would otherwise have carried.
    assert main([*argv[:3], "--json", "-q"]) == 0
    alone = json.loads(capsys.readouterr().out)
    assert alone["map"] == np.loadtxt(tmp_path / "m", dtype=np.int64).tolist()
    assert [it["polish"] for it in summary["iterations"]][-2:] == [False, True]
    # --multiscale that does not apply: a one-line note without -v.
    assert main([*argv, "--multiscale"]) == 0
    err = capsys.readouterr().err.splitlines(keepends=True)
    assert "".join(x for x in err if "likely failed" not in x) == (
        "hope-rs: note: --multiscale: multiscale not applied: A (300 vertices) is too sparse "
        "to halve by vertex clustering (see hope_rs.geometry.coarsen.coarse_mesh)\n"
    )


def test_to_pyfm_is_p2p_21_with_mesh1_b(spheres):
    a, b = spheres
    res = hope_rs.match(a, b, max_passes=1)
    p2p_21 = res.to_pyfm()
    # pyFM's p2p_21 has one entry per vertex of mesh2 (= A here), a vertex of mesh1 (= B).
    assert p2p_21.shape == (a.n_vertices,) and p2p_21.max() < b.n_vertices
    np.testing.assert_array_equal(p2p_21, res.map)
    p2p_21[0] = -1
    assert res.map[0] != -1  # a copy


def test_a_part_s_trials_log_their_lines_under_their_labels(caplog):
    """Each scale trial of a part's match, and the whole -> part match's nested one, heads its
    log lines with its label, so four trials' stages can be told apart."""
    sphere = hope_rs.Mesh(*bumpy_sphere(400, 0))
    part = cut_by_plane(sphere, plane_normal(2), 0.3).mesh
    caplog.set_level(logging.INFO, logger="hope_rs")
    hope_rs.match(part, sphere, max_passes=1)
    refine = [m for m in caplog.messages if m.startswith("partial ") and " refine:" in m]
    heads = {m.split(" refine:")[0] for m in refine}
    assert {"partial x1", "partial x0.95", "partial x1.05", "partial merge"} <= heads, heads
    caplog.clear()
    hope_rs.match(sphere, part, max_passes=1)
    assert any(m.startswith("partial B -> A partial x1 refine:") for m in caplog.messages)

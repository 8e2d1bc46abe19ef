"""The runner's control flow: halts, background work alongside a stage, and trials."""

from __future__ import annotations

import numpy as np
import pytest

from hope_rs import MatchConfig
from hope_rs.pipeline.progress import StageLog
from hope_rs.pipeline.result import MatchResult
from hope_rs.pipeline.runner import run_stages
from hope_rs.pipeline.state import Background, Halt, MatchState, Stage
from hope_rs.pipeline.trials import Candidate, adopt, choose, current, run_trial, run_trials


def bare_state(run=None) -> MatchState:
    return MatchState(None, None, MatchConfig(), "shot", StageLog(), run=run)


class Recorded(Stage):
    """A stage that notes that it ran and returns ``outcome``."""

    def __init__(self, name, seen, outcome=None, *, on_final=False, final_after=None):
        self.name, self.seen, self.outcome = name, seen, outcome
        self.runs_on_final_map = on_final
        self.verdict = final_after

    def run(self, state):
        self.seen.append(self.name)
        if isinstance(self.outcome, Exception):
            raise self.outcome
        return self.outcome

    def final_after(self, state, name):
        return self.verdict if name == "refine" else None


class Work(Background):
    def __init__(self, seen):
        self.seen = seen

    def start(self):
        self.seen.append("start")

    def stop(self, keep):
        self.seen.append(f"stop keep={keep}")


class WithWork(Recorded):
    alongside = "refine"

    def background(self, state):
        return Work(self.seen)


def names(state):
    return [(s.name, s.ran, s.reason) for s in state.log.stages]


def test_a_halt_skips_the_later_stages_that_change_the_map():
    seen = []
    stages = [
        Recorded("init", seen),
        Recorded("refine", seen, Halt("settled")),
        Recorded("spectral", seen),
        Recorded("confidence", seen, on_final=True),
    ]
    state = run_stages(bare_state(), stages)
    assert seen == ["init", "refine", "confidence"]
    assert names(state) == [("spectral", False, "settled")]  # the others record themselves


def test_a_later_stage_can_find_the_map_final_after_an_earlier_one():
    seen = []
    stages = [
        Recorded("refine", seen),
        Recorded("spectral", seen),
        Recorded("faces", seen, final_after="one to one"),
        Recorded("confidence", seen, on_final=True),
    ]
    state = run_stages(bare_state(), stages)
    assert seen == ["refine", "confidence"]
    assert names(state) == [("spectral", False, "one to one"), ("faces", False, "one to one")]


@pytest.mark.parametrize(
    "outcome, keep",
    [(None, True), (Halt("settled"), False), (RuntimeError("boom"), False)],
)
def test_background_work_runs_alongside_its_stage_and_ends_with_it(outcome, keep):
    seen = []
    stages = [Recorded("refine", seen, outcome), WithWork("spectral", seen)]
    if isinstance(outcome, Exception):
        with pytest.raises(RuntimeError, match="boom"):
            run_stages(bare_state(), stages)
    else:
        run_stages(bare_state(), stages)
    ran_spectral = ["spectral"] if keep else []
    assert seen == ["start", "refine", f"stop keep={keep}", *ran_spectral]


def fake_run(scores: dict):
    """A runner whose match of a candidate labelled by its ``init`` has the map [score]."""

    def run(a, b, init, config, *, landmarks=None, **kw):
        m = np.array([scores[init]], dtype=np.int64)
        return MatchResult(map=m, init_map=m, hope_map=m, timings={"refine": 1.0, "total": 2.0})

    return run


def cands(*labels):
    return [Candidate(x, _Same(), _Same(), x, MatchConfig()) for x in labels]


class _Same:
    """A shape stand-in whose numbering is the identity."""

    def map_in(self, other, m):
        return np.asarray(m)

    def map_out(self, other, m):
        return np.asarray(m)


def score(t):
    return float(t.result.map[0])


def test_run_trials_keeps_the_first_best_and_records_every_trial():
    state = bare_state(fake_run({"x0.9": 3, "x1": 5, "x1.1": 5}))
    out = run_trials(state, "partial", cands("x0.9", "x1", "x1.1"), score)
    assert out.kept.candidate.label == "x1"  # a tie keeps the first
    assert [t.score for t in out.tried] == [3.0, 5.0, 5.0]
    records = state.log.trials["partial"]
    assert [(r.label, r.score, r.kept) for r in records] == [
        ("x0.9", 3.0, False),
        ("x1", 5.0, True),
        ("x1.1", 5.0, False),
    ]
    state.log.ran("partial", 1.0, "A is a part")
    assert state.log.stages[-1].trials == records


def test_a_later_round_must_beat_the_kept_trial():
    state = bare_state(fake_run({"guess": 5, "merge": 5, "wide": 6, "wider": 7}))
    first = run_trial(state, "partial", cands("guess")[0])
    assert first.score is None and state.log.trials["partial"][0].kept
    # Strictly higher, without a margin: a tie keeps the earlier trial.
    assert run_trials(state, "partial", cands("merge"), score, against=first).kept is first
    # With a margin, at least that much higher.
    assert run_trials(state, "partial", cands("wide"), score, against=first, margin=2).kept is first
    kept = run_trials(state, "partial", cands("wider"), score, against=first, margin=2).kept
    assert kept.candidate.label == "wider"
    assert [r.label for r in state.log.trials["partial"] if r.kept] == ["wider"]
    with pytest.raises(ValueError, match="at least one candidate"):
        run_trials(state, "partial", [], score)


def test_adopt_makes_the_kept_match_the_state_s():
    state = bare_state(fake_run({"x1": 4}))
    state.timings["partial"] = 0.5
    adopt(state, run_trial(state, "partial", cands("x1")[0]))
    assert state.f.tolist() == state.f0.tolist() == state.hope_map.tolist() == [4]
    assert state.timings == {"partial": 0.5, "refine": 1.0}


def test_the_state_s_own_map_is_kept_unless_a_round_s_best_beats_it_by_the_margin():
    state = bare_state(fake_run({"mirror": 6, "reverse": 8, "again": 9}))
    state.a = state.b = _Same()
    state.f = state.f0 = state.hope_map = np.array([5])
    own = current(state, "orient", "kept")
    own.score = own.record.score = score(own)
    first = run_trials(state, "orient", cands("mirror"), score).tried
    # Trials of several rounds compared at once; the own map stays unless beaten by 2.
    assert choose(state, "orient", first, against=own, margin=2) is own
    later = first + run_trials(state, "orient", cands("reverse", "again"), score).tried
    kept = choose(state, "orient", later, against=own, margin=2)
    assert kept.candidate.label == "again"
    records = state.log.trials["orient"]
    assert [(r.label, r.kept) for r in records] == [
        ("kept", False),
        ("mirror", False),
        ("reverse", False),
        ("again", True),
    ]
    assert choose(state, "orient", [], against=own) is own and records[0].kept
    with pytest.raises(ValueError, match="at least one trial"):
        choose(state, "orient", [])


def test_adopt_maps_only_keeps_the_start_history_and_timings():
    state = bare_state(fake_run({"x1": 4}))
    state.f0, state.history, state.timings = np.array([1]), ["outer"], {"refine": 3.0}
    adopt(state, run_trial(state, "orient", cands("x1")[0]), maps_only=True)
    assert state.f.tolist() == state.hope_map.tolist() == [4]
    assert state.f0.tolist() == [1] and state.history == ["outer"]
    assert state.timings == {"refine": 3.0}

"""The runner's control flow: halts, background work alongside a stage, and trials."""

from __future__ import annotations

import pytest

from hope_rs import MatchConfig
from hope_rs.pipeline.progress import StageLog
from hope_rs.pipeline.runner import run_stages
from hope_rs.pipeline.state import Background, Halt, MatchState, Stage


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

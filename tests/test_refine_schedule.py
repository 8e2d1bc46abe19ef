"""The hop radii of each refinement pass: the schedule's, up to the pass's entry of
``RefineConfig.pass_k_max``."""

import numpy as np
import pytest
from meshes import bumpy_sphere

import hope_rs
from hope_rs.pipeline.config import RefineConfig
from hope_rs.pipeline.refine import pass_schedule, refine

FULL = [8, 7, 6, 5, 4, 3, 2, 1]


def test_pass_schedule_caps_each_pass_and_repeats_the_last_cap():
    assert all(pass_schedule(FULL, RefineConfig(), n) == FULL for n in range(6))
    cfg = RefineConfig(pass_k_max=(None, 7, 4))
    got = [pass_schedule(FULL, cfg, n) for n in range(5)]
    assert got == [FULL, FULL[1:], *[[4, 3, 2, 1]] * 3]
    # The schedule's order is kept, and a schedule with no radius that small keeps its smallest.
    assert pass_schedule([2, 6, 1, 5], cfg, 3) == [2, 1]
    assert pass_schedule([8, 6], cfg, 2) == [6]
    assert RefineConfig(pass_k_max=[None, 3]).pass_k_max == (None, 3)


def test_each_pass_runs_only_its_radii():
    s = hope_rs.Shape(hope_rs.Mesh(*bumpy_sphere(800, 3)))
    rng = np.random.default_rng(0)
    wrong = np.arange(s.n_vertices)
    moved = rng.choice(s.n_vertices, s.n_vertices // 2, replace=False)
    wrong[moved] = rng.permutation(moved)
    # No stopping rule ends the passes early: every pass runs.
    cfg = RefineConfig(
        max_passes=3, converged_fraction=0.0, min_untrusted_drop=0.0, pass_k_max=(None, 3, 2)
    )
    res = refine(s, s, wrong, cfg)
    radii = {
        n: [it.k for it in res.history if it.n_pass == n and it.k > 0 and not it.polish]
        for n in range(3)
    }
    assert radii == {0: list(range(s.k_max, 0, -1)), 1: [3, 2, 1], 2: [2, 1]}


@pytest.mark.parametrize("caps", [(), (0,), (4, 2.5), (True,), "8", 4])
def test_pass_k_max_is_checked(caps):
    with pytest.raises(ValueError, match="pass_k_max must be None or a non-empty sequence"):
        RefineConfig(pass_k_max=caps)


def test_the_progress_counts_each_pass_s_steps():
    s = hope_rs.Shape(hope_rs.Mesh(*bumpy_sphere(400, 2)))
    events = []
    cfg = hope_rs.MatchConfig(refine=RefineConfig(max_passes=5, pass_k_max=(None, 3, 1)))
    hope_rs.match(s, s, config=cfg, spectral=False, progress=events.append)
    totals = {e.total for e in events if e.stage == "refine" and e.total}
    # Every pass has its repair step; passes 3 to 5 run k = 1 only.
    assert totals == {(s.k_max + 1) + (3 + 1) + 3 * (1 + 1)}

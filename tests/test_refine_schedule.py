"""The hop radii of each refinement pass: the whole schedule, and from ``late_pass`` on only
the radii up to ``late_k_max``."""

import numpy as np
import pytest
from meshes import bumpy_sphere

import hope_rs
from hope_rs.pipeline.config import RefineConfig
from hope_rs.pipeline.refine import pass_schedule, refine


def test_pass_schedule_cuts_the_late_passes_only():
    full = [8, 7, 6, 5, 4, 3, 2, 1]
    assert all(pass_schedule(full, RefineConfig(), n) == full for n in range(6))
    cfg = RefineConfig(late_pass=2, late_k_max=4)
    assert [pass_schedule(full, cfg, n) for n in range(4)] == [full, full, *[[4, 3, 2, 1]] * 2]
    # The schedule's order is kept, and a schedule with no radius that small keeps its smallest.
    assert pass_schedule([2, 6, 1, 5], cfg, 3) == [2, 1]
    assert pass_schedule([8, 6], cfg, 2) == [6]


def test_late_passes_run_only_their_radii():
    s = hope_rs.Shape(hope_rs.Mesh(*bumpy_sphere(800, 3)))
    rng = np.random.default_rng(0)
    wrong = np.arange(s.n_vertices)
    moved = rng.choice(s.n_vertices, s.n_vertices // 2, replace=False)
    wrong[moved] = rng.permutation(moved)
    # No stopping rule ends the passes early: every pass runs.
    cfg = RefineConfig(
        max_passes=3, converged_fraction=0.0, min_untrusted_drop=0.0, late_pass=1, late_k_max=2
    )
    res = refine(s, s, wrong, cfg)
    radii = {
        n: [it.k for it in res.history if it.n_pass == n and it.k > 0 and not it.polish]
        for n in range(3)
    }
    assert radii == {0: list(range(s.k_max, 0, -1)), 1: [2, 1], 2: [2, 1]}


@pytest.mark.parametrize(
    ("setting", "message"),
    [
        ({"late_k_max": 0}, "late_k_max must be None or a hop radius >= 1, got 0"),
        ({"late_k_max": 2.5}, "late_k_max must be None or a hop radius >= 1, got 2.5"),
        ({"late_pass": -1}, "late_pass must be a pass index >= 0, got -1"),
        ({"late_pass": True}, "late_pass must be a pass index >= 0, got True"),
    ],
)
def test_the_late_settings_are_checked(setting, message):
    with pytest.raises(ValueError, match=message):
        RefineConfig(**setting)

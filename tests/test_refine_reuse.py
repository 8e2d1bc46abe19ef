"""A k-hop step whose inputs are those of the last step at the same k takes its result: the
refinement's maps and history are the same as when every step solves."""

import dataclasses

import numpy as np
import pytest
from conftest import data_path

import hope_rs
from hope_rs.pipeline import refine as refine_module
from hope_rs.pipeline import refine_steps


class _Forgetful(dict):
    """A ``RefineState.seen`` that stores nothing, so every step solves."""

    def __setitem__(self, key, value):
        pass


def _steps(res):
    """The history without the timings and the reuse flag."""
    drop = {"seconds", "cost_seconds", "assign_seconds", "reused"}
    return [
        {k: v for k, v in dataclasses.asdict(it).items() if k not in drop} for it in res.history
    ]


@pytest.mark.slow
def test_reused_steps_give_the_maps_of_solving(monkeypatch):
    # wolf0 -> wolf1: the first pass ends in a map its steps at k <= 5 leave unchanged, and the
    # second pass brings it back to them.
    a = hope_rs.load_mesh(data_path("tosca_r", "wolf0.off"))
    b = hope_rs.load_mesh(data_path("tosca_r", "wolf1.off"))
    reusing = hope_rs.match(a, b, spectral=False)
    reused = [it for it in reusing.history if it.reused]
    assert reused, "the pair must have steps that meet the inputs of an earlier one"
    assert all(it.k > 0 and not it.polish and it.assign_seconds == 0.0 for it in reused)

    start = refine_steps.start_state

    def forgetful_start(*args, **kwargs):
        st = start(*args, **kwargs)
        st.seen = _Forgetful()
        return st

    # refine.py imported the name: patch it there.
    monkeypatch.setattr(refine_module, "start_state", forgetful_start)
    solving = hope_rs.match(a, b, spectral=False)
    assert not any(it.reused for it in solving.history)
    np.testing.assert_array_equal(solving.map, reusing.map)
    np.testing.assert_array_equal(solving.hope_map, reusing.hope_map)
    assert _steps(solving) == _steps(reusing)

"""The bundled demo pairs and ``hope-rs demo``."""

import json
from importlib import resources

import numpy as np
import pytest
from conftest import data_path

import hope_rs
from hope_rs.cli import main
from hope_rs.evaluation.demo import DEMO_PAIRS, demo_pair, demo_truth, run_demo


def test_bundled_pairs_are_small_float32_files_inside_the_package():
    for name, (file, _) in DEMO_PAIRS.items():
        path = resources.files("hope_rs").joinpath("data", file)
        assert path.is_file() and 100_000 < len(path.read_bytes()) < 400_000
        with path.open("rb") as fh, np.load(fh) as z:
            assert z["a_vertices"].dtype == z["b_vertices"].dtype == np.float32
            assert z["faces"].dtype == z["b_faces"].dtype == np.int32
        a, b = demo_pair(name)
        assert a.vertices.dtype == np.float64
        ai, bi = demo_truth(name)
        assert ai.shape == bi.shape and ai.max() < a.n_vertices and bi.max() < b.n_vertices
    with pytest.raises(ValueError, match="no bundled pair 'x'; choose from faust_012_018"):
        demo_pair("x")


def test_the_remeshed_pair_is_faust_r_000_001_with_its_landmarks():
    d = data_path("faust_r")
    a, b = demo_pair("faust_r_000_001")
    orig_a, orig_b = (
        hope_rs.load_mesh(d / "tr_reg_000.off"),
        hope_rs.load_mesh(d / "tr_reg_001.off"),
    )
    np.testing.assert_array_equal(a.faces, orig_a.faces)
    np.testing.assert_array_equal(b.faces, orig_b.faces)
    np.testing.assert_allclose(a.vertices, orig_a.vertices, rtol=0, atol=1e-6)
    ai, bi = demo_truth("faust_r_000_001")
    np.testing.assert_array_equal(ai, hope_rs.load_vts(d / "corres" / "tr_reg_000.vts"))
    np.testing.assert_array_equal(bi, hope_rs.load_vts(d / "corres" / "tr_reg_001.vts"))


@pytest.mark.slow
def test_demo_reports_both_pairs(capsys):
    report = run_demo(verbose=True)
    text = capsys.readouterr().out
    same, remeshed = report["pairs"]
    assert same["same_triangulation"] and not remeshed["same_triangulation"]
    assert same["final"]["exact"] >= 0.95 and same["hope"]["exact"] >= 0.95
    assert remeshed["final"]["mean"] < remeshed["hope"]["mean"] < remeshed["initial_map"]["mean"]
    assert remeshed["final"]["mean"] < 0.02
    ran = [s["name"] for s in remeshed["stages"] if s["ran"]]
    assert ran[-3:] == ["polish", "spectral", "confidence"]
    # % exact is printed for the shared triangulation only, and the remeshed one says why.
    assert text.count("% exact,") == 3 and "the triangulations differ" in text
    assert f"{remeshed['final']['mean']:.4f}" in text
    assert "(4999 -> 5000 vertices, 5000 scored)" in text


@pytest.mark.slow
def test_demo_json(capsys):
    assert main(["demo", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert [p["pair"] for p in report["pairs"]] == list(DEMO_PAIRS)
    for p in report["pairs"]:
        assert {"initial_map", "hope", "final", "seconds", "stages"} <= set(p)

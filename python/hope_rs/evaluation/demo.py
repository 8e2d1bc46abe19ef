"""The bundled demo: two FAUST pairs with ground truth, matched and scored at run time.

* ``faust_012_018``: FAUST registrations tr_reg_012 → tr_reg_018 (6890 vertices each), one
  triangulation in two poses; vertex i of one corresponds to vertex i of the other (identity
  ground truth), so an exact map exists.
* ``faust_r_000_001``: FAUST tr_reg_000 → tr_reg_001 remeshed independently (4999 and 5000
  vertices, Ren et al. 2018), scored on the 5000 landmark pairs of its ``.vts`` files.

Bogo et al., "FAUST: Dataset and evaluation for 3D mesh registration", CVPR 2014. Vertices are
stored as float32, faces and landmarks as int32, in compressed ``.npz`` files of the package.
"""

from __future__ import annotations

import dataclasses
import time
from importlib import resources

import numpy as np

from ..geometry.mesh import Mesh
from ..matching import match
from .evaluate import geodesic_errors, score

__all__ = ["DEMO_PAIRS", "demo_pair", "demo_truth", "run_demo"]

#: Bundled pairs: name → (file in ``hope_rs/data``, description).
DEMO_PAIRS = {
    "faust_012_018": (
        "faust_012_018.npz",
        "FAUST tr_reg_012 -> tr_reg_018, same triangulation",
    ),
    "faust_r_000_001": (
        "faust_r_000_001.npz",
        "FAUST tr_reg_000 -> tr_reg_001, remeshed independently",
    ),
}
#: Why the remeshed pair is not matched exactly, for the demo's printout.
REMESHED_NOTE = (
    "the triangulations differ, so most landmarks of A have no vertex of B at exactly "
    "their spot; read the mean error"
)


def _load(name: str) -> dict:
    if name not in DEMO_PAIRS:
        raise ValueError(f"no bundled pair {name!r}; choose from {', '.join(DEMO_PAIRS)}")
    path = resources.files("hope_rs").joinpath("data").joinpath(DEMO_PAIRS[name][0])
    with path.open("rb") as fh, np.load(fh) as z:
        return {k: z[k] for k in z.files}


def demo_pair(name: str = "faust_012_018") -> tuple[Mesh, Mesh]:
    """The two meshes of a bundled pair (see :data:`DEMO_PAIRS`).

    Parameters
    ----------
    name : str
        "faust_012_018" (identity ground truth) or "faust_r_000_001" (remeshed; landmarks
        from :func:`demo_truth`).
    """
    z = _load(name)
    a = Mesh(z["a_vertices"].astype(np.float64), z["faces"])
    b = Mesh(z["b_vertices"].astype(np.float64), z["b_faces"])
    return a, b


def demo_truth(name: str = "faust_012_018") -> tuple[np.ndarray, np.ndarray]:
    """The ground truth of a bundled pair as ``(a_idx, b_idx)``: vertex ``a_idx[i]`` of A
    corresponds to vertex ``b_idx[i]`` of B (0-based; the identity for "faust_012_018")."""
    z = _load(name)
    if "a_idx" in z:
        return z["a_idx"].astype(np.int64), z["b_idx"].astype(np.int64)
    n = z["a_vertices"].shape[0]
    return np.arange(n), np.arange(n)


def score_pair(name: str) -> dict:
    """Match a bundled pair and score the initial map, HOPE's own map and the final map
    against its ground truth (edge-graph geodesic error / sqrt(area of B))."""

    a, b = demo_pair(name)
    ai, bi = demo_truth(name)
    t0 = time.perf_counter()
    res = match(a, b)
    seconds = time.perf_counter() - t0
    init, hope, final = (
        score(geodesic_errors(b, m, a_idx=ai, b_idx=bi))
        for m in (res.init_map, res.hope_map, res.map)
    )
    return {
        "pair": name,
        "description": DEMO_PAIRS[name][1],
        "n_a": a.n_vertices,
        "n_b": b.n_vertices,
        "n_scored": int(ai.size),
        "same_triangulation": "a_idx" not in _load(name),
        "initial_map": vars(init),
        "hope": vars(hope),
        "final": vars(final),
        "seconds": seconds,
        "timings": res.timings,
        "stages": [dataclasses.asdict(s) for s in res.stages],
    }


def run_demo(*, verbose: bool = True) -> dict:
    """Match both bundled pairs, score them against their ground truth and return a report
    (``{"pairs": [per-pair report, ...]}``); with ``verbose``, print it."""
    report = {"pairs": [score_pair(name) for name in DEMO_PAIRS]}
    if verbose:
        print("errors: geodesic distance on B / sqrt(area of B); 0 is an exact match")
        for r in report["pairs"]:
            _print_pair(r)
    return report


def _print_pair(r: dict) -> None:
    exact = r["same_triangulation"]

    def line(label: str, s: dict) -> str:
        share = f"{100 * s['exact']:5.1f}% exact, " if exact else ""
        return f"  {label:<20}: {share}mean geodesic error {s['mean']:.4f}"

    print(f"{r['description']} ({r['n_a']} -> {r['n_b']} vertices, {r['n_scored']} scored)")
    print(line("initial map (SHOT)", r["initial_map"]))
    print(line("HOPE", r["hope"]))
    ran = [s["name"] for s in r["stages"] if s["ran"] and s["name"] in ("spectral", "faces")]
    label = f"final (+{', '.join(ran)})" if ran else "final (= HOPE's)"
    print(line(label, r["final"]))
    if not exact:
        print(f"  {100 * r['final']['exact']:.1f}% of landmarks exact: {REMESHED_NOTE}")
    print(f"  time: {r['seconds']:.2f} s")

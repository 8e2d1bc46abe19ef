"""The bundled demo: FAUST registrations tr_reg_012 → tr_reg_018 (6890 vertices each).

Bogo et al., "FAUST: Dataset and evaluation for 3D mesh registration", CVPR 2014. Vertex i of
one registration corresponds to vertex i of the other, so the ground truth is the identity.
"""

from __future__ import annotations

import time
from importlib import resources

import numpy as np

from .mesh import Mesh


def demo_pair() -> tuple[Mesh, Mesh]:
    """The two bundled meshes (identity ground truth)."""
    with resources.files("hope_rs").joinpath("data/faust_012_018.npz").open("rb") as fh:
        z = np.load(fh)
        a = Mesh(z["a_vertices"].astype(np.float64), z["faces"])
        b = Mesh(z["b_vertices"].astype(np.float64), z["b_faces"])
    return a, b


def run_demo(*, verbose: bool = True) -> dict:
    """Match the bundled pair; score the initial map, HOPE's map and the final one (after the
    spectral pass and the shared-face finish, where they ran) against the ground truth; return
    a report."""
    from .evaluate import geodesic_errors, score
    from .matching import match

    a, b = demo_pair()
    t0 = time.perf_counter()
    res = match(a, b)
    seconds = time.perf_counter() - t0
    hope_map = res.map if res.hope_map is None else res.hope_map
    init, hope, final = (score(geodesic_errors(b, m)) for m in (res.init_map, hope_map, res.map))
    report = {
        "pair": "FAUST tr_reg_012 -> tr_reg_018 (6890 vertices)",
        "initial_map": vars(init),
        "hope": vars(hope),
        "final": vars(final),
        "seconds": seconds,
        "timings": res.timings,
    }
    if verbose:
        print(report["pair"])
        print(f"  initial map (SHOT, NN) : {init}")
        print(f"  HOPE                    : {hope}")
        # Both later stages are skipped when HOPE's map has settled or already sends every
        # face onto a face (see hope_rs.match's `spectral` and `shared_faces`).
        stages = [s for s in ("spectral", "faces") if s in res.timings]
        label = f"final (+{', '.join(stages)})" if stages else "final (HOPE's)"
        print(f"  {label:<23} : {final}")
        print(
            f"  time: {seconds:.2f} s  ("
            + ", ".join(f"{k} {v:.2f}s" for k, v in res.timings.items())
            + ")"
        )
    return report

"""Sizes passed to the Rust bindings that no machine can hold raise, they never abort.

Each case runs in a subprocess: an abort there (Rust's allocation failure, exit 134) fails the
test instead of killing pytest.
"""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import hope_rs

PYTHON_DIR = Path(hope_rs.__file__).resolve().parents[1]
PHYSICAL = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGESIZE")

PRELUDE = """
import numpy as np, scipy.sparse as sp
from hope_rs import _core, kernels
from hope_rs.kernels import assignment
faces = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)
vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
empty = np.zeros(0, dtype=np.int64)
"""


def outcome(code: str) -> str:
    """Runs ``code`` after :data:`PRELUDE` in a fresh interpreter; returns what it printed."""
    script = (
        PRELUDE
        + "try:\n"
        + textwrap.indent(textwrap.dedent(code), "    ")
        + """
    print("no error")
except Exception as e:
    print(type(e).__name__, str(e), sep=": ")
"""
    )
    env = dict(os.environ, PYTHONPATH=str(PYTHON_DIR))
    p = subprocess.run(
        [sys.executable, "-c", script],
        check=False,
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert p.returncode == 0, f"exit {p.returncode}: {p.stderr[-2000:]}"
    return p.stdout.strip()


CASES = [
    # (code, expected start of the printed line)
    (
        "kernels.khop_neighbourhoods(faces, 1, n_vertices=10**12)",
        "ValueError: n_vertices = 1000000000000 is too large: at most 2147483647 vertices",
    ),
    (
        "_core.khop_neighbourhoods(faces, 1, 10**12)",
        "ValueError: n_vertices = 1000000000000 is too large",
    ),
    ("_core.khop_neighbourhoods(faces, 1, 2**31)", "ValueError: n_vertices = 2147483648 is too"),
    ("_core.khop_neighbourhoods(faces, 1, 3)", "ValueError: faces[1] = [0, 2, 3] refers to"),
    ("kernels.khop_neighbourhoods(faces, 1, n_vertices=3)", "ValueError: faces refer to vertex 3"),
    (
        "_core.greedy_pairs(empty, empty, empty, 2**62)",
        "MemoryError: not enough memory for the columns' flags",
    ),
    (
        "assignment.auction_assignment(sp.csr_matrix(([1], ([0], [0])), shape=(1, 2**40)))",
        "ValueError: at most 2147483647 columns are supported",
    ),
    ("_core.MeshGraph(vertices, faces, 10**6)", "ValueError: k must be at most 255"),
]


@pytest.mark.parametrize(("code", "expected"), CASES)
def test_absurd_sizes_raise(code, expected):
    assert outcome(code).startswith(expected)


@pytest.mark.skipif(PHYSICAL > 100 * 2**30, reason="this machine could hold the graph")
@pytest.mark.parametrize(
    "call",
    [
        "kernels.khop_neighbourhoods(faces, 1, n_vertices=2**31 - 1)",
        "_core.khop_neighbourhoods(faces, 1, 2**31 - 1)",
    ],
)
def test_a_vertex_count_beyond_the_memory_is_a_memory_error(call):
    assert outcome(call).startswith(
        "MemoryError: not enough memory for the edge graph of 2147483647 vertices"
    )


def test_sensible_sizes_still_work():
    assert (
        outcome(
            """
        m = kernels.khop_neighbourhoods(faces, 1, n_vertices=6)
        assert m.shape == (6, 6) and m[4].nnz == 1 and m[0].nnz == 4
        assert _core.greedy_pairs(np.array([0]), np.array([2]), np.array([1]), 3)[1].tolist() == [2]
        """
        )
        == "no error"
    )


@pytest.mark.parametrize("n_cols", [2**62, 2**40])
@pytest.mark.parametrize("hint", ["None", "np.array([0])"])
def test_an_assignment_with_far_more_columns_than_entries(n_cols, hint):
    """The solver sizes its column arrays by the columns used, never by ``n_cols`` (a hint
    was checked with one flag per column before)."""
    args = f"np.array([0, 1]), np.array([0], np.int32), {{}}, 1, {n_cols}, True"
    code = f"""
        r = _core.auction_assignment_int({args.format("np.array([3])")}, hint={hint})
        assert r.tolist() == [0], r
        r = _core.auction_assignment_float({args.format("np.array([3.0])")})
        assert r.tolist() == [0], r
        """
    assert outcome(code) == "no error"

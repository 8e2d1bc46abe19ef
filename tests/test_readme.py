"""The README's Python examples run as tests."""

import dataclasses
import re
from pathlib import Path

import hope_rs

README = Path(__file__).resolve().parents[1] / "README.md"


def test_kernel_example_runs():
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), re.DOTALL)
    runnable = [b for b in blocks if 'load_mesh("tr_reg' not in b]
    assert runnable, "the README lost its runnable example"
    for block in runnable:
        exec(compile(block, str(README), "exec"), {})  # noqa: S102 - running the docs is the point


def test_the_api_table_names_every_field_of_match_config():
    (row,) = [x for x in README.read_text().splitlines() if x.startswith("| `MatchConfig` |")]
    named = re.findall(r"`(\w+)`", row.split("|")[2])
    fields = [f.name for f in dataclasses.fields(hope_rs.MatchConfig)]
    assert [n for n in named if n in fields] == fields

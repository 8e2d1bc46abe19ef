"""The README's Python examples run as tests."""

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_kernel_example_runs():
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), re.DOTALL)
    runnable = [b for b in blocks if 'load_mesh("tr_reg' not in b]
    assert runnable, "the README lost its runnable example"
    for block in runnable:
        exec(compile(block, str(README), "exec"), {})  # noqa: S102 - running the docs is the point

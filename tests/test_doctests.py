"""The examples in the package's docstrings run and print what they show."""

import doctest
import importlib
from pathlib import Path

import pytest

import hope_rs

PACKAGE = Path(hope_rs.__file__).parent


def modules_with_examples() -> list[str]:
    """Every module of the package whose source holds a ``>>>`` example."""
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if ">>>" in path.read_text():
            parts = path.relative_to(PACKAGE).with_suffix("").parts
            out.append(".".join(("hope_rs", *parts)).removesuffix(".__init__"))
    return out


#: Modules whose examples run a whole match of the bundled FAUST pair (several seconds).
SLOW = {"hope_rs.matching"}


@pytest.mark.parametrize(
    "name",
    [pytest.param(n, marks=pytest.mark.slow) if n in SLOW else n for n in modules_with_examples()],
)
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0
    assert result.failed == 0

"""Help texts built from one registry: ``hope-rs bench --help`` lists every method."""

import pytest

from hope_rs.cli import main
from hope_rs.evaluation.bench import methods_markdown
from hope_rs.evaluation.methods import ABLATIONS, METHODS


def test_bench_help_and_the_readme_table_list_every_method(capsys):
    with pytest.raises(SystemExit):
        main(["bench", "--help"])
    out = capsys.readouterr().out
    listed = out.split("methods (--methods")[1].splitlines()[1:]
    names = [line.split()[0] for line in listed if line.startswith("  ")]
    assert names == list(METHODS)
    assert "hope-nospectral" in names
    table = methods_markdown().splitlines()[2:]
    assert [row.split("`")[1] for row in table] == list(METHODS)
    for row in table:
        name = row.split("`")[1]
        assert ("ablation:" in row) == (name in ABLATIONS)

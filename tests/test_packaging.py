"""Packaging: the version a user sees, the README as an index's project page, the release
checks of ``scripts/check_dist.py`` (run on every build by ``scripts/build_wheel.sh``)."""

import importlib.metadata
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

import hope_rs
from hope_rs.cli import main

ROOT = Path(__file__).resolve().parents[1]

_spec = importlib.util.spec_from_file_location("check_dist", ROOT / "scripts" / "check_dist.py")
check_dist = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(check_dist)

# Fenced code blocks (``` or ~~~) and inline code spans: their brackets are not links.
_FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,}).*?^ {0,3}\1[^\n]*$", re.MULTILINE | re.DOTALL)
_CODE_SPAN = re.compile(r"(`+)(?:(?!\1).)+?\1", re.DOTALL)
# Inline links and images: [text](target "title") / ![alt](target), or a target in <...>.
_INLINE = re.compile(r"\]\(\s*(?:<([^>]*)>|([^)\s]+))")
# Reference definitions: [label]: target
_REFDEF = re.compile(r"^ {0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s|$)", re.MULTILINE)
# Raw HTML: <img src="..."> / <a href="...">
_HTML = re.compile(r"""\b(?:src|href)\s*=\s*["']([^"']+)["']""", re.IGNORECASE)
_ABSOLUTE = re.compile(r"^(?:https?:|mailto:|#)", re.IGNORECASE)


def relative_links(markdown: str) -> list[str]:
    """Link and image targets in ``markdown`` that are neither absolute http(s)/mailto URLs
    nor in-page anchors: on a package index's project page these resolve against the index,
    not the repository, and break."""
    text = _CODE_SPAN.sub("", _FENCE.sub("", markdown))
    inline = [angled or bare for angled, bare in _INLINE.findall(text)]
    targets = inline + _REFDEF.findall(text) + _HTML.findall(text)
    return [t for t in targets if not _ABSOLUTE.match(t)]


def project_version() -> str:
    """``[package] version`` of Cargo.toml, the one place the version is set (a regex:
    tomllib is 3.11+)."""
    text = (ROOT / "Cargo.toml").read_text()
    m = re.search(r'^\[package\]$[^\[]*?^version\s*=\s*"([^"]+)"', text, re.MULTILINE | re.DOTALL)
    assert m, "Cargo.toml has no [package] version"
    return m.group(1)


def test_relative_links_finds_what_an_index_would_break():
    md = (
        "See [results](docs/results/summary.md) and ![plot](docs/a.png).\n"
        "An [anchor](#install), a [site](https://example.org/x), ![remote](http://e.org/p.png).\n"
        "[ref]: docs/ref.md\n"
        "[web]: https://example.org\n"
        '<img src="docs/b.png" width="30%"> <a href="https://example.org">x</a>\n'
        "Code: `a[0](x)` stays code.\n"
        "```python\n"
        "m = arr[i](docs/not_a_link.md)\n"
        "```\n"
        '[angled](<docs/with space.md>) and [titled](docs/t.md "Title")\n'
    )
    assert relative_links(md) == [
        "docs/results/summary.md",
        "docs/a.png",
        "docs/with space.md",
        "docs/t.md",
        "docs/ref.md",
        "docs/b.png",
    ]
    assert relative_links("no links, [brackets] and (parens) only") == []


def test_readme_has_no_relative_links():
    # README.md is the project description on the package index, where relative targets
    # point at the index itself. Use absolute repository URLs instead.
    bad = relative_links((ROOT / "README.md").read_text(encoding="utf-8"))
    assert bad == [], f"README.md has {len(bad)} relative link(s): {bad}"


def test_version_comes_from_the_installed_distribution():
    assert hope_rs.__version__ == importlib.metadata.version("hope-rs") == project_version()


def test_version_files_agree():
    # pyproject.toml takes the version from Cargo.toml; the citation and the changelog's
    # latest release name it too.
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert re.search(r'^dynamic\s*=\s*\[[^\]]*"version"', pyproject, re.MULTILINE)
    assert not re.search(r"^version\s*=", pyproject, re.MULTILINE)
    cff = re.search(r"^version:\s*(\S+)\s*$", (ROOT / "CITATION.cff").read_text(), re.MULTILINE)
    changes = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    release = re.search(
        r"^## \[(\d[^\]]*)\] - (?:\d{4}-\d{2}-\d{2}|Unreleased)$", changes, re.MULTILINE
    )
    assert cff and release, "CITATION.cff or CHANGELOG.md names no version"
    assert cff.group(1) == release.group(1) == project_version()


def test_version_flag_prints_the_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out == f"hope-rs {hope_rs.__version__}\n"
    assert hope_rs.__version__ != "0+unknown"


def test_version_falls_back_without_metadata():
    # A source tree on sys.path with no installed metadata: hope_rs still imports.
    code = (
        "import importlib.metadata as md\n"
        "def missing(name):\n"
        "    raise md.PackageNotFoundError(name)\n"
        "md.version = missing\n"
        "import hope_rs\n"
        "print(hope_rs.__version__)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout == "0+unknown\n"


def _sdist(*extra: str, drop: str = "") -> list[str]:
    top = "hope_rs-0.1.0"
    names = [top, *(f"{top}/{r}" for r in check_dist.SDIST_REQUIRED if r != drop)]
    return names + [f"{top}/{r}" for r in extra]


def test_sdist_check_wants_build_inputs_and_refuses_results():
    assert check_dist.sdist_problems(_sdist("src/khop.rs", "tests/test_match.py")) == []
    assert check_dist.sdist_problems(_sdist(drop="Cargo.lock")) == ["sdist lacks Cargo.lock"]
    bad = _sdist("docs/results/tosca_best.png", ".ci/run", "benches/bench_match.py", "x.png")
    assert check_dist.sdist_problems(bad) == [
        f"sdist should not contain {r}"
        for r in (".ci/run", "benches/bench_match.py", "docs/results/tosca_best.png", "x.png")
    ]
    assert "exactly one top folder" in check_dist.sdist_problems(["a/x", "b/y"])[0]


_METADATA = "Metadata-Version: 2.4\nName: hope-rs\nLicense-Expression: MIT\nLicense-File: LICENSE\n"
_MANYLINUX = "Tag: cp39-abi3-manylinux_2_17_x86_64\nTag: cp39-abi3-manylinux2014_x86_64\n"


def _wheel(drop: str = "") -> list[str]:
    names = [*check_dist.WHEEL_REQUIRED, *check_dist.source_modules(), "hope_rs/_core.abi3.so"]
    names += ["hope_rs-0.1.0.dist-info/licenses/LICENSE", "hope_rs-0.1.0.dist-info/METADATA"]
    return [n for n in names if n != drop]


def test_wheel_check_wants_stub_marker_licence_and_manylinux_tag():
    assert check_dist.wheel_problems(_wheel(), _METADATA, _MANYLINUX) == []
    assert check_dist.wheel_problems(_wheel("hope_rs/py.typed"), _METADATA, _MANYLINUX) == [
        "wheel lacks hope_rs/py.typed"
    ]
    # Every module of the source tree must be packed.
    runner = "hope_rs/pipeline/runner.py"
    assert runner in check_dist.source_modules()
    assert check_dist.wheel_problems(_wheel(runner), _METADATA, _MANYLINUX) == [
        f"wheel lacks {runner}"
    ]
    no_licence = check_dist.wheel_problems(
        _wheel("hope_rs-0.1.0.dist-info/licenses/LICENSE"),
        _METADATA.replace("License-File: LICENSE\n", ""),
        _MANYLINUX,
    )
    assert no_licence == [
        "wheel lacks .dist-info/licenses/LICENSE",
        "METADATA lacks 'License-File: LICENSE'",
    ]
    plain = "Tag: cp39-abi3-linux_x86_64\n"
    assert check_dist.wheel_problems(_wheel(), _METADATA, plain) == [
        "wheel tags ['cp39-abi3-linux_x86_64'] are not all abi3 manylinux tags"
    ]
    assert check_dist.wheel_problems(_wheel(), _METADATA, plain, manylinux=False) == []
    not_abi3 = "Tag: cp311-cp311-manylinux_2_17_x86_64\n"
    assert check_dist.wheel_problems(_wheel(), _METADATA, not_abi3, manylinux=False) == [
        "wheel tags ['cp311-cp311-manylinux_2_17_x86_64'] are not all abi3 tags"
    ]


def test_the_settings_file_reader_is_a_dependency_where_python_lacks_tomllib():
    # `--config settings.toml` needs tomllib (3.11+) or the tomli backport: a package that
    # claims older Pythons must install tomli there.
    pyproject = (ROOT / "pyproject.toml").read_text()
    floor = re.search(r'^requires-python\s*=\s*">=3\.(\d+)"', pyproject, re.MULTILINE)
    assert floor is not None
    deps = re.search(r"^dependencies\s*=\s*\[(.*?)\]", pyproject, re.MULTILINE | re.DOTALL)
    assert deps is not None
    if int(floor.group(1)) < 11:
        assert re.search(
            r"""['"]tomli>=[\d.]+;\s*python_version\s*<\s*"3\.11"['"]""", deps.group(1)
        )

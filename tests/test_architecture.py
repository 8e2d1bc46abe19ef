"""The package's layers: imports go downward only, never inside a function, never in a cycle.

geometry → kernels → features → shape → pipeline → matching → batch / evaluation → cli, with
the private base modules (``_core``, ``_blas``...) below all of them. A module may import its
own layer and the layers below it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import hope_rs

PACKAGE = Path(hope_rs.__file__).parent

#: Layer of each top-level module or subpackage, lowest first.
LAYERS = {
    "_core": 0, "_blas": 0, "_cancel": 0, "_terminate": 0, "_validate": 0, "_version": 0, "_threads": 0,
    "geometry": 1,
    "kernels": 2,
    "features": 3,
    "shape": 4,
    "pipeline": 5,
    "matching": 6,
    "batch": 7, "evaluation": 7,
    "cli": 8,
    "__init__": 9,
}  # fmt: skip


def modules() -> list[tuple[str, Path]]:
    """(dotted name without the package, path) of every module of the package."""
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        out.append((".".join(parts), path))
    return out


def first_party_imports(name: str, path: Path) -> list[tuple[str, ast.AST]]:
    """Every import of a hope_rs module by ``name``: (imported dotted name, node)."""
    package = name.split(".")[:-1]
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                target = ".".join([*base, *(node.module.split(".") if node.module else [])])
                if node.module is None or not target:
                    for alias in node.names:
                        found.append((".".join([*base, alias.name]), node))
                else:
                    found.append((target, node))
            elif node.module and node.module.split(".")[0] == "hope_rs":
                found.append((node.module.removeprefix("hope_rs").lstrip("."), node))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "hope_rs":
                    found.append((alias.name.removeprefix("hope_rs").lstrip("."), node))
    return found


def layer(dotted: str) -> int:
    return LAYERS[dotted.split(".")[0] or "__init__"]


@pytest.mark.parametrize("name,path", modules(), ids=[n for n, _ in modules()])
def test_imports_go_downward(name, path):
    own = layer(name)
    for target, node in first_party_imports(name, path):
        if name == "__init__" or target == "":
            continue
        assert layer(target) <= own, (
            f"{name} (layer {own}) imports {target} (layer {layer(target)}), line {node.lineno}"
        )


@pytest.mark.parametrize("name,path", modules(), ids=[n for n, _ in modules()])
def test_no_first_party_import_inside_a_function(name, path):
    tree = ast.parse(path.read_text())
    for fn in ast.walk(tree):
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for node in ast.walk(fn):
            if isinstance(node, ast.ImportFrom) and (
                node.level or (node.module or "").startswith("hope_rs")
            ):
                pytest.fail(
                    f"{name}.{fn.name} imports {node.module!r} inside it, line {node.lineno}"
                )
            if isinstance(node, ast.Import) and any(
                a.name.split(".")[0] == "hope_rs" for a in node.names
            ):
                pytest.fail(f"{name}.{fn.name} imports hope_rs inside it, line {node.lineno}")


def test_no_import_cycle():
    names = {n for n, _ in modules()}
    graph = {}
    for name, path in modules():
        edges = set()
        for target, _ in first_party_imports(name, path):
            for cand in (target, f"{target}.__init__"):
                if cand in names and cand != name:
                    edges.add(cand)
        graph[name] = edges
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n: str) -> None:
        state[n] = 1
        stack.append(n)
        for m in sorted(graph[n]):
            if state.get(m) == 1:
                cycle = stack[stack.index(m) :] + [m]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if m not in state:
                visit(m)
        stack.pop()
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n)


def test_every_module_has_a_layer():
    missing = sorted({n.split(".")[0] for n, _ in modules()} - set(LAYERS))
    assert not missing, f"modules without a layer in LAYERS: {missing}"


TESTS = Path(__file__).resolve().parent


@pytest.mark.parametrize("path", sorted(TESTS.glob("test_*.py")), ids=lambda p: p.name)
def test_test_helpers_come_from_meshes_or_conftest(path):
    # A test file imports no other test file: shared helpers live in meshes.py or conftest.py.
    imported = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            imported.add(node.module.split(".")[0])
        elif isinstance(node, ast.Import):
            imported.update(alias.name.split(".")[0] for alias in node.names)
    assert not {m for m in imported if m.startswith("test_")}, f"{path.name} imports a test file"

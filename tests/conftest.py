import os
from pathlib import Path

import pytest
from hypothesis import settings

import hope_rs
from hope_rs.evaluation.datasets import pairs_of
from hope_rs.evaluation.demo import demo_pair
from hope_rs.geometry.map_io import check_writable_folder
from hope_rs.geometry.mesh import load_mesh

# CI runs a fixed sequence of examples, so a landing never hinges on the draw; local runs stay
# random to keep finding new cases.
settings.register_profile("ci", derandomize=True)
if os.environ.get("CI"):
    settings.load_profile("ci")

DATA = Path(
    os.environ.get("HOPE_DATA", Path(__file__).resolve().parents[1].parent / "shared" / "data")
)


def data_path(*parts: str) -> Path:
    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"benchmark data not found at {p} (set HOPE_DATA)")
    return p


def shared_pair(data_set: str, name: str) -> tuple:
    """Meshes and ground-truth vertices ``(a, b, a_idx, b_idx)`` of the pair ``name`` (as
    ``"A->B"``) of a shared data set."""
    pair = next(p for p in pairs_of(data_path(data_set)) if p.name == name)
    a, b = load_mesh(pair.a), load_mesh(pair.b)
    return (a, b, *pair.ground_truth(a.n_vertices, b.n_vertices))


_DEFAULT_MATCHES: dict = {}


def default_match(a_path: Path, b_path: Path) -> tuple:
    """``(a, b, hope_rs.match(a, b))`` of two mesh files, with the default settings, made once
    per test process: for a pair that tests of several modules check (golden maps, growth);
    the tests only read it."""
    key = (str(a_path), str(b_path))
    if key not in _DEFAULT_MATCHES:
        a, b = load_mesh(a_path), load_mesh(b_path)
        _DEFAULT_MATCHES[key] = (a, b, hope_rs.match(a, b))
    return _DEFAULT_MATCHES[key]


@pytest.fixture(scope="session")
def faust_pair():
    """FAUST tr_reg_012 and tr_reg_018 from the shared data, else the package's bundled copy
    (the same meshes, coordinates stored as float32)."""
    a, b = DATA / "faust_reg" / "tr_reg_012.off", DATA / "faust_reg" / "tr_reg_018.off"
    if a.exists() and b.exists():
        return load_mesh(a), load_mesh(b)
    return demo_pair()


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "slow: takes more than a few seconds (28k meshes, remeshed data, Ray, kills)"
    )


def unwritable_folder(tmp_path):
    """A folder this process cannot create files in (root ignores permission bits; /sys
    refuses new files even to root)."""
    if os.geteuid() != 0:
        d = tmp_path / "ro"
        d.mkdir()
        d.chmod(0o555)
        return d
    if os.path.isdir("/sys") and _refuses("/sys"):
        return "/sys"
    pytest.skip("no folder this process cannot write to")


def _refuses(folder) -> bool:
    try:
        check_writable_folder(folder)
    except ValueError:
        return True
    return False

"""Golden maps: the default ``match`` on a fixed set of pairs, recorded as SHA-256 hashes.

A change that moves any of these maps must say so in its own commit, with the errors before and
after; restructuring code must keep them bit-identical. Regenerate with
``python tests/test_golden_maps.py`` (prints the table to paste below).
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from conftest import DATA
from test_sites import subdivided

import hope_rs
from hope_rs.evaluation.demo import demo_pair

#: case name -> SHA-256 of ``match(...).map`` as little-endian int64.
GOLDEN = {
    "faust_reg_012_018": "4948114ddb2738e2567c892cfb0581117dd0559722186b48e639ee3f2cc631c6",
    "faust_r_000_001": "fe753e3104b5cec9a2aecd29582460620d3e5206c494b7fa4d7c2523d12e4437",
    "faust_r_002_007": "42b30fd7dee786d07497f02cfb7f7a06f067a8f7b212f65b7d7b58485f1b885d",
    "tosca_r_cat0_cat1": "7aa52f34f5840b0933375870ab7f02ae4d840aba2fd554cb479f00354ba9a1d1",
    "tosca_r_wolf0_wolf1": "81fcd141e38dec10aba7c25ae20236bde0db985d376820fe5b7a64356c0d2000",
    "tosca_cat0_cat6": "462be934aaffbd8a94db63e086bf329ab28a247ed830a1cb5cc2b3e11dda101d",
    "multiscale_faust_r_000_001_subdivided": "52a3622c29d6dd07d3faa25316dd14d0dfe2b855446a524c19a66b39272ab3ce",
    "init_identity_faust_reg_012_018": "4948114ddb2738e2567c892cfb0581117dd0559722186b48e639ee3f2cc631c6",
}


def _load(*parts: str) -> hope_rs.Mesh:
    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"benchmark data not found at {p} (set HOPE_DATA)")
    return hope_rs.load_mesh(p)


def _bundled() -> tuple[hope_rs.Mesh, hope_rs.Mesh]:
    return demo_pair()


def _subdivided(m: hope_rs.Mesh) -> hope_rs.Mesh:
    return hope_rs.Mesh(*subdivided(np.asarray(m.vertices), np.asarray(m.faces)))


def _case(name: str) -> np.ndarray:
    if name == "faust_reg_012_018":
        return hope_rs.match(*_bundled()).map
    if name == "init_identity_faust_reg_012_018":
        a, b = _bundled()
        return hope_rs.match(a, b, init=np.arange(a.n_vertices)).map
    if name.startswith("faust_r_0"):
        i, j = name.split("_")[2:]
        return hope_rs.match(
            _load("faust_r", f"tr_reg_{i}.off"), _load("faust_r", f"tr_reg_{j}.off")
        ).map
    if name.startswith("tosca_r_"):
        i, j = name.split("_")[2:]
        return hope_rs.match(_load("tosca_r", f"{i}.off"), _load("tosca_r", f"{j}.off")).map
    if name == "tosca_cat0_cat6":
        return hope_rs.match(_load("tosca", "cat0.off"), _load("tosca", "cat6.off")).map
    if name == "multiscale_faust_r_000_001_subdivided":
        a = _subdivided(_load("faust_r", "tr_reg_000.off"))
        b = _subdivided(_load("faust_r", "tr_reg_001.off"))
        res = hope_rs.match(a, b, multiscale=True)
        assert res.coarse is not None, "the subdivided pair must take the multiscale path"
        return res.map
    raise KeyError(name)


def digest(m: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(m, dtype="<i8").tobytes()).hexdigest()


FAST = {"faust_reg_012_018"}


@pytest.mark.parametrize(
    "name", [n if n in FAST else pytest.param(n, marks=pytest.mark.slow) for n in GOLDEN]
)
def test_golden_map(name):
    assert digest(_case(name)) == GOLDEN[name], f"the map of {name} changed"


if __name__ == "__main__":
    for n in GOLDEN:
        print(f'    "{n}": "{digest(_case(n))}",', flush=True)

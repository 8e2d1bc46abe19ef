from collections import deque

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import data_path
from meshes import relabel

import hope_rs
from hope_rs.geometry.mesh import load_mesh


def bfs_ball(adj: sp.csr_matrix, src: int, k: int) -> np.ndarray:
    depth = {src: 0}
    queue = deque([src])
    while queue:
        u = queue.popleft()
        if depth[u] == k:
            continue
        for w in adj.indices[adj.indptr[u] : adj.indptr[u + 1]]:
            if w not in depth:
                depth[w] = depth[u] + 1
                queue.append(w)
    return np.array(sorted(depth))


def edge_adjacency(faces, n):
    i = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]])
    j = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]])
    a = sp.coo_matrix((np.ones(i.size), (i, j)), shape=(n, n)).tocsr()
    return ((a + a.T) > 0).astype(np.int8).tocsr()


@pytest.mark.parametrize("name", [("faust_reg", "tr_reg_012.off"), ("tosca_r", "dog0.off")])
def test_matches_bfs_on_real_meshes_for_every_k(name):
    mesh = load_mesh(data_path(*name))
    adj = edge_adjacency(mesh.faces, mesh.n_vertices)
    rng = np.random.default_rng(0)
    sample = rng.choice(mesh.n_vertices, 60, replace=False)
    for k in range(1, 9):
        nb = hope_rs.khop_neighbourhoods(mesh.faces, k, n_vertices=mesh.n_vertices)
        assert nb.shape == (mesh.n_vertices, mesh.n_vertices)
        assert nb.has_sorted_indices
        for v in sample:
            row = nb.indices[nb.indptr[v] : nb.indptr[v + 1]]
            np.testing.assert_array_equal(row, bfs_ball(adj, int(v), k))


def test_matches_boolean_matrix_powers_everywhere(faust_pair):
    mesh = faust_pair[0]
    n = mesh.n_vertices
    step = edge_adjacency(mesh.faces, n) + sp.identity(n, dtype=np.int8, format="csr")
    reach = sp.identity(n, dtype=np.int8, format="csr")
    for k in range(1, 5):
        reach = ((reach @ step) > 0).astype(np.int8)
        nb = hope_rs.khop_neighbourhoods(mesh.faces, k)
        assert (nb.astype(bool) != reach.astype(bool)).nnz == 0


def test_isolated_vertices_and_components():
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    nb = hope_rs.khop_neighbourhoods(faces, 3, n_vertices=7)
    dense = nb.toarray().astype(bool)
    assert dense[:3, :3].all() and dense[3:6, 3:6].all()
    assert not dense[:3, 3:].any()
    assert dense[6].sum() == 1 and dense[6, 6]
    assert hope_rs.khop_neighbourhoods(faces, 0).nnz == 6


def test_relabelling_vertices_permutes_the_neighbourhoods(faust_pair):
    mesh = faust_pair[0]
    perm = np.random.default_rng(1).permutation(mesh.n_vertices)
    nb = hope_rs.khop_neighbourhoods(mesh.faces, 4)
    nb_perm = hope_rs.khop_neighbourhoods(relabel(mesh.faces, perm), 4)
    assert (nb_perm != nb[perm][:, perm]).nnz == 0


@pytest.mark.parametrize(
    "faces, kwargs, err, match",
    [
        (np.zeros((3, 4), int), {}, ValueError, r"\(M, 3\)"),
        (np.array([[0, 1, -2]]), {}, ValueError, "negative"),
        (np.array([[0, 1, 9]]), {"n_vertices": 5}, ValueError, "only 5 vertices"),
        (np.array([[0.5, 1, 2]]), {}, TypeError, "integer"),
        (np.array(["a", "b", "c"]).reshape(1, 3), {}, TypeError, "integer"),
        (np.zeros((0, 3), int), {}, ValueError, "empty"),
    ],
)
def test_bad_faces(faces, kwargs, err, match):
    with pytest.raises(err, match=match):
        hope_rs.khop_neighbourhoods(faces, 2, **kwargs)


@pytest.mark.parametrize("k", [-1, 256, 2.5, "3"])
def test_bad_k(k):
    with pytest.raises((ValueError, TypeError)):
        hope_rs.khop_neighbourhoods([[0, 1, 2]], k)

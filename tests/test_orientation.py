"""Face orientation: Shape orients its internal mesh consistently and outward."""

import numpy as np
import pytest
from conftest import data_path
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from meshes import bumpy_sphere, signed_volume

import hope_rs
from hope_rs.evaluation.demo import demo_pair
from hope_rs.features.descriptors import shot
from hope_rs.geometry.numbering import canonical_mesh
from hope_rs.geometry.orientation import orient_faces

SPHERE = bumpy_sphere(200, 1)


def directed_edge_conflicts(f):
    """Directed edges that occur twice (two faces running a shared edge the same way)."""
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    _, counts = np.unique(e, axis=0, return_counts=True)
    return int((counts > 1).sum())


def apply(f, flip):
    f = np.array(f)
    f[flip] = f[flip][:, ::-1]
    return f


def open_cap():
    """The bumpy sphere without the faces around one pole: an open, outward-oriented surface."""
    v, f = SPHERE
    keep = v[f].mean(axis=1)[:, 2] < 0.5
    return v, f[keep]


def two_components():
    v, f = SPHERE
    return np.vstack([v, v + [5.0, 0, 0]]), np.vstack([f, f + len(v)])


@pytest.mark.parametrize(
    "surface", [SPHERE, open_cap(), two_components()], ids=["closed", "open", "two"]
)
@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_a_random_subset_of_flipped_faces_is_repaired(surface, data):
    v, f = surface
    assert directed_edge_conflicts(f) == 0
    flip = data.draw(arrays(bool, len(f)), label="flip")
    bad = apply(f, flip)
    # The repair flips exactly the faces that were flipped: the input's outward orientation.
    np.testing.assert_array_equal(orient_faces(v, bad), flip)
    c_good = canonical_mesh(hope_rs.Mesh(v, f))[0]
    c_bad = canonical_mesh(hope_rs.Mesh(v, bad))[0]
    np.testing.assert_array_equal(c_bad.faces, c_good.faces)


@pytest.mark.parametrize(
    "surface", [SPHERE, open_cap(), two_components()], ids=["closed", "open", "two"]
)
def test_inward_surfaces_are_turned_outward(surface):
    v, f = surface
    inward = f[:, ::-1]
    assert orient_faces(v, inward).all()
    assert not orient_faces(v, f).any()
    fixed = canonical_mesh(hope_rs.Mesh(v, inward))[0]
    assert directed_edge_conflicts(fixed.faces) == 0
    if surface is SPHERE:
        assert signed_volume(fixed.vertices, fixed.faces) > 0


def test_each_component_is_oriented_on_its_own():
    v, f = two_components()
    n = len(SPHERE[1])
    mixed = np.vstack([f[:n], f[n:, ::-1]])  # the second sphere inside out
    np.testing.assert_array_equal(orient_faces(v, mixed), np.arange(2 * n) >= n)


def test_a_flat_patch_faces_its_largest_area_component_positive():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    down = np.array([[0, 2, 1], [0, 3, 2]])  # normals along -z
    np.testing.assert_array_equal(orient_faces(v, down), [True, True])
    np.testing.assert_array_equal(orient_faces(v, down[:, ::-1]), [False, False])


def test_non_manifold_and_moebius_surfaces_are_handled_deterministically():
    # Three triangles on one edge (0, 1): a book of three pages.
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1.0]])
    book = np.array([[0, 1, 2], [0, 1, 3], [1, 0, 4]])
    for f in (book, book[:, ::-1], apply(book, [True, False, False])):
        got = apply(f, orient_faces(v, f))
        np.testing.assert_array_equal(np.sort(got, axis=1), np.sort(book, axis=1))
        want = apply(book, orient_faces(v, book))
        np.testing.assert_array_equal(got, want)
    # A Möbius strip: no consistent orientation exists; the result is one seam, and the same
    # whichever faces come in flipped.
    k = 12
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    mid = np.stack([np.cos(t), np.sin(t), 0 * t], 1)
    w = 0.3 * np.stack([np.cos(t / 2) * np.cos(t), np.cos(t / 2) * np.sin(t), np.sin(t / 2)], 1)
    pts = np.vstack([mid + w, mid - w])
    i, j = np.arange(k), (np.arange(k) + 1) % k
    top_j = np.where(j == 0, k, j)  # crossing the seam swaps the two borders
    bot_j = np.where(j == 0, 0, j + k)
    strip = np.vstack([np.stack([i, i + k, top_j], 1), np.stack([i + k, bot_j, top_j], 1)])
    results = set()
    for flip in (np.zeros(len(strip), bool), np.arange(len(strip)) % 3 == 0):
        f = apply(strip, flip)
        results.add(apply(f, orient_faces(pts, f)).tobytes())
    assert len(results) == 1
    oriented = np.frombuffer(results.pop(), dtype=strip.dtype).reshape(strip.shape)
    assert 1 <= directed_edge_conflicts(oriented) <= 2


def test_degenerate_and_duplicate_faces_do_not_break_the_rest():
    v, f = SPHERE
    extra = np.vstack([f, [[0, 0, 1]], f[:1]])  # a degenerate face and a duplicate
    got = orient_faces(v, extra[:, ::-1])
    # Face 0 and its duplicate link to nothing (each is a flat patch of its own); every other
    # face of the sphere still turns outward.
    assert got[1 : len(f)].all()
    assert got[0] == got[-1]


def test_the_users_mesh_keeps_its_winding_and_descriptors_ignore_it():
    v, f = SPHERE
    mesh = hope_rs.Mesh(v, f[:, ::-1])
    shape = hope_rs.Shape(mesh)
    np.testing.assert_array_equal(shape.mesh.faces, f[:, ::-1])
    np.testing.assert_array_equal(shape.internal.faces, hope_rs.Shape((v, f)).internal.faces)
    np.testing.assert_array_equal(shot(mesh), shot(hope_rs.Mesh(v, f)))


@pytest.mark.parametrize("orient", ["false", 0, None])
def test_orient_must_be_a_bool(orient):
    with pytest.raises(
        TypeError, match=f"^orient must be a bool \\(True or False\\), got {orient!r}$"
    ):
        hope_rs.Shape(hope_rs.Mesh(*SPHERE), orient=orient)


def test_orient_takes_a_numpy_bool():
    v, f = SPHERE
    kept = hope_rs.Shape(hope_rs.Mesh(v, f[:, ::-1]), orient=np.False_)
    assert kept.orient is False
    assert signed_volume(kept.internal.vertices, kept.internal.faces) < 0  # left as given


@pytest.mark.parametrize("which", ["a", "b", "both"])
def test_reversing_all_faces_leaves_the_map_bit_identical(which):
    a, b = hope_rs.Mesh(*bumpy_sphere(600, 3)), hope_rs.Mesh(*bumpy_sphere(500, 4))
    want = hope_rs.match(a, b, max_passes=2)
    ra = hope_rs.Mesh(a.vertices, a.faces[:, ::-1]) if which != "b" else a
    rb = hope_rs.Mesh(b.vertices, b.faces[:, ::-1]) if which != "a" else b
    got = hope_rs.match(ra, rb, max_passes=2)
    np.testing.assert_array_equal(got.map, want.map)
    np.testing.assert_array_equal(got.init_map, want.init_map)


@pytest.mark.slow
def test_the_bundled_pair_reversed_is_matched_as_itself():
    a, b = demo_pair()
    want = hope_rs.match(a, b, max_passes=1, spectral=False, shared_faces=False).map
    ra = hope_rs.Mesh(a.vertices, a.faces[:, [0, 2, 1]])
    got = hope_rs.match(ra, b, max_passes=1, spectral=False, shared_faces=False).map
    np.testing.assert_array_equal(got, want)


@pytest.mark.slow
def test_a_remeshed_pair_reversed_gives_the_same_map():
    a = hope_rs.load_mesh(data_path("faust_r", "tr_reg_000.off"))
    b = hope_rs.load_mesh(data_path("faust_r", "tr_reg_001.off"))
    want = hope_rs.match(a, b).map
    got = hope_rs.match(hope_rs.Mesh(a.vertices, a.faces[:, ::-1]), b).map
    np.testing.assert_array_equal(got, want)

"""Coarse-to-fine matching: vertex clustering, the lift of a coarse map, ``match(multiscale=True)``."""

import dataclasses
import json

import numpy as np
import pytest
from meshes import bumpy_sphere, renumbered, signed_volume, write_off

import hope_rs
from hope_rs import MatchConfig
from hope_rs.batch.manifest import MANIFEST
from hope_rs.cli import main
from hope_rs.cli.batch_cli import config_from_args
from hope_rs.cli.commands import build_parser
from hope_rs.geometry.coarsen import CoarsenConfig, coarse_mesh
from hope_rs.pipeline import multiscale as M
from hope_rs.pipeline.config import OrientConfig, ResolutionConfig
from hope_rs.shape import ShapeConfig

#: Cells wide enough that the 6890-vertex FAUST meshes coarsen (to about 2.5k vertices); at the
#: default spacing only denser meshes do.
COARSER_SHAPES = ShapeConfig(coarsen=CoarsenConfig(spacing=0.025))
COARSER = MatchConfig(shape=COARSER_SHAPES).with_options(multiscale=True)


def test_coarse_mesh_clusters_vertices_and_keeps_the_surface(faust_pair):
    a, _ = faust_pair
    assert coarse_mesh(a) is None  # 6890 vertices: not halved at the default spacing
    c = coarse_mesh(a, CoarsenConfig(spacing=0.025))
    n = c.sites.size
    assert 1500 < n < a.n_vertices / CoarsenConfig().min_coarsening
    np.testing.assert_array_equal(c.mesh.vertices, a.vertices[c.sites])
    np.testing.assert_array_equal(c.owner[c.sites], np.arange(n))
    # Each fine vertex is within a cell's diagonal of its coarse vertex.
    d = np.linalg.norm(a.vertices - a.vertices[c.sites][c.owner], axis=1)
    assert d.max() <= np.sqrt(3) * 0.025 * a.scale
    # Faces: three distinct corners, each the image of some fine face, none repeated.
    f = c.mesh.faces
    assert (f[:, 0] != f[:, 1]).all() and (f[:, 1] != f[:, 2]).all() and (f[:, 2] != f[:, 0]).all()
    fine = {tuple(t) for t in c.owner[a.faces].tolist()}
    assert all(tuple(t) in fine for t in f.tolist())
    assert len({tuple(sorted(t)) for t in f.tolist()}) == len(f)
    # Same surface, same orientation: area and signed volume (the body is closed) close to
    # the fine mesh's; a flipped face would subtract its share.
    assert abs(c.mesh.area / a.area - 1) < 0.1
    volume = signed_volume(c.mesh.vertices, c.mesh.faces)
    assert abs(volume / signed_volume(a.vertices, a.faces) - 1) < 0.1


def test_lift_carries_a_similarity_to_the_exact_vertices(faust_pair):
    a, _ = faust_pair
    rng = np.random.default_rng(7)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))  # a rotation
    s, shift = 1.7, rng.normal(size=3)
    c = coarse_mesh(a, CoarsenConfig(spacing=0.025))
    moved = hope_rs.Mesh(s * c.mesh.vertices @ q.T + shift, c.mesh.faces)
    perm = rng.permutation(a.n_vertices)  # B's vertex i is A's vertex perm[i]
    points_b = (s * a.vertices @ q.T + shift)[perm]
    identity = np.arange(c.sites.size)
    g = M.lift_map(c.mesh, moved, identity, a.vertices, c.owner, points_b)
    truth = np.argsort(perm)
    assert np.mean(g == truth) > 0.99
    # A coarse map that is off moves the lifted one with it: the lift follows g, not geometry.
    shifted = M.lift_map(c.mesh, moved, np.roll(identity, 1), a.vertices, c.owner, points_b)
    assert np.mean(shifted == truth) < 0.1


@pytest.fixture(scope="module")
def coarser_match(faust_pair):
    """The FAUST pair's Shapes (coarsened at the wider spacing) and their multiscale match:
    ``(sa, sb, res)``."""
    a, b = faust_pair
    sa, sb = hope_rs.Shape(a, config=COARSER_SHAPES), hope_rs.Shape(b, config=COARSER_SHAPES)
    return sa, sb, hope_rs.match(sa, sb, config=COARSER)


@pytest.mark.slow
def test_multiscale_match_refines_a_lifted_coarse_match(coarser_match):
    sa, sb, res = coarser_match
    ca, cb = sa.coarse_level()[0], sb.coarse_level()[0]
    assert res.coarse is not None and res.coarse.map.shape == (ca.sites.size,)
    assert res.coarse.map.max() < cb.sites.size
    assert "coarse" in res.timings and "init" not in res.timings
    # Two fine passes at this size (one above 60k vertices): each a global step and
    # k_max..1, then the polish.
    assert M.fine_passes(sa.n_vertices, sb.n_vertices) == 2
    assert M.fine_passes(60_001, sb.n_vertices) == M.fine_passes(sa.n_vertices, 60_001) == 1
    assert 10 < len(res.history) <= 19
    e0 = hope_rs.geodesic_errors(sb, res.init_map).mean()
    e = hope_rs.geodesic_errors(sb, res.map).mean()
    assert e < e0 < 0.06  # measured: 0.034 lifted, 0.018 after the fine pass
    assert e < 0.03


@pytest.mark.slow
def test_multiscale_match_does_not_depend_on_the_numbering(faust_pair, coarser_match):
    a, b = faust_pair
    rng = np.random.default_rng(2)
    a2, pa = renumbered(a, rng)
    b2, pb = renumbered(b, rng)
    base = coarser_match[2]  # match(a, b, config=COARSER), on Shapes made with its settings
    other = hope_rs.match(a2, b2, config=COARSER)
    # a2's vertex i is a's vertex pa[i]; the map must follow both relabellings.
    np.testing.assert_array_equal(other.map, np.argsort(pb)[base.map[pa]])


def test_multiscale_takes_an_initial_map(faust_pair):
    a, b = faust_pair
    res = hope_rs.match(a, b, config=COARSER, init=np.arange(a.n_vertices))
    assert res.coarse is not None
    # The coarse copies are clustered differently, so even the true map comes back inexact
    # from the coarse level (measured 0.029), and the fine pass sharpens it (0.011).
    assert hope_rs.geodesic_errors(hope_rs.Shape(b), res.map).mean() < 0.02
    with pytest.raises(ValueError, match="init"):
        hope_rs.match(a, b, config=COARSER, init=np.arange(5))
    with pytest.raises(ValueError, match="unknown descriptor"):
        hope_rs.match(a, b, config=COARSER, init="sift")


@pytest.mark.slow
def test_unless_both_shapes_coarsen_match_takes_the_default_path(faust_pair):
    a, b = faust_pair
    sparse = hope_rs.Mesh(*bumpy_sphere(1500, seed=1))
    assert hope_rs.Shape(sparse, config=COARSER_SHAPES).coarse_level() is None
    assert hope_rs.Shape(a, config=COARSER_SHAPES).coarse_level() is not None
    # The multiscale path alone: the common-resolution stage would match the uneven pairs, and
    # the orient stage's nested matches of the body may take the multiscale path.
    coarser = dataclasses.replace(
        COARSER, resolution=ResolutionConfig(enabled=False), orient=OrientConfig(enabled=False)
    )
    plain_config = coarser.with_options(multiscale=False)
    for x, y in ((sparse, hope_rs.Mesh(*bumpy_sphere(1500, seed=2))), (a, sparse), (sparse, b)):
        plain = hope_rs.match(x, y, config=plain_config)
        multi = hope_rs.match(x, y, config=coarser)
        assert multi.coarse is None and "coarse" not in multi.timings
        np.testing.assert_array_equal(multi.map, plain.map)
    with pytest.raises(ValueError, match="not dense enough"):
        M.coarse_level(hope_rs.Shape(sparse), "shot")


@pytest.fixture
def coarser_files(tmp_path, faust_pair):
    """The FAUST pair as OFF files and a settings file coarsening at the wider spacing (so that
    these 6890-vertex bodies take the multiscale path, as larger meshes do by default)."""
    paths = [tmp_path / "a.off", tmp_path / "b.off", tmp_path / "coarser.toml"]
    for path, m in zip(paths, faust_pair):
        write_off(path, m.vertices, m.faces)
    paths[2].write_text(f"[shape.coarsen]\nspacing = {COARSER_SHAPES.coarsen.spacing}\n")
    return paths


@pytest.mark.slow
def test_cli_multiscale_flag(tmp_path, capsys, coarser_files, coarser_match, monkeypatch):
    import hope_rs.cli.commands

    a, b, settings = coarser_files
    want = coarser_match[2].map  # match(..., config=COARSER): multiscale=True
    out = tmp_path / "map.txt"
    args = ["match", str(a), str(b), "-o", str(out), "--config", str(settings), "--json", "-q"]
    assert main([*args, "--multiscale"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert "coarse" in summary["timings"]
    np.testing.assert_array_equal(np.loadtxt(out, dtype=np.int64), want)
    # Without the flag, large meshes get a hint on stderr (unless --quiet); "large" lowered
    # to two small spheres' size, so that the hint's runs are quick.
    a, b = tmp_path / "s1.off", tmp_path / "s2.off"
    write_off(a, *bumpy_sphere(300, seed=1))
    write_off(b, *bumpy_sphere(300, seed=2))
    monkeypatch.setattr(hope_rs.cli.commands, "HINT_VERTICES", 300)
    assert main(["match", str(a), str(b), "-o", str(tmp_path / "plain.txt")]) == 0
    assert "--multiscale is about 3x faster" in capsys.readouterr().err
    assert main(["match", str(a), str(b), "-o", str(tmp_path / "plain.txt"), "-q"]) == 0
    assert "hint" not in capsys.readouterr().err


@pytest.mark.slow
def test_batch_multiscale_flag_gives_the_maps_of_match(
    tmp_path, capsys, coarser_files, coarser_match
):
    a, b, settings = coarser_files
    want = coarser_match[2].map  # match(..., config=COARSER): multiscale=True
    pairs = tmp_path / "pairs.txt"
    pairs.write_text(f"{a} {b}\n")
    out = tmp_path / "out"
    args = ["batch", str(pairs), "--out", str(out), "--config", str(settings), "--multiscale"]
    assert main([*args, "-q", "-j", "1", "--cache", str(tmp_path / "c")]) == 0
    assert "1 matched" in capsys.readouterr().out
    (got,) = [p for p in out.iterdir() if p.name != MANIFEST]  # the map, beside the manifest
    np.testing.assert_array_equal(np.loadtxt(got, dtype=np.int64), want)


@pytest.mark.slow
def test_the_coarse_match_runs_with_the_callers_settings(faust_pair):
    """The coarse copies are matched with the caller's config (bar multiscale itself and a
    spectral pass the fine level runs): ``shared_faces=False`` holds there too."""
    a, b = faust_pair
    res = hope_rs.match(a, b, config=COARSER.with_options(shared_faces=False, top_k=24))
    assert res.coarse is not None
    assert res.coarse.stage("faces").reason == "turned off (shared_faces=False)"
    assert res.coarse.config.refine.top_k == 24 and not res.coarse.config.multiscale.enabled
    assert not res.coarse.config.spectral.enabled  # the fine shapes take the spectral pass
    assert res.config.refine.max_passes == M.fine_passes(a.n_vertices, b.n_vertices)


@pytest.mark.slow
def test_the_default_path_is_chosen_by_size(faust_pair):
    """``multiscale`` unset: coarse-to-fine above ``auto_vertices`` (lowered here so that the
    6890-vertex bodies count as large), the full path at or below it; ``multiscale=False``
    forces the full path and says so."""
    a, b = faust_pair
    auto = MatchConfig(shape=COARSER_SHAPES)
    assert auto.multiscale.enabled is None
    small = dataclasses.replace(
        auto, multiscale=dataclasses.replace(auto.multiscale, auto_vertices=5000)
    )
    res = hope_rs.match(a, b, config=small, max_passes=1)
    coarse = res.stage("coarse")
    assert coarse.ran and "chosen by size: 6890 vertices > 5000" in coarse.reason
    assert res.coarse is not None
    forced = hope_rs.match(a, b, config=small, max_passes=1, multiscale=False)
    assert res.coarse is not None and forced.coarse is None
    assert "multiscale=False" in forced.stage("coarse").reason
    plain = hope_rs.match(a, b, config=auto, max_passes=1)
    assert plain.coarse is None and "coarse" not in [s.name for s in plain.stages]
    np.testing.assert_array_equal(plain.map, forced.map)


def test_large_fine_levels_take_a_short_pass_and_smaller_seed_patches():
    cfg = hope_rs.MatchConfig()
    ms = cfg.multiscale
    small = M.fine_config(cfg, 20_000, ms.fine_passes_small_vertices)
    assert small.refine.schedule == cfg.refine.schedule
    assert small.refine.max_passes == ms.fine_passes_small
    assert small.finish == cfg.finish
    large = M.fine_config(cfg, 20_000, ms.fine_passes_small_vertices + 1)
    assert large.refine.schedule == ms.fine_schedule == (3, 2, 1)
    assert large.refine.max_passes == ms.fine_passes
    assert large.finish.growth.seed_share == ms.fine_seed_share < cfg.finish.growth.seed_share
    full = dataclasses.replace(cfg, multiscale=dataclasses.replace(ms, fine_schedule=None))
    assert M.fine_config(full, 1, 10**6).refine.schedule == cfg.refine.schedule


def test_the_fine_schedule_is_checked():
    with pytest.raises(ValueError, match="fine_schedule must be None or a non-empty"):
        M.MultiscaleConfig(fine_schedule=(3, 0))
    assert M.MultiscaleConfig(fine_schedule=[2, 1]).fine_schedule == (2, 1)


@pytest.mark.parametrize(
    "flags, enabled",
    [([], None), (["--multiscale"], True), (["--no-multiscale"], False)],
)
def test_the_path_flags_set_the_config_match_and_batch_read(flags, enabled):
    # Default: the path by size; --no-multiscale forces the full path at any size.
    for cmd in (["match", "a.off", "b.off"], ["batch", "pairs.txt", "--out", "maps"]):
        args = build_parser().parse_args([*cmd, *flags])
        assert config_from_args(args).multiscale.enabled is enabled


def test_the_path_flags_exclude_each_other(capsys):
    with pytest.raises(SystemExit) as e:
        main(["match", "a.off", "b.off", "--multiscale", "--no-multiscale"])
    assert e.value.code == 2
    assert "not allowed with argument" in capsys.readouterr().err

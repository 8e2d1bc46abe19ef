"""The command line's exit statuses, one-line errors, early output checks and help texts."""

import json
import os
import re
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from conftest import data_path, unwritable_folder
from meshes import bumpy_sphere_files

import hope_rs
import hope_rs.cli.commands
import hope_rs.geometry.mesh
import hope_rs.matching
from hope_rs.cli.batch_cli import ENVIRONMENT, EXIT_STATUS
from hope_rs.cli.commands import build_parser, main
from hope_rs.geometry.map_io import read_map

README = Path(__file__).resolve().parents[1] / "README.md"
N = 300


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    a, b = bumpy_sphere_files(tmp_path_factory.mktemp("cli"), 2, N)
    return str(a), str(b)


def one_line_error(err: str, status: str = "error") -> str:
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"hope-rs: {status}:"), err
    return lines[0]


def print_help(*args) -> None:
    with pytest.raises(SystemExit) as e:
        build_parser().parse_args([*args, "--help"])
    assert e.value.code == 0


def test_help_documents_exit_statuses_and_the_environment(capsys):
    for args in ([], ["batch"], ["match"]):
        print_help(*args)
        out = capsys.readouterr().out
        for code in (0, 1, 2, 130, 143):
            assert re.search(rf"^\s+{code}\s+\S", out, re.MULTILINE), (args, code)
        for name in ENVIRONMENT:
            assert re.search(rf"^\s+{name}\s+\S", out, re.MULTILINE), (args, name)
    assert set(EXIT_STATUS) == {0, 1, 2, 130, 143}


def test_every_environment_variable_the_readme_names_is_in_the_help():
    text = README.read_text()
    named = set(
        re.findall(r"\b(HOPE_RS_[A-Z_]+|HOPE_NO_SIMD|RAYON_[A-Z_]+|XDG_CACHE_HOME)\b", text)
    )
    assert "HOPE_RS_CACHE" in named and "RAYON_NUM_THREADS" in named
    assert named <= set(ENVIRONMENT), named - set(ENVIRONMENT)


def test_output_checks_come_before_any_work(meshes, tmp_path, monkeypatch, capsys):
    def no_loading(*args, **kwargs):
        raise AssertionError("the meshes were loaded before the output was checked")

    monkeypatch.setattr(hope_rs.geometry.mesh, "load_mesh", no_loading)
    a, b = meshes
    ro = unwritable_folder(tmp_path)
    cases = [
        (
            tmp_path / "missing" / "map.txt",
            f"output folder '{tmp_path / 'missing'}' does not exist",
        ),
        (Path(ro) / "map.txt", f"cannot write to output folder '{ro}'"),
        (tmp_path / "map.npz", "unknown suffix '.npz'"),
        (tmp_path, "is a folder"),
        ("", "-o names no file (an empty path)"),
    ]
    for out, message in cases:
        assert main(["match", a, b, "-o", str(out), "-q"]) == 2
        line = one_line_error(capsys.readouterr().err)
        assert message in line and ".hope-rs-" not in line


def test_match_writes_npy_that_show_reads_and_usual_permissions(meshes, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    a, b = meshes
    want = hope_rs.match(hope_rs.load_mesh(a), hope_rs.load_mesh(b)).map
    old = os.umask(0o027)
    try:
        for name in ("map.npy", "map.txt"):
            assert main(["match", a, b, "-o", str(tmp_path / name), "-q"]) == 0
            assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o640
    finally:
        os.umask(old)
    np.testing.assert_array_equal(np.load(tmp_path / "map.npy"), want)
    np.testing.assert_array_equal(read_map(tmp_path / "map.txt", N, N), want)
    png = tmp_path / "m.png"
    assert main(["show", a, b, str(tmp_path / "map.npy"), "--png", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"
    (tmp_path / "short.txt").write_text("1\n2\n")
    assert main(["show", a, b, str(tmp_path / "short.txt"), "--png", str(png)]) == 2
    assert "short.txt' has 2 entries but A has 300" in one_line_error(capsys.readouterr().err)


def test_show_without_matplotlib_prints_the_install_hint(meshes, tmp_path):
    a, b = meshes
    (tmp_path / "m.txt").write_text("0\n" * N)
    code = (
        "import sys; sys.modules['matplotlib'] = None\n"
        "from hope_rs.cli import main\n"
        f"sys.exit(main(['show', {a!r}, {b!r}, {str(tmp_path / 'm.txt')!r}, "
        f"'--png', {str(tmp_path / 'x.png')!r}]))"
    )
    package_root = str(Path(hope_rs.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": package_root}
    res = subprocess.run(
        [sys.executable, "-c", code], check=False, env=env, capture_output=True, text=True
    )
    assert res.returncode == 2
    assert res.stderr == "hope-rs: error: hope-rs show needs matplotlib: pip install matplotlib\n"
    assert not (tmp_path / "x.png").exists()


def test_unexpected_errors_runtime_failures_and_ctrl_c(meshes, tmp_path, monkeypatch, capsys):
    a, b = meshes

    def boom(*args, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr(hope_rs.cli.commands, "match", boom)
    monkeypatch.delenv("HOPE_RS_DEBUG", raising=False)
    assert main(["match", a, b, "-q"]) == 1
    line = one_line_error(capsys.readouterr().err, "internal error")
    assert "RuntimeError: boom" in line and "HOPE_RS_DEBUG=1" in line
    monkeypatch.setenv("HOPE_RS_DEBUG", "1")
    assert main(["match", a, b, "-q"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and "RuntimeError: boom" in err
    monkeypatch.delenv("HOPE_RS_DEBUG")

    def too_large(*args, **kwargs):
        raise MemoryError("the k-hop balls need 1.2 TiB")

    monkeypatch.setattr(hope_rs.cli.commands, "match", too_large)
    assert main(["match", a, b, "-q"]) == 1
    assert (
        capsys.readouterr().err == "hope-rs: error: out of memory: the k-hop balls need 1.2 TiB\n"
    )

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(hope_rs.cli.commands, "match", interrupted)
    assert main(["match", a, b, "-q"]) == 130
    assert capsys.readouterr().err == "hope-rs: interrupted\n"
    monkeypatch.undo()

    def disk_full(files):
        raise OSError(28, "No space left on device", str(files[0][0]))

    monkeypatch.setattr(hope_rs.cli.commands, "atomic_writes", disk_full)
    assert main(["match", a, b, "-q", "-o", str(tmp_path / "m.txt")]) == 1
    assert "No space left on device" in one_line_error(capsys.readouterr().err)


def test_usage_errors_exit_2(meshes, tmp_path, capsys):
    a, _ = meshes
    with pytest.raises(SystemExit) as e:
        main(["match", a])  # argparse: a missing argument
    assert e.value.code == 2
    capsys.readouterr()
    pairs = tmp_path / "p.txt"
    pairs.write_text(f"{a} {a} {a} {a}\n")
    assert main(["batch", str(pairs), "--out", str(tmp_path / "o")]) == 2
    assert "p.txt:1: expected two mesh paths" in one_line_error(capsys.readouterr().err)
    pairs.write_text(f"{a} {a} {a}\n")  # a mesh where the landmark file goes
    assert main(["batch", str(pairs), "--out", str(tmp_path / "o")]) == 2
    err = one_line_error(capsys.readouterr().err)
    assert "p.txt:1: a third field names the pair's landmark file" in err
    pairs.write_text(f"{a} {a}\n")
    assert main(["batch", str(pairs), "--out", str(tmp_path / "o"), "-j", "0"]) == 2
    assert "--jobs must be a positive integer" in one_line_error(capsys.readouterr().err)


def _cli(*args: str, stdout=subprocess.PIPE, cwd=None) -> subprocess.CompletedProcess:
    code = "import sys; from hope_rs.cli.commands import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run(
        [sys.executable, "-c", code, *map(str, args)],
        check=False,
        stdout=stdout,
        stderr=subprocess.PIPE,
        cwd=cwd,
    )


def test_the_map_goes_to_dev_stdout_and_a_closed_pipe_ends_quietly(meshes, tmp_path):
    a, b = meshes
    res = _cli("match", a, b, "-q", "-o", "/dev/stdout")
    assert res.returncode == 0, res.stderr
    assert len(res.stdout.split()) == N  # the map, one index per line, on the pipe
    # A reader gone before the output comes (`| head -c 0`): no error message, the status of
    # SIGPIPE.
    code = (
        "import subprocess, sys\n"
        "p = subprocess.Popen(sys.argv[1:], stdout=subprocess.PIPE, stderr=subprocess.PIPE)\n"
        "p.stdout.close()\n"
        "sys.stderr.buffer.write(p.stderr.read()); sys.exit(p.wait())\n"
    )
    cli = "import sys; from hope_rs.cli.commands import main; sys.exit(main(sys.argv[1:]))"
    big = [sys.executable, "-c", cli, "match", a, b, "-q", "--json"]
    res = subprocess.run([sys.executable, "-c", code, *big], capture_output=True, check=False)
    assert res.returncode == 141 and b"Broken pipe" not in res.stderr, res.stderr


def test_settings_files_a_folder_binary_or_with_a_byte_order_mark(meshes, tmp_path, capsys):
    a, b = meshes
    out = tmp_path / "m.txt"
    assert main(["match", a, b, "-q", "-o", str(out), "--config", str(tmp_path)]) == 2
    assert "is a folder" in one_line_error(capsys.readouterr().err)
    binary = tmp_path / "s.toml"
    binary.write_bytes(b"\x82\xff\x00\x93")
    assert main(["match", a, b, "-q", "-o", str(out), "--config", str(binary)]) == 2
    assert "s.toml' is not UTF-8 text" in one_line_error(capsys.readouterr().err)
    for text, says in [
        ("[refine]\nmax_passes = -1\n", "refine.max_passes must be an integer >= 1, got -1"),
        ('[multiscale]\nenabled = "yes"\n', "leaves [multiscale] enabled out"),
    ]:
        (tmp_path / "v.toml").write_text(text)
        assert main(["match", a, b, "-q", "--config", str(tmp_path / "v.toml")]) == 2
        line = one_line_error(capsys.readouterr().err)
        assert f"settings file '{tmp_path / 'v.toml'}'" in line and says in line
    bom = tmp_path / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbf[refine]\nmax_passes = 1\n")
    assert main(["match", a, b, "-q", "-o", str(out), "--config", str(bom)]) == 0
    assert read_map(out).shape == (N,)
    assert not list(tmp_path.glob(".hope-rs-*"))


def test_a_folder_given_as_the_pairs_file(tmp_path, capsys):
    assert main(["batch", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert "is a folder; give the pairs file" in one_line_error(capsys.readouterr().err)


def test_derived_set_commands_check_their_output_folder_first(tmp_path, capsys):
    taken = tmp_path / "file.off"
    taken.write_text("not a folder")
    source = str(data_path("faust_r"))
    for cmd in ("partial-set", "perturb-set", "resolution-set"):
        assert main([cmd, str(taken), "--from", source, "--max-pairs", "1"]) == 2
        assert "exists and is not a folder" in one_line_error(capsys.readouterr().err)
    with pytest.raises(ValueError, match="not a regular file"):
        hope_rs.load_mesh("/dev/null")


def test_derived_sets_are_named_after_the_source_and_never_written_into_it(
    tmp_path, capsys, monkeypatch
):
    source = tmp_path / "spheres"
    (source / "corres").mkdir(parents=True)
    bumpy_sphere_files(source, 2, N)
    for name in ("s0", "s1"):
        (source / "corres" / f"{name}.vts").write_text("1\n2\n3\n")
    (source / "pairs.txt").write_text("s0 s1\n")
    before = sorted(p.relative_to(source) for p in source.rglob("*"))
    for cmd in ("partial-set", "perturb-set", "resolution-set"):
        for out, where in ((source, "is the source"), (source / "sets", "is inside the source")):
            assert main([cmd, str(out), "--from", str(source)]) == 2
            assert f"{where} data set" in one_line_error(capsys.readouterr().err)
    assert sorted(p.relative_to(source) for p in source.rglob("*")) == before
    # "--from ." names the sets after the folder it stands for.
    monkeypatch.chdir(source)
    assert main(["perturb-set", "../out", "--from", ".", "--conditions", "noise02"]) == 0
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["spheres_noise02"]


def test_show_never_writes_over_one_of_its_inputs(tmp_path, capsys):
    # --ply OUT writes OUT_A.ply and OUT_B.ply: an input of that name is refused, unread.
    folder = tmp_path / "in"
    folder.mkdir()
    a, b = (str(p) for p in bumpy_sphere_files(folder, 2, N))
    ply_a = folder / "out_A.ply"
    mesh = hope_rs.load_mesh(a)
    trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).export(ply_a)
    (tmp_path / "m.txt").write_text("0\n" * N)
    before = ply_a.read_bytes()
    code = main(["show", str(ply_a), b, str(tmp_path / "m.txt"), "--ply", str(folder / "out.ply")])
    assert code == 2
    assert "one of the inputs" in one_line_error(capsys.readouterr().err)
    assert ply_a.read_bytes() == before


def test_no_output_file_is_the_standard_output_that_carries_the_json_or_the_map(meshes, tmp_path):
    a, b = meshes
    for args, option in [
        (["-o", "/dev/stdout", "--json"], "-o '/dev/stdout'"),
        (["--confidence-out", "/dev/stdout"], "--confidence-out '/dev/stdout'"),
    ]:
        res = _cli("match", a, b, "-q", *args)
        assert res.returncode == 2 and res.stdout == b""
        assert f"{option} is the standard output" in one_line_error(res.stderr.decode())
    # Standard output redirected to the file -o names: the same file.
    out = tmp_path / "out.txt"
    with open(out, "wb") as fh:
        res = _cli("match", a, b, "-q", "--json", "-o", str(out), stdout=fh)
    assert res.returncode == 2 and out.read_bytes() == b""
    # The map alone on standard output is fine (test above); so is the JSON with -o a file.
    res = _cli("match", a, b, "-q", "--json", "-o", str(tmp_path / "m.txt"))
    assert res.returncode == 0 and "map" not in json.loads(res.stdout)


def test_dash_as_the_output_is_the_standard_output(meshes, tmp_path):
    a, b = meshes
    plain = _cli("match", a, b, "-q", cwd=tmp_path)
    dash = _cli("match", a, b, "-q", "-o", "-", cwd=tmp_path)
    assert dash.returncode == 0 and plain.returncode == 0, dash.stderr
    assert dash.stdout == plain.stdout and len(dash.stdout.split()) == N
    assert not (tmp_path / "-").exists()
    # With --json, standard output carries the summary: '-' is refused as /dev/stdout is.
    res = _cli("match", a, b, "-q", "--json", "-o", "-", cwd=tmp_path)
    assert res.returncode == 2 and res.stdout == b""
    assert "-o '-' is the standard output" in one_line_error(res.stderr.decode())


def test_dev_stdout_redirected_to_a_file_is_written_through_not_replaced(meshes, tmp_path):
    a, b = meshes
    log = tmp_path / "log.txt"
    log.write_text("earlier line\n")
    with open(log, "ab") as fh:  # `>> log.txt`
        res = _cli("match", a, b, "-q", "-o", "/dev/stdout", stdout=fh)
    assert res.returncode == 0, res.stderr
    lines = log.read_text().splitlines()
    assert lines[0] == "earlier line" and len(lines) == 1 + N
    np.testing.assert_array_equal(np.array(lines[1:], dtype=int), read_map_lines(a, b))
    res = _cli("match", a, b, "-q", "-o", "/dev/stdout", stdout=subprocess.DEVNULL)
    assert res.returncode == 0
    # Standard output closed: refused before any work, whether the map goes there or to -o.
    for args in ([], ["-o", "/dev/stdout"], ["--json", "-o", str(tmp_path / "m.txt")]):
        code = "import sys; from hope_rs.cli.commands import main; sys.exit(main(sys.argv[1:]))"
        res = subprocess.run(
            [sys.executable, "-c", code, "match", a, b, "-q", *args],
            stderr=subprocess.PIPE,
            preexec_fn=lambda: os.close(1),  # `>&-`: the command starts without it
        )
        assert res.returncode == 2, res.stderr
        assert "standard output is closed" in res.stderr.decode() or "is not open for writing" in (
            res.stderr.decode()
        )


def read_map_lines(a, b) -> np.ndarray:
    return hope_rs.match(hope_rs.load_mesh(a), hope_rs.load_mesh(b)).map


def test_outputs_are_not_inputs_end_in_no_slash_and_come_whole_or_not_at_all(
    meshes, tmp_path, capsys
):
    a, b = meshes
    clicks = tmp_path / "clicks.txt"
    clicks.write_text("0 0\n5 5\n")
    start = tmp_path / "start.npy"
    np.save(start, np.arange(N))
    inputs = ["--landmarks", str(clicks), "--init-map", str(start)]
    for option, target, message in [
        ("-o", clicks, "one of the inputs"),
        ("-o", a, "one of the inputs"),
        ("--confidence-out", start, "one of the inputs"),
        ("--confidence-out", clicks, "must end in .npy"),
    ]:
        before = Path(target).read_bytes()
        status = main(["match", a, b, "-q", *inputs, option, str(target)])
        assert status == 2 and Path(target).read_bytes() == before
        assert message in one_line_error(capsys.readouterr().err)
    assert main(["match", a, b, "-q", "-o", str(tmp_path / "m.txt") + "/"]) == 2
    assert "so it names a folder" in one_line_error(capsys.readouterr().err)
    assert not (tmp_path / "m.txt").exists()
    with pytest.raises(NotADirectoryError, match="so it names a folder"):
        hope_rs.write_map(str(tmp_path / "m.txt") + "/", [0, 1])
    with pytest.raises(FileNotFoundError, match="names no file"):
        hope_rs.write_map("", [0, 1])
    # The map cannot be written (a full disk): the confidence file is not left alone.
    conf = tmp_path / "conf.npy"
    assert main(["match", a, b, "-q", "-o", "/dev/full", "--confidence-out", str(conf)]) == 1
    assert "No space left on device" in one_line_error(capsys.readouterr().err)
    assert not conf.exists() and not [p for p in tmp_path.iterdir() if p.suffix == ".tmp"]


def test_a_landmark_out_of_range_is_named_by_its_file_and_line(meshes, tmp_path, capsys):
    a, b = meshes
    clicks = tmp_path / "clicks.txt"
    clicks.write_text("# my clicks\n\n0 0\n99999 3\n")
    assert main(["match", a, b, "-q", "--landmarks", str(clicks)]) == 2
    assert f"{clicks}:4: vertex 99999 is not a vertex of A, which has {N}" in one_line_error(
        capsys.readouterr().err
    )
    clicks.write_text("0 0\n0 5\n")
    assert main(["match", a, b, "-q", "--landmarks", str(clicks)]) == 2
    assert f"{clicks}: landmarks contradict each other" in one_line_error(capsys.readouterr().err)
    with pytest.raises(ValueError, match=r"clicks.txt:2: vertex 5 is not a vertex of B"):
        hope_rs.read_landmarks(clicks, n_a=10, n_b=5)


def test_verbosity_adds_up_before_and_after_the_subcommand(meshes, tmp_path, capsys):
    a, b = meshes
    out = str(tmp_path / "m.txt")
    lines = {}
    for v in (["-v", "match"], ["match", "-v"], ["-v", "match", "-v"], ["match", "-vv"]):
        assert main([*v, a, b, "-o", out]) == 0
        lines[" ".join(v)] = len(capsys.readouterr().err.splitlines())
    assert lines["-v match"] == lines["match -v"] < lines["-v match -v"] == lines["match -vv"]


def test_a_starting_map_file_is_the_match_s_start_and_checked_against_the_meshes(
    meshes, tmp_path, monkeypatch, capsys
):
    a, b = meshes
    start = np.random.default_rng(0).integers(0, N, N)
    start_file = tmp_path / "start.txt"
    hope_rs.write_map(start_file, start)
    seen = {}

    def spy(*args, **kwargs):
        seen.update(kwargs)
        return hope_rs.matching.match(*args, **kwargs)

    monkeypatch.setattr(hope_rs.cli.commands, "match", spy)
    out = tmp_path / "map.txt"
    assert main(["match", a, b, "-q", "--init-map", str(start_file), "-o", str(out)]) == 0
    np.testing.assert_array_equal(seen["init"], start)
    assert read_map(out, N, N).shape == (N,)
    # Without it, the settings' descriptors.
    assert main(["match", a, b, "-q", "--init", "wks", "-o", str(out)]) == 0
    assert seen["init"] is None and seen["config"].initial.descriptor == "wks"
    capsys.readouterr()
    # Both at once, a map of another length, an index beyond B: one line each, nothing written.
    out.unlink()
    cases = [
        (["--init", "wks", "--init-map", str(start_file)], "give --init"),
        (["--init-map", str(tmp_path / "none.txt")], "no such map file"),
    ]
    hope_rs.write_map(tmp_path / "short.txt", start[:-1])
    cases.append((["--init-map", str(tmp_path / "short.txt")], f"has {N - 1} entries but A has"))
    (tmp_path / "far.txt").write_text("\n".join(["0"] * (N - 1) + [str(N)]) + "\n")
    cases.append((["--init-map", str(tmp_path / "far.txt")], f"B has {N} vertices"))
    for extra, why in cases:
        assert main(["match", a, b, "-q", *extra, "-o", str(out)]) == 2
        assert why in one_line_error(capsys.readouterr().err)
        assert not out.exists()


def test_quiet_keeps_the_warning_that_a_match_likely_failed(meshes, tmp_path, capsys):
    """-q removes the progress bar and hints, not the warning about the map: a single
    triangle against a sphere cannot be matched confidently."""
    tri = tmp_path / "tri.off"
    tri.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    for quiet in ([], ["-q"]):
        assert main(["match", str(tri), meshes[0], "-o", str(tmp_path / "m.txt"), *quiet]) == 0
        err = capsys.readouterr().err
        assert "hope-rs: warning: this match likely failed" in err, (quiet, err)

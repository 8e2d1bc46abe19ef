"""``hope-rs batch`` killed with SIGKILL: the maps written are whole, no worker outlives it, and
a rerun finishes the rest. Each batch runs as a subprocess whose environment carries a tag, so
every process it starts (pool workers, Ray's processes) can be found in /proc afterwards."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import pytest
from meshes import bumpy_sphere, write_off

import hope_rs
from hope_rs.geometry.map_io import read_map

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc"),
]

N, SHAPES = 1000, 4
TAG = "HOPE_RS_TEST_BATCH_TAG"


@pytest.fixture(scope="module")
def pairs_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("kill")
    for s in range(SHAPES):
        write_off(d / f"s{s}.off", *bumpy_sphere(N, 20 + s))
    lines = [f"s{i} s{j}" for i in range(SHAPES) for j in range(i + 1, SHAPES)]
    (d / "pairs.txt").write_text("\n".join(lines) + "\n")
    return d / "pairs.txt", len(lines)


@pytest.fixture(scope="module")
def many_pairs_file(tmp_path_factory):
    """Every pair of 8 shapes (28): a batch that cannot finish while a busy test process
    notices its first map."""
    d = tmp_path_factory.mktemp("many")
    for s in range(8):
        write_off(d / f"s{s}.off", *bumpy_sphere(N, 40 + s))
    lines = [f"s{i} s{j}" for i in range(8) for j in range(i + 1, 8)]
    (d / "pairs.txt").write_text("\n".join(lines) + "\n")
    return d / "pairs.txt", len(lines)


#: ``hope-rs`` with SIGINT back to Python's handler first: a shell without job control starts
#: background jobs (a test suite run with ``&``) with SIGINT ignored, and Python would keep
#: ignoring it, so Ctrl-C would do nothing.
CLI_WITH_SIGINT = (
    "import runpy, signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
    "runpy.run_module('hope_rs.cli', run_name='__main__', alter_sys=True)"
)


def tagged(tag: str) -> list[str]:
    """Processes whose environment carries ``tag``: the batch and everything it started."""
    found = []
    for p in Path("/proc").iterdir():
        if not p.name.isdigit():
            continue
        try:
            env = (p / "environ").read_bytes()
            if f"{TAG}={tag}".encode() in env.split(b"\0"):
                cmd = (p / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
                if (p / "stat").read_text().split(")")[-1].split()[0] != "Z":  # not a zombie
                    found.append(f"{p.name} {cmd[:100]}")
        except OSError:  # ended meanwhile, or not ours
            continue
    return found


def batch_command(pairs, out, cache, jobs, extra=()):
    return [sys.executable, "-m", "hope_rs.cli", "batch", str(pairs), "--ext", ".off",
            "--out", str(out), "-j", str(jobs), "-q", "--cache", str(cache), *extra]  # fmt: skip


def environment(tag=None):
    package_root = str(Path(hope_rs.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([package_root, os.environ.get(
        "PYTHONPATH", "")])}  # fmt: skip
    if tag:
        env[TAG] = tag
    return env


def kill_after_first_map(
    cmd, out: Path, tag: str, timeout: float = 600, *, scratch: Path | None = None
) -> list[Path]:
    """Start ``cmd``, SIGKILL it as soon as a map file appears; the maps present after. Its
    temporary folders, which a killed process cannot remove, go in ``scratch`` (by default
    ``out``'s parent / "tmp")."""
    scratch = scratch or out.parent / "tmp"
    scratch.mkdir(exist_ok=True)
    env = {**environment(tag), "TMPDIR": str(scratch)}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    t0 = time.monotonic()
    try:
        while not list(out.glob("*.txt")):
            if proc.poll() is not None:
                pytest.fail(f"the batch ended before writing a map: {proc.communicate()}")
            if time.monotonic() - t0 > timeout:
                pytest.fail("no map file appeared")
            time.sleep(0.02)
        workers = [w for w in tagged(tag) if not w.startswith(f"{proc.pid} ")]
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.kill()
        proc.communicate()
    assert workers or "-j 1" in " ".join(cmd), "found none of the batch's workers to watch"
    return sorted(out.glob("*.txt"))


def assert_no_survivors(tag: str, grace: float) -> None:
    t0 = time.monotonic()
    while tagged(tag) and time.monotonic() - t0 < grace:
        time.sleep(0.2)
    assert tagged(tag) == [], "processes of the killed batch are still alive"


def assert_whole(maps) -> None:
    for m in maps:
        assert read_map(m, N, N).shape == (N,)
        assert m.read_bytes().endswith(b"\n")


@pytest.mark.parametrize("jobs", [1, 2])
def test_sigkill_keeps_the_finished_maps_and_leaves_no_worker(pairs_file, tmp_path, jobs):
    pairs, total = pairs_file
    out, cache, tag = tmp_path / "out", tmp_path / "cache", uuid.uuid4().hex
    cmd = batch_command(pairs, out, cache, jobs)
    done = kill_after_first_map(cmd, out, tag)
    assert 1 <= len(done) < total  # maps appear one by one, not all at the end
    assert_whole(done)
    assert_no_survivors(tag, grace=10)
    rerun = subprocess.run(
        cmd, check=False, env=environment(), capture_output=True, text=True, timeout=900
    )
    assert rerun.returncode == 0, rerun.stderr
    k = len(done)
    assert f"{total} pairs: {total - k} matched, {k} skipped, 0 failed" in rerun.stdout
    assert_whole(sorted(out.glob("*.txt")))
    assert len(list(out.glob("*.txt"))) == total


def test_sigkill_of_a_ray_driver_leaves_no_ray_process(pairs_file, tmp_path):
    pytest.importorskip("ray")
    pairs, _ = pairs_file
    out, tag = tmp_path / "out", uuid.uuid4().hex
    cmd = batch_command(pairs, out, tmp_path / "cache", 1, ["--backend", "ray"])
    cmd.remove("-j")
    cmd.remove("1")
    # A short folder: Ray's socket paths under it must stay within 107 bytes.
    short = Path(tempfile.mkdtemp(prefix="hr-"))
    try:
        done = kill_after_first_map(cmd, out, tag, scratch=short)
        assert_whole(done)
        # Ray's fate sharing ends the instance it started; its agents poll for the lost
        # raylet, slowly when the machine is busy.
        assert_no_survivors(tag, grace=240)
    finally:
        shutil.rmtree(short, ignore_errors=True)


def test_ctrl_c_of_a_pool_batch_prints_the_summary_and_ends_its_workers(many_pairs_file, tmp_path):
    pairs, total = many_pairs_file
    out, tag = tmp_path / "out", uuid.uuid4().hex
    cmd = batch_command(pairs, out, tmp_path / "cache", 2)
    cmd[1:3] = ["-c", CLI_WITH_SIGINT]  # instead of "-m hope_rs.cli"
    # A terminal's Ctrl-C sends SIGINT to the whole foreground process group.
    proc = subprocess.Popen(
        cmd, env=environment(tag), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True,
    )  # fmt: skip
    try:
        while not list(out.glob("*.txt")) and proc.poll() is None:
            time.sleep(0.02)
        os.killpg(proc.pid, signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)  # not after the running pairs finish
    finally:
        proc.kill()
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "rerun the same command" in stderr
    done = sorted(out.glob("*.txt"))
    # The summary counts the pairs that finished before the interrupt; a map written as Ctrl-C
    # landed is kept but can be left out of the count (a rerun skips it once its manifest line
    # is written, else computes it again).
    counted = [
        k for k in (len(done), len(done) - 1)
        if f"{total} pairs: {k} matched, 0 skipped, 0 failed, {total - k} not run (interrupted)"
        in stdout
    ]  # fmt: skip
    assert counted, stdout
    assert_whole(done)
    assert_no_survivors(tag, grace=5)


def test_sigterm_of_a_batch_cleans_up_like_ctrl_c(many_pairs_file, tmp_path):
    """``kill``, ``timeout`` or a scheduler send SIGTERM to the batch's process: it stops as
    after Ctrl-C (the summary, its workers ended, the throw-away cache and the marks folder
    removed) and exits with 143."""
    pairs, total = many_pairs_file
    out, tag, tmp = tmp_path / "out", uuid.uuid4().hex, tmp_path / "tmp"
    tmp.mkdir()
    cmd = [sys.executable, "-m", "hope_rs.cli", "batch", str(pairs), "--ext", ".off",
           "--out", str(out), "-j", "2", "-q", "--no-cache"]  # fmt: skip
    proc = subprocess.Popen(
        cmd, env={**environment(tag), "TMPDIR": str(tmp)}, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        while not list(out.glob("*.txt")) and proc.poll() is None:
            time.sleep(0.02)
        assert list(tmp.iterdir()), "the batch made no temporary folder to clean up"
        os.kill(proc.pid, signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 143, stderr
    assert "Traceback" not in stderr and "rerun the same command" in stderr
    assert f"{total} pairs: " in stdout and "(interrupted)" in stdout
    assert_whole(sorted(out.glob("*.txt")))
    assert_no_survivors(tag, grace=5)
    assert list(tmp.iterdir()) == []


def test_a_killed_worker_fails_at_most_its_pair_and_the_batch_finishes(pairs_file, tmp_path):
    """As the out-of-memory killer would: one worker of a running pool batch gets SIGKILL. The
    pool is restarted; every pair ends matched, or failed when it was the one being matched."""
    pairs, total = pairs_file
    out, tag = tmp_path / "out", uuid.uuid4().hex
    cmd = batch_command(pairs, out, tmp_path / "cache", 2)
    proc = subprocess.Popen(
        cmd, env=environment(tag), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        while not list(out.glob("*.txt")) and proc.poll() is None:
            time.sleep(0.02)
        # pool workers run spawn_main (the resource tracker, also tagged, does not)
        workers = [int(w.split()[0]) for w in tagged(tag) if "spawn_main" in w]
        assert workers, "found none of the batch's workers"
        os.kill(workers[0], signal.SIGKILL)
        stdout, stderr = proc.communicate(timeout=600)
    finally:
        proc.kill()
    assert proc.returncode in (0, 1), stderr
    assert "Traceback" not in stderr
    failed = stderr.count("hope-rs: pair failed:")
    assert failed <= 1 and (failed == 0) == (proc.returncode == 0)
    if failed:
        assert "worker process died" in stderr
    assert (
        f"{total} pairs: {total - failed} matched, 0 skipped, {failed} failed, 0 not run" in stdout
    )
    assert_whole(sorted(out.glob("*.txt")))
    assert len(list(out.glob("*.txt"))) == total - failed
    assert_no_survivors(tag, grace=5)

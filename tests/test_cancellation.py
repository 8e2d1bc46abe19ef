"""Background work of ``match`` (eigenbases, early ZoomOut) ends on every exit path."""

import dataclasses
import io
import os
import select
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse.linalg as sla
from meshes import bumpy_sphere, write_off
from threadpoolctl import threadpool_info

import hope_rs
from hope_rs import MatchConfig, matching
from hope_rs._cancel import Cancelled
from hope_rs.evaluation.demo import demo_pair
from hope_rs.features.descriptors import (
    _unit_area_laplacian,
    laplacian_basis_as_numbered,
    single_threaded_blas,
)
from hope_rs.geometry.numbering import canonical_mesh
from hope_rs.pipeline import spectral
from hope_rs.pipeline.config import SpectralConfig
from hope_rs.pipeline.progress import ProgressBar

PYTHON_DIR = Path(hope_rs.__file__).resolve().parents[1]


def ours() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name.startswith("hope_rs-")]


def blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


@pytest.fixture(scope="module")
def pair():
    return demo_pair()


class Stop(Exception):
    pass


@pytest.mark.parametrize("exc", [Stop, KeyboardInterrupt])
def test_a_raising_callback_leaves_no_thread_running(pair, exc):
    a, b = (hope_rs.Shape(m) for m in pair)  # fresh shapes: no eigenbasis cached
    seen = []

    def callback(it):
        seen.append(ours())
        raise exc("stop here")

    blas = blas_threads()
    # The identity start makes the first step quick: the eigensolves are still running then.
    with pytest.raises(exc, match="stop here"):
        hope_rs.match(a, b, init=np.arange(a.n_vertices), callback=callback)
    assert seen == [["hope_rs-eigenbases"]], "the scenario needs the solve still running"
    assert ours() == []
    assert blas_threads() == blas  # threadpoolctl's limits restored too


def test_a_raising_callback_ends_the_progress_line(pair, monkeypatch):
    stream = io.StringIO()
    monkeypatch.setattr(matching, "ProgressBar", lambda: ProgressBar(stream, live=True))

    def callback(it):
        raise Stop("stop here")

    with pytest.raises(Stop):
        hope_rs.match(*pair, init=np.arange(pair[0].n_vertices), callback=callback, progress=True)
    assert stream.getvalue().startswith("\rhope_rs") and stream.getvalue().endswith("\n")
    assert ours() == []


def test_an_error_after_early_zoomout_started_stops_it(pair, monkeypatch):
    a, b = (hope_rs.Shape(m) for m in pair)
    # ZoomOut starts after the first step of the last pass; with one pass, that is the first.
    cfg = MatchConfig().with_options(max_passes=1)
    cfg = dataclasses.replace(cfg, spectral=dataclasses.replace(cfg.spectral, early_from_pass=0))
    seen = []

    def callback(it):
        seen.append(ours())
        if len(seen) == 3:  # the global repair, k = 8 (then ZoomOut starts), k = 7
            raise Stop("late")

    with pytest.raises(Stop):
        hope_rs.match(a, b, init=np.arange(a.n_vertices), config=cfg, callback=callback)
    assert "hope_rs-zoomout" in seen[-1]
    assert ours() == []


def test_cancel_stops_the_eigensolve(pair):
    a, b = (hope_rs.Shape(m) for m in pair)
    k = SpectralConfig().k_end
    p = spectral.BasisPrefetch(a, b, k).start()
    p.cancel()  # before the solver's first step: nothing is solved
    assert not p.thread.is_alive()
    assert p.solved == []
    p.finish()
    assert not a.has_spectral_basis(k)


def test_stop_event_raises_cancelled_in_the_solver(pair):
    mesh = canonical_mesh(pair[0])[0]
    stop = threading.Event()
    stop.set()
    with pytest.raises(Cancelled):
        laplacian_basis_as_numbered(mesh, 20, stop=stop)


def test_cancellable_eigensolve_is_bit_identical_to_eigsh(pair):
    mesh = canonical_mesh(pair[0])[0]
    with single_threaded_blas():
        evals, evecs, _ = laplacian_basis_as_numbered(mesh, 30, stop=threading.Event())
        L, M = _unit_area_laplacian(mesh)
        v0 = np.random.default_rng(0).random(mesh.n_vertices)
        e, v = sla.eigsh(L, k=30, M=M, sigma=-1e-8, which="LM", v0=v0)
    order = np.argsort(e)
    np.testing.assert_array_equal(evecs, v[:, order])
    np.testing.assert_array_equal(evals, np.maximum(e[order], 0.0))


# SIGINT first back to Python's handler: a shell without job control starts background jobs
# (a test suite run with `&`) with SIGINT ignored, and Python would keep ignoring it.
CLI_REPORTING_THREADS = """
import atexit, signal, sys, threading
signal.signal(signal.SIGINT, signal.default_int_handler)
names = lambda: sorted(t.name for t in threading.enumerate() if t.name.startswith("hope_rs-"))
atexit.register(lambda: print("threads at exit:", names(), file=sys.stderr))
from hope_rs.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_ctrl_c_in_the_cli_exits_130_at_once(tmp_path):
    import pty

    # Shapes large enough that the match is far from done when the first step reports, however
    # slowly this test gets to read that report on a busy machine.
    for name, seed in zip("ab", (1, 2)):
        write_off(tmp_path / f"{name}.off", *bumpy_sphere(20_000, seed))
    out = tmp_path / "map.txt"
    env = dict(os.environ, PYTHONPATH=str(PYTHON_DIR))
    # The progress line is written only to a terminal: give the child one for stderr.
    master, slave = pty.openpty()
    # `hope-rs match`, reporting at interpreter exit which of its threads are still alive.
    cmd = [sys.executable, "-c", CLI_REPORTING_THREADS, "match", "a.off", "b.off", "-o", str(out)]
    p = subprocess.Popen(
        cmd, cwd=tmp_path, stderr=slave, stdout=subprocess.DEVNULL, env=env
    )  # fmt: skip
    os.close(slave)
    err = b""

    def read(timeout: float) -> bool:
        nonlocal err
        if not select.select([master], [], [], timeout)[0]:
            return False
        try:
            chunk = os.read(master, 4096)
        except OSError:  # the child closed the terminal
            return False
        err += chunk
        return bool(chunk)

    try:
        while b"witnesses" not in err:  # a refinement step has run
            assert read(120), err.decode(errors="replace")
        t0 = time.monotonic()
        p.send_signal(signal.SIGINT)
        while read(60):
            pass
        rc = p.wait(timeout=60)
        elapsed = time.monotonic() - t0
    finally:
        if p.poll() is None:
            p.kill()
        os.close(master)
    text = err.decode(errors="replace")
    assert rc == 130, text
    assert "interrupted" in text
    assert "threads at exit: []" in text, text
    assert "Exception ignored" not in text and "Traceback" not in text, text
    assert not out.exists()
    # Generous: the point is that no solve runs on to its end (a full match takes seconds).
    assert elapsed < 20, elapsed


@pytest.mark.parametrize("where", ["wait", "callback"])
def test_ctrl_c_while_match_waits_for_its_eigenbases_stops_them(monkeypatch, where):
    """Ctrl-C while ``match`` waits for the background eigensolve (the refinement done first),
    or raised by the progress callback told of that wait, stops the solve and waits for its
    thread: none is left running. (In Python < 3.13 an interrupted ``Thread.join`` marks the
    thread as ended, so a second join returned at once.)"""
    # A remeshed pair: its map is not settled after the refinement, so the spectral pass waits.
    a, b = (hope_rs.Shape(m) for m in demo_pair("faust_r_000_001"))
    ended = []

    def slow_solve(self, k, *, stop=None):
        # A solve that outlasts the refinement and stops only when told to.
        assert stop is not None and stop.wait(60), "the solve was never told to stop"
        time.sleep(0.2)  # still running a moment after the flag: a join must wait for it
        ended.append(threading.current_thread().name)
        raise Cancelled("stopped")

    def on_progress(ev):
        if ev.stage == "spectral" and "finishing" in ev.detail:
            if where == "callback":
                raise KeyboardInterrupt
            # The runner now waits for the solve: a real signal interrupts that wait.
            signal.setitimer(signal.ITIMER_REAL, 0.3)

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    monkeypatch.setattr(hope_rs.Shape, "solve_spectral_basis", slow_solve)
    previous = signal.signal(signal.SIGALRM, interrupt)
    try:
        with pytest.raises(KeyboardInterrupt):
            hope_rs.match(a, b, progress=on_progress)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    assert ended == ["hope_rs-eigenbases"]
    assert ours() == []


def test_a_settled_map_does_not_wait_for_the_bases(pair, monkeypatch):
    """No spectral pass follows a settled map, so its eigensolves are stopped, not awaited."""
    made = []

    class Recorded(spectral.BasisPrefetch):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(spectral, "BasisPrefetch", Recorded)
    a, b = (hope_rs.Shape(m) for m in pair)
    res = hope_rs.match(a, b, init=np.arange(a.n_vertices))
    assert res.stage("spectral").ran is False  # settled: no spectral pass follows
    np.testing.assert_array_equal(res.map, np.arange(a.n_vertices))
    assert len(made) == 1 and made[0].stop.is_set()
    assert ours() == []

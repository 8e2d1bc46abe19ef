"""The one-BLAS-thread limit (hope_rs._blas) is shared by the threads inside it: set by every
thread that enters, restored by the last to leave to what the process had before."""

import threading

import threadpoolctl
from meshes import bumpy_sphere

from hope_rs._blas import single_threaded_blas
from hope_rs.features import descriptors as d
from hope_rs.geometry.mesh import Mesh


def blas_threads() -> set[int]:
    return {i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"}


def test_threads_share_the_limit_until_the_last_leaves():
    # Two threads inside, leaving in the other order than they came (as a match's background
    # eigenbasis thread and its caller, or two matches in threads, do). Each thread restoring
    # what it saw on entry left the process's BLAS on one thread for good.
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        before = blas_threads()
        assert before == {2}
        first_in, first_may_leave = threading.Event(), threading.Event()
        seen = {}

        def first():
            with single_threaded_blas():
                first_in.set()
                first_may_leave.wait(10)

        def second():
            first_in.wait(10)
            with single_threaded_blas():
                first_may_leave.set()
                t1.join(10)
                seen["inside, the first gone"] = blas_threads()
            seen["both gone"] = blas_threads()

        t1, t2 = threading.Thread(target=first), threading.Thread(target=second)
        t1.start()
        t2.start()
        t2.join(20)
        assert seen == {"inside, the first gone": {1}, "both gone": before}


def test_nested_entries_and_many_threads_restore_the_process_limit():
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        start = threading.Barrier(8)

        def work():
            start.wait(10)
            for _ in range(50):
                with single_threaded_blas(), single_threaded_blas():
                    assert blas_threads() == {1}

        threads = [threading.Thread(target=work) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(60)
        assert blas_threads() == {2}


def test_a_worker_thread_sets_the_limit_after_the_main_thread_did():
    # threadpoolctl lets only the first thread that changed OpenBLAS's limit change it
    # again: a match in a worker thread after one in the main thread ran on every core
    # (a 5k pair 3x slower).
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        with single_threaded_blas():
            assert blas_threads() == {1}
        assert blas_threads() == {2}
        seen = []

        def work():
            with single_threaded_blas():
                seen.append(blas_threads())
            seen.append(blas_threads())

        t = threading.Thread(target=work)
        t.start()
        t.join(10)
        assert seen == [{1}, {2}]
        with single_threaded_blas():  # and the main thread again after it
            assert blas_threads() == {1}
        assert blas_threads() == {2}


def test_other_threads_can_still_set_their_limits_afterwards():
    # The limit gives threadpoolctl's control back after each change: a user's
    # threadpool_limits in another thread, after a match in a worker, still takes effect.
    from concurrent.futures import ThreadPoolExecutor

    def enter_and_leave():
        with single_threaded_blas():
            pass

    with ThreadPoolExecutor(1) as pool:
        pool.submit(enter_and_leave).result()
        with threadpoolctl.threadpool_limits(limits=1, user_api="blas"):
            assert blas_threads() == {1}
        with single_threaded_blas():
            pass

        def user_limit():
            with threadpoolctl.threadpool_limits(limits=1, user_api="blas"):
                return blas_threads()

        assert pool.submit(user_limit).result() == {1}


def test_spectral_descriptors_solve_on_one_blas_thread(monkeypatch):
    # ARPACK's small dense steps run several times slower on a pool of BLAS threads, and the
    # thread count can move the last bits of the eigenpairs and of the descriptors' product:
    # both run on one thread, whatever the caller's limit.
    seen = []

    def recording(name, fn):
        def wrapper(*args, **kwargs):
            seen.append((name, blas_threads()))
            return fn(*args, **kwargs)

        return wrapper

    monkeypatch.setattr(d.sla, "eigsh", recording("eigsh", d.sla.eigsh))
    monkeypatch.setattr(d, "wks", recording("wks", d.wks))
    monkeypatch.setattr(d, "hks", recording("hks", d.hks))
    mesh = Mesh(*bumpy_sphere(600, seed=0))
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        for kind in ("wks", "hks"):
            d.descriptors(mesh, kind, n_eigen=20)
        evals, evecs = d.laplacian_eigenpairs(mesh, 20)
        for kind in ("wks", "hks"):  # the batch cache's path, from cached eigenpairs
            d.spectral_descriptors(kind, evals, evecs, mesh)
        assert blas_threads() == {2}
    assert seen == [
        ("eigsh", {1}), ("wks", {1}), ("eigsh", {1}), ("hks", {1}), ("eigsh", {1}),
        ("wks", {1}), ("hks", {1}),
    ]  # fmt: skip

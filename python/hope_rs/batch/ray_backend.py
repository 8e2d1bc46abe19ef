"""Running a batch on a Ray cluster (optional: ``pip install 'hope-rs[ray]'``).

The same tasks as the local pool, as Ray tasks. Nodes need not share a disk: a prepare task
returns the shape's arrays (mesh and descriptors) into Ray's object store and the pair tasks
receive them from there; each node still uses its own on-disk cache for the prepare step. Maps
come back to the driver, which writes them.

A local Ray instance that the batch starts itself (no cluster running, no ``address``) is shut
down on every exit path the driver lives through: the end of the batch, an error, Ctrl-C
(``close``, which also cancels the running tasks), and interpreter exit (``atexit``). A driver
killed with SIGKILL runs none of them; Ray's fate sharing then ends the instance it started
(``gcs_server``, ``raylet``, its agents and workers notice and exit on their own, which can
take a minute or more on a loaded machine). On a cluster the
batch connected to, Ray ends the tasks of a dead driver's job and the cluster stays up.
"""

from __future__ import annotations

import atexit
import contextlib
import signal

from .._terminate import keep_sigterm
from .tasks import pair_task, prepare_task


def _require_ray():
    try:
        import ray
    except ImportError:
        raise ValueError(
            "the Ray backend needs Ray: pip install 'hope-rs[ray]' (or pip install ray)"
        ) from None
    return ray


def _prepare_split(spec, cache_root, kinds):
    """Prepare task with two results: small metadata (waited on by the driver) and the arrays
    (left in the object store for the pair tasks)."""
    out = prepare_task(spec, cache_root, kinds, True)
    return out, out.pop("data", None)


class RayBackend:
    """Submit batch tasks to Ray.

    Parameters
    ----------
    address : str, optional
        Cluster to connect to when Ray is not initialised yet (``ray.init(address=...)``; None
        starts or finds a local instance as ``ray.init()`` does).
    cpus_per_pair : int
        CPUs reserved per task; also the Rust kernels' thread count inside it.
    """

    ships_data = True

    def __init__(self, address: str | None = None, cpus_per_pair: int = 1):
        ray = _require_ray()
        self._started = not ray.is_initialized()
        if self._started:
            before = signal.getsignal(signal.SIGTERM)
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
            keep_sigterm(before)  # ray's own handler exits without the batch's cleanup
            atexit.register(self._shutdown)
        self.ray = ray
        self.threads = int(cpus_per_pair)
        env = {"env_vars": {"RAYON_NUM_THREADS": str(self.threads)}}
        self._prepare = ray.remote(num_cpus=self.threads, num_returns=2, runtime_env=env)(
            _prepare_split
        )
        self._pair = ray.remote(num_cpus=self.threads, runtime_env=env)(pair_task)
        self._data: dict = {}
        self._pending: set = set()  # submitted and not yet returned by wait

    def submit(self, fn, *args):
        if fn is prepare_task:
            spec, cache_root, kinds = args[:3]  # the arrays travel with the tasks: no basis
            meta, data = self._prepare.remote(spec, cache_root, kinds)
            self._data[meta] = data
            self._pending.add(meta)
            return meta
        ref = self._pair.remote(*args)
        self._pending.add(ref)
        return ref

    def wait(self, handles):
        ready, _ = self.ray.wait(list(handles), num_returns=1)
        out = []
        for h in ready:
            self._pending.discard(h)
            try:
                value = self.ray.get(h)
            except Exception as e:  # noqa: BLE001 - the task's worker died
                value = {"error": f"Ray task failed: {type(e).__name__}: {e}"}
            if h in self._data:
                data = self._data.pop(h)
                if "error" not in value:
                    value = {**value, "token": data}
            out.append((h, value))
        return out

    def _shutdown(self) -> None:
        if self._started:  # a Ray instance this batch started ends with it
            self._started = False
            self.ray.shutdown()

    def close(self, abort: bool = False):
        """End the batch: drop the shipped arrays; shut down the Ray instance if this backend
        started it (with ``abort``, running tasks are cancelled first)."""
        if abort:
            for ref in list(self._pending):
                with contextlib.suppress(Exception):  # finished already, or its worker is gone
                    self.ray.cancel(ref, force=True)
        self._pending.clear()
        self._data.clear()
        self._shutdown()
        atexit.unregister(self._shutdown)

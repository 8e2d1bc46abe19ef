"""Running a batch on a Ray cluster (optional: ``pip install 'hope-rs[ray]'``).

The same tasks as the local pool, as Ray tasks. Nodes need not share a disk: a prepare task
returns the shape's arrays (mesh and descriptors) into Ray's object store and the pair tasks
receive them from there; each node still uses its own on-disk cache for the prepare step. Maps
come back to the driver, which writes them.
"""

from __future__ import annotations


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
    from .batch import prepare_task

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
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
        self.ray = ray
        self.threads = int(cpus_per_pair)
        env = {"env_vars": {"RAYON_NUM_THREADS": str(self.threads)}}
        self._prepare = ray.remote(num_cpus=self.threads, num_returns=2, runtime_env=env)(
            _prepare_split
        )
        from .batch import pair_task

        self._pair = ray.remote(num_cpus=self.threads, runtime_env=env)(pair_task)
        self._data = {}

    def submit(self, fn, *args):
        from .batch import prepare_task

        if fn is prepare_task:
            spec, cache_root, kinds = args[:3]  # the arrays travel with the tasks: no basis
            meta, data = self._prepare.remote(spec, cache_root, kinds)
            self._data[meta] = data
            return meta
        return self._pair.remote(*args)

    def wait(self, handles):
        ready, _ = self.ray.wait(list(handles), num_returns=1)
        out = []
        for h in ready:
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

    def close(self):
        self._data.clear()
        if self._started:  # a Ray instance this batch started ends with it
            self.ray.shutdown()

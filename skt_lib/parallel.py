"""One small per-item executor with two backends.

``local``: a process pool on this machine (in-process when ``n_workers == 1``).
``dask``:  a Dask distributed cluster (``scheduler_address``) or a LocalCluster.

Results come back in input order; each task must derive its randomness from its item
(see :mod:`skt_lib.seeding`), so results do not depend on backend or worker count.
Task functions must be importable top-level functions (they are pickled to workers).
"""

from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import TypeVar

from skt_lib.config import ComputeParams

T = TypeVar("T")
R = TypeVar("R")


def map_items(
    fn: Callable[[T], R],
    items: Sequence[T],
    compute: ComputeParams,
    on_done: Callable[[int, R], None] | None = None,
) -> list[R]:
    """Apply ``fn`` to every item; ``on_done(i, result)`` is called in this process as item
    ``i`` finishes (in completion order: e.g. to save it, see :mod:`skt_lib.resume`).

    An exception raised by ``fn`` propagates (tasks should turn expected per-item failures
    into return values themselves).
    """
    items = list(items)
    if compute.backend == "dask":
        return _map_dask(fn, items, compute, on_done)
    if compute.n_workers == 1 or len(items) <= 1:
        out = []
        for i, item in enumerate(items):
            out.append(fn(item))
            if on_done:
                on_done(i, out[-1])
        return out
    results: list = [None] * len(items)
    with ProcessPoolExecutor(max_workers=min(compute.n_workers, len(items))) as pool:
        futures = {pool.submit(fn, item): i for i, item in enumerate(items)}
        for fut in as_completed(futures):
            i = futures[fut]
            results[i] = fut.result()
            if on_done:
                on_done(i, results[i])
    return results


def _map_dask(fn, items, compute: ComputeParams, on_done):
    from distributed import Client, LocalCluster, as_completed as dask_completed

    cluster = None
    if compute.scheduler_address:
        client = Client(compute.scheduler_address)
    else:
        cluster = LocalCluster(
            n_workers=compute.n_workers, threads_per_worker=1, processes=True,
            dashboard_address=None,
        )
        client = Client(cluster)
    try:
        futures = client.map(fn, items, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        results: list = [None] * len(items)
        for fut in dask_completed(futures):
            i = index[fut.key]
            results[i] = fut.result()
            if on_done:
                on_done(i, results[i])
        return results
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


class Failed:
    """The value of an item whose work failed in an expected way (see :func:`capture`)."""

    __slots__ = ("reason", "message")

    def __init__(self, reason: str, message: str):
        self.reason, self.message = reason, message

    def __repr__(self) -> str:
        return f"Failed({self.reason!r}, {self.message!r})"


def capture(fn: Callable[[T], R], item: T) -> "R | Failed":
    """Run ``fn(item)``; expected failures (:class:`~skt_lib.errors.SktError`) become a
    :class:`Failed` value, anything else (a bug) propagates. Use with
    ``functools.partial(capture, fn)`` as the task of :func:`map_items`."""
    from skt_lib.errors import ItemFailure, SktError

    try:
        return fn(item)
    except ItemFailure as err:
        return Failed(err.reason, str(err))
    except SktError as err:
        return Failed(type(err).__name__, str(err))

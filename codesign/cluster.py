"""A design's independent pieces spread over the dask cluster it runs in, or done in turn.

``compare run --executor dask...`` sends whole runs (or batches of them) to a
cluster's workers as tasks. A large design holds pieces that do not depend on
each other: localized SLS's columns, the members of a learned ensemble trained
by the fused engine, the scoring of each design of a learned batch. Run as a
task of a dask cluster, such a design submits its pieces as tasks of their own
(:func:`spread`), seceding from its worker slot while they run, so that a
thousand-node design uses every worker of the cluster and not one. Elsewhere
(a local process pool, a notebook) :func:`spread` does them in turn. Either way
the pieces are the same computations, so the numbers are the same to the last
bit: a piece is spread only where that holds.
"""

from __future__ import annotations

__all__ = ["SPREAD_ABOVE", "cluster_client", "spread"]

#: States above which a learned model's training or a design's scoring is spread: each then
#: takes tens of seconds (a GRNN's scoring at N = 1000: about 30 s), long beside a task's
#: overhead and the transfer of its instance (8 MB for A at N = 1000).
SPREAD_ABOVE = 200


def cluster_client():
    """``distributed.worker_client`` where this code runs as a task of a dask cluster, else None."""
    try:
        from distributed import get_worker, worker_client
    except ImportError:
        return None
    try:
        get_worker()
    except ValueError:  # not in a dask worker
        return None
    return worker_client


def spread(function, items, *, shared: tuple = ()) -> tuple[list, int]:
    """``[function(*shared, item) for item in items]``, and the number of tasks that computed it.

    In a dask worker with more than one item, each item is a task of the cluster
    and ``shared`` is sent to every worker once (scattered); elsewhere the items
    are computed here in turn (one task). ``function`` must be importable by the
    workers (a module-level function).
    """
    items = list(items)
    client_of = cluster_client() if len(items) > 1 else None
    if client_of is None:
        return [function(*shared, item) for item in items], 1
    with client_of() as client:
        scattered = client.scatter(list(shared), broadcast=True) if shared else []
        # Scattered, not embedded in the task: a piece can hold megabytes (a model's plant).
        futures = [client.submit(function, *scattered, piece, pure=False) for piece in client.scatter(items)]
        return client.gather(futures), len(items)

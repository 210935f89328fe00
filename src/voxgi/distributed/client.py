"""The Dask client a distributed solve or render is given, and its workers."""

from __future__ import annotations

_EXTRA_HINT = 'pip install "voxgi[dask]"'


def _require_distributed():
    """Import dask.distributed or raise an ImportError that names the extra."""
    try:
        import distributed
    except ImportError as exc:
        raise ImportError(
            "client=: distributed solving and rendering need Dask's distributed scheduler, "
            f"which is not installed; install the extra with: {_EXTRA_HINT}"
        ) from exc
    return distributed


def check_client(client):
    """Return ``client`` if it is a ``dask.distributed.Client``.

    Raises
    ------
    ImportError
        If dask.distributed is not installed (the message names the extra).
    TypeError
        If ``client`` is not a Client.
    ValueError
        If the client's cluster has no worker.
    """
    distributed = _require_distributed()
    if not isinstance(client, distributed.Client):
        raise TypeError(
            f"client: expected a dask.distributed.Client, an executor or None, got "
            f"{type(client).__name__}"
        )
    return client


def _workers(client) -> dict:
    info = (
        client.scheduler_info(n_workers=-1) if _takes_n_workers(client) else client.scheduler_info()
    )
    workers = info.get("workers", {})
    if not workers:
        raise ValueError("client: the cluster has no worker (start some, or wait for them)")
    return workers


def _takes_n_workers(client) -> bool:
    import inspect

    try:
        return "n_workers" in inspect.signature(client.scheduler_info).parameters
    except (TypeError, ValueError):
        return False

"""Running episodes on Dask: a LocalCluster on this machine (bound to 127.0.0.1) or an
existing scheduler, so a suite runs unchanged on a cluster (Kubernetes, Slurm through
dask-jobqueue, a cloud). The workers need companion installed, as the client has it."""

from __future__ import annotations

import tempfile
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from companion.errors import ConfigError
from companion.sim.runner import EpisodeSpec, default_workers


def check_address(address: str) -> None:
    """A ConfigError unless ``address`` is ``"local"`` or a scheduler address."""
    if address != "local" and not address.startswith(("tcp://", "tls://", "ws://", "wss://")):
        raise ConfigError(f"--dask: expected 'local' or a scheduler address such as "
                          f"tcp://127.0.0.1:8786, got {address!r}")


def run_dask(specs: Sequence[EpisodeSpec], address: str, workers: int | None,
             func: Callable[[EpisodeSpec], Any]) -> Iterator[tuple[int, Any]]:
    """``(index, func(spec))`` for every spec as each finishes on Dask. ``address``:
    ``"local"`` starts a LocalCluster of ``workers`` single-threaded worker processes on
    127.0.0.1 (no dashboard, scratch space in a temporary folder) and stops it after;
    otherwise the address of a running scheduler (``tcp://host:port``)."""
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise ConfigError("--dask: needs dask.distributed (pip install -e '.[dask]')") from None
    check_address(address)
    cluster = None
    with tempfile.TemporaryDirectory(prefix="companion-dask-") as scratch:
        if address == "local":
            cluster = LocalCluster(n_workers=workers or default_workers(), threads_per_worker=1,
                                   processes=True, host="127.0.0.1", dashboard_address=None,
                                   local_directory=scratch)
            client = Client(cluster)
        else:
            try:
                client = Client(address, timeout="30s")
            except (OSError, TimeoutError) as exc:
                raise ConfigError(f"--dask: cannot reach the scheduler at {address}: "
                                  f"{exc}") from None
        try:
            futures = client.map(func, list(specs), pure=False)
            index = {f.key: i for i, f in enumerate(futures)}
            for future in as_completed(futures):
                yield index[future.key], future.result()
        finally:
            client.close()
            if cluster is not None:
                cluster.close()

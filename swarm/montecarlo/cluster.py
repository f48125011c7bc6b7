"""Campaigns on a dask.distributed cluster (``swarm montecarlo --dask tcp://HOST:8786``; extra ``dask``).

:func:`dask_executor` connects to an existing scheduler and hands :func:`~swarm.montecarlo.campaign.
run_campaign` the client's ``concurrent.futures`` executor: the same runs, the same seeds (a run's seed
depends on the root seed and its index only, :func:`~swarm.montecarlo.campaign.run_seed`), so the rows are
those of a local campaign, in another order. Each task is one docking run; a worker lost mid-campaign loses
only the runs it held, which the scheduler gives to another worker (dask's ``allowed-failures``), and the
campaign directory stays resumable as for a local campaign. The workers need this package installed (the
same version: the rows are bit for bit only for the same code), nothing else; each is limited to one BLAS
thread on connection, as the local pool's workers are.
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Iterator

from swarm.errors import ConfigError

try:  # the optional extra; without it --dask says what to install (dask_executor)
    from distributed.diagnostics.plugin import WorkerPlugin
except ImportError:  # pragma: no cover - exercised only without the extra
    WorkerPlugin = object

_ADDRESS = re.compile(r"^(tcp|tls)://[^\s/:]+:\d{1,5}$")


def check_address(address: str) -> str:
    """``address`` if it looks like a scheduler address (``tcp://HOST:PORT`` or ``tls://``), else a
    ConfigError naming it."""
    if not isinstance(address, str) or not _ADDRESS.match(address):
        raise ConfigError(f"--dask must be a scheduler address such as tcp://HOST:8786, got {address!r}")
    port = int(address.rsplit(":", 1)[1])
    if not 1 <= port <= 65535:
        raise ConfigError(f"--dask: port {port} out of range 1..65535 in {address!r}")
    return address


class OneBlasThread(WorkerPlugin):
    """A dask worker plugin: one BLAS thread in each worker (also in one that its nanny restarts), as the
    local pool's ``_init_worker`` gives its workers (BENCHMARKS.md, Monte Carlo: OpenBLAS's own threads
    only spin during a docking run)."""

    name = "swarm-one-blas-thread"
    idempotent = True

    def setup(self, worker) -> None:
        from threadpoolctl import threadpool_limits

        self._limit = threadpool_limits(limits=1)  # kept for the worker's lifetime


@contextlib.contextmanager
def dask_executor(address: str, timeout_s: float = 10.0) -> Iterator:
    """A ``concurrent.futures`` executor on the dask scheduler at ``address`` (closed on exit); a
    ConfigError when the extra is missing or the scheduler cannot be reached within ``timeout_s``."""
    check_address(address)
    try:
        from distributed import Client
    except ImportError:
        raise ConfigError(
            "--dask needs dask.distributed: pip install 'tpods-swarm[dask]' (or distributed)"
        ) from None
    try:
        client = Client(address, timeout=timeout_s, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise ConfigError(f"--dask: cannot reach the scheduler at {address}: {exc}") from None
    try:
        client.register_plugin(OneBlasThread())
        # pure=False: every run is its own task (the default would hash the scenario into the task key)
        with client.get_executor(pure=False) as executor:
            yield executor
    finally:
        client.close()

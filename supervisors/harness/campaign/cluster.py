"""The Ray engine: each job a Ray task, on a Ray cluster or a local Ray instance.

Each job is one task (``num_cpus=1``: a game is one Trio thread) running
`call`, which plays the game in a fresh Trio run, as a pool worker does;
workers are recycled after `RECYCLE_EVERY` tasks, as the pool's are. Results
stream back with ``ray.wait`` as they finish, with at most a few tasks per
CPU in flight (a campaign of a million games never holds a million refs).

Failures, two kinds: a game that fails is a result (`play_campaign_game`
never raises for it), so a task is never retried for what it returned
(``retry_exceptions`` off); a task whose worker process or node died is
retried by Ray up to `INFRA_RETRIES` times, and one lost every time becomes
a result too, with a ``harness.worker_lost`` violation (made by the caller's
``lost`` function), so the campaign goes on and the summary shows it.

Ray is an optional dependency (``pip install 'hideseek[cluster]'``),
imported only when this engine starts.
"""

from __future__ import annotations

import socket
from collections.abc import Callable, Iterable, Iterator
from typing import Any
from urllib.parse import urlsplit

from supervisors.harness.campaign.local import RECYCLE_EVERY, Job, call, default_workers
from supervisors.harness.campaign.refs import CampaignError

INSTALL_HINT = "the ray engine needs Ray: pip install 'hideseek[cluster]' (or pip install ray)"
INFRA_RETRIES = 3           # times Ray reruns a task whose worker or node died
IN_FLIGHT_PER_CPU = 2       # tasks submitted ahead per CPU of the cluster
_CONNECT_TIMEOUT_S = 5.0    # to tell an unreachable address at once [wall s]
_DEFAULT_PORTS = {"ray": 10001, "": 6379}   # Ray Client, and the GCS of `ray start --head`


def _ray() -> Any:
    try:
        import ray  # noqa: PLC0415 - an optional dependency, imported when used
    except ImportError:
        raise CampaignError(INSTALL_HINT) from None
    return ray


def check_reachable(address: str) -> None:
    """Raise a `CampaignError` at once when ``HOST:PORT`` or ``ray://HOST:PORT`` does not answer.

    ``ray.init`` on an address nobody listens at waits and retries for
    minutes; a plain TCP connect says it in seconds. ``auto`` and ``local``
    are Ray's own words and are left to it.
    """
    if address in ("auto", "local"):
        return
    parts = urlsplit(address if "://" in address else f"//{address}")
    try:
        port = parts.port or _DEFAULT_PORTS.get(parts.scheme, 6379)
    except ValueError:
        raise CampaignError(f"--address must be HOST:PORT, ray://HOST:PORT or auto, "
                            f"got {address!r}") from None
    if not parts.hostname:
        raise CampaignError(f"--address must be HOST:PORT, ray://HOST:PORT or auto, "
                            f"got {address!r}")
    try:
        socket.create_connection((parts.hostname, port), timeout=_CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        raise CampaignError(f"cannot reach a Ray cluster at {address!r}: {exc}") from None


class RayEngine:
    """Jobs as Ray tasks; joins a cluster at ``address`` or starts a local instance.

    Args:
        address: a running cluster (``HOST:PORT``, ``ray://HOST:PORT`` or
            ``auto``); None starts a local Ray instance with ``workers`` CPUs
            (or joins the one this process already started).
        workers: CPUs of the local instance (default one per core); ignored
            with an address (the cluster has its own).

    Raises:
        CampaignError: Ray is not installed, or the cluster cannot be reached.
    """

    name = "ray"

    def __init__(self, address: str | None = None, workers: int | None = None) -> None:
        ray = self._rayref = _ray()
        self._started = False
        if address:
            check_reachable(address)
        if not ray.is_initialized():
            options: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False,
                                       "logging_level": "warning"}
            if address:
                options["address"] = address
            else:
                options["num_cpus"] = workers or default_workers()
            try:
                ray.init(**options)
            except (ConnectionError, ValueError, RuntimeError) as exc:
                raise CampaignError(f"cannot start or join Ray ({address or 'local'}): "
                                    f"{exc}") from None
            self._started = True
        self.workers = max(1, int(ray.cluster_resources().get("CPU", 1)))
        self._task = ray.remote(num_cpus=1, max_retries=INFRA_RETRIES, retry_exceptions=False,
                                max_calls=RECYCLE_EVERY)(call)

    def map(self, jobs: Iterable[Job], *,
            lost: Callable[[Job, BaseException], dict[str, Any]] | None = None
            ) -> Iterator[dict[str, Any]]:
        """Run ``jobs`` as tasks; yield each result as it finishes (``ray.wait``).

        Args:
            jobs: the jobs, submitted in this order as slots free up.
            lost: makes the result of a job whose task Ray gave up on (its
                worker or node died every time); None re-raises Ray's error.

        Closing the generator cancels the tasks in flight.
        """
        ray = self._rayref
        window = IN_FLIGHT_PER_CPU * self.workers
        queue = iter(jobs)
        pending: dict[Any, Job] = {}
        try:
            for job in queue:
                pending[self._task.remote(job)] = job
                if len(pending) >= window:
                    break
            while pending:
                (ready,), _ = ray.wait(list(pending), num_returns=1)
                job = pending.pop(ready)
                for more in queue:  # keep the window full
                    pending[self._task.remote(more)] = more
                    break
                try:
                    yield ray.get(ready)
                except ray.exceptions.RayTaskError:
                    raise  # an entry point that raised: a bug, not an infrastructure failure
                except ray.exceptions.RayError as exc:
                    if lost is None:
                        raise
                    yield lost(job, exc)
        finally:
            for ref in pending:
                ray.cancel(ref, force=True)

    def close(self) -> None:
        """Disconnect (and stop the local instance) if this engine started Ray."""
        if self._started:
            self._rayref.shutdown()
            self._started = False

    def __enter__(self) -> RayEngine:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

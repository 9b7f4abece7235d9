"""The sweep's Ray backend: one task per run, on a local Ray instance or a multi-node cluster.

Each run asks for the profile's `cpus_per_run` CPUs (and `gpus_per_run` of a GPU where the
cluster has GPUs, so several small runs share one). A task returns its run's result to the
driver, which alone writes the run store: the nodes need no shared filesystem. On a cluster
(`address`) each node keeps its artifacts in its own `$GCDT_ARTIFACTS` (made there when
needed), or shares them through a storage URI (`gcdt.experiments.storage`); a shared folder
still works: point every node's `$GCDT_ARTIFACTS` at it. A local Ray instance uses the
driver's artifacts folder.

A run whose worker or node dies comes back as a `failed` result (`runner.lost_result`) that the
sweep retries like any other failure; Ray's own retries are off so that one count holds.
"""

from __future__ import annotations

import logging
import socket
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any, Protocol

from gcdt.errors import GcdtError
from gcdt.experiments.runner import lost_result, run_result
from gcdt.paths import artifacts_dir

if TYPE_CHECKING:
    from gcdt.experiments.profiles import Profile


class PlannedRun(Protocol):
    """What a backend needs of a sweep's planned run (`gcdt.experiments.sweep.PlannedRun`):
    its grid entry. The sweep imports this module, never the reverse."""

    @property
    def entry(self) -> Any: ...


RAY_CONNECT_TIMEOUT = 5.0  # seconds to reach a cluster's address before giving up


def check_address(address: str) -> None:
    """Fail within seconds, with the reason, if a Ray address cannot be reached."""
    if address in ("auto", "local"):
        return
    target = address.removeprefix("ray://")
    host, _, port = target.rpartition(":")
    if not host or not port.isdigit():
        raise GcdtError(f"Ray address {address!r} is not HOST:PORT (e.g. 10.0.0.5:6379)")
    try:
        socket.create_connection((host, int(port)), timeout=RAY_CONNECT_TIMEOUT).close()
    except OSError as err:
        raise GcdtError(
            f"cannot reach the Ray cluster at {address} ({err}): start it with `ray start "
            "--head` there, or leave out --address for a local Ray instance"
        ) from None


def check_resources(nodes: list[dict[str, Any]], profile: Profile, address: str) -> None:
    """Raise a `GcdtError` unless some live node of `nodes` (`ray.nodes()`) has the CPUs one
    run of `profile` asks for: its tasks would otherwise wait for ever."""
    largest = max(
        (n["Resources"].get("CPU", 0.0) for n in nodes if n.get("Alive")),
        default=0.0,
    )
    if largest < profile.cpus_per_run:
        raise GcdtError(
            f"the Ray cluster at {address} has no node with the {profile.cpus_per_run} CPU(s) "
            f"one run of profile {profile.name} asks for (cpus_per_run; its largest node has "
            f"{largest:g}): add a worker node with at least {profile.cpus_per_run} CPU(s)"
        )


class RayBackend:
    """Runs on Ray: `submit` each run, then iterate `results` as they finish (more may be
    submitted meanwhile, e.g. retries)."""

    name = "ray"

    def __init__(
        self, profile: Profile, workers: int, address: str | None, storage: str | None
    ) -> None:
        try:
            import ray
        except ImportError:
            raise GcdtError("the ray backend needs Ray: pip install 'ray==2.60.0'") from None
        self._ray = ray
        self._storage = storage
        # A local Ray instance is this machine: its workers use the driver's artifacts folder.
        self._artifacts = str(artifacts_dir().resolve()) if address is None else None
        self._started_here = not ray.is_initialized()
        if self._started_here:
            # Ray's connection chatter would bury the sweep's own one-line messages.
            kwargs: dict[str, Any] = {
                "include_dashboard": False,
                "log_to_driver": False,
                "logging_level": logging.WARNING,
            }
            if address is None:
                kwargs["num_cpus"] = workers * profile.cpus_per_run
            ray.init(address=address, **kwargs)
        try:
            check_resources(ray.nodes(), profile, address or "local")
        except GcdtError:
            self.close()
            raise
        gpus = profile.gpus_per_run if ray.cluster_resources().get("GPU", 0) > 0 else 0
        self._task = ray.remote(num_cpus=profile.cpus_per_run, num_gpus=gpus, max_retries=0)(
            run_result
        )
        self._pending: dict[Any, PlannedRun] = {}

    def submit(self, run: PlannedRun) -> None:
        spec = run.entry.spec.to_dict()
        ref = self._task.remote(
            spec, self.name, artifacts_root=self._artifacts, storage=self._storage
        )
        self._pending[ref] = run

    def results(self) -> Iterator[tuple[PlannedRun, dict[str, Any]]]:
        while self._pending:
            (ready,), _ = self._ray.wait(list(self._pending), num_returns=1)
            run = self._pending.pop(ready)
            try:
                result = self._ray.get(ready)
            except self._ray.exceptions.RayError as err:  # the worker or its node died
                text = str(err).strip()
                error = f"{type(err).__name__}: {text.splitlines()[0] if text else ''}"
                result = lost_result(run.entry.spec.to_dict(), self.name, error, text)
            yield run, result

    def close(self) -> None:
        if self._started_here:
            self._ray.shutdown()

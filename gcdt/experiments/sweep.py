"""Run a profile's grid on a backend, skipping finished runs: `gcdt sweep`.

Backends (both call `runner.execute_run`, so both write the same result files):

* `local` (default): a process pool with one worker per `cpus_per_run` cores;
* `ray`: one Ray task per run with `cpus_per_run` CPUs (and `gpus_per_run` of a GPU where the
  cluster has GPUs, so several small runs share one), on a local Ray instance or, with
  `address`, on an existing cluster. Workers then need the repository and the artifacts
  folder at the same paths (a shared file system).

A sweep reads the store first: runs with a valid `done` result are skipped; failed, missing
and untrusted (corrupt or foreign) results are run. It ends with a summary, and the CLI exits
non-zero when any run failed.
"""

from __future__ import annotations

import multiprocessing
import os
import socket
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gcdt.baselines.tqc_her import RUN_JSON
from gcdt.errors import GcdtError
from gcdt.experiments.costs import CostModel
from gcdt.experiments.grid import GridEntry, build_grid
from gcdt.experiments.profiles import Profile
from gcdt.experiments.runner import execute_run
from gcdt.experiments.store import RunStore
from gcdt.paths import artifacts_dir, results_dir
from gcdt.progress import progress_bar

BACKENDS = ("local", "ray")
RAY_CONNECT_TIMEOUT = 5.0  # seconds to reach a cluster's address before giving up


@dataclass
class PlannedRun:
    entry: GridEntry
    key: str
    state: str  # done / failed / missing / corrupt (before this sweep)
    problem: str | None
    estimate_seconds: float


@dataclass
class SweepSummary:
    profile: str
    planned: list[PlannedRun]
    done: list[str] = field(default_factory=list)  # run by this sweep, succeeded
    failed: list[str] = field(default_factory=list)  # run by this sweep, failed
    skipped: list[str] = field(default_factory=list)  # already done before
    warnings: list[str] = field(default_factory=list)  # corrupt or foreign result files
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return not self.failed

    def line(self) -> str:
        return (
            f"sweep {self.profile}: {len(self.done)} done, {len(self.skipped)} skipped, "
            f"{len(self.failed)} failed ({self.seconds:.0f} s)"
        )


def plan(
    profile: Profile,
    store: RunStore,
    only: str | None = None,
    costs: CostModel | None = None,
    methods: Sequence[str] | None = None,
) -> tuple[list[PlannedRun], list[str]]:
    """Every run of the grid (of section `only`, of `methods`) with its stored state and
    estimated cost; warnings for files that are not trusted (corrupt results, JSON files of no
    run of this grid)."""
    costs = costs or CostModel.measured()
    planned, warnings, trained = [], [], set()
    for entry in build_grid(profile, only):
        if methods is not None and entry.spec.method not in methods:
            continue
        key = entry.spec.key()
        stored = store.read(key)
        if stored.problem:
            warnings.append(f"{stored.problem}: it will be run again")
        # Runs that share a checkpoint (the return-target study's) pay for training once.
        train = entry.spec.method == "tqc" or entry.spec.training_key() not in trained
        trained.add(entry.spec.training_key())
        estimate = costs.estimate(entry.spec, train=train)
        planned.append(PlannedRun(entry, key, stored.state, stored.problem, estimate))
    if only is None and methods is None:
        keys = {p.key for p in planned}
        warnings += [
            f"{p} is not a result of this grid: ignored" for p in store.foreign_files(keys)
        ]
    return planned, warnings


def shared_cost(todo: list[PlannedRun], costs: CostModel | None = None) -> float:
    """Estimated seconds of the collections and TQC experts `todo` needs that do not exist."""
    from gcdt.experiments.artifacts import grid_dir

    costs = costs or CostModel.measured()
    bases, experts = {}, {}
    for p in todo:
        data = p.entry.spec.data
        if data is None:
            continue
        for base in (
            data.base("expert"),
            *(() if data.expert_ratio == 1 else (data.base("random"),)),
        ):
            bases[base.key()] = base
            if base.expert_tqc is not None:
                experts[base.expert_tqc.key()] = base.expert_tqc
    seconds = sum(
        costs.collection(b.size)
        for k, b in bases.items()
        if not (grid_dir() / "datasets" / f"{k}.npz").exists()
    )
    # An expert with a TQC+HER run's values is that run's agent, whose estimate counts it.
    runs = {p.entry.spec.tqc.key() for p in todo if p.entry.spec.tqc is not None}
    for key, spec in experts.items():
        if key not in runs and not (grid_dir() / "tqc" / key / RUN_JSON).exists():
            steps = spec.tqc_config().steps
            seconds += steps * costs.rates.get(f"tqc_step:{spec.config}", 1.0)
    return seconds


def default_workers(profile: Profile) -> int:
    return max(1, (os.cpu_count() or 1) // profile.cpus_per_run)


def sweep(
    profile: Profile,
    *,
    backend: str = "local",
    address: str | None = None,
    only: str | None = None,
    methods: Sequence[str] | None = None,
    workers: int | None = None,
    store_root: str | Path | None = None,
    progress: bool = True,
) -> SweepSummary:
    """Run every run of `profile` (of section `only`, of `methods`) not done yet."""
    if backend not in BACKENDS:
        raise GcdtError(f"unknown backend {backend!r}: expected one of {', '.join(BACKENDS)}")
    if address is not None and backend != "ray":
        raise GcdtError("--address applies only to --backend ray")
    if address is not None:
        _check_address(address)
    store = RunStore(store_root or results_dir(profile.name) / "runs")
    store.remove_partial_files()
    # The estimates matter to --dry-run only: defaults, without reading every result file.
    planned, warnings = plan(profile, store, only, CostModel(), methods=methods)
    summary = SweepSummary(profile.name, planned, warnings=warnings)
    summary.skipped = [p.key for p in planned if p.state == "done"]
    todo = [p for p in planned if p.state != "done"]
    workers = workers or default_workers(profile)
    started = time.perf_counter()
    if todo:
        run = _run_ray if backend == "ray" else _run_local
        bar = progress_bar(
            total=len(todo), desc=f"sweep {profile.name}", unit="run", progress=progress
        )
        try:
            for key, status in run(todo, str(store.root), workers, address, profile):
                (summary.done if status == "done" else summary.failed).append(key)
                bar.update(1)
                bar.set_postfix(failed=len(summary.failed))
        finally:
            bar.close()
    summary.seconds = time.perf_counter() - started
    return summary


def _run_local(
    todo: list[PlannedRun], root: str, workers: int, address: str | None, profile: Profile
):
    """Yield (key, status) as local worker processes finish runs."""
    artifacts = str(artifacts_dir())
    # Spawned, not forked: workers start clean of the driver's torch threads and env state.
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = {
            pool.submit(execute_run, p.entry.spec.to_dict(), root, artifacts, "local"): p.key
            for p in todo
        }
        for future in as_completed(futures):
            try:
                yield futures[future], future.result()
            except BrokenProcessPool:  # a worker died (killed, out of memory): no result file
                yield futures[future], "failed"


def _check_address(address: str) -> None:
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


def _run_ray(
    todo: list[PlannedRun], root: str, workers: int, address: str | None, profile: Profile
):
    """Yield (key, status) as Ray tasks finish runs."""
    artifacts = str(artifacts_dir())
    try:
        import ray
    except ImportError:
        raise GcdtError("the ray backend needs Ray: pip install 'ray==2.60.0'") from None
    started_here = not ray.is_initialized()
    if started_here:
        kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False}
        if address is None:
            kwargs["num_cpus"] = workers * profile.cpus_per_run
        ray.init(address=address, **kwargs)
    try:
        gpus = profile.gpus_per_run if ray.cluster_resources().get("GPU", 0) > 0 else 0
        task = ray.remote(num_cpus=profile.cpus_per_run, num_gpus=gpus, max_retries=0)(execute_run)
        refs = {task.remote(p.entry.spec.to_dict(), root, artifacts, "ray"): p.key for p in todo}
        pending = list(refs)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            try:
                status = ray.get(ready[0])
            except ray.exceptions.RayError:  # the worker died: no result file
                status = "failed"
            yield refs[ready[0]], status
    finally:
        if started_here:
            ray.shutdown()

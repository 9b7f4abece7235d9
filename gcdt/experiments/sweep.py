"""Run a profile's grid on a backend, skipping finished runs: `gcdt sweep`.

Backends (both call `runner.run_result` and hand its result back to this driver, which alone
writes the run store, so both write the same result files):

* `local` (default): a process pool with one worker per `cpus_per_run` cores;
* `ray`: one Ray task per run on a local Ray instance or, with `address`, on a cluster of any
  number of nodes with no shared filesystem (`gcdt.experiments.cluster`).

A sweep reads the store first: runs with a valid `done` result are skipped; failed, missing
and untrusted (corrupt or foreign) results are run. A run that fails (its worker or node lost
included) is tried again up to `retries` times, then recorded as failed with its traceback.
The summary lists the failed runs and the command that re-runs them; the CLI exits non-zero
when any run failed.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import shlex
import signal
import time
from collections import Counter
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gcdt.baselines.tqc_her import RUN_JSON
from gcdt.envs import get_task
from gcdt.errors import GcdtError
from gcdt.experiments.costs import CostModel
from gcdt.experiments.grid import GridEntry, build_grid
from gcdt.experiments.profiles import Profile
from gcdt.experiments.runner import lost_result, run_result
from gcdt.experiments.storage import ArtifactStorage
from gcdt.experiments.store import RunStore
from gcdt.paths import artifacts_dir, results_dir
from gcdt.progress import progress_bar

BACKENDS = ("local", "ray")
#: Times a failed run is tried again within one sweep before it is recorded as failed.
RETRIES = 2


@dataclass
class PlannedRun:
    entry: GridEntry
    key: str
    state: str  # done / failed / missing / corrupt / waiting (before this sweep)
    problem: str | None
    estimate_seconds: float
    done_steps: int = 0  # gradient steps its checkpoint on this machine holds already


@dataclass
class SweepSummary:
    profile: str
    planned: list[PlannedRun]
    done: list[str] = field(default_factory=list)  # run by this sweep, succeeded
    failed: list[str] = field(default_factory=list)  # run by this sweep, failed
    skipped: list[str] = field(default_factory=list)  # already done before
    waiting: list[str] = field(default_factory=list)  # not run: their published agent is not
    warnings: list[str] = field(default_factory=list)  # corrupt or foreign result files
    retried: list[str] = field(default_factory=list)  # "KEY: error" of each failed try retried
    errors: dict[str, str] = field(default_factory=dict)  # failed run -> its error line
    rerun: str = ""  # the command that runs this sweep's failed runs again
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return not self.failed

    def line(self) -> str:
        retried = f", {len(self.retried)} retried" if self.retried else ""
        waiting = f", {len(self.waiting)} waiting" if self.waiting else ""
        return (
            f"sweep {self.profile}: {len(self.done)} done, {len(self.skipped)} skipped, "
            f"{len(self.failed)} failed{retried}{waiting} ({self.seconds:.0f} s)"
        )

    def waiting_lines(self) -> list[str]:
        """One line per published agent that runs wait for, with how many, and what to do."""
        agents = Counter(p.problem for p in self.planned if p.key in self.waiting)
        lines = [f"waiting: {n} runs for {agent}" for agent, n in agents.items()]
        if lines:
            lines.append(
                "publish each finished agent with `gcdt tqc publish RUN_DIR` (or fix the "
                "profile's expert_agents path), then run this sweep again"
            )
        return lines

    def lines(self) -> list[str]:
        """`line()`, then each failed run with its error and the command that re-runs them."""
        if not self.failed:
            return [self.line(), *self.waiting_lines()]
        labels = {p.key: p.entry.spec.label for p in self.planned}
        failed = [f"failed: {k} {labels.get(k, '')}: {self.errors.get(k, '')}" for k in self.failed]
        return [
            self.line(),
            *self.waiting_lines(),
            *failed,
            f"re-run the failed runs (tracebacks in their result files): {self.rerun}",
        ]


def plan(
    profile: Profile,
    store: RunStore,
    only: str | None = None,
    costs: CostModel | None = None,
    methods: Sequence[str] | None = None,
    task: str | None = None,
    checkpoints: bool = True,
) -> tuple[list[PlannedRun], list[str]]:
    """Every run of the grid (of section `only`, of `methods`, of `task`) with its stored state
    and estimated cost, less the steps its checkpoint on this machine holds (without
    `checkpoints`, as on a fresh machine); warnings for files that are not trusted (corrupt
    results, JSON files of no run of this grid)."""
    if task is not None:
        get_task(task)  # an unknown task is refused, not read as an empty grid
    from gcdt.experiments.artifacts import checkpointed_steps

    costs = costs or CostModel.measured(profile.name)
    planned, warnings, trained = [], [], set()
    for entry in build_grid(profile, only):
        if methods is not None and entry.spec.method not in methods:
            continue
        if task is not None and entry.spec.task != task:
            continue
        key = entry.spec.key()
        stored = store.read(key)
        if stored.problem:
            warnings.append(f"{stored.problem}: it will be run again")
        state, problem = stored.state, stored.problem
        if (agent := entry.spec.waits_for) and state != "done":
            state, problem = "waiting", f"{agent} (not published, or not of agent_steps)"
        # Runs that share a checkpoint (the return-target study's) pay for training once,
        # and a checkpoint left here by a killed or finished run pays for the rest only.
        train = entry.spec.method == "tqc" or entry.spec.training_key() not in trained
        trained.add(entry.spec.training_key())
        done_steps = 0
        if checkpoints and train and state != "done" and entry.spec.method != "tqc":
            done_steps = checkpointed_steps(entry.spec)
        estimate = costs.estimate(entry.spec, train=train, done_steps=done_steps)
        planned.append(PlannedRun(entry, key, state, problem, estimate, done_steps))
    if only is None and methods is None and task is None:
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


def section_costs(todo: list[PlannedRun]) -> dict[str, tuple[int, int, float]]:
    """Runs, waiting runs and estimated seconds of `todo` per section, each run counted in the
    first of its sections in the sweep's order (Table 1's GC-DT is also RQ4's and RQ5's
    full-data point)."""
    out: dict[str, tuple[int, int, float]] = {}
    for p in todo:
        runs, waiting, seconds = out.get(p.entry.sections[0], (0, 0, 0.0))
        waits = int(p.state == "waiting")
        out[p.entry.sections[0]] = (runs + 1, waiting + waits, seconds + p.estimate_seconds)
    return out


def dispatch_order(todo: list[PlannedRun]) -> list[PlannedRun]:
    """The order a sweep hands `todo` out in. Runs a killed sweep left a checkpoint of go
    first: that work is lost with the machine until their result is written. Then the longest
    first (stable: ties keep grid order), so no worker is left alone with a long run at the
    end."""
    return sorted(todo, key=lambda p: (p.done_steps == 0, -p.estimate_seconds))


def wall_estimate(todo: list[PlannedRun], workers: int, shared: float = 0.0) -> float:
    """Estimated wall seconds of `todo` on `workers` local workers: the `shared` work (data,
    experts) spread over them, then each run, in the sweep's order, to the worker free first.
    A run is never split, so one long run bounds it however many workers there are."""
    loads = [shared / workers] * workers
    for p in dispatch_order(todo):
        loads[loads.index(min(loads))] += p.estimate_seconds
    return max(loads)


def default_workers(profile: Profile) -> int:
    return max(1, (os.cpu_count() or 1) // profile.cpus_per_run)


def sweep(
    profile: Profile,
    *,
    backend: str = "local",
    address: str | None = None,
    storage: str | None = None,
    retries: int = RETRIES,
    only: str | None = None,
    methods: Sequence[str] | None = None,
    task: str | None = None,
    workers: int | None = None,
    store_root: str | Path | None = None,
    progress: bool = True,
) -> SweepSummary:
    """Run every run of `profile` (of section `only`, of `methods`, of `task`) not done yet:
    those a checkpoint on this machine has begun first, then the longest first (by the
    estimate), so that no worker is left alone with a long run at the end.

    Bad input (backend, an unreachable `address`, a cluster too small for one run, a `storage`
    URI that cannot be written) is refused before anything is written.
    """
    if backend not in BACKENDS:
        raise GcdtError(f"unknown backend {backend!r}: expected one of {', '.join(BACKENDS)}")
    for option, value in (("--address", address), ("--storage", storage)):
        if value is not None and backend != "ray":
            raise GcdtError(f"{option} applies only to --backend ray")
    if retries < 0:
        raise GcdtError(f"retries must be >= 0, got {retries}")
    if address is not None:
        from gcdt.experiments.cluster import check_address

        check_address(address)
    if storage is not None:
        ArtifactStorage(storage).check_writable()
    store = RunStore(store_root or results_dir(profile.name) / "runs")
    store.remove_partial_files()
    # Defaults, without reading every result file: enough to order the runs longest first
    # (the dry run's absolute estimates read the measured rates).
    planned, warnings = plan(profile, store, only, CostModel(), methods=methods, task=task)
    summary = SweepSummary(profile.name, planned, warnings=warnings)
    summary.skipped = [p.key for p in planned if p.state == "done"]
    summary.waiting = [p.key for p in planned if p.state == "waiting"]
    summary.rerun = rerun_command(profile.name, backend, address, storage, retries, only, task)
    todo = dispatch_order([p for p in planned if p.state not in ("done", "waiting")])
    workers = workers or default_workers(profile)
    started = time.perf_counter()
    if todo:
        if backend == "ray":
            from gcdt.experiments.cluster import RayBackend

            runner: RayBackend | LocalBackend = RayBackend(profile, workers, address, storage)
        else:
            runner = LocalBackend(workers)
        try:
            _run_all(runner, todo, store, summary, retries, progress)
        finally:
            runner.close()
    summary.seconds = time.perf_counter() - started
    return summary


def _run_all(
    runner: Any,
    todo: list[PlannedRun],
    store: RunStore,
    summary: SweepSummary,
    retries: int,
    progress: bool,
) -> None:
    """Run `todo` on `runner` (a backend), each failed run again up to `retries` times; write
    each final result into `store` and record it in `summary`."""
    bar = progress_bar(
        total=len(todo), desc=f"sweep {summary.profile}", unit="run", progress=progress
    )
    try:
        for run in todo:
            runner.submit(run)
        tries: Counter[str] = Counter()
        for run, result in runner.results():
            if result["status"] != "done" and tries[run.key] < retries:
                tries[run.key] += 1
                summary.retried.append(f"{run.key}: {result['error']}")
                runner.submit(run)
                continue
            store.write(run.key, result)
            if result["status"] == "done":
                summary.done.append(run.key)
            else:
                summary.failed.append(run.key)
                summary.errors[run.key] = result["error"]
            bar.update(1)
            bar.set_postfix(failed=len(summary.failed))
    finally:
        bar.close()


def rerun_command(
    profile: str,
    backend: str,
    address: str | None,
    storage: str | None,
    retries: int,
    only: str | None,
    task: str | None,
) -> str:
    """The `gcdt sweep` command of these options (it runs again what is not done)."""
    argv = ["gcdt", "sweep", "--profile", profile]
    for flag, value, default in (
        ("--only", only, None),
        ("--task", task, None),
        ("--backend", backend, "local"),
        ("--address", address, None),
        ("--storage", storage, None),
        ("--retries", retries, RETRIES),
    ):
        if value != default:
            argv += [flag, str(value)]
    return shlex.join(argv)


class LocalBackend:
    """Runs in local worker processes: `submit` each run, then iterate `results` as they
    finish (more may be submitted meanwhile, e.g. retries). A pool that loses a worker
    (killed, out of memory) is replaced by a fresh one."""

    name = "local"

    def __init__(self, workers: int) -> None:
        self._artifacts = str(artifacts_dir())
        self._workers = workers
        self._pool: ProcessPoolExecutor | None = None
        self._pending: dict[Future, tuple[PlannedRun, ProcessPoolExecutor]] = {}

    def submit(self, run: PlannedRun) -> None:
        args = (run_result, run.entry.spec.to_dict(), self.name)
        pool = self._live_pool()
        try:
            future = pool.submit(*args, artifacts_root=self._artifacts)
        except BrokenProcessPool:  # a worker died before `results` saw it
            self._discard(pool)
            pool = self._live_pool()
            future = pool.submit(*args, artifacts_root=self._artifacts)
        self._pending[future] = (run, pool)

    def _live_pool(self) -> ProcessPoolExecutor:
        """The pool runs go to, started afresh after a broken one was discarded."""
        if self._pool is None:
            # Spawned, not forked: workers start clean of the driver's torch threads.
            context = multiprocessing.get_context("spawn")
            self._pool = ProcessPoolExecutor(max_workers=self._workers, mp_context=context)
        return self._pool

    def results(self) -> Iterator[tuple[PlannedRun, dict[str, Any]]]:
        while self._pending:
            finished, _ = wait(self._pending, return_when=FIRST_COMPLETED)
            for future in finished:
                run, pool = self._pending.pop(future)
                try:
                    result = future.result()
                except BrokenProcessPool:
                    # One dead worker fails every run its pool held, queued ones included:
                    # each counts a try, and the sweep's retries run it in a fresh pool,
                    # where a run that was training resumes from its checkpoint.
                    self._discard(pool)
                    result = self._lost_result(run, "a local worker process died")
                yield run, result

    def _discard(self, pool: ProcessPoolExecutor) -> None:
        """Stop broken `pool`: its surviving workers would run on (nothing before Python 3.14
        stops them), beside the fresh pool's on the same runs, and keep the driver from
        exiting. Their writes are atomic, so a kill leaves nothing half-written."""
        if pool is not self._pool:
            return  # stopped already
        survivors = list(getattr(pool, "_processes", None) or {})  # no public handle
        pool.shutdown(wait=False, cancel_futures=True)
        for pid in survivors:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        self._pool = None

    def _lost_result(self, run: PlannedRun, why: str) -> dict[str, Any]:
        return lost_result(run.entry.spec.to_dict(), self.name, f"BrokenProcessPool: {why}", why)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)

"""One run of the grid, start to finish: data, training, evaluation, result.

`run_result` is what every backend calls (a local worker process or a Ray task on any node):
it returns the run's result, which the sweep's driver alone writes into the run store, so the
workers need no access to it. It never raises for a failing run: the error and traceback go
into the result, marked `failed`, and the sweep retries it. The result holds only what the
run's config determines (spec, metrics, evaluations) apart from the `execution` block
(timings, host, backend, versions), so two backends produce the same files apart from it.
"""

from __future__ import annotations

import json
import os
import platform
import time
import traceback
from typing import Any

import numpy as np

from gcdt.baselines.tqc_her import ALL_TQC_PACKAGES, RUN_JSON
from gcdt.experiments import artifacts
from gcdt.experiments.grid import RUN_SCHEMA, RunSpec
from gcdt.experiments.storage import STORAGE_ENV
from gcdt.experiments.store import RunStore
from gcdt.paths import ARTIFACTS_ENV
from gcdt.provenance import (
    TRACKED_PACKAGES,
    cpu_signature,
    git_commit,
    package_versions,
    utc_now,
)
from gcdt.regions import GoalRegion

#: What a TQC+HER learning-curve point keeps (its timings depend on the machine, not the run).
TQC_CURVE_FIELDS = ("env_steps", "success_rate", "mean_return", "episodes")

#: The most loss-curve points a run file keeps. Training logs a row every `log_every` steps,
#: so an 800,000-step BC run logs 16,000; thinned, its file stays small. Every shorter run
#: keeps its whole log.
LOSS_CURVE_POINTS = 2000


def thin_curve(rows: list[dict[str, Any]], most: int = LOSS_CURVE_POINTS) -> list[dict[str, Any]]:
    """At most `most` of `rows`, at log-spaced positions: every early row and ever fewer later
    ones, since the loss changes fastest early and the loss figure's step axis is logarithmic.
    The first and the last row (the run's final loss) are always kept; no value is changed."""
    if most < 2:
        raise ValueError(f"a curve needs at least 2 points, got most={most}")
    if len(rows) <= most:
        return list(rows)
    picks = np.unique(np.geomspace(1, len(rows), most).round().astype(int)) - 1
    return [rows[i] for i in picks]


def execute_run(
    spec_dict: dict[str, Any], store_root: str, artifacts_root: str, backend: str
) -> str:
    """Run `spec_dict` (a `RunSpec.to_dict()`) with `artifacts_root`, write its result into
    the store at `store_root`; return "done" or "failed"."""
    result = run_result(spec_dict, backend, artifacts_root=artifacts_root)
    RunStore(store_root).write(result["key"], result)
    return result["status"]


def run_result(
    spec_dict: dict[str, Any],
    backend: str,
    *,
    artifacts_root: str | None = None,
    storage: str | None = None,
) -> dict[str, Any]:
    """Run `spec_dict` (a `RunSpec.to_dict()`); its result, "done" or "failed".

    Artifacts live in `artifacts_root` (None: this node's own, `$GCDT_ARTIFACTS` where the
    run executes) and, with a `storage` URI, are shared through it.
    """
    import torch

    if artifacts_root is not None:
        os.environ[ARTIFACTS_ENV] = artifacts_root
    if storage:
        os.environ[STORAGE_ENV] = storage
    else:  # a pooled worker may have run a task of a sweep with storage before
        os.environ.pop(STORAGE_ENV, None)
    spec = RunSpec.from_dict(spec_dict)
    key = spec.key()
    torch.set_num_threads(spec.threads)
    started, clock = utc_now(), time.perf_counter()
    timings: dict[str, float] = {}
    trained_steps = None
    result: dict[str, Any] = {"key": key, "schema": RUN_SCHEMA, "spec": spec.to_dict()}
    try:
        policy, trained, trained_steps = _trained_policy(spec, timings)
        result["training"] = trained
        began = time.perf_counter()
        result["evaluations"] = [_evaluate(policy, spec, seed) for seed in spec.eval_seeds]
        timings["evaluate_seconds"] = round(time.perf_counter() - began, 3)
        result["metrics"] = _metrics(result["evaluations"])
        result["status"] = "done"
    except Exception as err:  # recorded, retried by the next sweep; never stops the others
        result["status"] = "failed"
        result["error"] = f"{type(err).__name__}: {err}".splitlines()[0]
        result["traceback"] = traceback.format_exc()
    timings["total_seconds"] = round(time.perf_counter() - clock, 3)
    result["execution"] = {
        **_execution(backend, started, timings, torch.get_num_threads()),
        "cpu": cpu_signature(),
        # What `train_seconds` paid for: 0 for a checkpoint made before, part of the run's
        # steps for a resumed one (the rates of `gcdt sweep --dry-run` divide by it).
        "trained_steps": trained_steps,
    }
    return result


def lost_result(spec_dict: dict[str, Any], backend: str, error: str, trace: str) -> dict[str, Any]:
    """The `failed` result of a run whose worker or node died before it returned one."""
    spec = RunSpec.from_dict(spec_dict)
    return {
        "key": spec.key(),
        "schema": RUN_SCHEMA,
        "spec": spec.to_dict(),
        "status": "failed",
        "error": error,
        "traceback": trace,
        # Written by the driver: the host that lost the run is in `error`, not this block.
        "execution": {**_execution(backend, None, {}, None), "host": None},
    }


def _execution(
    backend: str, started: str | None, timings: dict[str, float], threads: int | None
) -> dict[str, Any]:
    """Where and how a run executed: the one block of a result that its config does not set."""
    return {
        "backend": backend,
        "host": platform.node(),
        "started": started,
        "finished": utc_now(),
        "seconds": timings,
        "torch_threads": threads,
        "git_commit": git_commit(),
        "versions": package_versions((*TRACKED_PACKAGES, *ALL_TQC_PACKAGES)),
    }


def _trained_policy(
    spec: RunSpec, timings: dict[str, float]
) -> tuple[Any, dict[str, Any], int | None]:
    """The run's agent as a policy (made if needed), what its training recorded, and the
    gradient steps this call trained (offline runs; None for TQC+HER). The result keeps the
    learning curve (TQC+HER) or the loss curve and model config (offline), so that every
    figure can be drawn from results alone, without the artifacts."""
    began = time.perf_counter()
    if spec.method == "tqc":
        from gcdt.policies.tqc import TQCPolicy

        model = artifacts.tqc_agent(spec.tqc)
        timings["train_seconds"] = round(time.perf_counter() - began, 3)
        run = json.loads((model.parent / RUN_JSON).read_text())
        trained = {
            "env_steps": run["env_steps"],
            "overrides": run["overrides"],
            **{k: {f: run[k][f] for f in TQC_CURVE_FIELDS} for k in ("best", "final")},
            "curve": artifacts.tqc_curve(model.parent, TQC_CURVE_FIELDS),
        }
        return TQCPolicy(model, spec.task), trained, None

    from gcdt.checkpoint import load_checkpoint
    from gcdt.policies.trained import TrainedPolicy

    data = artifacts.dataset(spec.data)
    timings["data_seconds"] = round(time.perf_counter() - began, 3)
    began = time.perf_counter()
    path, trained_steps = artifacts.trained_checkpoint(spec)
    ckpt = load_checkpoint(path)
    timings["train_seconds"] = round(time.perf_counter() - began, 3)
    history = ckpt["history"]
    trained = {
        "steps": ckpt["step"],
        "final_loss": history[-1]["loss"] if history else None,
        "dataset": {k: v for k, v in data.summary().items() if k != "task"},
        "model_config": ckpt["model_config"],
        "loss_curve": [{k: row[k] for k in ("step", "loss", "lr")} for row in thin_curve(history)],
    }
    policy = TrainedPolicy(ckpt, spec.task, target_return=spec.target_return)
    return policy, trained, trained_steps


def _evaluate(policy: Any, spec: RunSpec, seed: int) -> dict[str, Any]:
    from gcdt.evaluation import evaluate

    summary = evaluate(
        policy,
        spec.task,
        spec.reward,
        timesteps=spec.eval_timesteps,
        n_envs=spec.eval_envs,
        seed=seed,
        # A run of one core steps its envs in its own process: the same episodes, without
        # the messages to env processes that would share that core (`EvaluationConfig`).
        in_process=spec.threads == 1,
        goal_region=None if spec.eval_region is None else GoalRegion.parse(spec.eval_region),
        progress=False,
    ).summary
    keep = (
        "seed",
        "episodes",
        "success_rate",
        "mean_return",
        "std_return",
        "mean_length",
        "mean_final_distance",
    )
    return {k: summary[k] for k in keep}


def _metrics(evaluations: list[dict[str, Any]]) -> dict[str, Any]:
    """Success rate and return averaged over the evaluation seeds (None if nothing finished)."""
    rates = [e["success_rate"] for e in evaluations if e["success_rate"] is not None]
    returns = [e["mean_return"] for e in evaluations if e["mean_return"] is not None]
    return {
        "success_rate": float(np.mean(rates)) if rates else None,
        "mean_return": float(np.mean(returns)) if returns else None,
        "episodes": int(sum(e["episodes"] for e in evaluations)),
    }

"""End to end: `make reproduce PROFILE=smoke` from scratch, and the quick grid's per-run costs.

    python benchmarks/end_to_end.py [--skip-smoke]

Writes results/bench/end_to_end.json with
* the wall time of `make reproduce PROFILE=smoke` run from scratch: its datasets,
  checkpoints and its reproduction's results, figures and executed notebooks go to a fresh
  temporary GCDT_ARTIFACTS folder;
* the quick grid's cost per run: measured (the `execution` timings of finished runs in
  results/quick/runs, when there are any) and estimated from the benchmarks' rates (the
  model `gcdt sweep --dry-run` uses), per method and task, with the totals.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import tempfile
import time
from collections import defaultdict
from statistics import median
from typing import Any

from common import write_report

from gcdt.experiments import get_profile, plan
from gcdt.experiments.costs import CostModel
from gcdt.experiments.store import RunStore
from gcdt.experiments.sweep import default_workers, shared_cost, wall_estimate
from gcdt.paths import ARTIFACTS_ENV, REPO_ROOT, results_dir


def smoke_reproduce() -> float:
    """Seconds of `make reproduce PROFILE=smoke` from scratch."""
    with tempfile.TemporaryDirectory() as artifacts:
        env = {**os.environ, ARTIFACTS_ENV: artifacts}
        began = time.perf_counter()
        subprocess.run(
            ["make", "-s", "reproduce", "PROFILE=smoke"],
            cwd=REPO_ROOT,
            env=env,
            check=True,
            stdout=subprocess.DEVNULL,
        )
        return time.perf_counter() - began


def quick_costs() -> dict[str, Any]:
    """The quick grid's per-run seconds, measured where runs exist and estimated for all."""
    profile = get_profile("quick")
    costs = CostModel.measured()
    with tempfile.TemporaryDirectory() as empty:  # an empty store: every run is "to do"
        planned, _ = plan(profile, RunStore(empty), costs=costs)
    estimated: dict[str, list[float]] = defaultdict(list)
    for p in planned:
        spec = p.entry.spec
        estimated[f"{spec.method} {spec.task}"].append(p.estimate_seconds)
    measured: dict[str, list[float]] = defaultdict(list)
    store = RunStore(results_dir("quick") / "runs")
    for p in planned:
        stored = store.read(p.key)
        if stored.state == "done":
            seconds = stored.result["execution"]["seconds"]["total_seconds"]
            measured[f"{p.entry.spec.method} {p.entry.spec.task}"].append(seconds)
    shared = shared_cost(planned, costs)
    work = sum(p.estimate_seconds for p in planned) + shared
    workers = default_workers(profile)
    return {
        "runs": len(planned),
        "estimated_seconds_per_run": {k: round(median(v), 1) for k, v in estimated.items()},
        "measured_seconds_per_run": {k: round(median(v), 1) for k, v in measured.items()},
        "measured_runs": sum(len(v) for v in measured.values()),
        "estimated_work_hours": round(work / 3600, 2),
        "estimated_wall_hours": round(wall_estimate(planned, workers, shared) / 3600, 2),
        "workers": workers,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-smoke", action="store_true", help="only the quick grid's costs")
    args = parser.parse_args()
    results: dict[str, Any] = {"quick_grid": quick_costs()}
    if not args.skip_smoke:
        results["make_reproduce_smoke_seconds"] = round(smoke_reproduce(), 1)
    write_report(
        "end_to_end",
        "end_to_end.py",
        {
            "unit": "seconds (wall) unless named otherwise",
            "results": results,
        },
    )


if __name__ == "__main__":
    main()

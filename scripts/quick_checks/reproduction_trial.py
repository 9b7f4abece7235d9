"""Does the reproduction check tell an honest re-run from a regression? Run a slice of a
profile's Table 1 again, as `make reproduce` runs it, and check it against the published values.

    [ATEN_CPU_CAPABILITY=default] python scripts/quick_checks/reproduction_trial.py NAME
        --outputs DIR [--profile quick] [--tasks push] [--rewards sparse dense]
        [--methods gcdt bc] [--budget-scale 0.5] [--workers 2]

Trials, one per question:

* another CPU: run it on one with other vector units than the published run's machine (the
  published quick run: AVX2), or emulate one with `ATEN_CPU_CAPABILITY=default`, which makes
  PyTorch run its generic kernels instead of this CPU's vectorised ones: other rounding, so
  other weights and other policies from the same code and data;
* a regression: `--budget-scale 0.5` halves the offline training budget (GC-DT's steps, and
  BC's by the equal-samples rule), a change the check must flag.

The runs go to DIR/results/PROFILE/runs/ (resumed there, like a sweep); the check's rows for
the slice, its summary line and how the trial ran go to results/quick_checks/reproduction_trial/
NAME.{md,json}.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import torch

from gcdt.experiments.profiles import PROFILES, Scope, get_profile
from gcdt.experiments.sweep import sweep
from gcdt.paths import REPO_ROOT, results_dir, write_if_changed, write_json_atomic
from gcdt.provenance import git_commit
from gcdt.report import tables
from gcdt.report.reproduction import check_markdown, reproduction_check, summary_line

OUT = REPO_ROOT / "results" / "quick_checks" / "reproduction_trial"


def _run_seconds(path: Path) -> float:
    return json.loads(path.read_text())["execution"]["seconds"]["total_seconds"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name", help="the trial's name: its files in results/quick_checks/...")
    ap.add_argument("--outputs", required=True, help="the trial's folder (as $GCDT_OUTPUTS)")
    ap.add_argument("--profile", default="quick", choices=sorted(PROFILES))
    ap.add_argument("--tasks", nargs="+", default=["push"])
    ap.add_argument("--rewards", nargs="+", default=["sparse", "dense"])
    ap.add_argument("--methods", nargs="+", default=["gcdt", "bc"])
    ap.add_argument("--budget-scale", type=float, default=1.0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    if not 0 < args.budget_scale <= 1:
        sys.exit(f"error: --budget-scale must be in (0, 1], got {args.budget_scale}")

    published = get_profile(args.profile)
    if published.train_steps is None:
        sys.exit(f"error: profile {args.profile!r} trains for epochs, not steps: nothing to scale")

    def scaled(budget: dict[str, int] | None) -> dict[str, int] | None:
        return budget and {t: max(1, round(s * args.budget_scale)) for t, s in budget.items()}

    trial = dataclasses.replace(
        published,
        table1=Scope(tasks=tuple(args.tasks), rewards=tuple(args.rewards)),
        train_steps=scaled(published.train_steps),
        table1_train_steps=scaled(published.table1_train_steps),
    )
    steps = {t: trial.dt_steps(t, table1=True) for t in trial.train_steps}  # Table 1's
    outputs = Path(args.outputs).resolve()
    os.environ["GCDT_OUTPUTS"] = str(outputs)
    runs_dir = results_dir(trial.name, outputs) / "runs"
    began = time.time()
    summary = sweep(
        trial,
        only="table1",
        methods=args.methods,
        workers=args.workers,
        store_root=runs_dir,
        progress=False,
    )
    print(summary.line())
    if not summary.ok:
        sys.exit(f"error: {len(summary.failed)} runs failed: {summary.rerun}")

    ours = tables.load_runs(trial, runs_dir, agents=False)
    published_runs = results_dir(published.name, REPO_ROOT) / "runs"
    check = reproduction_check(tables.load_runs(published, published_runs, agents=False), ours)
    check = check[check["ours"].notna()].reset_index(drop=True)  # the slice's items only
    capability = torch.backends.cpu.get_cpu_capability()
    command = " ".join(
        (
            [f"ATEN_CPU_CAPABILITY={os.environ['ATEN_CPU_CAPABILITY']}"]
            if os.environ.get("ATEN_CPU_CAPABILITY")
            else []
        )
        + ["python", "scripts/quick_checks/reproduction_trial.py", *sys.argv[1:]]
    )
    record = {
        "command": command,
        "git_commit": git_commit(),
        "profile": args.profile,
        "tasks": args.tasks,
        "rewards": args.rewards,
        "methods": args.methods,
        "budget_scale": args.budget_scale,
        "train_steps": steps,
        "torch_cpu_capability": capability,
        "runs": len(summary.planned),
        # The runs' own times, from their files: a second call only re-checks finished runs.
        "run_seconds": round(sum(_run_seconds(p) for p in runs_dir.glob("*.json")), 1),
        "wall_seconds_this_call": round(time.time() - began, 1),
        "agree": int(check["agrees"].sum()),
        "values": len(check),
        "summary": summary_line(check),
        "rows": check.to_dict(orient="records"),
    }
    text = (
        f"# Reproduction trial `{args.name}`\n\n"
        f"Profile `{args.profile}`'s Table 1 on {', '.join(args.tasks)} × "
        f"{', '.join(args.rewards)}, methods {', '.join(args.methods)}, "
        f"{len(published.seeds)} seeds each, run "
        f"again with PyTorch's `{capability}` kernels and {args.budget_scale:g} times the "
        f"training budget ({steps}), against the published runs (`results/{args.profile}/`).\n\n"
        f"Command: `{command}` (commit {(record['git_commit'] or 'unknown')[:7]}).\n\n"
        + check_markdown(check)
        + "\n"
    )
    OUT.mkdir(parents=True, exist_ok=True)
    write_json_atomic(OUT / f"{args.name}.json", record)
    write_if_changed(OUT / f"{args.name}.md", text)
    print(summary_line(check))


if __name__ == "__main__":
    main()

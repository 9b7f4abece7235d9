"""TQC+HER on 2 CPU cores: training speed per config, and Reach trained to success.

    python benchmarks/tqc_her.py throughput [--task reach] [--learning-steps 300]
    python benchmarks/tqc_her.py reach [--config cpu] [--steps N]

`throughput` trains each config of gcdt/baselines/tqc_her.yaml for its `learning_starts`
random steps plus `--learning-steps` learning steps and reports env steps/s of the learning
phase (what decides how long a full run takes) -> results/bench/tqc_her_throughput.json.

`reach` trains TQC+HER on Reach with sparse and with dense rewards (models under
artifacts/tqc/), then measures the final and the best model with the paper's protocol
(`evaluate`, 10,000 steps, seed 0) -> results/bench/tqc_her_reach.json with the learning
curves. Target: >= 95 % success after at most ~15 minutes of training per reward.
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import tempfile
from pathlib import Path

from common import write_report

from gcdt.baselines.tqc_her import load_tqc_config, tqc_config_names, train_tqc
from gcdt.evaluation import evaluate
from gcdt.paths import artifacts_dir
from gcdt.policies import make_policy

TARGET_SUCCESS = 0.95
TARGET_MINUTES = 15.0


def throughput(task: str, learning_steps: int) -> dict:
    cells = {}
    for name in tqc_config_names():
        cfg = load_tqc_config(name, task)
        cfg = cfg.with_budget(steps=cfg.learning_starts + learning_steps)
        out = Path(tempfile.mkdtemp(prefix=f"tqc_{name}_"))
        try:
            result = train_tqc(
                task,
                "sparse",
                cfg,
                out / "run",
                eval_every=cfg.steps,
                eval_episodes=1,
                progress=False,
            )
        finally:
            shutil.rmtree(out)
        cells[name] = {
            "net_arch": list(cfg.net_arch),
            "batch_size": cfg.batch_size,
            "learning_steps_per_second": round(result.learning_steps_per_second, 2),
            "env_steps_per_second_incl_warmup": round(result.env_steps_per_second, 2),
            "hours_for_paper_budget": round(
                load_tqc_config("paper", task).steps / result.learning_steps_per_second / 3600, 2
            ),
        }
        print(name, cells[name], flush=True)
    return {"task": task, "learning_steps": learning_steps, "configs": cells}


def reach(config: str, steps: int | None) -> dict:
    runs = {}
    for reward in ("sparse", "dense"):
        cfg = load_tqc_config(config, "reach")
        if steps is not None:
            cfg = cfg.with_budget(steps=steps)
        out = artifacts_dir() / "tqc" / f"reach_{reward}_{config}"
        shutil.rmtree(out, ignore_errors=True)  # a benchmark always measures a fresh run
        result = train_tqc("reach", reward, cfg, out, progress=False)
        run = json.loads((out / "run.json").read_text())
        with open(out / "eval.csv") as f:
            curve = [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]
        measured = {}
        for which, path in (("final", result.model), ("best", result.best_model)):
            policy = make_policy(f"tqc:{path}", "reach")
            summary = evaluate(policy, "reach", reward, timesteps=10_000, progress=False).summary
            measured[which] = {
                k: summary[k] for k in ("success_rate", "mean_return", "episodes", "timesteps")
            }
        minutes = run["train_seconds"] / 60
        runs[reward] = {
            "model": str(result.model),
            "env_steps": run["env_steps"],
            "train_minutes": round(minutes, 2),
            "wall_minutes": round(run["wall_seconds"] / 60, 2),
            "env_steps_per_second": run["env_steps_per_second"],
            "learning_steps_per_second": run["learning_steps_per_second"],
            "overrides": run["overrides"],
            "evaluation_10k_steps": measured,
            "meets_target": measured["final"]["success_rate"] >= TARGET_SUCCESS
            and minutes <= TARGET_MINUTES,
            "learning_curve": curve,
        }
        print(reward, {k: v for k, v in runs[reward].items() if k != "learning_curve"}, flush=True)
    return {
        "config": config,
        "target": f"success >= {TARGET_SUCCESS:.0%} (final model, 10k-step evaluation) "
        f"after <= {TARGET_MINUTES:.0f} min of training",
        "runs": runs,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="mode", required=True)
    tp = sub.add_parser("throughput")
    tp.add_argument("--task", default="reach")
    tp.add_argument("--learning-steps", type=int, default=300)
    rc = sub.add_parser("reach")
    rc.add_argument("--config", default="cpu", choices=tqc_config_names())
    rc.add_argument("--steps", type=int)
    args = parser.parse_args()
    if args.mode == "throughput":
        write_report("tqc_her_throughput", "tqc_her.py", throughput(args.task, args.learning_steps))
    else:
        report = reach(args.config, args.steps)
        write_report("tqc_her_reach", "tqc_her.py", report)
        if not all(run["meets_target"] for run in report["runs"].values()):
            raise SystemExit("TQC+HER on Reach missed its target (see the report above)")


if __name__ == "__main__":
    main()

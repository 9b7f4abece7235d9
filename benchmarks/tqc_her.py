"""TQC+HER on 2 CPU cores: training speed per config and loop, and Reach trained to success.

    python benchmarks/tqc_her.py throughput [--task push] [--scale 1.0]
    python benchmarks/tqc_her.py reach [--config cpu] [--steps N]
    python benchmarks/tqc_her.py push --run results/experts/tqc_push_sparse

`throughput` trains each config of gcdt/baselines/tqc_her.yaml on `--task` with two loops in
the same run, today's (`sb3`: sb3-contrib's TQC on one env, rl-baselines3-zoo's loop) and the
config's own (SBX's TQC on 8 envs, as many gradient steps per env step), for the config's
`learning_starts` random steps plus a fixed number of learning steps, and reports env steps/s
of the learning phase (what decides how long a full run takes; the first iteration, where
JAX compiles, left out) and `speedup_vs_sb3` -> results/bench/tqc_her_throughput.json.
Target: >= 3x for the `cpu` config.

`reach` trains TQC+HER on Reach with sparse and with dense rewards (models under
artifacts/tqc/), then measures the final and the best model with the paper's protocol
(`evaluate`, 10,000 steps, seed 0) -> results/bench/tqc_her_reach.json with the learning
curves. Target: >= 95 % success after at most ~15 minutes of training per reward.

`push` reports a finished `gcdt tqc train` run on Push (sparse): its learning curve against
env steps and training wall-clock, its final model measured on 500 held-out episodes
(evaluation seed 5000: apart from training's and the periodic evaluations' episodes), and how
long PickAndPlace's ~700k steps would take at the same speed -> results/bench/tqc_her_push.json.
Target: >= 90 % success within 300k env steps.
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


#: Learning steps measured per config (at --scale 1): ~1 minute of today's loop each.
LEARNING_STEPS = {"cpu": 4000, "paper": 160}
TARGET_SPEEDUP = 3.0
#: Today's loop: the zoo's library on one env.
SB3_LOOP = {"backend": "sb3", "n_envs": 1}


def throughput(task: str, scale: float) -> dict:
    cells = {}
    for name in tqc_config_names():
        base = load_tqc_config(name, task)
        learning_steps = max(int(LEARNING_STEPS.get(name, 400) * scale) // 8 * 8, 16)
        loops = {}
        for loop, changes in (("sb3", SB3_LOOP), ("new", {})):
            cfg = base.with_budget(steps=base.learning_starts + learning_steps, **changes)
            out = Path(tempfile.mkdtemp(prefix=f"tqc_{name}_{loop}_"))
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
            loops[loop] = {
                "backend": cfg.backend,
                "n_envs": cfg.n_envs,
                "learning_steps": learning_steps,
                "env_steps_per_second": round(result.learning_steps_per_second, 2),
            }
            print(name, loop, loops[loop], flush=True)
        speed = {loop: cell["env_steps_per_second"] for loop, cell in loops.items()}
        budget = load_tqc_config("paper", task).steps
        cells[name] = {
            "net_arch": list(base.net_arch),
            "batch_size": base.batch_size,
            "sb3": loops["sb3"],
            "new": loops["new"],
            "speedup_vs_sb3": round(speed["new"] / speed["sb3"], 2),
            # Kept under this name for the cost model (gcdt/experiments/costs.py).
            "learning_steps_per_second": speed["new"],
            "hours_for_paper_budget": {
                loop: round(budget / rate / 3600, 2) for loop, rate in speed.items()
            },
        }
    return {
        "task": task,
        "target": f"speedup_vs_sb3 >= {TARGET_SPEEDUP:g} for the cpu config",
        "meets_target": cells["cpu"]["speedup_vs_sb3"] >= TARGET_SPEEDUP,
        "configs": cells,
    }


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


#: Held-out evaluation of the Push agent: no training or periodic-evaluation episode uses it.
PUSH_EVAL_SEED, PUSH_EVAL_EPISODES = 5000, 500
#: rl-baselines3-zoo's PickAndPlace agent reaches ~95 % at about this many env steps.
PICK_AND_PLACE_STEPS = 700_000


def push(run_dir: Path) -> dict:
    run = json.loads((run_dir / "run.json").read_text())
    if (run["task"], run["reward"]) != ("push", "sparse"):
        raise SystemExit(f"{run_dir} is a {run['task']}/{run['reward']} run, not push/sparse")
    with open(run_dir / "eval.csv") as f:
        curve = [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]
    policy = make_policy(f"tqc:{run_dir / 'model.zip'}", "push")
    result = evaluate(
        policy, "push", "sparse", episodes=PUSH_EVAL_EPISODES, seed=PUSH_EVAL_SEED, progress=False
    )
    held_out = {
        k: result.summary[k] for k in ("success_rate", "mean_return", "episodes", "timesteps")
    }
    rate = run["env_steps"] / run["train_seconds"]
    return {
        "run": str(run_dir),
        "training_command": run["command"],
        "training_commit": run["git_commit"],
        "config": run["config"],
        "env_steps": run["env_steps"],
        "train_minutes": round(run["train_seconds"] / 60, 1),
        "env_steps_per_second": round(rate, 1),
        "held_out_evaluation": {"seed": PUSH_EVAL_SEED, **held_out},
        "meets_target": held_out["success_rate"] >= 0.9 and run["env_steps"] <= 300_000,
        "pick_and_place_hours_at_this_speed": round(PICK_AND_PLACE_STEPS / rate / 3600, 1),
        "learning_curve": curve,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="mode", required=True)
    tp = sub.add_parser("throughput")
    tp.add_argument("--task", default="push")
    tp.add_argument("--scale", type=float, default=1.0, help="learning steps x SCALE")
    rc = sub.add_parser("reach")
    rc.add_argument("--config", default="cpu", choices=tqc_config_names())
    rc.add_argument("--steps", type=int)
    pu = sub.add_parser("push")
    pu.add_argument("--run", type=Path, required=True, help="a finished gcdt tqc train folder")
    args = parser.parse_args()
    if args.mode == "throughput":
        write_report("tqc_her_throughput", "tqc_her.py", throughput(args.task, args.scale))
    elif args.mode == "push":
        write_report("tqc_her_push", "tqc_her.py", push(args.run))
    else:
        report = reach(args.config, args.steps)
        write_report("tqc_her_reach", "tqc_her.py", report)
        if not all(run["meets_target"] for run in report["runs"].values()):
            raise SystemExit("TQC+HER on Reach missed its target (see the report above)")


if __name__ == "__main__":
    main()

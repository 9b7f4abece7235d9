"""TQC+HER on 2 CPU cores: training speed per config and loop, and Reach trained to success.

    python benchmarks/tqc_her.py throughput [--task push] [--scale 1.0]
    python benchmarks/tqc_her.py reach [--config cpu] [--steps N]
    python benchmarks/tqc_her.py push --run results/experts/tqc_push_sparse

`throughput` builds, for each config of gcdt/baselines/tqc_her.yaml on `--task`, two models:
today's loop (`sb3`: sb3-contrib's TQC on one env, rl-baselines3-zoo's) and the config's own
(SBX's TQC on 8 envs, as many gradient steps per env step). After the config's
`learning_starts` random steps and two loop iterations (where JAX compiles), the two take
turns learning in equal chunks, several rounds, so that a shared machine's drifting speed hits
both alike. It reports each loop's median env steps/s over the rounds (what decides how long a
full run takes) and `speedup_vs_sb3`, the median of the rounds' paired ratios with their
range -> results/bench/tqc_her_throughput.json.
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
import statistics
import time
from pathlib import Path

from common import write_report

from gcdt.baselines.tqc_her import build_tqc, load_tqc_config, tqc_config_names, train_tqc
from gcdt.evaluation import evaluate
from gcdt.paths import artifacts_dir
from gcdt.policies import make_policy

TARGET_SUCCESS = 0.95
TARGET_MINUTES = 15.0


#: Learning steps measured per config and loop (at --scale 1), in ROUNDS equal chunks.
LEARNING_STEPS = {"cpu": 4000, "paper": 160}
ROUNDS = {"cpu": 10, "paper": 4}
TARGET_SPEEDUP = 3.0
#: Today's loop: the zoo's library on one env.
SB3_LOOP = {"backend": "sb3", "n_envs": 1}


def _learn_rate(model, steps: int) -> float:
    """Env steps/s of `steps` more learning steps of `model`, picking up where it stopped."""
    started = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    return steps / (time.perf_counter() - started)


def throughput(task: str, scale: float) -> dict:
    cells = {}
    for name in tqc_config_names():
        base = load_tqc_config(name, task)
        rounds = ROUNDS.get(name, 4)
        chunk = max(int(LEARNING_STEPS.get(name, 400) * scale) // rounds // 8 * 8, 8)
        cfgs = {"sb3": base.with_budget(**SB3_LOOP), "new": base}
        models = {loop: build_tqc(cfg, task, "sparse", seed=0) for loop, cfg in cfgs.items()}
        # The random steps, then two loop iterations: JAX compiles the update in the first and
        # the policy's action in the second (the first after the random steps).
        for model in models.values():
            model.learn(base.learning_starts + 2 * cfgs["new"].n_envs)
        # The loops take turns, the first of each round alternating, so that the machine's
        # drift (a shared VM's speed wanders by 10-20 % within the hour) hits both alike; each
        # round's speedup compares two chunks measured back to back.
        rates = {loop: [] for loop in models}
        for r in range(rounds):
            for loop in sorted(models, reverse=r % 2 == 1):
                rates[loop].append(_learn_rate(models[loop], chunk))
            print(name, f"round {r}", {k: round(v[-1], 2) for k, v in rates.items()}, flush=True)
        for model in models.values():
            model.get_env().close()
        ratios = [new / sb3 for sb3, new in zip(rates["sb3"], rates["new"], strict=True)]
        speed = {loop: statistics.median(v) for loop, v in rates.items()}
        budget = load_tqc_config("paper", task).steps
        cells[name] = {
            "net_arch": list(base.net_arch),
            "batch_size": base.batch_size,
            **{
                loop: {
                    "backend": cfgs[loop].backend,
                    "n_envs": cfgs[loop].n_envs,
                    "learning_steps": chunk * rounds,
                    "env_steps_per_second": round(speed[loop], 2),
                    "per_round": [round(v, 2) for v in rates[loop]],
                }
                for loop in models
            },
            "rounds": rounds,
            # The median of the rounds' paired ratios, and their range.
            "speedup_vs_sb3": round(statistics.median(ratios), 2),
            "speedup_range": [round(min(ratios), 2), round(max(ratios), 2)],
            # Kept under this name for the cost model (gcdt/experiments/costs.py).
            "learning_steps_per_second": round(speed["new"], 2),
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

"""Evaluator throughput (env steps/s) next to the raw simulator, for 1 and N envs.

    python benchmarks/evaluator_throughput.py [--task push] [--timesteps 6000] [--envs 2]

Writes results/bench/evaluator_throughput_<task>.json (machine info included) and prints it.
Compared in one run, on one machine: raw stepping of one env in-process with random actions,
raw stepping of the vector env with random actions (the ceiling for N envs), and `evaluate`
with the random and the scripted policy on the same vector env sizes.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import sys
import time

import numpy as np

from gcdt.envs import episode_seed, make_env, make_vec_env
from gcdt.evaluation import evaluate
from gcdt.paths import REPO_ROOT, write_json_atomic
from gcdt.policies import make_policy


def raw_single(task: str, steps: int) -> float:
    """Steps/s of one env stepped in-process with random actions, resets included."""
    env = make_env(task, "sparse")
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    started, episode = time.perf_counter(), 0
    for _ in range(steps):
        action = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            episode += 1
            env.reset(seed=episode_seed(0, episode))
    rate = steps / (time.perf_counter() - started)
    env.close()
    return rate


def raw_vector(task: str, steps: int, n_envs: int) -> float:
    """Steps/s of the vector env with random actions and masked seeded resets, no policy."""
    with contextlib.closing(make_vec_env(task, "sparse", n_envs)) as envs:
        rng = np.random.default_rng(0)
        envs.reset(seed=[episode_seed(0, j) for j in range(n_envs)])
        shape = (n_envs, *envs.single_action_space.shape)
        started, episode = time.perf_counter(), n_envs
        for _ in range(steps // n_envs):
            _, _, terminated, truncated, _ = envs.step(rng.uniform(-1, 1, shape).astype(np.float32))
            done = terminated | truncated
            if done.any():
                seeds = [episode_seed(0, episode + i) if d else None for i, d in enumerate(done)]
                episode += int(done.sum())
                envs.reset(seed=seeds, options={"reset_mask": done})
        return (steps // n_envs) * n_envs / (time.perf_counter() - started)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="push")
    parser.add_argument("--timesteps", type=int, default=6000)
    parser.add_argument("--envs", type=int, default=2)
    args = parser.parse_args()
    import torch

    rows = {"raw_single_env": raw_single(args.task, args.timesteps)}
    for n in sorted({1, args.envs}):
        rows[f"raw_vector_{n}_envs"] = raw_vector(args.task, args.timesteps, n)
        for name in ("random", "scripted"):
            result = evaluate(
                make_policy(name, args.task),
                args.task,
                "sparse",
                timesteps=args.timesteps,
                n_envs=n,
                progress=False,
            )
            rows[f"evaluate_{name}_{n}_envs"] = result.summary["steps_per_second"]
    report = {
        "benchmark": "evaluator_throughput",
        "command": "python " + " ".join(["benchmarks/evaluator_throughput.py", *sys.argv[1:]]),
        "unit": "env steps per second",
        "task": args.task,
        "timesteps": args.timesteps,
        "results": {k: round(v, 1) for k, v in rows.items()},
        "machine": {
            "cpu": platform.processor() or platform.machine(),
            "cores": os.cpu_count(),
            "python": platform.python_version(),
            "torch": torch.__version__,
        },
    }
    out = REPO_ROOT / "results" / "bench" / f"evaluator_throughput_{args.task}.json"
    write_json_atomic(out, report)
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()

"""Evaluator throughput (env steps/s) next to the raw simulator, for 1 and N envs.

    python benchmarks/evaluator_throughput.py [--task push] [--timesteps 6000] [--envs 2]

Writes results/bench/evaluator_throughput_<task>.json (machine info included) and prints it.
Compared in one run, on one machine: raw stepping of one env in-process with random actions,
raw stepping of the vector env with random actions (the ceiling for N envs), and `evaluate`
with the random and the scripted policy on the same vector env sizes.
"""

from __future__ import annotations

import argparse

from common import raw_single, raw_vector, write_report

from gcdt.evaluation import evaluate
from gcdt.policies import make_policy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="push")
    parser.add_argument("--timesteps", type=int, default=6000)
    parser.add_argument("--envs", type=int, default=2)
    args = parser.parse_args()
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
        "unit": "env steps per second",
        "task": args.task,
        "timesteps": args.timesteps,
        "results": {k: round(v, 1) for k, v in rows.items()},
    }
    write_report(f"evaluator_throughput_{args.task}", "evaluator_throughput.py", report)


if __name__ == "__main__":
    main()

"""Collection throughput (transitions/s) next to raw random stepping, for 1 and N processes.

    python benchmarks/collection_throughput.py [--task push] [--transitions 4000] [--envs 2]

Writes results/bench/collection_throughput_<task>.json. Compared in one run, on one machine:
the raw vector env stepped with random actions (the ceiling) and `gcdt.data.collect` with the
random and the scripted policy, each on the same number of env processes. Rates count the
stepping loop only (env start-up excluded) and the transitions kept in the dataset.
"""

from __future__ import annotations

import argparse

from common import raw_vector, write_report

from gcdt.data import collect
from gcdt.policies import make_policy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="push")
    parser.add_argument("--transitions", type=int, default=4000)
    parser.add_argument("--envs", type=int, default=2)
    args = parser.parse_args()
    rows: dict[str, float] = {}
    for n in sorted({1, args.envs}):
        rows[f"raw_vector_{n}_envs"] = raw_vector(args.task, args.transitions, n)
        scripted = make_policy("scripted", args.task)
        rows[f"raw_vector_scripted_{n}_envs"] = raw_vector(args.task, args.transitions, n, scripted)
        for name in ("random", "scripted"):
            data = collect(
                make_policy(name, args.task), args.task, args.transitions, n_envs=n, progress=False
            )
            rows[f"collect_{name}_{n}_envs"] = len(data) / data.metadata["stepping_seconds"]
        for name in ("random", "scripted"):
            rows[f"collect_{name}_{n}_envs_vs_raw"] = (
                rows[f"collect_{name}_{n}_envs"] / rows[f"raw_vector_{n}_envs"]
            )
        # The collector's own overhead: the same expert, stepped without recording anything.
        rows[f"collect_scripted_{n}_envs_vs_raw_scripted"] = (
            rows[f"collect_scripted_{n}_envs"] / rows[f"raw_vector_scripted_{n}_envs"]
        )
    report = {
        "unit": "transitions (env steps) per second; *_vs_raw are ratios",
        "task": args.task,
        "transitions": args.transitions,
        "results": {k: round(v, 3 if "_vs_raw" in k else 1) for k, v in rows.items()},
    }
    write_report(f"collection_throughput_{args.task}", "collection_throughput.py", report)


if __name__ == "__main__":
    main()

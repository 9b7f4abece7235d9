"""Collection throughput (transitions/s) next to raw random stepping on N processes.

    python benchmarks/collection_throughput.py [--task push] [--transitions 1000] [--envs 2]

Writes results/bench/collection_throughput_<task>.json. Compared in one run, on one machine:
the raw vector env stepped with random actions (the ceiling) and `gcdt.data.collect` with the
random and the scripted policy, each on the same number of env processes. Rates count the
stepping loop only (env start-up excluded) and the transitions kept in the dataset; each cell
is the median of `--repeats` interleaved runs.
"""

from __future__ import annotations

import argparse
import functools

import numpy as np
from common import raw_vector, write_report

from gcdt.data import collect
from gcdt.policies import make_policy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="push")
    parser.add_argument("--transitions", type=int, default=1000)
    parser.add_argument("--envs", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()

    def collect_rate(name: str, n: int) -> float:
        policy = make_policy(name, args.task)
        data = collect(policy, args.task, args.transitions, n_envs=n, progress=False)
        return len(data) / data.metadata["stepping_seconds"]

    n, scripted = args.envs, make_policy("scripted", args.task)
    cells = {
        f"raw_vector_{n}_envs": functools.partial(raw_vector, args.task, args.transitions, n),
        f"raw_vector_scripted_{n}_envs": functools.partial(
            raw_vector, args.task, args.transitions, n, scripted
        ),
        f"collect_random_{n}_envs": functools.partial(collect_rate, "random", n),
        f"collect_scripted_{n}_envs": functools.partial(collect_rate, "scripted", n),
    }
    # Repeats are interleaved and the median kept: this VM's speed drifts by 2x and more
    # over minutes, which would otherwise land on whichever cell ran at the wrong time.
    samples: dict[str, list[float]] = {k: [] for k in cells}
    for _ in range(args.repeats):
        for key, measure in cells.items():
            samples[key].append(measure())
    rows = {k: float(np.median(v)) for k, v in samples.items()}
    for name in ("random", "scripted"):
        rows[f"collect_{name}_{n}_envs_vs_raw"] = (
            rows[f"collect_{name}_{n}_envs"] / rows[f"raw_vector_{n}_envs"]
        )
    # The collector's own overhead: the same expert, stepped without recording anything.
    rows[f"collect_scripted_{n}_envs_vs_raw_scripted"] = (
        rows[f"collect_scripted_{n}_envs"] / rows[f"raw_vector_scripted_{n}_envs"]
    )
    report = {
        "unit": "transitions (env steps) per second, median of repeats; *_vs_raw are ratios",
        "task": args.task,
        "envs": n,
        "targets": {f"collect_scripted_{n}_envs_vs_raw": ">= 0.8"},
        "transitions": args.transitions,
        "repeats": args.repeats,
        "results": {k: round(v, 3 if "_vs_raw" in k else 1) for k, v in rows.items()},
        "samples": {k: [round(x, 1) for x in v] for k, v in samples.items()},
    }
    write_report(f"collection_throughput_{args.task}", "collection_throughput.py", report)


if __name__ == "__main__":
    main()

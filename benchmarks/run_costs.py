"""Per-run costs as a local sweep sees them: two runs side by side, one torch thread each.

    python benchmarks/run_costs.py [--dt-steps 150] [--bc-steps 1000] [--eval-steps 1000]

Each of two spawned workers trains GC-DT and BC on the same PickAndPlace expert data (the
paper's model config, batch 64) and evaluates both; the report gives seconds per gradient
step and evaluation env steps/s (the median of the workers) -> results/bench/run_costs.json,
which `gcdt sweep --dry-run` uses for its estimates.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import tempfile
import time
from pathlib import Path
from statistics import median

from common import write_report

from gcdt.data import collect, load_dataset
from gcdt.policies import make_policy


def _worker(args: tuple[str, int, int, int, int]) -> dict[str, float]:
    import torch

    from gcdt.evaluation import evaluate
    from gcdt.policies.trained import TrainedPolicy
    from gcdt.training import TrainConfig, train

    data_path, seed, dt_steps, bc_steps, eval_steps = args
    torch.set_num_threads(1)
    dataset, out = load_dataset(data_path), {}
    with tempfile.TemporaryDirectory() as tmp:
        for method, steps in (("dt", dt_steps), ("bc", bc_steps)):
            began = time.perf_counter()
            result = train(
                dataset,
                TrainConfig(method=method, steps=steps, seed=seed),
                Path(tmp) / method,
                progress=False,
            )
            out[f"{method}_seconds_per_step"] = (time.perf_counter() - began) / result.steps
            policy = TrainedPolicy(result.checkpoint, dataset.task)
            summary = evaluate(
                policy, dataset.task, "sparse", timesteps=eval_steps, seed=seed, progress=False
            ).summary
            out[f"{method}_eval_steps_per_second"] = summary["steps_per_second"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dt-steps", type=int, default=100)
    parser.add_argument("--bc-steps", type=int, default=1000)
    parser.add_argument("--eval-steps", type=int, default=1000)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "pnp.npz"
        policy = make_policy("scripted", "pick_and_place")
        collect(policy, "pick_and_place", 2000, seed=0, progress=False).save(path)
        jobs = [(str(path), seed, args.dt_steps, args.bc_steps, args.eval_steps) for seed in (0, 1)]
        with mp.get_context("spawn").Pool(2) as pool:
            cells = pool.map(_worker, jobs)
    results = {k: round(median(c[k] for c in cells), 5) for k in cells[0]}
    write_report(
        "run_costs",
        "run_costs.py",
        {
            "layout": "2 runs in parallel, 1 torch thread each (a local sweep on 2 cores)",
            "task": "pick_and_place",
            "results": results,
            "workers": cells,
        },
    )


if __name__ == "__main__":
    main()

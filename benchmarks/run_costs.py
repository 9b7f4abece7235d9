"""Per-run costs as a local sweep sees them: two runs side by side, one torch thread each.

    python benchmarks/run_costs.py [--dt-steps 100] [--bc-steps 1000] [--eval-steps 10000]

Each of two spawned workers trains GC-DT and BC on the same PickAndPlace expert data (the
paper's model config, batch 64) and evaluates both; the report gives seconds per gradient
step and evaluation env steps/s (the median of the workers) -> results/bench/run_costs.json,
which `gcdt sweep --dry-run` uses for its estimates. The DT is also evaluated on 4 envs, as
the grid's runs are (`eval_envs`), with the envs in processes of their own and in the run's
own process (`in_process`, what a run of one core does): `dt_eval_4_envs_in_process_speedup`.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
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
            if method == "dt":  # the grid's 4 envs, in processes and in this one
                for in_process, name in ((False, "processes"), (True, "in_process")):
                    result = evaluate(
                        policy,
                        dataset.task,
                        "sparse",
                        timesteps=eval_steps,
                        n_envs=4,
                        seed=seed,
                        in_process=in_process,
                        progress=False,
                    )
                    # Wall time, the envs' start included: what a run pays for its evaluation.
                    out[f"dt_eval_4_envs_{name}_steps_per_second"] = (
                        result.timesteps / result.wall_seconds
                    )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dt-steps", type=int, default=100)
    parser.add_argument("--bc-steps", type=int, default=1000)
    parser.add_argument("--eval-steps", type=int, default=10_000)  # the grid's evaluation
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "pnp.npz"
        policy = make_policy("scripted", "pick_and_place")
        collect(policy, "pick_and_place", 2000, seed=0, progress=False).save(path)
        jobs = [(str(path), seed, args.dt_steps, args.bc_steps, args.eval_steps) for seed in (0, 1)]
        # As the sweep's workers: spawned, and free to start env processes (a Pool's are not).
        with ProcessPoolExecutor(2, mp_context=mp.get_context("spawn")) as pool:
            cells = list(pool.map(_worker, jobs))
    results = {k: round(median(c[k] for c in cells), 5) for k in cells[0]}
    results["dt_eval_4_envs_in_process_speedup"] = round(
        results["dt_eval_4_envs_in_process_steps_per_second"]
        / results["dt_eval_4_envs_processes_steps_per_second"],
        3,
    )
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

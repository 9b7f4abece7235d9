"""Training step cost of the paper's DT config (batch 64, K 20, hidden 128, 3 layers) and BC.

    python benchmarks/training_throughput.py [--steps 30] [--repeats 3]

Writes results/bench/training_throughput.json: ms per full training step (sample, forward,
backward, clip, AdamW) in fp32 and with bf16 autocast, BC's, and the batch sampler's share.
Data: a PickAndPlace-shaped dataset of 1,000 50-step episodes (the step cost depends on the
shapes only). Each cell is the median over interleaved repeats.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import asdict

import numpy as np
import torch
from common import write_report

from gcdt.data import from_episodes
from gcdt.envs import compute_rewards
from gcdt.models import BCConfig, DTConfig
from gcdt.training import TrainConfig, WindowSampler, build_model, train_step


def _dataset(episodes: int = 1000, length: int = 50):
    rng = np.random.default_rng(0)
    eps = []
    for e in range(episodes):
        goal = rng.normal(size=3).astype(np.float32)
        ag = rng.normal(size=(length + 1, 3)).astype(np.float32)
        r = compute_rewards(ag[1:], np.repeat(goal[None], length, 0), "pick_and_place")
        truncated = np.zeros(length, bool)
        truncated[-1] = True
        eps.append({
            "observation": rng.normal(size=(length, 19)).astype(np.float32),
            "desired_goal": np.repeat(goal[None], length, 0), "achieved_goal": ag[:-1],
            "action": rng.uniform(-1, 1, (length, 4)).astype(np.float32),
            "reward_sparse": r["sparse"], "reward_dense": r["dense"],
            "terminated": np.zeros(length, bool), "truncated": truncated,
            "success": np.zeros(length, bool), "final_observation": np.zeros(19, np.float32),
            "final_desired_goal": goal, "final_achieved_goal": ag[-1], "episode_seed": e,
        })  # fmt: skip
    return from_episodes("pick_and_place", eps, {"source": "benchmark"})


def _ms_per_step(dataset, cfg: TrainConfig, steps: int) -> tuple[float, float]:
    """(ms per training step, ms per batch sample) after a warm-up."""
    torch.manual_seed(0)
    d, a = dataset.spec.state_dim, dataset.spec.action_dim
    config = DTConfig(d, a) if cfg.method == "dt" else BCConfig(d, a)
    model = build_model(cfg.method, asdict(config))
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    sampler = WindowSampler(dataset, cfg, np.zeros(d, np.float32), np.ones(d, np.float32),
                            torch.device("cpu"))  # fmt: skip
    rng = np.random.default_rng(0)

    def step():
        train_step(model, opt, sampler.sample(rng), cfg, torch.device("cpu"))

    for _ in range(3):
        step()
    started = time.perf_counter()
    for _ in range(steps):
        step()
    per_step = (time.perf_counter() - started) / steps
    started = time.perf_counter()
    for _ in range(steps):
        sampler.sample(rng)
    return 1e3 * per_step, 1e3 * (time.perf_counter() - started) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    dataset = _dataset()
    cells = {
        "dt_fp32": TrainConfig(steps=1),
        "dt_bf16": TrainConfig(steps=1, bf16=True),
        "bc_fp32": TrainConfig(method="bc", steps=1),
    }
    samples: dict[str, list[tuple[float, float]]] = {k: [] for k in cells}
    for _ in range(args.repeats):
        for key, cfg in cells.items():
            samples[key].append(_ms_per_step(dataset, cfg, args.steps))
    results = {}
    for key, values in samples.items():
        step_ms = float(np.median([v[0] for v in values]))
        sample_ms = float(np.median([v[1] for v in values]))
        results[f"{key}_ms_per_step"] = round(step_ms, 2)
        results[f"{key}_samples_per_second"] = round(64 * 1e3 / step_ms, 1)
        results[f"{key}_sampler_share"] = round(sample_ms / step_ms, 4)
    report = {
        "unit": "ms per training step (batch 64), median of repeats",
        "config": {"batch": 64, "context": 20, "hidden": 128, "layers": 3, "heads": 1},
        "torch_threads": torch.get_num_threads(),
        "results": results,
    }
    write_report("training_throughput", "training_throughput.py", report)


if __name__ == "__main__":
    main()

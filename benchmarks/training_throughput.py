"""DT training throughput: gcdt's trainer step vs the authors' HuggingFace path, and BC's.

    python benchmarks/training_throughput.py [--steps 10] [--repeats 5] [--bf16-steps 2]
                                             [--device cpu|cuda]

Writes results/bench/training_throughput.json (`_cuda.json` with `--device cuda`). One full
training step (forward, masked MSE, backward, clip 0.25, AdamW) of the paper's config (batch
64, K 20, hidden 128, 3 layers, 1 head, dropout 0.1) in fp32 and with bf16 autocast, for
* gcdt: `gcdt.training.train_step` with `make_optimizer`, as `gcdt train` runs it;
* the authors' path: HuggingFace `transformers.DecisionTransformerModel` (the same config,
  ReLU, tanh actions) with the masked-MSE loss of their trainer and torch's AdamW (the HF
  Trainer's `adamw_torch`). Optional: the cell is skipped, and said so, when `transformers`
  is not installed (environment/requirements.txt pins it).
Both step on the very same batches, drawn beforehand by gcdt's sampler, whose own cost is
reported as its share of gcdt's step. Data: a PickAndPlace-shaped dataset of 1,000 50-step
episodes (19 % of a window's tokens are left padding); for the `*_short` cells one of
13-step episodes, the length of the quick profile's scripted PickAndPlace episodes (63 %
padding, which gcdt skips and HF computes); for the `*_tqc` cells one whose episode lengths are
drawn from those of the published Push TQC+HER expert (`--tqc-agent`), which collects the
`large` profile's data, measured here on its first 10,000 collected transitions. Cells run
interleaved, each gcdt cell beside its HF twin; a cell's time is the median of the repeats,
the speed-up the median of the repeats' paired ratios.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import asdict

import numpy as np
import torch
from common import write_report

from gcdt.checkpoint import build_model
from gcdt.data import from_episodes
from gcdt.device import resolve_device
from gcdt.envs import compute_rewards
from gcdt.models import BCConfig, DTConfig
from gcdt.paths import REPO_ROOT
from gcdt.training import TrainConfig, WindowSampler, keep_freed_memory, make_optimizer, train_step


def _dataset(episodes: int = 1000, length: int = 50, lengths: np.ndarray | None = None):
    """Random PickAndPlace-shaped episodes of `length` steps, or of lengths drawn from
    `lengths`."""
    rng = np.random.default_rng(0)
    eps = []
    for e in range(episodes):
        if lengths is not None:
            length = int(rng.choice(lengths))
        goal = rng.normal(size=3).astype(np.float32)
        ag = rng.normal(size=(length + 1, 3)).astype(np.float32)
        r = compute_rewards(ag[1:], np.repeat(goal[None], length, 0), "pick_and_place")
        truncated = np.zeros(length, bool)
        truncated[-1] = True
        eps.append(
            {
                "observation": rng.normal(size=(length, 19)).astype(np.float32),
                "desired_goal": np.repeat(goal[None], length, 0),
                "achieved_goal": ag[:-1],
                "action": rng.uniform(-1, 1, (length, 4)).astype(np.float32),
                "reward_sparse": r["sparse"],
                "reward_dense": r["dense"],
                "terminated": np.zeros(length, bool),
                "truncated": truncated,
                "success": np.zeros(length, bool),
                "final_observation": np.zeros(19, np.float32),
                "final_desired_goal": goal,
                "final_achieved_goal": ag[-1],
                "episode_seed": e,
            }
        )
    return from_episodes("pick_and_place", eps, {"source": "benchmark"})


def _agent_lengths(agent: str, task: str = "push", transitions: int = 10_000) -> np.ndarray:
    """Episode lengths of the first `transitions` steps the published agent collects."""
    from gcdt.data import collect
    from gcdt.policies import make_policy

    path = REPO_ROOT / agent  # a relative path is the repository's, as in the profiles
    data = collect(make_policy(f"tqc:{path}", task), task, transitions, progress=False)
    return data.episode_lengths


def _time(step: Callable[[int], object], steps: int, warmup: int, device: torch.device) -> float:
    """ms per call of `step(i)` after `warmup` calls (a GPU's queue drained at both ends)."""
    sync = torch.cuda.synchronize if device.type == "cuda" else lambda: None
    for i in range(warmup):
        step(i)
    sync()
    began = time.perf_counter()
    for i in range(steps):
        step(i)
    sync()
    return 1e3 * (time.perf_counter() - began) / steps


def _gcdt(cfg: TrainConfig, dim: int, batches: list[dict[str, torch.Tensor]]):
    torch.manual_seed(0)
    d, a = dim, 4
    config = DTConfig(d, a) if cfg.method == "dt" else BCConfig(d, a)
    device = batches[0]["states"].device
    model = build_model(cfg.method, asdict(config)).to(device).train()
    opt = make_optimizer(model, cfg)
    return lambda i: train_step(model, opt, batches[i % len(batches)], cfg, device)


def _huggingface(bf16: bool, dim: int, batches: list[dict[str, torch.Tensor]]):
    from gcdt.hf_reference import hf_actions, hf_model

    torch.manual_seed(0)
    device = batches[0]["states"].device
    model = hf_model(DTConfig(dim, 4)).to(device).train()
    opt = torch.optim.AdamW(model.parameters(), lr=1e-4, weight_decay=1e-4)

    def step(i: int) -> None:
        b = batches[i % len(batches)]
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=bf16):
            pred = hf_actions(
                model, b["states"], b["actions"], b["returns_to_go"], b["timesteps"], b["mask"]
            )
            keep = b["mask"].reshape(-1)  # the authors' loss: real tokens only
            loss = torch.mean((pred.reshape(-1, 4)[keep] - b["actions"].reshape(-1, 4)[keep]) ** 2)
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 0.25)
        opt.step()

    return step


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=5)
    # Few bf16 steps: a CPU without native bfloat16 (AVX512-BF16 / AMX; machine info's
    # cpu_bf16) emulates it ~15-25x slower than fp32.
    parser.add_argument("--bf16-steps", type=int, default=2)
    parser.add_argument("--device", default="cpu", help="cpu or cuda (both paths on it)")
    parser.add_argument(
        "--tqc-agent",
        default="results/experts/tqc_push_sparse/model.zip",
        help="the published agent whose episode lengths the *_tqc cells take ('': skip them)",
    )
    args = parser.parse_args()
    device = resolve_device(args.device)
    if device.type == "cpu":  # as `gcdt train` on CPU; process-wide, so HF runs under it too
        keep_freed_memory()
    dataset = _dataset()
    dim = dataset.spec.state_dim
    rng = np.random.default_rng(0)

    def sampler(data, method: str) -> WindowSampler:
        zeros, ones = np.zeros(dim, np.float32), np.ones(dim, np.float32)
        return WindowSampler(data, TrainConfig(method=method), zeros, ones, device)

    samplers = {method: sampler(dataset, method) for method in ("dt", "bc")}
    samplers["dt_short"] = sampler(_dataset(length=13), "dt")
    tqc_lengths = _agent_lengths(args.tqc_agent) if args.tqc_agent else None
    if tqc_lengths is not None:
        samplers["dt_tqc"] = sampler(_dataset(lengths=tqc_lengths), "dt")
    batches = {m: [s.sample(rng) for _ in range(8)] for m, s in samplers.items()}
    hf = _version("transformers") != "not installed"
    # Each gcdt cell right beside its HF twin: this VM's speed drifts within minutes.
    cells: dict[str, Callable[[], Callable[[int], object]]] = {
        "gcdt_fp32": lambda: _gcdt(TrainConfig(), dim, batches["dt"]),
        **({"huggingface_fp32": lambda: _huggingface(False, dim, batches["dt"])} if hf else {}),
        "gcdt_bf16": lambda: _gcdt(TrainConfig(bf16=True), dim, batches["dt"]),
        **({"huggingface_bf16": lambda: _huggingface(True, dim, batches["dt"])} if hf else {}),
        "gcdt_fp32_short": lambda: _gcdt(TrainConfig(), dim, batches["dt_short"]),
        **(
            {"huggingface_fp32_short": lambda: _huggingface(False, dim, batches["dt_short"])}
            if hf
            else {}
        ),
        **(
            {"gcdt_fp32_tqc": lambda: _gcdt(TrainConfig(), dim, batches["dt_tqc"])}
            if tqc_lengths is not None
            else {}
        ),
        **(
            {"huggingface_fp32_tqc": lambda: _huggingface(False, dim, batches["dt_tqc"])}
            if hf and tqc_lengths is not None
            else {}
        ),
        "bc_fp32": lambda: _gcdt(TrainConfig(method="bc"), dim, batches["bc"]),
        "dt_sampler": lambda: lambda i: samplers["dt"].sample(rng),
        "bc_sampler": lambda: lambda i: samplers["bc"].sample(rng),
    }
    samples: dict[str, list[float]] = {k: [] for k in cells}
    for _ in range(args.repeats):
        for key, make in cells.items():
            slow = key.endswith("bf16") and device.type == "cpu"
            steps, warmup = (args.bf16_steps, 1) if slow else (args.steps, 3)
            samples[key].append(_time(make(), steps, warmup, device))
    ms = {k: float(np.median(v)) for k, v in samples.items()}
    results: dict[str, float | None] = {}
    for key in (
        "gcdt_fp32",
        "gcdt_bf16",
        "huggingface_fp32",
        "huggingface_bf16",
        "gcdt_fp32_short",
        "huggingface_fp32_short",
        "gcdt_fp32_tqc",
        "huggingface_fp32_tqc",
        "bc_fp32",
    ):
        if key in ms:
            results[f"{key}_ms_per_step"] = round(ms[key], 2)
            results[f"{key}_samples_per_second"] = round(64e3 / ms[key], 1)
    for precision in ("fp32", "bf16", "fp32_short", "fp32_tqc"):  # median of paired ratios
        ours, theirs = samples.get(f"gcdt_{precision}"), samples.get(f"huggingface_{precision}")
        results[f"speedup_vs_huggingface_{precision}"] = (
            None
            if theirs is None or ours is None
            else round(float(np.median(np.divide(theirs, ours))), 3)
        )
    results["dt_sampler_share"] = round(ms["dt_sampler"] / ms["gcdt_fp32"], 4)
    results["bc_sampler_share"] = round(ms["bc_sampler"] / ms["bc_fp32"], 4)
    report = {
        "unit": "ms per training step (batch 64), median of interleaved repeats",
        "speedup": "median over repeats of huggingface ms / gcdt ms, measured side by side",
        "config": {
            "batch": 64,
            "context": 20,
            "hidden": 128,
            "layers": 3,
            "heads": 1,
            "dropout": 0.1,
            "state_dim": dim,
            "episode_steps": {"dt": 50, "dt_short": 13},
            "tqc_agent": args.tqc_agent or None,
            "tqc_episode_steps": None
            if tqc_lengths is None
            else {
                "episodes": len(tqc_lengths),
                "mean": round(float(tqc_lengths.mean()), 2),
                "percentiles_5_50_95": [int(q) for q in np.percentile(tqc_lengths, [5, 50, 95])],
            },
            "padding_share": {  # of the tokens of the batches timed
                m: round(1 - float(torch.cat([b["mask"] for b in batches[m]]).float().mean()), 3)
                for m in batches
                if m.startswith("dt")
            },
        },
        "targets": {
            "speedup_vs_huggingface_fp32": ">= 1.5",
            "speedup_vs_huggingface_fp32_tqc": ">= 2",
            "dt_sampler_share": "<= 0.05",
        },
        "huggingface": "transformers " + _version("transformers"),
        "device": str(device),
        "torch_threads": torch.get_num_threads(),
        "results": results,
        "samples_ms": {k: [round(x, 2) for x in v] for k, v in samples.items()},
    }
    suffix = "" if device.type == "cpu" else f"_{device.type}"
    write_report(f"training_throughput{suffix}", "training_throughput.py", report)


def _version(package: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(package)
    except PackageNotFoundError:
        return "not installed"


if __name__ == "__main__":
    main()

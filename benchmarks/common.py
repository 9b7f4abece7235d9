"""What every benchmark shares: machine info, raw-simulator ceilings, the JSON report."""

from __future__ import annotations

import contextlib
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from gcdt.envs import episode_seed, make_env, make_vec_env
from gcdt.paths import REPO_ROOT, write_json_atomic
from gcdt.policies import Policy
from gcdt.provenance import machine_info

BENCH_DIR = REPO_ROOT / "results" / "bench"


def write_report(name: str, script: str, report: dict[str, Any]) -> Path:
    """Write `results/bench/<name>.json` with the command and the machine, and print it."""
    full = {
        "benchmark": name,
        "command": "python " + " ".join([f"benchmarks/{script}", *sys.argv[1:]]),
        **report,
        "machine": machine_info(),
    }
    path = write_json_atomic(BENCH_DIR / f"{name}.json", full)
    print(json.dumps(full, indent=2))
    return path


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


def raw_vector(task: str, steps: int, n_envs: int, policy: Policy | None = None) -> float:
    """Steps/s of the vector env with masked seeded resets and nothing else: the ceiling for
    anything that steps `n_envs` envs (evaluation, collection).

    Actions are uniform random, or `policy`'s (to price the physics of its trajectories:
    contact-rich expert motions cost more per step than random flailing).
    """
    with contextlib.closing(make_vec_env(task, "sparse", n_envs)) as envs:
        rng = np.random.default_rng(0)
        obs, _ = envs.reset(seed=[episode_seed(0, j) for j in range(n_envs)])
        shape = (n_envs, *envs.single_action_space.shape)
        if policy is not None:
            policy.reset(n_envs, 0)
        no_start, no_reward = np.zeros(n_envs, bool), np.zeros(n_envs, np.float32)
        started, episode = time.perf_counter(), n_envs
        for _ in range(steps // n_envs):
            action = (
                rng.uniform(-1, 1, shape).astype(np.float32)
                if policy is None
                else policy.predict(obs, no_start, no_reward)
            )
            obs, _, terminated, truncated, _ = envs.step(action)
            done = terminated | truncated
            if done.any():
                seeds = [episode_seed(0, episode + i) if d else None for i, d in enumerate(done)]
                episode += int(done.sum())
                obs, _ = envs.reset(seed=seeds, options={"reset_mask": done})
        return (steps // n_envs) * n_envs / (time.perf_counter() - started)

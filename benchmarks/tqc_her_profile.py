"""Where TQC+HER's time goes per env step: today's SB3 loop, profiled.

    python benchmarks/tqc_her_profile.py [--task push] [--config cpu] [--learning-steps 1000]

Trains the config (gcdt/baselines/tqc_her.yaml) for its `learning_starts` random steps plus
`--learning-steps` learning steps under cProfile, then splits the learning phase's time per
env step into: the simulator step (the vector env's `step_wait`), HER's replay sampling less
its reward recomputation, the reward recomputation (`compute_reward` through `env_method`),
the gradient step (TQC's `train` less its sampling), the collection's action choice, adding to
the replay buffer, and the rest of SB3's loop -> results/bench/tqc_her_profile.json. The
profiler adds its own cost to Python-heavy parts, so the shares are indicative; the same run's
unprofiled env steps/s is `benchmarks/tqc_her.py throughput`'s number.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import shutil
import tempfile
import time
from pathlib import Path

from common import write_report

from gcdt.baselines.tqc_her import load_tqc_config, train_tqc

#: (part, the functions whose cumulative time it is, by (file suffix, function name)).
PARTS = {
    "learn": [("base_class.py", "learn"), ("off_policy_algorithm.py", "learn")],
    "env_step": [("dummy_vec_env.py", "step_wait")],
    "her_sample": [("her_replay_buffer.py", "sample")],
    "reward_recompute": [("dummy_vec_env.py", "env_method")],
    "train": [("tqc.py", "train")],
    "action": [("off_policy_algorithm.py", "_sample_action")],
    "buffer_add": [("her_replay_buffer.py", "add")],
}


def _cumulative(stats: pstats.Stats, targets: list[tuple[str, str]]) -> float:
    """The largest cumulative time among functions matching `targets` (nested calls of one
    function are counted once by cProfile's cumtime)."""
    best = 0.0
    for (path, _, name), (_, _, _, cumtime, _) in stats.stats.items():
        if any(path.endswith(suffix) and name == fn for suffix, fn in targets):
            best = max(best, cumtime)
    return best


def profile(task: str, config: str, learning_steps: int) -> dict:
    cfg = load_tqc_config(config, task)
    cfg = cfg.with_budget(steps=cfg.learning_starts + learning_steps)
    out = Path(tempfile.mkdtemp(prefix="tqc_profile_"))
    profiler = cProfile.Profile()
    began = time.perf_counter()
    try:
        profiler.enable()
        train_tqc(
            task, "sparse", cfg, out / "run", eval_every=cfg.steps, eval_episodes=1, progress=False
        )
        profiler.disable()
    finally:
        shutil.rmtree(out)
    wall = time.perf_counter() - began
    stats = pstats.Stats(profiler)
    seconds = {part: _cumulative(stats, targets) for part, targets in PARTS.items()}
    parts = {
        "env_step": seconds["env_step"],
        "her_sampling": seconds["her_sample"] - seconds["reward_recompute"],
        "reward_recompute": seconds["reward_recompute"],
        "gradient_step": seconds["train"] - seconds["her_sample"],
        "action": seconds["action"],
        "buffer_add": seconds["buffer_add"],
    }
    parts["sb3_loop_rest"] = seconds["learn"] - sum(parts.values())
    learning_only = ("her_sampling", "reward_recompute", "gradient_step")
    return {
        "task": task,
        "config": config,
        "net_arch": list(cfg.net_arch),
        "batch_size": cfg.batch_size,
        "env_steps": cfg.steps,
        "learning_steps": learning_steps,
        "profiled_wall_seconds": round(wall, 1),
        "seconds": {k: round(v, 3) for k, v in parts.items()},
        "share": {k: round(v / seconds["learn"], 3) for k, v in parts.items()},
        # The learning phase's cost of one env step: its own parts per learning step, the
        # others (taken on every env step, warm-up included) per env step.
        "ms_per_learning_env_step": {
            k: round(1000 * v / (learning_steps if k in learning_only else cfg.steps), 3)
            for k, v in parts.items()
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="push")
    parser.add_argument("--config", default="cpu")
    parser.add_argument("--learning-steps", type=int, default=1000)
    args = parser.parse_args()
    write_report(
        "tqc_her_profile",
        "tqc_her_profile.py",
        profile(args.task, args.config, args.learning_steps),
    )


if __name__ == "__main__":
    main()

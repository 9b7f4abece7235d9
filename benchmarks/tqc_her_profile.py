"""Where TQC+HER's time goes per env step, in both loops, and how fast the new one can get.

    python benchmarks/tqc_her_profile.py [--task push] [--config cpu] [--learning-steps 1600]

Trains the config (gcdt/baselines/tqc_her.yaml) for its `learning_starts` random steps plus
`--learning-steps` learning steps under cProfile, once in today's loop (sb3-contrib's TQC on
one env) and once in the config's own (SBX's on 8 envs), and splits each learning phase's time
per env step into: the simulator step (the vector env's `step_wait`), HER's replay sampling
less its reward recomputation, the reward recomputation (`compute_reward` through
`env_method`), the gradient step (TQC's `train` less its sampling), the collection's action
choice, adding to the replay buffer, and the rest of SB3's loop ->
results/bench/tqc_her_profile.json. The profiler adds its own cost to Python-heavy parts, so
the shares are indicative; unprofiled env steps/s are `benchmarks/tqc_her.py throughput`'s.

`gradient_step_speedup` compares the two gradient steps alone (the same networks and batch).
`speedup_ceiling` is today's loop's time per env step over the new loop's gradient step: the
speed-up the new loop would have if everything but its gradient steps took no time (an upper
bound, more so as the profiler slows today's Python-heavier loop). Each update needs the
previous one's weights and the next action needs both, so the gradient steps cannot overlap
the env steps without changing the algorithm.
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
from tqc_her import SB3_LOOP

from gcdt.baselines.tqc_her import TQCConfig, load_tqc_config, train_tqc

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
    loops = {
        loop: _profile_loop(task, config, learning_steps, changes)
        for loop, changes in (("sb3", SB3_LOOP), ("new", {}))
    }
    ms = {loop: cell["ms_per_learning_env_step"] for loop, cell in loops.items()}
    return {
        "task": task,
        "config": config,
        "learning_steps": learning_steps,
        "loops": loops,
        "gradient_step_speedup": round(ms["sb3"]["gradient_step"] / ms["new"]["gradient_step"], 2),
        "speedup_ceiling": round(sum(ms["sb3"].values()) / ms["new"]["gradient_step"], 2),
    }


def _profile_loop(task: str, config: str, learning_steps: int, changes: dict) -> dict:
    """One loop's time per learning env step: a run of `learning_starts` + `learning_steps`
    env steps less a run of `learning_starts` + 2 loop iterations, both profiled, so random
    warm-up steps and JAX's compilation (per model, in the first iterations) cancel out."""
    cfg = load_tqc_config(config, task).with_budget(**changes)
    short = 2 * cfg.n_envs
    began = time.perf_counter()
    base = _profiled_seconds(task, cfg.with_budget(steps=cfg.learning_starts + short))
    full = _profiled_seconds(task, cfg.with_budget(steps=cfg.learning_starts + learning_steps))
    wall = time.perf_counter() - began
    seconds = {part: full[part] - base[part] for part in full}
    parts = {
        "env_step": seconds["env_step"],
        "her_sampling": seconds["her_sample"] - seconds["reward_recompute"],
        "reward_recompute": seconds["reward_recompute"],
        "gradient_step": seconds["train"] - seconds["her_sample"],
        "action": seconds["action"],
        "buffer_add": seconds["buffer_add"],
    }
    parts["sb3_loop_rest"] = seconds["learn"] - sum(parts.values())
    steps = learning_steps - short
    return {
        "backend": cfg.backend,
        "n_envs": cfg.n_envs,
        "net_arch": list(cfg.net_arch),
        "batch_size": cfg.batch_size,
        "measured_env_steps": steps,
        "profiled_wall_seconds": round(wall, 1),
        "seconds": {k: round(v, 3) for k, v in parts.items()},
        "share": {k: round(v / seconds["learn"], 3) for k, v in parts.items()},
        "ms_per_learning_env_step": {k: round(1000 * v / steps, 3) for k, v in parts.items()},
    }


def _profiled_seconds(task: str, cfg: TQCConfig) -> dict[str, float]:
    """Cumulative seconds of each of PARTS' functions in one training run."""
    out = Path(tempfile.mkdtemp(prefix="tqc_profile_"))
    profiler = cProfile.Profile()
    try:
        profiler.enable()
        train_tqc(
            task, "sparse", cfg, out / "run", eval_every=cfg.steps, eval_episodes=1, progress=False
        )
        profiler.disable()
    finally:
        shutil.rmtree(out)
    stats = pstats.Stats(profiler)
    return {part: _cumulative(stats, targets) for part, targets in PARTS.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="push")
    parser.add_argument("--config", default="cpu")
    parser.add_argument("--learning-steps", type=int, default=1600)
    args = parser.parse_args()
    write_report(
        "tqc_her_profile",
        "tqc_her_profile.py",
        profile(args.task, args.config, args.learning_steps),
    )


if __name__ == "__main__":
    main()

"""Does a killed-and-resumed TQC+HER run learn like an uninterrupted one?

    python benchmarks/tqc_resume.py [--task reach] [--seeds 0 1 2] [--steps 6000]

A resume restores the learner exactly, and the envs by replaying their current episodes; on
Push and PickAndPlace PyBullet carries state over from an env's earlier episodes that the
replay does not rebuild (docs/library.md), so there the question is statistical (on Reach the
curves must be equal). For each seed the same command runs twice: once uninterrupted, once SIGKILLed
at the first checkpoint past `--kill-at` env steps and then continued with `--resume`. Both
evaluate on the same held-out episodes every `--eval-every` steps. The report puts the gap
between a seed's two curves beside the two yardsticks it must stay within: the binomial
standard error of a difference of two success rates, and the spread between seeds
-> results/bench/tqc_resume_<task>.json.
"""

from __future__ import annotations

import argparse
import csv
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from common import write_report

from gcdt.baselines.tqc_checkpoint import CHECKPOINT_FILE, read_header


def _argv(args: argparse.Namespace, seed: int, out: Path) -> list[str]:
    return [
        sys.executable, "-m", "gcdt", "tqc", "train", "--task", args.task, "--reward", "sparse",
        "--config", "cpu", "--steps", str(args.steps), "--seed", str(seed),
        "--eval-every", str(args.eval_every), "--eval-episodes", str(args.eval_episodes),
        "--checkpoint-seconds", str(args.checkpoint_seconds), "--out", str(out), "--no-progress",
    ]  # fmt: skip


def _curve(out: Path) -> list[float]:
    with open(out / "eval.csv", newline="") as f:
        return [float(row["success_rate"]) for row in csv.DictReader(f)]


def _killed_then_resumed(argv: list[str], out: Path, kill_at: int) -> dict[str, float]:
    """Run `argv`, SIGKILL it once a checkpoint past `kill_at` steps is on disk, resume it."""
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    ckpt = out / CHECKPOINT_FILE
    while proc.poll() is None:
        if ckpt.exists() and read_header(ckpt)["env_steps"] > kill_at:
            break
        time.sleep(0.2)
    if proc.poll() is not None:
        raise SystemExit(f"the run ended before {kill_at} steps: {proc.stderr.read().decode()}")
    os.kill(proc.pid, signal.SIGKILL)
    killed = time.time()
    proc.wait()
    kill = {
        "killed_at_steps": read_header(ckpt)["env_steps"],
        "lost_seconds": killed - ckpt.stat().st_mtime,
    }
    subprocess.run([*argv, "--resume"], check=True, stdout=subprocess.DEVNULL)
    return kill


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="reach")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--steps", type=int, default=6000)
    parser.add_argument("--eval-every", type=int, default=1000)
    parser.add_argument("--eval-episodes", type=int, default=100)
    parser.add_argument("--kill-at", type=int, default=2000)
    parser.add_argument("--checkpoint-seconds", type=float, default=30)
    args = parser.parse_args()
    whole, resumed, kills = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            a, b = Path(tmp) / f"whole_{seed}", Path(tmp) / f"resumed_{seed}"
            subprocess.run(_argv(args, seed, a), check=True, stdout=subprocess.DEVNULL)
            kills.append(_killed_then_resumed(_argv(args, seed, b), b, args.kill_at))
            whole.append(_curve(a))
            resumed.append(_curve(b))
    p, q, n = np.array(whole), np.array(resumed), args.eval_episodes
    gap = np.abs(p - q)
    # The standard error of a difference of two success rates measured on n episodes each
    # (0.5/sqrt(n) per rate where the observed rate is 0 or 1, so it never vanishes).
    se = np.sqrt(np.maximum(p * (1 - p), 0.25 / n) / n + np.maximum(q * (1 - q), 0.25 / n) / n)
    spread = np.concatenate([p, q]).std(axis=0, ddof=1) if len(args.seeds) > 1 else None
    marks = [args.eval_every * (i + 1) for i in range(p.shape[1])]
    write_report(
        f"tqc_resume_{args.task}",
        "tqc_resume.py",
        {
            "task": args.task,
            "seeds": args.seeds,
            "env_steps": args.steps,
            "eval_episodes": n,
            "checkpoint_seconds": args.checkpoint_seconds,
            "marks": marks,
            "uninterrupted": p.tolist(),
            "resumed": q.tolist(),
            "kills": kills,
            "gap": {
                "mean": round(float(gap.mean()), 4),
                "max": round(float(gap.max()), 4),
                "within_2_se": round(float((gap <= 2 * se).mean()), 4),
            },
            "seed_spread_mean": None if spread is None else round(float(spread.mean()), 4),
            "max_lost_seconds": round(max(k["lost_seconds"] for k in kills), 1),
        },
    )


if __name__ == "__main__":
    main()

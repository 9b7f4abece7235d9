"""What a TQC+HER checkpoint costs at the end of a 1M-step run: seconds per save and per
restore, and MiB on disk, with the HER buffer full (1M transitions).

    python benchmarks/tqc_checkpoint.py [--task pick_and_place] [--repeats 3]

The model is the `cpu` config's (sbx backend, 8 envs); its buffer is filled with random
values (a checkpoint's size and time do not depend on what the buffer holds, only on how much)
-> results/bench/tqc_checkpoint_<task>.json.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path
from statistics import median

import numpy as np
from common import write_report

from gcdt.baselines.tqc_checkpoint import load_checkpoint, save_checkpoint
from gcdt.baselines.tqc_her import build_tqc, load_tqc_config


def _filled_model(task: str, seed: int = 0):
    cfg = load_tqc_config("cpu", task)
    model = build_tqc(cfg, task, "sparse", seed)
    model.env.reset()  # each env at the start of its first episode, as after any reset
    buffer, rng = model.replay_buffer, np.random.default_rng(seed)
    for value in vars(buffer).values():
        arrays = value.values() if isinstance(value, dict) else [value]
        for array in arrays:
            if isinstance(array, np.ndarray) and len(array) == buffer.buffer_size:
                array[...] = rng.uniform(0, 50, array.shape).astype(array.dtype)
    buffer.full, buffer.pos = True, 0
    return cfg, model


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="pick_and_place")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    cfg, model = _filled_model(args.task)
    transitions = model.replay_buffer.buffer_size * model.replay_buffer.n_envs
    saves, loads = [], []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "checkpoint.tqc"
        for _ in range(args.repeats):
            started = time.perf_counter()
            size = save_checkpoint(path, model, {"task": args.task}, extra=None)
            saves.append(time.perf_counter() - started)
        for _ in range(args.repeats):
            fresh = build_tqc(cfg, args.task, "sparse", 0)
            started = time.perf_counter()
            load_checkpoint(path, fresh)
            loads.append(time.perf_counter() - started)
            fresh.env.close()
    write_report(
        f"tqc_checkpoint_{args.task}",
        "tqc_checkpoint.py",
        {
            "task": args.task,
            "config": cfg.name,
            "backend": cfg.backend,
            "buffer_transitions": int(transitions),
            "checkpoint_mib": round(size / 2**20, 1),
            "save_seconds_median": round(median(saves), 2),
            "save_seconds": [round(s, 2) for s in saves],
            "restore_seconds_median": round(median(loads), 2),
            "restore_seconds": [round(s, 2) for s in loads],
        },
    )


if __name__ == "__main__":
    main()

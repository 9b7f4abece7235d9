"""Dataset I/O: save and load of 1M transitions, Minari export and import of 100k.

    python benchmarks/dataset_io.py [--task push] [--collect 5000] [--transitions 1000000]

Writes results/bench/dataset_io_<task>.json. A real scripted-expert dataset of `--collect`
transitions is collected once and its episodes repeated up to `--transitions` (collecting 1M
transitions takes about an hour on 2 cores; I/O cost depends on the sizes, not on the values).
"Load to training-ready arrays" is `load_dataset` (with full validation) plus the goal-
conditioned states, returns-to-go and timesteps the trainer reads.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from common import write_report

from gcdt.data import collect, concatenate, export_minari, import_minari, load_dataset, subset
from gcdt.policies import make_policy


def _timed(fn):
    started = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="push")
    parser.add_argument("--collect", type=int, default=5_000)
    parser.add_argument("--transitions", type=int, default=1_000_000)
    parser.add_argument("--minari-transitions", type=int, default=100_000)
    args = parser.parse_args()

    real = collect(
        make_policy("scripted", args.task), args.task, args.collect, n_envs=2, progress=False
    )
    copies = -(-args.transitions // len(real))
    big = subset(concatenate([real] * copies, real.metadata), args.transitions, seed=0)
    small = subset(big, args.minari_transitions, seed=0)
    rows: dict[str, float] = {"transitions": len(big), "episodes": big.n_episodes}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "big.npz"
        _, rows["save_seconds"] = _timed(lambda: big.save(path))
        rows["file_mb"] = os.path.getsize(path) / 2**20
        loaded, rows["load_seconds"] = _timed(lambda: load_dataset(path))

        def training_ready():
            ds = load_dataset(path)
            return ds.states, ds.actions, ds.returns_to_go("sparse"), ds.timesteps

        _, rows["load_training_ready_seconds"] = _timed(training_ready)
        assert loaded.equal_data(big)

        os.environ["MINARI_DATASETS_PATH"] = str(Path(tmp) / "minari")
        rows["minari_transitions"] = len(small)
        _, rows["minari_export_seconds"] = _timed(lambda: export_minari(small, "bench/io-v0"))
        back, rows["minari_import_seconds"] = _timed(lambda: import_minari("bench/io-v0"))
        assert back.equal_data(small)
    report = {
        "unit": "seconds, MiB",
        "task": args.task,
        "collected": len(real),
        "results": {k: round(v, 3) if isinstance(v, float) else v for k, v in rows.items()},
    }
    write_report(f"dataset_io_{args.task}", "dataset_io.py", report)


if __name__ == "__main__":
    main()

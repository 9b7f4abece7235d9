"""Run one run of the quick grid again with the current code, into folders of its own.

    python scripts/quick_checks/rerun.py METHOD TASK REWARD --out FILE [--artifacts DIR]

Collects the run's dataset (the grid's data spec: same key, same data) if needed, trains and
evaluates exactly as `make reproduce PROFILE=quick` does, and copies the run's result JSON
to FILE. Used to check that a change to the training code leaves the published numbers
statistically unchanged.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
from pathlib import Path

from gcdt.experiments.grid import build_grid
from gcdt.experiments.profiles import get_profile
from gcdt.experiments.runner import execute_run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("method")
    parser.add_argument("task")
    parser.add_argument("reward")
    parser.add_argument("--out", required=True)
    parser.add_argument("--artifacts", default="artifacts/quick_checks/rerun")
    args = parser.parse_args()
    wanted = (args.method, args.task, args.reward)
    specs = [
        e.spec
        for e in build_grid(get_profile("quick"), "table1")
        if (e.spec.method, e.spec.task, e.spec.reward) == wanted
    ]
    if len(specs) != 1:
        raise SystemExit(f"error: no Table 1 run {' '.join(wanted)} in the quick grid")
    spec = specs[0]
    with tempfile.TemporaryDirectory() as store:
        status = execute_run(spec.to_dict(), store, str(Path(args.artifacts).resolve()), "local")
        if status != "done":
            raise SystemExit(f"error: run {spec.key()} {status}: see {store}")
        shutil.copy(Path(store) / f"{spec.key()}.json", args.out)
    print(f"run {spec.key()}: {args.out}")


if __name__ == "__main__":
    main()

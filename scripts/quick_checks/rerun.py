"""Run one Table 1 run of a profile's grid again with the current code, into folders of its own.

    python scripts/quick_checks/rerun.py METHOD TASK REWARD --out FILE [--artifacts DIR]
        [--profile P] [--seed S] [--noise STD] [--labels executed|clean] [--eval-seed E]

Collects the run's dataset (the grid's data spec: same key, same data) if needed, trains and
evaluates exactly as `make reproduce PROFILE=P` does, and copies the run's result JSON to
FILE. The default profile, `standard`, has the Table 1 that `quick` had when these checks
were made (20,000 transitions per dataset).

Used to check that a change to the training code leaves the published numbers statistically
unchanged, and, with `--noise`/`--labels` (the profile's expert data options) and
`--eval-seed` (evaluation episodes apart from the grid's own), to choose those options before
the grid runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import shutil
import tempfile
from pathlib import Path

from gcdt.data.collect import LABELS
from gcdt.experiments.grid import build_grid
from gcdt.experiments.profiles import PROFILES, get_profile
from gcdt.experiments.runner import execute_run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("method")
    parser.add_argument("task")
    parser.add_argument("reward")
    parser.add_argument("--out", required=True)
    parser.add_argument("--artifacts", default="artifacts/quick_checks/rerun")
    parser.add_argument(
        "--profile", default="standard", choices=list(PROFILES), help="whose Table 1 grid"
    )
    parser.add_argument("--seed", type=int, default=0, help="the run's training seed")
    parser.add_argument("--noise", type=float, help="the scripted experts' action noise std")
    parser.add_argument("--labels", choices=LABELS, help="the action a noisy collection records")
    parser.add_argument("--eval-seed", type=int, help="evaluate on this seed only")
    args = parser.parse_args()
    changes = {"expert_noise": args.noise, "expert_labels": args.labels}
    profile = dataclasses.replace(
        get_profile(args.profile), **{k: v for k, v in changes.items() if v is not None}
    )
    wanted = (args.method, args.task, args.reward, args.seed)
    specs = [
        e.spec
        for e in build_grid(profile, "table1")
        if (e.spec.method, e.spec.task, e.spec.reward, e.spec.seed) == wanted
    ]
    if len(specs) != 1:
        raise SystemExit(
            f"error: no Table 1 run {' '.join(map(str, wanted))} in the {profile.name} grid"
        )
    spec = specs[0]
    if args.eval_seed is not None:
        spec = dataclasses.replace(spec, eval_seeds=(args.eval_seed,))
    with tempfile.TemporaryDirectory() as store:
        status = execute_run(spec.to_dict(), store, str(Path(args.artifacts).resolve()), "local")
        if status != "done":
            raise SystemExit(f"error: run {spec.key()} {status}: see {store}")
        shutil.copy(Path(store) / f"{spec.key()}.json", args.out)
    print(f"run {spec.key()}: {args.out}")


if __name__ == "__main__":
    main()

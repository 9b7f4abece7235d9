"""Rename result files to the keys their runs have now, without running anything again.

    python scripts/migrate_run_keys.py [--profile P ...] [--check]

A run's key hashes everything the run computes from, resolved (`RunSpec.resolved`). When the
way a key is computed changes but no run's computation does (issue 41: configs by value, not
by name), the results already made are still right, filed under the old keys. This script
recomputes each result's key from the spec the file stores, renames the file, rewrites the
key inside it, and replaces the old key wherever a tracked text file of the repository
(README.md, docs, reports) names it. Only results of the current `RUN_SCHEMA` are moved: a
file of another schema was made under another meaning and is left for the sweep to re-run.
Running it again changes nothing.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
from pathlib import Path

from gcdt.experiments.grid import RUN_SCHEMA, RunSpec
from gcdt.paths import REPO_ROOT, results_dir

PROFILES = ("quick", "standard")  # the profiles whose results are published


def new_keys(runs: Path) -> dict[str, str]:
    """Old key -> new key of each result file in `runs` that is filed under a stale key."""
    moves = {}
    for path in sorted(runs.glob("*.json")):
        result = json.loads(path.read_text())
        if result.get("schema") != RUN_SCHEMA or result.get("key") != path.stem:
            print(f"skipped {path}: not a result of schema {RUN_SCHEMA} filed under its key")
            continue
        key = RunSpec.from_dict(result["spec"]).key()
        if key != path.stem:
            moves[path.stem] = key
    return moves


def move(runs: Path, moves: dict[str, str]) -> None:
    """Rename each file and the key inside it: a text edit, so the rest stays byte for byte."""
    for old, new in moves.items():
        target = runs / f"{new}.json"
        if target.exists():
            raise SystemExit(f"error: {target} exists already; two results claim run {new}")
        text = (runs / f"{old}.json").read_text()
        field = f'"key": "{old}"'
        if text.count(field) != 1:
            raise SystemExit(f"error: {runs / old}.json does not name its key once")
        target.write_text(text.replace(field, f'"key": "{new}"'))
        (runs / f"{old}.json").unlink()


def rewrite_references(moves: dict[str, str], runs_dirs: list[Path]) -> list[Path]:
    """Replace old keys in the repository's tracked text files (not in the run folders);
    return the files changed."""
    if not moves:
        return []
    pattern = re.compile(r"\b(" + "|".join(map(re.escape, moves)) + r")\b")
    listed = subprocess.run(
        ["git", "ls-files", "-z"], cwd=REPO_ROOT, capture_output=True, text=True, check=True
    ).stdout.split("\0")
    changed = []
    for name in filter(None, listed):
        path = REPO_ROOT / name
        if not path.is_file() or any(path.is_relative_to(d) for d in runs_dirs):
            continue
        try:
            text = path.read_text()
        except UnicodeDecodeError:  # binary: a figure, a model zip
            continue
        updated = pattern.sub(lambda m: moves[m.group(1)], text)
        if updated != text:
            path.write_text(updated)
            changed.append(path)
    return changed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", nargs="+", default=list(PROFILES), help="whose results")
    parser.add_argument("--check", action="store_true", help="list the moves, change nothing")
    args = parser.parse_args()
    runs_dirs = [(results_dir(p) / "runs").resolve() for p in args.profile]
    moves = {}
    for profile, runs in zip(args.profile, runs_dirs, strict=True):
        found = new_keys(runs)
        print(f"{profile}: {len(found)} of {len(list(runs.glob('*.json')))} run files to rename")
        if not args.check:
            move(runs, found)
        moves |= found
    if not args.check:
        for path in rewrite_references(moves, runs_dirs):
            print(f"rewrote the keys {path.relative_to(REPO_ROOT)} names")
    if args.check and moves:
        raise SystemExit(1)


if __name__ == "__main__":
    main()

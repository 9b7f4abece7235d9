#!/usr/bin/env bash
# Issue 42's long TQC+HER runs (1M env steps, cpu config, sbx loop), one after the other,
# each started or resumed from its checkpoint and published when it finishes: re-run this
# script after any stop. A run is task:reward (seed 0, the task's expert) or task:reward:seed
# (a further seed of Table 1's TQC+HER cell, published beside it as tqc_TASK_REWARD_seedS).
# Usage: nohup scripts/long_tqc_runs.sh [task:reward[:seed] ...] \
#          >> artifacts/long_tqc_runs.log 2>&1 &
#        scripts/long_tqc_runs.sh --snapshot   (before a session ends: commit what it writes)
# With no arguments it walks every run; two instances given disjoint lists use both cores
# (two instances must never share a run: they would write the same checkpoint).
# On a machine without a run's checkpoint, the run carries on from its committed snapshot
# (results/experts/in_progress/, `gcdt tqc snapshot`), which has no replay buffer to refill.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT="${GCDT_ARTIFACTS:-artifacts}/long_tqc"
STEPS="${GCDT_LONG_TQC_STEPS:-1000000}"   # a smaller value: a rehearsal of the whole script
# Another config of gcdt/baselines/tqc_her.yaml trains a candidate beside the published agents:
# its runs live in their own folders (NAME_CONFIG) and are never published over an agent by
# this script (compare the curves, then `gcdt tqc publish OUT --replace` by hand).
CONFIG="${GCDT_LONG_TQC_CONFIG:-cpu}"
if [ "${1:-}" = "--snapshot" ]; then
  for out in "$ROOT"/*/; do
    [ -f "$out/checkpoint.tqc" ] || continue
    config=$(.venv/bin/python -c 'import sys
from pathlib import Path
from gcdt.baselines.tqc_checkpoint import read_header
config = read_header(Path(sys.argv[1]))["config"]
print(config["name"] if isinstance(config, dict) else config)' "$out/checkpoint.tqc")
    where=()   # a candidate config's snapshot is named after its run folder, as below
    [ "$config" = cpu ] || where=(--out "results/experts/in_progress/tqc_$(basename "$out")")
    .venv/bin/gcdt tqc snapshot "$out" "${where[@]}"
  done
  exit 0
fi
runs=("$@")
# The large profile's experts first (its data waits for them), then the rest of Table 1's
# TQC+HER cells.
[ ${#runs[@]} -gt 0 ] ||
  runs=(push:sparse pick_and_place:sparse reach:sparse pick_and_place:dense push:dense reach:dense)
for run in "${runs[@]}"; do
  IFS=: read -r task reward seed <<< "$run"
  seed="${seed:-0}" name="${task}_${reward}"
  [ "$seed" = 0 ] || name="${name}_seed${seed}"
  out="$ROOT/$name" agent="results/experts/tqc_$name/run.json"         # finished and published
  [ "$CONFIG" = cpu ] || out="$ROOT/${name}_$CONFIG"
  # Done: an agent of STEPS published there (by a candidate config: that config's own).
  [ -f "$agent" ] && .venv/bin/python -c 'import json, sys
run, steps, config = json.load(open(sys.argv[1])), int(sys.argv[2]), sys.argv[3]
name = run.get("config", {}).get("name")
sys.exit(run["env_steps"] < steps or (config != "cpu" and name != config))' \
    "$agent" "$STEPS" "$CONFIG" && continue
  if [ ! -f "$out/run.json" ]; then                                   # not finished here
    snapshot="results/experts/in_progress/tqc_${task}_${reward}_seed${seed}"
    [ "$CONFIG" = cpu ] || snapshot="results/experts/in_progress/tqc_$(basename "$out")"
    if [ ! -f "$out/checkpoint.tqc" ] && [ -f "$snapshot/checkpoint.tqc" ]; then
      mkdir -p "$out" && cp "$snapshot"/* "$out"/
    fi
    resume=()
    [ -f "$out/checkpoint.tqc" ] && resume=(--resume)
    .venv/bin/gcdt tqc train --task "$task" --reward "$reward" --config "$CONFIG" --steps "$STEPS" \
      --seed "$seed" --eval-every 25000 --eval-episodes 100 --out "$out" --no-progress "${resume[@]}"
  fi
  if [ "$CONFIG" != cpu ]; then
    echo "long_tqc_runs: $out finished; compare it with $agent, then publish it by hand" >&2
    continue
  fi
  # Publish it at once (replacing an agent of fewer steps, and the run's snapshot): the large
  # profile's runs that wait for it can start; commit results/experts/ afterwards.
  replace=()
  [ -f "$agent" ] && replace=(--replace)
  .venv/bin/gcdt tqc publish "$out" "${replace[@]}" ||
    echo "long_tqc_runs: publishing $out failed; run gcdt tqc publish $out by hand" >&2
done

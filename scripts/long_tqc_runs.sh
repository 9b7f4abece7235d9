#!/usr/bin/env bash
# Issue 42's long TQC+HER runs (1M env steps, cpu config, sbx loop, seed 0), one after the
# other, each started or resumed from its checkpoint: re-run this script after any stop.
# Usage: nohup scripts/long_tqc_runs.sh [task:reward ...] >> artifacts/long_tqc_runs.log 2>&1 &
# With no arguments it walks every run; two instances given disjoint lists use both cores
# (two instances must never share a run: they would write the same checkpoint).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT="${GCDT_ARTIFACTS:-artifacts}/long_tqc"
runs=("$@")
# The sparse experts first (the large profile's data waits for them), then Table 1's dense cells.
[ ${#runs[@]} -gt 0 ] ||
  runs=(pick_and_place:sparse push:sparse reach:sparse push:dense pick_and_place:dense reach:dense)
for run in "${runs[@]}"; do
  task="${run%%:*}" reward="${run##*:}" out="$ROOT/${task}_${reward}"
  [ -f "$out/run.json" ] && continue  # finished
  resume=()
  [ -f "$out/checkpoint.tqc" ] && resume=(--resume)
  .venv/bin/gcdt tqc train --task "$task" --reward "$reward" --config cpu --steps 1000000 \
    --seed 0 --eval-every 25000 --eval-episodes 100 --out "$out" --no-progress "${resume[@]}"
done

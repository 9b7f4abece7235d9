"""Thin the loss curves of result files written before run files kept at most
`LOSS_CURVE_POINTS` of them, without running anything again.

    python scripts/thin_loss_curves.py [--profile P ...] [--check]

A run logs a training row every `log_every` steps and its result file used to keep them all,
so an 800,000-step BC run's file held 16,000 points (1.8 MB). The runner now stores
`thin_curve(history)`; this script applies the same function to a stored curve, which keeps
the rows a new run would keep, and leaves every other field as it was. Running it again
changes nothing. `--check` lists the files it would rewrite and exits 1 if there are any.
"""

from __future__ import annotations

import argparse
import sys

from gcdt.experiments.runner import LOSS_CURVE_POINTS, thin_curve
from gcdt.experiments.store import RunStore
from gcdt.paths import results_dir

PROFILES = ("quick", "standard", "large")  # the profiles whose results are published


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", action="append", choices=PROFILES)
    parser.add_argument("--check", action="store_true", help="only list the files to thin")
    args = parser.parse_args()
    stale = []
    for profile in args.profile or PROFILES:
        store = RunStore(results_dir(profile) / "runs")
        for path in sorted(store.root.glob("*.json")):
            result = store.read(path.stem).result  # None for a corrupt or foreign file: left alone
            curve = (result or {}).get("training", {}).get("loss_curve") or []
            if len(curve) <= LOSS_CURVE_POINTS:
                continue
            stale.append(path)
            if not args.check:
                result["training"]["loss_curve"] = thin_curve(curve)
                store.write(path.stem, result)
            print(f"{'would thin' if args.check else 'thinned'} {path}: {len(curve)} points")
    return 1 if args.check and stale else 0


if __name__ == "__main__":
    sys.exit(main())

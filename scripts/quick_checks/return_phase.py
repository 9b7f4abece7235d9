"""What a return-to-go near 0 means in the PickAndPlace training data: the carrying phase.

    python scripts/quick_checks/return_phase.py DATASET.npz --out F.json

For each sparse return-to-go threshold, the share of the dataset's steps at or above it where
the fingertips are within 2 cm of the cube, beside that share over all steps; and how many
episodes start with a return-to-go of 0 (the cube already at its goal). Used by
results/quick_checks/README.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from gcdt.data import load_dataset
from gcdt.paths import write_json_atomic


def return_phase(path: str) -> dict:
    data = load_dataset(path)
    if data.task != "pick_and_place":
        sys.exit(f"error: {path} holds {data.task} data; give a pick_and_place dataset")
    obs = data.arrays["observation"]
    near = np.linalg.norm(obs[:, 7:10] - obs[:, :3], axis=1) < 0.02
    rtg = data.returns_to_go("sparse")
    returns = data.episode_returns("sparse")
    return {
        "command": "python " + " ".join(sys.argv),
        "dataset": path,
        "episodes": data.n_episodes,
        "steps": len(data),
        "mean_return_sparse": float(returns.mean()),
        "mean_return_dense": float(data.episode_returns("dense").mean()),
        "episodes_with_return_0": int((returns == 0).sum()),
        "near_cube_share_all_steps": float(near.mean()),
        "near_cube_share_by_return_to_go": {
            f">= {lo}": {
                "steps": int((rtg >= lo).sum()),
                "near_cube": float(near[rtg >= lo].mean()),
            }
            for lo in (0, -1, -2, -3, -5)
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    result = return_phase(args.dataset)
    write_json_atomic(args.out, result)
    print(json.dumps(result))


if __name__ == "__main__":
    main()

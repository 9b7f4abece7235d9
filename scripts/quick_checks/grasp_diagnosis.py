"""Why GC-DT misses on PickAndPlace with sparse rewards: where does it close the gripper?

    python scripts/quick_checks/grasp_diagnosis.py CKPT --target-return R --episodes N --out F.json

Runs whole episodes (reset seeds `episode_seed(5000, j)`) and counts, per episode, the steps
on which the policy commands the gripper shut (action[3] < 0) while the fingertips are more
than 3 cm from the cube, and whether the cube was ever held (within 2 cm, fingers closed on
it) before the episode ended. Used by results/quick_checks/README.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from gcdt.paths import write_json_atomic
from gcdt.policies.scripted import GRASP_WIDTH, MISSED_WIDTH
from gcdt.policies.trained import TrainedPolicy
from gcdt.rollout import VectorRollout

SEED = 5000


def diagnose(checkpoint: str, target_return: float, episodes: int) -> dict:
    policy = TrainedPolicy(checkpoint, "pick_and_place", target_return=target_return)
    counts = {"success": 0, "failed_never_held": 0, "failed_after_holding": 0}
    closed_far = 0
    held = False
    # The project's one stepping loop, on one env: episode j starts from episode_seed(SEED, j).
    with VectorRollout(policy, "pick_and_place", "sparse", n_envs=1, seed=SEED) as rollout:
        while sum(counts.values()) < episodes:
            step = rollout.step()
            before, after, action = (
                step.obs["observation"][0],
                step.next_obs["observation"][0],
                step.action[0],
            )
            closed_far += int(action[3] < 0 and np.linalg.norm(before[7:10] - before[:3]) > 0.03)
            near = np.linalg.norm(after[7:10] - after[:3]) < 0.02
            held |= bool(near and MISSED_WIDTH < after[6] < GRASP_WIDTH)
            if step.done[0]:
                success = bool(step.terminated[0])
                key = (
                    "success"
                    if success
                    else ("failed_after_holding" if held else "failed_never_held")
                )
                counts[key] += 1
                held = False
    return {
        "command": "python " + " ".join(sys.argv),
        "checkpoint": checkpoint,
        "target_return": target_return,
        "episodes": episodes,
        **counts,
        "success_rate": counts["success"] / episodes,
        "gripper_closed_far_from_cube_steps": closed_far,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("checkpoint")
    parser.add_argument("--target-return", type=float, default=0.0)
    parser.add_argument("--episodes", type=int, default=150)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    result = diagnose(args.checkpoint, args.target_return, args.episodes)
    write_json_atomic(args.out, result)
    print(json.dumps(result))


if __name__ == "__main__":
    main()

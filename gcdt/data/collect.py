"""The collector: run a policy on parallel envs and keep whole episodes as a `Dataset`."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from gcdt.data.dataset import EPISODE_ARRAYS, TRANSITION_ARRAYS, Dataset, offsets_from_lengths
from gcdt.envs import OBS_KEYS, compute_rewards, env_id, get_task
from gcdt.errors import GcdtError
from gcdt.policies.base import Policy
from gcdt.progress import progress_bar
from gcdt.provenance import package_versions, utc_now
from gcdt.regions import GoalRegion
from gcdt.rollout import VectorRollout

#: What a collection records as each state's action (see `collect`).
LABELS = ("executed", "clean")


def collect(
    policy: Policy,
    task: str,
    transitions: int,
    *,
    seed: int = 0,
    n_envs: int = 1,
    reward: str = "sparse",
    labels: str = "executed",
    goal_region: GoalRegion | None = None,
    progress: bool = True,
) -> Dataset:
    """Collect the first episodes of a seeded run whose lengths add up to >= `transitions`.

    The dataset holds episodes `0..k-1` of the run (each reset with `episode_seed(seed, j,
    stream)`, stream "random-collection" for the random policy and "collection" otherwise),
    with `k` the smallest count reaching `transitions`, so it exceeds the request by less than
    one episode and is bit-for-bit the same for the same `seed` and `n_envs`. Episodes that
    other envs had started when the last needed one finished are discarded.

    `reward` is only what the policy sees as its previous reward (for return-conditioned
    policies); the dataset stores both reward types, computed from the goals. `labels` is the
    action recorded for each state: "executed", what the env ran, or "clean", what the
    policy meant before its own exploration noise (DART: the data then teaches the expert's
    action in the states its noisy execution visits). With `goal_region`, the envs draw
    their desired goals from that region only (`gcdt.regions`).
    """
    if labels not in LABELS:
        raise GcdtError(f"unknown action labels {labels!r}: expected one of {', '.join(LABELS)}")
    spec = get_task(task)
    if not isinstance(transitions, int | np.integer) or transitions < 1:
        raise GcdtError(f"transitions must be a positive integer, got {transitions!r}")
    # Random data and expert data come from seed streams of their own, and evaluation from
    # another one: no collected episode replays another collection's or an evaluation's.
    stream = "random-collection" if policy.name == "random" else "collection"
    env_kwargs = None if goal_region is None else {"goal_region": goal_region}
    rollout = VectorRollout(
        policy, task, reward, n_envs, seed, stream=stream, env_kwargs=env_kwargs
    )

    running: list[dict[str, list[np.ndarray]]] = [_empty_episode() for _ in range(n_envs)]
    finished: dict[int, dict[str, np.ndarray]] = {}
    kept, kept_steps = 0, 0  # the complete prefix of episodes 0..kept-1 and its length
    started = time.perf_counter()
    bar = progress_bar(
        total=transitions,
        unit="step",
        desc=f"collect {policy.name} on {task}",
        progress=progress,
        leave=False,
    )
    with rollout:
        while kept_steps < transitions:
            step = rollout.step()
            recorded = step.action if labels == "executed" else step.intended
            for i in range(n_envs):
                buf = running[i]
                for key in OBS_KEYS:
                    buf[key].append(step.obs[key][i])
                buf["action"].append(recorded[i])
                buf["terminated"].append(step.terminated[i])
                buf["truncated"].append(step.truncated[i])
                buf["success"].append(step.success[i])
                if step.done[i]:
                    j = int(step.episode[i])
                    final = {key: step.next_obs[key][i] for key in OBS_KEYS}
                    finished[j] = _finish_episode(buf, final, rollout.seed_of(j), spec.name)
                    running[i] = _empty_episode()
            while kept in finished and kept_steps < transitions:
                kept_steps += len(finished[kept]["action"])
                kept += 1
            bar.update(min(kept_steps, transitions) - bar.n)
        stepping_seconds = time.perf_counter() - rollout.stepping_started
    bar.close()

    episodes = [finished[j] for j in range(kept)]
    metadata = {
        "source": "collect",
        "task": spec.name,
        "env_ids": {"sparse": env_id(task, "sparse"), "dense": env_id(task, "dense")},
        "policy": policy.config(),
        "seed": int(seed),
        "n_envs": int(n_envs),
        "labels": labels,
        **({"goal_region": str(goal_region)} if goal_region is not None else {}),
        "transitions_requested": int(transitions),
        "seconds": round(time.perf_counter() - started, 3),
        "stepping_seconds": round(stepping_seconds, 3),
        "created": utc_now(),
        "versions": package_versions(),
    }
    return from_episodes(spec.name, episodes, metadata)


def _empty_episode() -> dict[str, list[np.ndarray]]:
    return {k: [] for k in (*OBS_KEYS, "action", "terminated", "truncated", "success")}


def _finish_episode(
    buf: dict[str, list[np.ndarray]], final: dict[str, np.ndarray], seed: int, task: str
) -> dict[str, np.ndarray]:
    """Stack one episode's steps and add both rewards, computed from the goals."""
    ep = {k: np.stack(v) for k, v in buf.items()}
    next_achieved = np.concatenate([ep["achieved_goal"][1:], final["achieved_goal"][None]])
    next_desired = np.concatenate([ep["desired_goal"][1:], final["desired_goal"][None]])
    rewards = compute_rewards(next_achieved, next_desired, task)
    ep |= {"reward_sparse": rewards["sparse"], "reward_dense": rewards["dense"]}
    ep |= {f"final_{k}": v for k, v in final.items()}
    ep["episode_seed"] = np.int64(seed)
    return ep


def from_episodes(task: str, episodes: list[dict[str, Any]], metadata: dict[str, Any]) -> Dataset:
    """Concatenate per-episode arrays (transition arrays `[T, ...]`, episode arrays scalar or
    `[dim]`) into one `Dataset`; the dtypes are the schema's, checked by the Dataset."""
    if not episodes:
        raise GcdtError("no episodes to build a dataset from")
    lengths = [len(ep["action"]) for ep in episodes]
    arrays = {
        k: np.concatenate([np.asarray(ep[k]) for ep in episodes]).astype(dtype, copy=False)
        for k, dtype in TRANSITION_ARRAYS.items()
    }
    arrays |= {
        k: np.stack([np.asarray(ep[k]) for ep in episodes]).astype(dtype, copy=False)
        for k, dtype in EPISODE_ARRAYS.items()
    }
    arrays["offsets"] = offsets_from_lengths(lengths)
    return Dataset(task, arrays, metadata)

"""The collector: run a policy on parallel envs and keep whole episodes as a `Dataset`."""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from gcdt.data.dataset import (
    EPISODE_ARRAYS,
    TRANSITION_ARRAYS,
    Dataset,
    load_dataset,
    offsets_from_lengths,
)
from gcdt.data.mixing import concatenate
from gcdt.envs import OBS_KEYS, compute_rewards, env_id, get_task
from gcdt.errors import GcdtError
from gcdt.policies.base import Policy
from gcdt.progress import progress_bar
from gcdt.provenance import package_versions, utc_now
from gcdt.regions import GoalRegion
from gcdt.rollout import VectorRollout

#: What a collection records as each state's action (see `collect`).
LABELS = ("executed", "clean")


#: Transitions per chunk of a collection. A collection runs as chunks, each on fresh envs
#: started at the episode after the previous chunk's last (PyBullet carries state from an
#: env's earlier episodes into the next: only restarts at fixed points let a resumed
#: collection equal an uninterrupted one), each keeping its first episodes that reach this
#: many transitions, the last chunk the remainder. Counted in transitions, not episodes,
#: because episodes last from one step to fifty: a collection of up to this many transitions
#: (every one of the smoke, quick and standard profiles) is one chunk, one run of fresh envs
#: from episode 0 as before chunks existed, bit for bit, while a million-transition
#: collection of the large profile is twenty chunks, each a few minutes of stepping, so a
#: kill loses at most that much.
CHUNK_TRANSITIONS = 50_000


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
    chunks_dir: str | Path | None = None,
) -> Dataset:
    """Collect the first episodes of a seeded run whose lengths add up to >= `transitions`.

    The dataset holds episodes `0..k-1` of the run (each reset with `episode_seed(seed, j,
    stream)`, stream "random-collection" for the random policy and "collection" otherwise),
    with `k` the smallest count reaching `transitions`, so it exceeds the request by less than
    one episode and is bit-for-bit the same for the same `seed` and `n_envs`. The run goes in
    chunks of `CHUNK_TRANSITIONS` (see there); in each, the episodes that other envs had
    started when the chunk's last needed one finished are discarded.

    With `chunks_dir`, each chunk is saved there as `00000.npz`, `00001.npz`, ... once
    collected, and chunks found there are loaded, not collected again: a collection killed
    midway resumes, and gives the same dataset as one never interrupted. A chunk that cannot
    be read, or that belongs to another collection, is refused. The caller removes the folder
    once it has saved the dataset (`remove_chunks`).

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

    # Each chunk's envs, started fresh at its first episode.
    rollout = partial(VectorRollout, policy, task, reward, n_envs, seed, stream=stream,
                      env_kwargs=env_kwargs)  # fmt: skip
    seed_of = rollout(first_episode=0).seed_of  # checks the arguments before any work
    # What every chunk of this collection shares (JSON, as the chunks store it).
    identity = json.loads(
        json.dumps(
            {
                "task": spec.name,
                "policy": policy.config(),
                **{"reward": reward, "seed": int(seed), "n_envs": int(n_envs), "labels": labels},
                "goal_region": None if goal_region is None else str(goal_region),
                "transitions_requested": int(transitions),
                "chunk_transitions": CHUNK_TRANSITIONS,
                "versions": package_versions(),
            }
        )
    )
    bar = progress_bar(
        total=transitions,
        unit="step",
        desc=f"collect {policy.name} on {task}",
        progress=progress,
        leave=False,
    )
    parts: list[Dataset] = []
    resumed = 0
    while (steps := sum(len(p) for p in parts)) < transitions:
        bar.update(steps - bar.n)
        where = {
            "chunk": len(parts),
            "first_episode": sum(p.n_episodes for p in parts),
            "transitions": min(CHUNK_TRANSITIONS, transitions - steps),
        }
        path = None if chunks_dir is None else Path(chunks_dir) / f"{len(parts):05d}.npz"
        if path is not None and path.exists():
            parts.append(_resumed_chunk(path, {**identity, **where}, seed_of))
            resumed += 1
            continue
        chunk = _collect_chunk(
            rollout(first_episode=where["first_episode"]), spec.name, where["transitions"],
            labels, bar,
        )  # fmt: skip
        parts.append(chunk.with_metadata(source="collect-chunk", **identity, **where))
        if path is not None:
            parts[-1].save(path)
    bar.update(transitions - bar.n)
    bar.close()
    return concatenate(parts, _metadata(identity, parts, resumed))


def _metadata(identity: dict[str, Any], parts: list[Dataset], resumed: int) -> dict[str, Any]:
    """The collection's metadata: one chunk's is the collection's as it was before chunks
    existed; more chunks add how many (and how many were resumed)."""
    task, region = identity["task"], identity["goal_region"]
    chunking = {"chunks": len(parts), "chunk_transitions": CHUNK_TRANSITIONS}
    return {
        "source": "collect",
        "task": task,
        "env_ids": {"sparse": env_id(task, "sparse"), "dense": env_id(task, "dense")},
        **{k: identity[k] for k in ("policy", "seed", "n_envs", "labels")},
        **({"goal_region": region} if region is not None else {}),
        "transitions_requested": identity["transitions_requested"],
        **(chunking if len(parts) > 1 else {}),
        **({"chunks_resumed": resumed} if resumed else {}),
        # The collecting time of every chunk, those of an interrupted earlier process included.
        "seconds": round(sum(p.metadata["seconds"] for p in parts), 3),
        "stepping_seconds": round(sum(p.metadata["stepping_seconds"] for p in parts), 3),
        "created": utc_now(),
        "versions": package_versions(),
    }


def _collect_chunk(
    rollout: VectorRollout, task: str, transitions: int, labels: str, bar: tqdm
) -> Dataset:
    """The first episodes of `rollout` (from its first one) whose lengths reach `transitions`."""
    n_envs, first = rollout.n_envs, rollout.first_episode
    running: list[dict[str, list[np.ndarray]]] = [_empty_episode() for _ in range(n_envs)]
    finished: dict[int, dict[str, np.ndarray]] = {}
    kept, kept_steps = first, 0  # the complete prefix of episodes first..kept-1 and its length
    done_before = bar.n
    started = time.perf_counter()
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
                    finished[j] = _finish_episode(buf, final, rollout.seed_of(j), task)
                    running[i] = _empty_episode()
            while kept in finished and kept_steps < transitions:
                kept_steps += len(finished[kept]["action"])
                kept += 1
            bar.update(done_before + min(kept_steps, transitions) - bar.n)
        stepping_seconds = time.perf_counter() - rollout.stepping_started
    timing = {
        "seconds": round(time.perf_counter() - started, 3),
        "stepping_seconds": round(stepping_seconds, 3),
    }
    return from_episodes(task, [finished[j] for j in range(first, kept)], timing)


def _resumed_chunk(path: Path, expected: dict[str, Any], seed_of: Callable[[int], int]) -> Dataset:
    """Chunk `path` of an earlier, interrupted run of this collection, checked to be one."""
    fix = f"delete {path} to collect that chunk again"
    try:
        part = load_dataset(path)
    except GcdtError as err:
        raise GcdtError(f"{err}: {fix}") from None
    meta = part.metadata
    if meta.get("source") != "collect-chunk":
        raise GcdtError(f"{path} is not a chunk of a collection: {fix}")
    for key, value in expected.items():
        if meta.get(key) != value:
            raise GcdtError(
                f"{path} is a chunk of another collection ({key} {meta.get(key)!r}, not "
                f"{value!r}): delete {path.parent} to start this collection afresh"
            )
    lengths, target = part.episode_lengths, expected["transitions"]
    first_seeds = part.arrays["episode_seed"][:1].tolist()
    if (
        lengths.sum() < target
        or lengths.sum() - lengths[-1] >= target
        or first_seeds != [seed_of(expected["first_episode"])]
    ):
        raise GcdtError(f"{path} does not hold the episodes its metadata names: {fix}")
    return part


def chunks_beside(path: str | Path) -> Path:
    """The folder that keeps the chunks of a collection saved to `path` until it is saved:
    `<name>.chunks` beside it."""
    path = Path(path)
    return path.with_name(f"{path.stem}.chunks")


def remove_chunks(folder: str | Path) -> None:
    """Remove a collection's chunk folder (`collect(chunks_dir=...)`), once its dataset is saved."""
    if Path(folder).exists():
        shutil.rmtree(folder)


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

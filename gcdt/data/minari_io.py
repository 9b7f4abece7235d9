"""Minari interop: a `Dataset` as a local Minari dataset, and back.

A Minari dataset holds one reward, so the export is for one reward type (sparse by default)
and carries that panda-gym env's spec, which makes `recover_environment()` work. The import
recomputes the other reward type from the goals and checks the stored one against the same
computation, so data whose rewards do not follow panda-gym's definition is refused rather
than silently relabelled. gcdt's own metadata and episode seeds travel in the Minari
metadata under the key "gcdt", which makes a round trip exact.

Minari keeps datasets under `$MINARI_DATASETS_PATH`; where it is unset, gcdt sets it to
`<artifacts>/minari` (`gcdt.paths.minari_dir`) for itself and its child processes.
"""

from __future__ import annotations

import os
import shutil
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gcdt.data.collect import from_episodes
from gcdt.data.dataset import SCHEMA_VERSION, Dataset, check_rewards
from gcdt.envs import OBS_KEYS, TASKS, check_reward, compute_rewards, env_id, is_success, make_env
from gcdt.errors import GcdtError
from gcdt.paths import MINARI_ENV, minari_dir
from gcdt.provenance import utc_now


def _minari():
    try:
        import minari
    except ImportError:  # pragma: no cover - minari is in environment/requirements.txt
        raise GcdtError("Minari is not installed: pip install 'minari[hdf5]'") from None
    # Minari reads the variable at every call: set, it makes gcdt and Minari agree.
    os.environ.setdefault(MINARI_ENV, str(minari_dir()))
    return minari


@dataclass(frozen=True)
class MinariCard:
    """The Minari metadata of a published dataset (see Minari's dataset standards); `gcdt`
    is merged into the metadata's "gcdt" entry. The reference scores need both or neither."""

    algorithm_name: str
    description: str
    code_permalink: str | None = None
    requirements: tuple[str, ...] = ()
    ref_min_score: float | None = None
    ref_max_score: float | None = None
    num_episodes_average_score: int | None = None
    gcdt: dict[str, Any] = field(default_factory=dict)


def default_minari_id(dataset: Dataset) -> str:
    """`panda-gym/<task>/<policy>-v0`, e.g. `panda-gym/push/scripted-v0`."""
    policy = (dataset.metadata.get("policy") or {}).get("name", "data")
    return f"panda-gym/{dataset.task}/{policy}-v0"


def local_ids() -> set[str]:
    """The ids of the Minari datasets in `gcdt.paths.minari_dir()`."""
    return set(_minari().list_local_datasets(compatible_minari_version=False))


def export_minari(
    dataset: Dataset,
    dataset_id: str | None = None,
    *,
    reward: str = "sparse",
    card: MinariCard | None = None,
):
    """Write `dataset` as the local Minari dataset `dataset_id`, with `card`'s metadata
    (else a plain description); returns the MinariDataset."""
    minari = _minari()
    from minari.data_collector import EpisodeBuffer
    from minari.dataset.minari_dataset import parse_dataset_id
    from minari.storage import get_dataset_path

    check_reward(reward)
    dataset_id = dataset_id or default_minari_id(dataset)
    try:
        parse_dataset_id(dataset_id)
    except Exception as err:
        raise GcdtError(f"invalid Minari dataset id {dataset_id!r}: {err}") from None
    if dataset_id in local_ids():
        raise GcdtError(
            f"Minari dataset {dataset_id!r} already exists: choose another id or delete it "
            f"(minari delete {dataset_id})"
        )

    a, rewards = dataset.arrays, dataset.rewards(reward)
    buffers = []
    for e in range(dataset.n_episodes):
        lo, hi = int(dataset.offsets[e]), int(dataset.offsets[e + 1])
        obs = {k: np.concatenate([a[k][lo:hi], a[f"final_{k}"][e][None]]) for k in OBS_KEYS}
        # Minari's infos have one entry per observation; the reset's is_success is unknown
        # to the dataset, so it is recorded from the initial goals.
        first = is_success(obs["achieved_goal"][0], obs["desired_goal"][0], dataset.task)
        infos = {"is_success": np.concatenate([[first], a["success"][lo:hi]])}
        buffers.append(
            EpisodeBuffer(
                id=e,
                observations=obs,
                actions=a["action"][lo:hi],
                rewards=rewards[lo:hi],
                terminations=a["terminated"][lo:hi],
                truncations=a["truncated"][lo:hi],
                infos=infos,
            )
        )

    card = card or MinariCard(
        algorithm_name=(dataset.metadata.get("policy") or {}).get("name", "unknown"),
        description=f"panda-gym {dataset.task} ({reward} reward) exported by gcdt",
    )
    scored = card.ref_max_score is not None
    if scored != (card.ref_min_score is not None):
        # Minari would fill a missing minimum with a random policy's score of its own.
        raise GcdtError("a Minari card needs both reference scores or neither")
    env = make_env(dataset.task, reward)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # Minari nags about missing author/permalink
            exported = minari.create_dataset_from_buffers(
                dataset_id,
                buffers,
                env=env,
                # The evaluation env is the dataset's own env spec (the reference scores').
                eval_env=env.spec if scored else None,
                algorithm_name=card.algorithm_name,
                author="gcdt",
                code_permalink=card.code_permalink,
                description=card.description,
                requirements=list(card.requirements) or None,
                ref_min_score=card.ref_min_score,
                ref_max_score=card.ref_max_score,
                # None where the scores average different episode counts (gcdt's entry has both).
                num_episodes_average_score=card.num_episodes_average_score,
            )
            exported.storage.update_metadata(
                {
                    "gcdt": {
                        "schema_version": SCHEMA_VERSION,
                        "task": dataset.task,
                        "reward": reward,
                        "metadata": dataset.metadata,
                        "episode_seed": a["episode_seed"].tolist(),
                        **card.gcdt,
                    }
                }
            )
    except BaseException:
        shutil.rmtree(get_dataset_path(dataset_id), ignore_errors=True)  # nothing half-written
        raise
    finally:
        env.close()
    return exported


def _task_of(env_spec) -> tuple[str, str]:
    """(task, reward) of a panda-gym v3 env spec."""
    for task in TASKS:
        for reward in ("sparse", "dense"):
            if env_spec is not None and env_spec.id == env_id(task, reward):
                return task, reward
    got = getattr(env_spec, "id", None)
    raise GcdtError(f"Minari dataset env {got!r} is not a panda-gym v3 task gcdt knows")


def import_minari(dataset_id: str) -> Dataset:
    """Read the local Minari dataset `dataset_id` into a validated `Dataset`."""
    minari = _minari()
    if dataset_id not in local_ids():
        raise GcdtError(
            f"no local Minari dataset {dataset_id!r} (see `minari list local`; "
            "gcdt never downloads)"
        )
    source = minari.load_dataset(dataset_id)
    task, reward = _task_of(source.spec.env_spec)
    extra: dict[str, Any] = source.storage.metadata.get("gcdt") or {}
    episodes = []
    for e, ep in enumerate(source.iterate_episodes()):
        obs = ep.observations
        if not isinstance(obs, dict) or set(obs) != set(OBS_KEYS):
            raise GcdtError(f"Minari dataset {dataset_id!r}: observations must be panda-gym dicts")
        rewards = compute_rewards(obs["achieved_goal"][1:], obs["desired_goal"][1:], task)
        check_rewards(np.asarray(ep.rewards), rewards[reward], reward, f"episode {e}")
        success = (ep.infos or {}).get("is_success")
        success = (
            np.asarray(success[1:], dtype=bool)
            if success is not None
            else is_success(obs["achieved_goal"][1:], obs["desired_goal"][1:], task)
        )
        seeds = extra.get("episode_seed")
        episodes.append(
            {
                **{k: obs[k][:-1] for k in OBS_KEYS},
                **{f"final_{k}": obs[k][-1] for k in OBS_KEYS},
                "action": ep.actions,
                "reward_sparse": rewards["sparse"],
                "reward_dense": rewards["dense"],
                "terminated": ep.terminations,
                "truncated": ep.truncations,
                "success": success,
                "episode_seed": seeds[e] if seeds is not None else -1,
            }
        )
    metadata = extra.get("metadata") or {
        "source": "minari",
        "task": task,
        "policy": {"name": source.spec.algorithm_name or "unknown"},
        "minari_id": dataset_id,
        "created": utc_now(),
    }
    return from_episodes(task, episodes, metadata)

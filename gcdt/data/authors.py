"""The authors' released format, a pickled list of episode dicts: import and export.

Each episode: `observations` and `next_observations` (dicts of `observation`,
`desired_goal`, `achieved_goal` arrays `[T, dim]`), `actions` `[T, action_dim]`, `rewards`
`[T]`, `terminals` `[T]`. The format has no truncation flag and no success flag: success is
panda-gym's condition on the goals, and since panda-gym v3 terminates an episode only on
success, an episode ends terminated when its last step is a success and truncated (timed
out) otherwise, whatever the file's terminal flags say; the number of episodes whose flag
disagreed is recorded in the metadata (`terminal_flags_disagreeing`). Everything else is
checked, not repaired: next observations must continue the observations, and the rewards
must be panda-gym's sparse or dense reward of the goals.

`export_authors` writes a `Dataset` in that format, so that the authors' code reads gcdt's
data; each episode also carries its reset seed as `episode_seed`, a key their code does not
read and the import does, which makes the round trip exact.
"""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

import numpy as np

from gcdt.data.collect import from_episodes
from gcdt.data.dataset import Dataset, check_rewards, rewards_match
from gcdt.envs import OBS_KEYS, REWARDS, TASKS, compute_rewards, get_task, is_success
from gcdt.errors import GcdtError
from gcdt.paths import atomic_write
from gcdt.provenance import utc_now

_EPISODE_KEYS = ("observations", "next_observations", "actions", "rewards", "terminals")


def import_authors(
    path: str | Path, *, trust_pickle: bool = False, task: str | None = None
) -> Dataset:
    """Read the authors' pickle at `path` into a `Dataset`.

    Unpickling runs whatever code the file names, so it happens only with
    `trust_pickle=True`. `task` is inferred from the array widths when not given (Push and
    Slide share them: say which).
    """
    path = Path(path)
    if not trust_pickle:
        raise GcdtError(
            f"refusing to unpickle {str(path)!r}: loading a pickle runs arbitrary code from the "
            "file; pass --trust-pickle (trust_pickle=True) only for a file from a source you trust"
        )
    if not path.is_file():
        raise GcdtError(f"pickle file {str(path)!r} does not exist")
    try:
        with path.open("rb") as f:
            raw = pickle.load(f)
    except Exception as err:
        raise GcdtError(f"{path} is not a readable pickle ({type(err).__name__}: {err})") from None
    if not isinstance(raw, list | tuple) or not raw:
        raise GcdtError(
            f"{path} must hold a non-empty list of episode dicts, got {type(raw).__name__}"
        )

    spec = get_task(task) if task is not None else _infer_task(raw[0], path)
    episodes, reward_type, disagreeing = [], None, 0
    for e, ep in enumerate(raw):
        where = f"{path}: episode {e}"
        converted, fits, disagrees = _episode(ep, spec.name, where)
        disagreeing += disagrees
        if reward_type is None:  # the first episode decides; all others must agree
            if not fits:
                raise GcdtError(
                    f"{where}: rewards are neither panda-gym's sparse nor its dense reward of "
                    "the goals, so the data does not come from this task's env"
                )
            reward_type = fits[0]
        check_rewards(ep["rewards"], converted[f"reward_{reward_type}"], reward_type, where)
        episodes.append(converted)

    metadata = {
        "source": "authors",
        "task": spec.name,
        "policy": {"name": "authors"},
        "reward_in_file": reward_type,
        "terminal_flags_disagreeing": disagreeing,
        "file": str(path),
        "created": utc_now(),
    }
    try:
        return from_episodes(spec.name, episodes, metadata)
    except GcdtError as err:
        raise GcdtError(f"{path}: {err}") from None


def export_authors(dataset: Dataset, path: str | Path, *, reward: str = "sparse") -> Path:
    """Write `dataset` to `path` in the authors' format, with its `reward` ("sparse" or
    "dense") as `rewards` and its terminated flags as `terminals`; atomic."""
    path = Path(path)
    rewards, nxt = dataset.rewards(reward), dataset.next_observations()
    a, episodes = dataset.arrays, []
    for e in range(dataset.n_episodes):
        lo, hi = int(dataset.offsets[e]), int(dataset.offsets[e + 1])
        episodes.append(
            {
                "observations": {k: a[k][lo:hi] for k in OBS_KEYS},
                "next_observations": {k: nxt[k][lo:hi] for k in OBS_KEYS},
                "actions": a["action"][lo:hi],
                "rewards": rewards[lo:hi],
                "terminals": a["terminated"][lo:hi],
                "episode_seed": int(a["episode_seed"][e]),
            }
        )
    with atomic_write(path, binary=True) as f:
        pickle.dump(episodes, f, protocol=4)
    return path


def _infer_task(ep: Any, path: Path):
    try:
        widths = (len(ep["observations"]["observation"][0]), len(ep["actions"][0]))
    except Exception:
        raise GcdtError(
            f"{path}: episodes must be dicts with keys {', '.join(_EPISODE_KEYS)}"
        ) from None
    matches = [t for t in TASKS.values() if (t.obs_dim, t.action_dim) == widths]
    if not matches:
        known = ", ".join(f"{t.name} {t.obs_dim}/{t.action_dim}" for t in TASKS.values())
        raise GcdtError(
            f"{path}: observation width {widths[0]} and action width {widths[1]} match no "
            f"panda-gym task (observation/action widths: {known}); the file is not panda-gym data"
        )
    if len(matches) != 1:
        names = ", ".join(t.name for t in matches) or "none"
        raise GcdtError(
            f"{path}: cannot tell the task from observation width {widths[0]} and action width "
            f"{widths[1]} (matches: {names}); pass --task"
        )
    return matches[0]


def _episode(ep: Any, task: str, where: str) -> tuple[dict[str, Any], list[str], bool]:
    """One episode in gcdt's layout, the reward types its rewards are consistent with, and
    whether the file's terminal flags disagree with panda-gym's (terminated on success only)."""
    if not isinstance(ep, dict) or not set(_EPISODE_KEYS) <= set(ep):
        raise GcdtError(f"{where}: expected a dict with keys {', '.join(_EPISODE_KEYS)}")
    try:
        obs = {k: np.asarray(ep["observations"][k], dtype=np.float32) for k in OBS_KEYS}
        nxt = {k: np.asarray(ep["next_observations"][k], dtype=np.float32) for k in OBS_KEYS}
        terminals = np.asarray(ep["terminals"]).astype(bool).reshape(-1)
        rewards = np.asarray(ep["rewards"], dtype=np.float64).reshape(-1)
        seed = int(ep.get("episode_seed", -1))  # gcdt's exports only
    except (KeyError, TypeError, ValueError) as err:
        raise GcdtError(f"{where}: malformed arrays ({err})") from None
    length = len(terminals)
    if length == 0 or any(len(v) != length for v in (*obs.values(), *nxt.values(), rewards)):
        raise GcdtError(
            f"{where}: observations, next_observations, rewards and terminals differ in length"
        )
    for k in OBS_KEYS:
        if not np.array_equal(nxt[k][:-1], obs[k][1:]):
            t = int(np.flatnonzero(~(nxt[k][:-1] == obs[k][1:]).all(axis=-1))[0])
            raise GcdtError(
                f"{where}: next_observations[{k}][{t}] is not observations[{k}][{t + 1}]"
            )
    recomputed = compute_rewards(nxt["achieved_goal"], nxt["desired_goal"], task)
    fits = [r for r in REWARDS if rewards_match(rewards, recomputed[r], r)]
    success = is_success(nxt["achieved_goal"], nxt["desired_goal"], task)
    terminated, truncated = np.zeros(length, dtype=bool), np.zeros(length, dtype=bool)
    terminated[-1], truncated[-1] = success[-1], not success[-1]  # panda-gym v3's rule
    converted = {
        **obs,
        **{f"final_{k}": nxt[k][-1] for k in OBS_KEYS},
        "action": np.asarray(ep["actions"], dtype=np.float32),
        "reward_sparse": recomputed["sparse"],
        "reward_dense": recomputed["dense"],
        "terminated": terminated,
        "truncated": truncated,
        "success": success,
        "episode_seed": seed,
    }
    disagrees = bool((terminals != terminated).any())
    return converted, fits, disagrees

"""`Dataset`: offline trajectories as flat contiguous arrays plus episode offsets.

Layout (N transitions in E episodes; episode `e` is rows `offsets[e]:offsets[e + 1]`):

* per transition: `observation`, `desired_goal`, `achieved_goal` (the observation the action
  was taken in), `action`, `reward_sparse`, `reward_dense`, `terminated`, `truncated`,
  `success` (info["is_success"] after the step);
* per episode: `final_observation`, `final_desired_goal`, `final_achieved_goal` (the last
  next-observation, which no transition starts from) and `episode_seed` (its reset seed,
  -1 where unknown);
* `offsets` `[E + 1]` and a JSON-able `metadata` dict (task, source, policy, seeds, versions).

Both reward types are stored, computed from the goals (`gcdt.envs.compute_rewards`), so one
collection serves the sparse and the dense variant of a task. Every Dataset is validated on
construction (dimensions against its task, episode boundaries, finite values), so a Dataset
that exists is a correct one; loading never repairs anything.

On disk a dataset is one uncompressed `.npz` (numpy only, no pickle), written atomically.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gcdt.envs import OBS_KEYS, REWARDS, TASKS, TaskSpec, check_reward, get_task, goal_state
from gcdt.errors import GcdtError
from gcdt.paths import atomic_write

#: Bumped whenever the arrays or their meaning change; files of another version are refused.
SCHEMA_VERSION = 1
FORMAT = "gcdt.dataset"
_META_KEY = "__metadata__"
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")  # a zip's first entry, or an empty zip


def _width(name: str, spec: TaskSpec) -> int | None:
    """Columns of array `name` for `spec` (None for 1-D arrays)."""
    if name.endswith("observation"):
        return spec.obs_dim
    if name.endswith("goal"):
        return spec.goal_dim
    if name == "action":
        return spec.action_dim
    return None


# name -> dtype, for the arrays with one row per transition and one row per episode.
TRANSITION_ARRAYS: dict[str, type] = {
    "observation": np.float32,
    "desired_goal": np.float32,
    "achieved_goal": np.float32,
    "action": np.float32,
    "reward_sparse": np.float32,
    "reward_dense": np.float32,
    "terminated": np.bool_,
    "truncated": np.bool_,
    "success": np.bool_,
}
EPISODE_ARRAYS: dict[str, type] = {
    "final_observation": np.float32,
    "final_desired_goal": np.float32,
    "final_achieved_goal": np.float32,
    "episode_seed": np.int64,
}
ARRAYS = {**TRANSITION_ARRAYS, **EPISODE_ARRAYS, "offsets": np.int64}


@dataclass(frozen=True, eq=False)
class Dataset:
    """Episodes of one task (see the module docstring for the layout)."""

    task: str
    arrays: dict[str, np.ndarray]
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _validate(self.task, self.arrays)
        json.dumps(self.metadata)  # fail now, not when saving, if it is not JSON-able

    # --- sizes ---------------------------------------------------------------------------

    @property
    def spec(self) -> TaskSpec:
        return TASKS[self.task]

    def __len__(self) -> int:
        """Number of transitions."""
        return int(self.arrays["offsets"][-1])

    @property
    def n_episodes(self) -> int:
        return len(self.arrays["offsets"]) - 1

    @property
    def offsets(self) -> np.ndarray:
        return self.arrays["offsets"]

    @property
    def episode_lengths(self) -> np.ndarray:
        return np.diff(self.offsets)

    @functools.cached_property
    def episode_index(self) -> np.ndarray:
        """int64 `[N]`: the episode of each transition."""
        return np.repeat(np.arange(self.n_episodes), self.episode_lengths)

    @functools.cached_property
    def timesteps(self) -> np.ndarray:
        """int64 `[N]`: the step of each transition within its episode (0-based)."""
        return np.arange(len(self)) - self.offsets[self.episode_index]

    # --- what the trainer reads ----------------------------------------------------------

    @functools.cached_property
    def states(self) -> np.ndarray:
        """float32 `[N, state_dim]`: the paper's `[observation, desired_goal, achieved_goal]`."""
        return goal_state(self.arrays)

    @property
    def actions(self) -> np.ndarray:
        return self.arrays["action"]

    def rewards(self, reward: str) -> np.ndarray:
        """float32 `[N]` rewards of type `reward` ("sparse" or "dense")."""
        return self.arrays[f"reward_{check_reward(reward)}"]

    def returns_to_go(self, reward: str) -> np.ndarray:
        """float32 `[N]`: the sum of this and all later rewards of the episode (undiscounted)."""
        r = self.rewards(reward).astype(np.float64)
        tail = np.append(np.cumsum(r[::-1])[::-1], 0.0)  # tail[i] = sum(r[i:])
        return (tail[:-1] - tail[self.offsets[1:]][self.episode_index]).astype(np.float32)

    def episode_returns(self, reward: str) -> np.ndarray:
        """float64 `[E]`: undiscounted return of each episode."""
        return np.add.reduceat(self.rewards(reward).astype(np.float64), self.offsets[:-1])

    @property
    def episode_success(self) -> np.ndarray:
        """bool `[E]`: success at any step of the episode (the evaluator's definition)."""
        return np.logical_or.reduceat(self.arrays["success"], self.offsets[:-1])

    def next_observations(self) -> dict[str, np.ndarray]:
        """The observation after each transition, `[N, dim]` per key (finals included)."""
        last = self.offsets[1:] - 1
        out = {}
        for key in OBS_KEYS:
            nxt = np.empty_like(self.arrays[key])
            nxt[:-1] = self.arrays[key][1:]
            nxt[last] = self.arrays[f"final_{key}"]
            out[key] = nxt
        return out

    def episode(self, e: int) -> dict[str, np.ndarray]:
        """Views of episode `e`'s transition arrays (for inspection and plots)."""
        if not 0 <= e < self.n_episodes:
            raise GcdtError(f"episode {e} out of range: the dataset has {self.n_episodes}")
        lo, hi = self.offsets[e], self.offsets[e + 1]
        return {k: self.arrays[k][lo:hi] for k in TRANSITION_ARRAYS}

    def summary(self) -> dict[str, Any]:
        """Episodes, transitions, mean length, success rate and mean return of both rewards."""
        out: dict[str, Any] = {
            "task": self.task,
            "source": self.metadata.get("source"),
            "policy": (self.metadata.get("policy") or {}).get("name"),
            "episodes": self.n_episodes,
            "transitions": len(self),
            "mean_length": float(self.episode_lengths.mean()),
            "success_rate": float(self.episode_success.mean()),
        }
        for reward in REWARDS:
            out[f"mean_return_{reward}"] = float(self.episode_returns(reward).mean())
        return out

    # --- building new datasets -----------------------------------------------------------

    def select(self, episodes: Sequence[int] | np.ndarray, metadata: dict[str, Any]) -> Dataset:
        """A new dataset of the given episodes, in the given order."""
        episodes = np.asarray(episodes, dtype=np.int64)
        lengths = self.episode_lengths[episodes]
        offsets = offsets_from_lengths(lengths)
        # Row indices of the chosen episodes' transitions, in order, without a Python loop.
        rows = np.repeat(self.offsets[episodes] - offsets[:-1], lengths) + np.arange(offsets[-1])
        arrays = {k: self.arrays[k][rows] for k in TRANSITION_ARRAYS}
        arrays |= {k: self.arrays[k][episodes] for k in EPISODE_ARRAYS}
        return Dataset(self.task, {**arrays, "offsets": offsets}, metadata)

    def equal_data(self, other: Dataset) -> bool:
        """Same task and bit-identical arrays (metadata is not compared)."""
        return self.task == other.task and all(
            np.array_equal(self.arrays[k], other.arrays[k]) for k in ARRAYS
        )

    def with_metadata(self, **updates: Any) -> Dataset:
        return dataclasses.replace(self, metadata={**self.metadata, **updates})

    # --- disk ----------------------------------------------------------------------------

    def save(self, path: str | Path) -> Path:
        """Write to `path` (`.npz`) through a temp file and a rename: never a partial file."""
        path = Path(path)
        if path.suffix != ".npz":
            raise GcdtError(f"dataset path {str(path)!r} must end in .npz")
        header = {"format": FORMAT, "schema_version": SCHEMA_VERSION, "task": self.task}
        meta = np.array(json.dumps({**header, "metadata": self.metadata}))
        with atomic_write(path, binary=True) as f:
            np.savez(f, **self.arrays, **{_META_KEY: meta})
        return path

    @classmethod
    def load(cls, path: str | Path) -> Dataset:
        """Read a dataset written by `save`; any problem is a one-line `GcdtError`."""
        path = Path(path)
        if not path.is_file():
            raise GcdtError(f"dataset file {str(path)!r} does not exist")
        not_ours = f"{path} is not a gcdt dataset (.npz archive written by gcdt collect)"
        try:
            with open(path, "rb") as f:
                magic = f.read(4)
        except OSError as err:
            raise GcdtError(f"{not_ours}: cannot read it ({err.strerror})") from None
        # Anything but a zip would reach numpy's .npy and pickle readers, whose refusal
        # advises unpickling the file.
        if not magic:
            raise GcdtError(f"{not_ours}: the file is empty")
        if magic not in _ZIP_MAGIC:
            raise GcdtError(f"{not_ours}: truncated or corrupt file (not a zip archive)")
        try:
            with np.load(path, allow_pickle=False) as npz:
                if _META_KEY not in npz.files:
                    raise GcdtError(
                        f"{path} is not a gcdt dataset (no {_META_KEY} entry); "
                        "make one with `gcdt collect` or a `gcdt dataset import-*` command"
                    )
                header = json.loads(str(npz[_META_KEY]))
                if header.get("format") != FORMAT:
                    raise GcdtError(
                        f"{path} is not a gcdt dataset (format {header.get('format')!r})"
                    )
                version = header.get("schema_version")
                if version != SCHEMA_VERSION:
                    raise GcdtError(
                        f"{path} has dataset schema version {version}, this gcdt reads version "
                        f"{SCHEMA_VERSION}: re-create it with the current `gcdt collect`"
                    )
                missing = sorted(set(ARRAYS) - set(npz.files))
                if missing:
                    raise GcdtError(f"{path} lacks arrays {', '.join(missing)} (wrong schema)")
                arrays = {k: npz[k] for k in ARRAYS}
        except GcdtError:
            raise
        except (zipfile.BadZipFile, ValueError, OSError, EOFError, KeyError) as err:
            raise GcdtError(f"{not_ours}: {_load_failure(err)}") from None
        try:
            return cls(header.get("task"), arrays, header.get("metadata") or {})
        except GcdtError as err:
            raise GcdtError(f"{path}: {err}") from None


def _load_failure(err: Exception) -> str:
    """A short reason for a failed read; never numpy's advice to load pickled data."""
    text = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
    if "pickle" in text.lower():  # an object array inside the archive
        return "an entry holds Python objects, which gcdt datasets never contain"
    return f"truncated or corrupt file ({text[:160]})"


def offsets_from_lengths(lengths: Sequence[int] | np.ndarray) -> np.ndarray:
    """Episode offsets `[E + 1]` (int64, from 0) of episodes with these lengths."""
    return np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)


def load_dataset(path: str | Path) -> Dataset:
    """`Dataset.load(path)`."""
    return Dataset.load(path)


#: |stored - recomputed| allowed for imported dense rewards: panda-gym computes them from its
#: float64 goal, the data holds the float32 one.
DENSE_TOLERANCE = 1e-5


def rewards_match(stored: np.ndarray, recomputed: np.ndarray, reward: str) -> bool:
    """Whether `stored` rewards are panda-gym's `reward` of the goals (`recomputed`)."""
    tol = 0.0 if reward == "sparse" else DENSE_TOLERANCE
    stored = np.asarray(stored, dtype=np.float64).reshape(-1)
    return stored.shape == recomputed.shape and bool(np.all(np.abs(stored - recomputed) <= tol))


def check_rewards(stored: np.ndarray, recomputed: np.ndarray, reward: str, where: str) -> None:
    """Refuse imported rewards that are not panda-gym's reward of the stored goals."""
    if not rewards_match(stored, recomputed, reward):
        raise GcdtError(
            f"{where}: the stored {reward} rewards differ from panda-gym's reward of the stored "
            "goals, so the data does not come from this task's env"
        )


def _validate(task: str, arrays: dict[str, np.ndarray]) -> None:
    """Raise a `GcdtError` naming the first thing wrong with these arrays for `task`."""
    spec = get_task(task)
    missing = sorted(set(ARRAYS) - set(arrays))
    if missing:
        raise GcdtError(f"dataset lacks arrays {', '.join(missing)}")
    offsets = arrays["offsets"]
    if offsets.dtype != np.int64 or offsets.ndim != 1 or len(offsets) < 2 or offsets[0] != 0:
        raise GcdtError(
            "dataset offsets must be int64 [episodes + 1] starting at 0, with >= 1 episode"
        )
    if np.any(np.diff(offsets) < 1):
        raise GcdtError("dataset has an episode with no transitions (offsets not increasing)")
    rows = {
        **dict.fromkeys(TRANSITION_ARRAYS, int(offsets[-1])),
        **dict.fromkeys(EPISODE_ARRAYS, len(offsets) - 1),
    }
    for name, dtype in {**TRANSITION_ARRAYS, **EPISODE_ARRAYS}.items():
        a = arrays[name]
        width = _width(name, spec)
        shape = (rows[name],) if width is None else (rows[name], width)
        if a.dtype != dtype:
            raise GcdtError(f"dataset array {name} has dtype {a.dtype}, expected {np.dtype(dtype)}")
        if a.shape != shape:
            raise GcdtError(
                f"dataset array {name} has shape {a.shape} but task {task!r} needs {shape}"
                " (does the data belong to another task?)"
            )
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            row = int(np.flatnonzero(~np.isfinite(a).reshape(len(a), -1).all(axis=1))[0])
            raise GcdtError(f"dataset array {name} contains NaN or inf (first at row {row})")
    done = arrays["terminated"] | arrays["truncated"]
    last = np.zeros_like(done)
    last[offsets[1:] - 1] = True
    if not np.array_equal(done, last):
        row = int(np.flatnonzero(done != last)[0])
        raise GcdtError(
            f"dataset episode boundaries disagree with terminated/truncated at transition {row}: "
            "every episode must end, and only end, with a terminated or truncated step"
        )

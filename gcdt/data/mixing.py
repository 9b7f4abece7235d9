"""Subsets (RQ4) and expert/random mixtures (RQ5), both by whole episodes.

Episodes are drawn in a random order fixed by `seed` and the prefix whose total length is
closest to the target is kept, so a size is met to within one episode. With the same seed,
a smaller subset of a dataset is contained in every larger one: the RQ4 curve then measures
more data of the same kind, not a different sample at each size.
"""

from __future__ import annotations

import numpy as np

from gcdt.data.dataset import Dataset, offsets_from_lengths
from gcdt.errors import GcdtError
from gcdt.provenance import utc_now


def _check_size(size: int) -> None:
    if not isinstance(size, int | np.integer) or size < 1:
        raise GcdtError(f"size must be a positive number of transitions, got {size!r}")


def _draw(
    dataset: Dataset, target: int, rng: np.random.Generator, what: str, minimum: int = 0
) -> np.ndarray:
    """Indices (sorted) of random episodes, at least `minimum` of them, whose total length
    is closest to `target`."""
    if target == 0:
        return np.zeros(0, dtype=np.int64)
    if target > len(dataset):
        raise GcdtError(
            f"{what} needs {target} transitions but the dataset has only {len(dataset)}: "
            "collect a larger dataset or ask for fewer"
        )
    order = rng.permutation(dataset.n_episodes)
    total = offsets_from_lengths(dataset.episode_lengths[order])  # length of each prefix
    count = max(minimum, int(np.argmin(np.abs(total - target))))
    return np.sort(order[:count])


def _part(dataset: Dataset, target: int, rng: np.random.Generator, name: str) -> Dataset | None:
    chosen = _draw(dataset, target, rng, f"the {name} part")
    return dataset.select(chosen, {}) if chosen.size else None


def subset(dataset: Dataset, size: int, seed: int = 0) -> Dataset:
    """About `size` transitions (within one episode) of whole episodes of `dataset`."""
    _check_size(size)
    chosen = _draw(dataset, int(size), np.random.default_rng(seed), "the subset", minimum=1)
    metadata = {
        "source": "subset",
        "task": dataset.task,
        "policy": dataset.metadata.get("policy"),
        "size": int(size),
        "seed": int(seed),
        "created": utc_now(),
        "parent": dataset.metadata,
    }
    return dataset.select(chosen, metadata)


def mix(expert: Dataset, random: Dataset, expert_ratio: float, size: int, seed: int = 0) -> Dataset:
    """About `size` transitions, a fraction `expert_ratio` of them from `expert`'s episodes.

    The expert part is the whole-episode draw closest to `expert_ratio * size`; the random
    part then fills the total up to `size`. Each part is within one of its episodes of its
    target, and the total within one random episode of `size`. Expert episodes come first.
    """
    _check_size(size)
    ratio = float(expert_ratio)
    if not 0.0 <= ratio <= 1.0:  # also rejects NaN
        raise GcdtError(f"expert ratio must be within [0, 1], got {expert_ratio!r}")
    if expert.task != random.task:
        raise GcdtError(f"cannot mix datasets of tasks {expert.task!r} and {random.task!r}")
    seeds = np.random.SeedSequence(seed).spawn(2)  # independent draws from each source
    from_expert = _part(expert, round(ratio * size), np.random.default_rng(seeds[0]), "expert")
    expert_steps = len(from_expert) if from_expert is not None else 0
    random_target = 0 if ratio == 1.0 else max(0, int(size) - expert_steps)
    from_random = _part(random, random_target, np.random.default_rng(seeds[1]), "random")
    parts = [p for p in (from_expert, from_random) if p is not None]
    if not parts:
        raise GcdtError(f"size {size} is too small to hold one whole episode")
    metadata = {
        "source": "mix",
        "task": expert.task,
        "policy": {
            "name": "mix",
            "expert": expert.metadata.get("policy"),
            "random": random.metadata.get("policy"),
        },
        "expert_ratio": ratio,
        "size": int(size),
        "seed": int(seed),
        "expert_transitions": expert_steps,
        "random_transitions": sum(len(p) for p in parts) - expert_steps,
        "created": utc_now(),
        "expert": expert.metadata,
        "random": random.metadata,
    }
    return concatenate(parts, metadata)


def concatenate(parts: list[Dataset], metadata: dict) -> Dataset:
    """The episodes of `parts` one after another, as one dataset of their (common) task."""
    if not parts:
        raise GcdtError("nothing to concatenate")
    first = parts[0]
    arrays = {}
    for k in first.arrays:
        if k == "offsets":
            lengths = np.concatenate([p.episode_lengths for p in parts])
            arrays[k] = offsets_from_lengths(lengths)
        else:
            arrays[k] = np.concatenate([p.arrays[k] for p in parts])
    return Dataset(first.task, arrays, metadata)

"""gcdt.data.mixing: RQ4 subsets and RQ5 mixtures by whole episodes."""

from __future__ import annotations

import numpy as np
import pytest

from gcdt.data import mix, subset
from gcdt.errors import GcdtError


@pytest.fixture
def expert(make_dataset):
    rng = np.random.default_rng(1)
    return make_dataset("push", lengths=tuple(rng.integers(5, 40, 120)), seed=1)


@pytest.fixture
def random_data(make_dataset):
    return make_dataset("push", lengths=(50,) * 60, seed=2)


def _episode_keys(ds):
    """Episodes identified by their (distinct) seeds and first action."""
    return {
        (int(s), float(a))
        for s, a in zip(ds.arrays["episode_seed"], ds.actions[ds.offsets[:-1], 0], strict=True)
    }


@pytest.mark.parametrize("size", [40, 500, 1000, 2000])
def test_subset_size_within_one_episode_and_whole_episodes(expert, size):
    part = subset(expert, size, seed=3)
    assert abs(len(part) - size) <= expert.episode_lengths.max()
    assert _episode_keys(part) <= _episode_keys(expert)
    assert part.metadata["source"] == "subset" and part.metadata["parent"] == expert.metadata


def test_subset_is_deterministic_and_nested(expert):
    a, b = subset(expert, 600, seed=5), subset(expert, 600, seed=5)
    assert a.equal_data(b)
    assert not a.equal_data(subset(expert, 600, seed=6))
    assert _episode_keys(subset(expert, 300, seed=5)) <= _episode_keys(a)  # RQ4 sizes nest


@pytest.mark.parametrize("ratio", [0.0, 0.25, 0.5, 0.75, 1.0])
def test_mix_ratio_and_size(expert, random_data, ratio):
    size = 1500
    mixed = mix(expert, random_data, ratio, size, seed=0)
    n_expert = mixed.metadata["expert_transitions"]
    n_random = mixed.metadata["random_transitions"]
    assert n_expert + n_random == len(mixed)
    assert abs(n_expert - ratio * size) <= expert.episode_lengths.max()
    assert abs(len(mixed) - size) <= random_data.episode_lengths.max()
    # The first n_expert transitions are expert episodes, the rest random ones.
    first_random = np.searchsorted(mixed.offsets, n_expert)
    assert mixed.offsets[first_random] == n_expert
    seeds = mixed.arrays["episode_seed"]
    assert set(seeds[:first_random]) <= set(expert.arrays["episode_seed"])
    assert set(seeds[first_random:]) <= set(random_data.arrays["episode_seed"])
    if ratio == 0.0:
        assert n_expert == 0
    if ratio == 1.0:
        assert n_random == 0


def test_mix_is_deterministic(expert, random_data):
    assert mix(expert, random_data, 0.5, 1000, seed=4).equal_data(
        mix(expert, random_data, 0.5, 1000, seed=4)
    )
    assert not mix(expert, random_data, 0.5, 1000, seed=4).equal_data(
        mix(expert, random_data, 0.5, 1000, seed=9)
    )


def test_bad_sizes_and_ratios(expert, random_data, make_dataset):
    with pytest.raises(GcdtError, match="has only"):
        subset(expert, len(expert) + 1)
    with pytest.raises(GcdtError, match="size must be a positive"):
        subset(expert, 0)
    with pytest.raises(GcdtError, match=r"within \[0, 1\]"):
        mix(expert, random_data, 1.5, 100)
    with pytest.raises(GcdtError, match=r"within \[0, 1\]"):
        mix(expert, random_data, float("nan"), 100)
    with pytest.raises(GcdtError, match="random part needs"):
        mix(expert, random_data, 0.0, len(random_data) + 100)
    with pytest.raises(GcdtError, match="expert part needs"):
        mix(expert, random_data, 1.0, len(expert) + 100)
    with pytest.raises(GcdtError, match="tasks 'push' and 'reach'"):
        mix(expert, make_dataset("reach"), 0.5, 10)

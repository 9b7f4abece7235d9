"""gcdt.data.dataset: layout, accessors, the .npz format and every way a file can be wrong."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from gcdt.data import Dataset, load_dataset
from gcdt.data import dataset as dataset_module
from gcdt.errors import GcdtError


def _write_raw(path, ds: Dataset, *, arrays=None, header=None) -> None:
    """Write an .npz like `Dataset.save`, with arrays or header overridden (bad files)."""
    arrays = {**ds.arrays, **(arrays or {})}
    head = {"format": "gcdt.dataset", "schema_version": 1, "task": ds.task, "metadata": {}}
    head |= header or {}
    np.savez(path, **arrays, __metadata__=np.array(json.dumps(head)))


def test_layout_and_accessors(make_dataset):
    ds = make_dataset("push", lengths=(5, 3, 7, 4))
    assert len(ds) == 19 and ds.n_episodes == 4
    np.testing.assert_array_equal(ds.offsets, [0, 5, 8, 15, 19])
    np.testing.assert_array_equal(ds.episode_lengths, [5, 3, 7, 4])
    np.testing.assert_array_equal(ds.timesteps[:9], [0, 1, 2, 3, 4, 0, 1, 2, 0])
    np.testing.assert_array_equal(ds.episode_index[4:6], [0, 1])

    # The paper's state order, whatever order the dict had.
    a = ds.arrays
    assert ds.states.shape == (19, 18 + 3 + 3) and ds.states.dtype == np.float32
    np.testing.assert_array_equal(ds.states[:, :18], a["observation"])
    np.testing.assert_array_equal(ds.states[:, 18:21], a["desired_goal"])
    np.testing.assert_array_equal(ds.states[:, 21:], a["achieved_goal"])

    for reward in ("sparse", "dense"):
        r = ds.rewards(reward)
        expected = np.concatenate(
            [
                np.cumsum(r[lo:hi][::-1])[::-1]
                for lo, hi in zip(ds.offsets, ds.offsets[1:], strict=False)
            ]
        )
        np.testing.assert_allclose(ds.returns_to_go(reward), expected, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(
            ds.episode_returns(reward),
            [r[lo:hi].sum() for lo, hi in zip(ds.offsets, ds.offsets[1:], strict=False)],
            rtol=1e-6,
        )
    success = [
        a["success"][lo:hi].any() for lo, hi in zip(ds.offsets, ds.offsets[1:], strict=False)
    ]
    np.testing.assert_array_equal(ds.episode_success, success)

    nxt = ds.next_observations()
    np.testing.assert_array_equal(nxt["observation"][:4], a["observation"][1:5])
    np.testing.assert_array_equal(nxt["achieved_goal"][4], a["final_achieved_goal"][0])
    np.testing.assert_array_equal(nxt["desired_goal"][18], a["final_desired_goal"][3])

    s = ds.summary()
    assert (s["episodes"], s["transitions"], s["mean_length"]) == (4, 19, 19 / 4)
    assert s["success_rate"] == pytest.approx(np.mean(success))
    assert s["mean_return_dense"] == pytest.approx(ds.episode_returns("dense").mean())
    with pytest.raises(GcdtError, match="unknown reward"):
        ds.rewards("shaped")


def test_select_keeps_whole_episodes_in_order(make_dataset):
    ds = make_dataset("reach", lengths=(2, 3, 4))
    part = ds.select([2, 0], {"source": "test"})
    np.testing.assert_array_equal(part.episode_lengths, [4, 2])
    np.testing.assert_array_equal(part.actions, np.concatenate([ds.actions[5:9], ds.actions[0:2]]))
    np.testing.assert_array_equal(part.arrays["episode_seed"], ds.arrays["episode_seed"][[2, 0]])


def test_save_load_round_trip(make_dataset, tmp_path):
    ds = make_dataset("pick_and_place", lengths=(6, 2))
    path = ds.save(tmp_path / "sub" / "d.npz")
    loaded = load_dataset(path)
    assert loaded.equal_data(ds) and loaded.metadata == ds.metadata and loaded.task == ds.task
    assert [p.name for p in path.parent.iterdir()] == ["d.npz"]  # no temp file left
    with np.load(path, allow_pickle=False) as npz:  # plain numpy, no pickle needed
        assert npz["action"].shape == (8, 4)
    with pytest.raises(GcdtError, match=r"must end in \.npz"):
        ds.save(tmp_path / "d.h5")


@pytest.mark.parametrize("when", ["new", "overwrite"])
def test_interrupted_save_leaves_nothing_half_written(make_dataset, tmp_path, monkeypatch, when):
    ds = make_dataset()
    path = tmp_path / "d.npz"
    if when == "overwrite":
        ds.save(path)
        before = path.read_bytes()

    def savez_then_interrupt(f, **arrays):
        f.write(b"PK\x03\x04 half a zip")
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savez", savez_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        ds.save(path)
    if when == "new":
        assert list(tmp_path.iterdir()) == []
    else:
        assert [p.name for p in tmp_path.iterdir()] == ["d.npz"]
        assert path.read_bytes() == before


def test_bad_files_are_refused_with_one_line(make_dataset, tmp_path):
    ds = make_dataset("push")
    good = ds.save(tmp_path / "good.npz")
    data = good.read_bytes()
    cases = {}

    (tmp_path / "truncated.npz").write_bytes(data[: len(data) // 2])
    cases["truncated.npz"] = "truncated or corrupt"
    corrupt = bytearray(data)
    corrupt[len(data) // 3 : len(data) // 3 + 64] = b"\xff" * 64  # inside an array's bytes
    (tmp_path / "corrupt.npz").write_bytes(bytes(corrupt))
    cases["corrupt.npz"] = "truncated or corrupt"  # zip CRC-32 catches it
    (tmp_path / "text.npz").write_text("not a dataset\n")
    cases["text.npz"] = "truncated or corrupt"
    np.savez(tmp_path / "plain.npz", x=np.zeros(3))
    cases["plain.npz"] = "not a gcdt dataset"
    _write_raw(tmp_path / "v0.npz", ds, header={"schema_version": 0})
    cases["v0.npz"] = "schema version 0"
    _write_raw(tmp_path / "task.npz", ds, header={"task": "reach"})
    cases["task.npz"] = "another task"
    _write_raw(tmp_path / "unknown.npz", ds, header={"task": "fly"})
    cases["unknown.npz"] = "unknown task"
    obs = ds.arrays["observation"].copy()
    obs[7, 2] = np.nan
    _write_raw(tmp_path / "nan.npz", ds, arrays={"observation": obs})
    cases["nan.npz"] = "observation contains NaN or inf .first at row 7"
    rew = ds.arrays["reward_dense"].copy()
    rew[3] = np.inf
    _write_raw(tmp_path / "inf.npz", ds, arrays={"reward_dense": rew})
    cases["inf.npz"] = "reward_dense contains NaN or inf"
    arrays = dict(ds.arrays)
    del arrays["success"]
    np.savez(
        tmp_path / "missing.npz",
        **arrays,
        __metadata__=np.array(
            json.dumps({"format": "gcdt.dataset", "schema_version": 1, "task": "push"})
        ),
    )
    cases["missing.npz"] = "lacks arrays success"
    cases["absent.npz"] = "does not exist"

    for name, pattern in cases.items():
        with pytest.raises(GcdtError, match=pattern) as err:
            load_dataset(tmp_path / name)
        assert "\n" not in str(err.value), name
        assert name in str(err.value) or name == "absent.npz" or "absent.npz" in str(err.value)


def test_construction_validates_boundaries_dims_and_dtypes(make_dataset):
    ds = make_dataset("reach", lengths=(3, 4))

    def broken(**changes):
        return Dataset("reach", {**ds.arrays, **changes}, {})

    done_mid = ds.arrays["truncated"].copy()
    done_mid[1] = True
    with pytest.raises(GcdtError, match=r"boundaries disagree .* transition 1"):
        broken(truncated=done_mid)
    with pytest.raises(GcdtError, match="offsets"):
        broken(offsets=np.array([1, 3, 7]))
    with pytest.raises(GcdtError, match="no transitions"):
        broken(offsets=np.array([0, 3, 3, 7]))
    with pytest.raises(GcdtError, match="dtype float64"):
        broken(action=ds.actions.astype(np.float64))
    with pytest.raises(GcdtError, match="shape"):
        broken(action=np.zeros((7, 4), np.float32))
    with pytest.raises(TypeError):
        Dataset("reach", ds.arrays, {"bad": object()})  # metadata must be JSON-able


def test_load_is_not_fooled_by_the_extension(tmp_path):
    path = tmp_path / "x.npz"
    with open(path, "wb") as f:
        f.write(os.urandom(4096))
    with pytest.raises(GcdtError, match="truncated or corrupt"):
        dataset_module.Dataset.load(path)

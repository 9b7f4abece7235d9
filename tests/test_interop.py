"""Minari export/import and the authors' pickle format."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from gcdt.data import export_minari, import_authors, import_minari
from gcdt.data.minari_io import default_minari_id
from gcdt.errors import GcdtError


@pytest.fixture
def minari_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    return tmp_path / "minari"


def test_minari_round_trip_is_exact(make_dataset, minari_dir):
    import minari

    ds = make_dataset("pick_and_place", lengths=(4, 9, 2))
    dataset_id = default_minari_id(ds)
    assert dataset_id == "panda-gym/pick_and_place/synth-v0"
    exported = export_minari(ds)
    assert (exported.total_episodes, exported.total_steps) == (3, 15)

    back = import_minari(dataset_id)
    assert back.equal_data(ds) and back.metadata == ds.metadata

    # A plain Minari user gets the same data and a working env.
    loaded = minari.load_dataset(dataset_id)
    ep = next(iter(loaded.iterate_episodes()))
    np.testing.assert_array_equal(ep.observations["observation"][:4], ds.arrays["observation"][:4])
    np.testing.assert_array_equal(ep.rewards, ds.rewards("sparse")[:4])
    env = loaded.recover_environment()
    try:
        assert env.spec.id == "PandaPickAndPlace-v3"
        obs, _ = env.reset(seed=0)
        assert obs["observation"].shape == (19,)
    finally:
        env.close()


def test_minari_dense_export_and_refusals(make_dataset, minari_dir, monkeypatch):
    import minari

    ds = make_dataset("reach", lengths=(3, 3))
    export_minari(ds, "gcdt/reach-dense-v0", reward="dense")
    assert minari.load_dataset("gcdt/reach-dense-v0").spec.env_spec.id == "PandaReachDense-v3"
    assert import_minari("gcdt/reach-dense-v0").equal_data(ds)

    with pytest.raises(GcdtError, match="already exists"):
        export_minari(ds, "gcdt/reach-dense-v0")
    with pytest.raises(GcdtError, match="invalid Minari dataset id"):
        export_minari(ds, "no version!")
    with pytest.raises(GcdtError, match="no local Minari dataset 'gcdt/absent-v0'"):
        import_minari("gcdt/absent-v0")

    # A failure while writing leaves no dataset behind.
    from minari.dataset.minari_storage import MinariStorage

    def fail(self, metadata):
        raise OSError("disk full")

    monkeypatch.setattr(MinariStorage, "update_metadata", fail)
    with pytest.raises(OSError, match="disk full"):
        export_minari(ds, "gcdt/half-v0")
    monkeypatch.undo()
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(minari_dir))
    assert "gcdt/half-v0" not in minari.list_local_datasets()


@pytest.mark.filterwarnings("ignore::UserWarning:minari")
def test_minari_import_refuses_foreign_rewards(make_dataset, minari_dir):
    import minari
    from minari.data_collector import EpisodeBuffer

    from gcdt.envs import make_env

    ds = make_dataset("reach", lengths=(3,))
    a = ds.arrays
    obs = {
        k: np.concatenate([a[k], a[f"final_{k}"]])
        for k in ("observation", "desired_goal", "achieved_goal")
    }
    buffer = EpisodeBuffer(
        observations=obs,
        actions=a["action"],
        rewards=np.full(3, 1.0, np.float32),  # not panda-gym's reward
        terminations=a["terminated"],
        truncations=a["truncated"],
    )
    env = make_env("reach", "sparse")
    minari.create_dataset_from_buffers("other/reach-v0", [buffer], env=env, author="x")
    env.close()
    with pytest.raises(GcdtError, match="differ from panda-gym's reward"):
        import_minari("other/reach-v0")


def _authors_episodes(ds, reward="dense"):
    """The dataset in the authors' released layout."""
    nxt = ds.next_observations()
    keys = ("observation", "desired_goal", "achieved_goal")
    episodes = []
    for lo, hi in zip(ds.offsets[:-1], ds.offsets[1:], strict=True):
        episodes.append(
            {
                "observations": {k: ds.arrays[k][lo:hi].astype(np.float64) for k in keys},
                "next_observations": {k: nxt[k][lo:hi] for k in keys},
                "actions": ds.actions[lo:hi],
                "rewards": ds.rewards(reward)[lo:hi].tolist(),
                "terminals": ds.arrays["terminated"][lo:hi].astype(np.float32),
            }
        )
    return episodes


def _pickle(path, obj):
    path.write_bytes(pickle.dumps(obj))
    return path


def test_authors_import(make_dataset, tmp_path):
    ds = make_dataset("pick_and_place", lengths=(5, 2, 8))
    path = _pickle(tmp_path / "data.pkl", _authors_episodes(ds))
    imported = import_authors(path, trust_pickle=True)
    assert imported.task == "pick_and_place"
    assert imported.metadata["reward_in_file"] == "dense"
    for key in ds.arrays:
        if key != "episode_seed":
            np.testing.assert_array_equal(imported.arrays[key], ds.arrays[key], err_msg=key)
    np.testing.assert_array_equal(imported.arrays["episode_seed"], -1)  # not in the format

    sparse = import_authors(
        _pickle(tmp_path / "s.pkl", _authors_episodes(ds, "sparse")), trust_pickle=True
    )
    assert sparse.metadata["reward_in_file"] == "sparse" and sparse.equal_data(imported)


def test_authors_terminal_flags_follow_panda_gyms_rule(make_dataset, tmp_path):
    """panda-gym v3 terminates on success only: a failed last step is a timeout, whatever the
    file says, and the disagreement is counted, not hidden."""
    ds = make_dataset("push", lengths=(4, 3, 5))
    episodes = _authors_episodes(ds)
    for ep in episodes:  # the file claims every episode terminated
        ep["terminals"] = np.zeros_like(ep["terminals"])
        ep["terminals"][-1] = 1.0
    imported = import_authors(_pickle(tmp_path / "t.pkl", episodes), trust_pickle=True, task="push")
    last = np.cumsum(imported.episode_lengths) - 1
    success = imported.arrays["success"][last]
    np.testing.assert_array_equal(imported.arrays["terminated"][last], success)
    np.testing.assert_array_equal(imported.arrays["truncated"][last], ~success)
    assert imported.metadata["terminal_flags_disagreeing"] == int((~success).sum()) > 0


def test_authors_import_refusals(make_dataset, tmp_path):
    push = make_dataset("push", lengths=(4, 3))
    good = _authors_episodes(push)
    path = _pickle(tmp_path / "push.pkl", good)

    with pytest.raises(
        GcdtError, match=r"refusing to unpickle .* runs arbitrary code .*--trust-pickle"
    ):
        import_authors(path)
    # Push and Slide have the same widths: the task must be named.
    with pytest.raises(GcdtError, match=r"matches: push, slide.*pass --task"):
        import_authors(path, trust_pickle=True)
    assert import_authors(path, trust_pickle=True, task="push").n_episodes == 2
    wide = [
        {**ep, "observations": {**ep["observations"], "observation": np.zeros((4, 7))}}
        for ep in good
    ]
    with pytest.raises(GcdtError, match="observation width 7 and action width 3 match no panda"):
        import_authors(_pickle(tmp_path / "wide.pkl", wide), trust_pickle=True)
    with pytest.raises(GcdtError, match="another task"):
        import_authors(path, trust_pickle=True, task="reach")

    def bad(name, episodes, pattern):
        with pytest.raises(GcdtError, match=pattern) as err:
            import_authors(_pickle(tmp_path / name, episodes), trust_pickle=True, task="push")
        assert "\n" not in str(err.value)

    broken = [dict(ep) for ep in good]
    broken[1] = {
        **broken[1],
        "next_observations": {k: v.copy() for k, v in good[1]["next_observations"].items()},
    }
    broken[1]["next_observations"]["observation"][0, 0] += 1.0
    bad("gap.pkl", broken, r"episode 1: next_observations\[observation\]\[0\] is not")
    wrong_reward = [dict(ep) for ep in good]
    wrong_reward[0] = {**wrong_reward[0], "rewards": [0.5] * 4}
    bad("reward.pkl", wrong_reward, "episode 0: rewards are neither")
    mixed = [good[0], {**good[1], "rewards": push.rewards("sparse")[4:].tolist()}]
    bad("mixed.pkl", mixed, "episode 1: the stored dense rewards differ")
    bad("dict.pkl", {"not": "a list"}, "non-empty list of episode dicts")
    bad("keys.pkl", [{"actions": []}], "expected a dict with keys")
    nan = [dict(ep) for ep in good]
    nan[0] = {**nan[0], "actions": np.full((4, 3), np.nan, np.float32)}
    bad("nan.pkl", nan, "action contains NaN")
    (tmp_path / "junk.pkl").write_bytes(b"\x80\x04junk")
    with pytest.raises(GcdtError, match="not a readable pickle"):
        import_authors(tmp_path / "junk.pkl", trust_pickle=True)

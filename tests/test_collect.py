"""gcdt.data.collect against the simulator: whole episodes, exact rewards, reproducibility."""

from __future__ import annotations

import hashlib
import importlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gcdt.cli import main
from gcdt.data import collect, load_dataset
from gcdt.envs import episode_seed, make_env
from gcdt.errors import GcdtError
from gcdt.policies import RandomPolicy, ScriptedExpert

# The module, which `gcdt.data.collect` (its function, exported by gcdt.data) hides.
collect_module = importlib.import_module("gcdt.data.collect")
_COLLECT_CHUNK = collect_module._collect_chunk


def _replay(ds, reward: str) -> dict[str, np.ndarray]:
    """Step one fresh env of `reward` type through the dataset's episodes and actions, in order
    (the history a single collecting env had), and record what the env itself returned."""
    env = make_env(ds.task, reward)
    out = {"reward": [], "terminated": [], "truncated": [], "success": [], "observation": []}
    try:
        for e in range(ds.n_episodes):
            obs, _ = env.reset(seed=int(ds.arrays["episode_seed"][e]))
            for action in ds.episode(e)["action"]:
                out["observation"].append(obs["observation"])
                obs, r, term, trunc, info = env.step(action)
                out["reward"].append(r)
                out["terminated"].append(term)
                out["truncated"].append(trunc)
                out["success"].append(info["is_success"])
    finally:
        env.close()
    return {k: np.asarray(v) for k, v in out.items()}


@pytest.mark.parametrize("task,policy", [("push", "random"), ("pick_and_place", "scripted")])
def test_collected_data_is_what_the_env_returned(task, policy):
    pol = RandomPolicy(task) if policy == "random" else ScriptedExpert(task)
    ds = collect(pol, task, 120, seed=3, n_envs=1, progress=False)

    # Whole episodes, the first of the run, just reaching the request.
    assert len(ds) >= 120 and len(ds) - ds.episode_lengths[-1] < 120
    stream = "random-collection" if policy == "random" else "collection"
    seeds = [episode_seed(3, j, stream) for j in range(ds.n_episodes)]
    np.testing.assert_array_equal(ds.arrays["episode_seed"], seeds)

    sparse, dense = _replay(ds, "sparse"), _replay(ds, "dense")
    np.testing.assert_array_equal(sparse["observation"], ds.arrays["observation"])
    np.testing.assert_array_equal(sparse["reward"], ds.rewards("sparse"))
    # The env computes the dense reward from its float64 goal, the dataset from the float32
    # goal it stores: equal to float32 rounding.
    np.testing.assert_allclose(dense["reward"], ds.rewards("dense"), rtol=0, atol=1e-6)
    for key in ("terminated", "truncated", "success"):
        np.testing.assert_array_equal(sparse[key], ds.arrays[key], err_msg=key)
        np.testing.assert_array_equal(dense[key], ds.arrays[key], err_msg=key)
    if policy == "scripted":
        assert ds.arrays["terminated"].sum() == ds.n_episodes  # the expert always succeeds here
    assert ds.metadata["policy"] == pol.config()
    assert ds.metadata["versions"]["panda-gym"] == "3.0.7"


def test_collection_is_bit_for_bit_reproducible():
    def run(seed, n_envs):
        return collect(
            ScriptedExpert("push"), "push", 150, seed=seed, n_envs=n_envs, progress=False
        )

    a = run(0, 2)
    assert a.equal_data(run(0, 2))
    assert not a.equal_data(run(1, 2))
    # Another process count runs the same episodes (same seeds, same initial states).
    b = run(0, 1)
    n = min(a.n_episodes, b.n_episodes)
    np.testing.assert_array_equal(a.arrays["episode_seed"][:n], b.arrays["episode_seed"][:n])
    np.testing.assert_array_equal(
        a.arrays["desired_goal"][a.offsets[:n]], b.arrays["desired_goal"][b.offsets[:n]]
    )


def test_clean_labels_record_the_experts_action_and_the_env_runs_the_noisy_one():
    """DART: with labels "clean", each state's action is the noise-free expert's action in that
    state, while the states themselves are those the noisy execution visited."""
    expert = ScriptedExpert("push", noise_std=0.2)
    clean = collect(expert, "push", 120, seed=5, labels="clean", progress=False)
    executed = collect(expert, "push", 120, seed=5, labels="executed", progress=False)
    assert clean.metadata["labels"] == "clean" and executed.metadata["labels"] == "executed"
    # The same noisy run (same seeds, same noise draws): same states, other actions.
    np.testing.assert_array_equal(clean.arrays["observation"], executed.arrays["observation"])
    assert not np.allclose(clean.actions, executed.actions)
    obs = {k: clean.arrays[k] for k in ("observation", "desired_goal", "achieved_goal")}
    noise_free = ScriptedExpert("push").predict(obs, np.zeros(len(clean), bool), np.zeros(0))
    np.testing.assert_array_equal(clean.actions, noise_free)
    # The executed actions are what the env ran: replaying them reproduces the observations.
    np.testing.assert_array_equal(_replay(executed, "sparse")["observation"], obs["observation"])


def test_bad_collection_arguments():
    with pytest.raises(GcdtError, match="unknown action labels 'noisy': expected one of"):
        collect(RandomPolicy("reach"), "reach", 10, labels="noisy")
    with pytest.raises(GcdtError, match="transitions must be a positive integer"):
        collect(RandomPolicy("reach"), "reach", 0)
    with pytest.raises(GcdtError, match="transitions must be a positive integer"):
        collect(RandomPolicy("reach"), "reach", -5)
    with pytest.raises(GcdtError, match="policy is for task 'reach', not 'push'"):
        collect(RandomPolicy("reach"), "push", 10)
    with pytest.raises(GcdtError, match="n_envs must be a positive integer"):
        collect(RandomPolicy("reach"), "reach", 10, n_envs=0)


# --- chunks: resumable collections ---------------------------------------------------------


class Killed(Exception):
    """Stands for the kill of a collecting process."""


def _killed_after(monkeypatch, chunks: int) -> list[int]:
    """Make collections die after collecting `chunks` chunks; returns the count of chunks
    collected (not loaded) since."""
    collected = []

    def chunk(*args, **kwargs):
        if len(collected) == chunks:
            raise Killed
        collected.append(1)
        return _COLLECT_CHUNK(*args, **kwargs)

    monkeypatch.setattr(collect_module, "_collect_chunk", chunk)
    return collected


def _digest(ds) -> str:
    h = hashlib.sha256()
    for k in sorted(ds.arrays):
        a = np.ascontiguousarray(ds.arrays[k])
        h.update(f"{k}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _push(**kwargs):
    """Two Push envs with a noisy expert: Bullet's carried state and the policy's noise."""
    expert = ScriptedExpert("push", noise_std=0.2)
    return collect(expert, "push", 150, seed=0, n_envs=2, progress=False, **kwargs)


#: The arrays the collector made before collections ran in chunks, for `_push()`'s arguments,
#: on a CPU where numpy's best kernels were X86_V3 (AVX2); the smoke, quick and standard
#: datasets (and their manifests' SHA-256s) are such one-chunk collections.
REFERENCE_KERNELS = "X86_V3"
REFERENCE_DIGEST = "db65c465081c380dfd9bb35b2834a90b965f2930c12a3be2fe1bf2993b2f2c99"
_DIGEST_SCRIPT = """
from test_collect import _digest, _push
print(_digest(_push()))
"""


def test_the_reference_collection_is_made_again_with_the_reference_kernels():
    """On any CPU that has the reference's numpy kernels: numpy switched down to them (in a
    process of its own, env workers included) collects the reference's bytes exactly. With
    AVX-512 kernels its scripted expert's `np.arctan2` differs in the last bit."""
    from gcdt.provenance import numpy_kernels

    kernels = numpy_kernels()
    if REFERENCE_KERNELS not in kernels:
        pytest.skip(f"this CPU lacks numpy's {REFERENCE_KERNELS} kernels (it has {kernels})")
    above = kernels[kernels.index(REFERENCE_KERNELS) + 1 :]
    env = {**os.environ, "NPY_DISABLE_CPU_FEATURES": " ".join(above)}
    env["PYTHONPATH"] = os.pathsep.join([str(Path(__file__).parent), env.get("PYTHONPATH", "")])
    out = subprocess.run(
        [sys.executable, "-c", _DIGEST_SCRIPT], env=env, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split()[-1] == REFERENCE_DIGEST


def test_a_collection_of_one_chunk_is_the_collection_made_before_chunks(tmp_path):
    assert 150 < collect_module.CHUNK_TRANSITIONS
    plain = _push()
    reference = _digest(plain)  # this CPU's; the reference kernels' is checked above
    saved = _push(chunks_dir=tmp_path / "chunks")  # saved as a chunk, and the same
    assert _digest(saved) == reference
    assert [p.name for p in (tmp_path / "chunks").iterdir()] == ["00000.npz"]
    for ds in (plain, saved):  # and so is the metadata: no chunk keys
        assert not {"chunks", "chunk_transitions", "chunks_resumed"} & set(ds.metadata)


def test_a_killed_collection_resumes_from_its_chunks_and_equals_an_uninterrupted_one(
    tmp_path, monkeypatch
):
    monkeypatch.setattr(collect_module, "CHUNK_TRANSITIONS", 40)
    whole = _push()
    chunks = whole.metadata["chunks"]
    assert chunks >= 3 and whole.metadata["chunk_transitions"] == 40
    assert "chunks_resumed" not in whole.metadata

    folder = tmp_path / "push.chunks"
    _killed_after(monkeypatch, 2)
    with pytest.raises(Killed):
        _push(chunks_dir=folder)
    assert sorted(p.name for p in folder.iterdir()) == ["00000.npz", "00001.npz"]
    collected = _killed_after(monkeypatch, 99)
    resumed = _push(chunks_dir=folder)
    assert len(collected) == chunks - 2  # those left; the two saved ones were loaded
    assert resumed.equal_data(whole)
    assert resumed.metadata["chunks"] == chunks and resumed.metadata["chunks_resumed"] == 2

    # Chunked or not, the run's episodes are the same instances in the same order, and the
    # first chunk is the first episodes of the one-chunk run; later chunks restart fresh
    # envs (and the noise), so they differ from it.
    monkeypatch.setattr(collect_module, "CHUNK_TRANSITIONS", 10_000)
    plain = _push()
    assert "chunks" not in plain.metadata
    n = min(plain.n_episodes, whole.n_episodes)
    np.testing.assert_array_equal(
        whole.arrays["episode_seed"][:n], plain.arrays["episode_seed"][:n]
    )
    first = load_dataset(folder / "00000.npz")
    assert plain.select(np.arange(first.n_episodes), {}).equal_data(first)
    assert len(first) >= 40 and len(first) - first.episode_lengths[-1] < 40
    assert not plain.select(np.arange(n), {}).equal_data(whole.select(np.arange(n), {}))


def test_later_chunks_do_not_replay_the_policys_noise(monkeypatch):
    monkeypatch.setattr(collect_module, "CHUNK_TRANSITIONS", 50)
    ds = collect(RandomPolicy("reach"), "reach", 150, seed=0, progress=False)
    assert ds.metadata["chunks"] >= 2
    starts = ds.actions[ds.offsets[:-1]]
    assert len({tuple(a) for a in starts}) == len(starts)


def test_a_bad_chunk_is_refused_and_kept(tmp_path, monkeypatch):
    monkeypatch.setattr(collect_module, "CHUNK_TRANSITIONS", 40)
    folder = tmp_path / "push.chunks"
    _killed_after(monkeypatch, 2)
    with pytest.raises(Killed):
        _push(chunks_dir=folder)
    bad = folder / "00001.npz"
    blob = bad.read_bytes()
    bad.write_bytes(blob[: len(blob) // 2])  # a disk that lost the end of the file
    with pytest.raises(GcdtError) as err:
        _push(chunks_dir=folder)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"{bad} is not a gcdt dataset")
    assert "truncated or corrupt" in message and message.endswith(
        f"delete {bad} to collect that chunk again"
    )
    assert bad.read_bytes() == blob[: len(blob) // 2]  # neither recollected nor removed

    # A chunk of another collection (here: another seed) is refused too.
    bad.write_bytes(blob)
    with pytest.raises(
        GcdtError, match=r"00000.npz is a chunk of another collection \(seed 0, not 1\): delete"
    ):
        collect(
            ScriptedExpert("push", noise_std=0.2),
            "push",
            150,
            seed=1,
            n_envs=2,
            progress=False,
            chunks_dir=folder,
        )


def test_gcdt_collect_resumes_a_killed_collection(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(collect_module, "CHUNK_TRANSITIONS", 60)
    out = tmp_path / "reach.npz"
    argv = ["collect", "--policy", "random", "--task", "reach", "--transitions", "150"]
    argv += ["--out", str(out), "--no-progress", "--seed", "2"]
    _killed_after(monkeypatch, 1)
    with pytest.raises(Killed):
        main(argv)
    assert not out.exists() and (tmp_path / "reach.chunks" / "00000.npz").is_file()
    _killed_after(monkeypatch, 99)
    assert main(argv) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["reach.npz"]  # chunks removed
    made = load_dataset(out)
    whole = collect(RandomPolicy("reach"), "reach", 150, seed=2, progress=False)
    assert made.equal_data(whole)
    assert (
        made.metadata["chunks_resumed"] == 1
        and made.metadata["chunks"] == whole.metadata["chunks"] >= 2
    )


def test_a_grid_collection_resumes_after_a_kill(tmp_path, monkeypatch):
    from gcdt.experiments import artifacts, build_grid
    from tests.test_experiments import TINY

    monkeypatch.setenv("GCDT_ARTIFACTS", str(tmp_path))
    monkeypatch.setattr(collect_module, "CHUNK_TRANSITIONS", 100)
    spec = next(e.spec for e in build_grid(TINY, only="table1") if e.spec.method == "gcdt")
    base = spec.data.base("expert")
    path = artifacts.grid_dir() / "datasets" / f"{base.key()}.npz"
    _killed_after(monkeypatch, 1)
    with pytest.raises(Killed):
        artifacts.dataset(base)
    assert not path.exists() and [p.name for p in path.with_suffix(".chunks").iterdir()] == [
        "00000.npz"
    ]
    _killed_after(monkeypatch, 99)
    made = artifacts.dataset(base)
    assert made.metadata["chunks_resumed"] == 1 and made.metadata["chunks"] >= 3
    assert load_dataset(path).equal_data(made) and not path.with_suffix(".chunks").exists()

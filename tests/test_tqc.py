"""TQC+HER: configs from the YAML, a short real training run, its zip as a policy, bad input.

Reaching >= 95 % success on Reach is measured by `benchmarks/tqc_her.py` (about 15 min per
reward on 2 cores: too long for the default suite).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import re
import shutil

import numpy as np
import pytest

from gcdt.baselines.tqc_her import RUN_FILES, load_tqc_config, tqc_config_names, train_tqc
from gcdt.cli import main
from gcdt.data import load_dataset
from gcdt.envs import make_env
from gcdt.errors import GcdtError
from gcdt.evaluation import evaluate
from gcdt.policies import make_policy


def test_paper_config_is_rl_zoo_her_defaults():
    cfg = load_tqc_config("paper", "push")
    assert (cfg.buffer_size, cfg.batch_size, cfg.learning_starts) == (1_000_000, 2048, 1000)
    assert (cfg.gamma, cfg.learning_rate, cfg.tau) == (0.95, 1e-3, 0.05)
    assert (cfg.net_arch, cfg.n_critics) == ((512, 512, 512), 2)
    assert (cfg.n_sampled_goal, cfg.goal_selection_strategy) == (4, "future")
    assert cfg.steps == 1_000_000 and cfg.overrides == {}
    # The loop: SBX's TQC on 8 envs, one gradient step per env step as in the zoo.
    assert (cfg.backend, cfg.n_envs, cfg.train_freq, cfg.gradient_steps) == ("sbx", 8, 1, 1)
    assert load_tqc_config("paper", "reach").steps == 20_000
    assert {"paper", "cpu"} <= set(tqc_config_names())


def test_cpu_config_records_what_it_changed():
    cfg = load_tqc_config("cpu", "reach")
    assert cfg.overrides == {
        "batch_size": [2048, 256],
        "net_arch": [[512, 512, 512], [256, 256]],
        "steps": [20_000, 10_000],
    }
    shorter = cfg.with_budget(steps=500)
    assert shorter.steps == 500 and shorter.overrides["steps"] == [20_000, 500]
    assert shorter.gamma == cfg.gamma  # everything else stays the paper's
    assert "steps" not in shorter.with_budget(steps=20_000).overrides  # back to the paper's


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"gamma": 0.9}, "gamma is not a budget or loop value"),
        ({"backend": "tf"}, "unknown TQC\\+HER backend 'tf': expected one of sb3, sbx"),
        ({"n_envs": 0}, "n_envs must be an integer >= 1"),
        ({"steps": 0}, "steps must be an integer >= 1"),
        ({"steps": -5}, "steps must be an integer >= 1"),
        ({"net_arch": []}, "net_arch must be a list of positive layer sizes"),
    ],
)
def test_only_valid_budget_changes(changes, message):
    with pytest.raises(GcdtError, match=message):
        load_tqc_config("paper", "reach").with_budget(**changes)


def test_unknown_config_name():
    with pytest.raises(GcdtError, match="unknown TQC\\+HER config 'gpu'"):
        load_tqc_config("gpu", "reach")


def _smoke_run(out, backend):
    """A few hundred steps of real TQC+HER training on Push (a smoke run, not a good agent)."""
    cfg = load_tqc_config("cpu", "push").with_budget(
        steps=320,
        learning_starts=100,
        batch_size=32,
        net_arch=[32, 32],
        buffer_size=2000,
        backend=backend,
        n_envs=2,  # two episodes before the first gradient step
    )
    return train_tqc("push", "sparse", cfg, out, eval_every=160, eval_episodes=2, progress=False)


@pytest.fixture(scope="module")
def push_run(tmp_path_factory):
    """The default backend: SBX's TQC."""
    return _smoke_run(tmp_path_factory.mktemp("tqc") / "push", "sbx")


@pytest.fixture(scope="module")
def push_run_sb3(tmp_path_factory):
    """The zoo's library: sb3-contrib's TQC."""
    return _smoke_run(tmp_path_factory.mktemp("tqc") / "push_sb3", "sb3")


def test_smoke_run_writes_models_curve_and_record(push_run):
    out = push_run.out_dir
    assert sorted(p.name for p in out.iterdir()) == sorted(RUN_FILES)
    with open(out / "eval.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["env_steps"]) for r in rows] == [160, 320]
    assert all(int(r["episodes"]) == 2 for r in rows)
    run = json.loads((out / "run.json").read_text())
    assert run["env_steps"] == push_run.env_steps == 320
    assert run["overrides"]["steps"] == [1_000_000, 320]
    assert run["config"]["batch_size"] == 32 and run["reward"] == "sparse"
    assert run["config"]["backend"] == "sbx" and run["device"] == "cpu"
    assert "sbx-rl" in run["versions"] and "jax" in run["versions"]
    assert 0 < run["train_seconds"] <= run["wall_seconds"]
    assert run["env_steps_per_second"] > 0
    assert run["final"]["env_steps"] == 320
    assert run["final"]["success_rate"] == float(rows[-1]["success_rate"])


@pytest.mark.parametrize("backend", ["sbx", "sb3"])
def test_zip_is_a_policy_acting_like_the_backends_own_loader(backend, request):
    if backend == "sbx":
        from sbx import TQC

        push_run = request.getfixturevalue("push_run")
    else:
        from sb3_contrib import TQC

        push_run = request.getfixturevalue("push_run_sb3")
    policy = make_policy(f"tqc:{push_run.model}", "push")
    assert policy.config()["reward"] == "sparse" and policy.name == "tqc"
    env = make_env("push", "sparse")
    try:
        sb3_model = TQC.load(push_run.model, env=env, device="cpu")
        obs, _ = env.reset(seed=3)
        batch = {k: np.repeat(v[None], 2, axis=0) for k, v in obs.items()}
        ours = policy.predict(batch, np.ones(2, bool), np.zeros(2, np.float32))
        theirs, _ = sb3_model.predict(batch, deterministic=True)
    finally:
        env.close()
    assert ours.shape == (2, 3) and ours.dtype == np.float32
    np.testing.assert_allclose(ours, theirs, atol=1e-6)
    assert np.abs(ours).max() > 0  # a trained actor, not zeros
    assert np.abs(ours).max() <= 1.0
    best = make_policy(f"tqc:{push_run.best_model}", "push")
    result = evaluate(best, "push", "sparse", episodes=2, progress=False)
    assert result.summary["episodes"] == 2


def test_collect_with_a_tqc_expert(push_run, tmp_path, capsys):
    out = tmp_path / "tqc_push.npz"
    argv = [
        "collect",
        "--policy",
        f"tqc:{push_run.model}",
        "--task",
        "push",
        "--transitions",
        "120",
        "--out",
        str(out),
        "--no-progress",
    ]
    assert main(argv) == 0
    dataset = load_dataset(out)
    assert dataset.task == "push" and dataset.summary()["transitions"] >= 120
    assert dataset.metadata["policy"]["name"] == "tqc"
    assert dataset.metadata["policy"]["path"] == str(push_run.model)


@pytest.fixture(scope="module")
def foreign_zips(tmp_path_factory, push_run):
    """SB3 zips gcdt did not write: a SAC agent, and a TQC agent on Reach without metadata."""
    from sb3_contrib import TQC
    from stable_baselines3 import SAC

    out = tmp_path_factory.mktemp("foreign")
    env = make_env("reach", "sparse")
    try:
        kwargs = {"buffer_size": 100, "policy_kwargs": {"net_arch": [8]}, "device": "cpu"}
        SAC("MultiInputPolicy", env, **kwargs).save(out / "sac.zip")
        TQC("MultiInputPolicy", env, **kwargs).save(out / "tqc_reach.zip")
    finally:
        env.close()
    (out / "garbage.zip").write_bytes(b"not a zip at all")
    data = push_run.model.read_bytes()
    (out / "truncated.zip").write_bytes(data[: len(data) // 2])
    return out


@pytest.mark.parametrize(
    ("policy", "task", "reward", "message"),
    [
        ("{run}/model.zip", "reach", "sparse", "was trained on task 'push', not 'reach'"),
        ("{run}/model.zip", "push", "dense", "trained with sparse rewards, not dense"),
        ("{foreign}/tqc_reach.zip", "push", "sparse", "it was trained on another task"),
        ("{foreign}/sac.zip", "reach", "sparse", "not a TQC policy"),
        ("{foreign}/garbage.zip", "push", "sparse", "not a readable SB3 TQC model zip"),
        ("{foreign}/truncated.zip", "push", "sparse", "not a readable SB3 TQC model zip"),
        ("{foreign}/absent.zip", "push", "sparse", "no TQC model at"),
    ],
)
def test_bad_zip_one_line_exit_2(
    assert_usage_error, push_run, foreign_zips, policy, task, reward, message
):
    spec = "tqc:" + policy.format(run=push_run.out_dir, foreign=foreign_zips)
    argv = ["evaluate", "--policy", spec, "--task", task, "--reward", reward, "--episodes", "1"]
    assert_usage_error(argv, message)


def test_a_zip_of_the_other_backend_is_refused_in_one_line(push_run, push_run_sb3):
    from gcdt.policies.tqc import TQCPolicy

    with pytest.raises(GcdtError, match="written by the sbx backend, not sb3: load it with"):
        TQCPolicy(push_run.model, "push", backend="sb3")
    with pytest.raises(GcdtError, match="written by the sb3 backend, not sbx"):
        TQCPolicy(push_run_sb3.model, "push", backend="sbx")
    assert TQCPolicy(push_run.model, "push", backend="sbx").meta["backend"] == "sbx"


def test_foreign_tqc_zip_for_its_own_task_is_a_policy(foreign_zips):
    policy = make_policy(f"tqc:{foreign_zips / 'tqc_reach.zip'}", "reach")
    assert policy.config()["reward"] is None  # no gcdt metadata: runs under either reward


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--config", "gpu"], "argument --config: invalid choice: 'gpu'"),
        (["--steps", "0"], "steps must be an integer >= 1, got 0"),
        (["--steps", "-5"], "steps must be an integer >= 1, got -5"),
        (["--eval-episodes", "0"], "eval_episodes must be a positive integer, got 0"),
        (["--backend", "tf"], "--backend: invalid choice: 'tf' (choose from 'sb3', 'sbx')"),
        (["--n-envs", "0"], "n_envs must be an integer >= 1, got 0"),
        (["--stop-at", "1.5"], "stop_at is a success rate in (0, 1], got 1.5"),
        (["--device", "cuda"], "the sbx backend runs on JAX's default device"),
    ],
)
def test_bad_train_input_exit_2_nothing_written(assert_usage_error, tmp_path, extra, message):
    out = tmp_path / "run"
    argv = ["tqc", "train", "--task", "reach", "--reward", "sparse", "--out", str(out), *extra]
    assert_usage_error(argv, message)
    assert not out.exists()


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"stop_at": 0.0}, "stop_at is a success rate in (0, 1], got 0.0"),
        ({"stop_at": float("nan")}, "stop_at is a success rate in (0, 1], got nan"),
        ({"checkpoint_seconds": -1.0}, "checkpoint_seconds must be >= 0, got -1.0"),
        ({"seed": -1}, "seed must be a non-negative integer, got -1"),
        ({"eval_every": 0}, "eval_every must be a positive integer, got 0"),
    ],
)
def test_run_settings_refuse_bad_values_before_anything_runs(tmp_path, settings, message):
    cfg = load_tqc_config("cpu", "reach")
    with pytest.raises(GcdtError, match=re.escape(message)):
        train_tqc("reach", "sparse", cfg, tmp_path / "run", progress=False, **settings)
    assert not (tmp_path / "run").exists()


def test_train_refuses_a_folder_holding_a_run(assert_usage_error, push_run, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(push_run.out_dir, out)
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    argv = ["tqc", "train", "--task", "push", "--reward", "sparse", "--out", str(out)]
    assert_usage_error(argv, "already holds a finished TQC+HER run")
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == before


def test_sbx_refuses_a_config_it_cannot_run(tmp_path):
    cfg = dataclasses.replace(load_tqc_config("cpu", "reach"), n_critics=3)
    with pytest.raises(GcdtError, match="the sbx backend's TQC has exactly 2 critics"):
        train_tqc("reach", "sparse", cfg, tmp_path / "run", progress=False)
    assert not (tmp_path / "run").exists()


def test_too_few_warm_up_steps_for_the_envs_are_refused(tmp_path):
    cfg = load_tqc_config("cpu", "reach").with_budget(learning_starts=100, n_envs=8)
    with pytest.raises(GcdtError, match="learning_starts \\(100\\) must be at least n_envs x"):
        train_tqc("reach", "sparse", cfg, tmp_path / "run", progress=False)
    assert not (tmp_path / "run").exists()


def _weights(policy):
    """A TQC actor's weights as numpy arrays, whichever backend trained it."""
    if hasattr(policy, "actor_state"):  # SBX: a pytree of JAX arrays
        import jax

        return [np.asarray(w) for w in jax.tree_util.tree_leaves(policy.actor_state.params)]
    return [w.numpy() for w in policy.state_dict().values()]


@pytest.mark.parametrize(("backend", "n_envs"), [("sbx", 4), ("sb3", 1)])
def test_training_is_reproducible(tmp_path, backend, n_envs):
    cfg = load_tqc_config("cpu", "reach").with_budget(
        steps=320, learning_starts=200, batch_size=16, net_arch=[16], backend=backend, n_envs=n_envs
    )
    weights = []
    for run in ("a", "b"):
        result = train_tqc(
            "reach",
            "dense",
            cfg,
            tmp_path / run,
            seed=3,
            eval_every=320,
            eval_episodes=1,
            progress=False,
        )
        weights.append(_weights(make_policy(f"tqc:{result.model}", "reach").sb3_policy))
    assert len(weights[0]) >= 4
    assert all(np.array_equal(a, b) for a, b in zip(*weights, strict=True))


PUBLISHED_PUSH = "results/experts/tqc_push_sparse/model.zip"


def test_the_published_push_expert_reaches_goals_and_can_collect_a_grids_data(tmp_path):
    """The TQC+HER Push agent kept in the repository (trained with the fast loop, see its
    run.json) succeeds on held-out episodes, and a profile can make it Push's expert."""
    from gcdt.experiments.artifacts import collecting_policy
    from gcdt.experiments.grid import data_spec
    from gcdt.experiments.profiles import SMOKE
    from gcdt.paths import REPO_ROOT

    path = REPO_ROOT / PUBLISHED_PUSH
    assert path.stat().st_size < 5 * 2**20  # small enough to keep in git
    result = evaluate(make_policy(f"tqc:{path}", "push"), "push", "sparse", episodes=40, seed=9)
    # Held out (the evaluation stream); its run.json's `published` record has 500 such episodes.
    assert result.summary["success_rate"] >= 0.9
    profile = dataclasses.replace(SMOKE, expert_agents={"push": PUBLISHED_PUSH})
    spec = data_spec(profile, "push", profile.dataset_size, 1.0)
    assert spec.expert == f"tqc:{PUBLISHED_PUSH}" and spec.expert_noise == 0.0
    assert spec.key() != data_spec(SMOKE, "push", SMOKE.dataset_size, 1.0).key()
    policy, reward = collecting_policy(spec)
    assert policy.name == "tqc" and reward == "sparse"
    with pytest.raises(GcdtError, match="changed since this grid was planned"):
        collecting_policy(dataclasses.replace(spec, expert_digest="0" * 16))
    # An agent not published (yet) is never stood in for: its data waits, and is not made.
    waiting = data_spec(dataclasses.replace(SMOKE, expert_agents={"push": "nope.zip"}), "push",
                        10, 1.0)  # fmt: skip
    assert waiting.waits_for == "nope.zip" and waiting.key() != spec.key()
    with pytest.raises(GcdtError, match=r"nope\.zip is not published yet"):
        collecting_policy(waiting)


def test_keep_lowest_keeps_what_a_sort_keeps_ties_included():
    import jax.numpy as jnp

    from gcdt.baselines.sbx_tqc import keep_lowest

    rng = np.random.default_rng(0)
    values = rng.integers(0, 6, size=(200, 50)).astype(np.float32)  # many ties
    keep = np.asarray(keep_lowest(jnp.asarray(values), 46))
    assert keep.shape == values.shape
    assert (keep.sum(axis=1) == 46).all()
    kept = np.sort(np.where(keep, values, np.inf), axis=1)[:, :46]
    np.testing.assert_array_equal(kept, np.sort(values, axis=1)[:, :46])


def test_sbx_backend_critic_update_is_sbx_s_own():
    """The sort-free critic update: SBX's losses, and its new parameters up to float rounding."""
    import jax
    import jax.numpy as jnp
    from sbx import TQC as SbxTQC

    from gcdt.baselines.tqc_her import build_tqc

    cfg = load_tqc_config("cpu", "push").with_budget(net_arch=[32, 32], n_envs=1)
    model = build_tqc(cfg, "push", "sparse", seed=0, device="auto")
    assert isinstance(model, SbxTQC) and type(model) is not SbxTQC
    rng = np.random.default_rng(1)
    batch, obs_dim = 64, sum(s.shape[0] for s in model.observation_space.spaces.values())
    p = model.policy
    args = (
        p.n_target_quantiles,
        p.actor_state,
        p.qf1_state,
        p.qf2_state,
        model.ent_coef_state,
        jnp.asarray(rng.normal(size=(batch, obs_dim)), dtype=jnp.float32),
        jnp.asarray(rng.uniform(-1, 1, size=(batch, *model.action_space.shape)), dtype=jnp.float32),
        jnp.asarray(rng.normal(size=(batch, obs_dim)), dtype=jnp.float32),
        jnp.asarray(-1.0 * (rng.random(batch) < 0.8), dtype=jnp.float32),  # sparse rewards
        jnp.zeros(batch),
        jnp.full(batch, cfg.gamma),
        jax.random.PRNGKey(7),
    )
    (ref_q1, ref_q2), ref_values, ref_key = SbxTQC.update_critic(*args)
    (new_q1, new_q2), new_values, new_key = type(model).update_critic(*args)
    np.testing.assert_allclose(np.asarray(new_values), np.asarray(ref_values), rtol=1e-6)
    assert np.array_equal(np.asarray(new_key), np.asarray(ref_key))
    moved = 0.0
    for ref, new, old in zip(
        jax.tree_util.tree_leaves((ref_q1.params, ref_q2.params)),
        jax.tree_util.tree_leaves((new_q1.params, new_q2.params)),
        jax.tree_util.tree_leaves((p.qf1_state.params, p.qf2_state.params)),
        strict=True,
    ):
        np.testing.assert_allclose(np.asarray(new), np.asarray(ref), rtol=1e-5, atol=1e-7)
        moved = max(moved, float(jnp.abs(new - old).max()))
    model.get_env().close()
    assert moved > 1e-4  # the update did change the critics


# --------------------------------------------------------------------------------------------
# Checkpoints and resume


def _reach_argv(out, *extra):
    return [
        "tqc", "train", "--task", "reach", "--reward", "sparse", "--config", "cpu",
        "--steps", "1600", "--eval-every", "800", "--eval-episodes", "2", "--n-envs", "2",
        "--out", str(out), "--no-progress", "--checkpoint-seconds", "0", *extra,
    ]  # fmt: skip


@pytest.fixture(scope="module")
def checkpointed(tmp_path_factory):
    """A run SIGKILLed mid-learning, its checkpoint on disk."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from gcdt.baselines.tqc_checkpoint import CHECKPOINT_FILE, read_header

    out = tmp_path_factory.mktemp("ckpt") / "run"
    argv = [sys.executable, "-m", "gcdt", *_reach_argv(out)]
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    ckpt = out / CHECKPOINT_FILE
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline and proc.poll() is None:
        if ckpt.exists() and read_header(ckpt)["env_steps"] > 1100:  # learning has begun
            break
        time.sleep(0.2)
    assert proc.poll() is None, proc.stderr.read().decode()
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    return out


def _all_weights(zip_path) -> list[np.ndarray]:
    """Every array of an SBX TQC zip's actor and critics (their targets included)."""
    from sbx import TQC

    env = make_env("reach", "sparse")
    try:
        return _policy_weights(TQC.load(zip_path, env=env).policy)
    finally:
        env.close()


def _policy_weights(policy) -> list[np.ndarray]:
    import jax

    states = [policy.actor_state.params, policy.qf1_state.params, policy.qf2_state.params]
    states += [policy.qf1_state.target_params, policy.qf2_state.target_params]
    return [np.asarray(leaf) for leaf in jax.tree_util.tree_leaves(states)]


def _add_to_clock(path, seconds):
    """Rewrite checkpoint `path` as if its run had taken `seconds` more wall and CPU time
    before it (the learning-speed mark moves with the clock: the rate since it is unchanged)."""
    from gcdt.baselines.tqc_checkpoint import _read, _write

    header, payload = _read(path, payload=True)
    extra = payload["extra"]
    extra["clock"] = {k: v + seconds for k, v in extra["clock"].items()}
    step, wall, eval_seconds = extra["evaluation"]["learning_mark"]
    extra["evaluation"]["learning_mark"] = (step, wall + seconds, eval_seconds)
    _write(path, header, payload)
    return extra["clock"]


def test_a_killed_run_resumes_and_finishes_as_one_run(checkpointed, tmp_path):
    """`--resume` after SIGKILL: the run ends with the full budget, one curve point per
    evaluation mark, no checkpoint left behind, the weights of the same run left alone (on
    the same machine), and run.json's times and core-hours over the whole run."""
    from gcdt.baselines.tqc_checkpoint import CHECKPOINT_FILE, read_header

    out = tmp_path / "run"
    shutil.copytree(checkpointed, out)
    assert 1000 < read_header(out / CHECKPOINT_FILE)["env_steps"] < 1600
    # A day before the kill: far more than the resumed part can take, so a record of the
    # last invocation alone would show.
    day = 86_400.0
    before = _add_to_clock(out / CHECKPOINT_FILE, day)
    # Checkpoints every loop iteration were for the kill: from here on, none is needed, and
    # the uninterrupted run writing none shows that writing them changes nothing.
    rarely = ("--checkpoint-seconds", "3600")
    assert main(_reach_argv(out, "--resume", *rarely)) == 0
    assert main(_reach_argv(tmp_path / "uninterrupted", *rarely)) == 0
    resumed = _all_weights(out / "model.zip")
    whole = _all_weights(tmp_path / "uninterrupted/model.zip")
    assert len(resumed) == len(whole) > 0
    for ours, theirs in zip(resumed, whole, strict=True):
        np.testing.assert_array_equal(ours, theirs)
    record = json.loads((out / "run.json").read_text())
    assert record["env_steps"] == 1600 and record["resumes"] == 1
    assert "--resume" not in record["command"]  # the command that started the run
    with open(out / "eval.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["env_steps"]) for r in rows] == [800, 1600]
    assert float(rows[0]["wall_seconds"]) < day < float(rows[1]["wall_seconds"])
    assert not (out / CHECKPOINT_FILE).exists()
    # The times cover the whole run: what the checkpoint carried and the resumed part.
    assert record["wall_seconds"] >= before["wall"]
    assert record["core_hours"] >= before["cpu"] / 3600 - 0.001  # rounded to 3.6 s
    assert record["train_seconds"] == pytest.approx(
        record["wall_seconds"] - record["eval_seconds"], abs=0.02
    )
    rate = 1600 / record["train_seconds"]
    assert record["env_steps_per_second"] == pytest.approx(rate, abs=0.005)  # 2 decimals
    # The learning speed counts from its mark, which moved with the clock: counted from the
    # day before, it would be under 1,600 steps a day.
    assert record["learning_steps_per_second"] > 1600 / day


def test_a_snapshot_resumes_on_a_fresh_folder_and_refills_its_buffer(
    checkpointed, tmp_path, capsys
):
    """`gcdt tqc snapshot`: the checkpoint without its buffer (a fraction of its size) and the
    curve; a fresh folder resumes from it, records the refill, and takes no gradient step
    before `learning_starts` new random steps have refilled the buffer."""
    from gcdt.baselines.tqc_checkpoint import CHECKPOINT_FILE, has_buffer, read_header

    snap = tmp_path / "snap"
    assert main(["tqc", "snapshot", str(checkpointed), "--out", str(snap)]) == 0
    full, kept = read_header(checkpointed / CHECKPOINT_FILE), read_header(snap / CHECKPOINT_FILE)
    steps = kept["env_steps"]
    assert f"at {steps:,} env steps" in capsys.readouterr().out
    assert has_buffer(full) and not has_buffer(kept) and steps == full["env_steps"]
    assert (snap / CHECKPOINT_FILE).stat().st_size < (checkpointed / CHECKPOINT_FILE).stat().st_size
    assert sorted(p.name for p in snap.iterdir()) == ["checkpoint.tqc", "eval.csv"]
    # Another machine: only the snapshot's files in the run's folder.
    out = tmp_path / "elsewhere"
    shutil.copytree(snap, out)
    assert main(_reach_argv(out, "--resume", "--checkpoint-seconds", "3600")) == 0
    record = json.loads((out / "run.json").read_text())
    assert record["env_steps"] == 1600 and record["buffer_refills"] == [steps]
    # The best model stayed behind: it is found again after the resume, zip and record alike.
    assert record["best"]["env_steps"] == 1600 and (out / "best_model.zip").is_file()
    # 1000 warm-up steps from `steps` (> 1100) pass the 1,600-step budget: no gradient step
    # after the resume, so the final weights are the snapshot's.
    from gcdt.baselines.tqc_checkpoint import _read

    saved = _read(snap / CHECKPOINT_FILE, payload=True)[1]["model"].policy
    final, at_snapshot = _all_weights(out / "model.zip"), _policy_weights(saved)
    for ours, theirs in zip(final, at_snapshot, strict=True):
        np.testing.assert_array_equal(ours, theirs)


@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("no checkpoint", "holds no TQC+HER checkpoint: snapshot a run in progress"),
        ("run folder", "is a run's folder, not a snapshot"),
        ("other run", "a checkpoint of reward 'dense', not 'sparse'"),
        ("later snapshot", "holds a later snapshot of this run"),
        ("not a snapshot", "exists and is not a run's snapshot"),
    ],
)
def test_tqc_snapshot_refuses_bad_input_in_one_line(
    assert_usage_error, checkpointed, tmp_path, case, message
):
    from gcdt.baselines.tqc_checkpoint import CHECKPOINT_FILE, _read, _write, strip_buffer

    run, out = checkpointed, tmp_path / "snap"
    if case == "no checkpoint":
        run = tmp_path / "empty"
        run.mkdir()
    elif case == "run folder":
        shutil.copytree(checkpointed, out)
    elif case == "not a snapshot":
        out.mkdir()
        (out / "notes.txt").write_text("mine")
    else:  # a snapshot already there, of another run or further on
        out.mkdir()
        strip_buffer(checkpointed / CHECKPOINT_FILE, out / CHECKPOINT_FILE)
        header, payload = _read(out / CHECKPOINT_FILE, payload=True)
        if case == "other run":
            header["reward"] = "dense"
        else:
            header["env_steps"] += 8
        _write(out / CHECKPOINT_FILE, header, payload)
    before = _unchanged(out) if out.exists() else None
    assert_usage_error(["tqc", "snapshot", str(run), "--out", str(out)], message)
    assert (_unchanged(out) if out.exists() else None) == before
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # nothing staged


def test_resume_without_a_checkpoint_is_one_line_exit_2(assert_usage_error, tmp_path):
    argv = ["tqc", "train", "--task", "reach", "--reward", "sparse", "--out", str(tmp_path)]
    assert_usage_error([*argv, "--resume"], "no TQC+HER checkpoint at")
    assert list(tmp_path.iterdir()) == []


def _unchanged(out):
    return {p.name: (p.stat().st_mtime_ns, p.stat().st_size) for p in out.iterdir()}


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--task", "push"], "a checkpoint of task 'reach', not 'push'"),
        (["--reward", "dense"], "a checkpoint of reward 'sparse', not 'dense'"),
        (["--config", "paper"], "a checkpoint of config"),
        (["--backend", "sb3"], "a checkpoint of backend 'sbx', not 'sb3'"),
    ],
)
def test_a_checkpoint_of_another_run_is_refused(assert_usage_error, checkpointed, extra, message):
    base = {"--task": "reach", "--reward": "sparse"}
    base.update(dict(zip(extra[::2], extra[1::2], strict=True)))
    argv = ["tqc", "train", *[x for kv in base.items() for x in kv], "--out", str(checkpointed)]
    before = _unchanged(checkpointed)
    assert_usage_error([*argv, "--resume"], message)
    assert _unchanged(checkpointed) == before


def test_a_truncated_checkpoint_is_refused(assert_usage_error, checkpointed, tmp_path):
    from gcdt.baselines.tqc_checkpoint import CHECKPOINT_FILE

    out = tmp_path / "run"
    shutil.copytree(checkpointed, out)
    data = (out / CHECKPOINT_FILE).read_bytes()
    (out / CHECKPOINT_FILE).write_bytes(data[: len(data) // 2])
    before = _unchanged(out)
    argv = ["tqc", "train", "--task", "reach", "--reward", "sparse", "--out", str(out)]
    assert_usage_error([*argv, "--resume"], "is truncated or not a TQC+HER checkpoint")
    assert _unchanged(out) == before


def test_a_folder_with_a_checkpoint_is_not_started_over(assert_usage_error, checkpointed):
    argv = ["tqc", "train", "--task", "reach", "--reward", "sparse", "--out", str(checkpointed)]
    before = _unchanged(checkpointed)
    assert_usage_error(argv, "resume it with --resume")
    assert _unchanged(checkpointed) == before


def test_an_env_restored_by_replay_starts_its_episode_exactly():
    """The reset state is rebuilt bit for bit (later steps can differ slightly where PyBullet
    carries state over from earlier episodes: `gcdt/baselines/tqc_checkpoint.py`)."""
    from gcdt.envs import SeededResets

    a = SeededResets(make_env("push", "sparse"), 0)
    rng = np.random.default_rng(0)
    for _ in range(3):
        a.reset()
        for _ in range(5):
            a.step(rng.uniform(-1, 1, a.action_space.shape).astype(np.float32))
    a.reset()
    b = SeededResets(make_env("push", "sparse"), 0)
    b.restore_replay_state(a.replay_state())
    assert b.episodes == a.episodes
    assert all(np.array_equal(a.last_obs[k], b.last_obs[k]) for k in a.last_obs)


def test_publish_picks_on_validation_and_measures_held_out_episodes(push_run, tmp_path):
    from gcdt.baselines.publish import (
        HELD_OUT_SEED,
        VALIDATION_SEED,
        PublishConfig,
        publish_agent,
    )

    out = publish_agent(push_run.out_dir, tmp_path / "agent", PublishConfig(3, 4))
    assert sorted(p.name for p in out.iterdir()) == ["eval.csv", "model.zip", "run.json"]
    record = json.loads((out / "run.json").read_text())
    published = record["published"]
    assert published["model"] in ("final", "best")
    assert {v["seed"] for v in published["validation"].values()} == {VALIDATION_SEED}
    assert [v["episodes"] for v in published["validation"].values()] == [3, 3]
    assert published["held_out"]["seed"] == HELD_OUT_SEED
    assert published["held_out"]["episodes"] == 4
    assert [p["env_steps"] for p in record["curve"]] == [160, 320]
    chosen = push_run.out_dir / ("model.zip" if published["model"] == "final" else "best_model.zip")
    assert (out / "model.zip").read_bytes() == chosen.read_bytes()
    # The agent loads as a policy, and a second publication into the same folder is refused.
    assert make_policy(f"tqc:{out / 'model.zip'}", "push").name == "tqc"
    with pytest.raises(GcdtError, match="already holds a published agent"):
        publish_agent(push_run.out_dir, out, PublishConfig(3, 4))


def test_publish_refuses_an_unfinished_run(checkpointed, tmp_path):
    from gcdt.baselines.publish import publish_agent

    with pytest.raises(GcdtError, match="unfinished TQC\\+HER run: finish it with --resume"):
        publish_agent(checkpointed, tmp_path / "agent")
    assert not (tmp_path / "agent").exists()


def _fake_finished_run(folder, task="push", reward="sparse"):
    """A folder with a finished run's files (the models are not zips: every refusal below
    comes before anything is measured)."""
    folder.mkdir(parents=True)
    record = {"task": task, "reward": reward, "seed": 0, "env_steps": 1000}
    (folder / "run.json").write_text(json.dumps(record))
    for name in ("eval.csv", "model.zip", "best_model.zip"):
        (folder / name).write_text("x")
    return folder


def _fake_agent(folder, task="push", reward="sparse", seed=0):
    folder.mkdir(parents=True)
    record = {"task": task, "reward": reward, "seed": seed, "old": True}
    (folder / "run.json").write_text(json.dumps(record))
    (folder / "model.zip").write_text("the old agent")
    return _unchanged(folder)


@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("missing", "no run folder at"),
        ("unfinished", "unfinished TQC+HER run: finish it with --resume"),
        ("no seed", "lacks seed: not a gcdt tqc train run's record"),
        ("taken", "already holds a published agent: pass --replace to replace it"),
        ("other task", "holds a reach/sparse agent of seed 0, not push/sparse of seed 0"),
        ("other seed", "holds a push/sparse agent of seed 1, not push/sparse of seed 0"),
        ("not an agent", "is not a published agent's folder"),
    ],
)
def test_tqc_publish_refuses_bad_input_in_one_line(assert_usage_error, tmp_path, case, message):
    run, out = tmp_path / "run", tmp_path / "experts" / "tqc_push_sparse"
    argv = ["tqc", "publish", str(run), "--out", str(out)]
    if case != "missing":
        _fake_finished_run(run)
    if case == "unfinished":  # killed before its end: a checkpoint, no run.json
        (run / "run.json").unlink()
        (run / "checkpoint.tqc").write_text("x")
    if case == "no seed":  # published as seed 0's expert, were a missing seed taken as 0
        record = json.loads((run / "run.json").read_text())
        (run / "run.json").write_text(json.dumps({k: v for k, v in record.items() if k != "seed"}))
    if case in ("taken", "other task", "other seed"):
        task, seed = ("reach" if case == "other task" else "push"), int(case == "other seed")
        before = _fake_agent(out, task=task, seed=seed)
    if case == "not an agent":
        out.mkdir(parents=True)
        (out / "notes.txt").write_text("mine")
        before = _unchanged(out)
    replace = ["--replace"] if case in ("other task", "other seed", "not an agent") else []
    assert_usage_error([*argv, *replace], message)
    if case in ("taken", "other task", "other seed", "not an agent"):
        assert _unchanged(out) == before  # nothing overwritten
        assert [p.name for p in out.parent.iterdir()] == [out.name]  # nothing staged
    else:
        assert not out.parent.exists()


def test_tqc_publish_replace_swaps_the_old_agent_for_the_new_one_whole(
    push_run, tmp_path, capsys, monkeypatch
):
    out = tmp_path / "experts" / "tqc_push_sparse"
    _fake_agent(out)
    argv = ["tqc", "publish", str(push_run.out_dir), "--out", str(out), "--replace"]
    argv += ["--validation-episodes", "2", "--held-out-episodes", "3"]
    # A publication that fails while measuring leaves the old agent as it was.
    import gcdt.baselines.publish as publish

    # The run's snapshot beside the agents goes once the run is published, not before.
    seed = json.loads((push_run.out_dir / "run.json").read_text())["seed"]
    snapshot = out.parent / "in_progress" / f"tqc_push_sparse_seed{seed}"
    snapshot.mkdir(parents=True)
    (snapshot / "checkpoint.tqc").write_text("x")
    # So does a candidate config's, named after the run's folder, when its header is this
    # run's; one of another config under that name would stay.
    from gcdt.baselines.tqc_checkpoint import _write

    run_record = json.loads((push_run.out_dir / "run.json").read_text())
    candidate = out.parent / "in_progress" / f"tqc_{push_run.out_dir.name}"
    candidate.mkdir()
    header = {"task": "push", "reward": "sparse", "seed": seed, "env_steps": 8}
    header["config"] = {"name": "elsewhere"}
    _write(candidate / "checkpoint.tqc", header, {})
    assert publish._snapshot_of(candidate) == ("push", "sparse", seed, "elsewhere")
    header["config"] = {"name": run_record["config"]["name"]}
    _write(candidate / "checkpoint.tqc", header, {})
    before = _unchanged(out)
    with monkeypatch.context() as m:
        m.setattr(publish, "_measure", lambda *a, **k: 1 / 0)
        with pytest.raises(ZeroDivisionError):
            main(argv)
    assert _unchanged(out) == before and snapshot.exists() and candidate.exists()
    assert main(argv) == 0
    assert not snapshot.exists() and not candidate.exists()
    assert f"on 3 held-out episodes: {out}" in capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == ["eval.csv", "model.zip", "run.json"]
    record = json.loads((out / "run.json").read_text())
    assert "old" not in record and record["published"]["held_out"]["episodes"] == 3
    # The run's accounting travels with the agent.
    run = json.loads((push_run.out_dir / "run.json").read_text())
    keys = ("env_steps", "train_seconds", "wall_seconds", "env_steps_per_second", "core_hours")
    assert {k: record[k] for k in (*keys, "resumes")} == {k: run[k] for k in (*keys, "resumes")}
    assert [p.name for p in out.parent.iterdir()] == [out.name]  # the old one is gone

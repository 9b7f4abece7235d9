"""gcdt.training and trained policies: sampler, resume, checkpoints, and policies that work."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time

import numpy as np
import pytest
import torch

from gcdt.checkpoint import load_checkpoint
from gcdt.cli import main
from gcdt.errors import GcdtError
from gcdt.evaluation import evaluate
from gcdt.methods import OFFLINE_METHODS, method_label
from gcdt.policies import make_policy
from gcdt.policies.trained import TrainedPolicy
from gcdt.training import TrainConfig, WindowSampler, train

FAST = {"log_every": 10, "checkpoint_every": 10}


def test_window_sampler_cuts_left_padded_windows(make_dataset):
    ds = make_dataset("reach", lengths=(3, 8, 2, 5))
    cfg = TrainConfig(steps=1, context=4, batch_size=256)
    mean, std = np.zeros(12, np.float32), np.ones(12, np.float32)
    batch = WindowSampler(ds, cfg, mean, std, torch.device("cpu")).sample(np.random.default_rng(0))
    rtg = ds.returns_to_go("sparse") / 100
    for i in range(256):
        mask = batch["mask"][i].numpy()
        n = int(mask.sum())
        assert mask.tolist() == [False] * (4 - n) + [True] * n  # left padding only
        # The real tokens are consecutive rows of one episode, in order.
        rows = [
            int(np.flatnonzero((ds.states == s.numpy()).all(1))[0])
            for s in batch["states"][i][mask]
        ]
        assert rows == list(range(rows[0], rows[0] + n))
        assert len(set(ds.episode_index[rows])) == 1
        np.testing.assert_allclose(batch["returns_to_go"][i, mask, 0].numpy(), rtg[rows], rtol=1e-6)
        np.testing.assert_array_equal(batch["timesteps"][i, mask].numpy(), ds.timesteps[rows])
        # A window is cut short only by its episode's end.
        end = ds.offsets[ds.episode_index[rows[0]] + 1]
        assert n == 4 or rows[-1] == end - 1
        assert (batch["states"][i][~mask] == 0).all()


def test_resumed_run_equals_uninterrupted(make_dataset, tmp_path):
    ds = make_dataset("push", lengths=(20, 30, 25))
    cfg = TrainConfig(steps=30, context=5, **FAST)
    full = train(ds, cfg, tmp_path / "full", progress=False)
    part = train(ds, cfg, tmp_path / "split", stop_after=13, progress=False)
    assert part.steps == 13 and not load_checkpoint(part.checkpoint)["complete"]
    resumed = train(ds, cfg, tmp_path / "split", resume=True, progress=False)
    # The resumed call paid for the steps after the checkpoint only (what a rate divides by).
    assert resumed.steps == 30 and (full.resumed_from, resumed.resumed_from) == (0, 13)
    a, b = load_checkpoint(full.checkpoint), load_checkpoint(resumed.checkpoint)
    assert a["complete"] and b["complete"]
    for key in a["model"]:
        torch.testing.assert_close(a["model"][key], b["model"][key], rtol=0, atol=0, msg=key)
    assert [h["loss"] for h in a["history"]] == [h["loss"] for h in b["history"]]
    assert (tmp_path / "full" / "train_log.csv").read_text().count("\n") == 4  # header + 3 rows

    with pytest.raises(GcdtError, match="already holds a checkpoint: resume it"):
        train(ds, cfg, tmp_path / "full", progress=False)
    with pytest.raises(GcdtError, match="another config or task: cannot resume"):
        train(ds, TrainConfig(steps=31, context=5, **FAST), tmp_path / "full", resume=True)


def test_killed_cli_run_resumes_to_the_uninterrupted_weights(make_dataset, tmp_path):
    """`gcdt train` checkpoints by the clock too, with its log; SIGKILLed, it resumes to the
    very weights of a run that was never interrupted."""
    data = make_dataset("reach", lengths=(12, 9, 12)).save(tmp_path / "d.npz")
    steps = 400  # about 3 s of training; a checkpoint every 0.2 s
    # One thread each: two runs side by side on a small machine, same arithmetic in both.
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    procs = []

    def gcdt_train(out, *extra):
        argv = [
            "train",
            "--dataset",
            str(data),
            "--out",
            str(tmp_path / out),
            "--steps",
            str(steps),
            "--context",
            "2",
            "--batch-size",
            "4",
            "--device",
            "cpu",
            "--checkpoint-seconds",
            "0.2",
            "--no-progress",
            *extra,
        ]
        procs.append(
            subprocess.Popen(
                [sys.executable, "-m", "gcdt", *argv],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
            )
        )
        return procs[-1]

    full, killed = gcdt_train("full"), gcdt_train("split")
    try:
        ckpt_path = tmp_path / "split" / "checkpoint.pt"
        deadline = time.monotonic() + 60
        while not ckpt_path.exists() and killed.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        killed.kill()  # SIGKILL: no handler, no final save
        killed.wait()
        assert ckpt_path.exists(), killed.stderr.read()
        ckpt = load_checkpoint(ckpt_path)
        assert 0 < ckpt["step"] < steps and not ckpt["complete"]
        assert (tmp_path / "split" / "train_log.csv").is_file()
        resumed = gcdt_train("split", "--resume")
        assert resumed.wait(timeout=120) == 0, resumed.stderr.read()
        assert full.wait(timeout=120) == 0, full.stderr.read()
    finally:
        for proc in procs:
            proc.kill()
            proc.wait()
    a = load_checkpoint(tmp_path / "full" / "checkpoint.pt")
    b = load_checkpoint(tmp_path / "split" / "checkpoint.pt")
    assert a["complete"] and b["complete"] and a["step"] == b["step"] == steps
    assert a["model"].keys() == b["model"].keys()
    for key, tensor in a["model"].items():
        assert torch.equal(tensor, b["model"][key]), key
    log = (tmp_path / "split" / "train_log.csv").read_text().splitlines()
    assert len(log) == 1 + steps // 50 and log[-1].startswith(f"{steps},")


def test_resume_ignores_the_checkpoint_schedule(make_dataset, tmp_path):
    ds = make_dataset("reach", lengths=(10, 10))
    train(ds, TrainConfig(method="bc", steps=20, **FAST), tmp_path, stop_after=5, progress=False)
    other = TrainConfig(
        method="bc", steps=20, log_every=10, checkpoint_every=7, checkpoint_seconds=0.5
    )
    assert train(ds, other, tmp_path, resume=True, progress=False).steps == 20
    with pytest.raises(GcdtError, match="checkpoint_seconds must be > 0, got 0"):
        TrainConfig(checkpoint_seconds=0)
    with pytest.raises(GcdtError, match="checkpoint_seconds must be > 0, got nan"):
        TrainConfig(checkpoint_seconds=float("nan"))


def test_nan_loss_stops_and_keeps_last_good_checkpoint(make_dataset, tmp_path, monkeypatch):
    import gcdt.training as training

    ds = make_dataset("reach", lengths=(10, 10))
    real_loss, calls = training._loss, {"n": 0}

    def loss_turning_nan(*args):
        calls["n"] += 1
        loss = real_loss(*args)
        return loss * float("nan") if calls["n"] > 12 else loss

    monkeypatch.setattr(training, "_loss", loss_turning_nan)
    with pytest.raises(GcdtError, match="loss became nan at step 12: stopped; the last good"):
        train(ds, TrainConfig(method="bc", steps=50, **FAST), tmp_path, progress=False)
    ckpt = load_checkpoint(tmp_path / "checkpoint.pt")
    assert ckpt["step"] == 10 and all(torch.isfinite(v).all() for v in ckpt["model"].values())


def test_bad_checkpoints_and_configs(make_dataset, tmp_path):
    ds = make_dataset("reach", lengths=(6, 6))
    result = train(ds, TrainConfig(method="bc", steps=3), tmp_path / "bc", progress=False)
    with pytest.raises(GcdtError, match="is for task 'reach', not 'push'"):
        make_policy(str(result.checkpoint), "push")
    broken = tmp_path / "broken.pt"
    broken.write_bytes(result.checkpoint.read_bytes()[:1000])
    with pytest.raises(GcdtError, match="not a readable gcdt checkpoint"):
        make_policy(str(broken), "reach")
    ckpt = load_checkpoint(result.checkpoint)
    ckpt["model_config"] = {**ckpt["model_config"], "hidden": 64}  # weights are 128 wide
    torch.save(ckpt, tmp_path / "mismatch.pt")
    with pytest.raises(GcdtError, match="does not fit its model config"):
        make_policy(str(tmp_path / "mismatch.pt"), "reach")
    torch.save({"weights": torch.zeros(2)}, tmp_path / "other.pt")
    with pytest.raises(GcdtError, match="is not a gcdt checkpoint"):
        make_policy(str(tmp_path / "other.pt"), "reach")
    with pytest.raises(GcdtError, match="one budget, steps or epochs, not both"):
        TrainConfig(steps=10, epochs=2)
    with pytest.raises(GcdtError, match="context must be a positive integer"):
        TrainConfig(steps=10, context=0)
    with pytest.raises(GcdtError, match="unknown method 'cql'"):
        TrainConfig(method="cql", steps=1)
    with pytest.raises(GcdtError, match=r"lr must be > 0, got 0\.0"):
        TrainConfig(steps=1, lr=0.0)
    with pytest.raises(GcdtError, match="is BC, which takes no target return"):
        make_policy(str(result.checkpoint), "reach", target_return=-5.0)
    with pytest.raises(GcdtError, match=r"target return must be a finite number .* got nan"):
        make_policy(str(result.checkpoint), "reach", target_return=float("nan"))
    # The authors' epochs: ceil(#episodes / batch) steps each.
    assert TrainConfig(epochs=3, batch_size=64).total_steps(130) == 9


def _reaches_goals(checkpoint, method: str, steps: int) -> None:
    policy = TrainedPolicy(checkpoint, "reach")
    outcome = evaluate(policy, "reach", "sparse", episodes=60, n_envs=1, seed=12345, progress=False)
    assert outcome.summary["success_rate"] >= 0.9, outcome.summary
    assert policy.config()["method"] == method and policy.config()["trained_steps"] == steps


@pytest.mark.slow
def test_trained_gcdt_reaches_goals(reach_gcdt):
    """400 steps at K = 5 (4x cheaper steps) on scripted Reach expert data reach >= 90 % on
    fresh seeds (the shared `reach_gcdt` checkpoint)."""
    _reaches_goals(reach_gcdt.checkpoint, "dt", 400)


@pytest.mark.slow
def test_trained_bc_reaches_goals(reach_expert_data, tmp_path):
    """BC at the grid's equal-sample budget: a DT sample holds K = 5 states, a BC sample one
    (at 400 steps BC scores ~80 % on the experts' 2.7-step episodes)."""
    cfg = TrainConfig(method="bc", steps=400 * 5, context=5, **FAST)
    _reaches_goals(train(reach_expert_data, cfg, tmp_path, progress=False).checkpoint, "bc", 2000)


def test_checkpoint_policy_matches_model_and_cli(reach_expert_data, tmp_path, capsys):
    """A checkpoint alone rebuilds the policy: the CLI trains one and evaluates it."""
    data_path = reach_expert_data.save(tmp_path / "reach.npz")
    out = tmp_path / "run"
    argv = [
        "train",
        "--dataset",
        str(data_path),
        "--out",
        str(out),
        "--steps",
        "20",
        "--context",
        "5",
        "--no-progress",
    ]
    assert main(argv) == 0
    ckpt = load_checkpoint(out / "checkpoint.pt")
    assert ckpt["train_config"]["goal_conditioning"] == "desired+achieved"
    ckpt_arg = ["--policy", str(out / "checkpoint.pt"), "--task", "reach", "--reward", "sparse"]
    assert main(["evaluate", *ckpt_arg, "--episodes", "3", "--json", "--no-progress"]) == 0
    assert '"policy": "gcdt"' in capsys.readouterr().out
    assert main(["evaluate", *ckpt_arg, "--episodes", "1", "--device", "tpu"]) == 2
    assert "unknown device 'tpu': use auto, cpu, cuda or cuda:N" in capsys.readouterr().err

    # Batched rollouts equal one-env rollouts: the per-env context is really per env.
    policy = TrainedPolicy(out / "checkpoint.pt")
    one = evaluate(policy, "reach", "sparse", episodes=4, n_envs=1, seed=3, progress=False)
    obs = {
        "observation": np.zeros((2, 6), np.float32),
        "desired_goal": np.ones((2, 3), np.float32),
        "achieved_goal": np.zeros((2, 3), np.float32),
    }
    policy.reset(2, 0)
    first = policy.predict(obs, np.array([True, True]), np.zeros(2))
    np.testing.assert_allclose(first[0], first[1], rtol=0, atol=1e-6)
    assert one.summary["episodes"] == 4


def test_a_trained_policy_is_named_as_the_grid_names_its_method():
    """One mapping, read both ways: each offline method's trainer method and goal conditioning
    give a policy of that name; BC is `bc` whatever its states hold."""
    for name, (method, conditioning) in OFFLINE_METHODS.items():
        assert method_label(method, conditioning) == name
    assert method_label("bc", "none") == method_label("bc", "desired") == "bc"


def test_policy_predicts_what_the_full_model_predicts(make_dataset, tmp_path):
    """Acting computes only the newest state token and skips padding common to all envs;
    the actions must equal the full model's on the same context, envs out of step too."""
    result = train(
        make_dataset("reach", (12, 9, 12)),
        TrainConfig(steps=3, context=5, **FAST),
        tmp_path,
        progress=False,
    )
    policy = TrainedPolicy(result.checkpoint)
    policy.reset(2, 0)
    rng = np.random.default_rng(0)
    widths = {"observation": 6, "desired_goal": 3, "achieved_goal": 3}
    for t in range(9):
        obs = {k: rng.normal(size=(2, n)).astype(np.float32) for k, n in widths.items()}
        start = np.array([t == 0, t in (0, 3)])  # env 1 starts a new episode at t = 3
        action = policy.predict(obs, start, rng.normal(size=2).astype(np.float32))
        with torch.no_grad():  # a_K, filled in by predict, is invisible to s_K (causal)
            p = policy
            full = p.model(p.states, p.actions, p.rtg, p.timesteps, p.mask, attention=[])
        np.testing.assert_allclose(action, full[:, -1].numpy(), rtol=0, atol=1e-5)


def test_cli_train_refuses_other_task(make_dataset, tmp_path, capsys):
    path = make_dataset("push").save(tmp_path / "push.npz")
    code = main(
        [
            "train",
            "--dataset",
            str(path),
            "--task",
            "reach",
            "--out",
            str(tmp_path / "o"),
            "--steps",
            "2",
        ]
    )
    assert code == 2
    assert "holds 'push' data, not 'reach'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_unknown_or_missing_device_fails_before_anything_is_written(make_dataset, tmp_path):
    ds = make_dataset("reach", lengths=(10, 10))
    with pytest.raises(GcdtError, match="unknown device 'tpu': use auto, cpu, cuda or cuda:N"):
        train(ds, TrainConfig(steps=2, device="tpu"), tmp_path / "a", progress=False)
    with pytest.raises(GcdtError, match="this torch sees no CUDA GPU; use cpu or auto"):
        train(ds, TrainConfig(steps=2, device="cuda"), tmp_path / "b", progress=False)  # conftest
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


@pytest.mark.parametrize(
    ("field", "value", "wanted"),
    [
        ("dropout", 1.0, "in [0, 1)"),
        ("dropout", -0.1, "in [0, 1)"),
        ("return_scale", 0.0, "> 0"),
        ("grad_clip", -1.0, "> 0"),
        ("warmup_fraction", 1.5, "in [0, 1]"),
        ("weight_decay", -1e-4, ">= 0"),
        ("lr", float("nan"), "> 0"),
    ],
)
def test_real_valued_settings_out_of_range_are_refused(field, value, wanted):
    with pytest.raises(GcdtError, match=re.escape(f"{field} must be {wanted}, got {value!r}")):
        TrainConfig(**{field: value})

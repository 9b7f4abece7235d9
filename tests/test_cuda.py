"""The CUDA paths, where a GPU is present (skipped elsewhere, CI included): the DT computes on
the GPU what it computes on the CPU, a resumed GPU run equals an uninterrupted one, and a
policy acts on the GPU as on the CPU."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from gcdt.checkpoint import load_checkpoint
from gcdt.models import DTConfig, GoalConditionedDT
from gcdt.policies.trained import TrainedPolicy
from gcdt.training import TrainConfig, train

pytestmark = [
    pytest.mark.cuda,
    pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU"),
]

FAST = {"log_every": 5, "checkpoint_every": 10}


def _padded_inputs(device: str) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    b, k = 4, 6
    inputs = {
        "states": torch.randn(b, k, 24, generator=g),
        "actions": torch.rand(b, k, 3, generator=g) * 2 - 1,
        "returns_to_go": -torch.rand(b, k, 1, generator=g),
        "timesteps": torch.arange(k).repeat(b, 1),
        "mask": torch.ones(b, k, dtype=torch.bool),
    }
    inputs["mask"][0, :2] = False
    inputs["mask"][2, :5] = False  # one real step
    return {name: x.to(device) for name, x in inputs.items()}


def test_dt_on_the_gpu_computes_what_it_computes_on_the_cpu():
    """Training path (padding skipped, SDPA) with its gradients, and the acting path."""
    torch.manual_seed(0)
    net = GoalConditionedDT(DTConfig(state_dim=24, action_dim=3, context=6, dropout=0.0)).train()
    results = []
    for device in ("cpu", "cuda"):
        net.to(device).zero_grad()
        inputs = _padded_inputs(device)
        out = net(**inputs)
        mask = inputs["mask"]
        torch.mean((out - inputs["actions"])[mask] ** 2).backward()
        with torch.no_grad():
            acting = net.eval()(**inputs, steps=slice(-1, None))
        net.train()
        # Copies: moving the module to the GPU moves its gradients' storage along.
        grads = {n: p.grad.detach().cpu().clone() for n, p in net.named_parameters()}
        results.append((out.detach().cpu().clone(), acting.cpu().clone(), grads))
    (out_c, act_c, grad_c), (out_g, act_g, grad_g) = results
    mask = _padded_inputs("cpu")["mask"]
    assert out_g[~mask].abs().max() == 0  # zeros on the padding, as on the CPU
    torch.testing.assert_close(out_g, out_c, atol=1e-5, rtol=1e-4)
    torch.testing.assert_close(act_g, act_c, atol=1e-5, rtol=1e-4)
    # Relative to each gradient's scale: the two devices sum in different orders.
    off = {}
    for name, g in grad_c.items():
        err = float((grad_g[name] - g).abs().max() / g.abs().max().clamp_min(1e-12))
        if err > 1e-4:
            off[name] = err
    assert not off, off


def test_resumed_gpu_run_equals_uninterrupted(make_dataset, tmp_path):
    """Dropout on the GPU draws from the device's generator: a resume must restore it. The
    GPU's reductions are not bit-reproducible, so losses are compared to 1e-4; a dropout
    stream restarted from the wrong state moves them by percents."""
    ds = make_dataset("push", lengths=(20, 30, 25))
    cfg = TrainConfig(steps=30, context=5, device="cuda", **FAST)
    full = train(ds, cfg, tmp_path / "full", progress=False)
    train(ds, cfg, tmp_path / "split", stop_after=13, progress=False)
    resumed = train(ds, cfg, tmp_path / "split", resume=True, progress=False)
    a, b = load_checkpoint(full.checkpoint), load_checkpoint(resumed.checkpoint)
    assert a["rng"]["cuda"] is not None
    losses_a = [h["loss"] for h in a["history"]]
    losses_b = [h["loss"] for h in b["history"]]
    np.testing.assert_allclose(losses_b, losses_a, rtol=1e-4)
    for key in a["model"]:
        torch.testing.assert_close(b["model"][key], a["model"][key], atol=1e-4, rtol=0, msg=key)


def test_policy_acts_on_the_gpu_as_on_the_cpu(make_dataset, tmp_path):
    ds = make_dataset("push", lengths=(20, 30, 25))
    ckpt = train(
        ds, TrainConfig(steps=20, context=5, device="cpu", **FAST), tmp_path, progress=False
    ).checkpoint
    policies = [TrainedPolicy(ckpt, "push", device=d) for d in ("cpu", "cuda")]
    assert policies[1].device.type == "cuda" and TrainedPolicy(ckpt).device.type == "cuda"
    rng = np.random.default_rng(0)
    for n in (3, 5):  # a reset with another number of envs captures a new graph
        for policy in policies:
            policy.reset(n, seed=0)
        for step in range(12):  # past K, with episodes starting at different steps
            obs = {
                "observation": rng.normal(size=(n, 18)).astype(np.float32),
                "desired_goal": rng.normal(size=(n, 3)).astype(np.float32),
                "achieved_goal": rng.normal(size=(n, 3)).astype(np.float32),
            }
            start = np.zeros(n, bool)
            start[:] = step == 0
            start[1] |= step == 7
            reward = -rng.integers(0, 2, n).astype(np.float32)
            cpu, gpu = (p.predict(obs, start, reward) for p in policies)
            np.testing.assert_allclose(gpu, cpu, atol=1e-5, rtol=1e-4)

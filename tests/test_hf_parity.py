"""Numerical parity with HuggingFace `DecisionTransformerModel`, the authors' model.

`transformers` is pinned in the test environment (environment/requirements.txt): this test
always runs in `make test`, never skipped. The HF model is built, and its weights mapped onto
ours, by `gcdt.hf_reference`, as the benchmarks do.
"""

from __future__ import annotations

import torch

from gcdt.hf_reference import copy_hf_weights, hf_actions, hf_model
from gcdt.models import DTConfig, GoalConditionedDT


def test_same_actions_as_huggingface():
    torch.manual_seed(0)
    cfg = DTConfig(state_dim=25, action_dim=4, context=20)
    hf = hf_model(cfg).eval()
    with torch.no_grad():  # non-trivial values everywhere, including wpe and the LN biases
        for p in hf.parameters():
            p.add_(0.05 * torch.randn_like(p))
    ours = GoalConditionedDT(cfg).eval()
    copy_hf_weights(hf, ours)

    b, k = 4, 20
    states, actions = torch.randn(b, k, 25), torch.rand(b, k, 4) * 2 - 1
    rtg, timesteps = -torch.rand(b, k, 1), torch.randint(0, 50, (b, k))
    mask = torch.ones(b, k, dtype=torch.bool)
    mask[1, :7] = False  # left padding in one sequence
    with torch.no_grad():
        expected = hf_actions(hf, states, actions, rtg, timesteps, mask)
        got = ours(states, actions, rtg, timesteps, mask)
    torch.testing.assert_close(got[mask], expected[mask], rtol=1e-5, atol=1e-5)

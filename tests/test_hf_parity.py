"""Numerical parity with HuggingFace `DecisionTransformerModel`, the authors' model.

`transformers` is pinned in the test environment (environment/requirements.txt): this test
always runs in `make test`, never skipped.
Weights are copied across; HF's GPT-2 uses Conv1D (transposed Linear) weights, and it adds
`wpe[0]` to every token after the embedding LayerNorm (it passes position_ids of zeros), a
constant that folds exactly into that LayerNorm's bias.
"""

from __future__ import annotations

import torch
import transformers

from gcdt.models import DTConfig, GoalConditionedDT


def _copy_hf_weights(hf, ours: GoalConditionedDT) -> None:
    sd = hf.state_dict()
    new = {
        "embed_timestep.weight": sd["embed_timestep.weight"],
        "embed_return.weight": sd["embed_return.weight"],
        "embed_return.bias": sd["embed_return.bias"],
        "embed_state.weight": sd["embed_state.weight"],
        "embed_state.bias": sd["embed_state.bias"],
        "embed_action.weight": sd["embed_action.weight"],
        "embed_action.bias": sd["embed_action.bias"],
        "embed_ln.weight": sd["embed_ln.weight"],
        "embed_ln.bias": sd["embed_ln.bias"] + sd["encoder.wpe.weight"][0],
        "ln_f.weight": sd["encoder.ln_f.weight"],
        "ln_f.bias": sd["encoder.ln_f.bias"],
        "predict_action.weight": sd["predict_action.0.weight"],
        "predict_action.bias": sd["predict_action.0.bias"],
    }
    for i in range(len(ours.blocks)):
        h = f"encoder.h.{i}."
        new |= {
            f"blocks.{i}.ln_1.weight": sd[h + "ln_1.weight"],
            f"blocks.{i}.ln_1.bias": sd[h + "ln_1.bias"],
            f"blocks.{i}.qkv.weight": sd[h + "attn.c_attn.weight"].T,
            f"blocks.{i}.qkv.bias": sd[h + "attn.c_attn.bias"],
            f"blocks.{i}.proj.weight": sd[h + "attn.c_proj.weight"].T,
            f"blocks.{i}.proj.bias": sd[h + "attn.c_proj.bias"],
            f"blocks.{i}.ln_2.weight": sd[h + "ln_2.weight"],
            f"blocks.{i}.ln_2.bias": sd[h + "ln_2.bias"],
            f"blocks.{i}.fc.weight": sd[h + "mlp.c_fc.weight"].T,
            f"blocks.{i}.fc.bias": sd[h + "mlp.c_fc.bias"],
            f"blocks.{i}.fc_proj.weight": sd[h + "mlp.c_proj.weight"].T,
            f"blocks.{i}.fc_proj.bias": sd[h + "mlp.c_proj.bias"],
        }
    ours.load_state_dict(new)


def test_same_actions_as_huggingface():
    torch.manual_seed(0)
    hf_config = transformers.DecisionTransformerConfig(
        state_dim=25,
        act_dim=4,
        hidden_size=128,
        n_layer=3,
        n_head=1,
        n_inner=None,
        activation_function="relu",
        max_ep_len=1000,
        action_tanh=True,
    )
    hf = transformers.DecisionTransformerModel(hf_config).eval()
    with torch.no_grad():  # non-trivial values everywhere, including wpe and the LN biases
        for p in hf.parameters():
            p.add_(0.05 * torch.randn_like(p))
    ours = GoalConditionedDT(DTConfig(state_dim=25, action_dim=4, context=20)).eval()
    _copy_hf_weights(hf, ours)

    b, k = 4, 20
    states, actions = torch.randn(b, k, 25), torch.rand(b, k, 4) * 2 - 1
    rtg, timesteps = -torch.rand(b, k, 1), torch.randint(0, 50, (b, k))
    mask = torch.ones(b, k, dtype=torch.bool)
    mask[1, :7] = False  # left padding in one sequence
    with torch.no_grad():
        _, expected, _ = hf(
            states=states,
            actions=actions,
            returns_to_go=rtg,
            timesteps=timesteps,
            attention_mask=mask.long(),
            return_dict=False,
        )
        got = ours(states, actions, rtg, timesteps, mask)
    torch.testing.assert_close(got[mask], expected[mask], rtol=1e-5, atol=1e-5)

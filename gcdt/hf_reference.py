"""The authors' model, HuggingFace `DecisionTransformerModel`, as the parity test and the
benchmarks build it from a `DTConfig`, and its weights mapped onto `GoalConditionedDT`.

`transformers` is pinned in the project's environment but is not a dependency of the library:
it is imported here only, when these functions are called.
"""

from __future__ import annotations

from typing import Any

from gcdt.models import DTConfig, GoalConditionedDT


def hf_model(cfg: DTConfig) -> Any:
    """The authors' configuration of HF's model: GPT-2 blocks with a ReLU MLP of 4x width,
    tanh actions, the same dropout everywhere."""
    import transformers

    config = transformers.DecisionTransformerConfig(
        state_dim=cfg.state_dim,
        act_dim=cfg.action_dim,
        hidden_size=cfg.hidden,
        n_layer=cfg.layers,
        n_head=cfg.heads,
        n_inner=None,
        activation_function="relu",
        resid_pdrop=cfg.dropout,
        embd_pdrop=cfg.dropout,
        attn_pdrop=cfg.dropout,
        max_ep_len=cfg.max_episode_steps,
        action_tanh=True,
        bos_token_id=None,  # GPT-2's text-token defaults mean nothing here (and warn)
        eos_token_id=None,
    )
    return transformers.DecisionTransformerModel(config)


def hf_actions(hf: Any, states, actions, returns_to_go, timesteps, mask) -> Any:
    """HF's predicted actions `[batch, K, action_dim]`, called with `GoalConditionedDT`'s
    arguments in its order (`mask` is the boolean left-padding mask)."""
    return hf(
        states=states,
        actions=actions,
        returns_to_go=returns_to_go,
        timesteps=timesteps,
        attention_mask=mask.long(),
        return_dict=False,
    )[1]


def copy_hf_weights(hf: Any, ours: GoalConditionedDT) -> None:
    """Load `hf`'s weights into `ours`. HF's GPT-2 keeps Conv1D (transposed Linear) weights,
    and adds `wpe[0]` to every token after the embedding LayerNorm (it passes position ids of
    zeros): a constant that folds exactly into that LayerNorm's bias."""
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

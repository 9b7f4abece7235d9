"""Checkpoints of a TQC+HER run in progress: everything `learn` needs to carry on exactly.

A checkpoint is taken between two loop iterations (after the gradient steps, before the next
env step), so no transition is half-stored. It holds the whole algorithm object (actor,
critics, their optimisers and targets, the entropy coefficient, the JAX or torch RNG state,
the step and episode counters), the HER replay buffer up to its fill level, the global
NumPy / Python / torch RNG states (HER samples with NumPy's), each env's place in its
episode stream, and what the caller adds (the learning curve so far).

An env mid-episode is restored by resetting it with that episode's seed and replaying the
episode's actions. On Reach that rebuilds the env bit for bit, and a resumed run ends with
the weights of an uninterrupted one (`tests/test_tqc.py`). With an object on the table (Push,
PickAndPlace) PyBullet carries state from an env's earlier episodes into the next one, which
a reset does not clear and a checkpoint does not hold: the replayed steps then differ
slightly from the original ones (docs/library.md gives the size). So the learner resumes
exactly, and the envs up to that difference.

A copy of a checkpoint may leave the replay buffer out (`strip_buffer`): a few MiB
instead of hundreds, small enough to travel with the repository to a fresh machine. The learner,
its optimisers, RNG states and curve resume exactly; the transitions do not, so the run refills
an empty buffer as it began, with `learning_starts` random steps before its next gradient step,
and records where it did (`buffer_refills` in its run.json).

The file: a magic line, the length of a JSON header, the header (what the run is, and the
payload's length and SHA-256), then the pickled payload; written to a temp file, synced and
renamed, so a reader sees the old checkpoint or the new one, never half of one.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import random
import struct
from pathlib import Path
from typing import Any

import numpy as np

from gcdt.errors import GcdtError
from gcdt.paths import atomic_write

CHECKPOINT_FILE = "checkpoint.tqc"
MAGIC = b"gcdt-tqc-checkpoint v1\n"
#: What a checkpoint must agree on with the command that resumes it.
IDENTITY_KEYS = ("task", "reward", "seed", "backend", "config", "evaluation")


def save_checkpoint(path: Path, model: Any, identity: dict[str, Any], extra: Any) -> int:
    """Write `model`'s training state and `extra` to `path` atomically; return its bytes."""
    payload = {
        "model": _detached(model),
        "envs": [env.replay_state() for env in _seeded(model.env)],
        "rng": _global_rng_state(),
        "extra": extra,
    }
    header = {**identity, "env_steps": int(model.num_timesteps), "buffer": True}
    return _write(path, header, payload)


def strip_buffer(src: Path, dst: Path) -> dict[str, Any]:
    """Write checkpoint `src` to `dst` without its replay buffer; return `dst`'s header."""
    header, payload = _read(src, payload=True)
    payload["model"].replay_buffer = None
    header = {**header, "buffer": False}
    _write(dst, header, payload)
    return header


def has_buffer(header: dict[str, Any]) -> bool:
    """Whether the checkpoint of `header` holds its replay buffer (older ones always do)."""
    return header.get("buffer", True)


def _write(path: Path, header: dict[str, Any], payload: dict[str, Any]) -> int:
    import cloudpickle

    blob = cloudpickle.dumps(payload, protocol=pickle.HIGHEST_PROTOCOL)
    header = {
        **header,
        "payload_bytes": len(blob),
        "payload_sha256": hashlib.sha256(blob).hexdigest(),
    }
    head = json.dumps(header, sort_keys=True).encode()
    with atomic_write(path, binary=True) as f:
        f.write(MAGIC + struct.pack("<Q", len(head)) + head)
        f.write(blob)
        f.flush()
        os.fsync(f.fileno())  # a checkpoint must outlive a power cut, not only a kill
    return len(MAGIC) + 8 + len(head) + len(blob)


def read_header(path: Path) -> dict[str, Any]:
    """The header of checkpoint `path`, checked to be whole (a one-line error otherwise)."""
    header, _ = _read(path, payload=False)
    return header


def check_identity(path: Path, header: dict[str, Any], identity: dict[str, Any]) -> None:
    """Refuse a checkpoint of another task, reward, seed, backend, config or evaluation."""
    for key in IDENTITY_KEYS:
        if header.get(key) != identity[key]:
            raise GcdtError(
                f"{path} is a checkpoint of {key} {header.get(key)!r}, not {identity[key]!r}: "
                "resume it with the command that started it, or choose another --out"
            )


def load_checkpoint(path: Path, model: Any) -> Any:
    """Restore `model` (freshly built, on fresh envs) to the state saved in `path`; return the
    saved `extra`."""
    _, payload = _read(path, payload=True)
    saved = payload["model"]
    envs, fresh_buffer, warm_up = model.env, model.replay_buffer, model.learning_starts
    buffer = saved.replay_buffer
    model.__dict__.update(saved.__dict__)
    model.env = envs
    if buffer is None:
        # The transitions stayed behind: the run refills an empty buffer as it began, with
        # random steps (SB3 acts at random below `learning_starts`) before its next update.
        model.replay_buffer = fresh_buffer  # built on `envs`
        model.learning_starts = model.num_timesteps + warm_up
    else:
        _fill_buffer(buffer)
        if hasattr(buffer, "set_env"):  # HER recomputes rewards through the envs
            buffer.set_env(envs)
    for env, state in zip(_seeded(envs), payload["envs"], strict=True):
        env.restore_replay_state(state)
    model._last_obs = _vec_observation(envs)
    _set_global_rng_state(payload["rng"])
    return payload["extra"]


def _read(path: Path, payload: bool) -> tuple[dict[str, Any], Any]:
    if not path.is_file():
        raise GcdtError(
            f"no TQC+HER checkpoint at {path}: start the run without --resume, or point --out "
            "at the folder of the run to resume"
        )
    truncated = GcdtError(
        f"{path} is truncated or not a TQC+HER checkpoint: delete it and start the run again"
    )
    with open(path, "rb") as f:
        if f.read(len(MAGIC)) != MAGIC:
            raise truncated
        (size,) = struct.unpack("<Q", f.read(8).rjust(8, b"\0"))
        try:
            header = json.loads(f.read(size))
        except ValueError:
            raise truncated from None
        expected = len(MAGIC) + 8 + size + header.get("payload_bytes", -1)
        if os.fstat(f.fileno()).st_size != expected:
            raise truncated
        if not payload:
            return header, None
        blob = f.read()
    if hashlib.sha256(blob).hexdigest() != header["payload_sha256"]:
        raise truncated
    return header, pickle.loads(blob)


# --------------------------------------------------------------------------------------------
# The pieces


def _detached(model: Any) -> Any:
    """A shallow copy of `model` without its envs and logger, its buffer cut to its fill."""
    import copy

    clone = copy.copy(model)
    clone.env = None
    clone._logger = None
    clone._custom_logger = False
    clone.replay_buffer = _trimmed(model.replay_buffer)
    return clone


def _trimmed(buffer: Any) -> Any:
    """A shallow copy of a replay buffer whose per-slot arrays keep only the filled slots
    (the rest are zeros, a 1M-slot buffer's bulk early in a run)."""
    import copy

    clone = copy.copy(buffer)
    filled = buffer.buffer_size if buffer.full else buffer.pos
    clone._slot_shapes = {}
    for name, value in vars(buffer).items():
        if name == "env":
            continue
        if isinstance(value, dict) and all(_is_slots(buffer, v) for v in value.values()):
            clone._slot_shapes[name] = {k: (v.shape, v.dtype) for k, v in value.items()}
            setattr(clone, name, {k: v[:filled] for k, v in value.items()})
        elif _is_slots(buffer, value):
            clone._slot_shapes[name] = (value.shape, value.dtype)
            setattr(clone, name, value[:filled])  # a view: pickled without the rest
    if "env" in vars(clone):
        clone.env = None
    return clone


def _is_slots(buffer: Any, value: Any) -> bool:
    return isinstance(value, np.ndarray) and value.ndim >= 1 and len(value) == buffer.buffer_size


def _fill_buffer(buffer: Any) -> None:
    """Undo `_trimmed` in place: full-size arrays with the saved slots at their start."""

    def full(kept: np.ndarray, shape_dtype: tuple) -> np.ndarray:
        array = np.zeros(*shape_dtype)
        array[: len(kept)] = kept
        return array

    for name, shapes in buffer.__dict__.pop("_slot_shapes").items():
        value = getattr(buffer, name)
        if isinstance(shapes, dict):
            setattr(buffer, name, {k: full(value[k], shapes[k]) for k in shapes})
        else:
            setattr(buffer, name, full(value, shapes))


def _seeded(envs: Any) -> list[Any]:
    """Each env's `SeededResets` wrapper (the place in its episode stream)."""
    from gcdt.envs import SeededResets

    found = []
    for env in envs.envs:
        while not isinstance(env, SeededResets):
            if not hasattr(env, "env"):
                raise TypeError("a TQC+HER checkpoint needs every env wrapped in SeededResets")
            env = env.env
        found.append(env)
    return found


def _vec_observation(envs: Any) -> dict[str, np.ndarray]:
    """The vec env's current observation, rebuilt from its envs after they were restored."""
    for k, env in enumerate(_seeded(envs)):
        envs._save_obs(k, env.last_obs)
    return envs._obs_from_buf()


def _global_rng_state() -> dict[str, Any]:
    # SB3's HER buffer samples with NumPy's legacy global generator: its state is the run's.
    state: dict[str, Any] = {"numpy": np.random.get_state(), "python": random.getstate()}  # noqa: NPY002
    try:
        import torch

        state["torch"] = torch.get_rng_state()
    except ImportError:  # pragma: no cover - torch is a dependency
        pass
    return state


def _set_global_rng_state(state: dict[str, Any]) -> None:
    np.random.set_state(state["numpy"])  # noqa: NPY002
    random.setstate(state["python"])
    if "torch" in state:
        import torch

        torch.set_rng_state(state["torch"])

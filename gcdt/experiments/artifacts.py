"""Content-keyed artifacts shared by the runs of a sweep: datasets, TQC agents, checkpoints.

`dataset(spec)`, `tqc_agent(spec)` and `checkpoint(spec)` return the artifact, made first
when it does not exist yet (the explorer notebook gets its checkpoint this way too).

Each artifact lives under `<artifacts>/grid/` at a path named by the hash of the spec that
makes it, so every run that needs the same dataset (or agent) uses one copy, made once. An
exclusive file lock per artifact stops two workers (processes or Ray tasks on one machine, or
nodes sharing the folder) from making it twice; each is written atomically, so a killed
worker leaves no half artifact behind; a killed collection resumes from the chunks it saved
(`gcdt.data.collect`). The sparse and dense variants of a task share one collection (both
rewards are stored).

Under a storage URI (`gcdt.experiments.storage`, a cluster without a shared filesystem) an
artifact missing here is first looked for there, and one made here is uploaded there.
"""

from __future__ import annotations

import contextlib
import csv
import fcntl
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from gcdt.baselines.tqc_checkpoint import CHECKPOINT_FILE
from gcdt.baselines.tqc_her import (
    EVAL_CSV,
    MODEL_ZIP,
    RUN_FILES,
    RUN_JSON,
    train_tqc,
)
from gcdt.data import Dataset, collect, load_dataset, mix, subset
from gcdt.data.collect import chunks_beside, remove_chunks
from gcdt.errors import GcdtError
from gcdt.experiments.grid import DataSpec, RunSpec, TQCSpec, file_digest
from gcdt.experiments.storage import run_storage
from gcdt.paths import REPO_ROOT, artifacts_dir
from gcdt.regions import GoalRegion

if TYPE_CHECKING:
    from gcdt.policies import Policy


def grid_dir() -> Path:
    return artifacts_dir() / "grid"


def _fetched(names: list[str]) -> bool:
    """Whether artifact `names` (relative to the grid folder, completion mark last) came
    from the run's storage URI; False without one."""
    storage = run_storage()
    return storage is not None and storage.fetch(grid_dir(), names)


def _publish(names: list[str]) -> None:
    """Upload artifact `names` (those that exist, completion mark last) to the run's storage."""
    storage = run_storage()
    if storage is not None:
        storage.publish(grid_dir(), [n for n in names if (grid_dir() / n).exists()])


@contextlib.contextmanager
def _locked(key: str) -> Iterator[None]:
    """Hold the exclusive lock of artifact `key` (released by the OS if the process dies)."""
    lock_dir = grid_dir() / "locks"
    lock_dir.mkdir(parents=True, exist_ok=True)
    with open(lock_dir / f"{key}.lock", "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def tqc_agent(spec: TQCSpec) -> Path:
    """The final model zip of TQC+HER run `spec`, trained first if it does not exist yet."""
    out = grid_dir() / "tqc" / spec.key()
    model = out / MODEL_ZIP
    # RUN_JSON is written last: without it the run did not finish.
    names = [f"tqc/{spec.key()}/{name}" for name in RUN_FILES if name != RUN_JSON]
    names.append(f"tqc/{spec.key()}/{RUN_JSON}")
    with _locked(spec.key()):
        if not (out / RUN_JSON).exists() and not _fetched(names):
            resume = (out / CHECKPOINT_FILE).exists()  # an interrupted run carries on from it
            if not resume:
                for name in RUN_FILES:  # what a run interrupted before its first checkpoint left
                    (out / name).unlink(missing_ok=True)
            train_tqc(
                spec.task,
                spec.reward,
                spec.tqc_config(),
                out,
                seed=spec.seed,
                eval_every=spec.eval_every,
                eval_episodes=spec.eval_episodes,
                progress=False,
                resume=resume,
            )
            _publish(names)
    return model


def dataset(spec: DataSpec) -> Dataset:
    """Dataset `spec`, made (collected, or drawn from its collections) if it does not exist."""
    name = f"datasets/{spec.key()}.npz"
    path = grid_dir() / name
    # A collection keeps its chunks beside the dataset until it is saved, so that a killed
    # worker's successor resumes it; they stay on this machine (only the dataset is uploaded).
    chunks = chunks_beside(path)
    with _locked(spec.key()):
        if path.exists() or _fetched([name]):
            remove_chunks(chunks)  # left by a worker killed after the save, or made elsewhere
            return load_dataset(path)
        if spec.is_base:
            made = _collect(spec, chunks)
        else:
            expert = dataset(spec.base("expert"))
            if spec.expert_ratio == 1.0:
                made = subset(expert, spec.size, seed=spec.seed)
            else:
                made = mix(
                    expert,
                    dataset(spec.base("random")),
                    spec.expert_ratio,
                    spec.size,
                    seed=spec.seed,
                )
        made = made.with_metadata(grid_spec=spec.key())
        made.save(path)
        remove_chunks(chunks)
        _publish([name])
    return made


def collecting_policy(spec: DataSpec) -> tuple[Policy, str]:
    """The policy that collects base dataset `spec`, and the reward type it is shown."""
    from gcdt.policies import TQC_PREFIX, make_policy

    if spec.expert == "tqc":
        return make_policy(f"tqc:{tqc_agent(spec.expert_tqc)}", spec.task), spec.expert_tqc.reward
    if spec.expert.startswith(TQC_PREFIX):  # a published agent, checked to be the planned one
        path = REPO_ROOT / spec.expert.removeprefix(TQC_PREFIX)
        if spec.waits_for:
            raise GcdtError(
                f"{path} is not published yet (or not of the profile's agent_steps): publish "
                "the finished run with `gcdt tqc publish` first"
            )
        if file_digest(path) != spec.expert_digest:
            raise GcdtError(f"{path} changed since this grid was planned; plan it again")
        policy = make_policy(f"{TQC_PREFIX}{path}", spec.task)
        return policy, policy.reward or "sparse"
    noise = {"noise_std": spec.expert_noise} if spec.expert_noise else {}  # scripted only
    return make_policy(spec.expert, spec.task, **noise), "sparse"


def _collect(spec: DataSpec, chunks_dir: Path) -> Dataset:
    policy, reward = collecting_policy(spec)
    return collect(
        policy,
        spec.task,
        spec.base_size,
        seed=spec.seed,
        n_envs=spec.collect_envs,
        reward=reward,
        labels=spec.expert_labels,
        goal_region=None if spec.goal_region is None else GoalRegion.parse(spec.goal_region),
        progress=False,
        chunks_dir=chunks_dir,
    )


def tqc_curve(run_dir: Path, fields: tuple[str, ...]) -> list[dict[str, float]]:
    """The learning curve (`eval.csv`) of a finished TQC+HER run, `fields` of each point."""
    with open(run_dir / EVAL_CSV, newline="") as f:
        return [{k: float(row[k]) for k in fields} for row in csv.DictReader(f)]


def checkpoint_dir(spec: RunSpec) -> Path:
    """Where an offline run keeps its training checkpoint (resumed after an interruption);
    runs that differ only in their evaluation share it."""
    return grid_dir() / "checkpoints" / spec.training_key()


def checkpoint(spec: RunSpec) -> Path:
    """The finished training checkpoint of offline run `spec`: trained first if it does not
    exist yet, resumed if an earlier training was interrupted."""
    return trained_checkpoint(spec)[0]


def checkpointed_steps(spec: RunSpec) -> int:
    """Gradient steps the checkpoint of offline run `spec` on this machine holds (0: none):
    where a killed run resumes, all of them once it is finished. Read from the loss log
    written beside each checkpoint, so that a dry run need not load the model."""
    from gcdt.checkpoint import CHECKPOINT_NAME
    from gcdt.training import LOG_NAME

    out = checkpoint_dir(spec)
    if not (out / CHECKPOINT_NAME).exists() or not (out / LOG_NAME).exists():
        return 0
    with open(out / LOG_NAME, newline="") as f:
        rows = list(csv.DictReader(f))
    try:
        return int(rows[-1]["step"]) if rows else 0
    except (KeyError, ValueError):  # not a loss log: estimate the whole training
        return 0


def trained_checkpoint(spec: RunSpec) -> tuple[Path, int]:
    """`checkpoint(spec)`, and the gradient steps this call trained to finish it: 0 where it
    was finished before (here or on another node), fewer than the run's where it resumed.
    What the training time of the call paid for, and so what a measured rate divides by."""
    from gcdt.checkpoint import CHECKPOINT_NAME, load_checkpoint
    from gcdt.training import train

    out = checkpoint_dir(spec)
    path = out / CHECKPOINT_NAME
    # Only a complete checkpoint is uploaded: its presence there marks it finished.
    name = str(path.relative_to(grid_dir()))
    trained = 0
    with _locked(spec.training_key()):
        ckpt = load_checkpoint(path) if path.exists() else None
        if (ckpt is None or not ckpt["complete"]) and _fetched([name]):
            ckpt = load_checkpoint(path)
        if ckpt is None or not ckpt["complete"]:
            cfg = spec.train_config()  # the config the run's key hashes
            done = train(dataset(spec.data), cfg, out, resume=ckpt is not None, progress=False)
            trained = done.steps - done.resumed_from
            _publish([name])
    return path, trained

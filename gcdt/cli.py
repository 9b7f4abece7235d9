"""The `gcdt` command line (also `python -m gcdt`).

Each command is a frozen dataclass: its fields are the command's options (`gcdt.settings`:
type, default, help), its `__post_init__` validates them and its `run` does the work. A field
that is a dataclass (`EvaluationConfig`, `TrainConfig`, ...) brings its own fields as options.
Bad input, from argparse or from the library (`GcdtError`), ends with one line
`gcdt: error: ...` on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import inspect
import json
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

from gcdt.baselines.publish import PublishConfig
from gcdt.baselines.tqc_her import BACKENDS as TQC_BACKENDS
from gcdt.baselines.tqc_her import RUN_JSON, TQCRunSettings, tqc_config_names
from gcdt.data.collect import LABELS
from gcdt.envs import TASKS, RewardType
from gcdt.errors import GcdtError
from gcdt.evaluation import EvaluationConfig
from gcdt.experiments.grid import SECTIONS
from gcdt.experiments.profiles import PROFILES
from gcdt.experiments.sweep import BACKENDS, RETRIES
from gcdt.paths import check_writable, write_json_atomic
from gcdt.policies import POLICY_NAMES, POLICY_SPECS, TQC_PREFIX
from gcdt.regions import GoalRegion
from gcdt.settings import REQUIRED, add_options, check_minimums, from_options, setting

if TYPE_CHECKING:
    from gcdt.training import TrainConfig

USAGE_ERROR = 2
#: The commands that group others (`gcdt dataset mix`), with their help.
GROUPS = {
    "dataset": "inspect, mix, subset, import and export datasets",
    "tqc": "TQC+HER: the online baseline and the paper's expert",
}
_REGION_HELP = (
    "draw the desired goals from this box only (world coordinates, metres; an empty bound is "
    "open), e.g. y=0: for one half of the table"
)


class _Parser(argparse.ArgumentParser):
    """argparse, but its errors are one line (no usage block) and exit with status 2.

    `arguments(parser)`, when given, adds the parser's arguments the first time it parses
    (its `--help` included): `gcdt --help` builds no command's options, and `gcdt train`'s
    come from a module that imports torch, which the other commands should not wait for.
    """

    def __init__(
        self, *args: Any, arguments: Callable[[_Parser], None] | None = None, **kwargs: Any
    ) -> None:
        super().__init__(*args, **kwargs)
        self.lazy_arguments = arguments

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[override]
        if self.lazy_arguments is not None:
            add, self.lazy_arguments = self.lazy_arguments, None
            add(self)
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> None:  # type: ignore[override]
        print(f"gcdt: error: {message}", file=sys.stderr)
        raise SystemExit(USAGE_ERROR)


@dataclass(frozen=True, kw_only=True)
class _Command:
    """A command: `name` (`group command` for one in a group), its options as fields, and the
    first line of its docstring as its help."""

    name: ClassVar[str]

    def __post_init__(self) -> None:
        check_minimums(self)

    @staticmethod
    def names() -> dict[str, Any]:
        """The names its annotations use that `gcdt.cli` imports only when it runs."""
        return {}

    def run(self, command: str) -> int:
        """Do the work; `command` is the command line, as result files record it."""
        raise NotImplementedError


@dataclass(frozen=True, kw_only=True)
class _Progress:
    no_progress: bool = setting(False, "hide the progress bar")


@dataclass(frozen=True, kw_only=True)
class _WritesDataset(_Command):
    out: Path = setting(REQUIRED, "the dataset file to write", metavar="PATH.npz")

    def __post_init__(self) -> None:
        super().__post_init__()
        if not str(self.out).endswith(".npz"):
            raise GcdtError(f"dataset paths end in .npz, got {str(self.out)!r}")


@dataclass(frozen=True, kw_only=True)
class PolicyOptions:
    """The policy a command runs, on its task."""

    policy: str = setting(
        REQUIRED,
        "a policy name, tqc:PATH of a TQC+HER zip (gcdt tqc train), or the path of a "
        "GC-DT/DT/BC checkpoint (gcdt train)",
        metavar=POLICY_SPECS,
    )
    task: str = setting(REQUIRED, "the task", choices=TASKS)
    noise: float = setting(0.0, "scripted expert action noise std")
    target_return: float | None = setting(
        None,
        "a DT checkpoint's target return at each episode's start (default 0, the paper's)",
        metavar="R",
    )
    device: str | None = setting(
        None, "where a DT or BC checkpoint runs: auto (the default, CUDA when present), cpu or cuda"
    )

    def __post_init__(self) -> None:
        if self.noise and self.policy != "scripted":
            raise GcdtError("--noise applies only to --policy scripted")
        checkpoint = self.policy not in POLICY_NAMES and not self.policy.startswith(TQC_PREFIX)
        if self.target_return is not None and not checkpoint:
            raise GcdtError("--target-return applies only to a DT checkpoint (gcdt train)")
        if self.device is not None and not checkpoint:
            raise GcdtError("--device applies only to a DT or BC checkpoint (gcdt train)")

    def make(self):
        """The policy, for the task."""
        from gcdt.policies import make_policy

        if self.policy == "scripted":
            return make_policy(self.policy, self.task, noise_std=self.noise)
        given = {"target_return": self.target_return, "device": self.device}
        return make_policy(
            self.policy, self.task, **{k: v for k, v in given.items() if v is not None}
        )


@dataclass(frozen=True, kw_only=True)
class Evaluate(_Command, _Progress):
    """measure a policy's success rate and return

    Run a policy with the paper's protocol, a fixed budget of env steps counting every finished
    episode, or a fixed number of episodes."""

    name = "evaluate"
    agent: PolicyOptions
    reward: RewardType = setting(REQUIRED, "the rewards the returns sum")
    evaluation: EvaluationConfig
    goal_region: GoalRegion | None = setting(
        None, _REGION_HELP, metavar="AXIS=LOW:HIGH,...", parse=GoalRegion.parse
    )
    json: bool = setting(False, "print the summary as one JSON line")
    out: Path | None = setting(
        None,
        "also write the full result (summary, every episode, the command) as JSON",
        metavar="PATH",
    )

    def run(self, command: str) -> int:
        from gcdt.evaluation import evaluate

        if self.out is not None:
            check_writable(self.out)  # before the run, not after it
        result = evaluate(
            self.agent.make(),
            self.agent.task,
            self.reward,
            **dataclasses.asdict(self.evaluation),
            goal_region=self.goal_region,
            progress=not self.no_progress,
        )
        summary = result.summary
        if self.out is not None:
            write_json_atomic(self.out, {"command": command, **result.to_dict()})
        if self.json:
            print(json.dumps(summary))
        else:
            print(
                f"{summary['policy']} on {summary['task']}/{summary['reward']}: "
                f"success {100 * summary['success_rate']:.1f} %, "
                f"return {summary['mean_return']:.2f} ± {summary['std_return']:.2f} "
                f"over {summary['episodes']} episodes ({summary['timesteps']} steps, "
                f"{summary['steps_per_second']:.0f} steps/s)"
                if summary["episodes"]
                else f"no episode finished within {summary['timesteps']} steps"
            )
        return 0


def _goal(text: str) -> tuple[float, ...]:
    """X,Y,Z in metres."""
    try:
        goal = tuple(float(v) for v in text.split(","))
    except ValueError:
        goal = ()
    if len(goal) != 3:
        raise GcdtError(f"a goal is three numbers X,Y,Z in metres, got {text!r}")
    return goal


@dataclass(frozen=True, kw_only=True)
class Rollout(_Command):
    """record one episode as an animated GIF, towards a goal of your choice

    Render evaluation episode 0 of --seed headless and save it as a GIF; --goal replaces its
    desired goal (the explorer of notebook 07, from the shell)."""

    name = "rollout"
    agent: PolicyOptions
    reward: RewardType = setting(REQUIRED, "the rewards the return sums")
    goal: tuple[float, ...] | None = setting(
        None,
        "the desired goal in world coordinates (metres), within the task's goal range",
        metavar="X,Y,Z",
        parse=_goal,
    )
    seed: int = setting(0, "evaluation seed", minimum=0)
    size: int = setting(360, "frame size, pixels", minimum=16)
    out: Path = setting(REQUIRED, "the animation to write", metavar="PATH.gif")

    def __post_init__(self) -> None:
        super().__post_init__()
        if not str(self.out).endswith(".gif"):
            raise GcdtError(f"animations are GIF files ending in .gif, got {str(self.out)!r}")

    def run(self, command: str) -> int:
        import numpy as np

        from gcdt.evaluation import record_rollout

        check_writable(self.out)
        policy, task = self.agent.make(), self.agent.task
        goal = None if self.goal is None else np.array(self.goal)
        rec = record_rollout(
            policy, task, self.reward, self.seed, path=self.out, size=self.size, goal=goal
        )
        where = ", ".join(f"{v:.3f}" for v in rec.goal)
        print(
            f"{policy.name} on {task}/{self.reward} towards ({where}): {rec.verdict}, "
            f"return {rec.ret:.2f} over {rec.steps} steps: {self.out}"
        )
        return 0


def _report(dataset, path: Path | None, as_json: bool = False) -> None:
    """Print a dataset's summary: one JSON line, or one readable line."""
    summary = dataset.summary()
    if as_json:
        print(json.dumps({"path": str(path) if path else None, **summary}))
        return
    where = f"{path}: " if path else ""
    print(
        f"{where}{summary['task']} {summary['source']} ({summary['policy']}): "
        f"{summary['transitions']} transitions in {summary['episodes']} episodes "
        f"(mean length {summary['mean_length']:.1f}), "
        f"success {100 * summary['success_rate']:.1f} %, "
        f"mean return sparse {summary['mean_return_sparse']:.2f} / "
        f"dense {summary['mean_return_dense']:.2f}"
    )


@dataclass(frozen=True, kw_only=True)
class Collect(_WritesDataset, _Progress):
    """collect an offline dataset with a policy

    Run a policy on parallel envs and save its first whole episodes that add up to at least N
    transitions (both reward types are stored). The collection keeps its finished chunks in
    PATH.chunks/ until PATH is written: run the same command again after a kill to resume it."""

    name = "collect"
    agent: PolicyOptions
    transitions: int = setting(REQUIRED, "transitions to collect, at least", minimum=1, metavar="N")
    seed: int = setting(0, "seeds the episodes", minimum=0)
    envs: int = setting(1, "parallel env processes", minimum=1)
    labels: str = setting(
        "executed",
        "the action recorded: executed (what the env ran) or clean (the expert's action "
        "before its noise, as in DART)",
        choices=LABELS,
    )
    goal_region: GoalRegion | None = setting(
        None, _REGION_HELP, metavar="AXIS=LOW:HIGH,...", parse=GoalRegion.parse
    )
    json: bool = setting(False, "print the summary as one JSON line")

    def run(self, command: str) -> int:
        from gcdt.data import collect
        from gcdt.data.collect import chunks_beside, remove_chunks

        check_writable(self.out)  # before the collection, not after it
        policy = self.agent.make()
        dataset = collect(
            policy,
            self.agent.task,
            self.transitions,
            seed=self.seed,
            n_envs=self.envs,
            # Both rewards are stored; a trained agent runs under the one it was trained with.
            reward=policy.config().get("reward") or "sparse",
            labels=self.labels,
            goal_region=self.goal_region,
            progress=not self.no_progress,
            chunks_dir=chunks_beside(self.out),
        )
        dataset = dataset.with_metadata(command=command)
        saved = dataset.save(self.out)
        remove_chunks(chunks_beside(self.out))
        _report(dataset, saved, self.json)
        return 0


@dataclass(frozen=True, kw_only=True)
class DatasetInfo(_Command):
    """summary statistics and metadata of a dataset"""

    name = "dataset info"
    path: Path = setting(REQUIRED, "the dataset", positional=True)
    json: bool = setting(False, "print summary and metadata as JSON")

    def run(self, command: str) -> int:
        from gcdt.data import load_dataset

        dataset = load_dataset(self.path)
        if self.json:
            print(json.dumps({"summary": dataset.summary(), "metadata": dataset.metadata}))
        else:
            _report(dataset, self.path)
        return 0


@dataclass(frozen=True, kw_only=True)
class DatasetMix(_WritesDataset):
    """expert/random mixture by whole episodes (RQ5)"""

    name = "dataset mix"
    expert: Path = setting(REQUIRED, "the expert dataset")
    random: Path = setting(REQUIRED, "the random dataset")
    ratio: float = setting(REQUIRED, "expert fraction in [0, 1]")
    size: int = setting(REQUIRED, "transitions", minimum=1)
    seed: int = setting(0, "seeds the episodes drawn", minimum=0)

    def run(self, command: str) -> int:
        from gcdt.data import load_dataset, mix

        check_writable(self.out)
        expert, random = load_dataset(self.expert), load_dataset(self.random)
        mixed = mix(expert, random, self.ratio, self.size, self.seed)
        _report(mixed, mixed.save(self.out))
        return 0


@dataclass(frozen=True, kw_only=True)
class DatasetSubset(_WritesDataset):
    """random whole episodes, about --size transitions (RQ4)"""

    name = "dataset subset"
    path: Path = setting(REQUIRED, "the dataset", positional=True)
    size: int = setting(REQUIRED, "transitions", minimum=1)
    seed: int = setting(0, "seeds the episodes drawn", minimum=0)

    def run(self, command: str) -> int:
        from gcdt.data import load_dataset, subset

        check_writable(self.out)
        part = subset(load_dataset(self.path), self.size, self.seed)
        _report(part, part.save(self.out))
        return 0


@dataclass(frozen=True, kw_only=True)
class DatasetExportMinari(_Command):
    """write a dataset as a local Minari dataset"""

    name = "dataset export-minari"
    path: Path = setting(REQUIRED, "the dataset", positional=True)
    id: str | None = setting(None, "Minari id (default panda-gym/<task>/<policy>-v0)")
    reward: RewardType = setting("sparse", "the rewards stored")

    def run(self, command: str) -> int:
        from gcdt.data import export_minari, load_dataset

        exported = export_minari(load_dataset(self.path), self.id, reward=self.reward)
        print(
            f"exported {exported.total_steps} steps in {exported.total_episodes} episodes "
            f"as Minari dataset {exported.spec.dataset_id!r}"
        )
        return 0


@dataclass(frozen=True, kw_only=True)
class DatasetImportMinari(_WritesDataset):
    """read a local Minari dataset"""

    name = "dataset import-minari"
    id: str = setting(REQUIRED, "the Minari id", positional=True)

    def run(self, command: str) -> int:
        from gcdt.data import import_minari

        check_writable(self.out)
        dataset = import_minari(self.id)
        _report(dataset, dataset.save(self.out))
        return 0


@dataclass(frozen=True, kw_only=True)
class DatasetImportAuthors(_WritesDataset):
    """read the authors' pickled list of episode dicts"""

    name = "dataset import-authors"
    pickle: Path = setting(REQUIRED, "the authors' pickle", positional=True)
    task: str | None = setting(None, "needed only when widths are ambiguous", choices=TASKS)
    trust_pickle: bool = setting(
        False, "allow unpickling, which runs code from the file: only for trusted files"
    )

    def run(self, command: str) -> int:
        from gcdt.data import import_authors

        check_writable(self.out)
        dataset = import_authors(self.pickle, trust_pickle=self.trust_pickle, task=self.task)
        _report(dataset, dataset.save(self.out))
        return 0


@dataclass(frozen=True, kw_only=True)
class DatasetExportAuthors(_Command):
    """write a dataset in the authors' pickle format"""

    name = "dataset export-authors"
    source: str = setting(REQUIRED, "a dataset: PATH.npz or a Minari id", positional=True)
    out: Path = setting(REQUIRED, "the pickle to write", metavar="PATH.pkl")
    reward: RewardType = setting("sparse", "the rewards stored")

    def run(self, command: str) -> int:
        from gcdt.data import export_authors
        from gcdt.experiments.release import load_source

        check_writable(self.out)
        dataset = load_source(self.source)
        path = export_authors(dataset, self.out, reward=self.reward)
        print(f"wrote {dataset.n_episodes} episodes ({self.reward} rewards) to {path}")
        return 0


@dataclass(frozen=True, kw_only=True)
class DatasetBuild(_Command):
    """build a profile's datasets as Minari datasets (make datasets)

    Build every expert and random dataset of a profile as Minari datasets in
    $MINARI_DATASETS_PATH (default artifacts/minari), then check them against the profile's
    manifest results/PROFILE/datasets.json, or write it where it has none."""

    name = "dataset build"
    profile: str = setting(REQUIRED, "the profile whose datasets to build", choices=PROFILES)
    write_manifest: bool = setting(
        False, "(maintainers) record these datasets as the manifest, replacing the committed one"
    )

    def run(self, command: str) -> int:
        from gcdt.experiments import get_profile
        from gcdt.experiments.release import build, manifest_path
        from gcdt.paths import minari_dir

        profile = get_profile(self.profile)
        print(f"MINARI_DATASETS_PATH={minari_dir()}")
        for entry in build(profile, write_manifest=self.write_manifest):
            print(
                f"{entry['id']}: {entry['transitions']:,} transitions, "
                f"{entry['episodes']:,} episodes"
            )
        print(f"manifest: {manifest_path(profile)}")
        return 0


@dataclass(frozen=True, kw_only=True)
class DatasetVerify(_Command):
    """check a profile's Minari datasets against its manifest

    Hash every file of the profile's datasets (building those not built yet) and compare with
    results/PROFILE/datasets.json."""

    name = "dataset verify"
    profile: str = setting(
        REQUIRED, "the profile whose datasets to check", choices=PROFILES, positional=True
    )

    def run(self, command: str) -> int:
        from gcdt.experiments import get_profile
        from gcdt.experiments.release import verify

        lines = verify(get_profile(self.profile))
        print("\n".join(lines))
        print(f"verified {len(lines)} datasets of profile {self.profile}: every file matches")
        return 0


@dataclass(frozen=True, kw_only=True)
class DatasetCard(_Command):
    """regenerate docs/datasets.md from the manifests"""

    name = "dataset card"

    def run(self, command: str) -> int:
        from gcdt.experiments.release import CARD, write_card

        print(f"{CARD} {'written' if write_card() else 'unchanged'}")
        return 0


@dataclass(frozen=True, kw_only=True)
class Train(_Command, _Progress):
    """train GC-DT, a DT ablation or BC on a dataset

    Train from an offline dataset with the paper's recipe; writes a checkpoint (usable as
    evaluate --policy) and the training log into --out."""

    name = "train"
    dataset: str = setting(REQUIRED, "a .npz file or a Minari id", metavar="PATH.npz|MINARI_ID")
    out: Path = setting(REQUIRED, "the folder to write into", metavar="DIR")
    task: str | None = setting(None, "refuse a dataset of another task", choices=TASKS)
    config: TrainConfig
    resume: bool = setting(False, "continue from the checkpoint in --out")

    @staticmethod
    def names() -> dict[str, Any]:
        from gcdt.training import TrainConfig

        return {"TrainConfig": TrainConfig}

    def run(self, command: str) -> int:
        from gcdt.experiments.release import load_source
        from gcdt.training import train

        check_writable(self.out, folder=True)
        dataset = load_source(self.dataset)
        if self.task is not None and dataset.task != self.task:
            raise GcdtError(f"{self.dataset} holds {dataset.task!r} data, not {self.task!r}")
        result = train(
            dataset, self.config, self.out, resume=self.resume, progress=not self.no_progress
        )
        print(
            f"trained {result.steps} steps in {result.seconds:.0f} s, final loss "
            f"{result.final_loss:.4f}: {result.checkpoint}"
        )
        return 0


@dataclass(frozen=True, kw_only=True)
class TQCTrain(_Command, _Progress):
    """train TQC+HER online on one task and reward

    Train TQC with HER (hyperparameters and loop: gcdt/baselines/tqc_her.yaml), evaluating it
    periodically; writes the last and the best model, the learning curve and run.json to
    --out."""

    name = "tqc train"
    task: str = setting(REQUIRED, "the task", choices=TASKS)
    reward: RewardType = setting(REQUIRED, "the rewards it learns from")
    out: Path = setting(REQUIRED, "the folder to write into", metavar="DIR")
    config: str = setting(
        "paper",
        "paper: rl-baselines3-zoo her-defaults (GPU-scale); cpu: smaller nets and batches; "
        "others: gcdt/baselines/tqc_her.yaml",
        choices=tqc_config_names,
    )
    steps: int | None = setting(None, "env steps (default: the config's)")
    backend: str | None = setting(
        None,
        "sbx: SBX's JAX TQC; sb3: sb3-contrib's, rl-baselines3-zoo's loop (default: the config's)",
        choices=TQC_BACKENDS,
    )
    n_envs: int | None = setting(None, "envs side by side (default: the config's)", metavar="N")
    settings: TQCRunSettings
    resume: bool = setting(
        False, "continue the run in --out from its checkpoint (same command otherwise)"
    )

    def run(self, command: str) -> int:
        from gcdt.baselines.tqc_her import load_tqc_config, train_tqc

        check_writable(self.out, folder=True)
        changes = {"steps": self.steps, "backend": self.backend, "n_envs": self.n_envs}
        cfg = load_tqc_config(self.config, self.task).with_budget(
            **{k: v for k, v in changes.items() if v is not None}
        )
        result = train_tqc(
            self.task,
            self.reward,
            cfg,
            self.out,
            progress=not self.no_progress,
            command=command,
            resume=self.resume,
            **dataclasses.asdict(self.settings),
        )
        print(
            f"TQC+HER {self.task}/{self.reward} ({cfg.name}): {result.env_steps} env steps in "
            f"{result.train_seconds:.0f} s ({result.env_steps_per_second:.1f} steps/s), "
            f"final success {100 * result.final_success_rate:.0f} %, "
            f"best {100 * result.best_success_rate:.0f} %: {result.model}"
        )
        return 0


def _tqc_run_dir(which: str) -> Any:
    """The RUN_DIR argument of the commands that read a `gcdt tqc train` run's folder."""
    return setting(REQUIRED, f"the --out folder of {which}", metavar="RUN_DIR", positional=True)


@dataclass(frozen=True, kw_only=True)
class TQCPublish(_Command):
    """publish a finished TQC+HER run as an agent in results/experts/

    Measure the run's final and best model on validation episodes, keep the better, measure it
    on held-out episodes, and write model.zip, eval.csv and run.json (with both measurements)
    to --out. An agent already there is replaced only with --replace, in one swap."""

    name = "tqc publish"
    run_dir: Path = _tqc_run_dir("a finished gcdt tqc train run")
    out: Path | None = setting(
        None,
        "the agent's folder (default: results/experts/tqc_TASK_REWARD, with _seedS after it "
        "for a seed other than 0)",
        metavar="DIR",
    )
    replace: bool = setting(
        False, "replace the agent of the same task, reward and seed already published in --out"
    )
    config: PublishConfig

    def run(self, command: str) -> int:
        from gcdt.baselines.publish import publish_agent

        out = publish_agent(self.run_dir, self.out, self.config, replace=self.replace)
        record = json.loads((out / RUN_JSON).read_text())
        held_out = record["published"]["held_out"]
        print(
            f"TQC+HER {record['task']}/{record['reward']}, {record['env_steps']} env steps "
            f"({record['published']['model']} model): {100 * held_out['success_rate']:.1f} % "
            f"success, return {held_out['mean_return']:.2f} on {held_out['episodes']} "
            f"held-out episodes: {out}"
        )
        return 0


@dataclass(frozen=True, kw_only=True)
class TQCSnapshot(_Command):
    """keep a TQC+HER run in progress in a few MiB, to resume on another machine

    Write the run's checkpoint without its replay buffer, and its curve, to --out, replacing
    an older snapshot of the same run. Copy them into a run folder and resume with gcdt tqc
    train --resume: the run refills its buffer, records that it did, and finds its best model
    again from the next evaluation on."""

    name = "tqc snapshot"
    run_dir: Path = _tqc_run_dir("a gcdt tqc train run in progress")
    out: Path | None = setting(
        None,
        "the snapshot's folder (default: results/experts/in_progress/tqc_TASK_REWARD_seedS)",
        metavar="DIR",
    )

    def run(self, command: str) -> int:
        from gcdt.baselines.publish import snapshot_run

        out, header = snapshot_run(self.run_dir, self.out)
        mib = sum(f.stat().st_size for f in out.iterdir()) / 2**20
        print(
            f"TQC+HER {header['task']}/{header['reward']} seed {header['seed']} at "
            f"{header['env_steps']:,} env steps, without its replay buffer ({mib:.1f} MiB): {out}"
        )
        return 0


_PROFILE_HELP = "the size of the grid (docs/experiments.md)"


@dataclass(frozen=True, kw_only=True)
class Sweep(_Command, _Progress):
    """run the experiment grid of a profile (skips finished runs)

    Run every run of a profile's grid whose result is not in results/PROFILE/runs/ yet (under
    $GCDT_OUTPUTS when set, else the repository's); failed and untrusted results are run
    again."""

    name = "sweep"
    profile: str = setting(REQUIRED, _PROFILE_HELP, choices=PROFILES)
    backend: str = setting("local", "a process pool, or Ray", choices=BACKENDS)
    address: str | None = setting(None, "Ray cluster address HOST:PORT (default: a local Ray)")
    storage: str | None = setting(
        None,
        "URI the Ray nodes share artifacts through, e.g. s3://bucket/gcdt (default: each node "
        "makes its own in its $GCDT_ARTIFACTS)",
    )
    retries: int = setting(RETRIES, "times a failed run is tried again", minimum=0)
    only: str | None = setting(None, "one section of the grid", choices=SECTIONS)
    task: str | None = setting(None, "one task's runs of the grid", choices=TASKS)
    workers: int | None = setting(None, "parallel runs (default: cores)", minimum=1)
    dry_run: bool = setting(False, "list the runs, their state and estimated cost")
    estimate_on: str = setting(
        "cpu",
        "the dry run's rates: this kind of CPU machine's, or a GPU's (results/bench/*_cuda.json)",
        choices=("cpu", "cuda"),
    )

    def run(self, command: str) -> int:
        from gcdt.experiments import get_profile, results_dir, sweep

        profile = get_profile(self.profile)
        if self.dry_run:
            return self._dry_run(profile)
        if self.estimate_on != "cpu":
            raise GcdtError("--estimate-on sets the rates of --dry-run: add --dry-run")
        from gcdt.paths import artifacts_dir

        # Before hours of runs, not after the first one.
        check_writable(results_dir(profile.name) / "runs", folder=True, option="results folder")
        check_writable(artifacts_dir(), folder=True, option="artifacts folder (GCDT_ARTIFACTS)")
        summary = sweep(
            profile,
            backend=self.backend,
            address=self.address,
            storage=self.storage,
            retries=self.retries,
            only=self.only,
            task=self.task,
            workers=self.workers,
            progress=not self.no_progress,
        )
        for warning in summary.warnings:
            print(f"warning: {warning}", file=sys.stderr)
        print("\n".join(summary.lines()))
        # Runs left waiting: the profile is not done, and `make reproduce` must not go on.
        return 0 if summary.ok and not summary.waiting else 1

    def _dry_run(self, profile) -> int:
        from gcdt.experiments import plan, results_dir
        from gcdt.experiments.costs import CostModel
        from gcdt.experiments.store import RunStore
        from gcdt.experiments.sweep import (
            default_workers,
            section_costs,
            shared_cost,
            wall_estimate,
        )

        # Reads the bench JSON and the results once.
        costs = CostModel.measured(profile.name, on=self.estimate_on)
        store = RunStore(results_dir(profile.name) / "runs")
        planned, warnings = plan(profile, store, self.only, costs, task=self.task)
        for warning in warnings:
            print(f"warning: {warning}", file=sys.stderr)
        for p in planned:
            resumes = f" (checkpoint here at step {p.done_steps:,})" if p.done_steps else ""
            print(
                f"{p.key}  {p.state:<8} {p.estimate_seconds / 60:8.1f} min  "
                f"{p.entry.spec.label}  [{', '.join(p.entry.sections)}]{resumes}"
            )
        todo = [p for p in planned if p.state != "done"]
        workers = self.workers or default_workers(profile)
        # How the estimates were scaled comes before the totals built from them.
        if costs.cpu:
            cpu, factor, n = costs.cpu
            print(
                f"this CPU ({cpu}) takes {factor:.2f}x as long per gradient step as the other"
                f" machines of the finished runs (median of {n} rates): their rates are scaled"
            )
        shared = shared_cost(todo, costs)
        for section, (runs, waiting, seconds) in section_costs(todo).items():
            also = f" ({waiting} of them waiting)" if waiting else ""
            print(
                f"section {section}: {runs} runs to run{also}, about {seconds / 3600:.1f} h of work"
            )
        print(f"datasets and TQC+HER experts to make: about {shared / 3600:.1f} h of work")
        if waiting := [p for p in todo if p.state == "waiting"]:
            agents = sorted({p.problem for p in waiting})
            print(f"{len(waiting)} of them wait for published agents: {'; '.join(agents)}")
        total = sum(p.estimate_seconds for p in todo) + shared
        wall = wall_estimate(todo, workers, shared)
        spread = f"{wall / 3600:.1f} h on {workers} worker(s) (estimate)"
        if costs.gpu:  # runs on one GPU share it rather than add up
            spread = f"one run after another on one {costs.gpu} (estimate)"
        print(
            f"{len(planned)} runs, {len(todo)} to run: about {total / 3600:.1f} h of work, "
            + spread
        )
        return 0


@dataclass(frozen=True, kw_only=True)
class Report(_Command):
    """tables and figures of the paper from results/PROFILE/runs/

    Write Table 1 and the ablation table (CSV, Markdown, LaTeX), Fig. 2-4 and the learning
    curves (PNG, PDF) from a profile's finished runs, and results/experts/table1_tqc.{md,csv}
    from the published TQC+HER agents (results/ and figures/ under $GCDT_OUTPUTS when set,
    else the repository's)."""

    name = "report"
    profile: str = setting(REQUIRED, _PROFILE_HELP, choices=PROFILES)
    readme: bool = setting(False, "also update README.md's results")
    wall_seconds: float | None = setting(
        None,
        "record S as the wall time of the `make reproduce` that made these results "
        "(results/PROFILE/reproduce.json)",
        metavar="S",
    )
    backend: str = setting(
        "local", "the backend of that `make reproduce` (with --wall-seconds)", choices=BACKENDS
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.wall_seconds is not None and not self.wall_seconds >= 0:  # NaN fails too
            raise GcdtError(f"--wall-seconds must be >= 0, got {self.wall_seconds}")

    def run(self, command: str) -> int:
        from gcdt.experiments import get_profile
        from gcdt.paths import REPO_ROOT
        from gcdt.report import record_reproduction, update_readme, write_report

        measured_at = dt.datetime.now(dt.UTC)  # when make measured --wall-seconds, near enough
        profile = get_profile(self.profile)
        written: list[Path] = []
        if self.wall_seconds is not None:  # first: report.md prints the record
            wall, backend = self.wall_seconds, self.backend
            written.append(record_reproduction(profile, wall, backend, measured_at=measured_at))
        written += write_report(profile)
        for path in written:
            print(path.relative_to(REPO_ROOT) if path.is_relative_to(REPO_ROOT) else path)
        if self.readme:
            update_readme(profile, REPO_ROOT / "README.md")
            print("README.md")
        return 0


def _reproduction_dir(given: Path | None) -> Path:
    """A reproduction's folder: the one given, else $GCDT_OUTPUTS, else artifacts/reproduce."""
    from gcdt.paths import reproduction_root

    folder = given or reproduction_root()
    if not folder.is_dir():
        raise GcdtError(f"{folder} does not exist: run `make reproduce` first, or give its folder")
    return folder


_REPRODUCTION_HELP = "the reproduction's folder (default: $GCDT_OUTPUTS, else artifacts/reproduce)"


@dataclass(frozen=True, kw_only=True)
class Compare(_Command):
    """check a reproduction against the published results

    For every Table 1 cell, ablation cell and Fig. 3/4 point: the published value, yours, the
    difference with its 95 % interval (Welch, from both runs' seeds), and whether that interval
    contains 0. Writes results/PROFILE/reproduction_check.{csv,md} under --ours."""

    name = "compare"
    profile: str = setting(REQUIRED, _PROFILE_HELP, choices=PROFILES)
    ours: Path | None = setting(
        None, _REPRODUCTION_HELP + ", holding results/PROFILE/runs/", metavar="DIR"
    )

    def run(self, command: str) -> int:
        from gcdt.experiments import get_profile
        from gcdt.report.reproduction import write_check

        text, path = write_check(get_profile(self.profile), _reproduction_dir(self.ours))
        print(text.rstrip())
        if path is not None:
            print(f"\n(written to {path})")
        return 0


@dataclass(frozen=True, kw_only=True)
class Publish(_Command):
    """(maintainers) make a finished reproduction the published results

    Mirror results/PROFILE/ and figures/PROFILE/ of a finished reproduction into the
    repository's; unchanged files are left untouched."""

    name = "publish"
    profile: str = setting(REQUIRED, _PROFILE_HELP, choices=PROFILES)
    source: Path | None = setting(None, _REPRODUCTION_HELP, flag="--from", metavar="DIR")

    def run(self, command: str) -> int:
        from gcdt.experiments import get_profile
        from gcdt.paths import REPO_ROOT
        from gcdt.report.reproduction import publish

        written, removed = publish(get_profile(self.profile), _reproduction_dir(self.source))
        for path in written:
            print(path.relative_to(REPO_ROOT))
        for path in removed:
            print(f"removed {path.relative_to(REPO_ROOT)}")
        print(f"published {self.profile}: {len(written)} file(s) written, {len(removed)} removed")
        return 0


COMMANDS: tuple[type[_Command], ...] = (
    Evaluate,
    Rollout,
    Collect,
    DatasetInfo,
    DatasetMix,
    DatasetSubset,
    DatasetExportMinari,
    DatasetImportMinari,
    DatasetImportAuthors,
    DatasetExportAuthors,
    DatasetBuild,
    DatasetVerify,
    DatasetCard,
    Train,
    TQCTrain,
    TQCPublish,
    TQCSnapshot,
    Sweep,
    Report,
    Compare,
    Publish,
)


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="gcdt",
        description="Goal-Conditioned Decision Transformer on panda-gym: datasets and evaluation.",
    )
    subparsers = {"": parser.add_subparsers(dest="command", required=True, parser_class=_Parser)}
    for command in COMMANDS:
        group, _, name = command.name.rpartition(" ")
        if group not in subparsers:
            grouped = subparsers[""].add_parser(group, help=GROUPS[group])
            subparsers[group] = grouped.add_subparsers(
                dest=f"{group}_command", required=True, parser_class=_Parser
            )
        doc = inspect.cleandoc(command.__doc__ or "")
        subparsers[group].add_parser(
            name,
            help=doc.splitlines()[0],
            description=doc,
            formatter_class=argparse.RawDescriptionHelpFormatter,
            arguments=lambda p, c=command: add_options(p, c, c.names()),
        ).set_defaults(options=command)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `gcdt` console script; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parsed = vars(_build_parser().parse_args(argv))
    command = parsed["options"]
    try:
        options = from_options(parsed, command, command.names())
        return options.run(" ".join(["gcdt", *argv]))  # recorded in the files it writes
    except GcdtError as err:
        print(f"gcdt: error: {err}", file=sys.stderr)
        return USAGE_ERROR

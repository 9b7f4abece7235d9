"""The experiment grid as data: every run of Table 1, RQ4, RQ5 and the ablations.

A run is a frozen `RunSpec`: method, task, reward, seed, the data it learns from, its training
and evaluation settings. Its key is a hash of everything the run computes from, resolved: the
whole `TrainConfig` the trainer gets (defaults and model shape included), the TQC+HER config's
values (not its name), the data with its expert's resolved config, the evaluation settings, and
`RUN_SCHEMA`. So a changed default re-runs exactly the runs it reaches, a run that appears in
two sections (Table 1's GC-DT is also RQ4's largest subset and RQ5's 100 % point) is one run,
and a result file can be matched to exactly the config that produced it.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gcdt import paper
from gcdt.baselines.tqc_her import TQCConfig, load_tqc_config
from gcdt.errors import GcdtError
from gcdt.experiments.profiles import EVAL_SEED_STEP, SECTIONS, Profile, target_seeds
from gcdt.methods import OFFLINE_METHODS
from gcdt.paths import REPO_ROOT
from gcdt.policies import TQC_PREFIX

if TYPE_CHECKING:
    from gcdt.training import TrainConfig

#: Bump when the meaning of a spec field or of a result file changes: old results re-run. A
#: changed value (a default, a tqc_her.yaml entry) needs no bump: the keys hash the values.
#: 3: data specs name the scripted experts' action noise. 4: TQC+HER's configs run SBX's TQC
#: on 8 envs (tqc_her.yaml's loop values); episode seeds come from one stream per purpose;
#: BC's budget follows `Profile.bc_budget`. 5: faster scripted experts (shorter episodes).
RUN_SCHEMA = 5
#: A published agent's digest while the agent a profile names is not published yet (or is not
#: of the profile's `agent_steps`): the data it would collect, and every run on it, wait.
PENDING = "pending"
#: The goal-generalisation study's methods: both learn from the same region's expert data.
GENERALISATION_METHODS = ("gcdt", "bc")
#: The RunSpec fields of evaluation: runs that differ only in them share what they train.
EVALUATION_FIELDS = ("eval_timesteps", "eval_seeds", "eval_envs", "target_return", "eval_region")
#: The grid's methods: the offline ones (`gcdt.methods`), and `tqc`, the online baseline.
METHODS = (*OFFLINE_METHODS, "tqc")
TABLE1_METHODS = ("gcdt", "bc", "tqc")
ABLATION_METHODS = ("dt", "dt-desired")


def content_key(payload: Any) -> str:
    """A short stable hash of a JSON-serialisable payload (sorted keys)."""
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclass(frozen=True, kw_only=True)
class TQCSpec:
    """A TQC+HER training run (the baseline, or the agent that collects expert data)."""

    task: str
    reward: str
    config: str  # name in tqc_her.yaml
    steps: int | None  # None: the config's steps for the task
    budget: tuple[tuple[str, Any], ...]  # further budget changes, sorted (key, value) pairs
    seed: int
    eval_every: int | None  # learning-curve points (they also pick best_model.zip)
    eval_episodes: int

    def tqc_config(self) -> TQCConfig:
        """The config the agent trains with: the named one, with the budget and steps."""
        changes = dict(self.budget)
        if self.steps is not None:
            changes["steps"] = self.steps
        return load_tqc_config(self.config, self.task).with_budget(**changes)

    def resolved(self) -> dict[str, Any]:
        """What the agent computes from: the config's values stand for its name, budget and
        steps (the name and what it overrides in `paper` are labels, not inputs)."""
        config = self.tqc_config().to_dict()
        for label in ("name", "overrides"):
            del config[label]
        own = {k: v for k, v in dataclasses.asdict(self).items() if k not in _TQC_CONFIG_FIELDS}
        return {**own, "config": config}

    def key(self) -> str:
        return content_key({"tqc": self.resolved(), "schema": RUN_SCHEMA})


#: TQCSpec fields that only pick the config, which `TQCSpec.resolved` holds by value.
_TQC_CONFIG_FIELDS = ("config", "steps", "budget")


@dataclass(frozen=True, kw_only=True)
class DataSpec:
    """An offline dataset: expert and random collections of `base_size` transitions, then the
    whole expert data (`size == base_size`, ratio 1), an expert subset (RQ4) or a mixture (RQ5).
    """

    task: str
    size: int
    expert_ratio: float
    expert: str  # "scripted" or "tqc"
    expert_tqc: TQCSpec | None  # the TQC agent when expert == "tqc"
    expert_noise: float  # action noise std of the scripted expert while collecting
    expert_labels: str  # with noise: the action recorded, "executed" or "clean" (DART)
    base_size: int
    seed: int
    collect_envs: int
    #: With expert "tqc:PATH" (a published agent): the zip's content hash, so that another
    #: agent at the same path makes other data.
    expert_digest: str | None = None
    #: The goal region (`gcdt.regions.GoalRegion` text) the expert collection's goals come
    #: from; None: the task's whole goal range.
    goal_region: str | None = None

    def resolved(self) -> dict[str, Any]:
        """What the data is made from: the spec, with its TQC+HER expert resolved."""
        expert = None if self.expert_tqc is None else self.expert_tqc.resolved()
        return {**dataclasses.asdict(self), "expert_tqc": expert}

    def key(self) -> str:
        return content_key({"data": self.resolved(), "schema": RUN_SCHEMA})

    @property
    def is_base(self) -> bool:
        """A collection (expert or random), not derived from one."""
        return (
            self.size == self.base_size
            and self.expert_ratio in (0.0, 1.0)
            and ((self.expert == "random") == (self.expert_ratio == 0.0))
        )

    @property
    def waits_for(self) -> str | None:
        """The published agent this data waits for, or None when it can be made."""
        if self.expert_digest == PENDING:
            return self.expert.removeprefix(TQC_PREFIX)
        return None

    def base(self, kind: str) -> DataSpec:
        """The `"expert"` or `"random"` collection that this data is drawn from."""
        if kind == "random":
            return dataclasses.replace(
                self,
                size=self.base_size,
                expert_ratio=0.0,
                expert="random",
                expert_tqc=None,
                expert_noise=0.0,
                expert_labels="executed",
                expert_digest=None,
                goal_region=None,
            )
        return dataclasses.replace(self, size=self.base_size, expert_ratio=1.0)


@dataclass(frozen=True, kw_only=True)
class RunSpec:
    """One run: train (or, for `tqc`, learn online) and evaluate one agent."""

    method: str  # one of METHODS
    task: str
    reward: str
    seed: int
    data: DataSpec | None  # None for the online TQC+HER baseline
    train_steps: int | None  # offline gradient steps; None: the paper's epochs
    learning_rate: float | None  # offline training's peak learning rate; None for `tqc`
    tqc: TQCSpec | None
    eval_timesteps: int
    eval_seeds: tuple[int, ...]
    eval_envs: int
    threads: int  # torch threads; part of the key since float results may depend on it
    #: A DT's return-to-go at each evaluation episode's start.
    target_return: float = paper.TARGET_RETURN
    eval_region: str | None = None  # the goal region evaluated in (None: the whole range)

    def train_config(self) -> TrainConfig:
        """The config offline training runs with (`artifacts.checkpoint`), every other field
        at `TrainConfig`'s default."""
        from gcdt.training import TrainConfig  # torch: not for `gcdt --help`

        if self.method not in OFFLINE_METHODS:
            raise GcdtError(f"{self.method} is not an offline method: it has no TrainConfig")
        method, conditioning = OFFLINE_METHODS[self.method]
        return TrainConfig(
            method=method,
            goal_conditioning=conditioning,
            reward=self.reward,
            steps=self.train_steps,
            lr=self.learning_rate,
            seed=self.seed,
        )

    def resolved(self) -> dict[str, Any]:
        """Everything the run computes from, as its key hashes it: the spec, with the data,
        the TQC+HER config and the training config (every field, the model's whole shape)
        resolved to their values."""
        out = {k: v for k, v in self.to_dict().items() if k not in _TRAIN_CONFIG_FIELDS}
        out["data"] = None if self.data is None else self.data.resolved()
        out["tqc"] = None if self.tqc is None else self.tqc.resolved()
        out["train"] = None if self.method == "tqc" else _trainer_inputs(self.train_config())
        return out

    def key(self) -> str:
        return content_key({"run": self.resolved(), "schema": RUN_SCHEMA})

    def training_key(self) -> str:
        """The key of what the run trains: runs that differ only in how they are evaluated
        (the return-target study's targets, the generalisation study's regions) share one
        checkpoint."""
        trained = {k: v for k, v in self.resolved().items() if k not in EVALUATION_FIELDS}
        return content_key({"training": trained, "schema": RUN_SCHEMA})

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RunSpec:
        def tqc(t: dict | None) -> TQCSpec | None:
            if t is None:
                return None
            return TQCSpec(**{**t, "budget": tuple(tuple(kv) for kv in t["budget"])})

        data = d["data"]
        if data is not None:
            data = DataSpec(**{**data, "expert_tqc": tqc(data["expert_tqc"])})
        return cls(
            **{**d, "data": data, "tqc": tqc(d["tqc"]), "eval_seeds": tuple(d["eval_seeds"])}
        )

    @property
    def waits_for(self) -> str | None:
        """The published agent the run's data waits for, or None when it can run."""
        return None if self.data is None else self.data.waits_for

    @property
    def label(self) -> str:
        """A readable one-line name for listings and progress output."""
        how = f" at target {self.target_return:g}" if self.target_return else ""
        if self.eval_region is not None:
            how += f" evaluated in {self.eval_region}"
        return f"{self.method} {self.task}/{self.reward} seed {self.seed} ({self._data_label}){how}"

    @property
    def _data_label(self) -> str:
        if self.data is None:
            where = "online"
        elif self.data.is_base:
            where = f"{self.data.size:,} expert"
            if self.data.goal_region is not None:
                where += f" with goals in {self.data.goal_region}"
        elif self.data.expert_ratio == 1.0:
            where = f"{self.data.size:,} expert subset"
        else:
            where = f"{self.data.size:,} at {self.data.expert_ratio:.0%} expert"
        return where


#: RunSpec fields that set the training config, which `RunSpec.resolved` holds by value.
_TRAIN_CONFIG_FIELDS = ("train_steps", "learning_rate")


def _trainer_inputs(cfg: TrainConfig) -> dict[str, Any]:
    """Every field of `cfg` but when checkpoints are written, and the model's whole shape
    (`max_episode_steps` too, which no TrainConfig field sets)."""
    from gcdt.training import SCHEDULING_FIELDS

    out = {k: v for k, v in dataclasses.asdict(cfg).items() if k not in SCHEDULING_FIELDS}
    shape = cfg.model_config(state_dim=0, action_dim=0)  # the dims follow from task and data
    out["model"] = {k: v for k, v in shape.items() if k not in ("state_dim", "action_dim")}
    return out


@dataclass(frozen=True)
class GridEntry:
    """A run and the sections (and the x-value within each) that use it."""

    spec: RunSpec
    sections: tuple[str, ...]


def _budget(profile: Profile) -> tuple[tuple[str, Any], ...]:
    return tuple(
        sorted((k, tuple(v) if isinstance(v, list) else v) for k, v in profile.tqc_budget.items())
    )


def expert_tqc_spec(profile: Profile, task: str) -> TQCSpec:
    """The TQC+HER agent that collects `task`'s expert data: sparse rewards, the config's steps."""
    return TQCSpec(
        task=task,
        reward="sparse",
        config=profile.tqc_config,
        steps=None,
        budget=_budget(profile),
        seed=profile.data_seed,
        eval_every=profile.tqc_eval_every,
        eval_episodes=profile.tqc_eval_episodes,
    )


def data_spec(
    profile: Profile, task: str, size: int, expert_ratio: float, goal_region: str | None = None
) -> DataSpec:
    expert, noise, digest = profile.expert, float(profile.expert_noise), None
    if task in profile.expert_agents:  # a published agent collects this task's expert data
        expert, noise = f"tqc:{profile.expert_agents[task]}", 0.0
        path = REPO_ROOT / profile.expert_agents[task]
        ready = agent_steps(path.parent) == profile.agent_steps or profile.agent_steps is None
        digest = file_digest(path) if path.is_file() and ready else PENDING
    expert_tqc = expert_tqc_spec(profile, task) if expert == "tqc" else None
    return DataSpec(
        task=task,
        size=int(size),
        expert_ratio=float(expert_ratio),
        expert=expert,
        expert_tqc=expert_tqc,
        expert_noise=noise,
        expert_labels=profile.expert_labels if noise else "executed",
        base_size=profile.dataset_size,
        seed=profile.data_seed,
        collect_envs=profile.collect_envs,
        expert_digest=digest,
        goal_region=goal_region,
    )


def agent_steps(agent: Path) -> int | None:
    """The online steps the published agent in folder `agent` trained for (None: none there)."""
    from gcdt.baselines.publish import read_agent

    record = read_agent(agent)
    return None if record is None else record["env_steps"]


def file_digest(path: Path) -> str:
    """The content hash of a published file the grid depends on (16 hex digits)."""
    if not path.is_file():
        raise GcdtError(f"no published expert agent at {path}: fix the profile's expert_agents")
    stat = path.stat()
    return _digest(str(path.resolve()), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=64)
def _digest(path: str, mtime_ns: int, size: int) -> str:
    # Every data spec of a task asks for its agent's hash: read the file once per version
    # of it (a replaced agent has another mtime or size, and is hashed again).
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def bc_steps(profile: Profile, dt_steps: int | None, data: DataSpec) -> int | None:
    """BC's gradient steps beside a DT's `dt_steps` (None: the paper's epochs) under the
    profile's BC budget rule (see `BC_BUDGETS`)."""
    if profile.bc_budget == "steps":
        return dt_steps
    from gcdt.training import TrainConfig  # torch: not for `gcdt --help`

    # The context K and the batch of offline training: the paper's, which the grid keeps.
    context, batch = TrainConfig.context, TrainConfig.batch_size
    # "samples": a DT step learns from `batch` windows of K state-action pairs, a BC step from
    # `batch` pairs, so BC takes K times the DT's steps; under the paper's epoch budget that
    # is the same number of epochs over transitions as the DT's over episodes.
    if dt_steps is not None:
        return dt_steps * context
    return paper.EPOCHS * math.ceil(data.size / batch)


def run_spec(
    profile: Profile,
    method: str,
    task: str,
    reward: str,
    seed: int,
    data: DataSpec | None,
    target_return: float = paper.TARGET_RETURN,
    eval_seeds: tuple[int, ...] | None = None,
    eval_region: str | None = None,
    budget_factor: int = 1,
    table1: bool = False,
) -> RunSpec:
    """A run of `profile`, evaluated on its training seed's evaluation seeds unless
    `eval_seeds` says otherwise, trained for `budget_factor` times the profile's budget
    (Table 1's with `table1`)."""
    tqc = None
    if method == "tqc":
        steps = profile.tqc_steps if profile.tqc_steps is not None else profile.dataset_size
        tqc = TQCSpec(
            task=task,
            reward=reward,
            config=profile.tqc_config,
            steps=steps,
            budget=_budget(profile),
            seed=seed,
            eval_every=profile.tqc_eval_every,
            eval_episodes=profile.tqc_eval_episodes,
        )
    train_steps = None  # TQC+HER: online; the DTs: the profile's steps, or the paper's epochs
    if method != "tqc":
        train_steps = profile.dt_steps(task, table1)
    if method == "bc":
        train_steps = bc_steps(profile, train_steps, data)
    if train_steps is not None:
        train_steps *= budget_factor
    learning_rate = None if method == "tqc" else profile.learning_rate
    if eval_seeds is None:
        eval_seeds = tuple(seed + EVAL_SEED_STEP * i for i in range(profile.eval_seeds))
    return RunSpec(
        method=method,
        task=task,
        reward=reward,
        seed=seed,
        data=data,
        train_steps=train_steps,
        learning_rate=learning_rate,
        tqc=tqc,
        eval_timesteps=profile.eval_timesteps,
        eval_seeds=eval_seeds,
        eval_envs=profile.eval_envs,
        threads=profile.cpus_per_run,
        target_return=float(target_return),
        eval_region=eval_region,
    )


def build_grid(profile: Profile, only: str | None = None) -> list[GridEntry]:
    """Every run of `profile` (of one section with `only`), each once, in a stable order."""
    if only is not None and only not in SECTIONS:
        from gcdt.errors import GcdtError

        raise GcdtError(f"unknown grid section {only!r}: expected one of {', '.join(SECTIONS)}")
    entries: dict[str, tuple[RunSpec, list[str]]] = {}

    def add(section: str, spec: RunSpec) -> None:
        entries.setdefault(spec.key(), (spec, []))[1].append(section)

    p = profile
    for section in p.section_order if only is None else (only,):
        scope = getattr(p, section)
        for task in scope.tasks:
            full = data_spec(p, task, p.dataset_size, 1.0)
            for reward in scope.rewards:
                for seed in p.seeds:
                    if section == "table1":
                        for method in TABLE1_METHODS:
                            tqc_scope = p.table1_tqc
                            if method == "tqc" and not (
                                task in tqc_scope.tasks and reward in tqc_scope.rewards
                            ):
                                continue
                            data = None if method == "tqc" else full
                            spec = run_spec(p, method, task, reward, seed, data, table1=True)
                            add(section, spec)
                    elif section == "budget":
                        if seed == p.seeds[0]:  # one seed: the check, not a cell
                            for ratio, base in p.budget_bases(task):
                                data = data_spec(p, task, p.dataset_size, ratio)
                                spec = run_spec(
                                    p, "gcdt", task, reward, seed, data,
                                    budget_factor=p.budget_factor, table1=base == "table1",
                                )  # fmt: skip
                                add(section, spec)
                    elif section == "ablation":
                        # Set against Table 1's GC-DT: trained for Table 1's budget.
                        for method in ABLATION_METHODS:
                            spec = run_spec(p, method, task, reward, seed, full, table1=True)
                            add(section, spec)
                    elif section == "targets":
                        # Validation and test evaluations in one run: the study picks a target
                        # on the first and scores it on the second. Trained for Table 1's
                        # budget: each target re-evaluates Table 1's GC-DT checkpoint.
                        split = target_seeds(seed)
                        for target in p.return_targets[reward]:
                            spec = run_spec(
                                p, "gcdt", task, reward, seed, full, target, split, table1=True
                            )
                            add(section, spec)
                    elif section == "generalisation":
                        # Trained on one region's goals, evaluated inside it and outside it.
                        inside, outside = p.goal_regions
                        data = data_spec(p, task, p.dataset_size, 1.0, goal_region=inside)
                        for method in GENERALISATION_METHODS:
                            for region in (inside, outside):
                                spec = run_spec(
                                    p, method, task, reward, seed, data, eval_region=region
                                )
                                add(section, spec)
                    elif section == "rq4":
                        for size in p.rq4_sizes:
                            data = data_spec(p, task, size, 1.0)
                            add(section, run_spec(p, "gcdt", task, reward, seed, data))
                    else:  # rq5
                        for ratio in p.rq5_ratios:
                            data = data_spec(p, task, p.dataset_size, ratio)
                            add(section, run_spec(p, "gcdt", task, reward, seed, data))
    # In the sweep's order (the profile's priority): by first section, RQ5 by expert share.
    rank = {section: i for i, section in enumerate(p.section_order)}

    def priority(item: tuple[RunSpec, list[str]]) -> tuple[int, int]:
        spec, sections = item
        share = p.rq5_ratios.index(spec.data.expert_ratio) if sections[0] == "rq5" else 0
        return rank[sections[0]], share

    ordered = sorted(entries.values(), key=priority)  # stable: the loops' order within
    return [GridEntry(spec, tuple(sections)) for spec, sections in ordered]

"""TQC+HER, the paper's online baseline and the source of its expert datasets.

TQC with Stable-Baselines3's `HerReplayBuffer` on panda-gym, in one of two implementations by
the same maintainers (the `backend`): `sb3` is sb3-contrib's PyTorch TQC, the loop
rl-baselines3-zoo runs; `sbx` is SBX's JAX TQC, whose whole gradient step is one compiled
function, with its critic target's sort replaced by a mask (`gcdt/baselines/sbx_tqc.py`);
their speeds are measured by `python benchmarks/tqc_her.py throughput`
(results/bench/tqc_her_throughput.json). `n_envs`
envs step side by side and each loop iteration takes `n_envs` gradient steps, so the updates
per env step stay the zoo's. The hyperparameters live in `tqc_her.yaml` next to this file
(`paper` = rl-baselines3-zoo's her-defaults); a config or a profile may change budget and loop
values only, and every run records what it changed. During training the project's own evaluator
measures the current policy every `eval_every` env steps (success rate and return ->
`eval.csv`, for learning curves); the best and the last model are saved as SB3 zips that carry
the task, reward, config and backend they were trained with, and `run.json` records the
wall-clock time and env steps/s.

A run checkpoints itself every `checkpoint_seconds` (`tqc_checkpoint.py`); `resume=True`
carries on from the last checkpoint (the learner exactly, the envs up to state PyBullet keeps:
see that module), or from a snapshot without the replay buffer (`gcdt tqc snapshot`), which
refills the buffer.

Output folder: `model.zip` (last), `best_model.zip`, `eval.csv`, `run.json`, and while the run
is in progress `checkpoint.tqc`.
"""

from __future__ import annotations

import csv
import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from gcdt.baselines.tqc_checkpoint import (
    CHECKPOINT_FILE,
    check_identity,
    has_buffer,
    load_checkpoint,
    read_header,
    save_checkpoint,
)
from gcdt.envs import check_reward, get_task
from gcdt.errors import GcdtError
from gcdt.paths import atomic_write, write_json_atomic
from gcdt.provenance import TRACKED_PACKAGES, git_commit, package_versions, utc_now
from gcdt.settings import check_minimums, setting

CONFIG_FILE = Path(__file__).with_name("tqc_her.yaml")
#: Values a config other than `paper`, or a profile, may change: the compute budget...
BUDGET_KEYS = ("steps", "net_arch", "batch_size", "buffer_size", "learning_starts")
#: ...and the training loop, which leaves the algorithm and its updates per env step alone.
LOOP_KEYS = ("backend", "n_envs")
CHANGEABLE_KEYS = (*BUDGET_KEYS, *LOOP_KEYS)
#: backend -> whose TQC it is.
BACKENDS = {"sb3": "sb3-contrib, PyTorch", "sbx": "SBX, JAX"}
#: A run's files: the last and the best model, the learning curve, and the record written last.
MODEL_ZIP, BEST_MODEL_ZIP = "model.zip", "best_model.zip"
EVAL_CSV, RUN_JSON = "eval.csv", "run.json"
RUN_FILES = (MODEL_ZIP, BEST_MODEL_ZIP, EVAL_CSV, RUN_JSON)
EVAL_FIELDS = (
    "env_steps",
    "train_seconds",
    "wall_seconds",
    "success_rate",
    "mean_return",
    "episodes",
)
#: Evaluation episodes during training use seeds apart from those of `gcdt evaluate --seed 0`.
EVAL_SEED_OFFSET = 1000
#: Seconds between checkpoints: a resume repeats at most this much work.
CHECKPOINT_SECONDS = 120.0


@dataclass(frozen=True)
class TQCConfig:
    """TQC+HER hyperparameters for one task (see `tqc_her.yaml` for their source)."""

    name: str  # the config in tqc_her.yaml
    task: str
    steps: int  # env steps of training
    buffer_size: int
    batch_size: int
    gamma: float
    learning_rate: float
    tau: float
    learning_starts: int  # random-action steps before the first gradient step
    ent_coef: str | float  # "auto": learned entropy coefficient
    train_freq: int
    gradient_steps: int
    net_arch: tuple[int, ...]  # hidden layers of the actor and of each critic
    n_critics: int
    n_sampled_goal: int  # HER: relabelled goals per real one
    goal_selection_strategy: str  # HER: "future", "final" or "episode"
    backend: str  # "sb3" or "sbx" (see BACKENDS)
    n_envs: int  # envs stepped side by side; gradient_steps are taken per env step
    #: Budget and loop values this config changed relative to `paper`: {key: [paper, this]}.
    overrides: dict[str, list[Any]] = field(default_factory=dict)

    def with_budget(self, **changes: Any) -> TQCConfig:
        """This config with budget or loop values changed (by `--steps`, a profile), recorded."""
        unknown = sorted(set(changes) - set(CHANGEABLE_KEYS))
        if unknown:
            raise GcdtError(
                f"{', '.join(unknown)} is not a budget or loop value; a TQC+HER config may "
                f"change only {', '.join(CHANGEABLE_KEYS)}"
            )
        values = {k: _budget_value(k, v) for k, v in changes.items()}
        paper = load_tqc_config("paper", self.task) if self.name != "paper" else self
        overrides = dict(self.overrides)
        for key, value in values.items():
            base = getattr(paper, key)
            if value != base:
                overrides[key] = [_plain(base), _plain(value)]
            else:
                overrides.pop(key, None)
        return dataclasses.replace(self, **values, overrides=overrides)

    def to_dict(self) -> dict[str, Any]:
        return {k: _plain(v) for k, v in dataclasses.asdict(self).items()}


def _plain(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


def _budget_value(key: str, value: Any) -> Any:
    """A checked budget or loop value: a known backend, positive integers, or for net_arch a
    non-empty tuple of them."""
    if key == "backend":
        if value not in BACKENDS:
            raise GcdtError(
                f"unknown TQC+HER backend {value!r}: expected one of {', '.join(BACKENDS)}"
            )
        return value
    if key == "net_arch":
        layers = tuple(value) if isinstance(value, list | tuple) else ()
        if not layers or not all(isinstance(n, int) and n > 0 for n in layers):
            raise GcdtError(f"net_arch must be a list of positive layer sizes, got {value!r}")
        return layers
    minimum = 0 if key == "learning_starts" else 1
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise GcdtError(f"{key} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def tqc_config_names() -> list[str]:
    """The configs defined in tqc_her.yaml."""
    return list(_read_yaml())


def _read_yaml() -> dict[str, dict[str, Any]]:
    with open(CONFIG_FILE) as f:
        return yaml.safe_load(f)


def load_tqc_config(name: str, task: str) -> TQCConfig:
    """Config `name` of tqc_her.yaml for `task`: `paper`, or `paper` with budget changes."""
    spec = get_task(task)
    configs = _read_yaml()
    if name not in configs:
        raise GcdtError(f"unknown TQC+HER config {name!r}: expected one of {', '.join(configs)}")
    paper = dict(configs["paper"])
    paper_cfg = TQCConfig(
        name="paper",
        task=spec.name,
        steps=int(paper.pop("steps")[spec.name]),
        net_arch=tuple(paper.pop("net_arch")),
        **paper,
    )
    if name == "paper":
        return paper_cfg
    changes = dict(configs[name])
    if "steps" in changes:
        changes["steps"] = changes["steps"][spec.name]
    return dataclasses.replace(paper_cfg, name=name).with_budget(**changes)


# --------------------------------------------------------------------------------------------
# Training


@dataclass(frozen=True, kw_only=True)
class TQCRunSettings:
    """How a TQC+HER run is seeded, measured and checkpointed, besides its `TQCConfig`:
    `train_tqc` takes each field as a keyword, and `gcdt tqc train` as an option."""

    seed: int = setting(0, "seeds the agent, its envs and its evaluations", minimum=0)
    eval_every: int | None = setting(
        None, "env steps between evaluations (default: 10 per run)", minimum=1, metavar="N"
    )
    eval_episodes: int = setting(20, "episodes per evaluation", minimum=1, metavar="N")
    stop_at: float | None = setting(
        None,
        "stop at the first evaluation whose success rate reaches RATE (0-1]",
        metavar="RATE",
    )
    device: str = setting("auto", "auto (CUDA when present), cpu or cuda")
    checkpoint_seconds: float = setting(
        CHECKPOINT_SECONDS, "seconds between checkpoints (0: every loop iteration)", metavar="S"
    )

    def __post_init__(self) -> None:
        check_minimums(self)
        if self.stop_at is not None and not 0 < self.stop_at <= 1:  # NaN fails too
            raise GcdtError(f"stop_at is a success rate in (0, 1], got {self.stop_at!r}")
        seconds = self.checkpoint_seconds
        if isinstance(seconds, bool) or not isinstance(seconds, int | float) or not seconds >= 0:
            raise GcdtError(f"checkpoint_seconds must be >= 0, got {seconds!r}")


@dataclass(frozen=True)
class TQCResult:
    """Where a run's files are and what it measured."""

    out_dir: Path
    model: Path
    best_model: Path
    env_steps: int
    train_seconds: float  # learning alone (environment steps and gradient steps)
    wall_seconds: float  # everything, periodic evaluation included
    #: Env steps/s once gradient steps run (after `learning_starts` random-action steps):
    #: the rate that decides how long a full-budget run takes.
    learning_steps_per_second: float | None
    best_success_rate: float | None
    final_success_rate: float | None

    @property
    def env_steps_per_second(self) -> float:
        return self.env_steps / max(self.train_seconds, 1e-9)


def train_tqc(
    task: str,
    reward: str,
    cfg: TQCConfig,
    out_dir: str | Path,
    *,
    progress: bool = True,
    command: str | None = None,
    resume: bool = False,
    **settings: Any,
) -> TQCResult:
    """Train TQC+HER on `task` with `reward`; write the run's files to `out_dir`.

    `settings` are `TQCRunSettings`' fields: the seed, the periodic evaluation (the current
    policy measured with `gcdt.evaluation.evaluate`, and once at the end), `stop_at`, the
    device and the checkpoint cadence. With `resume`, the run in `out_dir` continues from its
    checkpoint, which must be of the same task, reward, seed, config and evaluation.
    """
    run = _Run.start(task, reward, cfg, Path(out_dir), TQCRunSettings(**settings), command, resume)
    model, evaluator = run.model, run.evaluator
    if model.num_timesteps < cfg.steps and not (resume and evaluator.reached_target()):
        model.learn(
            cfg.steps - model.num_timesteps,
            callback=[
                evaluator.callback(cfg.steps, cfg.learning_starts, progress),
                _checkpoint_callback(run.checkpoint, run.settings.checkpoint_seconds),
            ],
            reset_num_timesteps=not resume,
        )
    # model.learn stops at the first multiple of n_envs >= steps, or at `stop_at`.
    return run.finish()


@dataclass
class _Run:
    """One `train_tqc` run: what it was started with (`identity`, checked on resume), its
    model, clock and evaluator, and how it checkpoints and finishes."""

    task: str
    reward: str
    cfg: TQCConfig
    out: Path
    settings: TQCRunSettings
    eval_every: int
    identity: dict[str, Any]
    model: Any
    clock: _RunClock
    evaluator: _PeriodicEvaluation
    commit: str | None
    command: str | None
    resumes: int = 0
    #: Env steps at which the run resumed without its replay buffer (`strip_buffer`).
    buffer_refills: list[int] = field(default_factory=list)

    @classmethod
    def start(
        cls,
        task: str,
        reward: str,
        cfg: TQCConfig,
        out: Path,
        settings: TQCRunSettings,
        command: str | None,
        resume: bool,
    ) -> _Run:
        """Check `out` and the config, build the model, and restore the checkpoint on
        `resume`; nothing is written before every check has passed."""
        spec = get_task(task)
        check_reward(reward)
        if cfg.task != spec.name:
            raise GcdtError(f"the TQC+HER config is for task {cfg.task!r}, not {spec.name!r}")
        seed = settings.seed
        eval_every = (
            settings.eval_every if settings.eval_every is not None else max(cfg.steps // 10, 1)
        )
        identity = {
            "task": spec.name,
            "reward": reward,
            "seed": seed,
            "backend": cfg.backend,
            "config": cfg.to_dict(),
            "evaluation": {
                "every": eval_every,
                "episodes": settings.eval_episodes,
                "stop_at": settings.stop_at,
            },
        }
        _check_out(out, identity, resume)
        commit = git_commit()  # the code the run starts with, not what the tree holds at its end
        model = build_tqc(cfg, spec.name, reward, seed, settings.device)  # refuses a bad loop
        out.mkdir(parents=True, exist_ok=True)
        # Travels inside every saved zip: what `TQCPolicy` checks a model against.
        model.gcdt = {
            "task": spec.name,
            "reward": reward,
            "config": cfg.name,
            "seed": seed,
            "backend": cfg.backend,
        }
        clock = _RunClock()
        evaluator = _PeriodicEvaluation(
            model,
            out,
            spec.name,
            reward,
            eval_every,
            settings.eval_episodes,
            seed + EVAL_SEED_OFFSET,
            clock,
            settings.stop_at,
        )
        run = cls(
            spec.name, reward, cfg, out, settings, eval_every, identity, model, clock, evaluator,
            commit, command,
        )  # fmt: skip
        if resume:
            buffer = has_buffer(read_header(out / CHECKPOINT_FILE))
            saved = load_checkpoint(out / CHECKPOINT_FILE, model)
            model.gcdt = saved["gcdt"]
            clock.set_state(saved["clock"])
            evaluator.set_state(saved["evaluation"])
            if not (out / BEST_MODEL_ZIP).is_file():
                # The best model did not travel (a snapshot leaves it out): the best is found
                # again from the next evaluation on, so the zip and its record always agree.
                evaluator.best, evaluator.best_row = (-np.inf, -np.inf), None
            run.resumes = saved["resumes"] + 1
            run.buffer_refills = saved.get("buffer_refills", [])
            if not buffer:
                run.buffer_refills = [*run.buffer_refills, int(model.num_timesteps)]
            run.commit, run.command = saved["git_commit"], saved["command"]  # as it started
        return run

    def checkpoint(self) -> int:
        """Save everything the run needs to carry on (`tqc_checkpoint`); its size in bytes."""
        extra = {
            "gcdt": self.model.gcdt,
            "evaluation": self.evaluator.state(),
            "clock": self.clock.state(),
            "resumes": self.resumes,
            "buffer_refills": self.buffer_refills,
            "git_commit": self.commit,
            "command": self.command,
        }
        return save_checkpoint(self.out / CHECKPOINT_FILE, self.model, self.identity, extra)

    def finish(self) -> TQCResult:
        """Measure the final policy, save it, write `run.json` last, drop the checkpoint."""
        model, evaluator, out = self.model, self.evaluator, self.out
        learning_rate = evaluator.learning_rate()
        if evaluator.last_step != model.num_timesteps:
            evaluator.run()  # the final policy is always measured
        wall = self.clock.wall()
        _save_zip(model, out / MODEL_ZIP)
        model.get_env().close()
        result = TQCResult(
            out_dir=out,
            model=out / MODEL_ZIP,
            best_model=out / BEST_MODEL_ZIP,
            env_steps=int(model.num_timesteps),
            train_seconds=wall - evaluator.seconds,
            wall_seconds=wall,
            learning_steps_per_second=learning_rate,
            best_success_rate=evaluator.best[0] if evaluator.rows else None,
            final_success_rate=evaluator.rows[-1]["success_rate"] if evaluator.rows else None,
        )
        write_json_atomic(out / RUN_JSON, self._record(result))
        (out / CHECKPOINT_FILE).unlink(missing_ok=True)  # run.json is the finished run's record
        return result

    def _record(self, result: TQCResult) -> dict[str, Any]:
        """`run.json`: the config, the evaluation, the times and where the run came from."""
        cfg, evaluator, seed = self.cfg, self.evaluator, self.settings.seed
        learning_rate = result.learning_steps_per_second
        return {
            "task": self.task,
            "reward": self.reward,
            "seed": seed,
            "config": cfg.to_dict(),
            "overrides": cfg.overrides,
            "device": _device_name(self.model, cfg.backend),
            "eval_every": self.eval_every,
            "eval_episodes": self.settings.eval_episodes,
            "eval_seed": seed + EVAL_SEED_OFFSET,
            "stop_at": self.settings.stop_at,
            "env_steps": result.env_steps,
            "train_seconds": round(result.train_seconds, 2),
            "eval_seconds": round(evaluator.seconds, 2),
            "wall_seconds": round(result.wall_seconds, 2),
            "env_steps_per_second": round(result.env_steps_per_second, 2),
            "learning_steps_per_second": learning_rate and round(learning_rate, 2),
            # CPU time of every thread over the kept work (a resume's repeated part excluded)
            "core_hours": round(self.clock.cpu_seconds() / 3600, 3),
            "resumes": self.resumes,
            "buffer_refills": self.buffer_refills,
            "best": evaluator.best_row,
            "final": evaluator.rows[-1] if evaluator.rows else None,
            "command": self.command,
            "created": utc_now(),
            "git_commit": self.commit,
            "versions": package_versions((*TRACKED_PACKAGES, *TQC_PACKAGES[cfg.backend])),
        }


def _check_out(out: Path, identity: dict[str, Any], resume: bool) -> None:
    """Refuse a finished run's folder, a fresh start over an existing run, and a resume from a
    missing checkpoint or one of another run (one line each)."""
    ckpt_path = out / CHECKPOINT_FILE
    if (out / RUN_JSON).exists():
        raise GcdtError(f"{out} already holds a finished TQC+HER run; choose another --out")
    if resume:
        check_identity(ckpt_path, read_header(ckpt_path), identity)  # a one-line error if not
        return
    taken = [name for name in (*RUN_FILES, CHECKPOINT_FILE) if (out / name).exists()]
    if taken:
        raise GcdtError(
            f"{out} already holds a TQC+HER run ({taken[0]}); resume it with --resume, "
            "or choose another --out"
        )


class _RunClock:
    """Wall-clock and CPU seconds of a run, carried across resumes."""

    def __init__(self) -> None:
        self.wall_start, self.cpu_start = time.perf_counter(), time.process_time()

    def wall(self) -> float:
        return time.perf_counter() - self.wall_start

    def cpu_seconds(self) -> float:
        return time.process_time() - self.cpu_start

    def state(self) -> dict[str, float]:
        return {"wall": self.wall(), "cpu": self.cpu_seconds()}

    def set_state(self, state: dict[str, float]) -> None:
        self.wall_start = time.perf_counter() - state["wall"]
        self.cpu_start = time.process_time() - state["cpu"]


def _checkpoint_callback(save: Any, every_seconds: float) -> Any:
    """Calls `save()` between loop iterations, at most every `every_seconds`."""
    from stable_baselines3.common.callbacks import BaseCallback

    class _Checkpoint(BaseCallback):
        def _on_training_start(self) -> None:
            self.last = (self.num_timesteps, time.perf_counter())

        def _on_rollout_start(self) -> None:
            # Between iterations: the last transitions are stored and trained on.
            step, clock = self.last
            if self.model.num_timesteps > step and time.perf_counter() - clock >= every_seconds:
                save()
                self.last = (self.model.num_timesteps, time.perf_counter())

        def _on_step(self) -> bool:
            return True

    return _Checkpoint()


#: The packages a backend's runs record the versions of.
TQC_PACKAGES = {
    "sb3": ("stable-baselines3", "sb3-contrib"),
    "sbx": ("stable-baselines3", "sbx-rl", "jax"),
}
#: Every backend's, in order: what a grid run records whatever its method.
ALL_TQC_PACKAGES = tuple(dict.fromkeys(p for pkgs in TQC_PACKAGES.values() for p in pkgs))


def _check_loop(cfg: TQCConfig, device: str) -> None:
    """Refuse what the chosen backend or loop cannot run, before anything is written."""
    # HER samples only from finished episodes, and n envs finish their first ones together.
    first_episodes = cfg.n_envs * get_task(cfg.task).max_episode_steps
    if cfg.learning_starts < first_episodes:
        raise GcdtError(
            f"learning_starts ({cfg.learning_starts}) must be at least n_envs x episode length "
            f"= {first_episodes}: HER needs a finished episode before its first gradient step; "
            "raise learning_starts or lower n_envs"
        )
    if cfg.backend == "sbx" and cfg.n_critics != 2:
        raise GcdtError(
            f"the sbx backend's TQC has exactly 2 critics, the config asks for {cfg.n_critics}; "
            "use backend sb3 for another number"
        )
    if cfg.backend == "sbx" and device not in ("auto", "cpu"):
        raise GcdtError(
            f"the sbx backend runs on JAX's default device; --device {device} applies to "
            "backend sb3 only (for a GPU with sbx, install jax's CUDA wheel)"
        )


def build_tqc(cfg: TQCConfig, task: str, reward: str, seed: int, device: str = "auto") -> Any:
    """An untrained TQC with HER of `cfg`'s backend on `cfg.n_envs` envs, episode seeds shared
    out between them: for loops of one's own (the benchmarks); `train_tqc` makes a run."""
    _check_loop(cfg, device)
    from stable_baselines3 import HerReplayBuffer
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import DummyVecEnv

    from gcdt.envs import SeededResets, make_env

    if cfg.backend == "sbx":
        from gcdt.baselines.sbx_tqc import TQC
    else:
        from sb3_contrib import TQC

    # Env k plays episodes k, k + n, k + 2n, ... of the run's seed: the instances a one-env
    # run would play, and reproducible whatever order the envs finish in.
    envs = DummyVecEnv(
        [
            lambda k=k: SeededResets(make_env(task, reward), seed, offset=k, stride=cfg.n_envs)
            for k in range(cfg.n_envs)
        ]
    )
    model = TQC(
        "MultiInputPolicy",
        envs,
        buffer_size=cfg.buffer_size,
        batch_size=cfg.batch_size,
        gamma=cfg.gamma,
        learning_rate=cfg.learning_rate,
        tau=cfg.tau,
        learning_starts=cfg.learning_starts,
        ent_coef=cfg.ent_coef,
        train_freq=cfg.train_freq,
        # One loop iteration steps every env once: as many gradient steps as env steps.
        gradient_steps=cfg.gradient_steps * cfg.n_envs,
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={
            "n_sampled_goal": cfg.n_sampled_goal,
            "goal_selection_strategy": cfg.goal_selection_strategy,
        },
        policy_kwargs={"net_arch": list(cfg.net_arch), "n_critics": cfg.n_critics},
        seed=seed,
        device=device,
        verbose=0,
    )
    # Without a logger of its own, every `learn` makes an empty /tmp/SB3-<time> folder.
    model.set_logger(Logger(folder=None, output_formats=[]))
    return model


def _device_name(model: Any, backend: str) -> str:
    if backend == "sbx":
        import jax

        return jax.default_backend()
    return str(model.device)


def _save_zip(model: Any, path: Path) -> None:
    """`model.save` through a temp file and a rename: a reader never sees half a zip.

    SBX pickles its policy whole and again its actor and critic, which the policy holds:
    leaving out the copies halves the zip.
    """
    copies = ["actor", "qf"] if model.gcdt["backend"] == "sbx" else None
    with atomic_write(path, binary=True) as f:
        model.save(f, exclude=copies)


class _PeriodicEvaluation:
    """Measures the live policy with the project's evaluator; keeps the best model on disk."""

    def __init__(
        self,
        model: Any,
        out: Path,
        task: str,
        reward: str,
        every: int,
        episodes: int,
        seed: int,
        clock: _RunClock,
        stop_at: float | None = None,
    ) -> None:
        self.model, self.out, self.task, self.reward = model, out, task, reward
        self.every, self.episodes, self.seed = every, episodes, seed
        self.rows: list[dict[str, Any]] = []
        self.best: tuple[float, float] = (-np.inf, -np.inf)  # (success rate, mean return)
        self.best_row: dict[str, Any] | None = None
        self.stop_at = stop_at
        self.evaluations = 0  # periodic evaluations so far
        self.seconds = 0.0  # time spent evaluating, excluded from the training speed
        self.last_step = -1
        self.clock = clock  # the run's, carried across resumes
        self.learning_mark: tuple[int, float, float] | None = None  # (step, wall s, eval s)
        with open(out / EVAL_CSV, "w", newline="") as f:
            csv.writer(f).writerow(EVAL_FIELDS)

    def run(self) -> None:
        from gcdt.evaluation import evaluate
        from gcdt.policies.tqc import TQCPolicy

        began = self.clock.wall()
        policy = TQCPolicy(self.model.policy, self.task, meta=self.model.gcdt)
        result = evaluate(
            policy, self.task, self.reward, episodes=self.episodes, seed=self.seed, progress=False
        )
        summary = result.summary
        row = {
            "env_steps": int(self.model.num_timesteps),
            "train_seconds": round(began - self.seconds, 2),
            "wall_seconds": round(began, 2),
            "success_rate": summary["success_rate"],
            "mean_return": summary["mean_return"],
            "episodes": summary["episodes"],
        }
        self.rows.append(row)
        self.evaluations = row["env_steps"] // self.every
        self.last_step = row["env_steps"]
        with open(self.out / EVAL_CSV, "a", newline="") as f:
            csv.DictWriter(f, EVAL_FIELDS).writerow(row)
        score = (row["success_rate"], row["mean_return"])
        if score > self.best:
            self.best, self.best_row = score, row
            _save_zip(self.model, self.out / BEST_MODEL_ZIP)
        self.seconds += self.clock.wall() - began

    def reached_target(self) -> bool:
        return (
            self.stop_at is not None
            and bool(self.rows)
            and self.rows[-1]["success_rate"] >= self.stop_at
        )

    def state(self) -> dict[str, Any]:
        """What a checkpoint keeps: the curve so far, the best point, the time spent."""
        return {
            "rows": self.rows,
            "best": self.best,
            "best_row": self.best_row,
            "evaluations": self.evaluations,
            "seconds": self.seconds,
            "last_step": self.last_step,
            "learning_mark": self.learning_mark,
        }

    def set_state(self, state: dict[str, Any]) -> None:
        """Continue from `state()` (the run's clock is restored beside it); eval.csv is
        rewritten to hold exactly the saved curve."""
        self.rows, self.best, self.best_row = state["rows"], state["best"], state["best_row"]
        self.evaluations, self.seconds = state["evaluations"], state["seconds"]
        self.last_step, self.learning_mark = state["last_step"], state["learning_mark"]
        if "elapsed" in state and self.learning_mark is not None:
            # Checkpoints written before the evaluator read the run's clock kept the seconds
            # since the mark; with the clock restored first, that is a wall time again.
            step, since, eval_seconds = self.learning_mark
            self.learning_mark = (step, self.clock.wall() - since, eval_seconds)
        with atomic_write(self.out / EVAL_CSV) as f:
            writer = csv.DictWriter(f, EVAL_FIELDS)
            writer.writeheader()
            writer.writerows(self.rows)

    def mark_learning_start(self) -> None:
        self.learning_mark = (self.model.num_timesteps, self.clock.wall(), self.seconds)

    def learning_rate(self) -> float | None:
        """Env steps/s since `mark_learning_start`, evaluations excluded (None if unmarked)."""
        if self.learning_mark is None or self.model.num_timesteps <= self.learning_mark[0]:
            return None
        step, wall, eval_seconds = self.learning_mark
        seconds = self.clock.wall() - wall - (self.seconds - eval_seconds)
        return (self.model.num_timesteps - step) / max(seconds, 1e-9)

    def callback(self, total: int, learning_starts: int, progress: bool) -> Any:
        from stable_baselines3.common.callbacks import BaseCallback

        from gcdt.progress import progress_bar

        evaluation = self

        class _Callback(BaseCallback):
            def _on_training_start(self) -> None:
                self.bar = progress_bar(total=total, desc="TQC+HER", unit="step", progress=progress)
                self.bar.update(self.num_timesteps)  # a resumed run's steps so far

            def _on_step(self) -> bool:
                self.bar.update(self.training_env.num_envs)
                # num_timesteps grows by n_envs per call: the first call at or past a mark.
                # From the second iteration with gradient steps: the first compiles SBX's update.
                started = learning_starts + 2 * self.training_env.num_envs
                if evaluation.learning_mark is None and self.num_timesteps >= started:
                    evaluation.mark_learning_start()
                if self.num_timesteps // evaluation.every > evaluation.evaluations:
                    evaluation.run()
                    self.bar.set_postfix(success=evaluation.rows[-1]["success_rate"])
                    if evaluation.reached_target():
                        return False  # stop training: the target success rate is reached
                return True

            def _on_training_end(self) -> None:
                self.bar.close()

        return _Callback()

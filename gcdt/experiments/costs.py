"""Estimated run costs for `gcdt sweep --dry-run`, from measured rates.

Rates come from the result files of finished runs (any profile) where there are some, and
otherwise from the benchmarks' JSON in results/bench/ or, failing those, from the values
measured on the reference machine (2 cores, one torch thread per run). They are estimates of
seconds on this kind of machine; `source` says where each rate came from.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from statistics import median

from gcdt.envs import TASKS
from gcdt.errors import GcdtError
from gcdt.experiments.grid import OFFLINE_METHODS, DataSpec, RunSpec
from gcdt.paths import REPO_ROOT, outputs_root
from gcdt.provenance import cpu_signature

#: Reference-machine rates (seconds per unit), used when neither results/bench/ nor finished
#: runs say better: `benchmarks/run_costs.py` (two runs in parallel, one torch thread each,
#: a local sweep's layout) and `benchmarks/tqc_her.py throughput`.
DEFAULT_RATES = {
    "dt_step": 0.38,  # one DT gradient step, batch 64, K 20
    "bc_step": 0.005,  # one BC gradient step
    "dt_eval_step": 1 / 88,  # one env step of evaluation with a DT policy (a forward pass)
    "eval_step": 1 / 170,  # one env step of evaluation with a BC or TQC policy
    "collect_step": 1 / 250,  # one collected transition
    "tqc_step:paper": 1 / 2.38,  # one TQC+HER env step with a gradient step, her-defaults
    "tqc_step:cpu": 1 / 61.4,  # the same with the cpu config
    "run_overhead": 5.0,  # process start, imports, env creation
}
#: The rates a CPU's speed sets most: gradient steps, whose matmuls differ several-fold
#: between CPUs that virtual machines report under one model name (AVX2 against AVX-512).
STEP_RATES = ("dt_step", "bc_step")
#: Mean expert episode length assumed to turn transitions into the authors' epochs where no
#: published evaluation of the collecting policy says better (`expert_episode_length`).
ASSUMED_EPISODE_LENGTH = 30
#: The grid's methods that train a Decision Transformer (their steps and their acting cost more).
DT_METHODS = tuple(name for name, (method, _) in OFFLINE_METHODS.items() if method == "dt")


@dataclass
class CostModel:
    rates: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_RATES))
    source: dict[str, str] = field(default_factory=lambda: dict.fromkeys(DEFAULT_RATES, "default"))
    gpu: str | None = None  # the GPU the rates were measured on (`measured(on="cuda")`)
    # This CPU, the factor its runs' gradient steps take over other machines', and from how
    # many rates (`_this_cpu`); None where no finished run measured it.
    cpu: tuple[str, float, int] | None = None

    @classmethod
    def measured(
        cls, profile: str | None = None, on: str = "cpu", this_machine: bool = True
    ) -> CostModel:
        """Defaults, overridden by benchmark JSON, overridden by finished runs' timings; with
        `profile`, a rate its own finished runs measure is theirs alone (its data, budgets and
        machine), the other profiles' runs filling in the rest. Offline gradient steps are
        also measured per task and data shape (`rate`), and per CPU: runs on this machine's
        kind of CPU set its rates, and scale those measured elsewhere (`_this_cpu`).
        `on="cuda"`: the GPU benchmarks' rates instead (`_gpu`), the CPU's where they
        measure nothing. Without `this_machine`, no CPU is this one: the same rates on every
        machine (what a published report quotes)."""
        model = cls()
        bench = REPO_ROOT / "results" / "bench"
        if on == "cuda":
            return model._gpu(bench)
        if (bench / "tqc_her_throughput.json").exists():
            tqc = json.loads((bench / "tqc_her_throughput.json").read_text())
            for name, cell in tqc["configs"].items():
                model._set(
                    f"tqc_step:{name}",
                    1 / cell["learning_steps_per_second"],
                    "tqc_her_throughput.json",
                )
        if (bench / "run_costs.json").exists():
            runs = json.loads((bench / "run_costs.json").read_text())["results"]
            for name, key, invert in (
                ("dt_step", "dt_seconds_per_step", False),
                ("bc_step", "bc_seconds_per_step", False),
                ("dt_eval_step", "dt_eval_steps_per_second", True),
                ("eval_step", "bc_eval_steps_per_second", True),
            ):
                model._set(name, 1 / runs[key] if invert else runs[key], "run_costs.json")
        # Samples by (on this CPU, of `profile`): a profile's runs outrank the others, and
        # this CPU's outrank every other machine's.
        samples: dict[tuple[bool, bool], dict[str, list[float]]] = {
            (here, own): {} for here in (False, True) for own in (False, True)
        }
        this_cpu = cpu_signature() if this_machine else None
        # The published runs and, in a reproduction, its own (the same file is read once).
        roots = dict.fromkeys(root.resolve() for root in (REPO_ROOT, outputs_root()))
        for path in (p for root in roots for p in (root / "results").glob("*/runs/*.json")):
            try:
                result = json.loads(path.read_text())
                if result.get("status") == "done":
                    group = (
                        result["execution"].get("cpu") == this_cpu,
                        path.parent.parent.name == profile,
                    )
                    for name, value in _samples(result):
                        samples[group].setdefault(name, []).append(value)
            except (OSError, ValueError, KeyError, TypeError, ZeroDivisionError):
                continue  # an unreadable file is the store's business, not the estimate's
        for here in (False, True):
            if here:  # every other machine's rates are in: scale them to this CPU first
                model._this_cpu(this_cpu, _merged(samples, True), _merged(samples, False))
            for own in (False, True):
                whose = f" {profile}" if own else ""
                where = " on this CPU" if here else ""
                for name, values in samples[here, own].items():
                    n = len(values)
                    model._set(name, median(values), f"median of {n} finished{whose} runs{where}")
        return model

    def _this_cpu(
        self, cpu: str, here: dict[str, list[float]], elsewhere: dict[str, list[float]]
    ) -> None:
        """Scale the gradient-step rates measured on other CPUs by how much slower or faster
        this one is: the median ratio of the two over the rates both measure, each of one
        task and data shape (pooled rates would compare different mixes of runs)."""
        ratios = [
            median(here[name]) / median(elsewhere[name])
            for name in here.keys() & elsewhere.keys()
            if name.split(":")[0] in STEP_RATES and _most_specific(name)
        ]
        if not ratios:
            return
        factor = median(ratios)
        self.cpu = (cpu, factor, len(ratios))
        for name in self.rates:
            if name.split(":")[0] in STEP_RATES:
                self.rates[name] *= factor
                self.source[name] += f", x {factor:.2f} for this CPU"

    def _gpu(self, bench: Path) -> CostModel:
        """Rates measured on a GPU machine by `benchmarks/*.py --device cuda`. Finished runs
        are not read (they ran on CPUs); collection is the simulator's, a CPU rate anyway."""
        files = {
            name: json.loads((bench / f"{name}_cuda.json").read_text())
            for name in ("training_throughput", "evaluator_throughput_push", "tqc_her_throughput")
            if (bench / f"{name}_cuda.json").exists()
        }
        if not files:
            raise GcdtError(
                f"no GPU benchmark in {bench} (*_cuda.json): run benchmarks/training_throughput.py"
                " and its siblings with --device cuda on a GPU machine first (docs/benchmarks.md)"
            )
        self.gpu = next(iter(files.values()))["machine"].get("gpu") or "a GPU"
        if train := files.get("training_throughput"):
            for name, key in (("dt_step", "gcdt_fp32"), ("bc_step", "bc_fp32")):
                ms = train["results"][f"{key}_ms_per_step"]
                self._set(name, ms / 1e3, "training_throughput_cuda.json")
        if ev := files.get("evaluator_throughput_push"):  # one env per run, as a sweep's
            rate = ev["results"]["evaluate_gcdt_1_envs"]
            self._set("dt_eval_step", 1 / rate, "evaluator_throughput_push_cuda.json")
        if tqc := files.get("tqc_her_throughput"):
            for name, cell in tqc["configs"].items():
                rate = 1 / cell["learning_steps_per_second"]
                self._set(f"tqc_step:{name}", rate, "tqc_her_throughput_cuda.json")
        return self

    def _set(self, name: str, value: float, source: str) -> None:
        self.rates[name], self.source[name] = value, source

    def estimate(self, spec: RunSpec, train: bool = True, done_steps: int = 0) -> float:
        """Seconds for `spec` alone (shared datasets and TQC experts are counted apart);
        without `train`, its evaluation only (another run makes its checkpoint); an offline
        run whose checkpoint holds `done_steps` gradient steps trains only the rest."""
        r = self.rates
        seconds = r["run_overhead"]
        eval_rate = r["dt_eval_step" if spec.method in DT_METHODS else "eval_step"]
        seconds += spec.eval_timesteps * len(spec.eval_seeds) * eval_rate
        if spec.method == "tqc":
            rate = r.get(f"tqc_step:{spec.tqc.config}", r["tqc_step:paper"])
            return seconds + (spec.tqc.steps or 0) * rate
        if not train:
            return seconds
        steps = max(0, offline_steps(spec) - done_steps)
        if spec.method == "bc":
            return seconds + steps * self.rate("bc_step", spec.task)
        return seconds + steps * self.rate(
            "dt_step", spec.task, window_shape(spec.data.expert_ratio)
        )

    def rate(self, name: str, task: str, shape: str | None = None) -> float:
        """Seconds per unit of `name` on `task` with data of `shape` (`window_shape`): the
        most specific rate measured, down to the pooled one (`rate_names`)."""
        return next(self.rates[n] for n in rate_names(name, task, shape) if n in self.rates)

    def collection(self, transitions: int) -> float:
        return transitions * self.rates["collect_step"]


def offline_steps(spec: RunSpec) -> int:
    """Gradient steps of an offline run: its budget, else the trainer's default (the authors'
    epochs) for the data size in episodes (`episodes`)."""
    from gcdt.training import TrainConfig  # imports torch: only once costs are estimated

    if spec.train_steps is not None:  # BC's always is (gcdt.experiments.grid.bc_steps)
        return spec.train_steps
    return TrainConfig().total_steps(episodes(spec.data))


def episodes(data: DataSpec) -> int:
    """Episodes in `data`: its expert part at the collecting policy's mean episode length
    (`expert_episode_length`), its random part at the task's full episodes (random actions
    rarely reach a goal, and an episode ends only then)."""
    expert = data.size * data.expert_ratio
    random = data.size - expert
    return math.ceil(
        expert / expert_episode_length(data) + random / TASKS[data.task].max_episode_steps
    )


@functools.lru_cache(maxsize=32)
def _published_length(path: Path) -> float | None:
    """Mean episode length of a published evaluation file: a TQC+HER agent's run.json (its
    held-out evaluation) or a scripted expert's `gcdt evaluate --json` output."""
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if held_out := record.get("published", {}).get("held_out"):
        return held_out["timesteps"] / held_out["episodes"]
    return record.get("summary", {}).get("mean_length")


def expert_episode_length(data: DataSpec) -> float:
    """The mean episode length of the policy that collects `data`'s expert part, from its
    published held-out evaluation (results/experts/: the TQC+HER agent's run.json, or the
    scripted expert's noise-free evaluation), else `ASSUMED_EPISODE_LENGTH`."""
    experts = REPO_ROOT / "results" / "experts"
    if data.expert.startswith("tqc"):  # a published agent, or the grid's own TQC expert
        reward = data.expert_tqc.reward if data.expert_tqc else "sparse"
        path = experts / f"tqc_{data.task}_{reward}" / "run.json"
        if data.expert.startswith("tqc:"):
            path = REPO_ROOT / Path(data.expert.removeprefix("tqc:")).parent / "run.json"
    else:
        path = experts / f"{data.task}_sparse.json"
    return _published_length(path) or ASSUMED_EPISODE_LENGTH


def _merged(
    samples: dict[tuple[bool, bool], dict[str, list[float]]], here: bool
) -> dict[str, list[float]]:
    """The samples of this CPU (`here`) or of the others, a profile's own outranking the rest."""
    return {**samples[here, False], **samples[here, True]}


def window_shape(expert_ratio: float) -> str:
    """What a Decision Transformer step's cost follows besides the CPU: "full" where the data
    has a random part, whose full-length episodes fill every K-step window, else "short"
    (expert episodes shorter than K: the model skips their windows' padding). Measured: a
    step on random data costs about twice one on TQC-expert data."""
    return "full" if expert_ratio < 1 else "short"


def rate_names(name: str, task: str, shape: str | None = None) -> list[str]:
    """The rates that may stand for `name` on `task` with data of `shape`, most specific
    first: "dt_step:push:full", "dt_step:full", "dt_step:push", "dt_step"."""
    shaped = [f"{name}:{task}:{shape}", f"{name}:{shape}"] if shape else []
    return [*shaped, f"{name}:{task}", name]


def _most_specific(name: str) -> bool:
    """Whether rate `name` is of one task and, for DT steps, one data shape."""
    return name.count(":") == (2 if name.startswith("dt_step") else 1)


def _samples(result: dict) -> list[tuple[str, float]]:
    """The rates one finished run measures, under every name they may stand for."""
    spec, execution = result["spec"], result["execution"]
    seconds = execution["seconds"]
    training = result.get("training", {})
    found: list[tuple[str, float]] = []
    if spec["method"] == "tqc":
        # Env steps with their gradient steps and learning-curve evaluations: what a run costs.
        if training.get("env_steps", 0) >= 1000 and seconds.get("train_seconds", 0) > 1:
            name = f"tqc_step:{spec['tqc']['config']}"
            found.append((name, seconds["train_seconds"] / training["env_steps"]))
    else:
        # The steps this run's process trained: fewer than the run's where it resumed a
        # checkpoint, none where it reused one (older results, without it: all of them).
        steps = execution.get("trained_steps", training.get("steps"))
        # (Short runs measure start-up more than steps.)
        if steps and steps >= 100 and seconds.get("train_seconds", 0) > 1:
            rate = seconds["train_seconds"] / steps
            if spec["method"] == "bc":
                found += [(name, rate) for name in rate_names("bc_step", spec["task"])]
            else:
                shape = window_shape(spec["data"]["expert_ratio"])
                found += [(name, rate) for name in rate_names("dt_step", spec["task"], shape)]
    evaluated = spec["eval_timesteps"] * len(spec["eval_seeds"])
    if seconds.get("evaluate_seconds") and evaluated >= 1000:
        name = "dt_eval_step" if spec["method"] in DT_METHODS else "eval_step"
        found.append((name, seconds["evaluate_seconds"] / evaluated))
    return found

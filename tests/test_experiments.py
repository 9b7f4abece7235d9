"""The experiment grid: profiles, run keys, the run store, and sweeps on local and Ray backends."""

from __future__ import annotations

import dataclasses
import fcntl
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from gcdt.baselines.tqc_her import CONFIG_FILE
from gcdt.checkpoint import load_checkpoint
from gcdt.data import load_dataset
from gcdt.envs import episode_seed, make_env
from gcdt.errors import GcdtError
from gcdt.experiments import (
    PROFILES,
    RunSpec,
    RunStore,
    build_grid,
    deviations,
    deviations_text,
    get_profile,
    sweep,
)
from gcdt.experiments.grid import RUN_SCHEMA, data_spec
from gcdt.experiments.profiles import SMOKE, Scope, target_seeds
from gcdt.experiments.runner import LOSS_CURVE_POINTS, thin_curve
from gcdt.paths import REPO_ROOT
from gcdt.provenance import cpu_signature
from gcdt.regions import GoalRegion
from gcdt.training import TrainConfig

ONE = Scope(tasks=("reach",), rewards=("sparse",))
#: Thirteen real runs on Reach in about a minute: Table 1 (GC-DT, BC, TQC+HER), one RQ4
#: subset, one RQ5 mixture, the two DT ablations, two return-target points (one is Table 1's
#: GC-DT checkpoint at target 0 on the study's seeds, the other at -10), and GC-DT and BC
#: trained on goals with y <= 0, each evaluated there and at y >= 0.
TINY = dataclasses.replace(
    SMOKE,
    name="tiny",
    dataset_size=300,
    rq4_sizes=(150, 300),
    rq5_ratios=(0.5, 1.0),
    train_steps={"reach": 5},
    learning_rate=2e-4,
    eval_timesteps=60,
    tqc_steps=120,
    tqc_budget={"learning_starts": 50, "batch_size": 16, "net_arch": [16], "n_envs": 1},
    tqc_eval_every=120,
    tqc_eval_episodes=1,
    table1=ONE,
    rq4=ONE,
    rq5=ONE,
    ablation=ONE,
    targets=ONE,
    return_targets={"sparse": (0.0, -10.0)},
    generalisation=ONE,
)


def test_paper_profile_is_the_paper_and_others_list_their_deviations():
    # The one deviation of `paper`: TQC+HER's loop, the algorithm and its budget unchanged.
    (loop,) = deviations(PROFILES["paper"])
    assert loop.startswith("TQC+HER trained with the sbx backend (SBX, JAX) on 8 envs")
    quick = deviations_text(get_profile("quick"))
    assert "per cell instead of" not in quick  # Table 1 at the paper's 3 seeds
    assert "RQ4 (Fig. 3) not run" in quick and "RQ4 subset sizes" not in quick
    standard = deviations_text(get_profile("standard"))
    assert "RQ4 (Fig. 3) on reach, push, pick_and_place × sparse only" in standard
    assert "RQ4 subset sizes 5,000, 10,000, 20,000 instead of" in standard
    assert "scripted experts" in standard and "20,000 transitions" in standard
    assert "env steps" not in standard  # the paper's 10,000-step evaluation
    # quick: standard's Table 1 at a quarter of the data and a shorter evaluation.
    assert "5,000 transitions of expert (and of random) data instead of 1,000,000" in quick
    assert "evaluation over 3,000 env steps instead of 10,000" in quick
    smoke = deviations_text(get_profile("smoke"))
    assert "evaluation over 100 env steps instead of 10,000" in smoke
    assert "learning rate 0.001 instead of 0.0001" in quick
    assert "actions with Gaussian noise of std 0.2" in quick
    with pytest.raises(GcdtError, match="unknown profile 'huge'"):
        get_profile("huge")


def test_profile_descriptions_state_no_measured_time():
    # What a profile took drifts: reproduce.json and `gcdt sweep --dry-run` say it instead.
    for profile in PROFILES.values():
        assert not re.search(r"\d\s*(h|min|minutes|hours)\b", profile.description), profile.name


def test_expert_noise_reaches_the_scripted_collections_only():
    mixture = next(
        e.spec.data
        for e in build_grid(get_profile("standard"), only="rq5")
        if e.spec.data.expert_ratio == 0.5
    )
    assert mixture.expert_noise == mixture.base("expert").expert_noise == 0.2
    assert mixture.base("random").expert_noise == 0.0  # random actions take no expert noise
    assert dataclasses.replace(mixture, expert_noise=0.0).key() != mixture.key()
    with pytest.raises(GcdtError, match="expert_noise applies to the scripted experts only"):
        dataclasses.replace(PROFILES["paper"], expert_noise=0.1)
    with pytest.raises(GcdtError, match="expert_noise must be >= 0"):
        dataclasses.replace(SMOKE, expert_noise=-0.1)


def test_a_profile_whose_evaluation_seeds_collide_is_refused():
    with pytest.raises(GcdtError, match="training seeds 0 and 100 would both be evaluated"):
        dataclasses.replace(SMOKE, seeds=(0, 100), eval_seeds=2)
    with pytest.raises(GcdtError, match="evaluation seeds reach 10000, the return-target study"):
        dataclasses.replace(SMOKE, seeds=(0, 10_000))
    with pytest.raises(GcdtError, match="return_targets must map sparse, dense to finite"):
        dataclasses.replace(SMOKE, return_targets={"sparse": (0.0, float("nan"))})
    assert dataclasses.replace(SMOKE, seeds=(0, 1, 2), eval_seeds=5).eval_seeds == 5


def test_bc_sees_as_many_samples_as_the_dt():
    quick = get_profile("quick")
    steps = {
        (e.spec.method, e.spec.task): e.spec.train_steps
        for e in build_grid(quick, only="table1")
        if e.spec.method in ("gcdt", "bc")
    }
    for task, dt_steps in quick.train_steps.items():
        assert steps["gcdt", task] == dt_steps and steps["bc", task] == 20 * dt_steps
    paper_bc = next(
        e.spec for e in build_grid(PROFILES["paper"], only="table1") if e.spec.method == "bc"
    )
    assert paper_bc.train_steps == 120 * 1_000_000 // 64  # 120 epochs over transitions
    same_steps = dataclasses.replace(quick, bc_budget="steps")
    assert "BC trained with as many gradient steps as the DT" in deviations_text(same_steps)
    with pytest.raises(GcdtError, match="unknown BC budget rule 'epochs': expected one of"):
        dataclasses.replace(quick, bc_budget="epochs")


def test_paper_grid_shares_runs_between_sections():
    grid = build_grid(PROFILES["paper"])
    keys = [e.spec.key() for e in grid]
    assert len(keys) == len(set(keys)) == 234
    # Table 1's GC-DT on the full data is also RQ4's largest subset and RQ5's 100 % point.
    full = [e for e in grid if e.spec.method == "gcdt" and "table1" in e.sections]
    assert len(full) == 18 and all(e.sections == ("table1", "rq4", "rq5") for e in full)
    assert {e.spec.method for e in grid} == {"gcdt", "bc", "tqc", "dt", "dt-desired"}
    tqc = next(e.spec for e in grid if e.spec.method == "tqc")
    assert tqc.tqc.steps == 1_000_000 and tqc.data is None  # "equivalent online steps"
    with pytest.raises(GcdtError, match="unknown grid section 'rq9'"):
        build_grid(PROFILES["paper"], only="rq9")


def test_run_key_is_stable_and_complete():
    spec = build_grid(TINY, only="table1")[0].spec
    assert RunSpec.from_dict(json.loads(json.dumps(spec.to_dict()))).key() == spec.key()
    assert dataclasses.replace(spec, seed=1).key() != spec.key()
    assert dataclasses.replace(spec, eval_timesteps=61).key() != spec.key()
    assert dataclasses.replace(spec, learning_rate=1e-3).key() != spec.key()


@pytest.mark.parametrize(
    ("name", "finished"), [("quick", True), ("standard", True), ("large", False)]
)
def test_each_published_run_file_is_a_run_its_grid_names(name, finished):
    """The published results are filed under the keys the grid gives their runs today (run
    scripts/migrate_run_keys.py after a change to how keys are computed); a grid still running
    (large) publishes its finished sections, so some of its runs have no file yet."""
    runs = REPO_ROOT / "results" / name / "runs"
    published = {path.stem: json.loads(path.read_text()) for path in runs.glob("*.json")}
    grid = {e.spec.key(): e.spec for e in build_grid(get_profile(name))}
    assert set(published) == set(grid) if finished else set(published) <= set(grid)
    for key, result in published.items():
        assert result["key"] == key and result["schema"] == RUN_SCHEMA
        assert result["spec"] == json.loads(json.dumps(grid[key].to_dict()))
        # a long run's loss curve is stored thinned (scripts/thin_loss_curves.py: older files)
        assert len(result.get("training", {}).get("loss_curve") or []) <= LOSS_CURVE_POINTS


def test_a_long_loss_curve_is_thinned_to_log_spaced_rows_keeping_its_ends():
    rows = [{"step": 50 * (i + 1), "loss": 1.0 / (i + 1), "lr": 1e-4} for i in range(16_000)]
    thinned = thin_curve(rows)
    gaps = np.diff([r["step"] for r in thinned]) // 50
    assert 1_000 < len(thinned) <= LOSS_CURVE_POINTS
    assert thinned[0] == rows[0] and thinned[-1] == rows[-1]  # the final loss is kept
    assert thinned[:150] == rows[:150]  # every early row, where the loss changes fastest
    assert gaps.min() >= 1 and gaps[-1] > 50  # increasing steps, sparse only late
    assert all(r in rows for r in thinned)  # logged values, never averaged or invented
    assert thin_curve(rows[:LOSS_CURVE_POINTS]) == rows[:LOSS_CURVE_POINTS]  # short: kept whole
    assert thin_curve(rows[:5], most=2) == [rows[0], rows[4]]
    with pytest.raises(ValueError, match="at least 2 points"):
        thin_curve(rows, most=1)


def _keys(profile) -> tuple[list[RunSpec], list[str], list[str]]:
    """The grid's runs (in their stable order), their keys and their training keys."""
    specs = [e.spec for e in build_grid(profile)]
    return specs, [s.key() for s in specs], [s.training_key() for s in specs]


def _changed(before: list[str], after: list[str]) -> set[int]:
    return {i for i, (a, b) in enumerate(zip(before, after, strict=True)) if a != b}


def test_a_changed_value_re_keys_exactly_the_runs_it_reaches(monkeypatch, tmp_path):
    """A run's key hashes the values it computes from: one training default, one evaluation
    setting, one tqc_her.yaml value each re-key the runs that use it, and no others."""
    # quick, with Reach and PickAndPlace data collected by TQC+HER experts and Push data by a
    # published agent (whose key is the zip's content hash).
    agent = "results/experts/tqc_push_sparse/model.zip"
    profile = dataclasses.replace(
        get_profile("quick"), expert="tqc", expert_noise=0.0, expert_agents={"push": agent}
    )
    specs, keys, trained = _keys(profile)
    tqc = {i for i, s in enumerate(specs) if s.method == "tqc"}
    tqc_data = {i for i, s in enumerate(specs) if s.data is not None and s.data.expert == "tqc"}
    offline = set(range(len(specs))) - tqc
    assert tqc and tqc_data and offline - tqc_data  # every kind of run is there to tell apart

    # A training default (dropout): every offline run, at training too; TQC+HER runs keep theirs.
    fields = [("dropout", float, dataclasses.field(default=0.2))]
    changed = dataclasses.make_dataclass("TrainConfig", fields, bases=(TrainConfig,), frozen=True)
    with monkeypatch.context() as m:
        m.setattr("gcdt.training.TrainConfig", changed)
        _, new_keys, new_trained = _keys(profile)
    assert _changed(keys, new_keys) == _changed(trained, new_trained) == offline

    # An evaluation setting: every run's key, no run's training.
    _, new_keys, new_trained = _keys(dataclasses.replace(profile, eval_timesteps=4_000))
    assert _changed(keys, new_keys) == set(range(len(specs)))
    assert not _changed(trained, new_trained)

    # tqc_her.yaml: the profile's config (cpu) trains the TQC+HER runs and the experts.
    config = yaml.safe_load(CONFIG_FILE.read_text())
    edited = tmp_path / "tqc_her.yaml"
    monkeypatch.setattr("gcdt.baselines.tqc_her.CONFIG_FILE", edited)
    edited.write_text(yaml.safe_dump({**config, "cpu": {**config["cpu"], "batch_size": 128}}))
    _, new_keys, new_trained = _keys(profile)
    assert _changed(keys, new_keys) == _changed(trained, new_trained) == tqc | tqc_data
    # A value cpu overrides, and a name: values, not names or overrides, make the key.
    paper = {**config["paper"], "batch_size": 4096}
    edited.write_text(yaml.safe_dump({**config, "paper": paper, "cpu2": config["cpu"]}))
    renamed = dataclasses.replace(profile, tqc_config="cpu2")
    assert _keys(renamed)[1] == keys


def _results(root: Path) -> dict[str, dict]:
    """Result files without their execution block (timings, host, backend)."""
    out = {}
    for path in sorted(root.glob("*.json")):
        result = json.loads(path.read_text())
        result.pop("execution")
        out[path.name] = result
    return out


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory):
    root = tmp_path_factory.mktemp("local")
    os.environ["GCDT_ARTIFACTS"] = str(root / "artifacts")
    try:
        summary = sweep(TINY, store_root=root / "runs", workers=2, progress=False)
    finally:
        del os.environ["GCDT_ARTIFACTS"]
    return root, summary


def test_local_sweep_runs_every_run_once(local_sweep):
    root, summary = local_sweep
    assert summary.ok and len(summary.done) == 13 and not summary.skipped
    results = _results(root / "runs")
    assert len(results) == 13 and all(r["status"] == "done" for r in results.values())
    methods = sorted(r["spec"]["method"] for r in results.values())
    assert methods == [*["bc"] * 3, "dt", "dt-desired", *["gcdt"] * 7, "tqc"]
    for r in results.values():
        assert r["schema"] == RUN_SCHEMA and r["evaluations"][0]["episodes"] >= 1
        assert 0.0 <= r["metrics"]["success_rate"] <= 1.0
    # Expert collections (the whole goal range, and one region's), one random collection, two
    # derived datasets, all content-keyed.
    datasets = list((root / "artifacts" / "grid" / "datasets").glob("*.npz"))
    assert len(datasets) == 5
    # The collections used the profile's expert noise; random actions got none.
    policies = {}
    for path in datasets:
        metadata = load_dataset(path).metadata
        if metadata["source"] == "collect" and "goal_region" not in metadata:
            policies[metadata["policy"]["name"]] = metadata["policy"].get("noise_std")
        elif "goal_region" in metadata:  # the generalisation study's data: one region's goals
            region = GoalRegion.parse(metadata["goal_region"])
            assert region.contains(load_dataset(path).arrays["desired_goal"]).all()
    assert policies == {"scripted": TINY.expert_noise, "random": None} and TINY.expert_noise > 0
    # Every offline run trained at the profile's learning rate, not the trainer's default; the
    # return-target runs evaluated Table 1's GC-DT checkpoint, on the study's own seeds.
    checkpoints = list((root / "artifacts" / "grid" / "checkpoints").glob("*/checkpoint.pt"))
    assert len(checkpoints) == 8
    assert {load_checkpoint(p)["train_config"]["lr"] for p in checkpoints} == {2e-4}
    study = [RunSpec.from_dict(r["spec"]) for r in results.values()]
    study = [s for s in study if s.eval_seeds == target_seeds(s.seed)]
    assert sorted(s.target_return for s in study) == [-10.0, 0.0]
    table1_gcdt = next(e.spec for e in build_grid(TINY, "table1") if e.spec.method == "gcdt")
    assert {s.training_key() for s in study} == {table1_gcdt.training_key()}
    assert len({s.key() for s in study} | {table1_gcdt.key()}) == 3
    regions = {(r["spec"]["method"], r["spec"]["eval_region"]) for r in results.values()}
    assert {(m, g) for m in ("gcdt", "bc") for g in TINY.goal_regions} <= regions
    again = sweep(TINY, store_root=root / "runs", workers=2, progress=False)
    assert len(again.skipped) == 13 and not again.done and not again.failed
    # Each run records its CPU and the gradient steps its own time paid for: the runs that
    # share a checkpoint trained its steps once between them, the others reused it.
    raw = [json.loads(p.read_text()) for p in sorted((root / "runs").glob("*.json"))]
    assert {r["execution"]["cpu"] for r in raw} == {cpu_signature()}
    by_training: dict[str, list[dict]] = {}
    for r in raw:
        if r["spec"]["method"] == "tqc":
            assert r["execution"]["trained_steps"] is None
        else:
            by_training.setdefault(RunSpec.from_dict(r["spec"]).training_key(), []).append(r)
    assert len(by_training) == 8 and any(len(runs) == 3 for runs in by_training.values())
    for runs in by_training.values():
        paid = sorted(r["execution"]["trained_steps"] for r in runs)
        assert paid == [0] * (len(runs) - 1) + [runs[0]["training"]["steps"]]


def _start(obs) -> tuple[float, ...]:
    """An episode's instance: its goal and the object's (Reach: the gripper's) start position."""
    return tuple(np.round(np.concatenate([obs["desired_goal"], obs["achieved_goal"]]), 5))


def test_evaluation_never_replays_a_training_instance(local_sweep):
    """Held out by construction: no evaluation episode of the grid starts from the goal and
    object position of an episode any of its runs learnt from (expert or random data, or
    TQC+HER's online training)."""
    root, _ = local_sweep
    env = make_env("reach", "sparse")
    try:
        trained = set()
        for path in (root / "artifacts" / "grid" / "datasets").glob("*.npz"):
            data = load_dataset(path)
            starts = np.concatenate([[0], np.cumsum(data.episode_lengths)[:-1]])
            trained |= {
                _start({k: data.arrays[k][i] for k in ("desired_goal", "achieved_goal")})
                for i in starts
            }
        tqc_episodes = TINY.tqc_steps // env.spec.max_episode_steps + 1
        trained |= {
            _start(env.reset(seed=episode_seed(seed, j, "tqc-training"))[0])
            for seed in {TINY.data_seed, *TINY.seeds}
            for j in range(tqc_episodes)
        }
        evaluated = set()
        for path in (root / "runs").glob("*.json"):
            result = json.loads(path.read_text())
            region = result["spec"]["eval_region"]  # the study's envs draw goals from it
            evaluator = env
            if region is not None:
                evaluator = make_env("reach", "sparse", goal_region=GoalRegion.parse(region))
            for e in result["evaluations"]:
                evaluated |= {
                    _start(evaluator.reset(seed=episode_seed(e["seed"], j))[0])
                    for j in range(e["episodes"])
                }
            if evaluator is not env:
                evaluator.close()
        # The comparison can fail: an episode reset with an expert collection's seed starts
        # where that collection's episode started.
        replayed = _start(env.reset(seed=episode_seed(TINY.data_seed, 0, "collection"))[0])
    finally:
        env.close()
    assert len(trained) >= 20 and evaluated  # (TINY evaluates 60 steps: one or two episodes)
    assert replayed in trained
    assert not trained & evaluated


def test_multi_node_sweep_survives_a_lost_node(
    local_sweep, tmp_path, monkeypatch, start_ray_cluster
):
    """A head and two worker nodes (separate raylets), no shared filesystem: each node makes
    its artifacts in its own folder, the driver alone writes the store. One worker node is
    lost mid-sweep; its run is retried on the other, and the results equal a local sweep's."""
    ray = pytest.importorskip("ray")

    driver_artifacts = tmp_path / "driver-artifacts"  # no run may touch the driver's folder
    # The head runs the driver alone, as on a real cluster: runs go to the worker nodes.
    cluster, nodes = start_ray_cluster(
        tuple({"GCDT_ARTIFACTS": str(tmp_path / f"node{i}")} for i in range(2))
    )
    try:
        monkeypatch.setenv("GCDT_ARTIFACTS", str(driver_artifacts))
        runs, outcome = tmp_path / "runs", {}
        # Every run node 0 starts waits on its first artifact's lock, held here: when node 0
        # is lost, a run is in flight there for certain.
        locks = tmp_path / "node0" / "grid" / "locks"
        locks.mkdir(parents=True)
        firsts = {(e.spec.tqc if e.spec.tqc else e.spec.data).key() for e in build_grid(TINY)}
        held = [open(locks / f"{key}.lock", "w") for key in firsts]
        for f in held:
            fcntl.flock(f, fcntl.LOCK_EX)

        def drive():
            try:
                outcome["summary"] = sweep(
                    TINY, backend="ray", address=cluster.address, store_root=runs, progress=False
                )
            except BaseException as err:  # re-raised below, in the test's thread
                outcome["error"] = err

        thread = threading.Thread(target=drive)
        thread.start()
        # Node 0 is lost once node 1 has finished a run (node 0 took one at the start).
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and not list(runs.glob("*.json")):
            time.sleep(0.1)
        cluster.remove_node(nodes[0])
        for f in held:
            f.close()
        thread.join(timeout=600)
    finally:
        ray.shutdown()
        cluster.shutdown()
    if "error" in outcome:
        raise outcome["error"]
    summary = outcome["summary"]
    print(summary.line())  # the run counts of a sweep that lost a node
    assert summary.ok and len(summary.done) == 13 and not summary.skipped
    assert summary.retried and all("Error" in r for r in summary.retried)
    assert _results(runs) == _results(local_sweep[0] / "runs")
    assert sorted(p.name for p in runs.iterdir()) == sorted(f"{k}.json" for k in summary.done)
    assert {json.loads(p.read_text())["execution"]["backend"] for p in runs.iterdir()} == {"ray"}
    assert not driver_artifacts.exists()
    # The surviving node made the artifacts it needed itself; no node wrote a result file.
    assert list((tmp_path / "node1" / "grid" / "datasets").glob("*.npz"))
    results = {f"{k}.json" for k in summary.done}
    assert not [p for p in tmp_path.glob("node*/**/*.json") if p.name in results]


def test_local_ray_instance_writes_the_same_results(local_sweep, tmp_path, monkeypatch):
    pytest.importorskip("ray")
    monkeypatch.setenv("GCDT_ARTIFACTS", str(tmp_path / "artifacts"))  # trains from scratch
    runs = tmp_path / "runs"
    summary = sweep(TINY, backend="ray", only="table1", store_root=runs, workers=2, progress=False)
    assert summary.ok and len(summary.done) >= 2
    assert _results(runs) == {
        name: r
        for name, r in _results(local_sweep[0] / "runs").items()
        if runs.joinpath(name).exists()
    }
    # The instance's workers made the artifacts in the driver's folder (one machine).
    assert list((tmp_path / "artifacts" / "grid" / "datasets").glob("*.npz"))


def test_corrupt_and_foreign_results_are_reported_and_rerun(local_sweep, tmp_path, monkeypatch):
    root, _ = local_sweep
    runs = tmp_path / "runs"
    runs.mkdir()
    for path in (root / "runs").glob("*.json"):
        runs.joinpath(path.name).write_bytes(path.read_bytes())
    victim = sorted(runs.glob("*.json"))[0]
    victim.write_text('{"key": "trunc')
    (runs / "0123456789abcdef.json").write_text("{}")
    monkeypatch.setenv("GCDT_ARTIFACTS", str(root / "artifacts"))
    summary = sweep(TINY, store_root=runs, workers=1, progress=False)
    assert summary.done == [victim.stem] and len(summary.skipped) == 12
    assert any("is not valid JSON" in w for w in summary.warnings)
    assert any("0123456789abcdef.json is not a result of this grid" in w for w in summary.warnings)
    assert RunStore(runs).read(victim.stem).state == "done"


def test_failing_run_is_recorded_and_the_others_complete(local_sweep, tmp_path, monkeypatch):
    monkeypatch.setenv("GCDT_ARTIFACTS", str(local_sweep[0] / "artifacts"))
    # A config that cannot resolve is refused before any run: the run keys hash its values.
    with pytest.raises(GcdtError, match="gamma is not a budget or loop value"):
        build_grid(dataclasses.replace(TINY, tqc_budget={**TINY.tqc_budget, "gamma": 0.5}))
    broken = dataclasses.replace(TINY, tqc_eval_every=0)  # refused by TQC+HER's training only
    summary = sweep(broken, store_root=tmp_path, workers=2, progress=False)
    assert not summary.ok and len(summary.failed) == 1 and len(summary.done) == 12
    failed = json.loads((tmp_path / f"{summary.failed[0]}.json").read_text())
    assert failed["status"] == "failed" and failed["spec"]["method"] == "tqc"
    assert "eval_every must be a positive integer, got 0" in failed["error"]
    assert "Traceback" in failed["traceback"]
    # Tried RETRIES more times in the sweep, then listed with the command that re-runs it.
    assert summary.retried == [f"{summary.failed[0]}: {failed['error']}"] * 2
    lines, label = (
        summary.lines(),
        next(p.entry.spec.label for p in summary.planned if p.key == summary.failed[0]),
    )
    assert lines[1] == f"failed: {summary.failed[0]} {label}: {failed['error']}"
    assert lines[2].endswith(": gcdt sweep --profile tiny")
    retry = sweep(broken, store_root=tmp_path, workers=2, retries=0, progress=False)
    assert retry.failed == summary.failed and len(retry.skipped) == 12  # failed runs re-run
    assert not retry.retried and retry.lines()[2].endswith("gcdt sweep --profile tiny --retries 0")


DRIVER = """
import sys
from tests.test_experiments import TINY
from gcdt.experiments import sweep
summary = sweep(TINY, store_root=sys.argv[1], workers=2, progress=False)
print(summary.line())
"""


def _pool_workers(pid: int) -> list[int]:
    """The worker processes of the process pool of driver `pid` (its spawned children)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            ppid = int(stat.read_text().rsplit(")", 1)[1].split()[1])
            cmdline = stat.with_name("cmdline").read_bytes()
        except (OSError, IndexError, ValueError):  # gone meanwhile
            continue
        if ppid == pid and b"spawn_main" in cmdline:
            out.append(int(stat.parent.name))
    return out


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="finds the pool's workers in /proc")
def test_killed_sweep_resumes_with_only_the_missing_runs(tmp_path):
    runs = tmp_path / "runs"
    env = {**os.environ, "GCDT_ARTIFACTS": str(tmp_path / "artifacts")}
    repo = Path(__file__).resolve().parent.parent
    driver = subprocess.Popen(
        [sys.executable, "-c", DRIVER, str(runs)], cwd=repo, env=env, start_new_session=True
    )
    deadline = time.monotonic() + 300
    while not list(runs.glob("*.json")) and time.monotonic() < deadline:
        time.sleep(0.2)
    os.killpg(driver.pid, signal.SIGKILL)  # the driver and its workers, mid-sweep
    driver.wait()
    first = {p.name: p.stat().st_mtime_ns for p in runs.glob("*.json")}
    assert 1 <= len(first) < 13
    for name in first:  # whatever was written is whole
        assert RunStore(runs).read(Path(name).stem).state == "done"
    # The resuming sweep loses a worker too (killed, out of memory): its pool breaks, and the
    # runs it held are tried again in a fresh pool instead of being recorded as failed.
    resumed = subprocess.Popen(
        [sys.executable, "-c", DRIVER, str(runs)],
        cwd=repo,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 300
    while not (workers := _pool_workers(resumed.pid)) and time.monotonic() < deadline:
        time.sleep(0.05)
    os.kill(workers[0], signal.SIGKILL)
    out, err = resumed.communicate(timeout=600)
    assert resumed.returncode == 0, err
    left = 13 - len(first)
    assert f"{left} done, {len(first)} skipped, 0 failed, {left} retried" in out
    assert {p.name: p.stat().st_mtime_ns for p in runs.glob("*.json") if p.name in first} == first
    assert not [p for p in runs.iterdir() if p.suffix != ".json"]  # no temp files left


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--profile", "huge"], "argument --profile: invalid choice: 'huge'"),
        (["--profile", "smoke", "--backend", "slurm"], "invalid choice: 'slurm'"),
        (["--profile", "smoke", "--only", "rq9"], "invalid choice: 'rq9'"),
        (["--profile", "smoke", "--address", "1.2.3.4:6379"], "--address applies only to"),
        (
            ["--profile", "smoke", "--backend", "ray", "--address", "nonsense"],
            "Ray address 'nonsense' is not HOST:PORT",
        ),
    ],
)
def test_bad_sweep_input_exit_2(assert_usage_error, argv, message):
    assert_usage_error(["sweep", *argv], message)


def test_unreachable_ray_address_fails_within_seconds(assert_usage_error):
    pytest.importorskip("ray")
    started = time.monotonic()
    assert_usage_error(
        ["sweep", "--profile", "smoke", "--backend", "ray", "--address", "127.0.0.1:9"],
        "cannot reach the Ray cluster at 127.0.0.1:9",
    )
    assert time.monotonic() - started < 30


def test_dry_run_lists_runs_with_state_and_cost(capsys):
    from gcdt.cli import main
    from gcdt.experiments.costs import CostModel

    assert main(["sweep", "--profile", "standard", "--dry-run", "--only", "rq4"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    p = get_profile("standard")
    n = len(p.rq4_sizes) * len(p.seeds) * len(p.rq4.tasks)
    runs = [line for line in lines if "[rq4" in line]
    assert len(runs) == n and lines[-1].startswith(f"{n} runs, ")
    assert all("/sparse seed " in line and " min " in line for line in runs)
    assert sum("gcdt push/sparse seed 2" in line for line in lines) == len(p.rq4_sizes)
    # Each section's cost, then the data's (done runs cost nothing: the published ones are).
    assert lines[-2].startswith("datasets and TQC+HER experts to make: about ")
    costs = CostModel()
    short, long = (
        dataclasses.replace(build_grid(TINY, only="table1")[0].spec, train_steps=n)
        for n in (10, 1000)
    )
    assert costs.estimate(long) - costs.estimate(short) == pytest.approx(
        990 * costs.rates["dt_step"]
    )


def test_a_checkpoint_left_here_counts_in_the_estimate(tmp_path, monkeypatch):
    """A killed run resumes from its checkpoint, so the dry run estimates only the steps
    left; a finished checkpoint (the return-target study's) leaves its evaluation alone."""
    from gcdt.experiments.artifacts import checkpoint_dir
    from gcdt.experiments.costs import CostModel
    from gcdt.experiments.sweep import plan

    monkeypatch.setenv("GCDT_ARTIFACTS", str(tmp_path / "artifacts"))
    costs, store = CostModel(), RunStore(tmp_path / "runs")
    spec = next(e.spec for e in build_grid(TINY, only="table1") if e.spec.method == "gcdt")
    full, steps = costs.estimate(spec), spec.train_steps

    def estimate(logged_steps: tuple[int, ...]) -> tuple[float, int]:
        rows = ["step,loss,lr,seconds", *(f"{s},0.5,0.001,{s}" for s in logged_steps)]
        (out / "train_log.csv").write_text("\n".join(rows) + "\n")
        (p,) = [p for p in plan(TINY, store, costs=costs)[0] if p.entry.spec == spec]
        return p.estimate_seconds, p.done_steps

    out = checkpoint_dir(spec)
    out.mkdir(parents=True)
    assert estimate((1, 2)) == (full, 0)  # a log without its checkpoint resumes nothing
    (out / "checkpoint.pt").write_bytes(b"stand-in")
    seconds, done = estimate((1, 2))
    # The 2 steps done are not paid again; the evaluation still is.
    assert done == 2 and full - seconds == pytest.approx(2 * costs.rate("dt_step", spec.task))
    assert estimate((1, 2, steps)) == (pytest.approx(costs.estimate(spec, train=False)), steps)


def test_the_wall_estimate_hands_runs_out_as_the_sweep_does():
    """On N workers a sweep takes at least its longest run, not the total over N: runs go out
    begun first, then longest first, each to the worker free first."""
    from types import SimpleNamespace

    from gcdt.experiments.sweep import dispatch_order, wall_estimate

    def runs(*seconds, begun=()):
        return [
            SimpleNamespace(estimate_seconds=s, done_steps=int(i in begun))
            for i, s in enumerate(seconds)
        ]

    assert wall_estimate(runs(10, 1, 1), workers=2) == 10  # not (10 + 1 + 1) / 2
    assert wall_estimate(runs(3, 3, 2, 2, 2), workers=2) == 7  # 3+2+2 beside 3+2
    assert wall_estimate(runs(3, 3, 2, 2, 2), workers=5) == 3
    assert wall_estimate(runs(4), workers=2, shared=6) == 7  # the data first, on both
    # A begun run goes out first, so here the long one waits for a free worker.
    begun = runs(1, 1, 6, begun=(0, 1))
    assert [p.estimate_seconds for p in dispatch_order(begun)] == [1, 1, 6]
    assert wall_estimate(begun, workers=2) == 7


def test_a_sweep_of_one_task_runs_its_runs_longest_first(capsys, monkeypatch, tmp_path):
    """`--task` keeps one task's runs (an unknown task is refused); the sweep hands them to the
    backend longest first, so that no worker is left alone with a long run at the end, after
    the runs a killed sweep began."""
    from gcdt.cli import main
    from gcdt.experiments.artifacts import checkpoint_dir
    from gcdt.experiments.costs import CostModel
    from gcdt.experiments.sweep import plan

    assert main(["sweep", "--profile", "standard", "--dry-run", "--task", "push"]) == 0
    runs = [line for line in capsys.readouterr().out.splitlines() if " min  " in line]
    assert runs and all(" push/" in line for line in runs)
    everything, _ = plan(get_profile("standard"), RunStore(tmp_path), costs=CostModel())
    assert len(runs) == sum(p.entry.spec.task == "push" for p in everything) < len(everything)
    with pytest.raises(GcdtError, match="unknown task 'pusj'"):
        plan(TINY, RunStore(tmp_path), task="pusj")

    handed: list = []

    def record(runner, todo, store, summary, retries, progress):
        handed.extend(todo)

    # The package's `sweep` is the function, which hides its module.
    monkeypatch.setattr(sys.modules["gcdt.experiments.sweep"], "_run_all", record)
    summary = sweep(TINY, store_root=tmp_path / "runs", task="reach", workers=1, progress=False)
    costs = [p.estimate_seconds for p in handed]
    assert len(handed) == len(build_grid(TINY))
    assert costs == sorted(costs, reverse=True) and costs[0] > costs[-1]
    assert summary.rerun.endswith("--task reach")

    # A run a killed sweep began (its checkpoint holds steps) goes first, however short its
    # rest: finishing it writes the result that work is at risk for.
    monkeypatch.setenv("GCDT_ARTIFACTS", str(tmp_path / "artifacts"))
    begun = next(p.entry.spec for p in handed[1:] if p.entry.spec.method == "gcdt")
    out = checkpoint_dir(begun)
    out.mkdir(parents=True)
    (out / "checkpoint.pt").write_bytes(b"stand-in")
    (out / "train_log.csv").write_text(f"step,loss,lr,seconds\n{begun.train_steps - 1},0.5,0,1\n")
    handed.clear()
    sweep(TINY, store_root=tmp_path / "runs", task="reach", workers=1, progress=False)
    assert handed[0].entry.spec == begun and handed[0].done_steps == begun.train_steps - 1
    rest = [p.estimate_seconds for p in handed[1:]]
    assert rest == sorted(rest, reverse=True) and handed[0].estimate_seconds < rest[0]


def test_the_epoch_budget_is_estimated_from_the_collecting_policys_episode_length(
    tmp_path, monkeypatch
):
    """The authors' epochs count episodes: the estimate reads the mean episode length of the
    policy that collects the data from its published held-out evaluation."""
    from gcdt.experiments import costs as cost_module
    from gcdt.experiments.grid import data_spec

    monkeypatch.setattr(cost_module, "REPO_ROOT", tmp_path)
    cost_module._published_length.cache_clear()
    agent = tmp_path / "results" / "experts" / "tqc_push_sparse"
    agent.mkdir(parents=True)
    held_out = {"timesteps": 3500, "episodes": 500}  # 7 steps per episode
    (agent / "run.json").write_text(json.dumps({"published": {"held_out": held_out}}))
    (tmp_path / "results" / "experts" / "push_sparse.json").write_text(
        json.dumps({"summary": {"mean_length": 12.5}})
    )
    paper = get_profile("paper")
    tqc = data_spec(paper, "push", 700_000, 1.0)
    assert cost_module.expert_episode_length(tqc) == 7.0
    assert cost_module.episodes(tqc) == 100_000
    mixed = data_spec(paper, "push", 700_000, 0.5)  # random episodes run to the time limit
    assert cost_module.episodes(mixed) == 50_000 + 350_000 // 50
    scripted = data_spec(dataclasses.replace(paper, expert="scripted"), "push", 1000, 1.0)
    assert cost_module.expert_episode_length(scripted) == 12.5
    unknown = data_spec(paper, "reach", 3000, 1.0)  # no published evaluation of it
    assert cost_module.expert_episode_length(unknown) == cost_module.ASSUMED_EPISODE_LENGTH
    spec = next(e.spec for e in build_grid(paper) if e.spec.method == "gcdt")
    spec = dataclasses.replace(spec, task="push", data=tqc)
    assert cost_module.offline_steps(spec) == 120 * -(-100_000 // 64)
    cost_module._published_length.cache_clear()


def test_a_gpu_estimate_reads_the_gpu_benchmarks_and_refuses_without_them(
    tmp_path, monkeypatch, assert_usage_error
):
    from gcdt.experiments import costs as cost_module

    bench = cost_module.REPO_ROOT / "results" / "bench"
    train = json.loads((bench / "training_throughput_cuda.json").read_text())
    tqc = json.loads((bench / "tqc_her_throughput_cuda.json").read_text())
    gpu = cost_module.CostModel.measured("paper", on="cuda")
    assert gpu.rates["dt_step"] == train["results"]["gcdt_fp32_ms_per_step"] / 1e3
    assert gpu.rates["bc_step"] == train["results"]["bc_fp32_ms_per_step"] / 1e3
    paper_tqc = tqc["configs"]["paper"]["learning_steps_per_second"]
    assert gpu.rates["tqc_step:paper"] == pytest.approx(1 / paper_tqc)
    assert gpu.gpu == train["machine"]["gpu"] and gpu.source["dt_step"].endswith("_cuda.json")
    assert gpu.rates["collect_step"] == cost_module.CostModel().rates["collect_step"]
    monkeypatch.setattr(cost_module, "REPO_ROOT", tmp_path)
    with pytest.raises(GcdtError, match=r"no GPU benchmark in .*: run .* --device cuda"):
        cost_module.CostModel.measured("paper", on="cuda")
    assert_usage_error(
        ["sweep", "--profile", "smoke", "--estimate-on", "cuda"],
        "--estimate-on sets the rates of --dry-run: add --dry-run",
    )


def test_costs_learn_every_rate_from_finished_runs(tmp_path, monkeypatch):
    """A reproduction's own finished runs (TQC+HER's included) set the dry run's rates."""
    from gcdt.experiments import costs as costs_module
    from gcdt.experiments.costs import CostModel

    # Away from the published runs and benchmarks, whose rates would join the medians.
    monkeypatch.setattr(costs_module, "REPO_ROOT", tmp_path / "repository")

    runs = tmp_path / "results" / "quick" / "runs"
    runs.mkdir(parents=True)
    timed = {"tqc": ({"env_steps": 20_000}, 600.0), "bc": ({"steps": 1_000}, 5.0)}
    for method, (training, train_seconds) in timed.items():
        spec = {
            "method": method,
            "task": "push",
            "tqc": {"config": "cpu"},
            "eval_timesteps": 0,
            "eval_seeds": [],
        }
        result = {
            "status": "done",
            "spec": spec,
            "training": training,
            "execution": {"seconds": {"train_seconds": train_seconds}},
        }
        (runs / f"{method}.json").write_text(json.dumps(result))
    monkeypatch.setenv("GCDT_OUTPUTS", str(tmp_path))
    costs = CostModel.measured()
    assert costs.rates["tqc_step:cpu"] == pytest.approx(600 / 20_000)
    assert costs.rates["bc_step"] == pytest.approx(5 / 1_000)
    assert costs.source["tqc_step:cpu"].endswith("finished runs")
    # A profile's own runs measure its rates (its data, budgets, machine), where they have any.
    large = tmp_path / "results" / "large" / "runs"
    large.mkdir(parents=True)
    bc = json.loads((runs / "bc.json").read_text())
    bc["execution"]["seconds"]["train_seconds"] = 2.0
    (large / "bc.json").write_text(json.dumps(bc))
    costs = CostModel.measured("large")
    assert costs.rates["bc_step"] == pytest.approx(2 / 1_000)
    assert costs.source["bc_step"] == "median of 1 finished large runs"
    assert costs.rates["tqc_step:cpu"] == pytest.approx(600 / 20_000)  # from quick's
    assert CostModel.measured().rates["bc_step"] == pytest.approx((5 + 2) / 2 / 1_000)
    # A task's own runs set its rate; the pooled rate stands in for tasks without any.
    reach = dict(bc, spec=dict(bc["spec"], task="reach"))
    reach["execution"] = {"seconds": {"train_seconds": 1.5}}
    (large / "bc_reach.json").write_text(json.dumps(reach))
    costs = CostModel.measured("large")
    assert costs.rate("bc_step", "reach") == pytest.approx(1.5 / 1_000)
    assert costs.rate("bc_step", "push") == pytest.approx(2 / 1_000)
    assert costs.rate("bc_step", "pick_and_place") == pytest.approx((1.5 + 2) / 2 / 1_000)


def test_costs_follow_the_data_shape_this_cpu_and_the_steps_a_run_paid_for(
    tmp_path, monkeypatch, capsys
):
    """A GC-DT step's rate is measured per task and data shape; runs on this kind of CPU set
    its rates and scale the other machines' by their ratio; a resumed run's rate divides its
    time by the steps it trained, and a reused checkpoint measures nothing."""
    from gcdt.cli import main
    from gcdt.experiments import costs as costs_module
    from gcdt.experiments.costs import CostModel

    monkeypatch.setattr(costs_module, "REPO_ROOT", tmp_path / "repository")
    monkeypatch.setattr(costs_module, "cpu_signature", lambda: "Test CPU, AVX2")
    monkeypatch.setenv("GCDT_OUTPUTS", str(tmp_path))
    runs = tmp_path / "results" / "large" / "runs"
    runs.mkdir(parents=True)

    def run(name, task, ratio, seconds, steps=1_000, **execution):
        spec = {"method": "gcdt", "task": task, "data": {"expert_ratio": ratio}}
        result = {
            "status": "done",
            "spec": {**spec, "eval_timesteps": 0, "eval_seeds": []},
            "training": {"steps": 1_000},
            "execution": {"seconds": {"train_seconds": seconds}, **execution},
        }
        (runs / f"{name}.json").write_text(json.dumps(result))

    run("push_expert", "push", 1.0, 60.0)  # another machine's (older results name no CPU)
    run("push_mixed", "push", 0.25, 120.0, cpu="Other CPU, AVX512")
    run("pick_expert", "pick_and_place", 1.0, 70.0)
    costs = CostModel.measured("large")
    assert costs.rate("dt_step", "push", "short") == pytest.approx(0.06)
    assert costs.rate("dt_step", "push", "full") == pytest.approx(0.12)
    # Reach has no run: the pooled rate of its shape, not another shape's.
    assert costs.rate("dt_step", "reach", "full") == pytest.approx(0.12)
    assert costs.rate("dt_step", "reach", "short") == pytest.approx(0.065)
    assert costs.cpu is None
    # This CPU: a resumed run trained 500 of its 1,000 steps in its 100 s, and a run that
    # reused a checkpoint trained none in 30 s (it loaded one).
    run("push_expert_here", "push", 1.0, 100.0, cpu="Test CPU, AVX2", trained_steps=500)
    run("push_reused_here", "push", 1.0, 30.0, cpu="Test CPU, AVX2", trained_steps=0)
    costs = CostModel.measured("large")
    assert costs.rate("dt_step", "push", "short") == pytest.approx(0.2)
    assert costs.source["dt_step:push:short"] == "median of 1 finished large runs on this CPU"
    cpu, factor, n = costs.cpu
    assert (cpu, n) == ("Test CPU, AVX2", 1) and factor == pytest.approx(0.2 / 0.06)
    assert costs.rate("dt_step", "push", "full") == pytest.approx(0.12 * factor)
    assert costs.rate("dt_step", "pick_and_place", "short") == pytest.approx(0.07 * factor)
    assert costs.source["dt_step:push:full"].endswith(f"x {factor:.2f} for this CPU")
    assert costs.rate("dt_eval_step", "push") == CostModel().rates["dt_eval_step"]  # unscaled
    # The estimate of a run on mixed Push data takes its steps at the scaled mixed rate.
    spec = next(
        e.spec
        for e in build_grid(get_profile("large"), only="rq5")
        if e.spec.task == "push" and e.spec.data.expert_ratio == 0.25
    )
    steps = dataclasses.replace(spec, train_steps=1_000)
    none = dataclasses.replace(spec, train_steps=0)
    assert costs.estimate(steps) - costs.estimate(none) == pytest.approx(1_000 * 0.12 * factor)
    assert main(["sweep", "--profile", "large", "--dry-run", "--only", "rq5"]) == 0
    lines = capsys.readouterr().out.splitlines()
    scaled = [i for i, line in enumerate(lines) if line.startswith("this CPU (")]
    assert len(scaled) == 1
    assert "this CPU (Test CPU, AVX2) takes 3.33x as long per gradient step" in lines[scaled[0]]
    # The note explains the totals, so it comes before them.
    totals = [i for i, line in enumerate(lines) if line.startswith(("section ", "datasets "))]
    assert totals and scaled[0] < min(totals)


#: The paper profile's structure at toy sizes: TQC+HER experts, expert data collected by a
#: TQC agent, the authors' epoch budget (GC-DT: 120 epochs over episodes; BC: over
#: transitions), TQC+HER for as many online steps as the data has transitions, evaluation.
PAPER_IN_MINIATURE = dataclasses.replace(
    PROFILES["paper"],
    name="paper-miniature",
    seeds=(0,),
    dataset_size=150,
    eval_timesteps=60,
    tqc_budget={
        "steps": 150,  # the expert's
        "learning_starts": 50,
        "batch_size": 16,
        "net_arch": [16],
        "buffer_size": 1000,
        "n_envs": 1,
    },
    tqc_eval_every=150,
    tqc_eval_episodes=1,
    table1=ONE,
    table1_tqc=ONE,
    rq4=Scope(tasks=()),
    rq5=Scope(tasks=()),
    ablation=Scope(tasks=()),
)


def test_the_paper_profiles_path_runs_end_to_end_in_miniature(tmp_path, monkeypatch):
    paper = PROFILES["paper"]
    assert (paper.expert, paper.train_steps, paper.tqc_steps) == ("tqc", None, None)
    monkeypatch.setenv("GCDT_ARTIFACTS", str(tmp_path / "artifacts"))
    summary = sweep(PAPER_IN_MINIATURE, store_root=tmp_path / "runs", workers=1, progress=False)
    assert summary.ok and len(summary.done) == 3, summary.line()
    results = {
        r["spec"]["method"]: r
        for r in map(json.loads, map(Path.read_text, (tmp_path / "runs").glob("*.json")))
    }
    assert set(results) == {"gcdt", "bc", "tqc"}
    # The expert data came from a TQC+HER agent the grid trained first. Here it is Table 1's
    # baseline too: the same task, reward, seed and resolved config (steps 150 by the budget
    # and by the data's size) make the same key, so one agent is trained, once.
    agents = {str(p) for p in (tmp_path / "artifacts" / "grid" / "tqc").glob("*/model.zip")}
    collections = [
        load_dataset(p) for p in (tmp_path / "artifacts" / "grid" / "datasets").glob("*.npz")
    ]
    (data,) = [d for d in collections if d.metadata["policy"]["name"] == "tqc"]
    assert len(agents) == 1 and data.metadata["policy"]["path"] in agents and len(data) >= 150
    # The epoch budget: GC-DT 120 epochs of ceil(episodes / 64) steps, BC 120 over transitions.
    gcdt_run, bc_run, tqc_run = results["gcdt"], results["bc"], results["tqc"]
    assert gcdt_run["spec"]["train_steps"] is None
    assert gcdt_run["training"]["steps"] == 120 * -(-data.n_episodes // 64)
    assert bc_run["training"]["steps"] == 120 * -(-150 // 64)
    # TQC+HER: as many online steps as the data has transitions.
    assert tqc_run["spec"]["tqc"]["steps"] == 150
    for r in results.values():
        assert r["evaluations"][0]["episodes"] >= 1


def test_large_profile_keeps_the_papers_data_and_evaluation():
    large = get_profile("large")
    text = deviations_text(large)
    assert "transitions of expert" not in text and "env steps instead of" not in text
    # TQC+HER agents, as in the paper, but for PickAndPlace's, which fell short of an expert.
    assert "- pick_and_place's expert data from the scripted experts" in text
    assert text.count("expert data from the") == 1 and "TQC+HER agent results/experts" in text
    pnp, push = (data_spec(large, task, 1000, 1.0) for task in ("pick_and_place", "push"))
    assert (pnp.expert, pnp.expert_noise) == ("scripted", 0.2)
    assert push.expert.startswith("tqc:") and push.expert_noise == 0.0
    assert "Table 1's TQC+HER cells from the published agents of 1,000,000 online steps" in text
    assert (
        "checked against one 4 times longer on push, pick_and_place (sparse), GC-DT, one seed, "
        "at 100%, 25% expert data" in text
    )
    assert "RQ5 (Fig. 4) on push, pick_and_place × sparse only" in text
    assert "RQ5 expert ratios" not in text  # the paper's shares, in priority order
    assert "RQ4 subset sizes 100,000, 250,000, 500,000, 1,000,000 instead of" in text
    grid = build_grid(large)
    assert not [e for e in grid if e.spec.method == "tqc"]  # the published agents instead
    # The sweep's order is the priority: Table 1, the budget check, then RQ5 from 25 %.
    first = [e.sections[0] for e in grid]
    assert first == sorted(first, key=large.section_order.index)
    # Table 1 trains Push and PickAndPlace 4 times longer than the figures' points, BC by the
    # same samples rule (K = 20 times the DT's steps); Reach keeps the grid's budget.
    assert "(reach 2,000, push 10,000, pick_and_place 10,000; Table 1: push 40,000, " in text
    steps = {
        (e.spec.method, e.spec.task, e.sections[0]): e.spec.train_steps
        for e in grid
        if e.sections[0] in ("table1", "rq5")
    }
    assert steps[("gcdt", "push", "table1")] == steps[("gcdt", "pick_and_place", "table1")]
    assert steps[("gcdt", "push", "table1")] == 40_000 and steps[("bc", "push", "table1")] == (
        800_000
    )
    assert (steps[("gcdt", "reach", "table1")], steps[("gcdt", "push", "rq5")]) == (2_000, 10_000)
    # The DT ablations are set against Table 1's GC-DT: they train for its budget.
    ablation = dataclasses.replace(large, ablation=Scope(tasks=("push",), rewards=("sparse",)))
    assert {e.spec.train_steps for e in build_grid(ablation, only="ablation")} == {40_000}
    # So does the return-target study: each target re-evaluates Table 1's checkpoint.
    targets = dataclasses.replace(large, targets=Scope(tasks=("push",), rewards=("sparse",)))
    target_runs = [e.spec for e in build_grid(targets, only="targets")]
    assert {s.train_steps for s in target_runs} == {40_000}
    label = "gcdt push/sparse seed 0 (1,000,000 expert)"
    (table1_run,) = [e.spec for e in grid if e.sections[0] == "table1" and e.spec.label == label]
    assert {s.training_key() for s in target_runs if s.seed == 0} == {table1_run.training_key()}
    budget = [e.spec for e in grid if "budget" in e.sections]
    # Each budget the grid trains with, 4 times longer: Table 1's on expert data, and the
    # figures' on expert data and at RQ5's disputed 25 %, each beside the grid's run of that
    # data at that budget (the figures' longer run on expert data is Table 1's own run).
    assert sorted((s.task, s.seed, s.train_steps, s.data.expert_ratio) for s in budget) == [
        ("pick_and_place", 0, 40_000, 0.25),
        ("pick_and_place", 0, 40_000, 1.0),
        ("pick_and_place", 0, 160_000, 1.0),
        ("push", 0, 40_000, 0.25),
        ("push", 0, 40_000, 1.0),
        ("push", 0, 160_000, 1.0),
    ]
    cells = {e.spec.key(): e.spec for e in grid if set(e.sections) - {"budget"}}
    for spec in budget:
        base = dataclasses.replace(spec, train_steps=spec.train_steps // 4)
        assert base.key() in cells, f"no grid run of the budget check's data: {spec.label}"
    rq5 = [e.spec.data.expert_ratio for e in grid if e.sections == ("rq5",)]
    assert rq5[:2] == [0.25, 0.25] and set(rq5) == {0.0, 0.25, 0.5, 0.75}
    with pytest.raises(GcdtError, match="section_order must order every section once"):
        dataclasses.replace(large, section_order=("table1",))
    with pytest.raises(GcdtError, match="the budget check needs fixed train_steps"):
        dataclasses.replace(large, train_steps=None)
    with pytest.raises(GcdtError, match=r"budget_ratios must be expert shares in \[0, 1\]"):
        dataclasses.replace(large, budget_ratios=(1.5,))
    # A share RQ5 does not run, or a task it does not cover, has no base run to compare with.
    with pytest.raises(GcdtError, match=r"budget check at 60% expert data has no rq5 run"):
        dataclasses.replace(large, budget_ratios=(1.0, 0.6))
    with pytest.raises(GcdtError, match=r"no rq5 run of its data for reach/sparse"):
        dataclasses.replace(large, budget=Scope(tasks=("reach", "push"), rewards=("sparse",)))
    # A task whose Table 1 keeps the grid's budget has one base run on expert data, not two.
    both = Scope(tasks=("reach", "push"), rewards=("sparse",))
    reach = dataclasses.replace(large, budget=both, rq5=both)
    checks = [e for e in build_grid(reach, only="budget") if e.spec.task == "reach"]
    assert sorted(e.spec.data.expert_ratio for e in checks) == [0.25, 1.0]
    assert {e.sections for e in checks} == {("budget",)}
    with pytest.raises(GcdtError, match=r"no table1 run of its data for push/sparse"):
        dataclasses.replace(large, table1=Scope(tasks=("reach",)))
    with pytest.raises(GcdtError, match=r"from the published agents \(tqc_agents\) or from grid"):
        dataclasses.replace(large, table1_tqc=Scope())
    with pytest.raises(GcdtError, match=r"table1_train_steps needs fixed train_steps and a "):
        dataclasses.replace(large, table1_train_steps={"push": 40_000})


def _publish_fake_agent(folder: Path, steps: int, success: float, seed: int = 0) -> None:
    """A published agent's files as `gcdt.baselines.publish` writes them (the zip's bytes are
    only hashed here)."""
    folder.mkdir(parents=True)
    (folder / "model.zip").write_bytes(f"agent of {steps} steps".encode())
    held_out = {"seed": 5000, "success_rate": success, "mean_return": -5.0, "std_return": 2.0,
                "episodes": 500, "timesteps": 9000}  # fmt: skip
    curve = [{"env_steps": float(steps), "success_rate": success, "mean_return": -5.0}]
    record = {"task": "reach", "reward": "sparse", "seed": seed, "env_steps": steps,
              "curve": curve, "published": {"held_out": held_out}}  # fmt: skip
    (folder / "run.json").write_text(json.dumps(record))


def test_runs_wait_for_their_published_agent(tmp_path, monkeypatch):
    """Data from an agent not published yet, or not of the profile's steps, is never made from
    a stand-in: its runs wait, and run once the agent is there."""
    from gcdt.experiments import plan
    from gcdt.report.tables import agent_rows, table1

    monkeypatch.setenv("GCDT_ARTIFACTS", str(tmp_path / "artifacts"))
    agent = tmp_path / "experts" / "tqc_reach_sparse"
    profile = dataclasses.replace(
        TINY,
        expert_agents={"reach": str(agent / "model.zip")},
        agent_steps=120,
        tqc_agents=True,
        table1_tqc=Scope(tasks=()),
        rq4=Scope(tasks=()),
        rq5=Scope(tasks=()),
        ablation=Scope(tasks=()),
        targets=Scope(tasks=()),
        generalisation=Scope(tasks=()),
    )
    summary = sweep(profile, store_root=tmp_path / "runs", workers=1, progress=False)
    assert summary.ok and not summary.done and len(summary.waiting) == 2  # GC-DT and BC
    assert "2 waiting" in summary.line()
    assert summary.lines()[1] == f"waiting: 2 runs for {agent / 'model.zip'} (not published, " \
        "or not of agent_steps)"  # fmt: skip
    assert "gcdt tqc publish RUN_DIR" in summary.lines()[2]
    assert not (tmp_path / "runs").exists() or not list((tmp_path / "runs").glob("*.json"))
    _publish_fake_agent(agent, steps=100, success=0.5)  # another budget's agent: still waits
    store = RunStore(tmp_path / "runs")
    assert {p.state for p in plan(profile, store)[0]} == {"waiting"}
    assert agent_rows(profile, tmp_path / "experts") == []  # nor is it Table 1's TQC+HER
    (agent / "run.json").unlink(), (agent / "model.zip").unlink(), agent.rmdir()
    _publish_fake_agent(agent, steps=120, success=0.9)
    planned = plan(profile, store)[0]
    assert {p.state for p in planned} == {"missing"}
    assert "pending" not in {p.entry.spec.data.expert_digest for p in planned}
    (row,) = agent_rows(profile, tmp_path / "experts")
    cell = table1(pd.DataFrame([row])).iloc[0]
    assert (cell["method"], cell["success_mean"], cell["seeds"]) == ("tqc", 90.0, 1)
    assert cell["success_ci_low"] < 90.0 < cell["success_ci_high"]  # 500 held-out episodes
    assert (cell["paper_success"], cell["paper_return"]) == (100.0, -1.82)
    # A further seed, published beside seed 0's agent, joins the cell.
    _publish_fake_agent(agent.parent / f"{agent.name}_seed1", steps=120, success=0.7, seed=1)
    rows = agent_rows(profile, tmp_path / "experts")
    assert [r["seed"] for r in rows] == [0, 1]
    cell = table1(pd.DataFrame(rows)).iloc[0]
    assert (cell["seeds"], cell["success_mean"]) == (2, pytest.approx(80.0))
    # A folder holding another cell's agent is refused, not counted in the wrong cell.
    other = agent.parent / f"{agent.name}_seed2"
    _publish_fake_agent(other, steps=120, success=0.7, seed=2)
    record = json.loads((other / "run.json").read_text())
    (other / "run.json").write_text(json.dumps({**record, "task": "push"}))
    with pytest.raises(GcdtError, match=r"tqc_reach_sparse_seed2 holds a push/sparse agent, not"):
        agent_rows(profile, tmp_path / "experts")

"""Markdown tables of results/bench/*.json, optionally written into docs/benchmarks.md.

    python benchmarks/summary.py          # print
    python benchmarks/summary.py --docs   # replace the block between the bench markers

The documented benchmark numbers come only from here, so they are always those of the JSON
files `make bench` wrote.
"""

from __future__ import annotations

import argparse
import json

from common import BENCH_DIR

from gcdt.paths import REPO_ROOT, write_between_markers

START, END = "<!-- bench:start -->", "<!-- bench:end -->"
TASKS = ("reach", "push", "pick_and_place")


def _load(name: str) -> dict | None:
    path = BENCH_DIR / f"{name}.json"
    return json.loads(path.read_text()) if path.exists() else None


def _table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _cpu(report: dict) -> str:
    """The machine a report ran on, in words: the CPU generation changes these rates ~3x."""
    m = report["machine"]
    extension = {True: "with", False: "without"}.get(m.get("cpu_bf16"))
    bf16 = f" {extension} AVX512-BF16" if extension else ""
    return f"{m['cores']} cores of {m['cpu']}{bf16}"


def _pct(x: float) -> str:
    return f"{100 * x:.0f} %"


def _rate(res: dict, key: str, ratio: str) -> str:
    return f"{res[key]:.0f} ({_pct(res[ratio])})"


def _verdict(ok: bool) -> str:
    return "yes" if ok else "**no**"


def _training_targets(train: dict | None) -> list[list]:
    """Target rows of a training benchmark: the speed-ups over HF (the 1.5x target is the
    CPU's), the sampler's share."""
    if train is None:
        return []
    rows, res = [], train["results"]
    if res.get("speedup_vs_huggingface_fp32") is not None:
        x = res["speedup_vs_huggingface_fp32"]
        cpu = train.get("device", "cpu") == "cpu"
        rows.append(
            [
                "DT training step vs HF `DecisionTransformerModel`, fp32",
                f"{x:.2f}x",
                ">= 1.5x" if cpu else "- (1.5x on CPU)",
                _verdict(x >= 1.5) if cpu else "-",
            ]
        )
    if res.get("speedup_vs_huggingface_bf16") is not None:
        x = res["speedup_vs_huggingface_bf16"]
        rows.append(["DT training step vs HF, bf16 autocast", f"{x:.2f}x", "-", "-"])
    if res.get("speedup_vs_huggingface_fp32_short") is not None:
        x = res["speedup_vs_huggingface_fp32_short"]
        rows.append(
            [
                "DT training step vs HF, fp32, 13-step episodes (the quick profile's "
                "PickAndPlace length)",
                f"{x:.2f}x",
                "-",
                "-",
            ]
        )
    if res.get("speedup_vs_huggingface_fp32_tqc") is not None:
        x = res["speedup_vs_huggingface_fp32_tqc"]
        steps = train["config"]["tqc_episode_steps"]
        cpu = train.get("device", "cpu") == "cpu"
        rows.append(
            [
                f"DT training step vs HF, fp32, the Push TQC expert's episode lengths (mean "
                f"{steps['mean']:.1f} steps, the `large` profile's data)",
                f"{x:.2f}x",
                ">= 2x" if cpu else "- (2x on CPU)",
                _verdict(x >= 2) if cpu else "-",
            ]
        )
    share = res["dt_sampler_share"]
    rows.append(
        [
            "batch sampling, share of a DT step",
            f"{100 * share:.1f} %",
            "<= 5 %",
            _verdict(share <= 0.05),
        ]
    )
    return rows


def _evaluator_targets(ev: dict | None) -> list[list]:
    """Target rows of an evaluator benchmark: `evaluate` vs the ceiling and vs the authors."""
    if ev is None or "envs" not in ev:
        return []
    n, res = ev["envs"], ev["results"]
    vs_raw, vs_authors = (
        res[f"evaluate_gcdt_{n}_envs_vs_raw"],
        res[f"evaluate_gcdt_{n}_envs_vs_authors"],
    )
    ceiling = res[f"raw_vector_{n}_envs"] / res["authors_unbatched"]
    bound = (
        f"; simulator + forward pass alone: {_pct(res[f'bound_{n}_envs_vs_raw'])}, "
        f"{res[f'bound_{n}_envs_vs_authors']:.1f}x"
        if f"bound_{n}_envs" in res
        else ""
    )
    if f"evaluate_random_{n}_envs_vs_raw" in res:
        own = res[f"evaluate_random_{n}_envs_vs_raw"]
        bound += f"; `evaluate` with random actions: {_pct(own)}"
    return [
        [
            f"`evaluate` GC-DT on {n} envs vs raw random stepping of {n} envs (Push{bound})",
            _pct(vs_raw),
            ">= 70 %",
            _verdict(vs_raw >= 0.7),
        ],
        [
            f"`evaluate` GC-DT on {n} envs vs the authors' unbatched loop (Push; the simulator "
            f"alone is {ceiling:.1f}x)",
            f"{vs_authors:.1f}x",
            ">= 4x",
            _verdict(vs_authors >= 4),
        ],
    ]


def targets_section() -> str | None:
    """The issue's targets beside what this machine measured."""
    rows = _training_targets(_load("training_throughput"))
    rows += _evaluator_targets(_load("evaluator_throughput_push"))
    for t in TASKS:
        r = _load(f"collection_throughput_{t}")
        if r is None or "envs" not in r:
            continue
        n, res = r["envs"], r["results"]
        x, own = (
            res[f"collect_scripted_{n}_envs_vs_raw"],
            res[f"collect_scripted_{n}_envs_vs_raw_scripted"],
        )
        rows.append(
            [
                f"collection, scripted expert vs raw random stepping, {n} processes ({t}; "
                f"vs the expert stepped without recording: {_pct(own)})",
                _pct(x),
                ">= 80 %",
                _verdict(x >= 0.8),
            ]
        )
    io = _load("dataset_io_push")
    if io is not None:
        x = io["results"]["load_training_ready_seconds"]
        rows.append(
            [
                f"load {io['results']['transitions']:,} transitions to training-ready arrays",
                f"{x:.2f} s",
                "< 3 s",
                _verdict(x < 3),
            ]
        )
    e2e = _load("end_to_end")
    if e2e is not None and "make_reproduce_smoke_seconds" in e2e["results"]:
        x = e2e["results"]["make_reproduce_smoke_seconds"]
        rows.append(["`make reproduce PROFILE=smoke`, from scratch", f"{x / 60:.1f} min", "-", "-"])
    if not rows:
        return None
    return "Targets (each measured side by side in one run on this machine):\n\n" + _table(
        ["comparison", "measured", "target", "met"], rows
    )


def evaluator_section(name: str = "evaluator_throughput_push") -> str | None:
    r = _load(name)
    if r is None or "envs" not in r:
        return None
    n, res = r["envs"], r["results"]
    rows = [
        [
            f"raw vector env, {n} processes, random actions (ceiling)",
            f"{res[f'raw_vector_{n}_envs']:.0f}",
        ],
        [f"`evaluate`, GC-DT, {n} envs", f"{res[f'evaluate_gcdt_{n}_envs']:.0f}"],
        [
            "`evaluate`, GC-DT, 1 env (as a local sweep runs it)",
            f"{res['evaluate_gcdt_1_envs']:.0f}",
        ],
        [
            f"authors' loop: 1 env, context re-padded every step ({r['authors_model']})",
            f"{res['authors_unbatched']:.0f}",
        ],
    ]
    if f"bound_{n}_envs" in res:
        rows.append(
            [
                f"raw vector env, {n} processes, plus one GC-DT forward pass per step "
                f"({res[f'predict_ms_{n}_envs']:.1f} ms): a synchronous evaluator's bound",
                f"{res[f'bound_{n}_envs']:.0f}",
            ]
        )
    if f"evaluate_random_{n}_envs" in res:
        rows.insert(
            1,
            [
                f"`evaluate`, random actions, {n} envs (the evaluator's own cost)",
                f"{res[f'evaluate_random_{n}_envs']:.0f}",
            ],
        )
    if f"predict_in_loop_ms_{n}_envs" in res:
        rows.append(
            [
                f"GC-DT forward pass per step inside `evaluate`, ms (alone: "
                f"{res[f'predict_ms_{n}_envs']:.1f} ms with a full context)",
                f"{res[f'predict_in_loop_ms_{n}_envs']:.1f} ms",
            ]
        )
    return (
        f"Evaluation throughput on Push, env steps/s, resets included "
        f"(`benchmarks/evaluator_throughput.py`, {r['torch_threads']} torch threads):\n\n"
        + _table(["what", "env steps / s"], rows)
    )


def collection_section() -> str | None:
    runs = {t: _load(f"collection_throughput_{t}") for t in TASKS}
    rows = []
    for t, r in runs.items():
        if r is None or "envs" not in r:
            continue
        n, res = r["envs"], r["results"]
        rows.append(
            [
                t,
                n,
                f"{res[f'raw_vector_{n}_envs']:.0f}",
                _rate(res, f"collect_random_{n}_envs", f"collect_random_{n}_envs_vs_raw"),
                _rate(res, f"collect_scripted_{n}_envs", f"collect_scripted_{n}_envs_vs_raw"),
                _rate(
                    res,
                    f"raw_vector_scripted_{n}_envs",
                    f"collect_scripted_{n}_envs_vs_raw_scripted",
                ),
            ]
        )
    if not rows:
        return None
    return (
        "Collection throughput, transitions/s, stepping loop only "
        "(`benchmarks/collection_throughput.py`; % of raw random stepping on the same "
        "processes; last column: the expert stepped without recording, and the collector's "
        "share of it):\n\n"
        + _table(
            [
                "task",
                "processes",
                "raw random stepping",
                "collect random",
                "collect scripted",
                "raw scripted stepping",
            ],
            rows,
        )
    )


def io_section() -> str | None:
    r = _load("dataset_io_push")
    if r is None:
        return None
    res = r["results"]
    rows = [
        [
            f"save {res['transitions']:,} transitions ({res['episodes']:,} episodes)",
            f"{res['save_seconds']:.2f} s",
        ],
        ["file size (uncompressed .npz)", f"{res['file_mb']:.0f} MiB"],
        ["load with validation", f"{res['load_seconds']:.2f} s"],
        [
            "load to training-ready arrays (states, returns-to-go, timesteps)",
            f"{res['load_training_ready_seconds']:.2f} s",
        ],
        [
            f"Minari export, {res['minari_transitions']:,} transitions",
            f"{res['minari_export_seconds']:.1f} s",
        ],
        [
            f"Minari import, {res['minari_transitions']:,} transitions",
            f"{res['minari_import_seconds']:.1f} s",
        ],
    ]
    return "Dataset I/O, Push (`benchmarks/dataset_io.py`):\n\n" + _table(
        ["operation", "time"], rows
    )


def training_section(name: str = "training_throughput") -> str | None:
    r = _load(name)
    if r is None or "gcdt_fp32_ms_per_step" not in r["results"]:
        return None
    res = r["results"]
    cells = (
        ("gcdt_fp32", "GC-DT, gcdt, fp32"),
        ("huggingface_fp32", "GC-DT, HF (authors), fp32"),
        ("gcdt_bf16", "GC-DT, gcdt, bf16 autocast"),
        ("huggingface_bf16", "GC-DT, HF (authors), bf16 autocast"),
        ("gcdt_fp32_short", "GC-DT, gcdt, fp32, 13-step episodes"),
        ("huggingface_fp32_short", "GC-DT, HF (authors), fp32, 13-step episodes"),
        ("gcdt_fp32_tqc", "GC-DT, gcdt, fp32, Push TQC expert's episode lengths"),
        ("huggingface_fp32_tqc", "GC-DT, HF (authors), fp32, Push TQC expert's episode lengths"),
        ("bc_fp32", "BC, fp32"),
    )
    rows = [
        [label, f"{res[f'{k}_ms_per_step']:.1f}", f"{res[f'{k}_samples_per_second']:.0f}"]
        for k, label in cells
        if f"{k}_ms_per_step" in res
    ]
    return (
        f"Training step, batch 64, the paper's DT config (`benchmarks/training_throughput.py`, "
        f"{r['torch_threads']} torch threads, {r['huggingface']}):\n\n"
        + _table(["model", "ms / step", "samples / s"], rows)
    )


def end_to_end_section() -> str | None:
    r = _load("end_to_end")
    if r is None:
        return None
    q = r["results"]["quick_grid"]
    rows = [
        [
            k,
            f"{v / 60:.1f}",
            f"{q['measured_seconds_per_run'][k] / 60:.1f}"
            if k in q["measured_seconds_per_run"]
            else "-",
        ]
        for k, v in q["estimated_seconds_per_run"].items()
    ]
    return (
        f"The quick grid's cost per run, minutes (`benchmarks/end_to_end.py`; estimated from "
        f"the benchmarks' rates, and measured from {q['measured_runs']} finished runs in "
        f"results/quick/; {q['runs']} runs, about {q['estimated_wall_hours']:.1f} h on "
        f"{q['workers']} workers):\n\n" + _table(["run", "estimated", "measured"], rows)
    )


def _tqc_speed(speed: dict, where: str) -> str:
    """The table of `benchmarks/tqc_her.py throughput`'s report `speed`, made `where`."""
    rows = [
        [
            name,
            "x".join(map(str, c["net_arch"])),
            c["batch_size"],
            f"{c['sb3']['env_steps_per_second']:.1f}",
            f"{c['new']['env_steps_per_second']:.1f}",
            f"{c['speedup_vs_sb3']:.2f}x"
            + (" ({:.2f}-{:.2f})".format(*c["speedup_range"]) if "speedup_range" in c else ""),
            " / ".join(f"{h:.1f}" for h in c["hours_for_paper_budget"].values()),
        ]
        for name, c in speed["configs"].items()
    ]
    new = next(iter(speed["configs"].values()))["new"]
    return (
        f"TQC+HER training speed on {speed['task']}, env steps/s once gradient steps run, "
        "today's loop (sb3-contrib's TQC on one env, rl-baselines3-zoo's) against the "
        f"configs' ({new['backend']} backend on {new['n_envs']} envs, one gradient step "
        f"per env step), measured in one run {where}, the two loops taking turns "
        "(`benchmarks/tqc_her.py throughput`; env steps/s: the median over the rounds; "
        "speedup: the median of the rounds' paired ratios, their range in parentheses; hours: "
        f"the paper's step budget of that task at each speed; {speed['target']}):\n\n"
        + _table(["config", "networks", "batch", "sb3, 1 env", "new", "speedup", "hours"], rows)
    )


def tqc_section() -> str | None:
    speed, reach = _load("tqc_her_throughput"), _load("tqc_her_reach")
    push = _load("tqc_her_push")
    parts = []
    if speed is not None:
        parts.append(_tqc_speed(speed, f"on {_cpu(speed)}"))
    profile = _load("tqc_her_profile")
    if profile is not None and "loops" in profile:
        loops = profile["loops"]
        rows = [
            [part.replace("_", " ")]
            + [f"{cell['ms_per_learning_env_step'][part]:.2f}" for cell in loops.values()]
            for part in next(iter(loops.values()))["ms_per_learning_env_step"]
        ]
        rows.append(
            ["**total**"]
            + [f"**{sum(c['ms_per_learning_env_step'].values()):.2f}**" for c in loops.values()]
        )
        parts.append(
            f"Where the time goes: ms per env step of the learning phase, config "
            f"`{profile['config']}` on {profile['task']}, both loops profiled in one run "
            "(`benchmarks/tqc_her_profile.py`; cProfile slows the Python-heavy parts). The "
            f"gradient step alone is {profile['gradient_step_speedup']:.2f}x faster in the new "
            "loop; were everything else free, the new loop would be at most "
            f"{profile['speedup_ceiling']:.2f}x today's:\n\n"
            + _table(
                ["part"] + [f"{c['backend']}, {c['n_envs']} env(s)" for c in loops.values()], rows
            )
        )
    if reach is not None:
        rows = [
            [
                reward,
                r["env_steps"],
                f"{r['train_minutes']:.1f}",
                f"{100 * r['evaluation_10k_steps']['final']['success_rate']:.1f} %",
                f"{r['evaluation_10k_steps']['final']['mean_return']:.2f}",
                f"{100 * r['evaluation_10k_steps']['best']['success_rate']:.1f} %",
            ]
            for reward, r in reach["runs"].items()
        ]
        parts.append(
            f"TQC+HER on Reach, config `{reach['config']}` (`make bench-tqc`; success and "
            "return of the final and best models under the paper's 10,000-step evaluation):"
            "\n\n"
            + _table(
                [
                    "reward",
                    "env steps",
                    "training min",
                    "final success",
                    "final return",
                    "best success",
                ],
                rows,
            )
        )
    if push is not None:
        held = push["held_out_evaluation"]
        rows = [
            [
                int(p["env_steps"]),
                f"{p['train_seconds'] / 60:.1f}",
                f"{100 * p['success_rate']:.0f} %",
            ]
            for p in push["learning_curve"]
        ]
        parts.append(
            f"TQC+HER on Push (sparse), config `{push['config']['name']}` with the "
            f"{push['config']['backend']} backend on {push['config']['n_envs']} envs "
            f"(`{push['training_command']}`, then `benchmarks/tqc_her.py push`): "
            f"{push['env_steps']:,} env steps in {push['train_minutes']:.1f} min of training "
            f"({push['env_steps_per_second']:.0f} env steps/s); the final model succeeds in "
            f"{100 * held['success_rate']:.1f} % of {held['episodes']} held-out episodes "
            f"(return {held['mean_return']:.2f}); PickAndPlace's ~700k steps would take "
            f"{push['pick_and_place_hours_at_this_speed']:.1f} h at this speed. Learning curve "
            "(periodic evaluations on their own seeds):\n\n"
            + _table(["env steps", "training min", "success"], rows)
        )
    return "\n\n".join(parts) or None


def gpu_section() -> str | None:
    """The `--device cuda` runs, made on another machine than the rest."""
    train, ev = _load("training_throughput_cuda"), _load("evaluator_throughput_push_cuda")
    tqc = _load("tqc_her_throughput_cuda")
    rows = _training_targets(train) + _evaluator_targets(ev)
    if not rows:
        return None
    m = (train or ev)["machine"]
    parts = [
        f"On a GPU machine ({m.get('gpu')}, {m.get('cores')} CPU cores, torch {m.get('torch')}, "
        f"Python {m.get('python')}), both paths' models on the GPU (`--device cuda`): targets "
        "measured side by side in one run there:\n\n"
        + _table(["comparison", "measured", "target", "met"], rows),
        training_section("training_throughput_cuda"),
        evaluator_section("evaluator_throughput_push_cuda"),
        _tqc_speed(tqc, "there, both loops' networks on the GPU") if tqc else None,
    ]
    return "\n\n".join(p for p in parts if p)


def summary() -> str:
    sections = [
        s
        for s in (
            targets_section(),
            training_section(),
            evaluator_section(),
            collection_section(),
            io_section(),
            end_to_end_section(),
            tqc_section(),
            gpu_section(),
        )
        if s
    ]
    cpu_runs = [p.stem for p in sorted(BENCH_DIR.glob("*.json")) if not p.stem.endswith("_cuda")]
    machines: dict[str, list[str]] = {}  # a machine's description -> the benchmarks run on it
    for name in cpu_runs:
        if (run := _load(name)) is not None:
            machines.setdefault(_machine_text(run["machine"]), []).append(name)
    if len(machines) <= 1:
        where = next(iter(machines), "")
    else:  # re-measured in part on another machine: say which ran where
        where = "; ".join(f"{m}: {', '.join(names)}" for m, names in machines.items())
    head = f"Generated by `python benchmarks/summary.py --docs` from `results/bench/` ({where})."
    return "\n\n".join([head, *sections])


def _machine_text(machine: dict) -> str:
    bf16 = {True: ", native bf16", False: ", bf16 emulated"}.get(machine.get("cpu_bf16"), "")
    return (
        f"{machine.get('cpu', 'CPU')}{bf16}, {machine.get('cores', '?')} cores, "
        f"{machine.get('device', 'cpu')}, torch {machine.get('torch', '?')}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--docs", action="store_true", help="update docs/benchmarks.md in place")
    args = parser.parse_args()
    text = summary()
    if not args.docs:
        print(text)
        return
    write_between_markers(REPO_ROOT / "docs" / "benchmarks.md", START, END, text)


if __name__ == "__main__":
    main()

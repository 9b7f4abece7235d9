"""Markdown tables of results/bench/*.json, optionally written into the README.

    python benchmarks/summary.py            # print
    python benchmarks/summary.py --readme   # replace the block between the bench markers

The README's benchmark numbers come only from here, so they are always those of the JSON
files `make bench` wrote.
"""

from __future__ import annotations

import argparse
import json
import re

from common import BENCH_DIR

from gcdt.paths import REPO_ROOT

START, END = "<!-- bench:start -->", "<!-- bench:end -->"
TASKS = ("reach", "push", "pick_and_place")


def _load(name: str) -> dict | None:
    path = BENCH_DIR / f"{name}.json"
    return json.loads(path.read_text()) if path.exists() else None


def _table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def evaluator_section() -> str | None:
    runs = {t: _load(f"evaluator_throughput_{t}") for t in TASKS}
    if not any(runs.values()):
        return None
    keys = [
        ("raw_single_env", "raw, 1 env in-process"),
        ("raw_vector_1_envs", "raw vector, 1 env"),
        ("evaluate_random_1_envs", "evaluate random, 1 env"),
        ("evaluate_scripted_1_envs", "evaluate scripted, 1 env"),
        ("raw_vector_2_envs", "raw vector, 2 envs"),
        ("evaluate_random_2_envs", "evaluate random, 2 envs"),
        ("evaluate_scripted_2_envs", "evaluate scripted, 2 envs"),
    ]
    rows = [
        [t, *(f"{r['results'][k]:.0f}" for k, _ in keys)] for t, r in runs.items() if r is not None
    ]
    return "Evaluator throughput, env steps/s (`benchmarks/evaluator_throughput.py`):\n\n" + _table(
        ["task", *(label for _, label in keys)], rows
    )


def collection_section() -> str | None:
    runs = {t: _load(f"collection_throughput_{t}") for t in TASKS}
    if not any(runs.values()):
        return None
    rows = []
    for t, r in runs.items():
        if r is None:
            continue
        res = r["results"]
        for n in (1, 2):
            rows.append(
                [
                    t,
                    n,
                    f"{res[f'raw_vector_{n}_envs']:.0f}",
                    f"{res[f'collect_random_{n}_envs']:.0f} "
                    f"({100 * res[f'collect_random_{n}_envs_vs_raw']:.0f} %)",
                    f"{res[f'collect_scripted_{n}_envs']:.0f} "
                    f"({100 * res[f'collect_scripted_{n}_envs_vs_raw']:.0f} %)",
                    f"{res[f'raw_vector_scripted_{n}_envs']:.0f} "
                    f"({100 * res[f'collect_scripted_{n}_envs_vs_raw_scripted']:.0f} %)",
                ]
            )
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


def training_section() -> str | None:
    r = _load("training_throughput")
    if r is None:
        return None
    res = r["results"]
    rows = [
        [label, f"{res[f'{k}_ms_per_step']:.0f}", f"{res[f'{k}_samples_per_second']:.0f}",
         f"{100 * res[f'{k}_sampler_share']:.1f} %"]
        for k, label in (("dt_fp32", "DT, fp32"), ("dt_bf16", "DT, bf16 autocast"),
                         ("bc_fp32", "BC, fp32"))
    ]  # fmt: skip
    return (
        f"Training step, batch 64, the paper's DT config (`benchmarks/training_throughput.py`, "
        f"{r['torch_threads']} torch threads):\n\n"
        + _table(["model", "ms / step", "samples / s", "batch sampling share"], rows)
    )


def tqc_section() -> str | None:
    speed, reach = _load("tqc_her_throughput"), _load("tqc_her_reach")
    parts = []
    if speed is not None:
        rows = [
            [name, "x".join(map(str, c["net_arch"])), c["batch_size"],
             f"{c['learning_steps_per_second']:.1f}", f"{c['hours_for_paper_budget']:.1f}"]
            for name, c in speed["configs"].items()
        ]  # fmt: skip
        parts.append(
            f"TQC+HER training speed on {speed['task']}, env steps/s once gradient steps run "
            "(`benchmarks/tqc_her.py throughput`; hours: the paper's step budget of that task "
            "at this speed):\n\n"
            + _table(["config", "networks", "batch", "env steps / s", "hours"], rows)
        )
    if reach is not None:
        rows = [
            [reward, r["env_steps"], f"{r['train_minutes']:.1f}",
             f"{100 * r['evaluation_10k_steps']['final']['success_rate']:.1f} %",
             f"{r['evaluation_10k_steps']['final']['mean_return']:.2f}",
             f"{100 * r['evaluation_10k_steps']['best']['success_rate']:.1f} %"]
            for reward, r in reach["runs"].items()
        ]  # fmt: skip
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
    return "\n\n".join(parts) or None


def summary() -> str:
    sections = [
        s
        for s in (
            evaluator_section(),
            collection_section(),
            io_section(),
            training_section(),
            tqc_section(),
        )
        if s
    ]
    machine = next(
        (r["machine"] for r in map(_load, [p.stem for p in sorted(BENCH_DIR.glob("*.json"))]) if r),
        {},
    )
    head = (
        f"Generated by `python benchmarks/summary.py --readme` from `results/bench/` "
        f"({machine.get('cores', '?')} cores, {machine.get('device', 'cpu')}, torch "
        f"{machine.get('torch', '?')})."
    )
    return "\n\n".join([head, *sections])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readme", action="store_true", help="update README.md in place")
    args = parser.parse_args()
    text = summary()
    if not args.readme:
        print(text)
        return
    readme = REPO_ROOT / "README.md"
    old = readme.read_text()
    if START not in old or END not in old:
        raise SystemExit(f"README.md lacks the markers {START} ... {END}")
    block = f"{START}\n{text}\n{END}"
    readme.write_text(
        re.sub(re.escape(START) + ".*?" + re.escape(END), lambda _: block, old, flags=re.S)
    )


if __name__ == "__main__":
    main()

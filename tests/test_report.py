"""gcdt.report: tables and figures computed from result files with known metrics."""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pandas as pd
import pytest

from gcdt import report
from gcdt.cli import main
from gcdt.errors import GcdtError
from gcdt.experiments import RunStore, build_grid
from gcdt.experiments.grid import RUN_SCHEMA
from gcdt.experiments.profiles import PROFILES, SMOKE, Scope
from gcdt.provenance import utc_now
from gcdt.report import figures, tables

ALL = Scope(tasks=("reach", "push"), rewards=("sparse",))
PROFILE = dataclasses.replace(
    SMOKE,
    name="report-test",
    seeds=(0, 1, 2),
    table1=ALL,
    table1_tqc=ALL,
    rq4=ALL,
    rq5=ALL,
    ablation=ALL,
    targets=Scope(tasks=()),  # its runs need evaluations: test_return_target_study_... has its own
)


def _success(spec) -> float:
    """A known, distinct success rate per run: grows with data size, ratio and seed."""
    size = spec.data.size / spec.data.base_size if spec.data else 1.0
    ratio = spec.data.expert_ratio if spec.data else 1.0
    return round(0.5 * size * ratio + 0.1 * spec.seed + (0.2 if spec.method == "gcdt" else 0), 4)


def _write_result(store: RunStore, spec, metrics: dict, **fields) -> None:
    """A finished run's result file with the given metrics (and other fields)."""
    result = {"key": spec.key(), "schema": RUN_SCHEMA, "status": "done", "spec": spec.to_dict()}
    store.write(spec.key(), {**result, "metrics": metrics, **fields})


def _write_runs(root) -> RunStore:
    store = RunStore(root)
    for entry in build_grid(PROFILE):
        spec = entry.spec
        metrics = {"success_rate": _success(spec), "mean_return": -10 * spec.seed, "episodes": 20}
        _write_result(store, spec, metrics)
    return store


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    return tables.load_runs(PROFILE, _write_runs(tmp_path_factory.mktemp("runs")).root)


def test_table1_aggregates_over_seeds_beside_the_paper(runs):
    table = tables.table1(runs)
    assert list(table["reward"].unique()) == ["sparse"]
    assert list(table["method"].unique()) == ["gcdt", "bc", "tqc"]
    row = table[(table["method"] == "gcdt") & (table["task"] == "reach")].iloc[0]
    expected = 100 * np.array([0.7, 0.8, 0.9])  # size 1, ratio 1, +0.2 for gcdt, +0.1 * seed
    assert row["success_mean"] == pytest.approx(expected.mean())
    assert row["success_std"] == pytest.approx(expected.std(ddof=1))
    assert expected.min() <= row["success_ci_low"] <= row["success_ci_high"] <= expected.max()
    assert row["return_mean"] == pytest.approx(-10.0) and row["seeds"] == 3
    assert (row["paper_return"], row["paper_success"]) == (-1.72, 100.0)
    md = tables.to_markdown(table)
    low, high = row["success_ci_low"], row["success_ci_high"]
    cell = f"-10.00 ± 10.00 / 80.0 ± 10.0 [{low:.1f}, {high:.1f}] (paper -1.72 / 100.0)"
    assert f"| GC-DT | {cell} |" in md
    tex = tables.to_latex(table, "Performance", "tab:t1")
    assert r"\multicolumn{4}{c}{\textit{Sparse Reward}} \\" in tex and r"\bottomrule" in tex


def test_ablation_table_compares_goal_conditionings(runs):
    table = tables.ablation_table(runs)
    assert set(table["method"]) == {"gcdt", "dt-desired", "dt"}
    gcdt, dt = (
        table[(table["method"] == m) & (table["task"] == "push")].iloc[0] for m in ("gcdt", "dt")
    )
    assert gcdt["success_mean"] - dt["success_mean"] == pytest.approx(20.0)


def test_figures_plot_the_means_over_seeds(runs):
    fig = figures.dataset_size_figure(runs)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "Dataset size (transitions)"
    assert ax.get_ylabel() == "Success rate (%)" and ax.get_title() == "Sparse reward"
    line = ax.lines[0]  # Reach
    np.testing.assert_array_equal(line.get_xdata(), PROFILE.rq4_sizes)
    sizes = np.array(PROFILE.rq4_sizes) / PROFILE.dataset_size
    ydata = np.asarray(line.get_ydata(), dtype=float)
    np.testing.assert_allclose(ydata, 100 * (0.5 * sizes + 0.2 + 0.1))
    fig = figures.expert_ratio_figure(runs)
    np.testing.assert_array_equal(fig.axes[0].lines[0].get_xdata(), [0, 50, 100])


def test_curve_tables_hold_the_figures_points(runs):
    curve = tables.curve_table(runs, "rq5", "expert_ratio")
    assert list(curve["task"]) == ["reach"] * 3 + ["push"] * 3  # the paper's task order
    assert list(curve["expert_ratio"]) == [0.0, 0.5, 1.0] * 2
    push_half = curve[(curve["task"] == "push") & (curve["expert_ratio"] == 0.5)].iloc[0]
    expected = 100 * np.array([0.45, 0.55, 0.65])  # 0.5 * 0.5 + 0.2 for gcdt + 0.1 * seed
    assert push_half["success_mean"] == pytest.approx(expected.mean())
    assert push_half["seeds"] == 3
    md = tables.curve_markdown(curve, "expert_ratio")
    assert md.splitlines()[0] == "| reward | task | 0 % | 50 % | 100 % |"
    low, high = push_half["success_ci_low"], push_half["success_ci_high"]
    assert f"| 55.0 [{low:.1f}, {high:.1f}] |" in md.splitlines()[-1]
    # The figure draws exactly these points.
    line = figures.expert_ratio_figure(runs).axes[0].containers[1].lines[0]  # Push's errorbar
    ydata = np.asarray(line.get_ydata(), dtype=float)
    np.testing.assert_allclose(ydata, curve[curve["task"] == "push"]["success_mean"])
    empty = tables.curve_table(runs[runs["method"] != "gcdt"], "rq4", "size")
    assert empty.empty and "No runs" in tables.curve_markdown(empty, "size")


def test_no_results_say_what_to_run(tmp_path):
    with pytest.raises(GcdtError, match="run `gcdt sweep --profile report-test`"):
        tables.load_runs(PROFILE, tmp_path)


def test_directions_set_each_claim_of_the_paper_beside_ours(runs):
    table = tables.directions(runs).set_index("comparison")
    # GC-DT is 20 points above BC and TQC+HER in the fixture; in the paper it is level with
    # BC (within a point) on Reach and Push.
    assert table.loc["GC-DT vs BC, Push sparse"].tolist() == [
        "equal (+0.4 pts)",
        "higher (+20.0 pts)",
        False,
    ]
    assert table.loc["GC-DT vs BC, Reach sparse"].tolist() == [
        "equal (+0.0 pts)",
        "higher (+20.0 pts)",
        False,
    ]
    assert table.loc["GC-DT vs TQC+HER, Push sparse", "paper"] == "lower (-4.5 pts)"
    rq4 = "RQ4, {} sparse: less success on the smallest subset than on all data"
    assert table.loc[rq4.format("Reach")].tolist() == [
        "no (invariant)",
        "yes (smallest 55.0 % vs all 80.0 %)",
        False,
    ]
    assert table.loc[rq4.format("Push"), "agrees"]
    assert table.loc["RQ5, Push sparse: less success at 0 % expert than at 100 %", "agrees"]
    assert "| GC-DT vs BC, Reach sparse | equal (+0.0 pts) | higher (+20.0 pts) | **no** |" in (
        tables.directions_markdown(runs)
    )


def test_directions_across_profiles_set_each_profiles_answer_side_by_side(runs, monkeypatch):
    """A comparison one profile makes and another does not shows '--'; a profile with no
    published runs gets no column; disagreements are bold and counted."""
    table1_only = runs[runs["sections"].apply(lambda s: "table1" in s)]
    table1_only = table1_only.assign(sections=[("table1",)] * len(table1_only))
    by_name = {"small": table1_only, "big": runs}

    def load(profile, runs_dir=None):
        if profile.name not in by_name:
            raise GcdtError("no finished runs")
        return by_name[profile.name]

    monkeypatch.setattr(tables, "load_runs", load)
    names = [dataclasses.replace(PROFILE, name=n) for n in ("small", "big", "unrun")]
    table = tables.directions_across(names).set_index("comparison")
    assert list(table.columns) == ["paper", "small", "big"]
    assert table.loc["GC-DT vs BC, Push sparse", "small"] == ("higher (+20.0 pts)", False)
    rq4 = "RQ4, Push sparse: less success on the smallest subset than on all data"
    assert pd.isna(table.loc[rq4, "small"]) and table.loc[rq4, "big"][1]
    text = tables.directions_across_markdown(names)
    row = "| GC-DT vs BC, Push sparse | equal (+0.4 pts) | **higher (+20.0 pts)** | **higher"
    assert row in text
    assert f"| {rq4} | yes | -- | yes (smallest" in text
    agree_small = sum(a for _, a in table["small"].dropna())
    last = f"| **same direction as the paper** | | {agree_small} of"
    assert text.splitlines()[-1].startswith(last)


def test_table1_across_profiles_sets_each_cell_beside_the_papers(runs, monkeypatch):
    """Each Table 1 cell's mean in every profile with published runs, then the paper's; a cell
    a profile has not finished with every seed is '--', not a mean of fewer seeds."""
    push_bc_seed2 = (runs["method"] == "bc") & (runs["task"] == "push") & (runs["seed"] == 2)
    by_name = {"small": runs[~push_bc_seed2], "big": runs}

    def load(profile, runs_dir=None):
        if profile.name not in by_name:
            raise GcdtError("no finished runs")
        return by_name[profile.name]

    monkeypatch.setattr(tables, "load_runs", load)
    names = [dataclasses.replace(PROFILE, name=n) for n in ("small", "big", "unrun")]
    across = tables.table1_across(names)
    assert list(across.columns) == ["reward", "method", "task", "small", "big", "paper"]
    whole = tables.table1(runs).set_index(["reward", "method", "task"])
    push_bc = across.set_index(["reward", "method", "task"]).loc[("sparse", "bc", "push")]
    mean = whole.loc[("sparse", "bc", "push")]
    assert push_bc["big"] == f"{mean['return_mean']:.2f} / {mean['success_mean']:.1f}"
    assert pd.isna(push_bc["small"])  # 2 of its 3 seeds
    assert push_bc["paper"] == "-8.18 / 94.6"  # the paper's Table 1
    text = tables.table1_across_markdown(names)
    assert text.splitlines()[0] == "| reward | method | task | `small` | `big` | paper |"
    assert f"| sparse | BC | Push | -- | {push_bc['big']} | -8.18 / 94.6 |" in text
    assert tables.table1_across_markdown(names[2:]).startswith("*No profile")


def test_a_grid_still_running_shows_only_its_whole_cells_and_says_how_far_it_got(runs, monkeypatch):
    """A cell missing a seed, or a curve missing a point, is not read from what is there: a
    profile half-way through its grid must not publish a mean of fewer seeds than planned."""
    push_bc_seed2 = (runs["method"] == "bc") & (runs["task"] == "push") & (runs["seed"] == 2)
    smallest = runs["size"] == min(PROFILE.rq4_sizes)
    rq4_smallest = runs["sections"].apply(lambda s: s == ("rq4",)) & smallest
    running = runs[~push_bc_seed2 & ~rq4_smallest]
    monkeypatch.setattr(tables, "load_runs", lambda profile, runs_dir=None: running)
    table = tables.directions_across([PROFILE]).set_index("comparison")
    whole = tables.directions(runs).set_index("comparison")
    assert "GC-DT vs BC, Push sparse" in whole.index
    assert "GC-DT vs BC, Push sparse" not in table.index  # 2 of its 3 seeds only
    assert table.loc["GC-DT vs BC, Reach sparse", PROFILE.name] == (
        whole.loc["GC-DT vs BC, Reach sparse", "ours"],
        bool(whole.loc["GC-DT vs BC, Reach sparse", "agrees"]),
    )
    assert not any(c.startswith("RQ4") for c in table.index)  # its smallest subset is missing
    assert any(c.startswith("RQ5") for c in table.index)
    planned = len(build_grid(PROFILE))
    head = tables.directions_across_markdown([PROFILE]).splitlines()[0]
    assert head == f"| comparison | paper | `report-test` ({len(running)} of {planned} runs) |"
    monkeypatch.setattr(tables, "load_runs", lambda profile, runs_dir=None: runs)
    assert tables.directions_across_markdown([PROFILE]).startswith(
        "| comparison | paper | `report-test` |"
    )


@pytest.mark.parametrize(("longer", "within"), [(0.53, True), (0.9, False)])
def test_budget_check_sets_the_longer_run_against_the_budget_runs_interval(
    tmp_path, longer, within
):
    from gcdt.report import budget

    push = Scope(tasks=("push",), rewards=("sparse",))
    profile = dataclasses.replace(
        PROFILE, table1=push, table1_tqc=Scope(tasks=()), rq4=push, rq5=push, ablation=push,
        budget=push, budget_factor=4, budget_ratios=(1.0, 0.5),
    )  # fmt: skip
    store = RunStore(tmp_path)
    for entry in build_grid(profile):
        ratio = entry.spec.data.expert_ratio
        # On expert data the longer run scores `longer`; on the mixture it changes nothing.
        # The budget runs' seeds differ by 2 points each.
        success = (0.5 if ratio == 1.0 else 0.3) + 0.02 * entry.spec.seed
        if entry.sections == ("budget",):
            success = longer if ratio == 1.0 else 0.3
        _write_result(store, entry.spec, {"success_rate": success, "mean_return": -9.0,
                                          "episodes": 200})  # fmt: skip
    table = budget.budget_table(tables.load_runs(profile, tmp_path), profile.budget_factor)
    row, mixed = table.sort_values("expert_ratio", ascending=False).itertuples()
    assert (row.task, row.seed, row.expert_ratio, row.steps, row.longer_steps) == (
        "push", 0, 1.0, 10, 40,
    )  # fmt: skip
    assert row.success == 50.0 and row.longer_success == pytest.approx(100 * longer)
    low, high = tables.wilson_ci(0.5, 200)
    assert (row.success_ci_low, row.success_ci_high) == pytest.approx((100 * low, 100 * high))
    assert row.within is within and row.change == pytest.approx(100 * longer - 50)
    # The mixture's check stands beside RQ5's run of the same mixture, not Table 1's.
    assert (mixed.expert_ratio, mixed.success, mixed.change, mixed.within) == (0.5, 30.0, 0, True)
    # The cell's three seeds at the budget span 50-54 % (30-34 % on the mixture).
    assert (row.seeds, row.seeds_low, row.seeds_high) == pytest.approx((3, 50.0, 54.0))
    assert row.within_seeds is within and mixed.within_seeds is True
    text = budget.budget_markdown(table)
    assert ("| 100 | 10 | 50.0 " in text) and ("| 50 | 10 | 30.0 " in text)
    assert "| 50.0-54.0 (3 seeds) |" in text and "| 30.0-34.0 (3 seeds) |" in text
    assert text.count("| **no** |") == (0 if within else 2)


def test_budget_check_sets_each_budget_of_the_grid_against_its_own_runs(tmp_path):
    from gcdt.report import budget

    # Table 1 trains twice as long as the figures' points: each budget gets its longer run,
    # set against the runs of that budget only (not the other budget's runs of the same data).
    push = Scope(tasks=("push",), rewards=("sparse",))
    profile = dataclasses.replace(
        PROFILE, table1=push, table1_tqc=Scope(tasks=()), rq4=Scope(tasks=()), rq5=push,
        ablation=Scope(tasks=()), generalisation=Scope(tasks=()), budget=push, budget_factor=4,
        budget_ratios=(1.0,), table1_train_steps={**PROFILE.train_steps, "push": 20},
    )  # fmt: skip
    store = RunStore(tmp_path)
    steps = {}
    for entry in build_grid(profile):
        spec = entry.spec
        if spec.data.expert_ratio != 1.0 or spec.method != "gcdt":
            continue
        steps.setdefault(spec.seed, []).append(spec.train_steps)
        # Success grows with the budget: 10 steps 40 %, 20 steps 60 %, 40 and 80 steps 70 %.
        success = {10: 0.4, 20: 0.6, 40: 0.7, 80: 0.7}[spec.train_steps] + 0.01 * spec.seed
        _write_result(store, spec, {"success_rate": success, "mean_return": -9.0,
                                    "episodes": 200})  # fmt: skip
    assert sorted(steps[0]) == [10, 20, 40, 80] and sorted(steps[1]) == [10, 20]
    table = budget.budget_table(tables.load_runs(profile, tmp_path), profile.budget_factor)
    rows = {r.steps: r for r in table.itertuples()}
    assert sorted(rows) == [10, 20] and set(table["expert_ratio"]) == {1.0}
    # The figures' budget: 40 % at 10 steps against 70 % at 40 (Table 1's own run of seed 0).
    assert (rows[10].longer_steps, rows[10].success, rows[10].longer_success) == (40, 40.0, 70.0)
    assert (rows[10].seeds_low, rows[10].seeds_high) == pytest.approx((40.0, 42.0))
    assert rows[10].within is False
    # Table 1's budget: 60 % at 20 steps against 70 % at 80, beside Table 1's seeds only.
    assert (rows[20].longer_steps, rows[20].success, rows[20].longer_success) == (80, 60.0, 70.0)
    assert (rows[20].seeds, rows[20].seeds_low, rows[20].seeds_high) == pytest.approx((3, 60, 62))


def test_fidelity_sets_each_gcdt_cell_against_the_papers_targets_beside_its_data(tmp_path):
    from gcdt.report import fidelity

    store = RunStore(tmp_path)
    # Reach: the paper's success, a return 20 % worse (within 25 %); Push: 5 points short and
    # twice the paper's return, from data that was itself that slow.
    ours = {"reach": (1.0, -1.72 * 1.2), "push": (0.90, -8.26 * 2)}
    for entry in build_grid(PROFILE):
        spec = entry.spec
        success, mean_return = ours[spec.task] if spec.method == "gcdt" else (0.5, -30.0)
        data = {"success_rate": success, "mean_return_sparse": mean_return - 1}
        _write_result(store, spec, {"success_rate": success, "mean_return": mean_return,
                                    "episodes": 200}, training={"dataset": data})  # fmt: skip
    table = fidelity.fidelity_table(tables.load_runs(PROFILE, tmp_path)).set_index("task")
    reach, push = table.loc["reach"], table.loc["push"]
    assert reach["success_met"] and reach["return_met"] and reach["seeds"] == 3
    assert reach["return_gap"] == pytest.approx(-0.2)
    assert push["success_gap"] == pytest.approx(90 - 95.0) and not push["success_met"]
    assert push["return_gap"] == pytest.approx(-1.0) and not push["return_met"]
    assert (push["data_success"], push["data_return"]) == pytest.approx((90.0, -8.26 * 2 - 1))
    md = fidelity.fidelity_markdown(table.reset_index())
    assert "| sparse | Push | 3 | 90.0 (95.0) | **-5.0** | -16.52 (-8.26) | **-100 %** |" in md
    assert "| sparse | Reach | 3 | 100.0 (100.0) | +0.0 | -2.06 (-1.72) | -20 % |" in md
    assert md.endswith("| 1 of 2 cells |")


def test_directions_check_the_papers_floor_at_a_quarter_of_expert_data(tmp_path):
    profile = dataclasses.replace(PROFILE, rq5_ratios=(0.0, 0.25, 1.0))
    store = RunStore(tmp_path)
    for entry in build_grid(profile):
        metrics = {"success_rate": _success(entry.spec), "mean_return": 0.0, "episodes": 20}
        _write_result(store, entry.spec, metrics)
    table = tables.directions(tables.load_runs(profile, tmp_path)).set_index("comparison")
    # 0.5 * 0.25 + 0.2 for gcdt + 0.1 * seed: 42.5 % over seeds 0-2, under the paper's 80 %.
    floor = "RQ5, Push sparse: above 80 % success at 25 % expert"
    assert table.loc[floor].tolist() == ["yes", "no (42.5 %)", False]
    assert not any(c.startswith("RQ5, Reach sparse: above") for c in table.index)  # not claimed
    # A grid still running: without the 0 % runs the trend waits, the floor does not.
    partial = RunStore(tmp_path / "partial")
    for entry in build_grid(profile):
        if not (entry.spec.data and entry.spec.data.expert_ratio == 0.0):
            _write_result(partial, entry.spec, {"success_rate": _success(entry.spec),
                                                "mean_return": 0.0, "episodes": 20})  # fmt: skip
    table = tables.directions(tables.load_runs(profile, tmp_path / "partial"))
    assert table.set_index("comparison").loc[floor].tolist() == ["yes", "no (42.5 %)", False]
    assert not table["comparison"].str.contains("at 0 % expert").any()


def test_reproduction_record_and_readme_block(tmp_path, monkeypatch):
    monkeypatch.setenv("GCDT_OUTPUTS", str(tmp_path))
    store = _write_runs(tmp_path / "results" / PROFILE.name / "runs")
    monkeypatch.setitem(PROFILES, PROFILE.name, PROFILE)
    unrecorded = "No wall time recorded: these results were not made by `make reproduce` "
    assert unrecorded + "(`gcdt sweep --profile report-test --dry-run` estimates" in (
        report.readme_block(PROFILE)
    )
    # Two runs made by an earlier, interrupted `make reproduce`; the others by this one.
    grid = build_grid(PROFILE)
    for i, entry in enumerate(grid):
        finished = "2026-01-01T00:00:00+00:00" if i < 2 else utc_now()
        execution = {"finished": finished, "seconds": {"total_seconds": 3600.0 if i < 2 else 60}}
        result = store.read(entry.spec.key()).result
        _write_result(store, entry.spec, result["metrics"], execution=execution)
    with pytest.raises(GcdtError, match="wall time must be >= 0"):
        report.record_reproduction(PROFILE, -1, "local")
    # `make reproduce`'s last step: the record, then the report that prints it.
    assert main(["report", "--profile", PROFILE.name, "--wall-seconds", "5430.04"]) == 0
    record = json.loads((tmp_path / "results" / PROFILE.name / "reproduce.json").read_text())
    assert record["command"] == "make reproduce PROFILE=report-test BACKEND=local"
    assert record["wall_seconds"] == 5430.0 and record["runs"] == len(grid)
    assert record["earlier_runs"] == 2 and record["earlier_run_seconds"] == 7200.0
    assert record["run_seconds"] == 7200.0 + 60 * (len(grid) - 2)
    # report.md prints the profile's description with the measured cost beside it.
    written = (tmp_path / "results" / PROFILE.name / "report.md").read_text()
    done = f"({len(grid)} of {len(grid)} runs finished)"
    assert f"{done}. {report.wall_time_text(PROFILE)}\n\nThe `report-test`" in written
    assert "it took **90 min** for the rest" in written
    block = report.readme_block(PROFILE)
    assert "**90 min**" in block and "| GC-DT vs BC, Push sparse |" in block
    assert (
        "resumed an interrupted reproduction: 2 runs (2.0 h of their own time) were done" in block
    )
    assert "it took **90 min** for the rest" in block  # the invocation's time, named as such
    assert "![Fig. 3: success rate vs dataset size (RQ4)](figures/report-test/" in block
    assert "![Goal generalisation (ours): success inside vs outside" in block
    # Each figure is followed by its numbers: Fig. 3's points, success inside and outside.
    after = block.split("fig3_dataset_size.png)")[1]
    assert after.startswith("\n\n| reward | task | ") and " [" in after.split("\n")[4]
    regions = block.split("goal_generalisation.png)")[1]
    assert "| success elsewhere (%) |" in regions and "| y ≤ 0 | " in regions
    assert "] at y ≤ 0 | " in regions and "] at y ≥ 0 |" in regions
    assert "**Goal-conditioning ablation**" in block and "deviates from the paper" in block
    # Run files shared with another profile's results, byte for byte, are counted as such; a
    # file of the same key whose content differs is not.
    assert "byte for byte" not in block
    smoke_runs = tmp_path / "results" / "smoke" / "runs"
    smoke_runs.mkdir(parents=True)
    own = sorted((tmp_path / "results" / PROFILE.name / "runs").glob("*.json"))
    for path in own[:3]:
        (smoke_runs / path.name).write_bytes(path.read_bytes())
    (smoke_runs / own[3].name).write_text("{}")
    assert "3 of its run files are the `smoke` profile's, byte for byte" in (
        report.readme_block(PROFILE)
    )
    # A finished grid that no `make reproduce` timed gives what its runs cost in all.
    (tmp_path / "results" / PROFILE.name / "reproduce.json").unlink()
    total = (7200 + 60 * (len(grid) - 2)) / 3600
    assert f"{done[:-1]}; its runs' own times add up to {total:.1f} h (one core" in (
        report.readme_block(PROFILE)
    )
    # A grid still running says so, and what its finished runs cost so far.
    for entry in grid[-2:]:  # two of the 60 s runs
        (tmp_path / "results" / PROFILE.name / "runs" / f"{entry.spec.key()}.json").unlink()
    report.write_report(PROFILE)
    written = (tmp_path / "results" / PROFILE.name / "report.md").read_text()
    hours = (7200 + 60 * (len(grid) - 4)) / 3600
    running = (
        f"({len(grid) - 2} of {len(grid)} runs finished; the grid is still running (its "
        f"finished runs took {hours:.1f} h of their own time"
    )
    assert running in written
    # The README block of a profile whose grid is running (the one to quote while it runs)
    # says the same, and where to find what is left.
    block = report.readme_block(PROFILE)
    assert running in block and f"`gcdt sweep --profile {PROFILE.name} --dry-run` lists" in block
    # Both list the grid's sections, each run once: what is finished, and the rest's estimate.
    left = tables.sections_left(PROFILE)
    assert list(left["section"]) == [s for s in PROFILE.section_order if s in set(left["section"])]
    assert left["planned"].sum() == len(grid) and left["finished"].sum() == len(grid) - 2
    unfinished = left[left["finished"] < left["planned"]]
    assert len(unfinished) >= 1 and (unfinished["hours_left"] > 0).all()
    assert (left[left["finished"] == left["planned"]]["hours_left"] == 0).all()
    row = unfinished.iloc[0]
    line = (
        f"| {row.section} | {row.finished} | {row.planned} | about {row.hours_left:.1f} h of work |"
    )
    assert "**The grid's sections**" in written and line in written and line in block
    # The published estimate is the same on every machine: a checkpoint left here by a
    # killed run shortens the dry run's, not the report's.
    import gcdt.experiments.artifacts as artifacts

    monkeypatch.setattr(artifacts, "checkpointed_steps", lambda spec: 10**9)
    assert tables.sections_left(PROFILE).equals(left)
    from gcdt.experiments.sweep import plan

    planned, _ = plan(PROFILE, RunStore(tmp_path / "results" / PROFILE.name / "runs"))
    resumed = [p for p in planned if p.state != "done" and p.entry.spec.method != "tqc"]
    # Runs sharing a checkpoint (one training, two evaluations) count it once.
    trained = {p.entry.spec.training_key() for p in resumed}
    assert resumed and trained == {p.entry.spec.training_key() for p in resumed if p.done_steps}


def test_report_cli_rejects_a_negative_wall_time(capsys):
    assert main(["report", "--profile", "smoke", "--wall-seconds", "-5"]) != 0
    assert "--wall-seconds must be >= 0, got -5.0" in capsys.readouterr().err


#: Validation and test success per target of the return-target study's synthetic runs: the
#: best target on validation (-5) is not the best on test (-10), so a choice made on the test
#: evaluations would show.
STUDY = {0.0: (0.5, 0.6), -5.0: (0.9, 0.7), -10.0: (0.8, 0.95)}


def test_return_target_study_picks_on_validation_and_scores_on_test(tmp_path):
    from gcdt.report import targets

    profile = dataclasses.replace(
        PROFILE,
        table1=Scope(tasks=("reach",), rewards=("sparse",)),
        targets=Scope(tasks=("reach",), rewards=("sparse",)),
        return_targets={"sparse": tuple(STUDY)},
    )
    store = RunStore(tmp_path)
    for entry in build_grid(profile, "targets"):
        spec = entry.spec
        evaluations = [
            {
                "seed": seed,
                "success_rate": rate + 0.01 * spec.seed,
                "mean_return": -20 * (1 - rate),
                "std_return": 1.0,
                "episodes": 100,
            }
            for seed, rate in zip(spec.eval_seeds, STUDY[spec.target_return], strict=True)
        ]
        metrics = {"success_rate": 0.0, "mean_return": 0.0, "episodes": 200}
        _write_result(store, spec, metrics, evaluations=evaluations)
    runs = tables.load_runs(profile, tmp_path)
    curve = targets.target_table(runs)
    assert list(curve["target_return"]) == [0.0, -5.0, -10.0] and set(curve["seeds"]) == {3}
    assert curve["success_mean"].tolist() == pytest.approx([61.0, 71.0, 96.0])  # test split
    (best,) = targets.best_targets(runs).to_dict("records")
    assert best["best_target"] == -5.0  # chosen on validation
    assert best["best_success_mean"] == pytest.approx(71.0)  # scored on test
    assert best["zero_success_mean"] == pytest.approx(61.0)
    assert "| sparse | Reach | -5 | 71.0 [" in targets.best_targets_markdown(pd.DataFrame([best]))
    fig = targets.target_figure(runs)
    assert [ax.get_title() for ax in fig.axes[:1]] == ["Sparse reward"]
    assert len(fig.axes[0].get_lines()) >= 1
    with pytest.raises(GcdtError, match="unknown split 'train': expected one of validation"):
        targets.study_runs(runs, "train")


def test_online_offline_figure_sets_agents_curves_beside_offline_runs(runs, tmp_path):
    agent = tmp_path / "tqc_push_sparse"
    agent.mkdir()
    record = {"task": "push", "reward": "sparse", "seed": 0, "env_steps": 3000}
    (agent / "run.json").write_text(json.dumps(record))
    (agent / "eval.csv").write_text(
        "env_steps,train_seconds,wall_seconds,success_rate,mean_return,episodes\n"
        "25000,1.0,1.0,0.2,-40.0,100\n50000,2.0,2.0,0.9,-9.5,100\n"
    )
    agents = tables.load_agent_curves(tmp_path)
    assert list(agents["env_steps"]) == [25000, 50000] and set(agents["agent"]) == {agent.name}
    fig = figures.online_offline_figure(runs, agents)
    reach, push = fig.axes
    assert push.get_title() == "Push, sparse reward" and push.get_xscale() == "log"
    (online,) = [line for line in push.lines if "published agent" in line.get_label()]
    np.testing.assert_allclose(online.get_ydata(), [20.0, 90.0])
    # GC-DT's points: the Table 1 and RQ4 runs on expert data, the mean over seeds per size.
    gcdt = push.containers[0].lines[0]
    sizes = sorted({*PROFILE.rq4_sizes, PROFILE.dataset_size})
    np.testing.assert_array_equal(gcdt.get_xdata(), sizes)
    expected = [100 * (0.5 * s / PROFILE.dataset_size + 0.2 + 0.1) for s in sizes]
    np.testing.assert_allclose(np.asarray(gcdt.get_ydata(), dtype=float), expected)
    assert not [line for line in reach.lines if "published agent" in line.get_label()]
    assert tables.load_agent_curves(tmp_path / "none").empty


def test_online_offline_figure_keeps_each_training_budget_apart(tmp_path):
    # Table 1 trains Push 4x longer than RQ4: its 1M dot must not average both budgets' seeds.
    steps = dict(SMOKE.train_steps)
    profile = dataclasses.replace(PROFILE, table1_train_steps={**steps, "push": 4 * steps["push"]})
    store = RunStore(tmp_path / "runs")
    for entry in build_grid(profile):
        spec = entry.spec
        rate = _success(spec) + (0.05 if spec.train_steps == 4 * steps["push"] else 0.0)
        _write_result(store, spec, {"success_rate": rate, "mean_return": -1.0, "episodes": 20})
    runs = tables.load_runs(profile, store.root)
    empty = tables.load_agent_curves(tmp_path / "none")
    push = figures.online_offline_figure(runs, empty).axes[1]
    labels = [c.get_label() for c in push.containers]
    short, long_ = (f"GC-DT, offline on expert data, {n:,} steps" for n in (10, 40))
    assert short in labels and long_ in labels
    (table1,) = [c.lines[0] for c in push.containers if c.get_label() == long_]
    np.testing.assert_array_equal(table1.get_xdata(), [profile.dataset_size])
    np.testing.assert_allclose(table1.get_ydata(), [100 * (0.5 + 0.2 + 0.1 + 0.05)])
    (rq4,) = [c.lines[0] for c in push.containers if c.get_label() == short]
    sizes = np.array(sorted({*profile.rq4_sizes, profile.dataset_size}))
    np.testing.assert_array_equal(rq4.get_xdata(), sizes)
    expected = 100 * (0.5 * sizes / profile.dataset_size + 0.2 + 0.1)
    np.testing.assert_allclose(np.asarray(rq4.get_ydata(), dtype=float), expected)


def _agent(root, task, reward, env_steps, curve, held_out=None, n_envs=8, seed=0):
    """A published agent's folder as `gcdt tqc publish` writes it (`held_out`: its held-out
    success and return; None: published before held-out measurements, without a record)."""
    folder = root / (f"tqc_{task}_{reward}" + (f"_seed{seed}" if seed else ""))
    folder.mkdir(parents=True)
    record = {"task": task, "reward": reward, "seed": seed, "env_steps": env_steps}
    record["config"] = {"n_envs": n_envs}
    if held_out is not None:
        success, ret, episodes = held_out
        measured = {"success_rate": success, "mean_return": ret, "std_return": 2.0}
        record["published"] = {"held_out": {**measured, "episodes": episodes, "seed": 5000}}
    (folder / "run.json").write_text(json.dumps(record))
    rows = [f"{steps},1.0,1.0,{success},-10.0,100" for steps, success in curve]
    header = "env_steps,train_seconds,wall_seconds,success_rate,mean_return,episodes"
    (folder / "eval.csv").write_text("\n".join([header, *rows]) + "\n")


def test_agents_table_puts_each_published_agent_beside_the_papers_tqc_cell(tmp_path, monkeypatch):
    from gcdt.report import agents

    experts = tmp_path / "experts"
    curve = [(25_000, 0.1), (100_000, 0.4), (250_000, 0.7), (500_000, 0.8), (1_000_000, 0.88)]
    _agent(experts, "push", "sparse", 1_000_000, curve, held_out=(0.9, -6.5, 500))
    # Evaluations land up to one loop iteration (n_envs steps) past a mark: 100,003 is the
    # 100k evaluation of 8 envs, 250,010 is past 250k's.
    short = [(100_003, 0.25), (250_010, 0.6), (300_000, 0.65)]
    _agent(experts, "pick_and_place", "dense", 300_000, short, held_out=(0.5, -20.0, 200))
    _agent(experts, "push", "dense", 300_000, [(100_000, 0.3)])  # no held-out record
    table = agents.agents_table(experts).set_index(["task", "reward"])
    assert list(table.index) == [
        (task, reward)
        for task in ("reach", "push", "pick_and_place")
        for reward in ("dense", "sparse")
    ]
    push = table.loc[("push", "sparse")]
    assert push["status"] == "published" and push["seeds"] == 1
    assert (push["success"], push["return"], push["env_steps"]) == (90.0, -6.5, 1_000_000)
    # Wilson's 95 % interval of 450 successes in 500 episodes.
    assert push[["success_ci_low", "success_ci_high"]].tolist() == pytest.approx(
        [87.058, 92.332], abs=1e-3
    )
    assert push["held_out_episodes"] == 500
    assert (push["paper_success"], push["paper_return"]) == (99.5, -4.54)
    assert push["paper_steps"] == 1_000_000
    assert push[[f"curve_success_{b}" for b in agents.CURVE_BUDGETS]].tolist() == pytest.approx(
        [40.0, 70.0, 80.0, 88.0]
    )
    pick = table.loc[("pick_and_place", "dense")]
    assert pick["curve_success_100000"] == 25.0
    assert pick[["curve_success_250000", "curve_success_1000000"]].isna().all()
    assert table.loc[("push", "dense"), "status"] == "no held-out record"
    assert np.isnan(table.loc[("push", "dense"), "success"])
    missing = table.loc[("pick_and_place", "sparse")]
    assert missing["status"] == "not yet published" and missing["seeds"] == 0
    assert (missing["paper_success"], missing["paper_return"]) == (77.0, -16.96)
    assert pd.isna(missing["env_steps"]) and np.isnan(missing["success"])
    assert table.loc[("reach", "sparse"), "paper_steps"] == 20_000

    # `gcdt report` writes it under the outputs root, as Markdown and CSV.
    monkeypatch.setenv("GCDT_OUTPUTS", str(tmp_path / "out"))
    md, csv = report.write_agents_table(experts)
    assert md == tmp_path / "out" / "results" / "experts" / "table1_tqc.md"
    lines = md.read_text().splitlines()
    assert (
        "| Push | sparse | 90.0 [87.1, 92.3] | -6.50 | 1,000,000 | 1 | 99.5 | -4.54 | 1,000,000 "
        "| 40.0 | 70.0 | 80.0 | 88.0 |" in lines
    )
    assert (
        "| PickAndPlace | sparse | not yet published | – | – | 0 | 77.0 | -16.96 | 1,000,000 "
        "| – | – | – | – |" in lines
    )
    assert (
        "| Push | dense | no held-out record | – | 300,000 | 1 | 98.7 | -1.04 |" in md.read_text()
    )
    written = pd.read_csv(csv).set_index(["task", "reward"])
    assert written.loc[("push", "sparse"), "success"] == 90.0
    assert written.loc[("reach", "dense"), "status"] == "not yet published"


def _snapshot(experts, name, task, reward, seed, env_steps, curve):
    """A run's snapshot as `gcdt tqc snapshot` keeps it: a checkpoint (its header is all the
    table reads) and the curve so far."""
    from gcdt.baselines.tqc_checkpoint import _write

    folder = experts / "in_progress" / name
    folder.mkdir(parents=True)
    config = {"name": "cpu_zoo_batch", "n_envs": 8}
    header = {"task": task, "reward": reward, "seed": seed, "config": config}
    _write(folder / "checkpoint.tqc", {**header, "env_steps": env_steps, "buffer": False}, {})
    rows = [f"{steps},1.0,1.0,{success},-10.0,100" for steps, success in curve]
    head = "env_steps,train_seconds,wall_seconds,success_rate,mean_return,episodes"
    (folder / "eval.csv").write_text("\n".join([head, *rows]) + "\n")
    return folder


def test_a_run_in_progress_is_shown_beside_the_published_agent_at_the_same_steps(
    tmp_path, monkeypatch
):
    """A candidate's snapshot (`gcdt tqc snapshot`) is read from its checkpoint's header and
    curve: its success at each budget it reached, and at its latest evaluation, beside the
    published agent's of its task, reward and seed (not another seed's) within one loop
    iteration of the same steps; curve points past the checkpoint (a resume rewrites them)
    are left out."""
    from gcdt.report import agents

    experts = tmp_path / "experts"
    curve = [(100_000, 0.12), (250_000, 0.185), (275_000, 0.24), (500_000, 0.265)]
    _agent(experts, "pick_and_place", "sparse", 1_000_000, curve, held_out=(0.46, -30.7, 500))
    other_seed = [(100_000, 0.9), (250_000, 0.9), (275_000, 0.9), (500_000, 0.9)]
    _agent(experts, "pick_and_place", "sparse", 1_000_000, other_seed, seed=1)
    ahead = [(100_003, 0.3), (250_003, 0.5), (275_003, 0.55), (300_003, 0.9)]
    candidate = "tqc_pick_and_place_sparse_cpu_zoo_batch"
    _snapshot(experts, candidate, "pick_and_place", "sparse", 0, 280_000, ahead)
    # Just begun, of a cell with no published agent: a row of its own, nothing to compare.
    _snapshot(experts, "tqc_push_dense_cpu_zoo_batch", "push", "dense", 0, 6_968, [])
    # A snapshot being written beside them (a killed `gcdt tqc snapshot` leaves one) is not
    # a run in progress.
    _snapshot(experts, ".tqc_push_dense.x1y2", "push", "dense", 0, 9_000, [])

    table = agents.in_progress_table(experts)
    assert list(table["run"]) == [candidate, "tqc_push_dense_cpu_zoo_batch"]
    row, fresh = table.to_dict("records")
    assert (row["config"], row["env_steps"], row["agent"]) == (
        "cpu_zoo_batch",
        280_000,
        "tqc_pick_and_place_sparse",
    )
    assert [row["success_100000"], row["agent_success_100000"]] == pytest.approx([30.0, 12.0])
    assert [row["success_250000"], row["agent_success_250000"]] == pytest.approx([50.0, 18.5])
    assert np.isnan(row["success_500000"]) and row["agent_success_500000"] == 26.5
    assert row["latest_steps"] == 275_003  # 300,003 lies past the snapshot's 280,000
    assert [row["success_latest"], row["agent_success_latest"]] == pytest.approx([55.0, 24.0])
    assert pd.isna(fresh["agent"]) and pd.isna(fresh["latest_steps"])
    assert all(np.isnan(fresh[f"agent_success_{b}"]) for b in agents.CURVE_BUDGETS)

    monkeypatch.setenv("GCDT_OUTPUTS", str(tmp_path / "out"))
    md, _ = report.write_agents_table(experts)
    lines = md.read_text().splitlines()
    assert "## Runs in progress" in lines
    assert (
        f"| {candidate} | cpu_zoo_batch | 280,000 | 275,003: 55.0 / 24.0 | 30.0 / 12.0 "
        "| 50.0 / 18.5 | – / 26.5 | – / – |" in lines
    )
    assert (
        "| tqc_push_dense_cpu_zoo_batch | cpu_zoo_batch | 6,968 | – | – / – | – / – "
        in md.read_text()
    )
    # A snapshot without its curve is refused in one line; without runs in progress the
    # section is left out.
    (experts / "in_progress" / candidate / "eval.csv").unlink()
    with pytest.raises(GcdtError, match=r"has a checkpoint but no eval.csv: snapshot the run"):
        agents.in_progress_table(experts)
    shutil.rmtree(experts / "in_progress")
    assert "Runs in progress" not in report.write_agents_table(experts)[0].read_text()


def test_a_damaged_agent_record_is_refused_in_one_line(tmp_path):
    from gcdt.baselines.publish import read_agent

    agent = tmp_path / "tqc_push_sparse"
    agent.mkdir()
    assert read_agent(agent) is None  # nothing published there
    (agent / "run.json").write_text('{"task": "push"')
    with pytest.raises(GcdtError, match=r"run.json is not a readable agent record .*publish"):
        read_agent(agent)
    (agent / "run.json").write_text('{"task": "push", "reward": "sparse"}')
    with pytest.raises(GcdtError, match=r"run\.json lacks seed, env_steps: publish it again"):
        read_agent(agent)

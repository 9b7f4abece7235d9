"""A reproduction against the published results: the check, publishing, and a regression test
that renders every notebook and the report from results alone, with the artifacts deleted."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest
from scipy import stats
from test_report import PROFILE, _write_result, _write_runs

from gcdt.cli import main
from gcdt.errors import GcdtError
from gcdt.experiments import RunStore, build_grid, get_profile, sweep
from gcdt.paths import ARTIFACTS_ENV, OUTPUTS_ENV, REPO_ROOT, figures_dir, results_dir
from gcdt.report import figures, reproduction, tables


def _runs(root: Path):
    return tables.load_runs(PROFILE, results_dir(PROFILE.name, root) / "runs")


def _shift(root: Path, method: str, task: str, by: float, seeds: tuple[int, ...] = (0,)) -> None:
    """Move the success rate of a Table 1 cell's runs of `seeds` by `by`."""
    store = RunStore(results_dir(PROFILE.name, root) / "runs")
    for entry in build_grid(PROFILE, only="table1"):
        spec = entry.spec
        if (spec.method, spec.task, spec.reward) == (method, task, "sparse") and spec.seed in seeds:
            result = store.read(spec.key()).result
            result["metrics"]["success_rate"] += by
            store.write(spec.key(), result)


@pytest.fixture
def published_and_ours(tmp_path):
    published, ours = tmp_path / "published", tmp_path / "ours"
    _write_runs(results_dir(PROFILE.name, published) / "runs")
    _write_runs(results_dir(PROFILE.name, ours) / "runs")
    return published, ours


def test_identical_runs_agree_everywhere(published_and_ours):
    published, ours = published_and_ours
    check = reproduction.reproduction_check(_runs(published), _runs(ours))
    table1_cells = 2 * 3 * 1  # tasks reach/push x methods gcdt/bc/tqc x sparse
    assert (check["item"].str.startswith("Table 1:")).sum() == 2 * table1_cells  # success, return
    assert (check["item"].str.startswith("Fig. 3:")).any()
    assert (check["item"].str.startswith("Fig. 4:")).any()
    assert check["agrees"].all() and (check["difference"] == 0).all()
    assert (check["diff_low"] < 0).all() and (check["diff_high"] > 0).all()  # seeds' spread
    assert (check["over"] == "seeds").all()


def test_identical_values_without_spread_agree(tmp_path):
    """Every seed alike on both sides: no spread, a difference of exactly 0, and agreement."""
    roots = tmp_path / "published", tmp_path / "ours"
    for root in roots:
        store = RunStore(results_dir(PROFILE.name, root) / "runs")
        for entry in build_grid(PROFILE):
            metrics = {"success_rate": 1.0, "mean_return": -2.0, "episodes": 20}
            _write_result(store, entry.spec, metrics)
    check = reproduction.reproduction_check(*(_runs(root) for root in roots))
    assert check["agrees"].all()
    assert (check[["difference", "diff_low", "diff_high"]] == 0).all(axis=None)


def test_a_shifted_cell_disagrees_and_the_interval_is_welchs(published_and_ours):
    """All three seeds of one cell 30 points lower (a regression such as a halved budget):
    flagged, with Welch's interval of the difference as scipy computes it from the seeds."""
    published, ours = published_and_ours
    _shift(ours, "bc", "push", by=-0.3, seeds=PROFILE.seeds)
    check = reproduction.reproduction_check(_runs(published), _runs(ours)).set_index(
        ["item", "metric"]
    )
    row = check.loc[("Table 1: BC, Push sparse", "success")]
    before = np.array([50.0, 60.0, 70.0])  # test_report._success: 0.5 + 0.1 * seed
    welch = stats.ttest_ind(before - 30, before, equal_var=False).confidence_interval(0.95)
    assert row["difference"] == pytest.approx(-30.0)
    assert (row["diff_low"], row["diff_high"]) == pytest.approx((welch.low, welch.high))
    assert row["diff_high"] < 0 and not row["agrees"]
    assert check.loc[("Table 1: GC-DT, Push sparse", "success"), "agrees"]
    assert int((~check["agrees"]).sum()) == 1
    line = reproduction.summary_line(check.reset_index())
    assert line.startswith(f"{len(check) - 1} of {len(check)} values agree: the 95 % interval")
    assert "contains 0" in line and "1 in 20" in line
    assert line.endswith("(values counted as independent): as expected of an honest re-run.")
    text, path = reproduction.write_check(PROFILE, ours, published)
    assert "(Welch's t interval), contains 0" in text and "1 in 20" in text
    assert "| -30.00 % | " not in text and "| 30.00 % | -30.00 [" in text
    written = pd.read_csv(path.with_suffix(".csv"))
    assert {"published", "ours", "difference", "diff_low", "diff_high", "agrees"} <= set(written)


def test_one_seed_shifted_by_a_seeds_spread_still_agrees(published_and_ours):
    """The case the published interval alone got wrong: one seed of three moved, the mean by
    15 points, within what a re-run's own seed spread allows."""
    published, ours = published_and_ours
    _shift(ours, "bc", "push", by=0.45)
    check = reproduction.reproduction_check(_runs(published), _runs(ours)).set_index(
        ["item", "metric"]
    )
    row = check.loc[("Table 1: BC, Push sparse", "success")]
    assert row["difference"] == pytest.approx(15.0)  # mean of 3 seeds moved by 45 / 3 points
    assert (
        row["ours"]
        > tables.table1(_runs(published))
        .query("method == 'bc' and task == 'push'")
        .iloc[0]["success_ci_high"]
    )  # outside the published mean's own interval
    assert row["agrees"] and check["agrees"].all()


#: Same-distribution re-runs: each run's success rate and return around these, by seed.
SUCCESS, SUCCESS_SD, RETURN, RETURN_SD = 0.6, 0.05, -10.0, 2.0


def _redrawn(runs: pd.DataFrame, rng: np.random.Generator, regressed: str = "") -> pd.DataFrame:
    """`runs` with every run's success and return drawn anew (its seed spread), and those of
    method `regressed` 6 standard deviations lower."""
    shift = np.where(runs["method"] == regressed, -6.0, 0.0)
    return runs.assign(
        success_rate=rng.normal(SUCCESS + shift * SUCCESS_SD, SUCCESS_SD, len(runs)),
        mean_return=rng.normal(RETURN + shift * RETURN_SD, RETURN_SD, len(runs)),
    )


@pytest.fixture(scope="module")
def grid_runs(tmp_path_factory):
    """The test profile's runs (3 seeds a cell) as `load_runs` gives them."""
    return tables.load_runs(PROFILE, _write_runs(tmp_path_factory.mktemp("runs")).root)


def test_same_distribution_reruns_agree_at_the_nominal_rate(grid_runs):
    """About 95 % of an honest re-run's values agree (Welch's interval is slightly wide with 3
    seeds a side: about 96-97 %), and not all: the rate is a rate, not a pass mark."""
    rng = np.random.default_rng(43)
    checks = [
        reproduction.reproduction_check(_redrawn(grid_runs, rng), _redrawn(grid_runs, rng))
        for _ in range(20)
    ]
    agrees = pd.concat(checks)["agrees"]
    assert len(agrees) >= 400 and 0.90 <= agrees.mean() <= 0.99


def test_a_regression_is_flagged(grid_runs):
    """GC-DT's runs 6 standard deviations lower, as a halved training budget would make them:
    every GC-DT value disagrees, the other methods' mostly agree."""
    rng = np.random.default_rng(7)
    check = reproduction.reproduction_check(
        _redrawn(grid_runs, rng), _redrawn(grid_runs, rng, regressed="gcdt")
    )
    gcdt = check["item"].str.contains("GC-DT") | check["item"].str.startswith("Fig.")
    assert gcdt.sum() >= 10 and not check.loc[gcdt, "agrees"].any()
    assert (check.loc[gcdt, "diff_high"] < 0).all()
    assert check.loc[~gcdt, "agrees"].mean() >= 0.8


def _write_episodes(root: Path, profile, rng: np.random.Generator, push_success: float) -> dict:
    """One-seed runs whose metrics and evaluation summarise drawn episodes (success on Reach
    always, `push_success` on Push; returns around RETURN); returns each run's episodes."""
    store, episodes = RunStore(results_dir(profile.name, root) / "runs"), {}
    for entry in build_grid(profile):
        spec = entry.spec
        success = (rng.random(200) < (1.0 if spec.task == "reach" else push_success)) * 1.0
        returns = rng.normal(RETURN, RETURN_SD, 200)
        n, mean = len(returns), float(returns.mean())
        evaluation = {"seed": spec.seed, "episodes": n, "success_rate": float(success.mean()),
                      "mean_return": mean, "std_return": float(returns.std())}  # fmt: skip
        metrics = {k: evaluation[k] for k in ("success_rate", "mean_return", "episodes")}
        _write_result(store, spec, metrics, evaluations=[evaluation])
        episodes[spec.key()] = (spec, success, returns)
    return episodes


def test_one_seed_cells_compare_their_episodes(tmp_path):
    """With one seed (the smoke profile), Welch's interval over each run's evaluation episodes,
    as scipy computes it from the episodes themselves; a lower success rate is flagged."""
    single = dataclasses.replace(PROFILE, name="report-test-1", seeds=(0,))
    rng = np.random.default_rng(1)
    published = _write_episodes(tmp_path / "published", single, rng, push_success=0.8)
    ours = _write_episodes(tmp_path / "ours", single, rng, push_success=0.5)
    check = reproduction.reproduction_check(
        *(tables.load_runs(single, results_dir(single.name, tmp_path / n) / "runs")
          for n in ("published", "ours"))
    ).set_index(["item", "metric"])  # fmt: skip
    assert (check["over"] == "episodes").all()
    bc_push = next(k for k, (s, _, _) in published.items() if (s.method, s.task) == ("bc", "push"))
    for metric, i, scale in (("success", 1, 100.0), ("return", 2, 1.0)):
        row = check.loc[("Table 1: BC, Push sparse", metric)]
        a, b = ours[bc_push][i] * scale, published[bc_push][i] * scale
        welch = stats.ttest_ind(a, b, equal_var=False).confidence_interval(0.95)
        assert (row["diff_low"], row["diff_high"]) == pytest.approx((welch.low, welch.high))
    push = check.xs("success", level="metric").filter(like="Push", axis=0)
    assert not push["agrees"].any()  # 80 % -> 50 % over 200 episodes
    reach = check.xs("success", level="metric").filter(like="Reach", axis=0)
    assert reach["agrees"].all() and (reach["diff_low"] == reach["diff_high"]).all()


def test_one_seed_cells_get_an_interval_from_their_episodes():
    low, high = tables.wilson_ci(0.9, 200)
    assert 0.84 < low < 0.9 < high < 0.94
    assert tables.wilson_ci(1.0, 100)[1] == pytest.approx(1.0)


def test_the_summary_tells_chance_disagreements_from_a_regression():
    """One value in 20 disagrees by chance; four of eight (a halved training budget, say) is
    too many for chance, and the summary says so; missing values are not counted."""

    def check(disagree: int, values: int, missing: int = 0) -> pd.DataFrame:
        agrees = [False] * (disagree + missing) + [True] * (values - disagree)
        ours = [np.nan] * missing + [1.0] * (disagree + values - disagree)
        return pd.DataFrame({"metric": "success", "agrees": agrees, "ours": ours})

    assert reproduction.chance_of_as_many(0, 8) == 1.0
    assert reproduction.chance_of_as_many(1, 1) == pytest.approx(0.05)
    assert reproduction.chance_of_as_many(4, 8) == pytest.approx(stats.binom.sf(3, 8, 0.05))
    assert "by chance with probability" not in reproduction.summary_line(check(0, 8))
    line = reproduction.summary_line(check(2, 40))
    assert "2 or more of 40 disagree by chance with probability 0.6" in line
    assert line.endswith("as expected of an honest re-run.")
    line = reproduction.summary_line(check(4, 8, missing=3))
    assert line.startswith("4 of 11 values agree") and "missing: 3" in line
    assert "4 or more of 8 disagree by chance with probability 0.00037" in line
    assert line.endswith("look for a regression (less training, a changed default).")


def test_missing_runs_are_reported_and_never_agree(published_and_ours):
    published, ours = published_and_ours
    for path in (results_dir(PROFILE.name, ours) / "runs").glob("*.json"):
        if json.loads(path.read_text())["spec"]["method"] == "tqc":
            path.unlink()
    check = reproduction.reproduction_check(_runs(published), _runs(ours))
    missing = check[check["item"].str.contains("TQC")]
    assert len(missing) and missing["ours"].isna().all() and not missing["agrees"].any()
    assert f"missing: {len(missing)}" in reproduction.summary_line(check)


def test_a_cell_left_with_one_seed_uses_its_episodes(published_and_ours):
    """Ours has one seed of a cell: its side of the difference is that run's episodes (its 20
    episodes' success rate), the published side its seeds; its return stored no spread over
    episodes, so there only an equal value would agree."""
    published, ours = published_and_ours
    for path in (results_dir(PROFILE.name, ours) / "runs").glob("*.json"):
        spec = json.loads(path.read_text())["spec"]
        if (spec["method"], spec["task"], spec["seed"]) in {("bc", "push", 1), ("bc", "push", 2)}:
            path.unlink()
    check = reproduction.reproduction_check(_runs(published), _runs(ours))
    cell = check.set_index(["item", "metric"]).loc["Table 1: BC, Push sparse"]
    assert (cell["over"] == "seeds / episodes").all()
    # Ours: 50 % of 20 episodes; published: seeds at 50, 60, 70 %.
    a, b = (100 * np.sqrt(0.25 * 20 / 19)) ** 2 / 20, 10.0**2 / 3  # squared standard errors
    df = (a + b) ** 2 / (a**2 / 19 + b**2 / 2)
    half = stats.t.ppf(0.975, df) * np.sqrt(a + b)
    success = cell.loc["success"]
    assert (success["diff_low"], success["diff_high"]) == pytest.approx((-10 - half, -10 + half))
    assert success["agrees"]
    back = cell.loc["return"]  # ours: seed 0's return 0; published: 0, -10, -20
    assert np.isnan(back["diff_low"]) and back["difference"] == 10.0 and not back["agrees"]
    assert "+10.00 [no spread known] | seeds / episodes | **no** |" in (
        reproduction.check_markdown(check)
    )


def test_compare_cli_without_published_results_says_so(tmp_path, capsys):
    (results_dir("smoke", tmp_path) / "runs").mkdir(parents=True)
    assert main(["compare", "--profile", "smoke", "--ours", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    if (results_dir("smoke", REPO_ROOT) / "runs").exists():  # a developer's own smoke run
        pytest.skip("this checkout has smoke results of its own")
    assert "No published results of profile 'smoke'" in out


def test_publish_mirrors_a_finished_run_and_refuses_an_unfinished_one(published_and_ours):
    published, ours = published_and_ours
    stale = results_dir(PROFILE.name, published) / "runs" / "0000000000000000.json"
    stale.write_text("{}")
    kept = results_dir(PROFILE.name, published) / ".gitkeep"  # hidden: never mirrored
    kept.write_text("")
    (figures_dir(PROFILE.name, ours)).mkdir(parents=True)
    (figures_dir(PROFILE.name, ours) / "a.png").write_bytes(b"png")
    checkpoints = figures_dir(PROFILE.name, ours) / ".ipynb_checkpoints"
    checkpoints.mkdir()
    (checkpoints / "b.png").write_bytes(b"")
    unchanged = next((results_dir(PROFILE.name, published) / "runs").glob("[1-9a-f]*.json"))
    os.utime(unchanged, (1, 1))
    _shift(ours, "gcdt", "reach", by=-0.1)
    with pytest.raises(GcdtError, match=r"holds no reproduce\.json: only a finished"):
        reproduction.publish(PROFILE, ours, published)  # runs done, notebooks never ran
    (results_dir(PROFILE.name, ours) / "reproduce.json").write_text("{}")
    written, removed = reproduction.publish(PROFILE, ours, published)
    assert removed == [stale] and kept.exists()
    assert unchanged.stat().st_mtime == 1  # identical: untouched
    assert (figures_dir(PROFILE.name, published) / "a.png").read_bytes() == b"png"
    assert not (figures_dir(PROFILE.name, published) / ".ipynb_checkpoints").exists()
    shifted = [p for p in written if p.parent.name == "runs"]  # the one changed run
    assert len(shifted) == 1 and {p.name for p in written} - {shifted[0].name} == {
        "a.png",
        "reproduce.json",
    }
    check = reproduction.reproduction_check(_runs(published), _runs(ours))
    assert check["agrees"].all()
    next((results_dir(PROFILE.name, ours) / "runs").glob("*.json")).unlink()
    with pytest.raises(GcdtError, match=r"1 run\(s\) of profile 'report-test' are not done"):
        reproduction.publish(PROFILE, ours, published)


def test_figures_are_written_only_when_their_bytes_change(tmp_path):
    def draw():
        fig, ax = plt.subplots()
        ax.plot([0, 1], [1, 0], marker="o")
        return fig

    paths = figures.save(draw(), tmp_path, "f")
    first = {p: p.read_bytes() for p in paths}
    for p in paths:
        os.utime(p, (1, 1))
    figures.save(draw(), tmp_path, "f")
    assert {p: p.read_bytes() for p in paths} == first  # no creation date in the files
    assert all(p.stat().st_mtime == 1 for p in paths)  # and not rewritten


@pytest.mark.slow
def test_notebooks_and_report_render_from_results_with_the_artifacts_deleted(tmp_path):
    """Today's fresh-clone failure, reproduced: a finished smoke grid whose artifacts are gone
    (as on a clone of published results). Notebooks 01-06 and the report must render from the
    run results alone, making no artifact; the explorer (07) may train its checkpoint."""
    import papermill

    artifacts, outputs = tmp_path / "artifacts", tmp_path / "outputs"
    env = {ARTIFACTS_ENV: str(artifacts), OUTPUTS_ENV: str(outputs)}
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)  # the kernels papermill starts inherit these
    try:
        smoke = get_profile("smoke")
        assert sweep(smoke, progress=False).ok
        shutil.rmtree(artifacts)
        for notebook in sorted((REPO_ROOT / "notebooks").glob("0[1-6]_*.ipynb")):
            papermill.execute_notebook(
                str(notebook),
                str(tmp_path / notebook.name),
                parameters={"profile": "smoke"},
                cwd=str(REPO_ROOT / "notebooks"),
                progress_bar=False,
                kernel_name="python3",
            )
        subprocess.run(
            [sys.executable, "-m", "gcdt", "report", "--profile", "smoke"],
            check=True,
            capture_output=True,
        )
        assert not artifacts.exists(), sorted(artifacts.rglob("*"))
        for name in (
            "fig2_architecture",
            "tqc_learning_curves",
            "training_loss",
            "fig3_dataset_size",
            "fig4_expert_ratio",
        ):
            assert (figures_dir("smoke", outputs) / f"{name}.png").stat().st_size > 0
        for name in ("table1.csv", "fig3_dataset_size.csv", "fig4_expert_ratio.csv"):
            assert (results_dir("smoke", outputs) / name).exists(), name
        papermill.execute_notebook(
            str(REPO_ROOT / "notebooks" / "07_explorer.ipynb"),
            str(tmp_path / "07.ipynb"),
            parameters={"profile": "smoke"},
            cwd=str(REPO_ROOT / "notebooks"),
            progress_bar=False,
            kernel_name="python3",
        )
        assert list((artifacts / "grid" / "checkpoints").glob("*/checkpoint.pt"))
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def test_notebooks_over_published_results_run_nothing_and_write_nothing_there(
    tmp_path, monkeypatch, capsys
):
    """JupyterLab over the published quick results: the sweep cell runs nothing, and a drawn
    figure goes to the artifacts, never into figures/quick/ (only make publish writes there)."""
    from gcdt import report

    monkeypatch.delenv(OUTPUTS_ENV, raising=False)
    monkeypatch.setenv(ARTIFACTS_ENV, str(tmp_path))
    sweeps = sys.modules["gcdt.experiments.sweep"]  # the module (the package exports a function)
    monkeypatch.setattr(sweeps, "sweep", lambda *a, **k: pytest.fail("a sweep ran"))
    quick = get_profile("quick")
    assert report.renders_published(quick) and not report.renders_published(get_profile("smoke"))
    report.run_grid(quick, "local")
    assert "rendering the published quick results" in capsys.readouterr().out
    fig, ax = plt.subplots()
    ax.plot([0, 1])
    report.show(fig, quick, "scratch_figure")
    assert (tmp_path / "notebooks" / "quick" / "scratch_figure.png").exists()
    assert not (figures_dir("quick", REPO_ROOT) / "scratch_figure.png").exists()
    report.show(None, quick, "fig9")
    assert "fig9: profile quick has no runs for this figure" in capsys.readouterr().out

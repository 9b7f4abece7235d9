"""A reproduction against the published results: the check, publishing, and a regression test
that renders every notebook and the report from results alone, with the artifacts deleted."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import pytest
from test_report import PROFILE, _write_runs

from gcdt.cli import main
from gcdt.errors import GcdtError
from gcdt.experiments import RunStore, build_grid, get_profile, sweep
from gcdt.paths import ARTIFACTS_ENV, OUTPUTS_ENV, REPO_ROOT, figures_dir, results_dir
from gcdt.report import figures, reproduction, tables


def _runs(root: Path):
    return tables.load_runs(PROFILE, results_dir(PROFILE.name, root) / "runs")


def _shift_one_run(root: Path, method: str, task: str, by: float) -> None:
    """Move one Table 1 run's success rate by `by` (its own seed 0 only)."""
    store = RunStore(results_dir(PROFILE.name, root) / "runs")
    for entry in build_grid(PROFILE, only="table1"):
        spec = entry.spec
        if (spec.method, spec.task, spec.reward, spec.seed) == (method, task, "sparse", 0):
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


def test_a_value_outside_the_published_interval_disagrees(published_and_ours):
    published, ours = published_and_ours
    _shift_one_run(ours, "bc", "push", by=0.45)
    check = reproduction.reproduction_check(_runs(published), _runs(ours)).set_index(
        ["item", "metric"]
    )
    row = check.loc[("Table 1: BC, Push sparse", "success")]
    assert row["difference"] == pytest.approx(15.0)  # mean of 3 seeds moved by 45 / 3 points
    assert row["published"] < row["high"] < row["ours"] and not row["agrees"]
    assert check.loc[("Table 1: GC-DT, Push sparse", "success"), "agrees"]
    assert int((~check["agrees"]).sum()) == 1
    line = reproduction.summary_line(check.reset_index())
    assert line.startswith(f"{len(check) - 1} of {len(check)} values agree")


def test_one_seed_cells_get_an_interval_from_their_episodes():
    low, high = tables.wilson_ci(0.9, 200)
    assert 0.84 < low < 0.9 < high < 0.94
    assert tables.wilson_ci(1.0, 100)[1] == pytest.approx(1.0)


def test_missing_runs_are_reported_and_never_agree(published_and_ours):
    published, ours = published_and_ours
    for path in (results_dir(PROFILE.name, ours) / "runs").glob("*.json"):
        if json.loads(path.read_text())["spec"]["method"] == "tqc":
            path.unlink()
    check = reproduction.reproduction_check(_runs(published), _runs(ours))
    missing = check[check["item"].str.contains("TQC")]
    assert len(missing) and missing["ours"].isna().all() and not missing["agrees"].any()
    assert f"missing: {len(missing)}" in reproduction.summary_line(check)


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
    _shift_one_run(ours, "gcdt", "reach", by=-0.1)
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

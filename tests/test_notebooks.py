"""The notebooks are committed clean and parameterised (nbval executes them: see pyproject)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parent.parent / "notebooks").glob("*.ipynb"))


def test_there_are_notebooks():
    assert len(NOTEBOOKS) >= 7


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_committed_without_outputs_and_with_parameters(path):
    cells = json.loads(path.read_text())["cells"]
    code = [c for c in cells if c["cell_type"] == "code"]
    dirty = [i for i, c in enumerate(code) if c["outputs"] or c["execution_count"] is not None]
    assert not dirty, f"{path.name}: code cells {dirty} hold outputs; clear them before committing"
    missing = [i for i, c in enumerate(cells) if not c.get("id")]
    assert not missing, f"{path.name}: cells {missing} have no id (nbformat 4.5 requires one)"
    params = [c for c in code if "parameters" in c.get("metadata", {}).get("tags", [])]
    assert len(params) == 1 and "profile = " in "".join(params[0]["source"])


def test_wrong_parameter_types_get_a_clear_message():
    from gcdt.errors import GcdtError
    from gcdt.report import check_parameters

    with pytest.raises(
        GcdtError, match="parameter profile must be one of smoke, quick, standard, large, paper"
    ):
        check_parameters(3, "local")
    with pytest.raises(GcdtError, match="parameter backend must be one of local, ray"):
        check_parameters("smoke", ["local"])
    assert check_parameters("smoke", "local").name == "smoke"


def test_the_gcdt_papermill_engine_runs_a_notebook_without_the_tcp_warning(tmp_path):
    """`make reproduce` executes notebooks with `papermill --engine gcdt`: the kernel's
    transport is encrypted, so ipykernel's plain-TCP warning no longer appears on each one."""
    import subprocess
    import sys

    import nbformat

    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("print(6 * 7)")])
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    nbformat.write(nb, tmp_path / "in.ipynb")
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "papermill",
            "--engine",
            "gcdt",
            "--no-progress-bar",
            str(tmp_path / "in.ipynb"),
            str(tmp_path / "out.ipynb"),
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "without encryption" not in done.stderr
    out = nbformat.read(tmp_path / "out.ipynb", as_version=4)
    assert out.cells[0].outputs[0]["text"] == "42\n"

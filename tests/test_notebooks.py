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
    params = [c for c in code if "parameters" in c.get("metadata", {}).get("tags", [])]
    assert len(params) == 1 and "profile = " in "".join(params[0]["source"])


def test_wrong_parameter_types_get_a_clear_message():
    from gcdt.errors import GcdtError
    from gcdt.report import check_parameters

    with pytest.raises(GcdtError, match="parameter profile must be one of smoke, quick, paper"):
        check_parameters(3, "local")
    with pytest.raises(GcdtError, match="parameter backend must be one of local, ray"):
        check_parameters("smoke", ["local"])
    assert check_parameters("smoke", "local").name == "smoke"

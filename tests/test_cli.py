"""The `gcdt` command: JSON output and one-line errors with exit status 2 for bad input."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from gcdt.cli import main

RANDOM_REACH = ["--policy", "random", "--task", "reach", "--reward", "sparse"]


def test_evaluate_json_last_line(capsys):
    code = main(
        [
            "evaluate",
            "--policy",
            "scripted",
            "--task",
            "reach",
            "--reward",
            "dense",
            "--episodes",
            "4",
            "--json",
            "--no-progress",
        ]
    )
    assert code == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    summary = json.loads(last)
    assert summary["episodes"] == 4
    assert summary["success_rate"] == 1.0
    assert -5.0 < summary["mean_return"] < 0.0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--policy", "random", "--task", "reech", "--reward", "sparse"],
            "argument --task: invalid choice: 'reech' "
            "(choose from 'reach', 'push', 'pick_and_place'",
        ),
        (
            ["--policy", "random", "--task", "reach", "--reward", "shaped"],
            "argument --reward: invalid choice: 'shaped'",
        ),
        (
            ["--policy", "expert", "--task", "reach", "--reward", "sparse"],
            "unknown policy 'expert': expected random, scripted or the path of an existing",
        ),
        (
            ["--policy", "scripted", "--task", "slide", "--reward", "sparse"],
            "no scripted expert for task 'slide': scripted experts cover reach, push, ",
        ),
        (
            [*RANDOM_REACH, "--episodes", "0"],
            "argument --episodes: expected a positive integer, got 0",
        ),
        (
            [*RANDOM_REACH, "--timesteps", "-5"],
            "argument --timesteps: expected a positive integer, got -5",
        ),
        (
            [*RANDOM_REACH, "--envs", "0"],
            "argument --envs: expected a positive integer, got 0",
        ),
        (
            [*RANDOM_REACH, "--episodes", "2", "--timesteps", "5"],
            "not allowed with argument",
        ),
        (
            ["--policy", "/no/such/model.pt", "--task", "reach", "--reward", "sparse"],
            "unknown policy '/no/such/model.pt': expected random, scripted or the path of an "
            "existing checkpoint file",
        ),
        (
            [*RANDOM_REACH, "--noise", "0.1"],
            "--noise applies only to --policy scripted",
        ),
    ],
)
def test_bad_input_one_line_exit_2(capsys, args, message):
    with pytest.raises(SystemExit) as exc:
        code = main(["evaluate", *args])
        raise SystemExit(code)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("gcdt: error: ")
    assert message in err[0]


def _run_module(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "gcdt", *args], capture_output=True, text=True, timeout=300
    )


def test_console_entry_point_no_traceback():
    """Through a real process (`python -m gcdt`): exit 2, one stderr line, no traceback."""
    proc = _run_module("evaluate", "--policy", "scripted", "--task", "stack", "--reward", "sparse")
    assert proc.returncode == 2
    assert proc.stderr.strip() == (
        "gcdt: error: no scripted expert for task 'stack': scripted experts cover reach, "
        "push, pick_and_place"
    )
    assert "Traceback" not in proc.stderr


def test_module_entry_point_with_parallel_envs():
    """`python -m gcdt` with spawned env workers runs once and prints one JSON last line."""
    proc = _run_module(
        "evaluate", "--policy", "random", "--task", "push", "--reward", "sparse",
        "--timesteps", "200", "--envs", "2", "--json",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    assert summary["timesteps"] == 200 and summary["n_envs"] == 2
    assert summary["episodes"] >= 4  # at least two 50-step episodes per env


def test_evaluate_out_writes_full_result(tmp_path, capsys):
    out = tmp_path / "runs" / "reach.json"
    argv = ["evaluate", *RANDOM_REACH, "--timesteps", "120", "--no-progress", "--out", str(out)]
    assert main(argv) == 0
    record = json.loads(out.read_text())
    assert record["command"] == "gcdt " + " ".join(argv)
    assert record["summary"]["timesteps"] == 120
    assert len(record["episodes"]) == record["summary"]["episodes"]
    assert sum(e["length"] for e in record["episodes"]) <= 120
    assert [p.name for p in out.parent.iterdir()] == ["reach.json"]  # no temp file left

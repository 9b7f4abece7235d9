"""The `gcdt` command: JSON output and one-line errors with exit status 2 for bad input."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys

import numpy as np
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
            "unknown policy 'expert': expected random, scripted, tqc:PATH of a TQC+HER zip",
        ),
        (
            ["--policy", "scripted", "--task", "slide", "--reward", "sparse"],
            "no scripted expert for task 'slide': scripted experts cover reach, push, ",
        ),
        (
            [*RANDOM_REACH, "--episodes", "0"],
            "episodes must be a positive integer, got 0",
        ),
        (
            [*RANDOM_REACH, "--timesteps", "-5"],
            "timesteps must be a positive integer, got -5",
        ),
        (
            [*RANDOM_REACH, "--envs", "0"],
            "n_envs must be a positive integer, got 0",
        ),
        (
            [*RANDOM_REACH, "--episodes", "2", "--timesteps", "5"],
            "give either timesteps or episodes, not both",
        ),
        (
            [*RANDOM_REACH, "--target-return", "-5"],
            "--target-return applies only to a DT checkpoint (gcdt train)",
        ),
        (
            ["--policy", "/no/such/model.pt", "--task", "reach", "--reward", "sparse"],
            "unknown policy '/no/such/model.pt': expected random, scripted, tqc:PATH of a "
            "TQC+HER zip, or the path of an existing checkpoint file",
        ),
        (
            [*RANDOM_REACH, "--noise", "0.1"],
            "--noise applies only to --policy scripted",
        ),
        (
            [*RANDOM_REACH, "--device", "cpu"],
            "--device applies only to a DT or BC checkpoint (gcdt train)",
        ),
    ],
)
def test_bad_input_one_line_exit_2(assert_usage_error, args, message):
    assert_usage_error(["evaluate", *args], message)


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
        "evaluate",
        "--policy",
        "random",
        "--task",
        "push",
        "--reward",
        "sparse",
        "--timesteps",
        "200",
        "--envs",
        "2",
        "--json",
    )
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


def test_train_options_are_trainconfig_fields():
    """`gcdt train` has an option per `TrainConfig` field, with the field's default."""
    from gcdt.cli import _build_parser
    from gcdt.training import TrainConfig

    args = _build_parser().parse_args(["train", "--dataset", "d.npz", "--out", "o"])
    fields = dataclasses.fields(TrainConfig)
    assert TrainConfig(**{f.name: getattr(args, f.name) for f in fields}) == TrainConfig()
    argv = ["train", "--dataset", "d.npz", "--out", "o", "--batch-size", "8", "--bf16"]
    args = _build_parser().parse_args([*argv, "--goal-conditioning", "none"])
    assert (args.batch_size, args.bf16, args.goal_conditioning) == (8, True, "none")


def test_evaluate_options_are_evaluationconfig_fields():
    """`gcdt evaluate` has an option per `EvaluationConfig` field, with the field's default."""
    from gcdt.cli import _build_parser
    from gcdt.evaluation import EvaluationConfig

    argv = ["evaluate", *RANDOM_REACH]
    args = _build_parser().parse_args(argv)
    fields = dataclasses.fields(EvaluationConfig)
    assert EvaluationConfig(**{f.name: getattr(args, f.name) for f in fields}) == (
        EvaluationConfig()
    )
    args = _build_parser().parse_args([*argv, "--envs", "3", "--episodes", "2", "--seed", "7"])
    assert (args.n_envs, args.episodes, args.timesteps, args.seed) == (3, 2, None, 7)


def test_tqc_train_options_are_tqcrunsettings_fields():
    """`gcdt tqc train` has an option per `TQCRunSettings` field, with the field's default."""
    from gcdt.baselines.tqc_her import TQCRunSettings
    from gcdt.cli import _build_parser

    argv = ["tqc", "train", "--task", "reach", "--reward", "sparse", "--out", "o"]
    args = _build_parser().parse_args(argv)
    fields = dataclasses.fields(TQCRunSettings)
    assert TQCRunSettings(**{f.name: getattr(args, f.name) for f in fields}) == TQCRunSettings()
    args = _build_parser().parse_args([*argv, "--stop-at", "0.5", "--eval-every", "7"])
    assert (args.stop_at, args.eval_every, args.eval_episodes) == (0.5, 7, 20)


def _imports_torch(code: str) -> tuple[bool, str]:
    """Whether running `code` in a fresh interpreter imports torch, and what it printed."""
    check = "\nimport sys; print('torch' in sys.modules, file=sys.stderr)"
    proc = subprocess.run(
        [sys.executable, "-c", code + check], capture_output=True, text=True, timeout=120
    )
    words = proc.stderr.split()  # the check's answer comes last, after any warning
    answer = words[-1] if words else ""
    assert proc.returncode == 0 and answer in ("True", "False"), proc.stderr
    return answer == "True", proc.stdout


def test_help_does_not_import_torch():
    help_ = "from gcdt.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass"
    imported, out = _imports_torch(help_)
    assert not imported
    assert "tqc" in out and "sweep" in out


def test_only_train_imports_torch():
    """The other commands, and `gcdt --help`, never wait for torch: `gcdt train` adds its
    options (from `TrainConfig`) when it parses."""
    imported, _ = _imports_torch(
        "from gcdt.cli import _build_parser\n"
        "_build_parser().parse_args(['dataset', 'info', 'x.npz'])"
    )
    assert not imported


# --- datasets -----------------------------------------------------------------------------


def test_dataset_commands_end_to_end(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    expert, rand = tmp_path / "expert.npz", tmp_path / "random.npz"
    common = ["--task", "reach", "--no-progress", "--seed", "1"]
    argv = ["collect", "--policy", "scripted", "--transitions", "60", "--out", str(expert)]
    assert main([*argv, *common]) == 0
    assert (
        main(
            [
                "collect",
                "--policy",
                "random",
                "--transitions",
                "200",
                "--out",
                str(rand),
                *common,
                "--json",
            ]
        )
        == 0
    )
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["transitions"] >= 200 and summary["policy"] == "random"

    assert main(["dataset", "info", str(expert), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["summary"]["success_rate"] == 1.0 and info["summary"]["transitions"] >= 60
    assert info["metadata"]["command"] == "gcdt " + " ".join([*argv, *common])

    mixed = tmp_path / "mix.npz"
    assert (
        main(
            [
                "dataset",
                "mix",
                "--expert",
                str(expert),
                "--random",
                str(rand),
                "--ratio",
                "0.25",
                "--size",
                "120",
                "--out",
                str(mixed),
            ]
        )
        == 0
    )
    assert (
        main(["dataset", "subset", str(rand), "--size", "100", "--out", str(tmp_path / "s.npz")])
        == 0
    )
    assert main(["dataset", "export-minari", str(expert), "--id", "tests/reach-expert-v0"]) == 0
    back = tmp_path / "back.npz"
    assert main(["dataset", "import-minari", "tests/reach-expert-v0", "--out", str(back)]) == 0
    out = capsys.readouterr().out
    assert "mix (mix)" in out and "subset (random)" in out and "tests/reach-expert-v0" in out

    from gcdt.data import load_dataset

    assert load_dataset(back).equal_data(load_dataset(expert))
    m = load_dataset(mixed)
    assert abs(m.metadata["expert_transitions"] - 30) <= 50 and abs(len(m) - 120) <= 50


@pytest.fixture
def data_files(tmp_path, make_dataset):
    """A push and a reach dataset on disk, plus a corrupt file and an authors' pickle."""
    import pickle

    push = make_dataset("push", lengths=(10, 10, 10))
    push.save(tmp_path / "push.npz")
    make_dataset("reach", lengths=(5, 5)).save(tmp_path / "reach.npz")
    (tmp_path / "corrupt.npz").write_bytes((tmp_path / "push.npz").read_bytes()[:500])
    (tmp_path / "data.pkl").write_bytes(pickle.dumps([]))
    return tmp_path


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            [
                "collect",
                "--policy",
                "random",
                "--task",
                "reach",
                "--transitions",
                "0",
                "--out",
                "{d}/new.npz",
            ],
            "transitions must be a positive integer, got 0",
        ),
        (
            [
                "collect",
                "--policy",
                "random",
                "--task",
                "reach",
                "--transitions",
                "5",
                "--out",
                "{d}/new.h5",
            ],
            "dataset paths end in .npz",
        ),
        (["dataset", "info", "{d}/absent.npz"], "does not exist"),
        (["dataset", "info", "{d}/corrupt.npz"], "truncated or corrupt"),
        (["dataset", "info", "{d}/data.pkl"], "truncated or corrupt"),
        (
            [
                "dataset",
                "mix",
                "--expert",
                "{d}/push.npz",
                "--random",
                "{d}/push.npz",
                "--ratio",
                "1.5",
                "--size",
                "10",
                "--out",
                "{d}/new.npz",
            ],
            "expert ratio must be within [0, 1], got 1.5",
        ),
        (
            [
                "dataset",
                "mix",
                "--expert",
                "{d}/push.npz",
                "--random",
                "{d}/reach.npz",
                "--ratio",
                "0.5",
                "--size",
                "10",
                "--out",
                "{d}/new.npz",
            ],
            "cannot mix datasets of tasks 'push' and 'reach'",
        ),
        (
            ["dataset", "subset", "{d}/push.npz", "--size", "31", "--out", "{d}/new.npz"],
            "the subset needs 31 transitions but the dataset has only 30",
        ),
        (
            ["dataset", "import-authors", "{d}/data.pkl", "--out", "{d}/new.npz"],
            "refusing to unpickle",
        ),
        (
            ["dataset", "import-authors", "{d}/data.pkl", "--out", "{d}/new.npz", "--trust-pickle"],
            "must hold a non-empty list of episode dicts",
        ),
        (
            ["dataset", "import-minari", "absent/x-v0", "--out", "{d}/new.npz"],
            "no local Minari dataset 'absent/x-v0'",
        ),
    ],
)
def test_bad_dataset_input_exit_2_nothing_written(
    assert_usage_error, data_files, monkeypatch, argv, message
):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(data_files / "minari"))
    before = sorted(p.name for p in data_files.iterdir())
    assert_usage_error([a.format(d=data_files) for a in argv], message)
    assert sorted(p.name for p in data_files.iterdir() if p.name != "minari") == before


# --- outputs that cannot be written, files that are not datasets ---------------------------

UNWRITABLE = [
    [
        "collect",
        "--policy",
        "scripted",
        "--task",
        "reach",
        "--transitions",
        "100000",
        "--out",
        "{out}.npz",
    ],
    [
        "dataset",
        "mix",
        "--expert",
        "{d}/x.npz",
        "--random",
        "{d}/x.npz",
        "--ratio",
        "0.5",
        "--size",
        "10",
        "--out",
        "{out}.npz",
    ],
    ["dataset", "subset", "{d}/x.npz", "--size", "10", "--out", "{out}.npz"],
    ["dataset", "import-minari", "tests/x-v0", "--out", "{out}.npz"],
    ["dataset", "import-authors", "{d}/x.pkl", "--out", "{out}.npz"],
    ["evaluate", *RANDOM_REACH, "--episodes", "1", "--out", "{out}.json"],
    ["train", "--dataset", "{d}/x.npz", "--out", "{out}"],
    ["tqc", "train", "--task", "reach", "--reward", "sparse", "--out", "{out}"],
]


@pytest.fixture
def no_work(monkeypatch):
    """Every command's work (policies, data, training) fails the test if it starts."""
    import gcdt.baselines.tqc_her as tqc
    import gcdt.data
    import gcdt.policies
    import gcdt.training

    def started(*args, **kwargs):
        pytest.fail("work started before the output location was checked")

    for module, names in [
        (gcdt.data, ["collect", "load_dataset", "import_minari", "import_authors"]),
        (gcdt.policies, ["make_policy"]),
        (gcdt.training, ["train"]),
        (tqc, ["load_tqc_config", "train_tqc"]),
    ]:
        for name in names:
            monkeypatch.setattr(module, name, started)


def _tree(root):
    return sorted((str(p.relative_to(root)), p.is_dir()) for p in root.rglob("*"))


@pytest.mark.parametrize(
    "argv", UNWRITABLE, ids=lambda a: "-".join(w for w in a[:2] if w[0] != "-")
)
def test_unwritable_out_fails_before_any_work(assert_usage_error, no_work, tmp_path, argv):
    """--out below a regular file (unwritable even for root): exit 2 before any work (the
    `no_work` fixture fails the test if a command's work starts), nothing made."""
    (tmp_path / "file.txt").write_text("x")
    before = _tree(tmp_path)
    out = tmp_path / "file.txt" / "deeper" / "out"
    assert_usage_error(
        [a.format(d=tmp_path, out=out) for a in argv],
        f"cannot write {out}",
    )
    assert _tree(tmp_path) == before


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (UNWRITABLE[0], "it is a folder, not a file; choose another --out"),
        (UNWRITABLE[6], "it is a file, not a folder; choose another --out"),
    ],
    ids=["collect-into-folder", "train-into-file"],
)
def test_out_of_the_wrong_kind_fails_before_any_work(
    assert_usage_error, no_work, tmp_path, argv, message
):
    (tmp_path / "taken.npz").mkdir()  # a folder where collect writes a file
    (tmp_path / "taken").write_text("x")  # a file where train writes a folder
    before = _tree(tmp_path)
    assert_usage_error([a.format(d=tmp_path, out=tmp_path / "taken") for a in argv], message)
    assert _tree(tmp_path) == before


@pytest.mark.skipif(
    hasattr(os, "geteuid") and os.geteuid() == 0, reason="root bypasses file permissions"
)
def test_collect_into_read_only_folder_fails_before_any_work(assert_usage_error, no_work, tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        assert_usage_error(
            [a.format(out=locked / "sub" / "out") for a in UNWRITABLE[0]],
            f"cannot write {locked}/sub/out.npz: {locked} is not writable (permission denied",
        )
        assert list(locked.iterdir()) == []
    finally:
        locked.chmod(0o755)


def _object_array_npz(path):
    np.savez(path, __metadata__=np.array([{"format": "gcdt.dataset"}], dtype=object))


@pytest.mark.parametrize(
    ("make", "reason"),
    [
        (lambda p: p.write_bytes(np.random.default_rng(0).bytes(4096)), "not a zip archive"),
        (lambda p: p.write_bytes(b""), "the file is empty"),
        (lambda p: p.write_bytes(p.with_name("good.npz").read_bytes()[:3000]), "truncated"),
        (
            lambda p: (
                np.save(p.with_suffix(".npy"), np.zeros(3)) or p.with_suffix(".npy").rename(p)
            ),
            "not a zip archive",
        ),
        (_object_array_npz, "an entry holds Python objects"),
    ],
    ids=["random-bytes", "empty", "truncated", "npy", "object-array"],
)
def test_dataset_info_on_a_non_dataset_never_suggests_unpickling(
    make_dataset, tmp_path, capsys, make, reason
):
    make_dataset("reach", lengths=(30, 30)).save(tmp_path / "good.npz")
    path = tmp_path / "bad.npz"
    make(path)
    capsys.readouterr()
    assert main(["dataset", "info", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    expected = f"gcdt: error: {path} is not a gcdt dataset (.npz archive written by gcdt collect): "
    assert err[0].startswith(expected), err[0]
    assert reason in err[0] and "pickle" not in err[0].lower(), err[0]


def test_sweep_checks_its_results_folder_before_any_run(assert_usage_error, tmp_path, monkeypatch):
    (tmp_path / "file.txt").write_text("x")
    monkeypatch.setenv("GCDT_OUTPUTS", str(tmp_path / "file.txt"))
    assert_usage_error(["sweep", "--profile", "smoke"], "choose another results folder")
    assert [p.name for p in tmp_path.iterdir()] == ["file.txt"]

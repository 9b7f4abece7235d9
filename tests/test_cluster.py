"""Past one machine: storage URIs, bad cluster inputs, and the launch recipes (the multi-node
sweep that loses a node is in tests/test_experiments.py, beside the local sweep it matches)."""

from __future__ import annotations

import copy
import os
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

from gcdt.experiments import artifacts, build_grid
from gcdt.experiments.profiles import PAPER
from gcdt.experiments.storage import STORAGE_ENV, ArtifactStorage
from gcdt.paths import REPO_ROOT
from tests.test_experiments import TINY


def test_artifacts_made_on_one_node_are_fetched_from_the_storage_uri(tmp_path, monkeypatch):
    storage = tmp_path / "storage"
    ArtifactStorage(storage.as_uri()).check_writable()  # makes the folder, leaves it empty
    assert storage.is_dir() and not list(storage.iterdir())
    monkeypatch.setenv(STORAGE_ENV, storage.as_uri())
    spec = next(e.spec for e in build_grid(TINY, only="table1") if e.spec.method == "gcdt")
    monkeypatch.setenv("GCDT_ARTIFACTS", str(tmp_path / "node0"))
    made = artifacts.checkpoint(spec)  # collects the data and trains, then uploads both
    uploaded = sorted(str(p.relative_to(storage)) for p in storage.rglob("*") if p.is_file())
    assert uploaded == [
        f"checkpoints/{spec.training_key()}/checkpoint.pt",
        f"datasets/{spec.data.key()}.npz",
    ]
    # A collection's chunks stay on its node, and only until its dataset is saved.
    assert not list((tmp_path / "node0").rglob("*.chunks"))
    # Another node, with its own empty folder, makes nothing: it downloads.
    monkeypatch.setenv("GCDT_ARTIFACTS", str(tmp_path / "node1"))
    monkeypatch.setattr(artifacts, "_collect", lambda *a: pytest.fail("collected again"))
    monkeypatch.setattr("gcdt.training.train", lambda *a, **k: pytest.fail("trained again"))
    fetched = artifacts.checkpoint(spec)
    assert fetched == tmp_path / "node1" / made.relative_to(tmp_path / "node0")
    assert fetched.read_bytes() == made.read_bytes()
    data = artifacts.dataset(spec.data)
    assert (
        data.summary()
        == artifacts.load_dataset(
            tmp_path / "node0" / "grid" / "datasets" / f"{spec.data.key()}.npz"
        ).summary()
    )
    assert not [p for p in (tmp_path / "node1").rglob("*.tmp")]


@pytest.fixture
def outputs(tmp_path, monkeypatch):
    """Where a sweep would write (results, artifacts): a bad input must leave both absent."""
    out, art = tmp_path / "outputs", tmp_path / "artifacts"
    monkeypatch.setenv("GCDT_OUTPUTS", str(out))
    monkeypatch.setenv("GCDT_ARTIFACTS", str(art))
    yield
    assert not out.exists() and not art.exists()


RAY_SMOKE = ["sweep", "--profile", "smoke", "--backend", "ray"]


def test_unreachable_cluster_is_refused(assert_usage_error, outputs):
    assert_usage_error(
        [*RAY_SMOKE, "--address", "127.0.0.1:9"], "cannot reach the Ray cluster at 127.0.0.1:9"
    )


@pytest.mark.parametrize(
    ("uri", "message"),
    [
        ("nope://bucket/gcdt", "cannot use storage URI 'nope://bucket/gcdt'"),
        ("file:///proc/gcdt", "cannot write storage URI 'file:///proc/gcdt'"),
    ],
)
def test_unwritable_storage_uri_is_refused(assert_usage_error, outputs, uri, message):
    assert_usage_error([*RAY_SMOKE, "--storage", uri], message)


def test_storage_uri_needs_the_ray_backend(assert_usage_error, outputs, tmp_path):
    assert_usage_error(
        ["sweep", "--profile", "smoke", "--storage", tmp_path.as_uri()],
        "--storage applies only to --backend ray",
    )


def test_cluster_without_room_for_one_run_is_refused(
    assert_usage_error, outputs, start_ray_cluster
):
    ray = pytest.importorskip("ray")

    cluster, _ = start_ray_cluster()  # a head of no CPUs, no worker node: a run asks for 1
    try:
        assert_usage_error(
            [*RAY_SMOKE, "--address", cluster.address],
            f"the Ray cluster at {cluster.address} has no node with the 1 CPU(s) one run of "
            "profile smoke asks for (cpus_per_run; its largest node has 0)",
        )
        assert not ray.is_initialized()  # the sweep disconnected
    finally:
        cluster.shutdown()


def test_ray_cluster_yaml_is_what_ray_up_accepts():
    from jsonschema import ValidationError
    from ray.autoscaler._private.util import prepare_config, validate_config

    config = yaml.safe_load((REPO_ROOT / "environment" / "ray-cluster.yaml").read_text())
    prepared = prepare_config(copy.deepcopy(config))  # what `ray up` does first
    validate_config(prepared)
    types = prepared["available_node_types"]
    assert types[prepared["head_node_type"]]["resources"]["CPU"] == 0  # the driver only
    worker = types["worker"]
    assert worker["min_workers"] >= 1 and worker["resources"]["CPU"] >= PAPER.cpus_per_run
    assert (REPO_ROOT / config["file_mounts"]["~/gcdt"]).resolve() == REPO_ROOT
    broken = copy.deepcopy(prepared)
    broken["available_node_types"]["worker"]["min_worker"] = 1  # a misspelt key
    with pytest.raises(ValidationError):
        validate_config(broken)


STUB = """\
#!{python}
# Stands for `gcdt`: it checks the cluster the script started, then fails with status 3.
import sys
import ray

args = sys.argv[1:]
ray.init(address=args[args.index("--address") + 1], logging_level="error")
print("cpus", ray.cluster_resources().get("CPU"), *args)
ray.shutdown()
sys.exit(3)
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_slurm_script_starts_ray_runs_the_sweep_and_stops_ray(tmp_path):
    stub = tmp_path / "gcdt"
    stub.write_text(textwrap.dedent(STUB.format(python=sys.executable)))
    stub.chmod(0o755)
    port = _free_port()
    env = {
        **os.environ,
        "GCDT_SLURM_LOCAL": "1",
        "SLURM_CPUS_PER_TASK": "1",
        "RAY_PORT": str(port),
        "GCDT": str(stub),
        "RAY": str(Path(sys.executable).with_name("ray")),
        "PROFILE": "smoke",
    }
    done = subprocess.run(
        ["bash", "environment/slurm-paper.sbatch", "--storage", "s3://b/gcdt"],
        cwd=REPO_ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 3, done.stderr  # the sweep's status is the job's
    lines = done.stdout.splitlines()
    head = lines[0].removeprefix("ray head up at ")
    assert head.endswith(f":{port}")
    assert lines[1:] == [
        f"cpus 1.0 sweep --profile smoke --backend ray --address {head} --no-progress "
        "--storage s3://b/gcdt",
        "ray stopped",
    ]
    with pytest.raises(OSError):  # nothing listens on the head's port any more
        socket.create_connection(head.rsplit(":", 1), timeout=2).close()

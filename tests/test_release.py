"""The datasets as a release: ids, Minari build, manifest, verify, card, the authors' format."""

from __future__ import annotations

import dataclasses
import json
import pickle

import pytest

from gcdt.cli import main
from gcdt.data import export_authors, import_authors
from gcdt.errors import GcdtError
from gcdt.experiments import profiles
from gcdt.experiments import release as rel
from gcdt.experiments.grid import data_spec
from gcdt.experiments.profiles import SMOKE, STANDARD, Scope


def test_ids_say_what_the_data_is():
    from minari.dataset.minari_dataset import parse_dataset_id

    push = data_spec(SMOKE, "push", SMOKE.dataset_size, 1.0)
    assert rel.dataset_id(push) == "gcdt/panda-push/expert-scripted-noise0p2-1k-v0"
    assert rel.dataset_id(push.base("random")) == "gcdt/panda-push/random-1k-v0"
    region = data_spec(SMOKE, "pick_and_place", 1000, 1.0, goal_region="x=-0.1:0.1,y=0:")
    assert rel.dataset_id(region) == (
        "gcdt/panda-pick-and-place/expert-scripted-noise0p2-goals-xfromm0p1to0p1_yfrom0-1k-v0"
    )
    clean = dataclasses.replace(push, expert_labels="clean", seed=3, collect_envs=4)
    assert rel.dataset_id(clean).endswith("noise0p2-cleanlabels-1k-seed3-envs4-v0")
    with pytest.raises(GcdtError, match="subsets and mixtures are recipes"):
        rel.dataset_id(data_spec(SMOKE, "push", 500, 1.0))

    smoke = rel.release(SMOKE)
    assert sorted(smoke.bases) == sorted(
        [
            *(
                f"gcdt/panda-{t}/{k}-1k-v0"
                for t in ("reach", "push", "pick-and-place")
                for k in ("expert-scripted-noise0p2", "random")
            ),
            "gcdt/panda-push/expert-scripted-noise0p2-goals-yto0-1k-v0",
        ]
    )
    assert {s.size for s in smoke.derived} == {500, 1000} and len(smoke.derived) == 9
    for ident in smoke.bases:
        parse_dataset_id(ident)  # a valid Minari id
    assert rel.dataset_id(data_spec(STANDARD, "push", 20_000, 1.0)).endswith("-20k-v0")
    rel.check_ids()  # no two different collections of any profile share an id


def test_two_collections_under_one_id_are_refused(monkeypatch):
    monkeypatch.setattr(rel, "dataset_id", lambda spec: f"gcdt/panda-{spec.task}/data-v0")
    with pytest.raises(GcdtError, match="two different collections would share the Minari id"):
        rel.release(SMOKE)


def test_data_that_waits_for_its_agent_is_not_built(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    monkeypatch.setenv("GCDT_ARTIFACTS", str(tmp_path / "artifacts"))
    agent = tmp_path / "experts" / "tqc_reach_sparse" / "model.zip"  # not published
    waiting = dataclasses.replace(_tiny(), expert_agents={"reach": str(agent)})
    with pytest.raises(GcdtError, match=f"waits for published agents \\({agent}\\): publish"):
        rel.build(waiting)
    assert not (tmp_path / "minari").exists() and not (tmp_path / "artifacts").exists()


def _tiny():
    """A smoke profile of one task and 100 transitions per collection, with one mixture."""
    return dataclasses.replace(
        SMOKE,
        dataset_size=100,
        eval_timesteps=60,
        table1=Scope(tasks=("reach",), rewards=("sparse",)),
        table1_tqc=Scope(tasks=()),
        rq4=Scope(tasks=()),
        rq5=Scope(tasks=("reach",), rewards=("sparse",)),
        rq5_ratios=(0.5,),
        ablation=Scope(tasks=()),
        targets=Scope(tasks=()),
        generalisation=Scope(tasks=()),
    )


@pytest.fixture
def tiny(tmp_path, monkeypatch):
    """The tiny profile as `smoke`, with artifacts, results and Minari folders in tmp_path."""
    monkeypatch.setitem(profiles.PROFILES, "smoke", _tiny())
    monkeypatch.setenv("GCDT_ARTIFACTS", str(tmp_path / "artifacts"))
    monkeypatch.setenv("GCDT_OUTPUTS", str(tmp_path / "out"))
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    return profiles.PROFILES["smoke"]


def _hashes(root):
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in root.rglob("*") if p.is_file()}


def test_build_verify_train_and_refusals(tiny, tmp_path, capsys, monkeypatch):
    import shutil

    import minari

    from gcdt.experiments.artifacts import dataset

    expert_id = "gcdt/panda-reach/expert-scripted-noise0p2-100-v0"
    random_id = "gcdt/panda-reach/random-100-v0"
    assert main(["dataset", "build", "--profile", "smoke"]) == 0
    assert f"MINARI_DATASETS_PATH={tmp_path / 'minari'}" in capsys.readouterr().out
    manifest = json.loads((tmp_path / "out/results/smoke/datasets.json").read_text())
    assert [e["id"] for e in manifest["datasets"]] == [expert_id, random_id]

    expert_spec = rel.release(tiny).bases[expert_id]
    grid_data = dataset(expert_spec)
    for entry in manifest["datasets"]:
        loaded = minari.load_dataset(entry["id"])  # plain Minari loads it
        meta = loaded.storage.metadata
        for field in ("algorithm_name", "author", "code_permalink", "description", "requirements"):
            assert meta[field], field
        assert meta["eval_env_spec"] and meta["ref_min_score"] < meta["ref_max_score"]
        assert (entry["ref_min_score"], entry["ref_max_score"]) == (
            meta["ref_min_score"],
            meta["ref_max_score"],
        )
        assert loaded.total_steps == entry["transitions"] >= 100
        assert set(entry["files"]) == {"data/main_data.hdf5", "data/metadata.json"}
        assert entry["collection"]["seed"] == 0 and entry["collection"]["command"]
    expert = manifest["datasets"][0]
    assert expert["success_rate"] == pytest.approx(grid_data.summary()["success_rate"])
    assert expert["mean_return_sparse"] == pytest.approx(grid_data.summary()["mean_return_sparse"])
    assert rel.load_source(expert_id).equal_data(grid_data)

    # A recipe draws the grid's own mixture from the released datasets.
    (recipe,) = manifest["derived"]
    import gcdt.data

    mixed = eval(recipe["recipe"], {"gcdt": gcdt})
    assert mixed.equal_data(dataset(rel.release(tiny).derived[0]))

    # Rebuilt from scratch at a later commit: the same bytes (the published commit is kept).
    first = _hashes(tmp_path / "minari")
    shutil.rmtree(tmp_path / "minari")
    shutil.rmtree(tmp_path / "artifacts")
    monkeypatch.setattr(rel, "git_commit", lambda: "f" * 40)
    assert main(["dataset", "build", "--profile", "smoke"]) == 0
    assert _hashes(tmp_path / "minari") == first
    assert main(["dataset", "verify", "smoke"]) == 0
    assert "verified 2 datasets" in capsys.readouterr().out
    assert main(["dataset", "build", "--profile", "smoke"]) == 0  # built ones are read
    assert _hashes(tmp_path / "minari") == first

    # gcdt train takes a Minari id; an unknown id is one line listing the known ones.
    out = tmp_path / "run"
    assert (
        main(["train", "--dataset", expert_id, "--out", str(out), "--steps", "2", "--no-progress"])
        == 0
    )
    assert (out / "checkpoint.pt").exists()
    capsys.readouterr()
    assert main(["train", "--dataset", "gcdt/panda-reach/nope-v0", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and f"known ids: {expert_id}, {random_id}" in err

    # An altered or a missing file: verify names it, exit 2.
    folder = tmp_path / "minari" / expert_id / "data"
    hdf5 = folder / "main_data.hdf5"
    hdf5.write_bytes(hdf5.read_bytes() + b"\0")
    assert main(["dataset", "verify", "smoke"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and f"{hdf5} differs from the manifest" in err
    hdf5.write_bytes(hdf5.read_bytes()[:-1])
    (folder / "metadata.json").rename(tmp_path / "moved.json")
    assert main(["dataset", "verify", "smoke"]) == 2
    assert f"{folder / 'metadata.json'} is missing" in capsys.readouterr().err
    (tmp_path / "moved.json").rename(folder / "metadata.json")
    assert main(["dataset", "verify", "smoke"]) == 0

    # A folder holding another dataset under one of the ids: refused, nothing overwritten.
    meta = json.loads((folder / "metadata.json").read_text())
    meta["gcdt"]["collection"]["data_key"] = "another"
    (folder / "metadata.json").write_text(json.dumps(meta))
    before = _hashes(tmp_path / "minari")
    assert main(["dataset", "build", "--profile", "smoke"]) == 2
    err = capsys.readouterr().err
    assert "holds another dataset under the id" in err and "nothing was overwritten" in err
    assert _hashes(tmp_path / "minari") == before


def test_authors_export_round_trip(make_dataset, tmp_path, capsys):
    ds = make_dataset("pick_and_place", lengths=(5, 2, 8))
    for reward in ("sparse", "dense"):
        path = export_authors(ds, tmp_path / f"{reward}.pkl", reward=reward)
        raw = pickle.loads(path.read_bytes())
        assert len(raw) == 3 and set(raw[0]["observations"]) == {
            "observation",
            "desired_goal",
            "achieved_goal",
        }
        back = import_authors(path, trust_pickle=True)
        assert back.equal_data(ds) and back.metadata["reward_in_file"] == reward
    npz = ds.save(tmp_path / "d.npz")
    assert main(["dataset", "export-authors", str(npz), "--out", str(tmp_path / "c.pkl")]) == 0
    assert import_authors(tmp_path / "c.pkl", trust_pickle=True).equal_data(ds)


def test_card_states_the_conventions(tiny, tmp_path):
    manifest = {
        "profile": "smoke",
        "command": "make datasets PROFILE=smoke",
        "datasets": [
            {
                "id": "gcdt/panda-reach/random-100-v0",
                "policy": "uniformly random actions",
                "episodes": 2,
                "transitions": 100,
                "success_rate": 0.0,
                "mean_return_sparse": -50.0,
                "mean_return_dense": -9.5,
                "ref_min_score": -50.0,
                "ref_max_score": -2.0,
                "collection": {"seed": 0, "collect_command": "gcdt collect ...", "command": "x"},
                "code_commit": "abc",
            }
        ],
        "derived": [],
    }
    path = tmp_path / "out/results/smoke/datasets.json"
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(manifest))
    text = rel.card_text(tmp_path / "out")
    for needle in (
        "`[observation, desired_goal, achieved_goal]`",
        "recomputed from the stored goals",
        'minari.load_dataset("gcdt/panda-reach/random-100-v0")',
        "gcdt train --dataset gcdt/panda-reach/random-100-v0",
        "import h5py",
        "| `gcdt/panda-reach/random-100-v0` | uniformly random actions | 2 | 100 | 0.0 % "
        "| -50.00 / -9.50 | -50.00 / -2.00 |",
    ):
        assert needle in text, needle
    assert "No profile has a manifest" in rel.card_text(tmp_path / "elsewhere")


def test_published_manifest_and_card_are_current():
    """The committed smoke manifest lists the datasets and recipes the code makes, and
    docs/datasets.md is what `gcdt dataset card` writes from the committed manifests."""
    manifest = rel.read_manifest(SMOKE, rel.REPO_ROOT)
    smoke = rel.release(SMOKE)
    assert [e["id"] for e in manifest["datasets"]] == list(smoke.bases)
    assert [e["collection"]["data_key"] for e in manifest["datasets"]] == [
        s.key() for s in smoke.bases.values()
    ]
    assert [d["data_key"] for d in manifest["derived"]] == [s.key() for s in smoke.derived]
    assert rel.CARD.read_text() == rel.card_text()

"""The datasets as a release: a profile's collections as Minari datasets, a manifest, a card.

`build(profile)` (`make datasets PROFILE=P`) makes every base dataset of the profile's grid,
expert and random data per task and any other collection the grid learns from (the
goal-generalisation study's expert data), as Minari datasets under `gcdt.paths.minari_dir()`.
The data is the grid's own (`gcdt.experiments.artifacts.dataset`: one collector, one cache).
Subsets and mixtures are derived data: the manifest records their recipe, not their bytes.

Ids are `gcdt/panda-<task>/<what>-v0`, where `<what>` names everything that tells two
collections apart (`dataset_id`): the policy, its action noise and labels, a goal region, the
size, and the seed and env count where they are not 0 and 1. `check_ids` refuses two different
collections of any profiles under one id, and a build refuses a folder that holds another
dataset under one of its ids.

The manifest, `results/<profile>/datasets.json`, holds each dataset's statistics, collection
and the SHA-256 of every file; `verify(profile)` checks the built datasets against it.

Bytes: the HDF5 file depends on the data alone. metadata.json holds the data's gcdt metadata
without its creation time and timings (`VOLATILE_METADATA`), and `code_permalink`, the commit
that built these bytes: a rebuild whose HDF5 file matches the manifest's keeps the manifest's
commit, so a user who regenerates gets the same bytes at a later commit.

Reference scores (`ref_min_score`, `ref_max_score`): the mean sparse return of the random policy
and of the dataset's expert, measured by the evaluator with the profile's evaluation budget
(`eval_timesteps` env steps, evaluation seed `REFERENCE_SEED`), in the dataset's goal region.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path
from typing import Any

from gcdt.data.dataset import Dataset
from gcdt.envs import env_id
from gcdt.errors import GcdtError
from gcdt.experiments.grid import DataSpec, build_grid, data_spec
from gcdt.experiments.profiles import PAPER_TASKS, PROFILES, Profile
from gcdt.paths import (
    REPO_ROOT,
    artifacts_dir,
    minari_dir,
    results_dir,
    write_if_changed,
    write_json_atomic,
)
from gcdt.provenance import git_commit, numpy_kernels, package_versions

MANIFEST_NAME = "datasets.json"
NAMESPACE = "gcdt"
#: The reward a released Minari dataset stores; the other one follows from the goals.
RELEASE_REWARD = "sparse"
#: Evaluation seed of the reference scores (the grid's run seeds are evaluated from 0 too).
REFERENCE_SEED = 0
#: Metadata of a collection that differs between two identical collections: its time, its
#: timings, how many chunks a resumed collection loaded, and the versions of every tracked
#: package (torch's differs between CPU and CUDA builds); the versions that decide the bytes
#: are the card's `requirements`.
VOLATILE_METADATA = ("created", "seconds", "stepping_seconds", "chunks_resumed", "versions")
#: The packages whose versions decide the data and load its env (Minari's `requirements`).
REQUIREMENTS = ("panda-gym", "gymnasium", "pybullet", "numpy")
HDF5_FILE = "data/main_data.hdf5"
CARD = REPO_ROOT / "docs" / "datasets.md"


# --- ids -------------------------------------------------------------------------------------


def _number(x: float) -> str:
    """A number as Minari ids allow it (letters, digits, - and _): 0.2 -> 0p2, -0.1 -> m0p1."""
    return f"{x:g}".replace("-", "m").replace(".", "p")


def _size(n: int) -> str:
    for unit, scale in (("m", 1_000_000), ("k", 1_000)):
        if n % scale == 0:
            return f"{n // scale}{unit}"
    return str(n)


def _region(text: str) -> str:
    """`y=:0` -> `yto0`, `x=-0.1:0.1` -> `xfromm0p1to0p1`."""
    parts = []
    for clause in filter(None, text.split(",")):
        axis, _, bounds = clause.partition("=")
        low, _, high = bounds.partition(":")
        parts.append(
            axis
            + (f"from{_number(float(low))}" if low else "")
            + (f"to{_number(float(high))}" if high else "")
        )
    return "_".join(parts)


def _expert(spec: DataSpec) -> str:
    if spec.expert == "tqc":  # a grid-trained agent: its config is part of the name unless paper's
        tqc = spec.expert_tqc
        paper = (tqc.config, tqc.steps, tqc.budget) == ("paper", None, ())
        return "tqc" if paper else f"tqc-{tqc.key()[:8]}"
    if spec.expert.startswith("tqc:"):  # a published agent, named by its content
        return f"tqc-{spec.expert_digest[:8]}"
    return spec.expert


def dataset_id(spec: DataSpec) -> str:
    """The Minari id of collection `spec`, e.g. `gcdt/panda-push/expert-scripted-noise0p2-1k-v0`."""
    if not spec.is_base:
        raise GcdtError("only collections have a Minari id: subsets and mixtures are recipes")
    parts = ["random"] if spec.expert == "random" else ["expert", _expert(spec)]
    if spec.expert_noise:
        parts.append(f"noise{_number(spec.expert_noise)}")
    if spec.expert_labels != "executed":
        parts.append(f"{spec.expert_labels}labels")
    if spec.goal_region is not None:
        parts.append(f"goals-{_region(spec.goal_region)}")
    parts.append(_size(spec.base_size))
    if spec.seed:
        parts.append(f"seed{spec.seed}")
    if spec.collect_envs != 1:
        parts.append(f"envs{spec.collect_envs}")
    return f"{NAMESPACE}/panda-{spec.task.replace('_', '-')}/{'-'.join(parts)}-v0"


@dataclasses.dataclass(frozen=True)
class Release:
    """A profile's datasets: the collections by id, and the derived data (recipes)."""

    profile: Profile
    bases: dict[str, DataSpec]
    derived: tuple[DataSpec, ...]


def release(profile: Profile) -> Release:
    """Every collection `profile`'s grid learns from, expert and random per task, by id."""
    bases: dict[str, DataSpec] = {}
    derived: dict[str, DataSpec] = {}

    def add(spec: DataSpec) -> None:
        ident = dataset_id(spec)
        other = bases.setdefault(ident, spec)
        if other.key() != spec.key():
            raise GcdtError(
                f"two different collections would share the Minari id {ident!r} "
                f"(data keys {other.key()} and {spec.key()}): make dataset_id tell them apart"
            )

    for entry in build_grid(profile):
        data = entry.spec.data
        if data is None:
            continue
        if not data.is_base:
            derived.setdefault(data.key(), data)
            add(data.base("expert"))
        elif data.expert != "random":
            add(data)
        add(data.base("random"))  # random data for every task, used or not
    order = sorted(bases, key=lambda i: (bases[i].task, bases[i].expert == "random", i))
    # Recipes in an order of their own, whatever order the sweep runs them in: subsets, then
    # mixtures, each by task, size and expert share.
    tasks = {task: i for i, task in enumerate(PAPER_TASKS)}
    recipes = sorted(
        derived.values(),
        key=lambda d: (d.expert_ratio != 1.0, tasks[d.task], d.size, d.expert_ratio),
    )
    return Release(profile, {i: bases[i] for i in order}, tuple(recipes))


def check_ids(profiles: dict[str, Profile] = PROFILES) -> None:
    """Refuse two different collections under one id, within or across `profiles`."""
    seen: dict[str, tuple[str, str]] = {}
    for profile in profiles.values():
        for ident, spec in release(profile).bases.items():
            name, key = seen.setdefault(ident, (profile.name, spec.key()))
            if key != spec.key():
                raise GcdtError(
                    f"profiles {name} and {profile.name} hold different collections under the "
                    f"Minari id {ident!r}: make dataset_id tell them apart"
                )


# --- files and the manifest ------------------------------------------------------------------


def manifest_path(profile: Profile) -> Path:
    return results_dir(profile.name) / MANIFEST_NAME


def read_manifest(profile: Profile, root: Path | None = None) -> dict[str, Any] | None:
    """The profile's manifest (under `root`, default `outputs_root()`), or None where it has
    none."""
    path = results_dir(profile.name, root) / MANIFEST_NAME
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise GcdtError(f"{path} is not a readable manifest ({err}): restore it with git") from None


def file_hashes(folder: Path) -> dict[str, str]:
    """SHA-256 of every file under `folder`, by path relative to it."""
    return {
        p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def _built_key(ident: str) -> str | None:
    """The data key of the dataset built under `ident`, None where none is; refuses a folder
    that holds something else."""
    folder = minari_dir() / ident
    if not folder.exists():
        return None
    try:
        meta = json.loads((folder / "data" / "metadata.json").read_text())
        return meta["gcdt"]["collection"]["data_key"]
    except (OSError, ValueError, KeyError, TypeError):
        raise GcdtError(
            f"{folder} holds a dataset that gcdt's release did not build under the id {ident!r}: "
            f"delete it (minari delete {ident}) or choose another MINARI_DATASETS_PATH"
        ) from None


def _stable(metadata: dict[str, Any]) -> dict[str, Any]:
    """A collection's metadata without what differs between two identical collections (its
    time and timings; a grid agent's path inside this machine's artifacts folder)."""
    out = {k: v for k, v in metadata.items() if k not in VOLATILE_METADATA}
    policy = dict(out.get("policy") or {})
    path = policy.get("path")
    if isinstance(path, str) and Path(path).is_relative_to(artifacts_dir()):
        policy["path"] = "<artifacts>/" + Path(path).relative_to(artifacts_dir()).as_posix()
        out["policy"] = policy
    return out


# --- building --------------------------------------------------------------------------------


def _describe(spec: DataSpec) -> str:
    """What collected `spec`, in words."""
    if spec.expert == "random":
        return "uniformly random actions"
    who = {"scripted": "the scripted expert (gcdt.policies.scripted)"}.get(
        spec.expert, "a TQC+HER agent"
    )
    if spec.expert_noise:
        who += f" with Gaussian action noise of std {spec.expert_noise:g}"
        if spec.expert_labels == "clean":
            who += ", recorded with the clean action as label"
    if spec.goal_region is not None:
        who += f", desired goals drawn from {spec.goal_region}"
    return who


def _collect_command(spec: DataSpec) -> str | None:
    """The `gcdt collect` line that makes the same arrays, where one exists (not for a TQC+HER
    agent the grid trains: `gcdt dataset build` trains it first)."""
    if spec.expert == "tqc":
        return None
    line = (
        f"gcdt collect --policy {spec.expert} --task {spec.task} --transitions {spec.base_size} "
        f"--seed {spec.seed} --envs {spec.collect_envs}"
    )
    if spec.expert_noise:
        line += f" --noise {spec.expert_noise:g} --labels {spec.expert_labels}"
    if spec.goal_region is not None:
        line += f" --goal-region {spec.goal_region}"
    return line + " --out DATA.npz"


def _reference(profile: Profile, spec: DataSpec, cache: dict) -> dict[str, Any]:
    """The mean sparse return of the policy that collects `spec`, by the evaluator."""
    from gcdt.evaluation import evaluate
    from gcdt.experiments.artifacts import collecting_policy
    from gcdt.regions import GoalRegion

    region = spec.goal_region
    key = (spec.key(), region)
    if key not in cache:
        policy, _ = collecting_policy(spec)
        result = evaluate(
            policy,
            spec.task,
            RELEASE_REWARD,
            timesteps=profile.eval_timesteps,
            n_envs=profile.eval_envs,
            seed=REFERENCE_SEED,
            goal_region=None if region is None else GoalRegion.parse(region),
            progress=False,
        ).summary
        if not result["episodes"]:
            raise GcdtError(
                f"no {spec.task} episode of {policy.name} ended within {profile.eval_timesteps} "
                f"env steps: profile {profile.name}'s eval_timesteps is too small for a score"
            )
        cache[key] = {
            "policy": "random" if spec.expert == "random" else f"expert: {_describe(spec)}",
            "mean_return": result["mean_return"],
            "success_rate": result["success_rate"],
            "episodes": result["episodes"],
            "timesteps": result["timesteps"],
        }
    return cache[key]


def _card(profile: Profile, spec: DataSpec, data: Dataset, refs: dict) -> Any:
    from gcdt.data.minari_io import MinariCard

    versions = package_versions(REQUIREMENTS)
    kind = "random" if spec.expert == "random" else "expert"
    description = (
        f"{kind.capitalize()} data of panda-gym's {env_id(spec.task, RELEASE_REWARD)}: "
        f"{len(data):,} transitions in {data.n_episodes:,} whole episodes of {_describe(spec)}, "
        f"made by gcdt (profile {profile.name}). Rewards are the sparse reward; the dense one "
        "is minus the distance from achieved_goal to desired_goal of the next observation. "
        "ref_min_score and ref_max_score: mean sparse returns of the random policy and the "
        f"expert, each over {profile.eval_timesteps:,} evaluation env steps."
    )
    return MinariCard(
        algorithm_name="random" if kind == "random" else _describe(spec),
        description=description,
        code_permalink=None,  # set by `_build_one` once the bytes are known
        requirements=tuple(f"{name}=={v}" for name, v in versions.items() if v),
        ref_min_score=refs["min"]["mean_return"],
        ref_max_score=refs["max"]["mean_return"],
        num_episodes_average_score=None,  # two evaluations of different episode counts
        gcdt={
            "collection": {
                "profile": profile.name,
                "data_key": spec.key(),
                "spec": spec.resolved(),
                "seed": spec.seed,
                "command": f"gcdt dataset build --profile {profile.name}",
                "collect_command": _collect_command(spec),
            },
            "reference_scores": {
                "reward": RELEASE_REWARD,
                "seed": REFERENCE_SEED,
                "eval_timesteps": profile.eval_timesteps,
                "eval_envs": profile.eval_envs,
                "goal_region": spec.goal_region,
                "min": refs["min"],
                "max": refs["max"],
            },
        },
    )


def _permalink(commit: str) -> str:
    return f"gcdt git commit {commit}"


def _build_one(
    rel: Release, ident: str, published: dict[str, Any] | None, cache: dict
) -> dict[str, Any]:
    """Build dataset `ident` (unless built) and return its manifest entry."""
    import shutil

    import minari

    from gcdt.data.minari_io import export_minari, import_minari
    from gcdt.experiments.artifacts import dataset

    spec, profile = rel.bases[ident], rel.profile
    folder = minari_dir() / ident
    if _built_key(ident) is not None:
        data = import_minari(ident)  # built already: read, not collected or evaluated again
    else:
        data = dataset(spec)
        data = dataclasses.replace(data, metadata=_stable(data.metadata))
        expert = (
            spec if spec.expert != "random" else data_spec(profile, spec.task, spec.base_size, 1.0)
        )
        random = dataclasses.replace(expert.base("random"), goal_region=spec.goal_region)
        refs = {
            "min": _reference(profile, random, cache),
            "max": _reference(profile, expert, cache),
        }
        card = _card(profile, spec, data, refs)
        export_minari(data, ident, reward=RELEASE_REWARD, card=card)
        try:
            hdf5 = file_hashes(folder)[HDF5_FILE]
            # The commit that built these bytes: the published one when they are the same.
            same = published is not None and published["files"].get(HDF5_FILE) == hdf5
            commit = published["code_commit"] if same else (git_commit() or "unknown")
            minari.load_dataset(ident).storage.update_metadata(
                {"code_permalink": _permalink(commit)}
            )
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)  # nothing half-written
            raise
    meta = json.loads((folder / "data" / "metadata.json").read_text())
    summary = data.summary()
    return {
        "id": ident,
        "task": spec.task,
        "kind": "random" if spec.expert == "random" else "expert",
        "policy": _describe(spec),
        "reward": RELEASE_REWARD,
        "episodes": summary["episodes"],
        "transitions": summary["transitions"],
        "mean_length": summary["mean_length"],
        "success_rate": summary["success_rate"],
        "mean_return_sparse": summary["mean_return_sparse"],
        "mean_return_dense": summary["mean_return_dense"],
        "ref_min_score": meta["ref_min_score"],
        "ref_max_score": meta["ref_max_score"],
        "collection": meta["gcdt"]["collection"],
        "code_commit": meta["code_permalink"].removeprefix(_permalink("")),
        "files": file_hashes(folder),
    }


def _recipe(rel: Release, spec: DataSpec) -> dict[str, Any]:
    """How derived data `spec` is drawn from the released collections."""
    expert = dataset_id(spec.base("expert"))
    load = "gcdt.experiments.release.load_source"
    if spec.expert_ratio == 1.0:
        kind, random = "subset", None
        code = f"gcdt.data.subset({load}({expert!r}), {spec.size}, seed={spec.seed})"
    else:
        kind, random = "mixture", dataset_id(spec.base("random"))
        code = (
            f"gcdt.data.mix({load}({expert!r}), {load}({random!r}), {spec.expert_ratio!r}, "
            f"{spec.size}, seed={spec.seed})"
        )
    return {
        "task": spec.task,
        "kind": kind,
        "size": spec.size,
        "expert_ratio": spec.expert_ratio,
        "seed": spec.seed,
        "expert": expert,
        "random": random,
        "data_key": spec.key(),
        "recipe": code,
    }


def _manifest(rel: Release, entries: list[dict[str, Any]]) -> dict[str, Any]:
    return {
        "profile": rel.profile.name,
        "command": f"make datasets PROFILE={rel.profile.name}",
        "minari_datasets_path": "artifacts/minari (or $MINARI_DATASETS_PATH)",
        "reward": RELEASE_REWARD,
        "datasets": entries,
        "derived": [_recipe(rel, spec) for spec in rel.derived],
    }


def build(profile: Profile, *, write_manifest: bool = False) -> list[dict[str, Any]]:
    """Build `profile`'s datasets (those built already are kept) and return their manifest
    entries. The manifest is written where there is none or with `write_manifest`; else the
    built datasets must match it (`verify`)."""
    check_ids()
    rel = release(profile)
    if waiting := sorted({s.waits_for for s in rel.bases.values() if s.waits_for}):
        raise GcdtError(
            f"profile {profile.name}'s expert data waits for published agents "
            f"({', '.join(waiting)}): publish them with `gcdt tqc publish RUN_DIR` first; "
            "nothing was built"
        )
    for ident, spec in rel.bases.items():  # refuse before building anything
        built = _built_key(ident)
        if built not in (None, spec.key()):
            raise GcdtError(
                f"{minari_dir() / ident} holds another dataset under the id {ident!r} (data key "
                f"{built}, this build's {spec.key()}): delete it (minari delete {ident}) or "
                "choose another MINARI_DATASETS_PATH; nothing was overwritten"
            )
    published = read_manifest(profile)
    by_id = {e["id"]: e for e in (published or {}).get("datasets", [])}
    cache: dict = {}
    entries = [_build_one(rel, ident, by_id.get(ident), cache) for ident in rel.bases]
    if published is None or write_manifest:
        write_json_atomic(manifest_path(profile), _manifest(rel, entries))
    else:
        verify(profile)
    return entries


def verify(profile: Profile) -> list[str]:
    """Check the profile's built datasets against its manifest (building those not built yet);
    the lines of what was checked. Any missing, altered or extra file is a `GcdtError` that
    names it."""
    path = manifest_path(profile)
    manifest = read_manifest(profile)
    if manifest is None:
        raise GcdtError(
            f"profile {profile.name} has no manifest {path}: build it with "
            f"`make datasets PROFILE={profile.name}`"
        )
    expected = {e["id"]: e for e in manifest["datasets"]}
    rel = release(profile)
    if sorted(expected) != sorted(rel.bases):
        raise GcdtError(
            f"{path} lists other datasets than profile {profile.name} makes: rebuild it with "
            f"`gcdt dataset build --profile {profile.name} --write-manifest`"
        )
    cache: dict = {}
    for ident in rel.bases:  # "rebuilds the datasets, or reads the built ones"
        if not (minari_dir() / ident).exists():
            _build_one(rel, ident, expected[ident], cache)
    problems, lines = [], []
    for ident, entry in expected.items():
        folder = minari_dir() / ident
        actual = file_hashes(folder)
        for name, sha in entry["files"].items():
            if name not in actual:
                problems.append(f"{folder / name} is missing")
            elif actual[name] != sha:
                problems.append(f"{folder / name} differs from the manifest's sha256")
        problems += [
            f"{folder / n} is not in the manifest"
            for n in sorted(set(actual) - set(entry["files"]))
        ]
        lines.append(f"{ident}: {len(entry['files'])} files")
    if problems:
        raise GcdtError(
            f"{len(problems)} file(s) disagree with {path}: {'; '.join(problems)} (rebuild: "
            f"delete the dataset and run `make datasets PROFILE={profile.name}`; data rebuilt "
            "on a CPU whose numpy kernels differ from the manifest's machine differs in the "
            f"last bits, see docs/datasets.md: here {' '.join(numpy_kernels()) or 'baseline'})"
        )
    return lines


# --- loading ---------------------------------------------------------------------------------


def manifest_ids() -> dict[str, str]:
    """Every id of a committed manifest -> its profile."""
    out: dict[str, str] = {}
    for profile in PROFILES.values():
        for entry in (read_manifest(profile) or {}).get("datasets", []):
            out.setdefault(entry["id"], profile.name)
    return out


def load_source(source: str | Path) -> Dataset:
    """A dataset given as a `.npz` path or as the id of a Minari dataset in `minari_dir()`."""
    from gcdt.data import import_minari, load_dataset
    from gcdt.data.minari_io import local_ids

    text = str(source)
    if text.endswith(".npz") or Path(text).exists():
        return load_dataset(text)
    local = local_ids()
    if text in local:
        return import_minari(text)
    published = manifest_ids()
    if text in published:
        raise GcdtError(
            f"Minari dataset {text!r} is not built in {minari_dir()}: "
            f"make datasets PROFILE={published[text]}"
        )
    known = ", ".join(sorted(set(local) | set(published))) or "none"
    raise GcdtError(
        f"no dataset {text!r} (neither a .npz file nor a known Minari id); known ids: {known}"
    )


# --- the card --------------------------------------------------------------------------------


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def _profile_section(manifest: dict[str, Any]) -> list[str]:
    name = manifest["profile"]
    out = [
        f"## Profile `{name}`",
        "",
        f"Built by `{manifest['command']}`; manifest: `results/{name}/{MANIFEST_NAME}` "
        f"(check: `gcdt dataset verify {name}`). {PROFILES[name].description[0].upper()}"
        f"{PROFILES[name].description[1:]}.",
        "",
        "| Minari id | data | episodes | transitions | success | return sparse / dense "
        "| ref_min_score / ref_max_score |",
        "|---|---|--:|--:|--:|--:|--:|",
    ]
    for e in manifest["datasets"]:
        out.append(
            f"| `{e['id']}` | {e['policy']} | {e['episodes']:,} | {e['transitions']:,} "
            f"| {_pct(e['success_rate'])} | {e['mean_return_sparse']:.2f} / "
            f"{e['mean_return_dense']:.2f} | {e['ref_min_score']:.2f} / {e['ref_max_score']:.2f} |"
        )
    out += [
        "",
        "How each was made (collection seed, and the command that makes the same arrays):",
        "",
    ]
    for e in manifest["datasets"]:
        c = e["collection"]
        how = f"`{c['collect_command']}`" if c["collect_command"] else c["command"]
        out.append(f"- `{e['id']}`: seed {c['seed']}, {how}; commit `{e['code_commit']}`")
    if manifest["derived"]:
        out += [
            "",
            "Derived data (subsets for RQ4, mixtures for RQ5): recipes, not files.",
            "",
            "| task | kind | transitions | expert share | drawn from | recipe |",
            "|---|---|--:|--:|---|---|",
        ]
        for d in manifest["derived"]:
            sources = ", ".join(f"`{i}`" for i in (d["expert"], d["random"]) if i)
            out.append(
                f"| {d['task']} | {d['kind']} | {d['size']:,} | {d['expert_ratio']:.0%} "
                f"| {sources} | `{d['recipe']}` |"
            )
    return [*out, ""]


def card_text(root: Path = REPO_ROOT) -> str:
    """docs/datasets.md, from the manifests under `root` (results/<profile>/datasets.json;
    default the published ones)."""
    manifests = [m for p in PROFILES.values() if (m := read_manifest(p, root))]
    example = manifests[0]["datasets"][0]["id"] if manifests else "gcdt/panda-push/random-1k-v0"
    head = f"""# Datasets

<!-- Generated by `gcdt dataset card` from results/*/{MANIFEST_NAME}: do not edit. -->

gcdt publishes its offline data as [Minari](https://minari.farama.org) datasets: for each
profile, the expert and the random data of every task (and any other collection its grid
learns from), built by `make datasets PROFILE=P` into `artifacts/minari/` (the
`MINARI_DATASETS_PATH` it prints; a `MINARI_DATASETS_PATH` you set wins). The data is the
grid's own: the same collector, seeds and cache as `make reproduce`.

Ids read `gcdt/panda-<task>/<what>-v0`, `<what>` naming all that tells two collections apart:
`random` or `expert-<policy>`, the expert's action noise (`noise0p2`: std 0.2; Minari ids
allow no dot), `cleanlabels` for DART labels, `goals-<region>` for goals drawn from a region
(`yto0`: y below 0), the size (`1k` transitions), and `seedN` / `envsN` where they are not 0
and 1. No two different collections share an id: gcdt refuses to build one, and refuses to
build into a folder that holds another dataset under the same id.

## What every dataset holds

- **Episodes, whole.** Each Minari episode is one panda-gym episode: observations (one more
  than actions), actions, rewards, terminations, truncations and `infos/is_success`.
  panda-gym v3 terminates an episode on success only and truncates it after 50 steps.
- **State order.** gcdt's models read the state `[observation, desired_goal, achieved_goal]`
  (concatenated in that order), the paper's.
- **Rewards.** The stored reward is the {RELEASE_REWARD} one: `-1` while the achieved goal is
  farther than the task's distance threshold from the desired goal, `0` within it. Sparse and dense
  rewards are both recomputed from the stored goals: with `d` the distance from
  `achieved_goal` to `desired_goal` of the next observation, sparse is `-(d > threshold)` and
  dense is `-d`. Loading through gcdt checks the stored rewards against that computation and
  refuses data that does not follow it.
- **Metadata.** `algorithm_name`, `author`, `code_permalink` (the gcdt commit that built these
  bytes), `description`, `requirements` (the package versions that decide the data),
  `env_spec` and `eval_env_spec` (the task's panda-gym env), and `ref_min_score` /
  `ref_max_score`: the mean sparse return of the random policy and of the dataset's expert,
  measured by gcdt's evaluator with the profile's evaluation budget (its `eval_timesteps` env
  steps, evaluation seed {REFERENCE_SEED}, in the dataset's goal region). The `gcdt` entry
  holds the collection (its data spec, seed, `gcdt collect` command), the reference
  evaluations' details, the episode seeds and gcdt's own metadata.
- **Bytes.** Building twice gives the same bytes: the manifest holds the SHA-256 of every file
  and `gcdt dataset verify P` checks them (building what is not built yet). Creation times,
  timings and machine-dependent package versions are left out of the metadata for this.
  The bytes hold on CPUs where numpy dispatches to the same vector kernels: the published
  manifests were built where the best were AVX2's (`X86_V3`). With AVX-512 kernels
  `np.arctan2` in the Push expert differs in the last bit, its actions and so its episodes
  drift apart, and `verify` reports the files as different (it names this CPU's
  kernels, `gcdt.provenance.numpy_kernels()`). `NPY_DISABLE_CPU_FEATURES="X86_V4
  AVX512_ICL"` (the levels above `X86_V3` on your CPU) makes the same bytes again; a test
  (`tests/test_collect.py`) checks that. Whether data collected by a TQC agent (JAX) keeps
  its bytes across CPUs is not checked.

## Loading

With Minari (point it at the folder first):

```python
import os
os.environ["MINARI_DATASETS_PATH"] = "artifacts/minari"
import minari

data = minari.load_dataset("{example}")
for episode in data.iterate_episodes():
    obs = episode.observations  # dict: observation, desired_goal, achieved_goal, [T + 1, dim]
    actions, rewards = episode.actions, episode.rewards  # [T, dim], [T]
env = data.recover_environment()  # the panda-gym env (needs panda-gym installed)
```

With gcdt: train on a dataset by its id, or load it as a `gcdt.data.Dataset` (both rewards,
goal-conditioned states, episode boundaries):

```bash
gcdt train --dataset {example} --out runs/gcdt --steps 1000
```

```python
from gcdt.experiments.release import load_source

dataset = load_source("{example}")
states, actions = dataset.states, dataset.actions  # [N, obs + 2 goal dims], [N, action dim]
```

Without gcdt or Minari, with h5py alone:

```python
import h5py

with h5py.File("artifacts/minari/{example}/data/main_data.hdf5") as f:
    episode = f["episode_0"]
    observation = episode["observations/observation"][:]  # [T + 1, dim]
    desired_goal = episode["observations/desired_goal"][:]
    achieved_goal = episode["observations/achieved_goal"][:]
    actions, rewards = episode["actions"][:], episode["rewards"][:]
```

In the authors' released format (a pickled list of episode dicts, which their code reads):
`gcdt dataset export-authors {example} --out data.pkl`.
"""
    body = [_profile_section(m) for m in manifests]
    if not body:
        body = [["No profile has a manifest yet: `make datasets PROFILE=P` makes one.", ""]]
    return head + "\n" + "\n".join(line for section in body for line in section).rstrip() + "\n"


def write_card(path: Path = CARD) -> bool:
    """Write docs/datasets.md (only if it changes); whether it wrote."""
    return write_if_changed(path, card_text())

"""Publish a TQC+HER run: a finished one as an agent others can use (`results/experts/tqc_*/`),
one in progress as a snapshot a fresh machine resumes (`results/experts/in_progress/`).

A run leaves two models, the last one and the best one by its periodic evaluations. Picking
the best by those same evaluations would flatter it, so both are measured again on fresh
validation episodes and the better one is published; it is then measured once more, on held-out
episodes that neither training, the periodic evaluations nor the validation saw. The folder
holds `model.zip` (at most `MAX_ZIP_MIB`), the run's `eval.csv`, and its `run.json` (with
its env steps, times, env steps/s and core-hours over the whole run, every resume included)
extended with the curve and a `published` record of the choice and both measurements.

`gcdt tqc publish RUN_DIR` runs it. An agent already published in the folder is replaced only
when asked (`replace`), and then in one swap: readers see the old agent or the new one.

A 1M-step run outlasts a working session, and a session may end on another machine than the
next one starts on. `gcdt tqc snapshot RUN_DIR` keeps what the run needs to carry on there, in
a few MiB the repository can hold: its checkpoint without the replay buffer (`strip_buffer`)
and its curve; not its best model (as large again), whose count starts afresh on the resume.
Copied into a run folder, `--resume` continues from it.
"""

from __future__ import annotations

import csv
import json
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gcdt.baselines.tqc_checkpoint import (
    CHECKPOINT_FILE,
    check_identity,
    has_buffer,
    read_header,
    strip_buffer,
)
from gcdt.baselines.tqc_her import BEST_MODEL_ZIP, EVAL_CSV, MODEL_ZIP, RUN_JSON
from gcdt.errors import GcdtError
from gcdt.paths import REPO_ROOT, check_writable, swap_dirs, write_json_atomic
from gcdt.provenance import git_commit, utc_now
from gcdt.settings import check_minimums, setting

AGENTS_DIR = REPO_ROOT / "results" / "experts"
#: Beside the agents: the snapshots of the runs that will become agents.
SNAPSHOTS_DIR = AGENTS_DIR / "in_progress"
#: Episode seeds of the validation and of the held-out measurement: apart from each other and
#: from training's and the periodic evaluations' (seeds 0-2 and 1000 and their streams).
VALIDATION_SEED, HELD_OUT_SEED = 4000, 5000
#: A published zip stays small enough for the repository.
MAX_ZIP_MIB = 5.0
CANDIDATES = {"final": MODEL_ZIP, "best": BEST_MODEL_ZIP}


@dataclass(frozen=True)
class PublishConfig:
    """What `publish_agent` measures: episodes per validation and held-out evaluation."""

    validation_episodes: int = setting(
        200,
        "episodes on which the final and the best model are compared",
        minimum=1,
        metavar="N",
    )
    held_out_episodes: int = setting(
        500, "held-out episodes on which the chosen model is measured", minimum=1, metavar="N"
    )

    def __post_init__(self) -> None:
        check_minimums(self)


#: What every reader of a published agent's run.json relies on.
AGENT_FIELDS = ("task", "reward", "seed", "env_steps")


def read_agent(folder: str | Path) -> dict[str, Any] | None:
    """The run.json of the agent published in `folder` (None where there is none); a file
    that cannot be read, or lacks what readers rely on, is refused in one line."""
    path = Path(folder) / RUN_JSON
    if not path.is_file():
        return None
    return _read_record(path, "agent record", "publish it again (gcdt tqc publish)")


def _read_record(path: Path, what: str, fix: str) -> dict[str, Any]:
    """The run.json at `path`, refused in one line (naming `what` it should be, and the `fix`)
    where it cannot be read or lacks `AGENT_FIELDS`: a missing seed is never assumed, since it
    names the folder an agent is published to."""
    try:
        record = json.loads(path.read_text())
        missing = [k for k in AGENT_FIELDS if k not in record]
    except (OSError, ValueError, TypeError) as err:
        raise GcdtError(f"{path} is not a readable {what} ({err}): {fix}") from err
    if missing:
        raise GcdtError(f"{path} lacks {', '.join(missing)}: {fix}")
    return record


def agent_dir(task: str, reward: str, root: str | Path = AGENTS_DIR, seed: int = 0) -> Path:
    """Where the agent of `task` with `reward` and `seed` is published: seed 0's folder is the
    task's expert (`tqc_TASK_REWARD`), further seeds sit beside it (`..._seedS`)."""
    return Path(root) / (f"tqc_{task}_{reward}" + (f"_seed{seed}" if seed else ""))


def agent_dirs(task: str, reward: str, root: str | Path = AGENTS_DIR) -> list[Path]:
    """The folders `agent_dir` gives the cell of `task` and `reward`: seed 0's first, then
    those of the further seeds published beside it."""
    first = agent_dir(task, reward, root)
    return [first, *sorted(first.parent.glob(f"{first.name}_seed*"))]


def _finished_run(run: Path) -> dict[str, Any]:
    """The run's record, refusing a folder that is not a finished `gcdt tqc train` run."""
    if not run.is_dir():
        raise GcdtError(f"no run folder at {run}: give the --out folder of a gcdt tqc train run")
    if (run / CHECKPOINT_FILE).exists():
        raise GcdtError(f"{run} holds an unfinished TQC+HER run: finish it with --resume first")
    missing = [n for n in (RUN_JSON, EVAL_CSV, *CANDIDATES.values()) if not (run / n).is_file()]
    if missing:
        raise GcdtError(f"{run} is not a finished gcdt tqc train run: {', '.join(missing)} missing")
    for name in CANDIDATES.values():
        mib = (run / name).stat().st_size / 2**20
        if mib > MAX_ZIP_MIB:
            raise GcdtError(
                f"{run / name} is {mib:.1f} MiB, over the {MAX_ZIP_MIB:g} MiB a published "
                "agent may take: train it with a smaller net_arch"
            )
    return _read_record(run / RUN_JSON, "run record", "not a gcdt tqc train run's record")


def _measure(zip_path: Path, task: str, reward: str, episodes: int, seed: int) -> dict:
    from gcdt.evaluation import evaluate  # imports torch and the envs: only when measuring
    from gcdt.policies import make_policy

    policy = make_policy(f"tqc:{zip_path}", task)
    summary = evaluate(policy, task, reward, episodes=episodes, seed=seed, progress=False).summary
    keep = ("success_rate", "mean_return", "std_return", "episodes", "timesteps")
    return {"seed": seed, **{k: summary[k] for k in keep}}


def _check_out(out: Path, task: str, reward: str, seed: int, replace: bool) -> None:
    """Refuse an existing `out` unless `replace` is asked and it holds an agent of the same
    task, reward and seed (anything else there is not a published agent's to swap)."""
    check_writable(out.parent, folder=True)  # the new agent is built beside `out`
    if not out.exists() and not out.is_symlink():
        return
    record = out / RUN_JSON
    if out.is_symlink() or not out.is_dir() or not record.is_file():
        raise GcdtError(f"{out} exists and is not a published agent's folder: choose another --out")
    if not replace:
        raise GcdtError(
            f"{out} already holds a published agent: pass --replace to replace it "
            "(git history keeps the old one)"
        )
    old = json.loads(record.read_text())
    if (old.get("task"), old.get("reward"), old.get("seed")) != (task, reward, seed):
        raise GcdtError(
            f"{out} holds a {old.get('task')}/{old.get('reward')} agent of seed "
            f"{old.get('seed')}, not {task}/{reward} of seed {seed}: choose the --out of this "
            "task, reward and seed"
        )


def publish_agent(
    run: str | Path,
    out: str | Path | None = None,
    config: PublishConfig = PublishConfig(),
    replace: bool = False,
) -> Path:
    """Publish the finished run in `run` (default folder: `agent_dir(task, reward, seed)`);
    returns the folder. An agent already there is refused unless `replace` (of the same task,
    reward and seed); it is then swapped for the new one whole. The run's snapshot beside the
    agents (`snapshot_dir` under out's folder, or one named after the run's folder), if one
    is kept, is removed: the run is finished."""
    run = Path(run)
    record = _finished_run(run)
    task, reward, seed = record["task"], record["reward"], record["seed"]
    out = Path(out) if out is not None else agent_dir(task, reward, seed=seed)
    _check_out(out, task, reward, seed, replace)  # before minutes of measuring, not after
    validation = {
        name: _measure(run / zip_name, task, reward, config.validation_episodes, VALIDATION_SEED)
        for name, zip_name in CANDIDATES.items()
    }
    # The better on validation; the final model on a tie (it has learned the longest).
    chosen = max(
        CANDIDATES,
        key=lambda n: (validation[n]["success_rate"], validation[n]["mean_return"], n == "final"),
    )
    held_out = _measure(
        run / CANDIDATES[chosen], task, reward, config.held_out_episodes, HELD_OUT_SEED
    )
    with open(run / EVAL_CSV, newline="") as f:
        curve = [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]
    published = {
        "model": chosen,
        "validation": validation,
        "held_out": held_out,
        "created": utc_now(),
        "git_commit": git_commit(),
    }
    with _built_whole(out) as staging:  # `replace` was checked above
        shutil.copyfile(run / CANDIDATES[chosen], staging / MODEL_ZIP)
        shutil.copyfile(run / EVAL_CSV, staging / EVAL_CSV)
        write_json_atomic(staging / RUN_JSON, {**record, "curve": curve, "published": published})
    snapshots = out.parent / SNAPSHOTS_DIR.name
    shutil.rmtree(snapshot_dir(task, reward, seed, snapshots), ignore_errors=True)
    # A candidate config's snapshot is named after its run's folder (scripts/long_tqc_runs.sh).
    named = snapshots / f"tqc_{run.name}"
    if _snapshot_of(named) == (task, reward, seed, record.get("config", {}).get("name")):
        shutil.rmtree(named)
    with suppress(OSError):
        snapshots.rmdir()  # the last run in progress is finished: no empty folder is left
    return out


def _snapshot_of(folder: Path) -> tuple[str, str, int, str] | None:
    """Task, reward, seed and config name of the snapshot in `folder`; None if none is."""
    try:
        header = read_header(folder / CHECKPOINT_FILE)
    except GcdtError:
        return None
    return (*_run_of(header), header["config"]["name"])


def snapshot_dir(task: str, reward: str, seed: int, root: str | Path = SNAPSHOTS_DIR) -> Path:
    """Where the snapshot of the run of `task`, `reward` and `seed` in progress is kept."""
    return Path(root) / f"tqc_{task}_{reward}_seed{seed}"


def snapshot_run(run: str | Path, out: str | Path | None = None) -> tuple[Path, dict[str, Any]]:
    """Snapshot the run in progress in `run` (default folder: `snapshot_dir`): its checkpoint
    without the replay buffer, and `eval.csv`. An older snapshot of the same
    run is replaced in one swap; anything else in `out` is refused. Returns the folder and the
    snapshot's checkpoint header."""
    run = Path(run)
    if not (run / CHECKPOINT_FILE).is_file():
        raise GcdtError(
            f"{run} holds no TQC+HER checkpoint: snapshot a run in progress (gcdt tqc train "
            "--out), or publish a finished one with gcdt tqc publish"
        )
    header = read_header(run / CHECKPOINT_FILE)
    out = Path(out) if out is not None else snapshot_dir(*_run_of(header))
    check_writable(out.parent, folder=True)
    if out.exists() or out.is_symlink():
        old = out / CHECKPOINT_FILE
        if out.is_symlink() or not old.is_file():
            raise GcdtError(f"{out} exists and is not a run's snapshot: choose another --out")
        previous = read_header(old)
        if has_buffer(previous):
            raise GcdtError(f"{out} is a run's folder, not a snapshot: choose another --out")
        check_identity(old, previous, header)  # a snapshot of another run: one line
        if previous["env_steps"] > header["env_steps"]:
            raise GcdtError(
                f"{out} holds a later snapshot of this run ({previous['env_steps']:,} env steps, "
                f"{run} is at {header['env_steps']:,}): resume from it, or choose another --out"
            )
    with _built_whole(out) as staging:
        kept = strip_buffer(run / CHECKPOINT_FILE, staging / CHECKPOINT_FILE)
        # The curve may run ahead of the checkpoint: a resume rewrites it to the checkpoint's.
        shutil.copyfile(run / EVAL_CSV, staging / EVAL_CSV)
    return out, kept


@contextmanager
def _built_whole(out: Path) -> Iterator[Path]:
    """A folder to build `out`'s new content in, beside it, renamed (or swapped) into place
    when the block ends: a stop leaves no half-built folder, and a replaced one is whole until
    the new one is."""
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        staging.chmod(0o755)  # mkdtemp's 0700 would become the published folder's
        yield staging
        if out.exists():
            swap_dirs(staging, out)  # staging now holds the old content
        else:
            staging.rename(out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _run_of(header: dict[str, Any]) -> tuple[str, str, int]:
    return header["task"], header["reward"], header["seed"]

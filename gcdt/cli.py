"""The `gcdt` command line (also `python -m gcdt`).

Bad input, from argparse or from the library (`GcdtError`), ends with one line
`gcdt: error: ...` on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import json
import sys
import typing
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from gcdt.baselines.tqc_her import BACKENDS as TQC_BACKENDS
from gcdt.baselines.tqc_her import CHECKPOINT_SECONDS, RUN_FILES, tqc_config_names
from gcdt.data.collect import LABELS
from gcdt.envs import REWARDS, TASKS
from gcdt.errors import GcdtError
from gcdt.evaluation import DEFAULT_TIMESTEPS, EvaluationConfig
from gcdt.experiments.grid import SECTIONS
from gcdt.experiments.profiles import PROFILES
from gcdt.experiments.sweep import BACKENDS, RETRIES
from gcdt.paths import check_writable, write_json_atomic
from gcdt.policies import POLICY_NAMES, POLICY_SPECS, TQC_PREFIX

USAGE_ERROR = 2
POLICY_HELP = (
    "a policy name, tqc:PATH of a TQC+HER zip (gcdt tqc train), or the path of a GC-DT/DT/BC "
    "checkpoint (gcdt train)"
)


class _Parser(argparse.ArgumentParser):
    """argparse, but its errors are one line (no usage block) and exit with status 2.

    `arguments(parser)`, when given, adds the parser's arguments the first time it parses
    (`gcdt train --help` included): they come from a module that imports torch, which
    `gcdt --help` and the other commands should not wait for.
    """

    def __init__(
        self, *args: Any, arguments: Callable[[_Parser], None] | None = None, **kwargs: Any
    ) -> None:
        super().__init__(*args, **kwargs)
        self.lazy_arguments = arguments

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[override]
        if self.lazy_arguments is not None:
            add, self.lazy_arguments = self.lazy_arguments, None
            add(self)
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> None:  # type: ignore[override]
        print(f"gcdt: error: {message}", file=sys.stderr)
        raise SystemExit(USAGE_ERROR)


def _success_rate(text: str) -> float:
    """An argparse type: a success rate in (0, 1]."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0 < value <= 1:  # NaN fails too
        raise argparse.ArgumentTypeError(f"expected a success rate in (0, 1], got {text}")
    return value


def _int_at_least(minimum: int) -> Callable[[str], int]:
    """An argparse type: an integer >= `minimum`, with a message that says so."""
    wanted = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {wanted}, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected {wanted}, got {value}")
        return value

    return parse


_positive_int = _int_at_least(1)


def _ratio(text: str) -> float:
    """An argparse type: a fraction within [0, 1]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {text!r}") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {text}")
    return value


def _gif_path(text: str) -> Path:
    """An argparse type: an output animation path, which must end in .gif."""
    if not text.endswith(".gif"):
        raise argparse.ArgumentTypeError(f"animations are GIF files ending in .gif, got {text!r}")
    return Path(text)


def _npz_path(text: str) -> Path:
    """An argparse type: an output dataset path, which must end in .npz."""
    if not text.endswith(".npz"):
        raise argparse.ArgumentTypeError(f"dataset paths end in .npz, got {text!r}")
    return Path(text)


def _add_field_option(
    parser: Any, field: dataclasses.Field, kind: Any, flag: str | None = None, **settings: Any
) -> None:
    """Option `flag` (default `--field-name`) for a dataclass field of type `kind`, parsed into
    `field.name`: the field's default and help (`metadata["help"]`), and choices (a
    `Literal`), a switch (`bool`), an integer of at least `metadata["minimum"]`, or `kind` as
    the type. `settings` adds to or overrides these argparse settings (e.g. `metavar`)."""
    option: dict[str, Any] = {
        "dest": field.name,
        "default": field.default,
        "help": field.metadata["help"],
    }
    if kind is bool:
        option["action"] = "store_true"
    elif typing.get_origin(kind) is typing.Literal:
        option["choices"] = typing.get_args(kind)
    elif "minimum" in field.metadata:
        option["type"] = _int_at_least(field.metadata["minimum"])
    else:
        option["type"] = kind
    if field.default is not None and kind is not bool:
        option["help"] += " (default: %(default)s)"
    parser.add_argument(flag or f"--{field.name.replace('_', '-')}", **{**option, **settings})


def _add_config_options(
    parser: argparse.ArgumentParser,
    config: type,
    exclusive: tuple[str, ...] = (),
    settings: dict[str, dict[str, Any]] | None = None,
) -> None:
    """An option per field of the dataclass `config` (`_add_field_option`, with the field's
    `settings`); those of the fields named in `exclusive` in one mutually exclusive group."""
    kinds = typing.get_type_hints(config)
    group = parser.add_mutually_exclusive_group() if exclusive else parser
    for field in dataclasses.fields(config):
        target = group if field.name in exclusive else parser
        _add_field_option(target, field, kinds[field.name], **(settings or {}).get(field.name, {}))


def _config_from(args: argparse.Namespace, config: type) -> Any:
    """The dataclass `config` with the values of its options (`_add_config_options`)."""
    return config(**{f.name: getattr(args, f.name) for f in dataclasses.fields(config)})


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="gcdt",
        description="Goal-Conditioned Decision Transformer on panda-gym: datasets and evaluation.",
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for add_command in (
        _evaluate_parser,
        _rollout_parser,
        _collect_parser,
        _dataset_parser,
        _train_parser,
        _tqc_parser,
        _sweep_parser,
        _report_parser,
        _compare_parser,
        _publish_parser,
    ):
        add_command(sub)
    return parser


def _add_policy_options(parser: argparse.ArgumentParser, *, reward: bool) -> None:
    """What every command that runs a policy asks for: the policy, its task (and reward), and
    the scripted expert's action noise."""
    parser.add_argument("--policy", required=True, metavar=POLICY_SPECS, help=POLICY_HELP)
    parser.add_argument("--task", required=True, choices=list(TASKS))
    if reward:
        parser.add_argument("--reward", required=True, choices=list(REWARDS))
    parser.add_argument("--noise", type=float, default=0.0, help="scripted expert action noise std")


def _evaluate_parser(sub: argparse._SubParsersAction) -> None:
    ev = sub.add_parser(
        "evaluate",
        help="measure a policy's success rate and return",
        description="Run a policy with the paper's protocol: a fixed budget of env steps "
        f"(default {DEFAULT_TIMESTEPS:,}) counting every finished episode, or a fixed number "
        "of episodes.",
    )
    _add_policy_options(ev, reward=True)
    _add_config_options(
        ev,
        EvaluationConfig,
        exclusive=("timesteps", "episodes"),
        settings={"n_envs": {"flag": "--envs", "metavar": "N"}},
    )
    ev.add_argument(
        "--target-return",
        type=float,
        metavar="R",
        help="a DT checkpoint's target return at each episode's start (default 0, the paper's)",
    )
    ev.add_argument(
        "--goal-region",
        type=_goal_region,
        metavar="AXIS=LOW:HIGH,...",
        help="draw the desired goals from this box only (world coordinates, metres; an empty "
        "bound is open), e.g. y=0: for one half of the table",
    )
    ev.add_argument(
        "--device",
        help="where a DT or BC checkpoint runs: auto (the default, CUDA when present), cpu or cuda",
    )
    ev.add_argument("--json", action="store_true", help="print the summary as one JSON line")
    ev.add_argument(
        "--out",
        type=Path,
        metavar="PATH",
        help="also write the full result (summary, every episode, the command) as JSON",
    )
    ev.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    ev.set_defaults(run=_evaluate)


def _evaluate(args: argparse.Namespace) -> int:
    from gcdt.evaluation import evaluate
    from gcdt.policies import make_policy

    if args.out is not None:
        check_writable(args.out)  # before the run, not after it
    policy = make_policy(args.policy, args.task, **_policy_kwargs(args))
    config = dataclasses.asdict(_config_from(args, EvaluationConfig))
    result = evaluate(
        policy,
        args.task,
        args.reward,
        **config,
        goal_region=args.goal_region,
        progress=not args.no_progress,
    )
    summary = result.summary
    if args.out is not None:
        record = {"command": _command(args), **result.to_dict()}
        write_json_atomic(args.out, record)
    if args.json:
        print(json.dumps(summary))
    else:
        print(
            f"{summary['policy']} on {summary['task']}/{summary['reward']}: "
            f"success {100 * summary['success_rate']:.1f} %, "
            f"return {summary['mean_return']:.2f} ± {summary['std_return']:.2f} "
            f"over {summary['episodes']} episodes ({summary['timesteps']} steps, "
            f"{summary['steps_per_second']:.0f} steps/s)"
            if summary["episodes"]
            else f"no episode finished within {summary['timesteps']} steps"
        )
    return 0


def _rollout_parser(sub: argparse._SubParsersAction) -> None:
    ro = sub.add_parser(
        "rollout",
        help="record one episode as an animated GIF, towards a goal of your choice",
        description="Render evaluation episode 0 of --seed headless and save it as a GIF; "
        "--goal replaces its desired goal (the explorer of notebook 07, from the shell).",
    )
    _add_policy_options(ro, reward=True)
    ro.add_argument(
        "--goal",
        type=_goal,
        metavar="X,Y,Z",
        help="the desired goal in world coordinates (metres), within the task's goal range",
    )
    ro.add_argument(
        "--target-return",
        type=float,
        metavar="R",
        help="a DT checkpoint's target return (default 0, the paper's)",
    )
    ro.add_argument("--seed", type=_int_at_least(0), default=0, help="evaluation seed")
    ro.add_argument("--size", type=_int_at_least(16), default=360, help="frame size, pixels")
    ro.add_argument("--out", type=_gif_path, required=True, metavar="PATH.gif")
    ro.set_defaults(run=_rollout)


def _goal(text: str):
    import numpy as np

    try:
        goal = np.array([float(v) for v in text.split(",")])
    except ValueError:
        goal = np.array([])
    if goal.shape != (3,):
        raise argparse.ArgumentTypeError(f"a goal is three numbers X,Y,Z in metres, got {text!r}")
    return goal


def _rollout(args: argparse.Namespace) -> int:
    from gcdt.evaluation import record_rollout
    from gcdt.policies import make_policy

    check_writable(args.out)
    policy = make_policy(args.policy, args.task, **_policy_kwargs(args))
    rec = record_rollout(
        policy, args.task, args.reward, args.seed, path=args.out, size=args.size, goal=args.goal
    )
    goal = ", ".join(f"{v:.3f}" for v in rec.goal)
    print(
        f"{policy.name} on {args.task}/{args.reward} towards ({goal}): {rec.verdict}, "
        f"return {rec.ret:.2f} over {rec.steps} steps: {args.out}"
    )
    return 0


def _goal_region(text: str):
    from gcdt.regions import GoalRegion

    try:
        return GoalRegion.parse(text)
    except GcdtError as err:  # argparse turns this into a usage error, exit 2
        raise argparse.ArgumentTypeError(str(err)) from None


def _command(args: argparse.Namespace) -> str:
    """The command line that is running, as recorded in result files and datasets."""
    return " ".join(["gcdt", *args.argv])


def _policy_kwargs(args: argparse.Namespace) -> dict:
    if args.noise and args.policy != "scripted":
        raise GcdtError("--noise applies only to --policy scripted")
    checkpoint = args.policy not in POLICY_NAMES and not args.policy.startswith(TQC_PREFIX)
    kwargs = {}
    target = getattr(args, "target_return", None)
    if target is not None:
        if not checkpoint:
            raise GcdtError("--target-return applies only to a DT checkpoint (gcdt train)")
        kwargs["target_return"] = target
    device = getattr(args, "device", None)
    if device is not None:
        if not checkpoint:
            raise GcdtError("--device applies only to a DT or BC checkpoint (gcdt train)")
        kwargs["device"] = device
    return {"noise_std": args.noise} if args.policy == "scripted" else kwargs


def _report(dataset, path: Path | None, as_json: bool) -> None:
    """Print a dataset's summary: one JSON line, or one readable line."""
    summary = dataset.summary()
    if as_json:
        print(json.dumps({"path": str(path) if path else None, **summary}))
        return
    where = f"{path}: " if path else ""
    print(
        f"{where}{summary['task']} {summary['source']} ({summary['policy']}): "
        f"{summary['transitions']} transitions in {summary['episodes']} episodes "
        f"(mean length {summary['mean_length']:.1f}), "
        f"success {100 * summary['success_rate']:.1f} %, "
        f"mean return sparse {summary['mean_return_sparse']:.2f} / "
        f"dense {summary['mean_return_dense']:.2f}"
    )


def _collect_parser(sub: argparse._SubParsersAction) -> None:
    co = sub.add_parser(
        "collect",
        help="collect an offline dataset with a policy",
        description="Run a policy on parallel envs and save its first whole episodes that "
        "add up to at least N transitions (both reward types are stored).",
    )
    _add_policy_options(co, reward=False)
    co.add_argument("--transitions", required=True, type=_positive_int, metavar="N")
    co.add_argument("--out", required=True, type=_npz_path, metavar="PATH.npz")
    co.add_argument("--seed", type=_int_at_least(0), default=0)
    co.add_argument("--envs", type=_positive_int, default=1, help="parallel env processes")
    co.add_argument(
        "--labels",
        choices=LABELS,
        default="executed",
        help="the action recorded: executed (what the env ran) or clean (the expert's action "
        "before its noise, as in DART)",
    )
    co.add_argument(
        "--goal-region",
        type=_goal_region,
        metavar="AXIS=LOW:HIGH,...",
        help="draw the desired goals from this box only (world coordinates, metres), e.g. y=0:",
    )
    co.add_argument("--json", action="store_true", help="print the summary as one JSON line")
    co.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    co.set_defaults(run=_collect)


def _collect(args: argparse.Namespace) -> int:
    from gcdt.data import collect
    from gcdt.policies import make_policy

    check_writable(args.out)  # before the collection, not after it
    policy = make_policy(args.policy, args.task, **_policy_kwargs(args))
    dataset = collect(
        policy,
        args.task,
        args.transitions,
        seed=args.seed,
        n_envs=args.envs,
        # Both rewards are stored; a trained agent runs under the one it was trained with.
        reward=policy.config().get("reward") or "sparse",
        labels=args.labels,
        goal_region=args.goal_region,
        progress=not args.no_progress,
    )
    dataset = dataset.with_metadata(command=_command(args))
    _report(dataset, dataset.save(args.out), args.json)
    return 0


def _dataset_parser(sub: argparse._SubParsersAction) -> None:
    ds = sub.add_parser("dataset", help="inspect, mix, subset, import and export datasets")
    dsub = ds.add_subparsers(dest="dataset_command", required=True, parser_class=_Parser)
    info = dsub.add_parser("info", help="summary statistics and metadata of a dataset")
    info.add_argument("path", type=Path)
    info.add_argument("--json", action="store_true", help="print summary and metadata as JSON")
    info.set_defaults(run=_dataset_info)

    mx = dsub.add_parser("mix", help="expert/random mixture by whole episodes (RQ5)")
    mx.add_argument("--expert", required=True, type=Path)
    mx.add_argument("--random", required=True, type=Path)
    mx.add_argument("--ratio", required=True, type=_ratio, help="expert fraction in [0, 1]")
    mx.add_argument("--size", required=True, type=_positive_int, help="transitions")
    mx.add_argument("--out", required=True, type=_npz_path, metavar="PATH.npz")
    mx.add_argument("--seed", type=_int_at_least(0), default=0)
    mx.set_defaults(run=_dataset_mix)

    sb = dsub.add_parser("subset", help="random whole episodes, about --size transitions (RQ4)")
    sb.add_argument("path", type=Path)
    sb.add_argument("--size", required=True, type=_positive_int, help="transitions")
    sb.add_argument("--out", required=True, type=_npz_path, metavar="PATH.npz")
    sb.add_argument("--seed", type=_int_at_least(0), default=0)
    sb.set_defaults(run=_dataset_subset)

    ex = dsub.add_parser("export-minari", help="write a dataset as a local Minari dataset")
    ex.add_argument("path", type=Path)
    ex.add_argument("--id", help="Minari id (default panda-gym/<task>/<policy>-v0)")
    ex.add_argument("--reward", choices=list(REWARDS), default="sparse")
    ex.set_defaults(run=_dataset_export_minari)

    im = dsub.add_parser("import-minari", help="read a local Minari dataset")
    im.add_argument("id")
    im.add_argument("--out", required=True, type=_npz_path, metavar="PATH.npz")
    im.set_defaults(run=_dataset_import_minari)

    ia = dsub.add_parser("import-authors", help="read the authors' pickled list of episode dicts")
    ia.add_argument("pickle", type=Path)
    ia.add_argument("--out", required=True, type=_npz_path, metavar="PATH.npz")
    ia.add_argument("--task", choices=list(TASKS), help="needed only when widths are ambiguous")
    ia.add_argument(
        "--trust-pickle",
        action="store_true",
        help="allow unpickling, which runs code from the file: only for trusted files",
    )
    ia.set_defaults(run=_dataset_import_authors)

    ea = dsub.add_parser("export-authors", help="write a dataset in the authors' pickle format")
    ea.add_argument("source", help="a dataset: PATH.npz or a Minari id")
    ea.add_argument("--out", required=True, type=Path, metavar="PATH.pkl")
    ea.add_argument("--reward", choices=list(REWARDS), default="sparse")
    ea.set_defaults(run=_dataset_export_authors)

    bd = dsub.add_parser(
        "build",
        help="build a profile's datasets as Minari datasets (make datasets)",
        description="Build every expert and random dataset of a profile as Minari datasets in "
        "$MINARI_DATASETS_PATH (default artifacts/minari), then check them against the "
        "profile's manifest results/PROFILE/datasets.json, or write it where it has none.",
    )
    bd.add_argument("--profile", required=True, choices=list(PROFILES))
    bd.add_argument(
        "--write-manifest",
        action="store_true",
        help="(maintainers) record these datasets as the manifest, replacing the committed one",
    )
    bd.set_defaults(run=_dataset_build)

    vf = dsub.add_parser(
        "verify",
        help="check a profile's Minari datasets against its manifest",
        description="Hash every file of the profile's datasets (building those not built "
        "yet) and compare with results/PROFILE/datasets.json.",
    )
    vf.add_argument("profile", choices=list(PROFILES))
    vf.set_defaults(run=_dataset_verify)

    cd = dsub.add_parser("card", help="regenerate docs/datasets.md from the manifests")
    cd.set_defaults(run=_dataset_card)


def _dataset_info(args: argparse.Namespace) -> int:
    from gcdt.data import load_dataset

    dataset = load_dataset(args.path)
    if args.json:
        print(json.dumps({"summary": dataset.summary(), "metadata": dataset.metadata}))
    else:
        _report(dataset, args.path, False)
    return 0


def _dataset_mix(args: argparse.Namespace) -> int:
    from gcdt.data import load_dataset, mix

    check_writable(args.out)
    mixed = mix(
        load_dataset(args.expert), load_dataset(args.random), args.ratio, args.size, args.seed
    )
    _report(mixed, mixed.save(args.out), False)
    return 0


def _dataset_subset(args: argparse.Namespace) -> int:
    from gcdt.data import load_dataset, subset

    check_writable(args.out)
    part = subset(load_dataset(args.path), args.size, args.seed)
    _report(part, part.save(args.out), False)
    return 0


def _dataset_export_minari(args: argparse.Namespace) -> int:
    from gcdt.data import export_minari, load_dataset

    exported = export_minari(load_dataset(args.path), args.id, reward=args.reward)
    print(
        f"exported {exported.total_steps} steps in {exported.total_episodes} episodes "
        f"as Minari dataset {exported.spec.dataset_id!r}"
    )
    return 0


def _dataset_import_minari(args: argparse.Namespace) -> int:
    from gcdt.data import import_minari

    check_writable(args.out)
    dataset = import_minari(args.id)
    _report(dataset, dataset.save(args.out), False)
    return 0


def _dataset_import_authors(args: argparse.Namespace) -> int:
    from gcdt.data import import_authors

    check_writable(args.out)
    dataset = import_authors(args.pickle, trust_pickle=args.trust_pickle, task=args.task)
    _report(dataset, dataset.save(args.out), False)
    return 0


def _dataset_export_authors(args: argparse.Namespace) -> int:
    from gcdt.data import export_authors
    from gcdt.experiments.release import load_source

    check_writable(args.out)
    dataset = load_source(args.source)
    path = export_authors(dataset, args.out, reward=args.reward)
    print(f"wrote {dataset.n_episodes} episodes ({args.reward} rewards) to {path}")
    return 0


def _dataset_build(args: argparse.Namespace) -> int:
    from gcdt.experiments import get_profile
    from gcdt.experiments.release import build, manifest_path
    from gcdt.paths import minari_dir

    profile = get_profile(args.profile)
    print(f"MINARI_DATASETS_PATH={minari_dir()}")
    for entry in build(profile, write_manifest=args.write_manifest):
        print(
            f"{entry['id']}: {entry['transitions']:,} transitions, {entry['episodes']:,} episodes"
        )
    print(f"manifest: {manifest_path(profile)}")
    return 0


def _dataset_verify(args: argparse.Namespace) -> int:
    from gcdt.experiments import get_profile
    from gcdt.experiments.release import verify

    lines = verify(get_profile(args.profile))
    print("\n".join(lines))
    print(f"verified {len(lines)} datasets of profile {args.profile}: every file matches")
    return 0


def _dataset_card(args: argparse.Namespace) -> int:
    from gcdt.experiments.release import CARD, write_card

    print(f"{CARD} {'written' if write_card() else 'unchanged'}")
    return 0


def _train_parser(sub: argparse._SubParsersAction) -> None:
    sub.add_parser(
        "train",
        help="train GC-DT, a DT ablation or BC on a dataset",
        arguments=_train_arguments,
    ).set_defaults(run=_train)


def _train_arguments(tr: argparse.ArgumentParser) -> None:
    """`gcdt train`'s arguments: its files, and an option per `TrainConfig` field."""
    from gcdt.checkpoint import CHECKPOINT_NAME
    from gcdt.training import LOG_NAME, TrainConfig

    tr.description = (
        f"Train from an offline dataset with the paper's recipe; writes {CHECKPOINT_NAME} "
        f"(usable as evaluate --policy) and {LOG_NAME} into --out."
    )
    tr.add_argument(
        "--dataset", required=True, metavar="PATH.npz|MINARI_ID", help="a .npz file or a Minari id"
    )
    tr.add_argument("--out", required=True, type=Path, metavar="DIR")
    tr.add_argument("--task", choices=list(TASKS), help="refuse a dataset of another task")
    _add_config_options(
        tr,
        TrainConfig,
        exclusive=("steps", "epochs"),
        settings={"context": {"metavar": "K"}, "checkpoint_seconds": {"metavar": "S"}},
    )
    tr.add_argument("--resume", action="store_true", help=f"continue from --out/{CHECKPOINT_NAME}")
    tr.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def _train(args: argparse.Namespace) -> int:
    from gcdt.experiments.release import load_source
    from gcdt.training import TrainConfig, train

    check_writable(args.out, folder=True)
    dataset = load_source(args.dataset)
    if args.task is not None and dataset.task != args.task:
        raise GcdtError(f"{args.dataset} holds {dataset.task!r} data, not {args.task!r}")
    cfg = _config_from(args, TrainConfig)
    result = train(dataset, cfg, args.out, resume=args.resume, progress=not args.no_progress)
    print(
        f"trained {result.steps} steps in {result.seconds:.0f} s, final loss "
        f"{result.final_loss:.4f}: {result.checkpoint}"
    )
    return 0


def _tqc_parser(sub: argparse._SubParsersAction) -> None:
    tq = sub.add_parser("tqc", help="TQC+HER: the online baseline and the paper's expert")
    tqsub = tq.add_subparsers(dest="tqc_command", required=True, parser_class=_Parser)
    tt = tqsub.add_parser(
        "train",
        help="train TQC+HER online on one task and reward",
        description="Train TQC with HER (hyperparameters and loop: gcdt/baselines/"
        f"tqc_her.yaml), evaluating it periodically; writes {', '.join(RUN_FILES)} to --out.",
    )
    tt.add_argument("--task", required=True, choices=list(TASKS))
    tt.add_argument("--reward", required=True, choices=list(REWARDS))
    tt.add_argument("--out", required=True, type=Path, metavar="DIR")
    tt.add_argument(
        "--config",
        default="paper",
        choices=tqc_config_names(),
        help="paper: rl-baselines3-zoo her-defaults (GPU-scale); cpu: smaller nets and batches",
    )
    tt.add_argument("--steps", type=_positive_int, help="env steps (default: the config's)")
    tt.add_argument(
        "--backend",
        choices=list(TQC_BACKENDS),
        help="sbx: SBX's JAX TQC, 2.7x faster on 2 CPU cores; sb3: sb3-contrib's "
        "(default: the config's)",
    )
    tt.add_argument(
        "--n-envs", type=_positive_int, metavar="N", help="envs side by side (default: config's)"
    )
    tt.add_argument(
        "--stop-at",
        type=_success_rate,
        metavar="RATE",
        help="stop at the first evaluation whose success rate reaches RATE (0-1]",
    )
    tt.add_argument("--seed", type=_int_at_least(0), default=0)
    tt.add_argument(
        "--eval-every", type=_positive_int, metavar="N", help="env steps between evaluations"
    )
    tt.add_argument("--eval-episodes", type=_positive_int, default=20, metavar="N")
    tt.add_argument("--device", default="auto", help="auto (CUDA when present), cpu or cuda")
    tt.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    tt.add_argument(
        "--resume",
        action="store_true",
        help="continue the run in --out from its checkpoint (same command otherwise)",
    )
    tt.add_argument(
        "--checkpoint-seconds",
        type=float,
        default=CHECKPOINT_SECONDS,
        metavar="S",
        help=f"seconds between checkpoints (default {CHECKPOINT_SECONDS:g}; 0: every loop "
        "iteration)",
    )
    tt.set_defaults(run=_tqc_train)


def _tqc_train(args: argparse.Namespace) -> int:
    from gcdt.baselines.tqc_her import load_tqc_config, train_tqc

    check_writable(args.out, folder=True)
    cfg = load_tqc_config(args.config, args.task)
    changes = {"steps": args.steps, "backend": args.backend, "n_envs": args.n_envs}
    cfg = cfg.with_budget(**{k: v for k, v in changes.items() if v is not None})
    result = train_tqc(
        args.task,
        args.reward,
        cfg,
        args.out,
        seed=args.seed,
        eval_every=args.eval_every,
        eval_episodes=args.eval_episodes,
        device=args.device,
        stop_at=args.stop_at,
        progress=not args.no_progress,
        command=_command(args),
        resume=args.resume,
        checkpoint_seconds=args.checkpoint_seconds,
    )
    final = result.final_success_rate
    print(
        f"TQC+HER {args.task}/{args.reward} ({cfg.name}): {result.env_steps} env steps in "
        f"{result.train_seconds:.0f} s ({result.env_steps_per_second:.1f} steps/s), "
        f"final success {100 * final:.0f} %, best {100 * result.best_success_rate:.0f} %: "
        f"{result.model}"
    )
    return 0


def _sweep_parser(sub: argparse._SubParsersAction) -> None:
    sw = sub.add_parser(
        "sweep",
        help="run the experiment grid of a profile (skips finished runs)",
        description="Run every run of a profile's grid whose result is not in "
        "results/PROFILE/runs/ yet (under $GCDT_OUTPUTS when set, else the repository's); "
        "failed and untrusted results are run again.",
    )
    sw.add_argument("--profile", required=True, choices=list(PROFILES))
    sw.add_argument("--backend", default="local", choices=list(BACKENDS))
    sw.add_argument("--address", help="Ray cluster address HOST:PORT (default: a local Ray)")
    sw.add_argument(
        "--storage",
        help="URI the Ray nodes share artifacts through, e.g. s3://bucket/gcdt (default: each "
        "node makes its own in its $GCDT_ARTIFACTS)",
    )
    sw.add_argument(
        "--retries",
        type=_int_at_least(0),
        default=RETRIES,
        help=f"times a failed run is tried again (default {RETRIES})",
    )
    sw.add_argument("--only", choices=list(SECTIONS), help="one section of the grid")
    sw.add_argument("--workers", type=_positive_int, help="parallel runs (default: cores)")
    sw.add_argument(
        "--dry-run", action="store_true", help="list the runs, their state and estimated cost"
    )
    sw.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    sw.set_defaults(run=_sweep)


def _sweep(args: argparse.Namespace) -> int:
    from gcdt.experiments import get_profile, plan, results_dir, sweep
    from gcdt.experiments.costs import CostModel
    from gcdt.experiments.store import RunStore
    from gcdt.experiments.sweep import default_workers, shared_cost

    profile = get_profile(args.profile)
    if not args.dry_run:  # before hours of runs, not after the first one
        from gcdt.paths import artifacts_dir, check_writable

        check_writable(results_dir(profile.name) / "runs", folder=True, option="results folder")
        check_writable(artifacts_dir(), folder=True, option="artifacts folder (GCDT_ARTIFACTS)")
    if args.dry_run:
        costs = CostModel.measured()  # reads the bench JSON and every result file: once
        store = RunStore(results_dir(profile.name) / "runs")
        planned, warnings = plan(profile, store, args.only, costs)
        for warning in warnings:
            print(f"warning: {warning}", file=sys.stderr)
        for p in planned:
            print(
                f"{p.key}  {p.state:<8} {p.estimate_seconds / 60:8.1f} min  "
                f"{p.entry.spec.label}  [{', '.join(p.entry.sections)}]"
            )
        todo = [p for p in planned if p.state != "done"]
        workers = args.workers or default_workers(profile)
        total = sum(p.estimate_seconds for p in todo) + shared_cost(todo, costs)
        print(
            f"{len(planned)} runs, {len(todo)} to run: about {total / 3600:.1f} h of work, "
            f"{total / 3600 / workers:.1f} h on {workers} worker(s) (estimate)"
        )
        return 0
    summary = sweep(
        profile,
        backend=args.backend,
        address=args.address,
        storage=args.storage,
        retries=args.retries,
        only=args.only,
        workers=args.workers,
        progress=not args.no_progress,
    )
    for warning in summary.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    print("\n".join(summary.lines()))
    return 0 if summary.ok else 1


def _report_parser(sub: argparse._SubParsersAction) -> None:
    rp = sub.add_parser(
        "report",
        help="tables and figures of the paper from results/PROFILE/runs/",
        description="Write Table 1 and the ablation table (CSV, Markdown, LaTeX), Fig. 2-4 "
        "and the learning curves (PNG, PDF) from a profile's finished runs (results/ and "
        "figures/ under $GCDT_OUTPUTS when set, else the repository's).",
    )
    rp.add_argument("--profile", required=True, choices=list(PROFILES))
    rp.add_argument("--readme", action="store_true", help="also update README.md's results")
    rp.add_argument(
        "--wall-seconds",
        type=float,
        metavar="S",
        help="record S as the wall time of the `make reproduce` that made these "
        "results (results/PROFILE/reproduce.json)",
    )
    rp.add_argument(
        "--backend",
        default="local",
        choices=list(BACKENDS),
        help="the backend of that `make reproduce` (with --wall-seconds)",
    )
    rp.set_defaults(run=_report_cmd)


def _report_cmd(args: argparse.Namespace) -> int:
    from gcdt.experiments import get_profile
    from gcdt.paths import REPO_ROOT
    from gcdt.report import record_reproduction, update_readme, write_report

    measured_at = dt.datetime.now(dt.UTC)  # when make measured --wall-seconds, near enough
    profile = get_profile(args.profile)
    if args.wall_seconds is not None and not args.wall_seconds >= 0:  # before writing anything
        raise GcdtError(f"--wall-seconds must be >= 0, got {args.wall_seconds}")
    written = write_report(profile)
    if args.wall_seconds is not None:
        written.append(
            record_reproduction(profile, args.wall_seconds, args.backend, measured_at=measured_at)
        )
    for path in written:
        print(path.relative_to(REPO_ROOT) if path.is_relative_to(REPO_ROOT) else path)
    if args.readme:
        update_readme(profile, REPO_ROOT / "README.md")
        print("README.md")
    return 0


def _reproduction_dir(given: Path | None) -> Path:
    """A reproduction's folder: the one given, else $GCDT_OUTPUTS, else artifacts/reproduce."""
    from gcdt.paths import reproduction_root

    folder = given or reproduction_root()
    if not folder.is_dir():
        raise GcdtError(f"{folder} does not exist: run `make reproduce` first, or give its folder")
    return folder


def _compare_parser(sub: argparse._SubParsersAction) -> None:
    cmp = sub.add_parser(
        "compare",
        help="check a reproduction against the published results",
        description="For every Table 1 cell, ablation cell and Fig. 3/4 point: the published "
        "value and its 95 % interval, yours, the difference, and whether yours lies inside. "
        "Writes results/PROFILE/reproduction_check.{csv,md} under --ours.",
    )
    cmp.add_argument("--profile", required=True, choices=list(PROFILES))
    cmp.add_argument(
        "--ours",
        type=Path,
        metavar="DIR",
        help="the reproduction's folder, "
        "holding results/PROFILE/runs/ (default: $GCDT_OUTPUTS, else "
        "artifacts/reproduce)",
    )
    cmp.set_defaults(run=_compare)


def _compare(args: argparse.Namespace) -> int:
    from gcdt.experiments import get_profile
    from gcdt.report.reproduction import write_check

    text, path = write_check(get_profile(args.profile), _reproduction_dir(args.ours))
    print(text.rstrip())
    if path is not None:
        print(f"\n(written to {path})")
    return 0


def _publish_parser(sub: argparse._SubParsersAction) -> None:
    pb = sub.add_parser(
        "publish",
        help="(maintainers) make a finished reproduction the published results",
        description="Mirror results/PROFILE/ and figures/PROFILE/ of a finished reproduction "
        "into the repository's; unchanged files are left untouched.",
    )
    pb.add_argument("--profile", required=True, choices=list(PROFILES))
    pb.add_argument(
        "--from",
        dest="source",
        type=Path,
        metavar="DIR",
        help="the reproduction's folder (default: $GCDT_OUTPUTS, else artifacts/reproduce)",
    )
    pb.set_defaults(run=_publish)


def _publish(args: argparse.Namespace) -> int:
    from gcdt.experiments import get_profile
    from gcdt.paths import REPO_ROOT
    from gcdt.report.reproduction import publish

    written, removed = publish(get_profile(args.profile), _reproduction_dir(args.source))
    for path in written:
        print(path.relative_to(REPO_ROOT))
    for path in removed:
        print(f"removed {path.relative_to(REPO_ROOT)}")
    print(f"published {args.profile}: {len(written)} file(s) written, {len(removed)} removed")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `gcdt` console script; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = _build_parser().parse_args(argv)
    args.argv = argv  # recorded in result files: the command that made them
    try:
        return args.run(args)
    except GcdtError as err:
        print(f"gcdt: error: {err}", file=sys.stderr)
        return USAGE_ERROR

"""The `gcdt` command line (also `python -m gcdt`).

Bad input, from argparse or from the library (`GcdtError`), ends with one line
`gcdt: error: ...` on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from gcdt.envs import REWARDS, TASKS
from gcdt.errors import GcdtError
from gcdt.paths import write_json_atomic

USAGE_ERROR = 2


class _Parser(argparse.ArgumentParser):
    """argparse, but its errors are one line (no usage block) and exit with status 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        print(f"gcdt: error: {message}", file=sys.stderr)
        raise SystemExit(USAGE_ERROR)


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


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="gcdt",
        description="Goal-Conditioned Decision Transformer on panda-gym: evaluate policies.",
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    ev = sub.add_parser(
        "evaluate",
        help="measure a policy's success rate and return",
        description="Run a policy with the paper's protocol: a fixed budget of env steps "
        "(default 10,000) counting every finished episode, or a fixed number of episodes.",
    )
    ev.add_argument(
        "--policy",
        required=True,
        metavar="random|scripted|CHECKPOINT",
        help="a policy name or the path of a trained checkpoint",
    )
    ev.add_argument("--task", required=True, choices=list(TASKS))
    ev.add_argument("--reward", required=True, choices=list(REWARDS))
    budget = ev.add_mutually_exclusive_group()
    budget.add_argument("--episodes", type=_positive_int, help="run this many whole episodes")
    budget.add_argument(
        "--timesteps", type=_positive_int, help="env steps in total (default 10000)"
    )
    ev.add_argument("--envs", type=_positive_int, default=1, help="parallel env processes")
    ev.add_argument("--seed", type=_int_at_least(0), default=0)
    ev.add_argument("--noise", type=float, default=0.0, help="scripted expert action noise std")
    ev.add_argument("--json", action="store_true", help="print the summary as one JSON line")
    ev.add_argument(
        "--out",
        type=Path,
        metavar="PATH",
        help="also write the full result (summary, every episode, the command) as JSON",
    )
    ev.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    ev.set_defaults(run=_evaluate)
    return parser


def _evaluate(args: argparse.Namespace) -> int:
    from gcdt.evaluation import evaluate
    from gcdt.policies import make_policy

    if args.noise and args.policy != "scripted":
        raise GcdtError("--noise applies only to --policy scripted")
    kwargs = {"noise_std": args.noise} if args.policy == "scripted" else {}
    policy = make_policy(args.policy, args.task, **kwargs)
    result = evaluate(
        policy,
        args.task,
        args.reward,
        timesteps=args.timesteps,
        episodes=args.episodes,
        n_envs=args.envs,
        seed=args.seed,
        progress=not args.no_progress,
    )
    summary = result.summary
    if args.out is not None:
        record = {"command": " ".join(["gcdt", *args.argv]), **result.to_dict()}
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

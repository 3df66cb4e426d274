"""``armreach experiment paper``: the paper's experiment on our env, with its tables and figures."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import Any

from armreach_core.cli.checks import check_backends, check_out
from armreach_core.plugins.defaults import DEFAULT_BACKEND


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("experiment", help="train + evaluate PPO and DDPG over seeds; write report.md")
    parser.add_argument("name", choices=("paper",), help="experiment to run")
    parser.add_argument("--seeds", type=int, default=3, help="seeds per agent (default: 3)")
    parser.add_argument(
        "--steps",
        type=_steps,
        action="append",
        default=None,
        metavar="N|KEY=N",
        help="env steps per run: N for both paper agents, or by agent (repeatable: --steps ppo=614400 --steps "
        "ddpg=60000 --steps fast-sac=20000; keys ppo, ddpg, fast-ppo, fast-sac); default: the paper's 614,400 "
        "and the fast preset's own",
    )
    parser.add_argument("--episodes", type=int, default=100, help="evaluation episodes per run (default: 100)")
    parser.add_argument("--backend", default=DEFAULT_BACKEND, help="physics backend (default: %(default)s)")
    parser.add_argument("--fast", action="store_true", help="add the `fast` preset's agents (PPO and SAC)")
    parser.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="runs trained at once, each in a process of its own (default: 1; the number of cores is the most "
        "that pays)",
    )
    parser.add_argument("--out", type=Path, default=None, help="experiment folder (default: runs/experiment-...)")
    parser.set_defaults(run=run)


#: ``--steps`` keys (armreach_core.rl.experiment.contender_keys, spelled out so that --help needs no rl extra).
STEP_KEYS = ("ppo", "ddpg", "fast-ppo", "fast-sac")


def _steps(text: str) -> tuple[str | None, int]:
    algo, _, number = text.rpartition("=")
    if algo and algo not in STEP_KEYS:
        raise argparse.ArgumentTypeError(f"{algo!r}: use one of {', '.join(STEP_KEYS)}")
    try:
        value = int(number)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not N or ALGO=N") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"steps must be positive, got {value}")
    return (algo or None, value)


def run(args: argparse.Namespace) -> int:
    from armreach_core.rl import runs
    from armreach_core.rl.experiment import paper_contenders, run_experiment
    from armreach_core.rl.report import warm_up, write_report

    check_out(args.out)
    check_backends([args.backend])
    out = args.out or runs.default_run_dir("runs", ["experiment", args.name])
    steps: dict[str, int] = {}
    for algo, n in args.steps or []:
        steps.update({"ppo": n, "ddpg": n} if algo is None else {algo: n})
    contenders = paper_contenders(steps, args.fast)
    try:
        results, ik = run_experiment(
            out,
            contenders,
            seeds=args.seeds,
            episodes=args.episodes,
            backend=args.backend,
            stream=sys.stderr,
            command=args.command_line,
            jobs=args.jobs,
            when_a_core_frees=warm_up,
        )
    except KeyboardInterrupt:
        print(
            f"armreach: interrupted; finished runs and checkpoints are kept in {out}: run the same command with "
            f"--out {out} to continue",
            file=sys.stderr,
        )
        return 130
    command = shlex.join(args.command_line)
    report = write_report(out, results, ik, episodes=args.episodes, backend=args.backend, command=command)
    for r in results:
        rates = ", ".join(f"{100 * s['success_rate']:.0f}%" for s in r.summaries)
        print(f"{r.contender.label}: success {rates}")
    print(f"DLS IK reference: success {100 * ik.summary()['success_rate']:.0f}%")
    print(f"report: {report}")
    return 0

"""``armreach bench``: env step vs the bare engine loop, reset, creation, vectorized and training throughput."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from armreach_core.cli.checks import add_arms_argument, check_out, check_urdf
from armreach_core.cli.checks import check_backends as check_installed
from armreach_core.cli.robot_args import add_robot_arguments, description_kwargs, robot_kwargs


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("bench", help="benchmark every backend: JSON plus a markdown table")
    parser.add_argument(
        "--backends", nargs="+", default=None, help="backends (default: every installed one but variants)"
    )
    parser.add_argument(
        "--steps", type=int, default=None, help="timed steps per measurement (default: 5000; --corpus: 1000)"
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=5,
        help="passes, taken in turns; steps/s: the best pass's, cost ratios: each pass's own, median (default: 5)",
    )
    parser.add_argument(
        "--episode-steps",
        type=int,
        default=None,
        help="steps per episode of random actions from home (default: 100, the fast and any-arm presets' episodes)",
    )
    parser.add_argument("--no-vector", action="store_true", help="skip the vectorized measurements")
    parser.add_argument(
        "--sb3",
        default="ppo=4096,ddpg=1000",
        help="timed training steps per algorithm, or 'none' (default: %(default)s)",
    )
    parser.add_argument(
        "--learners",
        default="sb3,sbx",
        help="learners whose training speed is measured, side by side (default: %(default)s)",
    )
    parser.add_argument("--out", type=Path, default=None, help="write bench.json and bench.md into this folder")
    parser.add_argument(
        "--corpus",
        action="store_true",
        help="time every corpus arm's env step against the bundled arm's, in turns, on each backend "
        "(writes corpus-speed.json and corpus-speed.md; --steps per repeat, default 1000 here)",
    )
    add_arms_argument(parser)
    learning = parser.add_argument_group("learning speed (--learning)")
    learning.add_argument(
        "--learning",
        action="store_true",
        help="time each algorithm of a preset to its held-out success threshold, over seeds, "
        "instead of the engine benchmarks (writes learning.json and learning.md); on the bundled arm, "
        "the --urdf arm, or with --corpus each corpus arm (e.g. --preset any-arm --corpus --algos sac)",
    )
    learning.add_argument("--preset", default="fast", help="preset whose algorithms are timed (default: fast)")
    learning.add_argument("--algos", default=None, help="comma-separated algorithms (default: the preset's)")
    learning.add_argument("--seeds", type=int, default=3, help="seeds per algorithm and backend (default: 3)")
    add_robot_arguments(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.diagnostics.bench import run_bench, save, to_markdown
    from armreach_core.errors import ConfigError

    check_out(args.out)
    if args.learning:
        return run_learning(args)
    if args.corpus:
        return run_corpus(args)
    steps = _checked_counts(args, 5000)
    backends = _checked_backends(args)
    check_urdf(args.urdf, description_kwargs(args))
    sb3: dict[str, int] = {}
    learners: list[str] = []
    measure_sb3 = None
    if args.sb3 != "none":  # training throughput: the rl extra (its import says so when it is missing)
        from armreach_core.rl.learners import ALGORITHMS, LEARNERS
        from armreach_core.rl.throughput import bench_training

        algos = ALGORITHMS["sb3"]
        for item in args.sb3.split(","):
            algo, _, n = item.partition("=")
            if algo not in algos or not n.isdigit():
                raise ConfigError(f"--sb3 {args.sb3!r}: expected ALGO=N[,ALGO=N] with ALGO in {', '.join(algos)}")
            sb3[algo] = int(n)
        learners = [name for name in args.learners.split(",") if name]
        unknown = [name for name in learners if name not in LEARNERS]
        if unknown or not learners:
            raise ConfigError(
                f"--learners {args.learners!r}: use one or more of {', '.join(LEARNERS)}, comma-separated"
            )
        measure_sb3 = bench_training
    results = run_bench(
        backends,
        steps=steps,
        repeats=args.repeats,
        vector=not args.no_vector,
        sb3_steps=sb3,
        sb3=measure_sb3,
        learners=learners,
        env_kwargs=robot_kwargs(args)
        | ({} if args.episode_steps is None else {"max_episode_steps": args.episode_steps}),
    )
    print(to_markdown(results))
    if args.out is not None:
        saved = save(results, args.out)
        print(f"saved {saved[0]} and {saved[1]}")
    return 0


def _checked_counts(args: argparse.Namespace, default_steps: int) -> int:
    """``--steps`` (``default_steps`` when not given), with ``--repeats`` and ``--episode-steps`` checked."""
    from armreach_core.errors import ConfigError

    steps = default_steps if args.steps is None else args.steps
    if steps < 10 or args.repeats < 1:
        raise ConfigError("--steps must be >= 10 and --repeats >= 1")
    if args.episode_steps is not None and args.episode_steps < 1:
        raise ConfigError(f"--episode-steps must be >= 1, got {args.episode_steps}")
    return steps


def _checked_backends(args: argparse.Namespace) -> list[str]:
    """``--backends`` (every installed one when not given): at least one, each one's engine importable."""
    from armreach_core.diagnostics.bench import check_backends
    from armreach_core.diagnostics.installed import installed_backends

    backends: list[str] = args.backends or installed_backends()
    check_backends(backends)
    check_installed(backends)
    return backends


def run_corpus(args: argparse.Namespace) -> int:
    """``--corpus``: each corpus arm's env steps/s over the bundled arm's, timed in turns."""
    from armreach_core.diagnostics import arm_speed
    from armreach_core.diagnostics.bench import EPISODE_STEPS
    from armreach_core.errors import ConfigError

    if args.urdf is not None:
        raise ConfigError("--corpus times the corpus arms; drop --urdf")
    steps = _checked_counts(args, 1000)
    episode_steps = args.episode_steps or EPISODE_STEPS
    speeds = [
        speed
        for backend in _checked_backends(args)
        for speed in arm_speed.corpus_speeds(
            backend, steps=steps, repeats=args.repeats, episode_steps=episode_steps, arms=args.arms
        )
    ]
    print(arm_speed.to_markdown(speeds))
    if args.out is not None:
        saved = arm_speed.save(speeds, args.out, episode_steps=episode_steps)
        print(f"saved {saved[0]} and {saved[1]}")
    return 0


def run_learning(args: argparse.Namespace) -> int:
    """``--learning``: the preset's algorithms, each trained to its threshold over ``--seeds`` seeds."""
    from armreach_core.errors import ConfigError
    from armreach_core.plugins.defaults import DEFAULT_TASK
    from armreach_core.rl.learning_bench import bench_learning
    from armreach_core.rl.presets import load_preset
    from armreach_core.rl.validation import UntilSuccess

    if args.seeds < 1:
        raise ConfigError(f"--seeds must be >= 1, got {args.seeds}")
    if args.out is None:
        raise ConfigError("--learning keeps its runs: give --out FOLDER")
    arms = _learning_arms(args)
    preset = load_preset(args.preset)
    have = preset.algos(DEFAULT_TASK)
    algos = args.algos.split(",") if args.algos else have
    unknown = [a for a in algos if a not in have]
    if unknown:
        raise ConfigError(f"--algos: preset {args.preset!r} has no {', '.join(unknown)}; it has {', '.join(have)}")
    missing = [a for a in algos if UntilSuccess.from_settings(preset.get(DEFAULT_TASK, a)) is None]
    if missing:
        raise ConfigError(
            f"preset {args.preset!r} does not stop at a success rate for {', '.join(missing)}: "
            "add an until_success section to time it"
        )
    backends = _checked_backends(args)
    bench_learning(algos, backends, args.seeds, args.out, preset=args.preset, arms=arms)
    print((args.out / "learning.md").read_text(encoding="utf-8"), end="")
    print(f"saved {args.out / 'learning.json'} and {args.out / 'learning.md'}")
    return 0


def _learning_arms(args: argparse.Namespace) -> list[Any]:
    """The arms ``--learning`` trains on: the ``--urdf`` arm or the bundled one, as the robot flags
    place it, or the corpus arms (``--corpus``, ``--arms``; those not installed are skipped with
    a line saying how to install them)."""
    from armreach_core.cli.checks import check_corpus_flags
    from armreach_core.cli.robot_args import arm_flags, arm_spec
    from armreach_core.diagnostics.corpus import for_each_corpus_arm
    from armreach_core.errors import ConfigError
    from armreach_core.rl.learning_bench import BUNDLED, BenchArm

    check_corpus_flags(args, args.urdf)
    if args.corpus:
        given = arm_flags(arm_spec(args))
        if given:
            raise ConfigError(f"--corpus takes each corpus arm as it is listed; drop {' '.join(given)}")
        found = for_each_corpus_arm(lambda arm, _: BenchArm(arm.name, tuple(arm_flags(arm.spec()))), arms=args.arms)
        if not found:
            raise ConfigError("no corpus arm is installed: make install (or pip install the packages named above)")
        return list(found.values())
    check_urdf(args.urdf, description_kwargs(args))
    flags = tuple(arm_flags(arm_spec(args)))  # empty on the bundled arm as it comes
    return [BenchArm(BUNDLED if args.urdf is None else Path(args.urdf).stem, flags)]  # labelled as a sweep labels it

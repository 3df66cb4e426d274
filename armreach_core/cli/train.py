"""``armreach train``: train an agent with a preset into a run folder (or continue one).

Training is the ``rl`` extra: :mod:`armreach_core.rl` is imported only when the command
runs, so that ``armreach`` itself works without it (and says what to install when a
training command needs it).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

from armreach_core.cli.checks import add_control_argument, check_backends, check_control, check_out, check_urdf
from armreach_core.cli.robot_args import DESCRIPTION_FLAGS, add_robot_arguments, description_kwargs
from armreach_core.errors import ConfigError
from armreach_core.plugins.defaults import DEFAULT_BACKEND, DEFAULT_TASK

#: ``--algo`` choices: :data:`armreach_core.rl.presets.ALGOS`, spelled out so that ``--help``
#: works without the rl extra (a test keeps the two equal).
ALGOS = ("ppo", "ddpg", "td3", "sac", "tqc", "crossq", "ik")

#: Flags that define a run; with --resume they come from the run's config instead.
RESUME_CONFLICTS = (
    ("--algo", "algo", None),
    ("--preset", "preset", "paper"),
    ("--task", "task", DEFAULT_TASK),
    ("--backend", "backend", DEFAULT_BACKEND),
    ("--her", "her", False),
    ("--learner", "learner", None),
    ("--seed", "seed", 0),
    ("--n-envs", "n_envs", None),
    ("--urdf", "urdf", None),
    ("--ee-link", "ee_link", None),
    ("--home", "home", None),
    ("--base-position", "base_position", None),
    ("--base-orientation", "base_orientation", None),
    ("--out", "out", None),
)


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("train", help="train an agent (Stable-Baselines3 or SBX) into a run folder")
    parser.add_argument(
        "--algo", choices=ALGOS, default=None, help="algorithm (default: the preset's own; ddpg for paper)"
    )
    parser.add_argument("--preset", default="paper", help="bundled preset (paper, fast) or a YAML file")
    parser.add_argument("--task", default=DEFAULT_TASK, help="registered task (default: %(default)s)")
    parser.add_argument("--backend", default=DEFAULT_BACKEND, help="physics backend (default: %(default)s)")
    parser.add_argument("--her", action="store_true", help="hindsight experience replay (off-policy algorithms)")
    add_control_argument(parser, " (default: the preset's, else joints)")
    parser.add_argument(
        "--physics", default=None, metavar="PROFILE", help="train on a fitted physics profile (armreach sysid)"
    )
    parser.add_argument(
        "--learner",
        choices=("sb3", "sbx"),
        default=None,
        help="library that trains: sb3 (PyTorch) or sbx (JAX) (default: the preset's; else sbx, or sb3 for ppo)",
    )
    parser.add_argument("--steps", type=int, default=None, help="total env steps (default: the preset's)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    parser.add_argument(
        "--until-success",
        type=float,
        default=None,
        metavar="RATE",
        help="stop at the first held-out evaluation with at least this success rate (0: train to --steps; "
        "default: the preset's, 0.98 for fast)",
    )
    parser.add_argument("--n-envs", type=int, default=None, help="parallel envs (default: the preset's, or 1)")
    add_robot_arguments(parser)
    parser.add_argument(
        "--threads", type=int, default=None, help="torch CPU threads (default: the preset's, else torch's)"
    )
    parser.add_argument("--device", default="auto", help="torch device (default: auto)")
    parser.add_argument("--out", type=Path, default=None, help="run folder (default: runs/<algo>-<preset>-...)")
    parser.add_argument("--resume", type=Path, default=None, metavar="RUN", help="continue the run in RUN")
    parser.add_argument(
        "--trust", action="store_true", help="resume a run another user owns or may write to (its files are pickles)"
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.rl import runs
    from armreach_core.rl.config import default_algo, extend, resolve_config
    from armreach_core.rl.train import train

    check_device(args.device)
    if args.resume is not None:
        run_dir: Path = args.resume
        conflicting = [flag for flag, value, default in RESUME_CONFLICTS if getattr(args, value) != default]
        if conflicting:
            raise ConfigError(
                f"--resume continues {run_dir} with the settings in its config.yaml; drop {', '.join(conflicting)} "
                "(only --steps, --until-success, --threads and --device may change)"
            )
        config = runs.read_config(run_dir)
        if args.steps is not None:
            config = extend(config, args.steps)
        if args.threads is not None:
            if args.threads < 1:
                raise ConfigError(f"--threads must be >= 1, got {args.threads}")
            config = config.with_settings(torch_threads=args.threads)
        if args.device != "auto":
            config = dataclasses.replace(config, device=args.device)
        if args.until_success is not None:
            config = with_until_success(config, args.until_success)
        print(f"resuming {run_dir} towards {config.timesteps} steps")
        result = train(config, run_dir, resume=True, stream=sys.stderr, command=args.command_line, trust=args.trust)
    else:
        config = resolve_config(
            algo=args.algo or default_algo(args.preset, args.task),
            preset=args.preset,
            task=args.task,
            backend=args.backend,
            steps=args.steps,
            seed=args.seed,
            n_envs=args.n_envs,
            her=args.her,
            urdf=args.urdf,
            ee_link=args.ee_link,
            device=args.device,
            threads=args.threads,
            placement={
                **{key: getattr(args, key) for key in ("home", "base_position", "base_orientation", "physics")},
                **description_kwargs(args),
            },
            learner=args.learner,
        )
        if args.until_success is not None:
            config = with_until_success(config, args.until_success)
        if args.control is not None:
            check_control(config.task)
            config = config.with_settings(env={**config.settings.get("env", {}), "control": args.control})
        # before the run folder is made: a failing command leaves none behind
        check_backends([config.backend])
        description = {key: value for key, value in config.arm.env_kwargs().items() if key in DESCRIPTION_FLAGS}
        check_urdf(config.urdf, description)
        check_out(args.out)
        her = "-her" if config.uses_her else ""
        name = [config.algo + her, config.preset, config.backend, f"s{config.seed}"]
        run_dir = args.out or runs.default_run_dir("runs", name)
        if not config.learns:
            runs.new_run_dir(run_dir)
            runs.write_config(run_dir, config)
            runs.record_command(run_dir, args.command_line)
            runs.write_json(run_dir / runs.ENVIRONMENT, runs.environment_record())
            print(f"ik has nothing to train; evaluate it with `armreach evaluate {run_dir}`")
            return 0
        result = train(config, run_dir, stream=sys.stderr, command=args.command_line)
    if result.interrupted:
        print(
            f"interrupted at {result.timesteps}/{result.total} steps; checkpoint saved. "
            f"Continue with `armreach train --resume {run_dir}`",
            file=sys.stderr,
        )
        return 130
    from armreach_core.rl.eval_summary import table

    rate = result.timesteps / result.seconds if result.seconds > 0 else float("nan")
    stopped = []
    if result.passed is not None:
        passed = result.passed
        stopped = [
            (
                "stopped",
                f"{100 * passed.success_rate:.0f} % success on {passed.episodes} held-out targets "
                f"at {result.timesteps:,} steps",
            )
        ]
    if result.kept is not None:
        best = f"the policy of step {result.kept:,}, the best of the held-out evaluations (validation.csv)"
        stopped = [("kept", best)]
    print(
        table(
            [
                ("run", str(run_dir)),
                ("algorithm", f"{config.algo} ({config.preset} preset) on {config.backend}, seed {config.seed}"),
                ("env steps", f"{result.timesteps:,} of {result.total:,}"),
                ("wall time", f"{result.seconds / 60:.1f} min ({rate:,.0f} env steps/s)"),
                *stopped,
                ("model", str(run_dir / runs.MODEL)),
                ("next", f"armreach evaluate {run_dir}"),
            ]
        )
    )
    return 0


def with_until_success(config: Any, rate: float) -> Any:
    """``config`` stopping at a held-out success ``rate`` (0: at its step budget), the preset's other
    ``until_success`` settings kept."""
    if not config.learns:
        raise ConfigError(f"--until-success stops training, and {config.algo!r} is not trained; drop it")
    if not 0.0 <= rate <= 1.0:
        raise ConfigError(f"--until-success must be a success rate in [0, 1], got {rate}")
    section = dict(config.settings.get("until_success") or {})
    section["threshold"] = rate
    return config.with_settings(until_success=section)


def check_device(device: str) -> None:
    """``--device`` is ``auto`` or a device torch knows (``cpu``, ``cuda``, ``cuda:1``...)."""
    if device == "auto":
        return
    try:
        import torch
    except ImportError:  # training itself says what to install
        return
    try:
        torch.device(device)
    except (RuntimeError, ValueError):
        raise ConfigError(f"--device {device!r} is not a torch device; use auto, cpu or cuda[:N]") from None

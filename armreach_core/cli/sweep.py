"""``armreach sweep SPEC.yaml``: a grid of runs as Ray Tune trials, on this machine or a Ray cluster."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from armreach_core.cli.checks import check_out


def add_parser(sub: Any) -> None:
    parser = sub.add_parser(
        "sweep", help="run a grid of algorithms x seeds x arms x settings on Ray Tune; write one report"
    )
    parser.add_argument("spec", type=Path, help="sweep spec (YAML: algos, seeds, arms, backends, preset, overrides...)")
    parser.add_argument("--out", type=Path, default=None, help="sweep folder (default: runs/sweep-<spec name>)")
    parser.add_argument(
        "--address",
        default=None,
        help="Ray cluster to run on (`auto`, or host:port; default: $RAY_ADDRESS, else a local Ray on this machine)",
    )
    parser.add_argument(
        "--storage", default=None, help="where Ray keeps the sweep's state; on a cluster a path every node reaches"
    )
    parser.add_argument("--cpus", type=int, default=None, help="CPUs of the local Ray (default: all cores)")
    parser.add_argument(
        "--resume", action="store_true", help="finish a sweep in --out: reuse finished trials, continue the others"
    )
    parser.add_argument("--report-only", action="store_true", help="write the report of --out from its run folders")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.errors import ConfigError
    from armreach_core.rl.sweep import collect, load_spec, missing_trials, run_sweep
    from armreach_core.rl.sweep_report import write_report
    from armreach_core.rl.sweep_trials import check_fits

    check_out(args.out)
    spec = load_spec(args.spec)
    out: Path = args.out or Path("runs") / f"sweep-{spec.name}"
    if args.cpus is not None and args.cpus < 1:
        raise ConfigError(f"--cpus must be >= 1, got {args.cpus}")
    if args.report_only:
        if not (out / "runs").is_dir():
            raise ConfigError(f"{out} holds no trials of a sweep (no runs folder); run the sweep first")
        report = write_report(out, collect(out, spec))
        print(f"report: {report}")
        return 0
    started = (out / "runs").is_dir() and any((out / "runs").iterdir())
    if started and not args.resume:
        raise ConfigError(f"{out} already holds trials of a sweep; finish it with --resume, or choose another --out")
    check_fits(spec.cpus, args.address, args.cpus)  # before it says it runs them
    todo = missing_trials(out, spec)
    total = len(spec.trials())
    print(f"{total - len(todo)} of {total} trials finished; running {len(todo)} on Ray", file=sys.stderr)
    rows = run_sweep(
        spec, out, address=args.address, storage=args.storage, cpus=args.cpus, resume=args.resume, stream=None
    )
    print(f"{len(rows)} trials; report: {out / 'report.md'}")
    print((out / "report.md").read_text(encoding="utf-8"))
    return 0 if len(rows) == total else 1

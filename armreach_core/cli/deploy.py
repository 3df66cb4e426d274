"""``armreach deploy``: run a run's exported policy on an arm through a driver, behind the safety layer."""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path
from typing import Any

from armreach_core.errors import ConfigError
from armreach_core.plugins.defaults import DEFAULT_BACKEND


def option(text: str) -> tuple[str, Any]:
    """``--driver-option KEY=VALUE``: numbers become numbers."""
    key, eq, value = text.partition("=")
    if not eq or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    for kind in (int, float):
        try:
            return key, kind(value)
        except ValueError:
            pass
    return key, value


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("deploy", help="run an exported policy on an arm through a driver, behind the safety layer")
    parser.add_argument("run_dir", type=Path, metavar="RUN", help="run folder (exported into RUN/export when needed)")
    parser.add_argument(
        "--driver", required=True, help="installed driver (entry-point group armreach.drivers), e.g. sim"
    )
    parser.add_argument(
        "--driver-option", type=option, action="append", default=[], metavar="KEY=VALUE", help="passed to the driver"
    )
    parser.add_argument("--targets", type=int, default=10, help="targets to reach (default: 10)")
    parser.add_argument("--max-steps", type=int, default=200, help="control steps per target (default: 200)")
    parser.add_argument("--seed", type=int, default=10_000, help="seed of the first target (default: 10000)")
    parser.add_argument("--speed-fraction", type=float, default=0.5, help="speed cap, share of URDF limits (0.5)")
    parser.add_argument("--backend", default=DEFAULT_BACKEND, help="backend of the twin env that draws targets")
    parser.add_argument("--joint-log", type=Path, default=None, help="joint log (default: RUN/deploy/joints.npz)")
    parser.add_argument(
        "--shadow", action="store_true", help="command nothing: the policy on the live state beside a simulated twin"
    )
    parser.add_argument("--trust", action="store_true", help="load a run folder made elsewhere (it is unpickled)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.cli.checks import check_counts
    from armreach_core.sim2real.card import export_run
    from armreach_core.sim2real.deploy import deploy, twin_env
    from armreach_core.sim2real.driver import load_driver_class
    from armreach_core.sim2real.joint_log import write_joint_log
    from armreach_core.sim2real.runtime import PolicyRuntime
    from armreach_core.sim2real.safety import SafetyLayer, SafetyLimits

    check_counts(targets=(args.targets, 1), max_steps=(args.max_steps, 1))
    driver_class = load_driver_class(args.driver)
    folder = args.run_dir / "export"
    if not (folder / "card.json").is_file():
        export_run(args.run_dir, folder, trust=args.trust)
    policy = PolicyRuntime(folder)
    env = twin_env(policy.card, args.backend)
    try:
        dt = float(policy.card["control_dt"])
        safety = SafetyLayer(env.robot, dt, SafetyLimits(speed_fraction=args.speed_fraction))
        try:
            driver = driver_class(env.robot, dt, **dict(args.driver_option))
        except TypeError as exc:
            raise ConfigError(f"driver {args.driver!r} does not take these options: {exc}") from None
        if args.shadow:
            return _shadow(args, policy, driver, env)
        with driver:
            result = deploy(
                policy,
                driver,
                env,
                safety,
                targets=args.targets,
                max_steps=args.max_steps,
                seed=args.seed,
                progress=lambda k, ok, n: print(f"target {k + 1}: {'reached' if ok else 'missed'} in {n} steps"),
            )
    finally:
        env.close()
    log_path = args.joint_log or args.run_dir / "deploy" / "joints.npz"
    if result.log is not None:
        write_joint_log(result.log, log_path)
    counts = ", ".join(f"{r} {n}" for r, n in sorted(Counter(t.rule for t in result.trips).items()))
    cycles = sorted(result.cycle_s)
    p99 = cycles[int(0.99 * (len(cycles) - 1))] * 1e3 if cycles else float("nan")
    print(
        f"reached {sum(result.reached)}/{len(result.reached)} targets; safety trips {len(result.trips)} "
        f"({counts or 'none'}); cycle p99 {p99:.1f} ms" + (f"; stopped by {result.stopped}" if result.stopped else "")
    )
    print(f"joint log: {log_path}")
    return 0 if not result.stopped else 1


def _shadow(args: argparse.Namespace, policy: Any, driver: Any, env: Any) -> int:
    import json

    from armreach_core.sim2real.shadow import plot_shadow, shadow

    with driver:
        result = shadow(policy, driver, env, steps=args.max_steps, seed=args.seed)
    out = args.run_dir / "shadow"
    out.mkdir(parents=True, exist_ok=True)
    png = plot_shadow(result, env.robot.joint_names, out / "shadow.png")
    largest = float(result.gap_m.max())
    summary = {"steps": len(result.gap_m), "parted_at": result.parted_at, "max_gap_m": largest}
    (out / "shadow.json").write_text(json.dumps(summary, indent=2) + "\n")
    where = f"they part at step {result.parted_at}" if result.parted_at is not None else "they never part"
    print(f"shadow: nothing sent; {where} (largest gap {largest * 1e3:.1f} mm); {png}")
    return 0

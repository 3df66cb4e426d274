"""``armreach export``: a trained run's policy as ONNX plus a card (JSON) to run it on a robot."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("export", help="write a run's policy as ONNX with a card (observation, action, joints)")
    parser.add_argument("run_dir", type=Path, metavar="RUN", help="run folder made by `armreach train`")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default: RUN/export)")
    parser.add_argument("--trust", action="store_true", help="load a run folder made elsewhere (it is unpickled)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.sim2real.card import export_run

    paths = export_run(args.run_dir, args.out or args.run_dir / "export", trust=args.trust)
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0

"""``armreach plugins``: every plugin with its version and what it registered."""

from __future__ import annotations

import argparse
import json
from typing import Any

from armreach_core.plugins.host import get_host


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("plugins", help="list plugins, their versions and registrations")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    host = get_host()
    infos = host.plugins()
    if args.json:
        payload = {
            "plugins": [
                {"name": i.name, "distribution": i.distribution, "version": i.version, "registered": i.registered}
                for i in infos
            ],
            "failures": [
                {"name": f.name, "distribution": f.distribution, "stage": f.stage, "error": f.error}
                for f in host.failures
            ],
            "disabled": host.disabled,
        }
        print(json.dumps(payload, indent=2))
        return 0
    for info in infos:
        origin = f"{info.distribution} {info.version}" if info.distribution else "in-process"
        print(f"{info.name}  ({origin})")
        for kind, names in info.registered.items():
            if names:
                print(f"    {kind + 's':9} {', '.join(names)}")
    for failure in host.failures:
        print(f"FAILED  {failure}")
    for name in host.disabled:
        print(f"disabled  {name}")
    return 0

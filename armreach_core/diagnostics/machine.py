"""The machine a figure was measured on, in one line: processor, cores, Python and system.

Every report that quotes a speed says where it came from with :func:`machine`; the learning
benchmark's pace (:mod:`armreach_core.diagnostics.pace`) names the processor with :func:`cpu_name`.
"""

from __future__ import annotations

import os
import platform
from pathlib import Path

__all__ = ["cpu_count", "cpu_name", "machine"]


def cpu_count() -> int:
    """The cores this process may run on (its affinity where the system has one)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def cpu_name(cpuinfo: Path = Path("/proc/cpuinfo")) -> str:
    """The processor's model name with its family and model numbers (``AMD EPYC, family 25, model 17``):
    a virtual machine often shows only the vendor's family name, and the numbers tell its generations
    apart. Where the system has no ``cpuinfo``, what :func:`platform.processor` says."""
    fields: dict[str, str] = {}
    try:
        for line in cpuinfo.read_text(encoding="utf-8", errors="replace").splitlines():
            key, sep, value = line.partition(":")
            if not sep:
                if fields:
                    break  # the first processor's block is enough
                continue
            fields.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    name = fields.get("model name") or platform.processor() or platform.machine() or "unknown"
    labels = (("cpu family", "family"), ("model", "model"))
    numbers = [f"{label} {fields[key]}" for key, label in labels if key in fields]
    return ", ".join([name, *numbers])


def machine() -> str:
    """``x86_64 (AMD EPYC, family 25, model 17), 2 CPU cores, Python 3.11.7, Linux``."""
    python = f"Python {platform.python_version()}, {platform.system()}"
    return f"{platform.machine()} ({cpu_name()}), {cpu_count()} CPU cores, {python}"

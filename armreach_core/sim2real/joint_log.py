"""The joint-log format: what an arm was commanded and what it did, one row per control step.

A log is the meeting point of the simulated and the real arm: ``armreach rollout
--joint-log`` and the deploy loop write one, a user's own driver can write one, and
``armreach sysid`` reads them. Version 1, in CSV or NPZ (chosen by the file's suffix):

=============  ===========================================================  ==========
field          meaning                                                      unit
=============  ===========================================================  ==========
time           when the row's state was read, from the log's start          s
commanded      joint targets sent right after the state was read            rad or m
position       measured joint positions (NaN-free; absent in a plan)        rad or m
velocity       measured joint velocities (optional)                         rad/s, m/s
effort         measured joint efforts (optional)                            N m or N
joint_names    the URDF names of the joints, in the columns' order
metadata       free text pairs: ``arm``, ``backend``, ``control_dt``, ...
=============  ===========================================================  ==========

Row ``k`` holds the state read at ``time[k]`` and the command sent after it, so
``commanded[k]`` acts on ``position[k + 1 + latency]``. Rows are evenly spaced at the
control period. An excitation plan is a log without ``position``.

CSV: lines starting ``#`` first (``# armreach-joint-log 1``, then ``# key: value`` for the
metadata), then a header ``time,cmd:<joint>...,q:<joint>...,qd:<joint>...,effort:<joint>...``
and one row per step. NPZ: arrays ``time``, ``commanded``, ``position``, ``velocity``,
``effort`` (the optional ones left out), ``joint_names``, ``format``, ``version`` and
``metadata`` (JSON text).
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ConfigError

FloatArray = npt.NDArray[np.float64]

FORMAT = "armreach-joint-log"
VERSION = 1
SUFFIXES = (".csv", ".npz")
_PREFIXES = {"commanded": "cmd", "position": "q", "velocity": "qd", "effort": "effort"}


@dataclass(frozen=True)
class JointLog:
    """One log (see the module's table); arrays are ``(steps,)`` or ``(steps, joints)``."""

    joint_names: tuple[str, ...]
    time: FloatArray
    commanded: FloatArray
    position: FloatArray | None = None
    velocity: FloatArray | None = None
    effort: FloatArray | None = None
    metadata: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n, steps = len(self.joint_names), len(self.time)
        if n == 0 or len(set(self.joint_names)) != n:
            raise ConfigError(f"joint log: joint names {list(self.joint_names)} must be distinct and not empty")
        if steps < 2 or np.ndim(self.time) != 1 or not np.all(np.diff(self.time) > 0):
            raise ConfigError("joint log: `time` must hold at least two increasing values (s)")
        for name in ("commanded", "position", "velocity", "effort"):
            value = getattr(self, name)
            if value is None:
                continue
            if np.shape(value) != (steps, n):
                raise ConfigError(f"joint log: `{name}` has shape {np.shape(value)}, expected ({steps}, {n})")
            if not np.isfinite(value).all():
                raise ConfigError(f"joint log: `{name}` holds NaN or inf; cut the log before the first bad row")

    @property
    def steps(self) -> int:
        return len(self.time)

    @property
    def control_dt(self) -> float:
        """The mean period between rows (s)."""
        return float((self.time[-1] - self.time[0]) / (self.steps - 1))

    def require_position(self, where: str) -> FloatArray:
        """The measured positions; ConfigError when the log is a plan without them."""
        if self.position is None:
            raise ConfigError(f"{where}: the joint log has no measured positions (`q:` columns); play it and log it")
        return self.position

    def in_order(self, joint_names: Sequence[str]) -> JointLog:
        """The same log with its columns in ``joint_names`` order (an arm's); ConfigError naming missing joints."""
        missing = [j for j in joint_names if j not in self.joint_names]
        if missing or len(joint_names) != len(self.joint_names):
            extra = [j for j in self.joint_names if j not in joint_names]
            raise ConfigError(
                f"joint log joints {list(self.joint_names)} do not match the arm's {list(joint_names)} "
                f"(missing {missing}, extra {extra}); log the arm's joints under their URDF names"
            )
        order = [self.joint_names.index(j) for j in joint_names]
        pick: dict[str, Any] = {
            k: (None if getattr(self, k) is None else getattr(self, k)[:, order]) for k in _PREFIXES
        }
        return JointLog(tuple(joint_names), self.time, metadata=self.metadata, **pick)


def _columns(log: JointLog) -> list[tuple[str, FloatArray]]:
    columns: list[tuple[str, FloatArray]] = [("time", log.time)]
    for key, prefix in _PREFIXES.items():
        value = getattr(log, key)
        if value is not None:
            columns += [(f"{prefix}:{j}", value[:, i]) for i, j in enumerate(log.joint_names)]
    return columns


def write_joint_log(log: JointLog, path: str | os.PathLike[str]) -> Path:
    """Write ``log`` to ``path`` (``.csv`` or ``.npz``); returns the path."""
    target = Path(path)
    suffix = _suffix(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".npz":
        arrays = {k: getattr(log, k) for k in ("time", *_PREFIXES) if getattr(log, k) is not None}
        np.savez_compressed(
            target,
            format=np.array(FORMAT),
            version=np.array(VERSION),
            joint_names=np.array(log.joint_names),
            metadata=np.array(json.dumps(dict(log.metadata))),
            **arrays,
        )
        return target
    columns = _columns(log)
    buffer = io.StringIO()
    buffer.write(f"# {FORMAT} {VERSION}\n")
    for key, value in log.metadata.items():
        buffer.write(f"# {key}: {value}\n")
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([name for name, _ in columns])
    table = np.column_stack([values for _, values in columns])
    writer.writerows([[repr(float(v)) for v in row] for row in table])
    target.write_text(buffer.getvalue())
    return target


def read_joint_log(path: str | os.PathLike[str]) -> JointLog:
    """Read a joint log written by :func:`write_joint_log` or by hand; ConfigError saying what is wrong."""
    source = Path(path)
    suffix = _suffix(source)
    if not source.is_file():
        raise ConfigError(f"joint log {str(source)!r} does not exist")
    try:
        return _read_npz(source) if suffix == ".npz" else _read_csv(source)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None
    except (ValueError, KeyError, OSError) as exc:
        raise ConfigError(
            f"{source} is not a readable joint log ({exc}); see docs/sim2real.md for the format"
        ) from None


def _suffix(path: Path) -> str:
    if path.suffix.lower() not in SUFFIXES:
        raise ConfigError(f"joint log {str(path)!r}: use a .csv or .npz file name")
    return path.suffix.lower()


def _check_version(kind: str, version: int) -> None:
    if kind != FORMAT:
        raise ConfigError(f"not a joint log (format {kind!r}, expected {FORMAT!r})")
    if version > VERSION:
        raise ConfigError(
            f"joint log version {version} is newer than this armreach reads ({VERSION}); upgrade armreach"
        )


def _read_npz(path: Path) -> JointLog:
    with np.load(path, allow_pickle=False) as data:
        _check_version(str(data["format"]), int(data["version"]))
        arrays: dict[str, Any] = {k: np.asarray(data[k], dtype=np.float64) for k in _PREFIXES if k in data}
        return JointLog(
            tuple(str(j) for j in data["joint_names"]),
            np.asarray(data["time"], dtype=np.float64),
            metadata={str(k): str(v) for k, v in json.loads(str(data["metadata"])).items()},
            **arrays,
        )


def _read_csv(path: Path) -> JointLog:
    lines = path.read_text().splitlines()
    comments = [line[1:].strip() for line in lines if line.startswith("#")]
    if not comments or len(comments[0].split()) != 2:
        raise ConfigError(f"the first line must be `# {FORMAT} {VERSION}`")
    kind, version = comments[0].split()
    _check_version(kind, int(version))
    metadata: dict[str, str] = {}
    for comment in comments[1:]:
        key, colon, value = comment.partition(":")
        if colon:
            metadata[key.strip()] = value.strip()
    rows = list(csv.reader(line for line in lines if line and not line.startswith("#")))
    header, body = rows[0], np.array(rows[1:], dtype=np.float64)
    if header[0] != "time":
        raise ConfigError(f"the header must start with `time`, got {header[0]!r}")
    names: list[str] = []
    arrays: dict[str, Any] = {}
    for key, prefix in _PREFIXES.items():
        picked = [(i, h.split(":", 1)[1]) for i, h in enumerate(header) if h.startswith(prefix + ":")]
        if not picked:
            continue
        joints = [j for _, j in picked]
        if names and joints != names:
            raise ConfigError(f"the `{prefix}:` columns name {joints}, the `cmd:` columns {names}")
        names = joints
        arrays[key] = body[:, [i for i, _ in picked]]
    if "commanded" not in arrays:
        raise ConfigError("no `cmd:<joint>` columns: a log needs the commanded joint targets")
    return JointLog(tuple(names), body[:, 0], metadata=metadata, **arrays)


__all__ = ["FORMAT", "VERSION", "JointLog", "read_joint_log", "write_joint_log"]

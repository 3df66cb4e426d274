"""One folder per run: resolved config, command, plugins and versions, model, logs.

Layout of ``runs/<name>/``::

    config.yaml        the resolved settings (what `--resume` and `evaluate` read back)
    arm.urdf           for an arm described by xacro: the URDF it expanded to
    command.txt        the command line that created the run (and each resume)
    environment.json   Python, package and engine versions, and the loaded plugins
    monitor/           one log per training env, a row per episode (reward, length, time, success),
                       read by armreach_core.rl.monitor
    tb/                TensorBoard logs
    checkpoint.zip     the latest checkpoint (+ checkpoint_replay.pkl for off-policy)
    checkpoint.json    its step count and the training wall-clock so far
    model.zip          the final model, written when training completes
    eval-<backend>/    what `armreach evaluate` writes

Every file is written to a temporary name in the same folder and renamed into place,
so a run killed at any moment leaves the previous version of each file readable.

Trust: ``model.zip``, ``checkpoint.zip`` and ``checkpoint_replay.pkl`` are pickles (as
in Stable-Baselines3), and loading one runs code from it. :func:`check_trusted` refuses
a run folder another user owns or may write to, unless the user passes ``--trust``.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import os
import platform
import re
import shlex
import shutil
import stat
import tempfile
from collections.abc import Callable, Iterator, Sequence
from importlib import metadata
from pathlib import Path
from typing import IO, Any

import yaml

from armreach_core.errors import ConfigError
from armreach_core.plugins.host import get_host
from armreach_core.rl.config import RunConfig
from armreach_core.rl.monitor import MONITOR_DIR, monitor_paths

CONFIG = "config.yaml"
#: The URDF a xacro arm expanded to (written beside ``config.yaml`` for xacro arms only).
ARM_URDF = "arm.urdf"
COMMAND = "command.txt"
ENVIRONMENT = "environment.json"
#: What the run's demonstration buffer holds (preset key ``demonstrations``): episodes, steps, success rate.
DEMONSTRATIONS = "demonstrations.json"
#: What imitation did before reinforcement (preset key ``imitation``): each stage's episodes, states, success.
IMITATION = "imitation.json"
MONITOR = "monitor.csv"
MODEL = "model.zip"
CHECKPOINT = "checkpoint.zip"
REPLAY = "checkpoint_replay.pkl"
PROGRESS = "checkpoint.json"
TRUST_NOTE = (
    "model and checkpoint files are pickles: loading one runs code from it; load only runs you or someone "
    "you trust produced"
)
#: The files of a run that are unpickled when they are loaded.
PICKLES = (MODEL, CHECKPOINT, REPLAY)


def _private_group(gid: int, uid: int) -> bool:
    """Whether ``gid`` is ``uid``'s own group (a umask of 002 with per-user groups makes files group-writable)."""
    import grp
    import pwd

    try:
        group, user = grp.getgrgid(gid), pwd.getpwuid(uid)
    except KeyError:
        return False
    return group.gr_name == user.pw_name and all(member == user.pw_name for member in group.gr_mem)


def check_trusted(run_dir: str | os.PathLike[str], *, trust: bool = False) -> None:
    """Refuse to unpickle from a run folder that someone other than the current user could have written.

    The folder and its pickle files (:data:`PICKLES`) must belong to the current user (or
    root) and must not be writable by others, nor by a group other than the user's own;
    otherwise another local user could have put code in them. ``trust=True`` (``--trust``)
    skips the check. Nothing is checked where the system has no user ids (Windows).

    Raises:
        ConfigError: naming the file, who owns it or who may write it, and ``--trust``.
    """
    if trust or not hasattr(os, "getuid"):
        return
    me = os.getuid()
    folder = Path(run_dir)
    for path in (folder, *(folder / name for name in PICKLES)):
        try:
            info = path.stat()
        except FileNotFoundError:
            continue
        problem = None
        if info.st_uid not in (me, 0):
            problem = f"it belongs to user id {info.st_uid}, not to you ({me})"
        elif info.st_mode & stat.S_IWOTH:
            problem = "it is writable by every user"
        elif info.st_mode & stat.S_IWGRP and not _private_group(info.st_gid, me):
            problem = f"it is writable by group id {info.st_gid}"
        if problem:
            raise ConfigError(
                f"refusing to load the run in {folder}: {path} is not safe to trust, {problem}. Model, checkpoint "
                "and replay files are pickles, and loading one runs any code put in it. If you know where this "
                "run came from, pass --trust (trust=True in Python); otherwise copy nothing from it"
            )


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it replaces ``path`` atomically."""
    final = Path(path)
    final.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{final.name}.", suffix=".tmp", dir=final.parent)
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp creates 0600; results should be as readable as any file
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        with open(tmp_path, "rb") as handle:
            os.fsync(handle.fileno())
        os.replace(tmp_path, final)
    finally:
        tmp_path.unlink(missing_ok=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


#: Names :func:`atomic_path` and :func:`atomic_save` give their temporary files.
_TEMPORARY = re.compile(r"^\..+\.[a-z0-9_]{8}\.(tmp|zip|pkl)$")


def remove_temporaries(run_dir: str | os.PathLike[str]) -> list[Path]:
    """Delete temporary files a killed writer left in ``run_dir``; returns what was removed."""
    removed = []
    for path in Path(run_dir).iterdir():
        if path.is_file() and _TEMPORARY.match(path.name):
            path.unlink(missing_ok=True)
            removed.append(path)
    return removed


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def atomic_save(path: str | os.PathLike[str], save: Callable[[Path], None]) -> None:
    """Call ``save(tmp)`` then move ``tmp`` onto ``path`` atomically (for library savers)."""
    final = Path(path)
    with atomic_path(final) as tmp:
        # Savers such as SB3's append ".zip" when it is missing; keep the suffix.
        target = tmp.with_suffix(final.suffix)
        try:
            save(target)
            os.replace(target, tmp)
        finally:
            target.unlink(missing_ok=True)


def write_yaml(path: str | os.PathLike[str], data: dict[str, Any]) -> None:
    atomic_write_text(path, yaml.safe_dump(data, sort_keys=False))


def write_config(run_dir: str | os.PathLike[str], config: RunConfig) -> None:
    """Write ``config.yaml`` (atomically) and, for an arm described by a xacro file, the URDF it
    expanded to (``arm.urdf``, meshes as absolute paths), so that the run can be reproduced."""
    write_yaml(Path(run_dir) / CONFIG, config.to_dict())
    arm = config.arm
    if arm.urdf is None or not Path(arm.urdf).is_file():
        return
    from armreach_core.robot.xacro_sandbox import is_xacro

    if is_xacro(Path(arm.urdf), Path(arm.urdf).read_bytes()):
        from armreach_core.robot.factory import build_robot

        atomic_write_text(Path(run_dir) / ARM_URDF, build_robot(arm).parsed.resolved_xml.decode("utf-8"))


def read_config(run_dir: str | os.PathLike[str]) -> RunConfig:
    """The resolved config of a run, with a clear error when the folder is not a run.

    Any ``config.yaml`` written since the first version reads back; see
    :mod:`armreach_core.rl.config` for what is required and what happens to unknown keys.
    """
    path = Path(run_dir) / CONFIG
    if not path.is_file():
        raise ConfigError(f"{run_dir} is not a run folder: {CONFIG} is missing (create one with `armreach train`)")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path} is not valid YAML: {exc}") from None
    return RunConfig.from_dict(data, source=str(path))


#: Packages every result depends on, whatever the plugins; the plugins' own distributions and
#: what they require (their engines) are added by :func:`versions`.
CORE_PACKAGES = ("armreach", "stable-baselines3", "torch", "gymnasium", "numpy")


def versions() -> dict[str, str]:
    """Versions of the packages a result depends on: the core's, each loaded plugin's and its requirements'."""
    out = {"python": platform.python_version(), "platform": platform.platform()}
    names = list(CORE_PACKAGES)
    for plugin in get_host().plugins():
        if plugin.distribution:
            names.append(plugin.distribution)
            names += _requirement_names(plugin.distribution)
    for dist in dict.fromkeys(names):
        with contextlib.suppress(metadata.PackageNotFoundError):
            out[dist] = metadata.version(dist)
    return out


def _requirement_names(distribution: str) -> list[str]:
    """Names of what ``distribution`` requires unconditionally (no extras, no environment markers)."""
    try:
        requirements = metadata.requires(distribution) or []
    except metadata.PackageNotFoundError:
        return []
    names = []
    for requirement in requirements:
        if ";" in requirement:  # an extra's or a platform's requirement
            continue
        match = re.match(r"[A-Za-z0-9][A-Za-z0-9._-]*", requirement.strip())
        if match:
            names.append(match.group(0))
    return names


def environment_record() -> dict[str, Any]:
    host = get_host()
    return {
        "versions": versions(),
        "plugins": [
            {"name": p.name, "distribution": p.distribution, "version": p.version, "registered": p.registered}
            for p in host.plugins()
        ],
        "plugin_failures": [str(f) for f in host.failures],
    }


def record_command(run_dir: Path, command: Sequence[str]) -> None:
    """Append the command line (with a timestamp) to ``command.txt``."""
    stamp = _dt.datetime.now().astimezone().isoformat(timespec="seconds")
    path = run_dir / COMMAND
    previous = path.read_text(encoding="utf-8") if path.is_file() else ""
    atomic_write_text(path, f"{previous}# {stamp}\n{shlex.join(command)}\n")


def default_run_dir(root: str | os.PathLike[str], parts: Sequence[str]) -> Path:
    """``root/<parts joined by '-'>-<timestamp>``, unique."""
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    base = Path(root) / "-".join([*parts, stamp])
    path, n = base, 1
    while path.exists():
        n += 1
        path = base.with_name(f"{base.name}-{n}")
    return path


def new_run_dir(path: Path) -> Path:
    """Create ``path`` for a new run; refuse a folder that holds a run with something to resume.

    A folder with a config but neither checkpoint nor model (a start that failed before
    its first checkpoint) is started over.
    """
    if (path / CONFIG).exists():
        if (path / CHECKPOINT).exists() or (path / MODEL).exists():
            raise ConfigError(
                f"{path} already holds a run; continue it with `armreach train --resume {path}` or choose another --out"
            )
        for stale in (MONITOR_DIR, "tb"):
            shutil.rmtree(path / stale, ignore_errors=True)
        for name in (CONFIG, PROGRESS, REPLAY):
            (path / name).unlink(missing_ok=True)
    path.mkdir(parents=True, exist_ok=True)
    return path


def monitor_rows(run_dir: Path) -> dict[str, int]:
    """Episodes recorded so far in each monitor log (file name → rows)."""
    out: dict[str, int] = {}
    for path in monitor_paths(run_dir):
        with open(path, "rb") as handle:
            out[path.name] = max(sum(1 for _ in handle) - 2, 0)
    return out


def truncate_monitors(run_dir: Path, rows: dict[str, int]) -> None:
    """Cut each monitor log back to ``rows`` episodes (those the checkpoint includes)."""
    for path in monitor_paths(run_dir):
        keep = rows.get(path.name, 0)
        lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
        if len(lines) > keep + 2:
            atomic_write_text(path, "".join(lines[: keep + 2]))


def write_json(path: str | os.PathLike[str], data: Any) -> None:
    atomic_write_text(path, json.dumps(data, indent=2, default=str) + "\n")


def open_text(path: Path) -> IO[str]:
    return open(path, encoding="utf-8")

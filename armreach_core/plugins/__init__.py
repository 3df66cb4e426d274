"""How armreach finds backends, tasks and robots: the plugin seam.

- :mod:`.hookspecs`: the hooks a plugin implements (``armreach_register_*``).
- :mod:`.specs`: what a plugin registers (:class:`~.specs.BackendSpec`, ...).
- :mod:`.host`: the pluggy host that loads the ``armreach`` entry-point group.
- :mod:`.lookup`: from a name to a backend class, a task or a robot, with helpful errors.
- :mod:`.registration`: one Gymnasium id per registered task.
- :mod:`.builtin`: armreach's own plugin (the reach task and the bundled arm), loaded
  through the same entry point as any third party's.
- :mod:`.defaults`: what is used when no backend, task or robot is named.
"""

from __future__ import annotations

from typing import Any

_HOST_NAMES = (
    "PluginHost",
    "Registry",
    "available_backends",
    "available_robots",
    "available_tasks",
    "get_host",
    "register_plugin",
    "unregister_plugin",
)

__all__ = list(_HOST_NAMES)


def __getattr__(name: str) -> Any:  # lazy, so that importing a submodule does not load the host
    if name in _HOST_NAMES:
        from armreach_core.plugins import host

        return getattr(host, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

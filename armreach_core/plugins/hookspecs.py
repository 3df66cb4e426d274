"""The hooks an armreach plugin may implement.

A plugin is any module or object listed in the ``armreach`` entry-point group (or
registered in-process with :func:`armreach_core.plugins.host.register_plugin`) that defines
one or more of these functions decorated with :data:`hookimpl`. Each hook receives a
*register* callable and calls it once per thing it provides.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pluggy

if TYPE_CHECKING:
    from armreach_core.plugins.specs import Register

hookspec = pluggy.HookspecMarker("armreach")
hookimpl = pluggy.HookimplMarker("armreach")


@hookspec
def armreach_register_backends(register: Register) -> None:
    """Register physics backends with ``register(BackendSpec(...))``.

    Called once per plugin when the plugin registry is first built (on ``import
    armreach_core``) and again whenever a plugin is added or removed in-process.
    Must be cheap: import the physics engine inside ``BackendSpec.load``, not here.
    """


@hookspec
def armreach_register_tasks(register: Register) -> None:
    """Register tasks with ``register(TaskSpec(...))``; each becomes a Gymnasium id.

    Called at the same moments as :func:`armreach_register_backends`.
    """


@hookspec
def armreach_register_robots(register: Register) -> None:
    """Register robot descriptions with ``register(RobotSpec(...))``.

    Called at the same moments as :func:`armreach_register_backends`.
    """

"""The one place the core names a backend, a task and a robot: what is used when none is asked for.

Each is registered by a plugin like any other (the backend by ``armreach-pybullet``, the
task and the robot by :mod:`armreach_core.plugins.builtin`); nothing else in the core
refers to them by name.
"""

from __future__ import annotations

#: Backend of an env, a run or a command when ``backend=`` / ``--backend`` is not given.
DEFAULT_BACKEND = "pybullet"
#: Task of ``armreach train`` and friends when ``--task`` is not given.
DEFAULT_TASK = "reach"
#: Robot of a task that names none, when no ``urdf=`` is given.
DEFAULT_ROBOT = "ar6"

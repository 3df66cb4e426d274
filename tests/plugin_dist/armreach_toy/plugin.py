"""The toy plugin: one hook, one task, nothing in armreach_core names it."""

from armreach_core import TaskSpec, hookimpl


def _load():
    from armreach_core.tasks.reach.task import ReachTask

    class ToyReach(ReachTask):
        name = "toy"

        def __init__(self, robot, **options):
            options.setdefault("success_threshold", 0.20)
            super().__init__(robot, **options)

    return ToyReach


@hookimpl
def armreach_register_tasks(register):
    register(TaskSpec(name="toy", env_id="armreach/Toy-v0", load=_load, description="reach within 20 cm"))

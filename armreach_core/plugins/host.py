"""Plugin discovery: the ``armreach`` entry-point group, loaded with pluggy.

Built-in backends and tasks arrive exactly like third-party ones: each distribution
lists a module in the ``armreach`` entry-point group, that module implements hooks from
:mod:`armreach_core.plugins.hookspecs`, and the :class:`PluginHost` calls them to build a
:class:`Registry`. A plugin that fails to import, or raises in a hook, is reported by
its distribution name (a :class:`PluginLoadWarning` and ``armreach plugins``) and the
others still load. Two plugins registering the same name is a :class:`PluginError`.

Set ``ARMREACH_DISABLE_PLUGINS`` to a comma-separated list of plugin or distribution
names (or ``all``) to skip them.
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from importlib.metadata import EntryPoint, entry_points
from typing import Any

import pluggy

from armreach_core.errors import PluginError
from armreach_core.plugins import hookspecs
from armreach_core.plugins.specs import BackendSpec, RobotSpec, Spec, TaskSpec, check_name

ENTRY_POINT_GROUP = "armreach"
DISABLE_ENV = "ARMREACH_DISABLE_PLUGINS"
_ENV_ID = re.compile(r"^armreach/[A-Z][A-Za-z0-9]*-v\d+$")
_KINDS: dict[str, type] = {"backend": BackendSpec, "task": TaskSpec, "robot": RobotSpec}
_HOOKS = {
    "backend": "armreach_register_backends",
    "task": "armreach_register_tasks",
    "robot": "armreach_register_robots",
}


class PluginLoadWarning(UserWarning):
    """A plugin could not be imported or raised in a hook; the others were loaded."""


@dataclass(frozen=True)
class PluginInfo:
    """One loaded plugin: where it came from and what it registered."""

    name: str
    distribution: str | None
    version: str | None
    registered: dict[str, tuple[str, ...]]


@dataclass(frozen=True)
class PluginFailure:
    """A plugin that was skipped, and why."""

    name: str
    distribution: str | None
    stage: str
    error: str

    def __str__(self) -> str:
        who = f"plugin {self.name!r}" + (f" (distribution {self.distribution!r})" if self.distribution else "")
        return f"{who} failed during {self.stage}: {self.error}"


@dataclass
class Registry:
    """Everything the loaded plugins registered, by name."""

    backends: dict[str, BackendSpec] = field(default_factory=dict)
    tasks: dict[str, TaskSpec] = field(default_factory=dict)
    robots: dict[str, RobotSpec] = field(default_factory=dict)
    owners: dict[tuple[str, str], str] = field(default_factory=dict)

    def table(self, kind: str) -> dict[str, Any]:
        tables: dict[str, dict[str, Any]] = {"backend": self.backends, "task": self.tasks, "robot": self.robots}
        return tables[kind]


def _disabled_names() -> set[str]:
    raw = os.environ.get(DISABLE_ENV, "")
    return {part.strip() for part in raw.split(",") if part.strip()}


class PluginHost:
    """A pluggy manager for the ``armreach`` group, and the registry its hooks build."""

    def __init__(self, *, load_entry_points: bool = True) -> None:
        self.pm = pluggy.PluginManager(ENTRY_POINT_GROUP)
        self.pm.add_hookspecs(hookspecs)
        self.failures: list[PluginFailure] = []
        self.disabled: list[str] = []
        self._distributions: dict[str, tuple[str | None, str | None]] = {}
        self._registry: Registry | None = None
        self._listeners: list[Callable[[Registry], None]] = []
        if load_entry_points:
            self.load_entry_points(entry_points(group=ENTRY_POINT_GROUP))

    # -- loading -----------------------------------------------------------------------
    def _fail(self, name: str, stage: str, error: BaseException | str) -> None:
        dist = self._distributions.get(name, (None, None))[0]
        text = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
        failure = PluginFailure(name=name, distribution=dist, stage=stage, error=text)
        self.failures.append(failure)
        warnings.warn(str(failure), PluginLoadWarning, stacklevel=3)

    def load_entry_points(self, eps: Iterable[EntryPoint]) -> None:
        """Import and register the plugins of ``eps`` (the ``armreach`` group's entry points by default).

        A plugin that fails to import or to register is recorded in :attr:`failures` and warned
        about; the others still load.
        """
        disabled = _disabled_names()
        for ep in sorted(eps, key=lambda e: e.name):
            dist = ep.dist.name if ep.dist is not None else None
            version = ep.dist.version if ep.dist is not None else None
            if "all" in disabled or ep.name in disabled or dist in disabled:
                self.disabled.append(ep.name)
                continue
            if self.pm.has_plugin(ep.name):
                self._distributions.setdefault(ep.name, (dist, version))
                self._fail(ep.name, "import", f"another plugin is already named {ep.name!r}")
                continue
            self._distributions[ep.name] = (dist, version)
            try:
                plugin = ep.load()
            except Exception as exc:  # a broken plugin must not take the host down
                self._fail(ep.name, "import", exc)
                continue
            self._add(plugin, ep.name, raise_errors=False)

    def _add(self, plugin: object, name: str, *, raise_errors: bool) -> None:
        try:
            self.pm.register(plugin, name=name)
            self.pm.check_pending()
        except Exception as exc:
            if self.pm.has_plugin(name):
                self.pm.unregister(name=name)
            if raise_errors:
                raise PluginError(f"plugin {name!r} is invalid: {exc}") from exc
            self._fail(name, "registration", exc)

    def register_plugin(self, plugin: object, name: str) -> None:
        """Add a plugin in-process (tests, notebooks). Raises :class:`PluginError` on clashes."""
        if self.pm.has_plugin(name):
            raise PluginError(f"a plugin named {name!r} is already registered")
        self._distributions[name] = (None, None)
        self._add(plugin, name, raise_errors=True)
        try:
            self._rebuild(strict_plugin=name)
        except PluginError:
            self.pm.unregister(name=name)
            self._distributions.pop(name, None)
            self._rebuild()
            raise

    def unregister_plugin(self, name: str) -> None:
        """Remove a plugin added with :meth:`register_plugin` (or loaded from an entry point)."""
        if not self.pm.has_plugin(name):
            raise PluginError(f"no plugin named {name!r} is registered")
        self.pm.unregister(name=name)
        self._distributions.pop(name, None)
        self._rebuild()

    # -- registry ----------------------------------------------------------------------
    @property
    def registry(self) -> Registry:
        """The registry, built on first use."""
        if self._registry is None:
            self._rebuild()
        assert self._registry is not None
        return self._registry

    def on_rebuild(self, listener: Callable[[Registry], None]) -> None:
        """Call ``listener`` with every new registry (now, if one exists)."""
        self._listeners.append(listener)
        if self._registry is not None:
            listener(self._registry)

    def _rebuild(self, strict_plugin: str | None = None) -> None:
        registry = Registry()
        for kind, hook_name in _HOOKS.items():
            caller = getattr(self.pm.hook, hook_name)
            for impl in caller.get_hookimpls():  # registration order
                owner = impl.plugin_name
                register = self._registrar(registry, kind, owner)
                try:
                    impl.function(**{arg: register for arg in impl.argnames})
                except PluginError:
                    raise
                except Exception as exc:
                    if owner == strict_plugin:
                        raise PluginError(f"plugin {owner!r} raised in {hook_name}: {exc}") from exc
                    self._fail(owner, hook_name, exc)
        self._registry = registry
        for listener in self._listeners:
            listener(registry)

    @staticmethod
    def _registrar(registry: Registry, kind: str, owner: str) -> Callable[[Spec], None]:
        expected = _KINDS[kind]

        def register(spec: Spec) -> None:
            if not isinstance(spec, expected):
                raise PluginError(
                    f"plugin {owner!r} passed {type(spec).__name__} to the {kind} register; "
                    f"expected {expected.__name__}"
                )
            check_name(kind, spec.name)
            if isinstance(spec, TaskSpec):
                for env_id in (spec.env_id, *spec.deprecated_ids):
                    if not _ENV_ID.match(env_id):
                        raise PluginError(
                            f"task {spec.name!r} of plugin {owner!r} has env id {env_id!r}; "
                            "use the form 'armreach/Name-vN'"
                        )
            table = registry.table(kind)
            if spec.name in table:
                first = registry.owners[(kind, spec.name)]
                raise PluginError(
                    f"{kind} {spec.name!r} is registered twice: by plugin {first!r} and by plugin {owner!r}; "
                    f"remove one, or disable it with {DISABLE_ENV}={owner}"
                )
            if isinstance(spec, TaskSpec):
                for other in registry.tasks.values():
                    for env_id in {spec.env_id, *spec.deprecated_ids} & {other.env_id, *other.deprecated_ids}:
                        raise PluginError(
                            f"env id {env_id!r} is registered twice: by task {other.name!r} and by "
                            f"task {spec.name!r} of plugin {owner!r}"
                        )
            table[spec.name] = spec
            registry.owners[(kind, spec.name)] = owner

        return register

    # -- reporting ---------------------------------------------------------------------
    def plugins(self) -> list[PluginInfo]:
        """Every loaded plugin with its distribution, version and registrations."""
        registry = self.registry
        infos = []
        for name, _plugin in sorted(self.pm.list_name_plugin()):
            dist, version = self._distributions.get(name, (None, None))
            registered = {
                kind: tuple(sorted(n for (k, n), owner in registry.owners.items() if k == kind and owner == name))
                for kind in _KINDS
            }
            infos.append(PluginInfo(name=name, distribution=dist, version=version, registered=registered))
        return infos


_HOST: PluginHost | None = None


def get_host() -> PluginHost:
    """The process-wide plugin host, created (and entry points loaded) on first use."""
    global _HOST
    if _HOST is None:
        _HOST = PluginHost()
    return _HOST


def register_plugin(plugin: object, name: str) -> None:
    """Register a plugin object in-process; its tasks get Gymnasium ids at once."""
    get_host().register_plugin(plugin, name)


def unregister_plugin(name: str) -> None:
    """Remove a plugin registered with :func:`register_plugin`."""
    get_host().unregister_plugin(name)


def available_backends(*, variants: bool = True) -> list[str]:
    """Names of the registered backends (their engines may still be missing); without ``variants``,
    those that are no other backend's variant (:attr:`~armreach_core.plugins.specs.BackendSpec.variant_of`)."""
    backends = get_host().registry.backends
    return sorted(name for name, spec in backends.items() if variants or spec.variant_of is None)


def available_tasks() -> list[str]:
    """Names of the registered tasks."""
    return sorted(get_host().registry.tasks)


def available_robots() -> list[str]:
    """Names of the registered robots."""
    return sorted(get_host().registry.robots)

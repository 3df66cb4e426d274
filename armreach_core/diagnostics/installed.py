"""Which registered backends can run here: their engine imports."""

from __future__ import annotations

from collections.abc import Iterable


def installed_backends(names: Iterable[str] | None = None) -> list[str]:
    """The backends of ``names`` (default: every registered one but variants of others) whose engine is
    installed, in order."""
    from armreach_core.errors import BackendUnavailableError
    from armreach_core.plugins.host import available_backends
    from armreach_core.plugins.lookup import load_backend_class

    found = []
    for name in available_backends(variants=False) if names is None else names:
        try:
            load_backend_class(name)
        except BackendUnavailableError:
            continue
        found.append(name)
    return found

"""Training, evaluation and experiments on top of Stable-Baselines3: the ``rl`` extra.

Importing this package (or any module in it) checks that the extra is installed, without
importing it: torch and Stable-Baselines3 are still imported only where they are used.
When a package is missing the import raises
:class:`~armreach_core.errors.MissingExtraError`, which names the command that installs it.
"""

from __future__ import annotations

from importlib.util import find_spec

from armreach_core.errors import MissingExtraError

#: Import name → distribution name of what the ``rl`` extra installs and this package uses.
REQUIRED = {
    "stable_baselines3": "stable-baselines3",
    "torch": "torch",
    "tensorboard": "tensorboard",
    "matplotlib": "matplotlib",
    "tqdm": "tqdm",
}
INSTALL_HINT = "pip install 'armreach[rl]' (from a checkout: pip install -e '.[rl]')"


def missing_packages() -> list[str]:
    """Distributions of the ``rl`` extra that cannot be imported (``sys.modules[name] = None`` counts)."""
    missing = []
    for module, distribution in REQUIRED.items():
        try:
            found = find_spec(module) is not None
        except (ImportError, ValueError):  # a half-imported or broken package
            found = False
        if not found:
            missing.append(distribution)
    return missing


_missing = missing_packages()
if _missing:
    raise MissingExtraError(
        f"training, evaluation and experiments need the rl extra, and {', '.join(_missing)} "
        f"{'is' if len(_missing) == 1 else 'are'} not installed: {INSTALL_HINT}"
    )

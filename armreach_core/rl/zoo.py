"""rl-zoo3 support: the hyperparameter file armreach ships for its envs.

``python -m armreach_core.rl.zoo`` prints its path, for ``rl_zoo3.train --conf-file``.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def hyperparams_path() -> Path:
    """The rl-zoo3 hyperparameter file for armreach/Reach-v0 and armreach/Grasp-v0."""
    return Path(str(resources.files("armreach_core").joinpath("hyperparams", "rl_zoo3.yml")))


if __name__ == "__main__":  # pragma: no cover - a one-line helper for shells
    print(hyperparams_path())

"""matplotlib's ``pyplot`` on the Agg backend: figures drawn to files, never a window.

Every figure armreach writes imports ``pyplot`` from here (inside the function that draws,
so that commands which draw nothing do not pay for matplotlib's import)::

    from armreach_core.plotting import pyplot as plt
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as pyplot  # after the backend is chosen

__all__ = ["pyplot"]

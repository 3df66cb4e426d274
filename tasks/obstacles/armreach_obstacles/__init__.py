"""armreach-obstacles: reach a target around boxes, spheres and cylinders, with a planning reference.

Installing the distribution registers ``armreach/ReachAround-v3`` through the ``armreach``
entry-point group; ``import armreach_core`` is all it takes to ``gym.make`` it. Nothing in
``armreach_core`` names this package.
"""

from __future__ import annotations

__version__ = "0.1.0"

"""armreach-grasp: pick a cube from a table with a parallel two-finger gripper and lift it.

Installing the distribution registers ``armreach/Grasp-v3`` and the ``ar6-gripper`` robot
through the ``armreach`` entry-point group; ``import armreach_core`` is all it takes to
``gym.make`` it. Nothing in ``armreach_core`` names this package.
"""

from __future__ import annotations

__version__ = "0.1.0"

"""Diagnostics that stand apart from the runtime core.

- :mod:`.bench`, :mod:`.soak`: env speed and memory over time.
- :mod:`.parity`: the two engines driven alike and compared.
- :mod:`.robot_report`, :mod:`.corpus`: what ``armreach robot`` says of an arm, and the
  public arms it is tried on.
- :mod:`.contract`: the backend contract suite every backend's tests run.
- :mod:`.smoothness`: jerk of a trajectory.
- :mod:`.tables`: markdown tables, the one way reports write them.

Nothing in the env imports this package, and it imports no training code (the training
throughput of ``armreach bench`` lives in :mod:`armreach_core.rl.throughput`).
"""

"""Diagnostics that stand apart from the runtime core.

- :mod:`.bench`, :mod:`.soak`: env speed and memory over time; :mod:`.installed`: which
  registered backends can run here; :mod:`.pace`: how fast the machine runs at a moment
  (the engine loop and dense arithmetic), written beside timings that follow it;
  :mod:`.machine`: the processor, cores and Python a figure was measured on.
- :mod:`.parity`: the two engines driven alike and compared, from the parts
  :mod:`.parity_sequences` (driving one backend), :mod:`.parity_gaps` (the comparison
  and its tolerances) and :mod:`.parity_report` (Markdown, plot, files).
- :mod:`.robot_report`, :mod:`.robot_page`, :mod:`.corpus`: what ``armreach robot``
  measures of an arm, the page it writes, and the public arms it is tried on
  (:func:`.corpus.for_each_corpus_arm` runs a check on each).
- :mod:`.rollout`: one seeded episode with pictures (``armreach rollout``).
- :mod:`.contract`: the backend contract suite every backend's tests run.
- :mod:`.smoothness`: jerk of a trajectory.
- :mod:`.tables`: markdown tables, the one way reports write them.

Nothing in the env imports this package, and it imports no training code (the training
throughput of ``armreach bench`` lives in :mod:`armreach_core.rl.throughput`).
"""

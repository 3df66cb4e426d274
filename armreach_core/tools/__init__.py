"""Diagnostics that stand apart from the runtime core: ``bench``, ``parity`` and ``soak``.

Nothing in the env imports this package, and it imports no training code (the training
throughput of ``armreach bench`` lives in :mod:`armreach_core.rl.throughput`).
"""

"""armreach's own tasks, each registered by :mod:`armreach_core.plugins.builtin` the way a
third-party task distribution registers its own (see ``tasks/`` in the repository)."""

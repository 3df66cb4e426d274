"""A plugin module that cannot be imported: armreach must report it by name and load the others."""

import armreach_no_such_dependency  # noqa: F401
